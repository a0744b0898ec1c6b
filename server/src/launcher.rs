//! Workers started through a cluster's batch system while jobs wait (`--launcher slurm`), as
//! dask-jobqueue and Ray's autoscaler grow a pool: every few seconds the coordinator counts the
//! jobs that want a worker (queued, and running ones, which hold theirs) and its own batch
//! jobs (`squeue --name`), and submits more with `sbatch` up to `--max-workers`. Each batch job
//! is `crm worker` with `--idle-exit-s`, so the pool shrinks by itself when the queue empties;
//! SIGTERM from `scancel` or a time limit makes a worker checkpoint and give its job back.
//! The token reaches workers in a file readable by its owner only, never on a command line.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};

use crate::AppState;

/// The batch systems the coordinator can start workers through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum LauncherKind {
    /// `sbatch`, `squeue` and `scancel` on this host (a login node).
    Slurm,
}

/// How the coordinator starts workers (`launch` in a config file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default, deny_unknown_fields)]
pub struct LaunchConfig {
    /// Start workers through this batch system while jobs wait (default: none; start
    /// `crm worker`s yourself).
    #[arg(long, value_enum)]
    pub launcher: Option<LauncherKind>,
    /// Most workers queued or running in the batch system at once.
    #[arg(long, default_value_t = 4)]
    pub max_workers: usize,
    /// The Slurm partition (`sbatch --partition`; default: the cluster's).
    #[arg(long)]
    pub slurm_partition: Option<String>,
    /// Each worker's time limit (`sbatch --time`, e.g. `02:00:00`); a worker gets SIGTERM
    /// 60 s before it and gives its job back.
    #[arg(long)]
    pub slurm_time: Option<String>,
    /// CPUs per worker (`sbatch --cpus-per-task`); the worker steps one environment per CPU
    /// when a job does not say.
    #[arg(long, default_value_t = 2)]
    pub slurm_cpus: u32,
    /// More `sbatch` options, one per flag (`--slurm-option=--account=lab`).
    #[arg(long = "slurm-option", value_name = "OPTION")]
    pub slurm_options: Vec<String>,
    /// The `crm` binary the workers run (default: `crm` beside this binary, or this one).
    #[arg(long, value_name = "FILE")]
    pub worker_command: Option<PathBuf>,
    /// The gRPC URL workers dial (default: the gRPC listener's address, or this host's name
    /// when it listens on every address).
    #[arg(long, value_name = "URL")]
    pub worker_coordinator: Option<String>,
    /// The CA certificate workers check a TLS coordinator against.
    #[arg(long, value_name = "FILE")]
    pub worker_ca: Option<PathBuf>,
    /// Seconds a worker waits without a job before it exits.
    #[arg(long, default_value_t = 60)]
    pub worker_idle_exit_s: u64,
    /// Seconds between the launcher's looks at the queue.
    #[arg(long, default_value_t = 5)]
    pub launch_every_s: u64,
}

impl Default for LaunchConfig {
    fn default() -> Self {
        Self {
            launcher: None,
            max_workers: 4,
            slurm_partition: None,
            slurm_time: None,
            slurm_cpus: 2,
            slurm_options: Vec::new(),
            worker_command: None,
            worker_coordinator: None,
            worker_ca: None,
            worker_idle_exit_s: 60,
            launch_every_s: 5,
        }
    }
}

/// What the launcher needs, resolved once at start.
pub struct Launcher {
    config: LaunchConfig,
    /// The batch jobs' name: unique to this coordinator's data folder.
    name: String,
    worker: PathBuf,
    coordinator: String,
    token_file: Option<PathBuf>,
    logs: PathBuf,
}

/// The default binary workers run: `crm` beside this binary (`crm-server`), else this one
/// (`crm up`).
fn worker_binary() -> anyhow::Result<PathBuf> {
    let me = std::env::current_exe().context("finding this binary")?;
    let sibling = me.with_file_name("crm");
    Ok(if sibling.is_file() { sibling } else { me })
}

