//! Helpers for the end-to-end tests: start the real binaries on free loopback ports with a
//! temporary data folder, a small HTTP client over `std::net`, and polling.

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// The `crm` binary of this package.
pub fn crm() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_crm"))
}

/// The coordinator's binary, built beside `crm` by `cargo test --workspace`.
pub fn crm_server() -> PathBuf {
    let path = crm().with_file_name(format!("crm-server{}", std::env::consts::EXE_SUFFIX));
    assert!(
        path.exists(),
        "{} is missing: run the tests with `cargo test --release --workspace`",
        path.display()
    );
    path
}

/// A temporary folder removed on drop.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(name: &str) -> Self {
        let path = std::env::temp_dir().join(format!(
            "crm-e2e-{name}-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos())
        ));
        std::fs::create_dir_all(&path).expect("temp dir");
        Self(path)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// A child process killed on drop.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        self.0.kill().ok();
        self.0.wait().ok();
    }
}

/// A running coordinator.
pub struct Server {
    pub proc: Proc,
    pub http: String,
    pub grpc: String,
}

/// Starts `crm-server` on free ports with `data` and extra flags; waits for its address line.
pub fn start_server(data: &Path, extra: &[&str]) -> Server {
    start_server_with(data, extra, &[])
}

/// [`start_server`] with environment variables set for the coordinator.
pub fn start_server_with(data: &Path, extra: &[&str], env: &[(&str, &Path)]) -> Server {
    let mut child = Command::new(crm_server())
        .envs(env.iter().copied())
        .args([
            "--http",
            "127.0.0.1:0",
            "--grpc",
            "127.0.0.1:0",
            "--data-dir",
        ])
        .arg(data)
        .args(extra)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start crm-server");
    let stdout = child.stdout.take().expect("stdout");
    let mut line = String::new();
    BufReader::new(stdout)
        .read_line(&mut line)
        .expect("address line");
    // "crm-server: REST http://ADDR/api/v1  gRPC http://ADDR"
    let words: Vec<&str> = line.split_whitespace().collect();
    let http = words
        .iter()
        .find(|w| w.ends_with("/api/v1"))
        .and_then(|w| {
            w.strip_prefix("http://")
                .or_else(|| w.strip_prefix("https://"))
        })
        .and_then(|w| w.strip_suffix("/api/v1"))
        .unwrap_or_else(|| panic!("no REST address in {line:?}"))
        .to_string();
    let grpc = words
        .last()
        .and_then(|w| {
            w.strip_prefix("http://")
                .or_else(|| w.strip_prefix("https://"))
        })
        .unwrap_or_else(|| panic!("no gRPC address in {line:?}"))
        .to_string();
    Server {
        proc: Proc(child),
        http,
        grpc,
    }
}

/// Starts `crm worker` against `grpc` with extra flags.
pub fn start_worker(grpc: &str, extra: &[&str]) -> Proc {
    start_worker_with(grpc, extra, &[])
}

/// [`start_worker`] with environment variables set for the worker.
pub fn start_worker_with(grpc: &str, extra: &[&str], env: &[(&str, &Path)]) -> Proc {
    Proc(
        Command::new(crm())
            .envs(env.iter().copied())
            .args(["worker", "--coordinator", grpc, "--poll-s", "0.2"])
            .args(extra)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start crm worker"),
    )
}

/// A response: status, header block and body.
pub struct Reply {
    pub status: u16,
    /// The status line and headers, as received.
    pub head: String,
    pub body: Vec<u8>,
}

impl Reply {
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "status {} body is not JSON ({e}): {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }

    /// A response header's value (names compare without case).
    pub fn header(&self, name: &str) -> Option<String> {
        self.head.lines().skip(1).find_map(|line| {
            let (key, value) = line.split_once(':')?;
            key.trim()
                .eq_ignore_ascii_case(name)
                .then(|| value.trim().to_string())
        })
    }
}

/// One HTTP/1.1 request with `Connection: close`.
pub fn http(
    addr: &str,
    method: &str,
    path: &str,
    body: Option<&str>,
    token: Option<&str>,
) -> Reply {
    let auth = token.map(|t| format!("Bearer {t}"));
    let headers: Vec<(&str, &str)> = auth.iter().map(|a| ("Authorization", a.as_str())).collect();
    try_http(addr, method, path, body, &headers).expect("HTTP request")
}

/// One HTTP/1.1 request with extra headers; an error where the connection fails (a
/// coordinator killed mid-request).
pub fn try_http(
    addr: &str,
    method: &str,
    path: &str,
    body: Option<&str>,
    headers: &[(&str, &str)],
) -> std::io::Result<Reply> {
    try_http_bytes(
        addr,
        method,
        path,
        body.unwrap_or("").as_bytes(),
        "application/json",
        headers,
    )
}

