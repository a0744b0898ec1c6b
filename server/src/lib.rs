//! The crm-grasp coordinator: an axum REST API, the web dashboard (`web.rs`, pages from
//! `web/`, charts rendered as SVG in `charts.rs`) and a tonic gRPC endpoint for rollout
//! workers over one sqlite store. Jobs are leased with a heartbeat; an expired lease puts the
//! job back in the queue and the next worker resumes it from its last uploaded checkpoint.
//! Links neither rapier, candle nor rerun.

pub mod api;
pub mod auth;
pub mod charts;
pub mod config;
pub mod errors;
pub mod grpc;
pub mod launcher;
pub mod listen;
pub mod secrets;
pub mod store;
pub mod tls;
pub mod uploads;
pub mod web;

use std::net::SocketAddr;
use std::sync::Arc;

use anyhow::Context;
use crm_api::Catalog;
use tokio::sync::Notify;

pub use config::ServerConfig;
pub use store::Store;

/// What every handler shares.
pub struct AppState {
    pub store: Store,
    pub catalog: Arc<Catalog>,
    /// The worlds jobs may name: the built-in one first, then those of `--worlds`.
    pub worlds: Arc<Vec<crm_api::worlds::WorldEntry>>,
    pub config: ServerConfig,
    /// The bearer tokens and their scopes (`auth.rs`).
    pub tokens: auth::Tokens,
    /// The REST API's per-client request budget (`--rate-limit-per-s`).
    pub rate: api::rate::Limiter,
    /// A counter bumped when a job is queued, changes state or reports progress; live pages
    /// follow it through `GET /api/v1/events`. [`SHUTDOWN`] ends their streams.
    pub events: tokio::sync::watch::Sender<u64>,
    /// Places for open event streams (`--max-event-streams`).
    pub event_streams: Arc<tokio::sync::Semaphore>,
}

/// The `events` value that tells live streams the coordinator is stopping.
pub const SHUTDOWN: u64 = u64::MAX;

impl AppState {
    pub fn notify(&self) {
        self.events
            .send_modify(|v| *v = v.wrapping_add(1) % SHUTDOWN);
    }
}

/// A running coordinator.
pub struct Running {
    pub http_addr: SocketAddr,
    pub grpc_addr: SocketAddr,
    /// Whether both listeners speak TLS (`https://` addresses).
    pub tls: bool,
    pub state: Arc<AppState>,
    tasks: Vec<tokio::task::JoinHandle<anyhow::Result<()>>>,
    shutdown: Arc<Notify>,
}

impl Running {
    /// Stops serving and closes the store. Requests in flight get a few seconds; a worker's
    /// open progress stream does not hold the shutdown (its job is re-queued when the lease
    /// expires, as if the worker had died).
    pub async fn stop(self) -> anyhow::Result<()> {
        self.shutdown.notify_waiters();
        self.state.events.send_replace(SHUTDOWN);
        for task in self.tasks {
            let abort = task.abort_handle();
            match tokio::time::timeout(std::time::Duration::from_secs(3), task).await {
                Ok(joined) => joined??,
                Err(_) => {
                    abort.abort();
                    tracing::warn!("open streams cut at shutdown");
                }
            }
        }
        self.state.store.close().await;
        Ok(())
    }

    /// Serves until ctrl-c.
    pub async fn wait(self) -> anyhow::Result<()> {
        tokio::signal::ctrl_c().await?;
        tracing::info!("shutting down");
        self.stop().await
    }
}

