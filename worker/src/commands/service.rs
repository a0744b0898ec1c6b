//! `crm up`, `crm worker` and `crm serve-policy`: the service from the command line.

use std::path::PathBuf;

use crm_server::ServerConfig;

use crate::service::{WorkerOptions, policy, up, worker_main};

/// Options every worker takes.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkerFlags {
    /// Seconds between checkpoint uploads while training.
    #[arg(long, default_value_t = 60)]
    pub checkpoint_every_s: u64,
    /// Seconds between asks when the queue is empty.
    #[arg(long, default_value_t = 1.0)]
    pub poll_s: f64,
    /// Environments per training job when the job does not say (default: one per core).
    #[arg(long)]
    pub envs: Option<usize>,
    /// This worker's name (default: the Slurm job's id, `slurm-JOB` or `slurm-JOB_TASK` in
    /// an array, else the host name).
    #[arg(long)]
    pub name: Option<String>,
    /// The CA certificate (PEM) that signed the coordinator's TLS certificate, for an
    /// `https://` coordinator with a private CA (`crm certs dev` writes `ca.pem`); without it
    /// the system's roots are used.
    #[arg(long, value_name = "FILE")]
    pub ca: Option<PathBuf>,
}

impl WorkerFlags {
    fn options(
        &self,
        coordinator: String,
        token: Option<String>,
        worlds: Option<PathBuf>,
    ) -> WorkerOptions {
        WorkerOptions {
            coordinator,
            token,
            ca: self.ca.clone(),
            worlds,
            name: self.name.clone().unwrap_or_else(default_name),
            checkpoint_every_s: self.checkpoint_every_s,
            poll_s: self.poll_s.clamp(0.05, 60.0),
            envs: self.envs,
            max_jobs: None,
            idle_exit_s: None,
        }
    }
}

/// A worker's name when none is given: the scheduler's job (Slurm's array job and task, or
/// its job id), else the host's name.
fn default_name() -> String {
    let var = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
    match (
        var("SLURM_ARRAY_JOB_ID"),
        var("SLURM_ARRAY_TASK_ID"),
        var("SLURM_JOB_ID"),
    ) {
        (Some(array), Some(task), _) => format!("slurm-{array}_{task}"),
        (_, _, Some(job)) => format!("slurm-{job}"),
        _ => crm_server::launcher::host_name().unwrap_or_else(|| "worker".into()),
    }
}

#[derive(clap::Args, Debug)]
pub struct UpArgs {
    #[command(flatten)]
    pub server: ServerConfig,
    /// A JSON file with the coordinator's settings instead of the flags.
    #[arg(long, value_name = "FILE")]
    pub config_file: Option<PathBuf>,
    /// Local workers (default: one per core).
    #[arg(long)]
    pub workers: Option<usize>,
    #[command(flatten)]
    pub worker: WorkerFlags,
}

#[derive(clap::Args, Debug)]
pub struct WorkerArgs {
    /// The coordinator's gRPC URL.
    #[arg(long, default_value = "http://127.0.0.1:50051")]
    pub coordinator: String,
    /// The coordinator's bearer token.
    #[arg(long, env = "CRM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// A folder of world folders (each with a `world.json`) this worker can run besides the
    /// built-in world: the coordinator's `--worlds`, as this machine sees it.
    #[arg(long, value_name = "DIR")]
    pub worlds: Option<PathBuf>,
    #[command(flatten)]
    pub worker: WorkerFlags,
    /// A file holding the coordinator's token (a batch system copies the environment, and
    /// with it `CRM_TOKEN`, into its records; a file readable by the user alone does not
    /// leak).
    #[arg(long, value_name = "FILE", conflicts_with = "token")]
    pub token_file: Option<PathBuf>,
    /// Exit (0) after this many jobs.
    #[arg(long, value_name = "N")]
    pub max_jobs: Option<u64>,
    /// Exit (0) after this many seconds without a job: a pool of batch jobs shrinks as the
    /// queue empties.
    #[arg(long, value_name = "SECONDS")]
    pub idle_exit_s: Option<f64>,
    /// Seconds a stopping worker (SIGTERM, SIGINT) has to checkpoint and give its job back
    /// before it exits anyway. Default 25: under Slurm's default `KillWait` of 30 s between
    /// SIGTERM and SIGKILL (Kubernetes' `terminationGracePeriodSeconds` default is 30 too).
    #[arg(long, value_name = "SECONDS", default_value_t = 25.0)]
    pub grace_s: f64,
}

#[derive(clap::Args, Debug)]
pub struct ServePolicyArgs {
    #[arg(long)]
    pub checkpoint: PathBuf,
    /// Address to serve the Policy gRPC on.
    #[arg(long, default_value = "127.0.0.1:50052")]
    pub listen: String,
    /// Bearer token every call must carry (`authorization: Bearer <token>`); without one the
    /// policy answers anyone who reaches the address.
    #[arg(long, env = "CRM_POLICY_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// PEM certificate chain: with `--tls-key`, the policy is served over TLS only.
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// PEM private key of `--tls-cert`.
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// The world folder the checkpoint was trained in (default: the built-in world).
    #[arg(long, value_name = "DIR")]
    pub world: Option<PathBuf>,
}

pub fn up(args: UpArgs) -> anyhow::Result<()> {
    let config = match &args.config_file {
        Some(path) => crm_server::config::load(path)?,
        None => args.server,
    };
    config.validate()?;
    if config.tls_cert.is_some() && args.worker.ca.is_none() {
        anyhow::bail!(
            "--ca: needed with --tls-cert, to check the coordinator's certificate from the local workers (`crm certs dev` writes ca.pem)"
        );
    }
    let workers = args
        .workers
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let options = args
        .worker
        .options(String::new(), config.token.clone(), config.worlds.clone());
    up::up_main(config, workers, options)
}

pub fn worker(args: WorkerArgs) -> anyhow::Result<()> {
    if args.token.as_deref() == Some("") {
        anyhow::bail!("--token must not be empty");
    }
    let token = match &args.token_file {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| anyhow::anyhow!("--token-file {}: {e}", path.display()))?;
            let token = text.trim().to_string();
            if token.is_empty() {
                anyhow::bail!("--token-file {}: the file is empty", path.display());
            }
            Some(token)
        }
        None => args.token,
    };
    for (flag, value) in [
        ("--idle-exit-s", args.idle_exit_s),
        ("--grace-s", Some(args.grace_s)),
    ] {
        if value.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
            anyhow::bail!("{flag} must be a number of seconds >= 0");
        }
    }
    if args.max_jobs == Some(0) {
        anyhow::bail!("--max-jobs must be at least 1");
    }
    let options = WorkerOptions {
        max_jobs: args.max_jobs,
        idle_exit_s: args.idle_exit_s,
        ..args.worker.options(args.coordinator, token, args.worlds)
    };
    worker_main(options, args.grace_s)
}

pub fn serve_policy(args: ServePolicyArgs) -> anyhow::Result<()> {
    let env = match args.world {
        Some(dir) => crm_run::Env::in_world(dir),
        None => crm_run::Env::default(),
    };
    let access = policy::Access::new(args.token, args.tls_cert.zip(args.tls_key))?;
    policy::serve_main(&args.checkpoint, &args.listen, &env, access)
}