/// One HTTP/1.1 request with a body of any bytes. A server that answers before reading the
/// whole body (413) may close the connection while it is written: the answer is still read.
pub fn try_http_bytes(
    addr: &str,
    method: &str,
    path: &str,
    body: &[u8],
    content_type: &str,
    headers: &[(&str, &str)],
) -> std::io::Result<Reply> {
    let mut stream = TcpStream::connect(addr)?;
    stream.set_read_timeout(Some(Duration::from_secs(30)))?;
    let extra: String = headers
        .iter()
        .map(|(k, v)| format!("{k}: {v}\r\n"))
        .collect();
    write!(
        stream,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: {content_type}\r\n{extra}Content-Length: {}\r\n\r\n",
        body.len()
    )?;
    stream.write_all(body).ok();
    let mut raw = Vec::new();
    stream.read_to_end(&mut raw)?;
    let broken = || std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "no complete answer");
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(broken)?;
    let head = String::from_utf8_lossy(&raw[..split]).to_string();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .ok_or_else(broken)?;
    let mut body = raw[split + 4..].to_vec();
    if head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        body = dechunk(&body);
    }
    Ok(Reply { status, head, body })
}

fn dechunk(mut data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let Some(end) = data.windows(2).position(|w| w == b"\r\n") else {
            return out;
        };
        let size =
            usize::from_str_radix(String::from_utf8_lossy(&data[..end]).trim(), 16).unwrap_or(0);
        if size == 0 {
            return out;
        }
        out.extend_from_slice(&data[end + 2..end + 2 + size]);
        data = &data[end + 2 + size + 2..];
    }
}

/// The token the end-to-end tests start token-guarded coordinators with. Reads send it
/// always: a coordinator without tokens is open and ignores it.
pub const TOKEN: &str = "s3cret";

/// `GET path` (with [`TOKEN`]); any status but 200 fails the test.
pub fn get(addr: &str, path: &str) -> Value {
    let reply = http(addr, "GET", path, None, Some(TOKEN));
    assert_eq!(
        reply.status,
        200,
        "GET {path}: {}",
        String::from_utf8_lossy(&reply.body)
    );
    reply.json()
}

/// Polls `f` until it returns `Some`, or panics after `secs` with `what`.
pub fn wait_for<T>(secs: u64, what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        if let Some(value) = f() {
            return value;
        }
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The workers' names in a `GET /api/v1/workers` answer, in registration order.
pub fn worker_names(workers: &Value) -> Vec<&str> {
    workers["workers"]
        .as_array()
        .expect("workers")
        .iter()
        .filter_map(|w| w["name"].as_str())
        .collect()
}

/// An iteration's metrics without the fields that depend on the wall clock (`wall_s`,
/// `steps_per_s`): what two runs of the same seed share.
pub fn without_wall_clock(iteration: &Value) -> Value {
    let mut data = iteration.clone();
    if let Some(map) = data.as_object_mut() {
        map.remove("wall_s");
        map.remove("steps_per_s");
    }
    data
}

/// Waits until job `id` reaches `state`; fails early on another final state.
pub fn wait_state(addr: &str, id: i64, state: &str, secs: u64) -> Value {
    wait_for(secs, &format!("job {id} to be {state}"), || {
        let job = get(addr, &format!("/api/v1/jobs/{id}"));
        let now = job["state"].as_str().unwrap_or("").to_string();
        if now == state {
            return Some(job);
        }
        assert!(
            !["succeeded", "failed", "cancelled"].contains(&now.as_str()),
            "job {id} ended {now}, expected {state}: {job}"
        );
        None
    })
}

/// Submits a job (JSON text) and returns the stored job; any status but 201 fails the test.
/// POSTs `body` to `path` with no token and expects 201; returns the answer.
pub fn submit_to(addr: &str, path: &str, body: &str) -> Value {
    let reply = http(addr, "POST", path, Some(body), None);
    assert_eq!(
        reply.status,
        201,
        "{}",
        String::from_utf8_lossy(&reply.body)
    );
    reply.json()
}

pub fn submit(addr: &str, body: &str) -> Value {
    submit_as(addr, body, None)
}

/// [`submit`] with a bearer token.
pub fn submit_as(addr: &str, body: &str, token: Option<&str>) -> Value {
    let reply = http(addr, "POST", "/api/v1/jobs", Some(body), token);
    assert_eq!(
        reply.status,
        201,
        "{}",
        String::from_utf8_lossy(&reply.body)
    );
    reply.json()
}

/// A loopback port nothing listens on (bound, then freed).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// The status of `GET /api/v1/jobs/{id}/recording`.
pub fn recording_status(addr: &str, id: i64) -> u16 {
    http(
        addr,
        "GET",
        &format!("/api/v1/jobs/{id}/recording"),
        None,
        Some(TOKEN),
    )
    .status
}
