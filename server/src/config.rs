//! The coordinator's settings, from flags or a JSON config file.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// Coordinator settings. Defaults: REST on 127.0.0.1:8080, gRPC on 127.0.0.1:50051, data in
/// `./data`, no token, the shipped models from `./models`.
#[derive(Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default, deny_unknown_fields)]
pub struct ServerConfig {
    /// Address of the REST API and dashboard.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: String,
    /// Address of the gRPC endpoint for workers.
    #[arg(long, default_value = "127.0.0.1:50051")]
    pub grpc: String,
    /// Folder of the sqlite file and the checkpoints (created if missing).
    #[arg(long, default_value = "data")]
    pub data_dir: PathBuf,
    /// Bearer token with every scope: reads, submissions and workers (docs/SECURITY.md). With
    /// any token set, only `/healthz` and the dashboard's pages answer without one.
    #[arg(long, env = "CRM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Bearer token that may read: every GET of the API, downloads, the event stream, the
    /// dashboard.
    #[arg(long, env = "CRM_READ_TOKEN", hide_env_values = true)]
    pub read_token: Option<String>,
    /// Bearer token that may submit (jobs, sweeps, uploads, cancels, deletes) and read.
    #[arg(long, env = "CRM_SUBMIT_TOKEN", hide_env_values = true)]
    pub submit_token: Option<String>,
    /// Bearer token of rollout workers (the gRPC Coordinator service).
    #[arg(long, env = "CRM_WORKER_TOKEN", hide_env_values = true)]
    pub worker_token: Option<String>,
    /// A JSON file of tokens, `{"token", "read", "submit", "worker"}` (any of them), for
    /// those the flags and variables leave unset; keeps them out of the process list.
    #[arg(long, value_name = "FILE")]
    pub tokens_file: Option<PathBuf>,
    /// REST requests one client address may make per second, on average; beyond its burst
    /// it is answered 429 with `Retry-After`. 0 turns the limit off. Default 50 (a dashboard
    /// page makes a few a second; nginx's `limit_req` examples use 1-10 per second).
    #[arg(long, default_value_t = 50)]
    pub rate_limit_per_s: u32,
    /// Requests a client address may make at once above its rate (the bucket's size).
    /// Default 200: a dashboard's first load and a burst of `crm results` calls.
    #[arg(long, default_value_t = 200)]
    pub rate_limit_burst: u32,
    /// PEM certificate chain of the coordinator: with `--tls-key`, both listeners (REST and
    /// gRPC) speak TLS only. `crm certs dev DIR` makes one to try.
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// PEM private key of `--tls-cert`.
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Seconds a lease lives without a heartbeat before the job is re-queued.
    #[arg(long, default_value_t = 30)]
    pub lease_ttl_s: u32,
    /// Seconds between worker heartbeats (told to workers when they register).
    #[arg(long, default_value_t = 5)]
    pub heartbeat_interval_s: u32,
    /// Largest REST request body, bytes.
    #[arg(long, default_value_t = 256 * 1024)]
    pub max_body_bytes: usize,
    /// REST requests served at once.
    #[arg(long, default_value_t = 256)]
    pub max_concurrent_requests: usize,
    /// Open REST connections; one beyond is answered 503 with `Retry-After` and closed.
    /// Default 512: twice the requests served at once, far under the descriptors a process
    /// gets (1,024 at the least), so accepting never fails for want of them.
    #[arg(long, default_value_t = 512)]
    pub max_connections: usize,
    /// Open connections from one client address, on each listener (nginx's `limit_conn` per
    /// address); one beyond is answered 503 and closed, so one client cannot hold every
    /// connection. Default 64: a browser opens at most 6 per host (Chromium's limit) and a
    /// worker one or two, with room for scripts and event streams.
    #[arg(long, default_value_t = 64)]
    pub max_connections_per_client: usize,
    /// Event streams (`GET /api/v1/events`) open at once; one beyond is answered 503 with
    /// `Retry-After`. Default 64: a page holds one, so 64 browser tabs.
    #[arg(long, default_value_t = 64)]
    pub max_event_streams: usize,
    /// Seconds a client has to send a request's headers (and a new connection its first
    /// byte, on both listeners). Default 10 (nginx's `client_header_timeout` is 60; a browser
    /// sends its headers at once).
    #[arg(long, default_value_t = 10)]
    pub header_timeout_s: u32,
    /// Seconds a REST connection may read and write nothing before it is closed. Default 60
    /// (nginx's `keepalive_timeout` is 75); an event stream writes a keep-alive every 15 s.
    #[arg(long, default_value_t = 60)]
    pub idle_timeout_s: u32,
    /// Largest checkpoint a worker may upload, bytes.
    #[arg(long, default_value_t = 256 * 1024 * 1024)]
    pub max_checkpoint_bytes: u64,
    /// Largest rerun recording one job may grow to, bytes.
    #[arg(long, default_value_t = 1024 * 1024 * 1024)]
    pub max_recording_bytes: u64,
    /// Episode summaries kept per job.
    #[arg(long, default_value_t = 200)]
    pub episodes_kept: u32,
    /// Checkpoints kept per job besides its final one (the newest; older ones are removed,
    /// file and row, unless an evaluation job names them).
    #[arg(long, default_value_t = 3)]
    pub keep_checkpoints: u32,
    /// Folder of shipped policy checkpoints registered, as uploads, when the coordinator
    /// starts on a new data folder (skipped when missing).
    #[arg(long, default_value = "models")]
    pub models: PathBuf,
    /// Most training jobs one sweep may create.
    #[arg(long, default_value_t = 200)]
    pub max_sweep_jobs: usize,
    /// A folder of world folders (each with a `world.json`) that jobs may name besides the
    /// built-in world; workers need the same folders (`crm worker --worlds`).
    #[arg(long, value_name = "DIR")]
    pub worlds: Option<PathBuf>,
    /// An MLflow tracking server (`http://HOST:PORT`) the workers log every training job to,
    /// as a run with its parameters, metrics, tags and final checkpoint, and each evaluation
    /// of its checkpoints into that run (the workers reach it, not the coordinator).
    #[arg(long, value_name = "URI")]
    pub mlflow_uri: Option<String>,
    /// The MLflow experiment of those runs (made when missing).
    #[arg(long, value_name = "NAME", default_value = "crm-grasp")]
    pub mlflow_experiment: String,
    /// Workers started through a batch system (`launch` in a config file).
    #[command(flatten)]
    pub launch: crate::launcher::LaunchConfig,
}

