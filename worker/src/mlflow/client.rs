//! The calls of MLflow's REST API (`/api/2.0/mlflow`, served by `mlflow server` 2.x and 3.x)
//! that a run's logging needs: find or create the experiment, create the run, log batches of
//! parameters, metrics and tags, upload an artifact through the server's artifact proxy
//! (`/api/2.0/mlflow-artifacts`, on by default since MLflow 2.0), end the run. Each call is
//! one request; retrying is the caller's (`super::Logger`).

use std::time::Duration;

use anyhow::{Context, bail};
use serde_json::{Value, json};

/// One metric value as MLflow stores it.
#[derive(Clone, Debug, PartialEq)]
pub struct Metric {
    pub key: String,
    pub value: f64,
    pub step: u64,
    /// Milliseconds since the Unix epoch.
    pub timestamp: i64,
}

/// A request the server refused for what it asked (HTTP 4xx but 408 and 429): sending it
/// again will not change the answer.
#[derive(Debug)]
pub struct Refused(pub String);

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Refused {}

/// A tracking server at `base` (`http://HOST:PORT`).
pub struct Client {
    base: String,
    agent: ureq::Agent,
}

/// A run as the server made it.
#[derive(Clone, Debug)]
pub struct Run {
    pub run_id: String,
    /// Where its artifacts go (`mlflow-artifacts:/...` when the server proxies them).
    pub artifact_uri: String,
}

/// MLflow's limits per `log-batch` request.
pub const MAX_METRICS: usize = 1000;
pub const MAX_PARAMS: usize = 100;
pub const MAX_TAGS: usize = 100;

