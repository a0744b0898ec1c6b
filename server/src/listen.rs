//! The REST listener with connection hygiene, where `axum::serve` has none (axum 0.8.9: no
//! header-read timeout, since hyper's needs a timer it does not set; no idle timeout; no cap,
//! so idle sockets exhausted the process's file descriptors and accept errors stopped
//! `/healthz`). Each connection gets hyper's header-read timeout, a deadline for its first
//! byte and an idle timeout (nothing read or written); beyond `max_connections` open ones, or
//! `per_client` from one address (so that one client cannot hold them all), a connection is
//! answered 503 with `Retry-After` and closed; an accept error (out of descriptors) is logged and retried, never
//! fatal. Shutdown lets open connections finish their requests. The gRPC listener's
//! connections ([`grpc_incoming`]) are capped and closed when idle the same way (a worker
//! heartbeats every few seconds). With `--tls-cert`, each REST connection is a TLS stream
//! (rustls; the handshake gets the header timeout), and each request carries its client's
//! address for the rate limit (`api/rate.rs`).

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::net::IpAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto::Builder;
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc, watch};
use tokio::time::{Instant, Sleep};

use crate::api::rate::ClientAddr;

/// How long and how many connections the listener keeps.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    pub max_connections: usize,
    /// Open connections from one client address.
    pub per_client: usize,
    /// Longest wait for a request's headers, from the first byte of the connection or the
    /// end of the previous request.
    pub header_timeout: Duration,
    /// Longest time a connection may read and write nothing (an event stream writes a
    /// keep-alive every 15 s).
    pub idle_timeout: Duration,
}

/// What a listener speaks: plain TCP, or TLS with this configuration (`tls.rs`).
pub type Tls = Option<Arc<rustls::ServerConfig>>;

/// The answer to a connection beyond the cap.
const BUSY: &str = "{\"error\":{\"code\":\"unavailable\",\"field\":\"connection\",\"message\":\"too many open connections; retry later\"}}";

/// Serves `router` on `listener` until `stop` completes.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    limits: Limits,
    tls: Tls,
    stop: impl Future<Output = ()>,
) {
    let acceptor = tls.map(tokio_rustls::TlsAcceptor::from);
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let clients = Clients::default();
    let (close, closing) = watch::channel(false);
    let mut stop = std::pin::pin!(stop);
    loop {
        let stream = tokio::select! {
            stream = accept(&listener) => stream,
            () = &mut stop => break,
        };
        let client = stream.peer_addr().ok();
        let guarded = match Guarded::new(stream, &permits, &clients, limits) {
            Ok(guarded) => guarded,
            Err(stream) => {
                tokio::spawn(refuse(stream));
                continue;
            }
        };
        // Each request carries its connection's address, for the per-client rate limit.
        let service = TowerToHyperService::new(tower::util::MapRequest::new(
            router.clone(),
            move |mut request: axum::extract::Request<hyper::body::Incoming>| {
                if let Some(addr) = client {
                    request.extensions_mut().insert(ClientAddr(addr));
                }
                request
            },
        ));
        let closing = closing.clone();
        let acceptor = acceptor.clone();
        tokio::spawn(async move {
            let Some(acceptor) = acceptor else {
                return connection(TokioIo::new(guarded), service, limits, closing).await;
            };
            // The handshake gets the header timeout; a client that stalls in it is dropped.
            match tokio::time::timeout(limits.header_timeout, acceptor.accept(guarded)).await {
                Ok(Ok(tls)) => connection(TokioIo::new(tls), service, limits, closing).await,
                Ok(Err(err)) => tracing::debug!(%err, "TLS handshake failed"),
                Err(_) => tracing::debug!("TLS handshake timed out"),
            }
        });
    }
    let _ = close.send(true);
    // Open connections finish their requests, for at most 10 s.
    let all = u32::try_from(limits.max_connections).unwrap_or(u32::MAX);
    let _ = tokio::time::timeout(Duration::from_secs(10), permits.acquire_many(all)).await;
}

/// Serves one connection's requests until it closes, or until `closing` asks it to finish.
async fn connection<I, S>(
    io: TokioIo<I>,
    service: S,
    limits: Limits,
    mut closing: watch::Receiver<bool>,
) where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
    S: hyper::service::Service<
            hyper::Request<hyper::body::Incoming>,
            Response = axum::response::Response,
            Error = std::convert::Infallible,
        > + Clone
        + Send
        + 'static,
    S::Future: Send + 'static,
{
    let mut builder = Builder::new(TokioExecutor::new());
    builder
        .http1()
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    builder.http2().timer(TokioTimer::new());
    let conn = builder.serve_connection_with_upgrades(io, service);
    let mut conn = std::pin::pin!(conn);
    // `is_ok` lets go of the watch's read guard before the select's output holds it.
    let shutdown = async { closing.wait_for(|c| *c).await.is_ok() };
    tokio::select! {
        _ = conn.as_mut() => {}
        _ = shutdown => {
            conn.as_mut().graceful_shutdown();
            let _ = conn.await;
        }
    }
}