/// This host's name from `/etc/hostname`, if it has one (workers name themselves by it, and
/// the launcher tells cluster workers to dial it).
pub fn host_name() -> Option<String> {
    std::fs::read_to_string("/etc/hostname")
        .map(|s| s.trim().to_string())
        .ok()
        .filter(|s| !s.is_empty())
}

impl Launcher {
    /// The launcher of `state`'s configuration (none without `--launcher`); `grpc` is the
    /// address the gRPC listener got.
    pub fn new(
        state: &AppState,
        grpc: std::net::SocketAddr,
        tls: bool,
    ) -> anyhow::Result<Option<Self>> {
        let config = state.config.launch.clone();
        if config.launcher.is_none() {
            return Ok(None);
        }
        if config.max_workers == 0 || config.slurm_cpus == 0 || config.launch_every_s == 0 {
            bail!("max_workers, slurm_cpus and launch_every_s must be at least 1");
        }
        let dir = state.config.data_dir.join("launcher");
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let token_file = match state.tokens.for_workers() {
            Some(token) => Some(write_secret(&dir.join("worker-token"), &token)?),
            None => None,
        };
        let scheme = if tls { "https" } else { "http" };
        // Bound to every address: workers dial this host by name; else the address it is.
        let host = if grpc.ip().is_unspecified() {
            host_name().unwrap_or_else(|| "localhost".into())
        } else {
            grpc.ip().to_string()
        };
        let coordinator = config
            .worker_coordinator
            .clone()
            .unwrap_or_else(|| format!("{scheme}://{host}:{}", grpc.port()));
        let worker = match &config.worker_command {
            Some(path) => path.clone(),
            None => worker_binary()?,
        };
        // One coordinator's workers apart from another's on the same cluster.
        let canonical = std::fs::canonicalize(&state.config.data_dir)
            .unwrap_or_else(|_| state.config.data_dir.clone());
        let digest = short_hash(canonical.to_string_lossy().as_bytes());
        Ok(Some(Self {
            config,
            name: format!("crm-worker-{digest}"),
            worker,
            coordinator,
            token_file,
            logs: dir,
        }))
    }

    /// The batch jobs' name (`squeue --name`).
    pub fn job_name(&self) -> &str {
        &self.name
    }

    /// This coordinator's batch jobs in the queue: (pending, running or ending).
    fn ours(&self) -> anyhow::Result<(usize, usize)> {
        let out = std::process::Command::new("squeue")
            .args(["--noheader", "--format=%t", "--name", &self.name])
            .output()
            .context("running squeue")?;
        if !out.status.success() {
            bail!("squeue: {}", String::from_utf8_lossy(&out.stderr).trim());
        }
        let states = String::from_utf8_lossy(&out.stdout);
        let pending = states.lines().filter(|s| s.trim() == "PD").count();
        let all = states.lines().filter(|s| !s.trim().is_empty()).count();
        Ok((pending, all - pending))
    }

    /// The `sbatch` arguments of one worker.
    fn sbatch_args(&self) -> Vec<String> {
        let c = &self.config;
        let mut args = vec![
            "--parsable".to_string(),
            format!("--job-name={}", self.name),
            format!("--cpus-per-task={}", c.slurm_cpus),
            format!("--output={}", self.logs.join("slurm-%j.out").display()),
        ];
        if let Some(partition) = &c.slurm_partition {
            args.push(format!("--partition={partition}"));
        }
        if let Some(time) = &c.slurm_time {
            args.push(format!("--time={time}"));
            // SIGTERM to the worker a minute before the limit: time to give its job back.
            args.push("--signal=B:TERM@60".into());
        }
        args.extend(c.slurm_options.iter().cloned());
        let mut worker = vec![
            self.worker.display().to_string(),
            "worker".into(),
            "--coordinator".into(),
            self.coordinator.clone(),
            "--idle-exit-s".into(),
            c.worker_idle_exit_s.to_string(),
            "--envs".into(),
            c.slurm_cpus.to_string(),
        ];
        if let Some(file) = &self.token_file {
            worker.extend(["--token-file".into(), file.display().to_string()]);
        }
        if let Some(ca) = &c.worker_ca {
            worker.extend(["--ca".into(), ca.display().to_string()]);
        }
        let words: Vec<String> = worker.iter().map(|w| shell_quote(w)).collect();
        args.push(format!("--wrap=exec {}", words.join(" ")));
        args
    }

