//! The service side of the `crm` binary: a rollout worker that leases jobs from the
//! coordinator over gRPC and runs them with the learners (`crm worker`), the `Policy` gRPC
//! server for a trained checkpoint (`crm serve-policy`), and `crm up`, which starts the
//! coordinator and local workers in one process.

pub mod client;
pub mod policy;
pub mod run;
pub mod up;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use crm_proto::pb;

pub use client::Client;

/// How a worker behaves.
#[derive(Clone, Debug)]
pub struct WorkerOptions {
    /// The coordinator's gRPC URL, e.g. `http://127.0.0.1:50051`.
    pub coordinator: String,
    pub token: Option<String>,
    /// The CA certificate (PEM file) of an `https://` coordinator with a private CA.
    pub ca: Option<std::path::PathBuf>,
    pub name: String,
    /// Seconds between checkpoint uploads while training.
    pub checkpoint_every_s: u64,
    /// Seconds between asks when the queue is empty.
    pub poll_s: f64,
    /// Environments per training job when the job does not say (default: one per core).
    pub envs: Option<usize>,
    /// The folder of world folders this worker can run besides the built-in world.
    pub worlds: Option<std::path::PathBuf>,
}

/// Leases and runs jobs until `stop` is set. Reconnects when the coordinator goes away.
pub async fn run_worker(options: WorkerOptions, stop: Arc<AtomicBool>) -> anyhow::Result<()> {
    let mut backoff = Duration::from_millis(200);
    while !stop.load(Ordering::Relaxed) {
        let connected = Client::connect(
            &options.coordinator,
            options.token.as_deref(),
            options.ca.as_deref(),
        );
        let mut client = match connected.await {
            Ok(client) => client,
            Err(err) => {
                tracing::warn!(%err, coordinator = options.coordinator, "cannot reach the coordinator; retrying");
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        let registration = match client
            .inner
            .register(pb::RegisterRequest {
                name: options.name.clone(),
                cores: std::thread::available_parallelism().map_or(1, |n| n.get() as u32),
                version: env!("CARGO_PKG_VERSION").into(),
            })
            .await
        {
            Ok(reply) => reply.into_inner(),
            // A wrong token, a token without the worker scope or a name the coordinator
            // refuses will not change on a retry.
            Err(status)
                if matches!(
                    status.code(),
                    tonic::Code::Unauthenticated
                        | tonic::Code::PermissionDenied
                        | tonic::Code::InvalidArgument
                ) =>
            {
                anyhow::bail!("the coordinator refused this worker: {}", status.message());
            }
            Err(status) => {
                tracing::warn!(%status, "register failed; retrying");
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        backoff = Duration::from_millis(200);
        tracing::info!(worker = registration.worker_id, "registered");
        client.worker_id = registration.worker_id;
        client.worker_secret = registration.worker_secret;
        client.heartbeat = Duration::from_secs(u64::from(registration.heartbeat_interval_s.max(1)));
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            let lease = client
                .inner
                .lease(pb::LeaseRequest {
                    worker_id: client.worker_id.clone(),
                    worker_secret: client.worker_secret.clone(),
                })
                .await;
            match lease {
                Ok(reply) => match reply.into_inner().job {
                    Some(job) => {
                        let id = job.job_id;
                        // The job's calls carry its lease's secret.
                        let leased = Client {
                            lease_token: job.lease_token.clone(),
                            ..client.clone()
                        };
                        if let Err(err) = run::run_job(&leased, &options, job).await {
                            tracing::error!(job = id, err = format!("{err:#}"), "job failed");
                            leased.fail(id, &format!("{err:#}")).await.ok();
                        }
                    }
                    None => tokio::time::sleep(Duration::from_secs_f64(options.poll_s)).await,
                },
                Err(status) if status.code() == tonic::Code::Unauthenticated => {
                    anyhow::bail!("the coordinator refused this worker: {}", status.message());
                }
                Err(status) => {
                    tracing::warn!(%status, "lease failed; reconnecting");
                    tokio::time::sleep(backoff).await;
                    break;
                }
            }
        }
    }
    Ok(())
}

/// `crm worker`'s entry: runs until ctrl-c.
pub fn worker_main(options: WorkerOptions) -> anyhow::Result<()> {
    crm_server::init_logging();
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(async move {
        let stop = Arc::new(AtomicBool::new(false));
        tokio::select! {
            result = run_worker(options, stop.clone()) => result,
            _ = tokio::signal::ctrl_c() => {
                stop.store(true, Ordering::Relaxed);
                tracing::info!("stopping; a running job is re-queued when its lease expires");
                Ok(())
            }
        }
    });
    // Do not wait for a job's blocking thread (see `up_main`).
    runtime.shutdown_timeout(Duration::from_secs(2));
    result
}