impl Client {
    /// A client of the server at `uri`; each request gives up after `timeout`.
    pub fn new(uri: &str, timeout: Duration) -> anyhow::Result<Self> {
        let base = uri.trim_end_matches('/').to_string();
        if !(base.starts_with("http://") || base.starts_with("https://")) {
            bail!("--mlflow-uri: {base:?} is not an http:// or https:// URL of a tracking server");
        }
        let config = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(timeout))
            .build();
        Ok(Self {
            base,
            agent: ureq::Agent::new_with_config(config),
        })
    }

    pub fn base(&self) -> &str {
        &self.base
    }

    /// One request; the answer's JSON, or an error quoting MLflow's `error_code` and message.
    fn call(&self, method: &str, path: &str, body: Option<(&str, &[u8])>) -> anyhow::Result<Value> {
        let url = format!("{}{path}", self.base);
        let result = match (method, body) {
            ("GET", _) => self.agent.get(&url).call(),
            ("PUT", Some((kind, bytes))) => self.agent.put(&url).content_type(kind).send(bytes),
            (_, body) => {
                let (kind, bytes) = body.unwrap_or(("application/json", b"{}"));
                self.agent.post(&url).content_type(kind).send(bytes)
            }
        };
        let mut response = result.with_context(|| format!("cannot reach {}", self.base))?;
        let status = response.status().as_u16();
        let text = response
            .body_mut()
            .read_to_string()
            .with_context(|| format!("reading the answer of {method} {path}"))?;
        let value: Value = if text.trim().is_empty() {
            json!({})
        } else {
            serde_json::from_str(&text).unwrap_or_else(|_| json!({ "message": text }))
        };
        if status >= 400 {
            let message = format!(
                "{method} {path}: {status} {} {}",
                value["error_code"].as_str().unwrap_or(""),
                value["message"].as_str().unwrap_or(&text)
            );
            if (400..500).contains(&status) && status != 408 && status != 429 {
                return Err(Refused(message).into());
            }
            bail!(message);
        }
        Ok(value)
    }

    fn post(&self, path: &str, body: &Value) -> anyhow::Result<Value> {
        let bytes = serde_json::to_vec(body)?;
        self.call(
            "POST",
            &format!("/api/2.0/mlflow/{path}"),
            Some(("application/json", &bytes)),
        )
    }

    /// The id of the experiment named `name`, made if there is none.
    pub fn experiment(&self, name: &str) -> anyhow::Result<String> {
        let query: String = name
            .bytes()
            .map(|b| match b {
                b'a'..=b'z' | b'A'..=b'Z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => {
                    (b as char).to_string()
                }
                other => format!("%{other:02X}"),
            })
            .collect();
        let path = format!("/api/2.0/mlflow/experiments/get-by-name?experiment_name={query}");
        match self.call("GET", &path, None) {
            Ok(found) => found["experiment"]["experiment_id"]
                .as_str()
                .map(str::to_string)
                .context("get-by-name answered without an experiment id"),
            Err(err) if err.to_string().contains("RESOURCE_DOES_NOT_EXIST") => {
                match self.post("experiments/create", &json!({ "name": name })) {
                    Ok(made) => made["experiment_id"]
                        .as_str()
                        .map(str::to_string)
                        .context("experiments/create answered without an id"),
                    // Another run made it meanwhile.
                    Err(err) if err.to_string().contains("RESOURCE_ALREADY_EXISTS") => {
                        let found = self.call("GET", &path, None)?;
                        found["experiment"]["experiment_id"]
                            .as_str()
                            .map(str::to_string)
                            .context("get-by-name answered without an experiment id")
                    }
                    Err(err) => Err(err),
                }
            }
            Err(err) => Err(err),
        }
    }

    /// Starts a run in `experiment_id` named `name` with `tags`.
    pub fn create_run(
        &self,
        experiment_id: &str,
        name: &str,
        start_ms: i64,
        tags: &[(String, String)],
    ) -> anyhow::Result<Run> {
        let tags: Vec<Value> = tags
            .iter()
            .map(|(k, v)| json!({ "key": k, "value": v }))
            .collect();
        let made = self.post(
            "runs/create",
            &json!({
                "experiment_id": experiment_id,
                "run_name": name,
                "start_time": start_ms,
                "tags": tags,
            }),
        )?;
        let info = &made["run"]["info"];
        Ok(Run {
            run_id: info["run_id"]
                .as_str()
                .context("runs/create answered without a run id")?
                .to_string(),
            artifact_uri: info["artifact_uri"]
                .as_str()
                .unwrap_or_default()
                .to_string(),
        })
    }

    /// The newest run of `experiment_id` whose tag `key` is `value`, if there is one.
    pub fn find_run(
        &self,
        experiment_id: &str,
        key: &str,
        value: &str,
    ) -> anyhow::Result<Option<Run>> {
        let found = self.post(
            "runs/search",
            &json!({
                "experiment_ids": [experiment_id],
                "filter": format!("tags.`{key}` = '{}'", value.replace('\'', "")),
                "max_results": 1,
                "order_by": ["attributes.start_time DESC"],
            }),
        )?;
        Ok(found["runs"]
            .as_array()
            .and_then(|runs| runs.first())
            .and_then(|run| {
                let info = &run["info"];
                Some(Run {
                    run_id: info["run_id"].as_str()?.to_string(),
                    artifact_uri: info["artifact_uri"]
                        .as_str()
                        .unwrap_or_default()
                        .to_string(),
                })
            }))
    }

    /// Logs parameters, metrics and tags in one request (within MLflow's limits per request).
    pub fn log_batch(
        &self,
        run_id: &str,
        params: &[(String, String)],
        metrics: &[Metric],
        tags: &[(String, String)],
    ) -> anyhow::Result<()> {
        let pairs = |list: &[(String, String)]| -> Vec<Value> {
            list.iter()
                .map(|(k, v)| json!({ "key": k, "value": v }))
                .collect()
        };
        let metrics: Vec<Value> = metrics
            .iter()
            .map(|m| {
                json!({ "key": m.key, "value": m.value, "timestamp": m.timestamp, "step": m.step })
            })
            .collect();
        self.post(
            "runs/log-batch",
            &json!({
                "run_id": run_id,
                "params": pairs(params),
                "metrics": metrics,
                "tags": pairs(tags),
            }),
        )?;
        Ok(())
    }

    /// Uploads `bytes` as the run's artifact `name` through the server's artifact proxy.
    pub fn upload_artifact(&self, run: &Run, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
        let Some(path) = run.artifact_uri.strip_prefix("mlflow-artifacts:") else {
            bail!(
                "the server keeps this run's artifacts at {:?}, not behind its artifact proxy \
                 (start it with --serve-artifacts): {name} is not uploaded",
                run.artifact_uri
            );
        };
        let path = path.trim_start_matches('/');
        self.call(
            "PUT",
            &format!("/api/2.0/mlflow-artifacts/artifacts/{path}/{name}"),
            Some(("application/octet-stream", bytes)),
        )?;
        Ok(())
    }

    /// Sets the run's `status` (`RUNNING`, or at its end `FINISHED`, `FAILED`, `KILLED` with
    /// `end_ms`).
    pub fn set_status(
        &self,
        run_id: &str,
        status: &str,
        end_ms: Option<i64>,
    ) -> anyhow::Result<()> {
        let mut body = json!({ "run_id": run_id, "status": status });
        if let Some(end) = end_ms {
            body["end_time"] = json!(end);
        }
        self.post("runs/update", &body)?;
        Ok(())
    }
}
