//! Per-client rate limits on the REST API: a token bucket per client address (an IPv6
//! client by its /64, the block one host is usually given), refilled at
//! `--rate-limit-per-s` up to `--rate-limit-burst`. A request that finds its bucket empty is
//! answered 429 with `Retry-After`, before any token check or store work. The table of
//! buckets is bounded: past [`MAX_CLIENTS`] addresses, idle ones (full buckets) are dropped,
//! and when none is idle new addresses share one overflow bucket.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use axum::extract::{Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;
use crate::AppState;

/// Most client addresses tracked one by one.
pub const MAX_CLIENTS: usize = 65_536;

/// The address a connection came from, put on each request by the listener.
#[derive(Clone, Copy, Debug)]
pub struct ClientAddr(pub SocketAddr);

#[derive(Clone, Copy, Debug)]
struct Bucket {
    tokens: f64,
    at: Instant,
}

/// The buckets; `per_s == 0` is no limit.
#[derive(Clone)]
pub struct Limiter {
    per_s: f64,
    burst: f64,
    buckets: Arc<Mutex<HashMap<IpAddr, Bucket>>>,
}

/// The key of a client: an IPv4 address, or an IPv6 address's /64.
fn key(ip: IpAddr) -> IpAddr {
    match ip {
        IpAddr::V4(_) => ip,
        IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
            Some(v4) => IpAddr::V4(v4),
            None => {
                let mut s = v6.segments();
                s[4..].fill(0);
                IpAddr::V6(s.into())
            }
        },
    }
}

/// The shared bucket of addresses the table has no room for.
const OVERFLOW: IpAddr = IpAddr::V6(std::net::Ipv6Addr::UNSPECIFIED);

impl Limiter {
    pub fn new(per_s: u32, burst: u32) -> Self {
        Self {
            per_s: f64::from(per_s),
            burst: f64::from(burst.max(1)),
            buckets: Arc::new(Mutex::new(HashMap::new())),
        }
    }

    /// Takes one request from `ip`'s bucket at `now`: `Ok` or `Err(seconds to wait)`.
    pub fn take(&self, ip: IpAddr, now: Instant) -> Result<(), u64> {
        if self.per_s <= 0.0 {
            return Ok(());
        }
        let mut buckets = self.buckets.lock().unwrap_or_else(|e| e.into_inner());
        let mut ip = key(ip);
        if !buckets.contains_key(&ip) && buckets.len() >= MAX_CLIENTS {
            let (per_s, burst) = (self.per_s, self.burst);
            buckets.retain(|_, b| {
                b.tokens + now.saturating_duration_since(b.at).as_secs_f64() * per_s < burst
            });
            if buckets.len() >= MAX_CLIENTS {
                ip = OVERFLOW;
            }
        }
        let bucket = buckets.entry(ip).or_insert(Bucket {
            tokens: self.burst,
            at: now,
        });
        let elapsed = now.saturating_duration_since(bucket.at).as_secs_f64();
        bucket.tokens = (bucket.tokens + elapsed * self.per_s).min(self.burst);
        bucket.at = now;
        if bucket.tokens >= 1.0 {
            bucket.tokens -= 1.0;
            Ok(())
        } else {
            Err(((1.0 - bucket.tokens) / self.per_s).ceil().max(1.0) as u64)
        }
    }
}

/// The middleware: 429 with `Retry-After` once a client's bucket is empty. Requests without
/// a client address (handed to the router in-process) are not limited.
pub async fn limit(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    if let Some(ClientAddr(addr)) = request.extensions().get::<ClientAddr>().copied()
        && let Err(wait) = state.rate.take(addr.ip(), Instant::now())
    {
        return (
            [(header::RETRY_AFTER, wait.to_string())],
            ApiError::rate_limited(),
        )
            .into_response();
    }
    next.run(request).await
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_client_gets_its_burst_then_its_rate_and_others_are_untouched() {
        let limiter = Limiter::new(10, 5);
        let (a, b): (IpAddr, IpAddr) = (
            "10.0.0.1".parse().expect("address"),
            "10.0.0.2".parse().expect("address"),
        );
        let t0 = Instant::now();
        for _ in 0..5 {
            assert_eq!(limiter.take(a, t0), Ok(()));
        }
        assert_eq!(limiter.take(a, t0), Err(1));
        assert_eq!(
            limiter.take(b, t0),
            Ok(()),
            "another address has its own bucket"
        );
        // 0.1 s refills one request at 10 per second.
        assert_eq!(limiter.take(a, t0 + Duration::from_millis(110)), Ok(()));
        assert!(limiter.take(a, t0 + Duration::from_millis(110)).is_err());
        assert_eq!(Limiter::new(0, 1).take(a, t0), Ok(()), "0 is no limit");
    }

    #[test]
    fn an_ipv6_client_is_its_slash_64_and_a_mapped_ipv4_is_the_ipv4() {
        let limiter = Limiter::new(1, 1);
        let t0 = Instant::now();
        let one: IpAddr = "2001:db8:1:2::1".parse().expect("address");
        let same_block: IpAddr = "2001:db8:1:2:ffff::9".parse().expect("address");
        assert_eq!(limiter.take(one, t0), Ok(()));
        assert!(limiter.take(same_block, t0).is_err());
        let v4: IpAddr = "192.0.2.7".parse().expect("address");
        let mapped: IpAddr = "::ffff:192.0.2.7".parse().expect("address");
        assert_eq!(limiter.take(v4, t0), Ok(()));
        assert!(limiter.take(mapped, t0).is_err());
    }

    #[test]
    fn the_table_stays_bounded_when_every_request_comes_from_a_new_address() {
        let limiter = Limiter::new(1, 2);
        let t0 = Instant::now();
        for n in 0..(MAX_CLIENTS as u32 + 1000) {
            let ip = IpAddr::V4(n.to_be_bytes().into());
            let _ = limiter.take(ip, t0);
        }
        let len = limiter.buckets.lock().expect("lock").len();
        assert!(len <= MAX_CLIENTS + 1, "{len}");
    }
}
