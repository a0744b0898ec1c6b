//! A small client of the coordinator's REST API for commands that run on a coordinator
//! instead of here (`crm eval --coordinator URL`, `crm results`): upload a checkpoint, submit
//! a job or a sweep, wait for it, read resources. Errors name the address and carry the API's own message and field.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use serde_json::Value;

/// The coordinator's REST API at `base` (`http://HOST:PORT`), with an optional token.
pub struct Rest {
    base: String,
    token: Option<String>,
    agent: ureq::Agent,
}

impl Rest {
    /// A client of the API at `base`; an `https://` one is checked against `ca` (a PEM file)
    /// or, without it, the built-in web roots.
    pub fn new(base: &str, token: Option<String>, ca: Option<&Path>) -> anyhow::Result<Self> {
        let base = base.trim_end_matches('/').to_string();
        if !(base.starts_with("http://") || base.starts_with("https://")) {
            bail!("--coordinator: {base:?} is not an http:// URL of the coordinator's REST API");
        }
        let mut config = ureq::Agent::config_builder();
        if let Some(path) = ca {
            let pem = std::fs::read(path)
                .with_context(|| format!("--ca {}: cannot read it", path.display()))?;
            let certs = ureq::tls::parse_pem(&pem)
                .filter_map(|item| match item {
                    Ok(ureq::tls::PemItem::Certificate(cert)) => Some(cert),
                    _ => None,
                })
                .collect::<Vec<_>>();
            if certs.is_empty() {
                bail!("--ca {}: no PEM certificate in it", path.display());
            }
            let roots = ureq::tls::RootCerts::new_with_certs(&certs);
            config = config.tls_config(ureq::tls::TlsConfig::builder().root_certs(roots).build());
        }
        let config = config
            .http_status_as_error(false)
            .timeout_global(Some(Duration::from_secs(120)))
            .build();
        Ok(Self {
            base,
            token,
            agent: ureq::Agent::new_with_config(config),
        })
    }

    /// Sends a request and returns `(status, JSON body)`; an API error becomes an error that
    /// quotes its field and message.
    fn call(&self, method: &str, path: &str, body: Option<(&str, &[u8])>) -> anyhow::Result<Value> {
        let url = format!("{}{path}", self.base);
        let auth = self.token.as_ref().map(|t| format!("Bearer {t}"));
        let result = match (method, body) {
            ("GET", _) => {
                let mut request = self.agent.get(&url);
                if let Some(auth) = &auth {
                    request = request.header("authorization", auth);
                }
                request.call()
            }
            (_, body) => {
                let mut request = self.agent.post(&url);
                if let Some(auth) = &auth {
                    request = request.header("authorization", auth);
                }
                let (kind, bytes) = body.unwrap_or(("application/json", b"{}"));
                request.content_type(kind).send(bytes)
            }
        };
        let mut response =
            result.with_context(|| format!("cannot reach the coordinator at {}", self.base))?;
        let status = response.status().as_u16();
        let text = response
            .body_mut()
            .with_config()
            .limit(64 << 20)
            .read_to_string()
            .with_context(|| format!("reading the answer of {method} {url}"))?;
        let value: Value = serde_json::from_str(&text)
            .with_context(|| format!("{method} {url}: answered {status} with no JSON"))?;
        if status >= 400 {
            let error = &value["error"];
            let field = error["field"]
                .as_str()
                .map(|f| format!("{f}: "))
                .unwrap_or_default();
            bail!(
                "{method} {path}: {status} {field}{}",
                error["message"].as_str().unwrap_or(&text)
            );
        }
        Ok(value)
    }

    /// Uploads a checkpoint file (or finds the same bytes uploaded before); returns its id.
    pub fn upload_checkpoint(&self, path: &Path) -> anyhow::Result<i64> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        let query: String = name
            .bytes()
            .map(|b| match b {
                b'a'..=b'z' | b'A'..=b'Z' | b'0'..=b'9' | b'-' | b'_' | b'.' => {
                    (b as char).to_string()
                }
                other => format!("%{other:02X}"),
            })
            .collect();
        let row = self.call(
            "POST",
            &format!("/api/v1/checkpoints?name={query}"),
            Some(("application/octet-stream", &bytes)),
        )?;
        row["id"]
            .as_i64()
            .context("the coordinator's answer has no checkpoint id")
    }

    /// Queues a job; returns its id.
    pub fn submit(&self, job: &Value) -> anyhow::Result<i64> {
        let job = self.post_json("/api/v1/jobs", job)?;
        job["id"]
            .as_i64()
            .context("the coordinator's answer has no job id")
    }

    /// POSTs a JSON body; returns the answer.
    pub fn post_json(&self, path: &str, body: &Value) -> anyhow::Result<Value> {
        let body = serde_json::to_vec(body)?;
        self.call("POST", path, Some(("application/json", &body)))
    }

    /// GETs a JSON resource.
    pub fn get(&self, path: &str) -> anyhow::Result<Value> {
        self.call("GET", path, None)
    }

    /// GETs a file's bytes (a checkpoint's download); an error status quotes the API's
    /// message.
    pub fn get_bytes(&self, path: &str) -> anyhow::Result<Vec<u8>> {
        let url = format!("{}{path}", self.base);
        let mut request = self.agent.get(&url);
        if let Some(token) = &self.token {
            request = request.header("authorization", format!("Bearer {token}"));
        }
        let mut response = request
            .call()
            .with_context(|| format!("cannot reach the coordinator at {}", self.base))?;
        let status = response.status().as_u16();
        let bytes = response
            .body_mut()
            .with_config()
            .limit(1 << 30)
            .read_to_vec()
            .with_context(|| format!("reading the answer of GET {url}"))?;
        if status >= 400 {
            let value: Value = serde_json::from_slice(&bytes).unwrap_or_default();
            bail!(
                "GET {path}: {status} {}",
                value["error"]["message"].as_str().unwrap_or("no message")
            );
        }
        Ok(bytes)
    }

    /// Waits for a job to finish, calling `progress` with its progress (0 to 1) as it
    /// changes; returns the job when it succeeded, an error with its message otherwise.
    pub fn wait(&self, id: i64, mut progress: impl FnMut(f64)) -> anyhow::Result<Value> {
        let started = Instant::now();
        loop {
            let job = self.get(&format!("/api/v1/jobs/{id}"))?;
            progress(job["progress"].as_f64().unwrap_or(0.0));
            match job["state"].as_str() {
                Some("succeeded") => return Ok(job),
                Some("failed") => bail!(
                    "job {id} failed: {}",
                    job["error"].as_str().unwrap_or("no message")
                ),
                Some("cancelled") => bail!("job {id} was cancelled"),
                _ => {}
            }
            // Short polls first (small jobs), then once a second.
            let pause = if started.elapsed() < Duration::from_secs(5) {
                200
            } else {
                1000
            };
            std::thread::sleep(Duration::from_millis(pause));
        }
    }
}