/// Debug without the tokens' values: a token shows as `<set>`, so a logged configuration
/// never carries a secret.
impl std::fmt::Debug for ServerConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServerConfig")
            .field("http", &self.http)
            .field("grpc", &self.grpc)
            .field("data_dir", &self.data_dir)
            .field("token", &self.token.as_ref().map(|_| "<set>"))
            .field("read_token", &self.read_token.as_ref().map(|_| "<set>"))
            .field("submit_token", &self.submit_token.as_ref().map(|_| "<set>"))
            .field("worker_token", &self.worker_token.as_ref().map(|_| "<set>"))
            .field("tokens_file", &self.tokens_file)
            .field("rate_limit_per_s", &self.rate_limit_per_s)
            .field("rate_limit_burst", &self.rate_limit_burst)
            .field("tls_cert", &self.tls_cert)
            .field("tls_key", &self.tls_key)
            .field("lease_ttl_s", &self.lease_ttl_s)
            .field("heartbeat_interval_s", &self.heartbeat_interval_s)
            .field("max_body_bytes", &self.max_body_bytes)
            .field("max_concurrent_requests", &self.max_concurrent_requests)
            .field("max_connections", &self.max_connections)
            .field(
                "max_connections_per_client",
                &self.max_connections_per_client,
            )
            .field("max_event_streams", &self.max_event_streams)
            .field("header_timeout_s", &self.header_timeout_s)
            .field("idle_timeout_s", &self.idle_timeout_s)
            .field("max_checkpoint_bytes", &self.max_checkpoint_bytes)
            .field("max_recording_bytes", &self.max_recording_bytes)
            .field("episodes_kept", &self.episodes_kept)
            .field("keep_checkpoints", &self.keep_checkpoints)
            .field("models", &self.models)
            .field("max_sweep_jobs", &self.max_sweep_jobs)
            .field("worlds", &self.worlds)
            .field("mlflow_uri", &self.mlflow_uri)
            .field("mlflow_experiment", &self.mlflow_experiment)
            .field("launch", &self.launch)
            .finish()
    }
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            http: "127.0.0.1:8080".into(),
            grpc: "127.0.0.1:50051".into(),
            data_dir: PathBuf::from("data"),
            token: None,
            read_token: None,
            submit_token: None,
            worker_token: None,
            tokens_file: None,
            rate_limit_per_s: 50,
            rate_limit_burst: 200,
            tls_cert: None,
            tls_key: None,
            lease_ttl_s: 30,
            heartbeat_interval_s: 5,
            max_body_bytes: 256 * 1024,
            max_concurrent_requests: 256,
            max_connections: 512,
            max_connections_per_client: 64,
            max_event_streams: 64,
            header_timeout_s: 10,
            idle_timeout_s: 60,
            max_checkpoint_bytes: 256 * 1024 * 1024,
            max_recording_bytes: 1024 * 1024 * 1024,
            episodes_kept: 200,
            keep_checkpoints: 3,
            models: PathBuf::from("models"),
            max_sweep_jobs: 200,
            worlds: None,
            mlflow_uri: None,
            mlflow_experiment: "crm-grasp".into(),
            launch: crate::launcher::LaunchConfig::default(),
        }
    }
}

