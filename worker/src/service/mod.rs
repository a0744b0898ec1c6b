//! The service side of the `crm` binary: a rollout worker that leases jobs from the
//! coordinator over gRPC and runs them with the learners (`crm worker`), the `Policy` gRPC
//! server for a trained checkpoint (`crm serve-policy`), and `crm up`, which starts the
//! coordinator and local workers in one process.

pub mod client;
pub mod policy;
pub mod run;
pub mod up;
mod video;

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
    /// Exit after this many jobs (a batch allocation that should end with its work).
    pub max_jobs: Option<u64>,
    /// Exit after this many seconds without a job (an elastic pool shrinks with the queue).
    pub idle_exit_s: Option<f64>,
}

/// Leases and runs jobs until `stop` is set (a running job then ends where it can be resumed
/// and goes back to the queue), `max_jobs` have run or the queue has been empty for
/// `idle_exit_s`. Reconnects when the coordinator goes away.
pub async fn run_worker(options: WorkerOptions, stop: Arc<AtomicBool>) -> anyhow::Result<()> {
    let mut backoff = Duration::from_millis(200);
    let mut jobs = 0u64;
    let mut idle_since = std::time::Instant::now();
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
        client.mlflow = (!registration.mlflow_uri.is_empty()).then_some(client::MlflowSetting {
            uri: registration.mlflow_uri,
            experiment: registration.mlflow_experiment,
            coordinator_id: registration.coordinator_id,
        });
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            if options.max_jobs.is_some_and(|most| jobs >= most) {
                tracing::info!(jobs, "ran --max-jobs jobs; exiting");
                return Ok(());
            }
            if options
                .idle_exit_s
                .is_some_and(|s| idle_since.elapsed().as_secs_f64() >= s)
            {
                tracing::info!("no job for --idle-exit-s seconds; exiting");
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
                        if let Err(err) = run::run_job(&leased, &options, job, &stop).await {
                            tracing::error!(job = id, err = format!("{err:#}"), "job failed");
                            leased.fail(id, &format!("{err:#}")).await.ok();
                        }
                        jobs += 1;
                        idle_since = std::time::Instant::now();
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

/// `crm worker`'s entry: runs until SIGTERM or SIGINT (or `--max-jobs`, `--idle-exit-s`).
/// The first signal stops it: a training job ends at its next iteration boundary with a
/// checkpoint upload, an evaluation at its current episode's end with its progress, the job
/// goes back to the queue and the worker
/// exits 0, within `grace_s` seconds at most (then it exits anyway, and the job waits for its
/// lease to expire). A second signal exits at once.
pub fn worker_main(options: WorkerOptions, grace_s: f64) -> anyhow::Result<()> {
    crm_server::init_logging();
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(async move {
        let stop = Arc::new(AtomicBool::new(false));
        let mut signals = Signals::new()?;
        let worker = run_worker(options, stop.clone());
        tokio::pin!(worker);
        tokio::select! {
            result = &mut worker => return result,
            name = signals.next() => {
                stop.store(true, Ordering::Relaxed);
                tracing::info!(signal = name, grace_s, "stopping: the running job ends where it can resume and is queued again");
            }
        }
        tokio::select! {
            result = &mut worker => result,
            name = signals.next() => {
                tracing::warn!(signal = name, "a second signal: exiting at once");
                std::process::exit(1);
            }
            _ = tokio::time::sleep(Duration::from_secs_f64(grace_s)) => {
                tracing::warn!(grace_s, "the job did not stop within the grace period; exiting (it is queued again when its lease expires)");
                Ok(())
            }
        }
    });
    // Do not wait for a job's blocking thread (see `up_main`).
    runtime.shutdown_timeout(Duration::from_secs(2));
    result
}

/// A flag the first SIGTERM or SIGINT sets, for a synchronous command that stops at its next
/// safe point (`crm train`); a second signal exits at once.
pub fn stop_on_signals() -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the signal listener")?;
    let mut signals = runtime.block_on(async { Signals::new() })?;
    let flag = stop.clone();
    std::thread::spawn(move || {
        runtime.block_on(async move {
            let name = signals.next().await;
            eprintln!(
                "{name}: stopping at the end of this iteration (a second signal exits at once)"
            );
            flag.store(true, Ordering::Relaxed);
            let name = signals.next().await;
            eprintln!("{name}: exiting at once");
            std::process::exit(1);
        })
    });
    Ok(stop)
}

/// SIGTERM (`scancel`, a batch system's time limit, `docker stop`, Kubernetes) and SIGINT
/// (ctrl-c), as one stream.
pub struct Signals {
    term: tokio::signal::unix::Signal,
    int: tokio::signal::unix::Signal,
}

impl Signals {
    pub fn new() -> anyhow::Result<Self> {
        use tokio::signal::unix::{SignalKind, signal};
        Ok(Self {
            term: signal(SignalKind::terminate()).context("listening for SIGTERM")?,
            int: signal(SignalKind::interrupt()).context("listening for SIGINT")?,
        })
    }

    /// The next signal's name.
    pub async fn next(&mut self) -> &'static str {
        tokio::select! {
            _ = self.term.recv() => "SIGTERM",
            _ = self.int.recv() => "SIGINT",
        }
    }
}
