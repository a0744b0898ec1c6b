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
    /// This worker's name (default: the host name).
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
            name: self.name.clone().unwrap_or_else(host_name),
            checkpoint_every_s: self.checkpoint_every_s,
            poll_s: self.poll_s.clamp(0.05, 60.0),
            envs: self.envs,
        }
    }
}

fn host_name() -> String {
    std::fs::read_to_string("/etc/hostname")
        .map(|s| s.trim().to_string())
        .ok()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "worker".into())
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
    worker_main(
        args.worker
            .options(args.coordinator, args.token, args.worlds),
    )
}

pub fn serve_policy(args: ServePolicyArgs) -> anyhow::Result<()> {
    let env = match args.world {
        Some(dir) => crm_run::Env::in_world(dir),
        None => crm_run::Env::default(),
    };
    let access = policy::Access::new(args.token, args.tls_cert.zip(args.tls_key))?;
    policy::serve_main(&args.checkpoint, &args.listen, &env, access)
}