/// The gRPC listener's connections: at most `max_connections` open (one beyond is closed at
/// once), each closed after `idle_timeout` of silence.
pub fn grpc_incoming(
    listener: TcpListener,
    limits: Limits,
) -> tokio_stream::wrappers::ReceiverStream<io::Result<Guarded>> {
    let (send, receive) = mpsc::channel(16);
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let clients = Clients::default();
    tokio::spawn(async move {
        loop {
            let stream = accept(&listener).await;
            let Ok(guarded) = Guarded::new(stream, &permits, &clients, limits) else {
                tracing::warn!("too many gRPC connections; one closed");
                continue;
            };
            if send.send(Ok(guarded)).await.is_err() {
                return; // the server stopped
            }
        }
    });
    tokio_stream::wrappers::ReceiverStream::new(receive)
}

/// The next connection; an accept error (out of descriptors) is logged and retried after
/// 50 ms, never returned.
async fn accept(listener: &TcpListener) -> TcpStream {
    loop {
        match listener.accept().await {
            Ok((stream, _)) => return stream,
            Err(err) => {
                tracing::warn!(%err, "accept failed; retrying");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
}

/// Answers 503 with `Retry-After` and closes, within a second.
async fn refuse(mut stream: TcpStream) {
    let reply = format!(
        "HTTP/1.1 503 Service Unavailable\r\nretry-after: 1\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{BUSY}",
        BUSY.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), async {
        let _ = stream.write_all(reply.as_bytes()).await;
        let _ = stream.shutdown().await;
    })
    .await;
}

/// Open connections per client address.
#[derive(Clone, Default)]
struct Clients(Arc<Mutex<HashMap<IpAddr, usize>>>);

/// One connection's place in its client's count, given back on drop.
struct ClientSlot {
    clients: Clients,
    ip: IpAddr,
}

impl Clients {
    /// A place for one more connection from `ip`, unless it holds `most` already.
    fn take(&self, ip: IpAddr, most: usize) -> Option<ClientSlot> {
        let mut counts = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let count = counts.entry(ip).or_insert(0);
        if *count >= most {
            return None;
        }
        *count += 1;
        Some(ClientSlot {
            clients: self.clone(),
            ip,
        })
    }
}

impl Drop for ClientSlot {
    fn drop(&mut self) {
        let mut counts = self.clients.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(count) = counts.get_mut(&self.ip) {
            *count -= 1;
            if *count == 0 {
                counts.remove(&self.ip);
            }
        }
    }
}

/// A connection holding its place under the caps, which fails with `TimedOut` once nothing
/// has been read or written for `timeout`, or when its first byte has not come within the
/// header timeout.
pub struct Guarded {
    stream: TcpStream,
    timeout: Duration,
    deadline: Pin<Box<Sleep>>,
    /// Until the first byte arrives.
    first_byte: Option<Pin<Box<Sleep>>>,
    _permit: OwnedSemaphorePermit,
    _slot: Option<ClientSlot>,
}

impl Guarded {
    /// `stream` with a place under the caps, or back when there is none.
    fn new(
        stream: TcpStream,
        permits: &Arc<Semaphore>,
        clients: &Clients,
        limits: Limits,
    ) -> Result<Self, TcpStream> {
        let slot = match stream.peer_addr() {
            Ok(addr) => match clients.take(addr.ip(), limits.per_client) {
                Some(slot) => Some(slot),
                None => return Err(stream),
            },
            Err(_) => None,
        };
        let Ok(permit) = permits.clone().try_acquire_owned() else {
            return Err(stream);
        };
        Ok(Self {
            stream,
            timeout: limits.idle_timeout,
            deadline: Box::pin(tokio::time::sleep(limits.idle_timeout)),
            first_byte: Some(Box::pin(tokio::time::sleep(limits.header_timeout))),
            _permit: permit,
            _slot: slot,
        })
    }

    fn active(&mut self) {
        let next = Instant::now() + self.timeout;
        self.deadline.as_mut().reset(next);
    }

    fn expired(&mut self, cx: &mut Context<'_>) -> bool {
        let silent = self
            .first_byte
            .as_mut()
            .is_some_and(|first| first.as_mut().poll(cx).is_ready());
        silent || self.deadline.as_mut().poll(cx).is_ready()
    }
}

impl tonic::transport::server::Connected for Guarded {
    type ConnectInfo = tonic::transport::server::TcpConnectInfo;

    fn connect_info(&self) -> Self::ConnectInfo {
        self.stream.connect_info()
    }
}

fn timed_out() -> io::Error {
    io::Error::new(io::ErrorKind::TimedOut, "connection idle")
}

impl AsyncRead for Guarded {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        match Pin::new(&mut self.stream).poll_read(cx, buf) {
            Poll::Ready(result) => {
                if buf.filled().len() > before {
                    self.first_byte = None;
                    self.active();
                }
                Poll::Ready(result)
            }
            Poll::Pending if self.expired(cx) => Poll::Ready(Err(timed_out())),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl AsyncWrite for Guarded {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[u8],
    ) -> Poll<io::Result<usize>> {
        match Pin::new(&mut self.stream).poll_write(cx, data) {
            Poll::Ready(Ok(n)) => {
                if n > 0 {
                    self.active();
                }
                Poll::Ready(Ok(n))
            }
            Poll::Ready(err) => Poll::Ready(err),
            // A client that stops reading is idle too.
            Poll::Pending if self.expired(cx) => Poll::Ready(Err(timed_out())),
            Poll::Pending => Poll::Pending,
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}