impl ServerConfig {
    /// Refuses settings that cannot work, naming the setting.
    pub fn validate(&self) -> anyhow::Result<()> {
        if self.heartbeat_interval_s == 0 || self.lease_ttl_s <= self.heartbeat_interval_s {
            anyhow::bail!(
                "lease_ttl_s ({}) must exceed heartbeat_interval_s ({}), which must be positive",
                self.lease_ttl_s,
                self.heartbeat_interval_s
            );
        }
        if self.tls_cert.is_some() != self.tls_key.is_some() {
            anyhow::bail!("tls_cert and tls_key: give both or neither");
        }
        crate::auth::Tokens::configured(self)?;
        if self.keep_checkpoints == 0 {
            anyhow::bail!("keep_checkpoints: must be at least 1 (a job resumes from its newest)");
        }
        if let Some(uri) = &self.mlflow_uri
            && !(uri.starts_with("http://") || uri.starts_with("https://"))
        {
            anyhow::bail!(
                "mlflow_uri: {uri:?} is not an http:// or https:// URL of a tracking server"
            );
        }
        if self.mlflow_experiment.trim().is_empty() {
            anyhow::bail!("mlflow_experiment: must not be empty");
        }
        if self.max_body_bytes == 0 || self.max_concurrent_requests == 0 {
            anyhow::bail!("max_body_bytes and max_concurrent_requests must be positive");
        }
        Ok(())
    }
}

/// Reads settings from a JSON file; unknown keys are refused by name.
pub fn load(path: &std::path::Path) -> anyhow::Result<ServerConfig> {
    use anyhow::Context;
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::ServerConfig;

    #[test]
    fn debug_shows_no_token() {
        let config = ServerConfig {
            token: Some("every-s3cret".into()),
            worker_token: Some("w0rker-s3cret".into()),
            ..ServerConfig::default()
        };
        let shown = format!("{config:?}");
        assert!(!shown.contains("s3cret"), "{shown}");
        assert!(
            shown.contains("<set>") && shown.contains("read_token: None"),
            "{shown}"
        );
    }
}