/// Opens the store, binds both listeners and starts serving.
pub async fn start(config: ServerConfig) -> anyhow::Result<Running> {
    config.validate()?;
    let store = Store::open(&config.data_dir)
        .await
        .with_context(|| format!("opening the store in {}", config.data_dir.display()))?;
    let catalog = Arc::new(Catalog::builtin()?);
    let worlds =
        Arc::new(crm_api::worlds::discover(config.worlds.as_deref()).context("reading --worlds")?);
    let tokens = auth::Tokens::configured(&config)?;
    let identity = match (&config.tls_cert, &config.tls_key) {
        (Some(cert), Some(key)) => Some(tls::Identity::load(cert, key)?),
        _ => None,
    };
    let state = Arc::new(AppState {
        store,
        catalog,
        worlds,
        tokens,
        rate: api::rate::Limiter::new(config.rate_limit_per_s, config.rate_limit_burst),
        config: config.clone(),
        events: tokio::sync::watch::channel(0).0,
        event_streams: Arc::new(tokio::sync::Semaphore::new(config.max_event_streams.max(1))),
    });
    if state.store.created() && config.models.is_dir() {
        let n = uploads::register_dir(&state, &config.models)
            .await
            .with_context(|| format!("registering the models in {}", config.models.display()))?;
        tracing::info!(models = n, dir = %config.models.display(), "shipped models registered");
    } else if state.store.created() {
        tracing::info!(dir = %config.models.display(), "no models folder: none registered");
    }
    let http = tokio::net::TcpListener::bind(&config.http)
        .await
        .with_context(|| format!("binding the HTTP address {}", config.http))?;
    let grpc = tokio::net::TcpListener::bind(&config.grpc)
        .await
        .with_context(|| format!("binding the gRPC address {}", config.grpc))?;
    let http_addr = http.local_addr()?;
    let grpc_addr = grpc.local_addr()?;
    let shutdown = Arc::new(Notify::new());

    let router = api::router(state.clone());
    let stop = shutdown.clone();
    let limits = listen::Limits {
        max_connections: config.max_connections.max(1),
        per_client: config.max_connections_per_client.max(1),
        header_timeout: std::time::Duration::from_secs(config.header_timeout_s.max(1).into()),
        idle_timeout: std::time::Duration::from_secs(config.idle_timeout_s.max(1).into()),
    };
    let rest_tls = identity.as_ref().map(|i| i.rest.clone());
    let http_task = tokio::spawn(async move {
        let stopped = async move { stop.notified().await };
        listen::serve(http, router, limits, rest_tls, stopped).await;
        anyhow::Ok(())
    });
    let stop = shutdown.clone();
    let service = grpc::service(state.clone());
    // HTTP/2 pings find a worker whose connection died without a close (a cable pulled):
    // every 20 s, 10 s to answer (gRPC's keepalive guide suggests minutes for clients; a
    // server may ping more often, and a worker's heartbeat is 5 s anyway).
    let mut builder = tonic::transport::Server::builder()
        .http2_keepalive_interval(Some(std::time::Duration::from_secs(20)))
        .http2_keepalive_timeout(Some(std::time::Duration::from_secs(10)));
    if let Some(identity) = &identity {
        builder = builder
            .tls_config(identity.grpc())
            .context("the gRPC listener's TLS")?;
    }
    let grpc_task = tokio::spawn(async move {
        builder
            .add_service(service)
            .serve_with_incoming_shutdown(listen::grpc_incoming(grpc, limits), async move {
                stop.notified().await
            })
            .await
            .context("gRPC server")
    });
    // Expired leases go back to the queue even when no worker asks for work.
    let stop = shutdown.clone();
    let sweeper_state = state.clone();
    let sweeper = tokio::spawn(async move {
        loop {
            tokio::select! {
                () = stop.notified() => return Ok(()),
                () = tokio::time::sleep(std::time::Duration::from_secs(1)) => {}
            }
            match sweeper_state.store.requeue_expired().await {
                Ok(0) => {}
                Ok(n) => {
                    tracing::warn!(jobs = n, "leases expired; jobs re-queued");
                    sweeper_state.notify();
                }
                Err(err) => tracing::error!(%err, "requeue sweep failed"),
            }
        }
    });
    let mut tasks = vec![http_task, grpc_task, sweeper];
    // Workers through a batch system while jobs wait (`--launcher`).
    if let Some(launcher) = launcher::Launcher::new(&state, grpc_addr, identity.is_some())? {
        tracing::info!(
            name = launcher.job_name(),
            "launcher: workers start through Slurm"
        );
        let (state, stop) = (state.clone(), shutdown.clone());
        tasks.push(tokio::spawn(async move {
            launcher.run(state, stop).await;
            anyhow::Ok(())
        }));
    }
    tracing::info!(%http_addr, %grpc_addr, data = %config.data_dir.display(), "coordinator up");
    Ok(Running {
        http_addr,
        grpc_addr,
        tls: identity.is_some(),
        state,
        tasks,
        shutdown,
    })
}

/// Structured logs to stderr; `RUST_LOG` filters (default `info`).
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init()
        .ok();
}