    /// Submits one worker; returns its batch job id.
    fn submit(&self) -> anyhow::Result<String> {
        let out = std::process::Command::new("sbatch")
            .args(self.sbatch_args())
            .output()
            .context("running sbatch")?;
        if !out.status.success() {
            bail!("sbatch: {}", String::from_utf8_lossy(&out.stderr).trim());
        }
        Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
    }

    /// One look at the queue: submits the workers the waiting jobs want, up to the limit.
    async fn tick(&self, state: &AppState) -> anyhow::Result<usize> {
        let (queued, running) = state.store.open_jobs().await?;
        let wanted = (queued + running).min(self.config.max_workers as u64) as usize;
        let (pending, active) = self.ours()?;
        let missing = wanted.saturating_sub(pending + active);
        // Queued jobs beyond what idle running workers will take.
        let mut started = 0;
        for _ in 0..missing {
            let id = self.submit()?;
            tracing::info!(
                batch_job = id,
                name = self.name,
                "worker submitted to Slurm"
            );
            started += 1;
        }
        Ok(started)
    }

    /// Looks at the queue every `launch_every_s` until `stop`.
    pub async fn run(self, state: Arc<AppState>, stop: Arc<tokio::sync::Notify>) {
        let every = std::time::Duration::from_secs(self.config.launch_every_s);
        loop {
            if let Err(err) = self.tick(&state).await {
                tracing::error!(
                    err = format!("{err:#}"),
                    "the launcher could not start workers"
                );
            }
            tokio::select! {
                () = stop.notified() => return,
                () = tokio::time::sleep(every) => {}
            }
        }
    }
}

/// The first 8 hex digits of the SHA-256 of `bytes`.
pub fn short_hash(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .take(4)
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// `word` as a POSIX shell reads it back: as it is when it holds only safe characters, else
/// in single quotes.
pub fn shell_quote(word: &str) -> String {
    let safe = |c: char| c.is_ascii_alphanumeric() || "-_./=:,@+".contains(c);
    if !word.is_empty() && word.chars().all(safe) {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
    }
}

/// Writes `secret` to `path`, readable by its owner only.
fn write_secret(path: &Path, secret: &str) -> anyhow::Result<PathBuf> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)
        .with_context(|| format!("writing {}", path.display()))?;
    file.write_all(secret.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path.to_path_buf())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_workers_batch_job_carries_its_limits_and_no_secret() {
        let launcher = Launcher {
            config: LaunchConfig {
                launcher: Some(LauncherKind::Slurm),
                slurm_partition: Some("gpu".into()),
                slurm_time: Some("01:00:00".into()),
                slurm_options: vec!["--account=lab x".into()],
                ..LaunchConfig::default()
            },
            name: "crm-worker-abc".into(),
            worker: PathBuf::from("/opt/crm bin/crm"),
            coordinator: "https://login:50051".into(),
            token_file: Some(PathBuf::from("/data/launcher/worker-token")),
            logs: PathBuf::from("/data/launcher"),
        };
        let args = launcher.sbatch_args();
        for expected in [
            "--job-name=crm-worker-abc",
            "--cpus-per-task=2",
            "--partition=gpu",
            "--time=01:00:00",
            "--signal=B:TERM@60",
            "--account=lab x",
        ] {
            assert!(args.iter().any(|a| a == expected), "{expected} in {args:?}");
        }
        let wrap = args.last().expect("wrap");
        assert_eq!(
            wrap,
            "--wrap=exec '/opt/crm bin/crm' worker --coordinator https://login:50051 \
             --idle-exit-s 60 --envs 2 --token-file /data/launcher/worker-token"
        );
        assert_eq!(shell_quote("it's"), "'it'\\''s'");
    }
}
