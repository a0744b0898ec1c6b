//! Runs logged to a real MLflow tracking server (`mlflow server` from PyPI, a sqlite store, on
//! loopback; scripts/test installs it into a venv and sets `CRM_MLFLOW_PYTHON`), read back with
//! MLflow's own client (`scripts/mlflow-run.py`): `crm train --mlflow-uri` logs the job's
//! settings as parameters, every series of every iteration by step, its tags and the final
//! checkpoint. The server is started only after the run has found it down: training goes on,
//! and what waited in the queue reaches the server once it answers. A resumed run goes on in
//! the same MLflow run.

mod support;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;
use support::*;

fn python() -> String {
    std::env::var("CRM_MLFLOW_PYTHON").unwrap_or_else(|_| {
        panic!(
            "CRM_MLFLOW_PYTHON is not set: scripts/test installs mlflow into a venv under \
             ~/.cache and sets it; run the suite with scripts/test"
        )
    })
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("bind")
        .local_addr()
        .expect("addr")
        .port()
}

/// A running `mlflow server`: its own process group (uvicorn, the job runner and its
/// consumers are children of the command), all of it killed when dropped.
struct MlflowServer(std::process::Child);

impl Drop for MlflowServer {
    fn drop(&mut self) {
        let group = format!("-{}", self.0.id());
        Command::new("kill")
            .args(["-KILL", "--", &group])
            .status()
            .ok();
        self.0.wait().ok();
    }
}

/// `mlflow server` on `port` with its store and artifacts under `dir`.
fn start_mlflow(dir: &Path, port: u16) -> MlflowServer {
    use std::os::unix::process::CommandExt;
    let store = format!("sqlite:///{}", dir.join("mlflow.db").display());
    let proc = MlflowServer(
        Command::new(python())
            .process_group(0)
            .args(["-m", "mlflow", "server", "--backend-store-uri", &store])
            .arg("--artifacts-destination")
            .arg(dir.join("artifacts"))
            .args(["--host", "127.0.0.1", "--port", &port.to_string()])
            .args(["--workers", "1"])
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(dir.join("mlflow.log")).expect("log"))
            .spawn()
            .expect("mlflow server"),
    );
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "mlflow server did not listen within 120 s: {}",
            std::fs::read_to_string(dir.join("mlflow.log")).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    proc
}

fn read_back(uri: &str, experiment: &str, download: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/mlflow-run.py");
    let out = Command::new(python())
        .arg(script)
        .args([uri, experiment])
        .arg(download)
        .output()
        .expect("python");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

#[test]
fn a_training_run_logs_to_mlflow_even_when_the_server_comes_up_late() {
    let dir = TempDir::new("mlflow");
    let config = dir.0.join("ppo.json");
    std::fs::write(&config, r#"{"rollout_steps": 512, "minibatch_size": 128}"#).expect("config");
    let port = free_port();
    let uri = format!("http://127.0.0.1:{port}");
    let out = dir.0.join("run");
    let log = dir.0.join("train.log");
    let mut train = Proc(
        Command::new(crm())
            .args(["train", "--algo", "crm-ppo", "--task", "mouse-press"])
            .args(["--steps", "2048", "--envs", "1", "--seed", "7", "--config"])
            .arg(&config)
            .arg("--out")
            .arg(&out)
            .args(["--mlflow-uri", &uri, "--mlflow-experiment", "crm-test"])
            .args(["--mlflow-run-name", "late-server", "--mlflow-wait-s", "180"])
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).expect("log"))
            .spawn()
            .expect("crm train"),
    );
    // The run finds the server down, says so and trains on.
    wait_for(60, "the report of a server that is down", || {
        std::fs::read_to_string(&log)
            .unwrap_or_default()
            .contains("logging to http")
            .then_some(())
    });
    let server_dir = dir.0.join("server");
    std::fs::create_dir_all(&server_dir).expect("dir");
    let _server = start_mlflow(&server_dir, port);
    let started = Instant::now();
    let status = loop {
        if let Some(status) = train.0.try_wait().expect("wait") {
            break status;
        }
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "crm train hangs"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let stderr = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(status.success(), "{stderr}");
    assert!(stderr.contains("answers again"), "{stderr}");
    assert!(stderr.contains("logged to MLflow as run"), "{stderr}");

    let download = dir.0.join("download");
    std::fs::create_dir_all(&download).expect("dir");
    let run = read_back(&uri, "crm-test", &download);
    assert_eq!(run["status"], "FINISHED", "{run}");
    assert_eq!(run["tags"]["mlflow.runName"], "late-server");
    assert_eq!(run["tags"]["crm.algorithm"], "crm-ppo");
    assert_eq!(run["tags"]["crm.seed"], "7");
    assert_eq!(run["tags"]["crm.world"], "crm");
    assert!(
        run["tags"]["crm.world_hash"]
            .as_str()
            .is_some_and(|h| !h.is_empty())
    );
    let lineage: Value =
        serde_json::from_str(run["tags"]["crm.lineage"].as_str().expect("lineage")).expect("json");
    assert_eq!(lineage[0]["kind"], "train", "{lineage}");
    assert_eq!(run["params"]["algorithm"], "crm-ppo");
    assert_eq!(run["params"]["config.rollout_steps"], "512");
    assert_eq!(run["params"]["steps"], "2048");
    // Every series of every iteration, at its step, with the logged value.
    let logged: Vec<crm_api::Iteration> = std::fs::read_to_string(out.join("metrics.jsonl"))
        .expect("metrics.jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).expect("an iteration"))
        .collect();
    assert_eq!(logged.len(), 4);
    let mut checked = 0;
    for it in &logged {
        for (key, value) in crm_api::tensorboard::scalars(it) {
            let series = run["metrics"][&key]
                .as_array()
                .unwrap_or_else(|| panic!("no metric {key}"));
            let found = series
                .iter()
                .find(|p| p[0].as_u64() == Some(it.steps))
                .unwrap_or_else(|| panic!("{key} has no value at step {}", it.steps));
            assert_eq!(found[1].as_f64(), Some(value), "{key} at step {}", it.steps);
            checked += 1;
        }
    }
    assert!(checked >= 14 * logged.len(), "{checked} values");
    // The final checkpoint and the job's document, byte for byte.
    let artifacts: Vec<&str> = run["artifacts"]
        .as_array()
        .expect("artifacts")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    assert!(artifacts.contains(&"crm-ppo.safetensors"), "{artifacts:?}");
    assert_eq!(
        std::fs::read(download.join("crm-ppo.safetensors")).expect("downloaded"),
        std::fs::read(out.join("crm-ppo.safetensors")).expect("checkpoint")
    );
    let job: Value =
        serde_json::from_slice(&std::fs::read(download.join("job.json")).expect("job.json"))
            .expect("json");
    assert_eq!(job["steps"], 2048);

    // Resumed to more steps, the run goes on in the same MLflow run (its --out folder's).
    let resumed = Command::new(crm())
        .args(["train", "--algo", "crm-ppo", "--task", "mouse-press"])
        .args(["--steps", "3072", "--envs", "1", "--seed", "7", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .arg("--resume")
        .arg(out.join("crm-ppo.safetensors"))
        .args(["--mlflow-uri", &uri, "--mlflow-experiment", "crm-test"])
        .output()
        .expect("crm train --resume");
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    let again = dir.0.join("download-again");
    std::fs::create_dir_all(&again).expect("dir");
    let run_again = read_back(&uri, "crm-test", &again);
    assert_eq!(run_again["run_id"], run["run_id"], "one run");
    assert_eq!(run_again["status"], "FINISHED");
    let steps: Vec<u64> = run_again["metrics"]["train/episodes"]
        .as_array()
        .expect("series")
        .iter()
        .filter_map(|p| p[0].as_u64())
        .collect();
    assert_eq!(steps, [512, 1024, 1536, 2048, 2560, 3072]);
}

#[test]
fn a_server_that_never_answers_never_fails_the_run() {
    let dir = TempDir::new("mlflow-down");
    let config = dir.0.join("ppo.json");
    std::fs::write(&config, r#"{"rollout_steps": 512, "minibatch_size": 128}"#).expect("config");
    let uri = format!("http://127.0.0.1:{}", free_port());
    let out = dir.0.join("run");
    let ran = Command::new(crm())
        .args(["train", "--algo", "crm-ppo", "--task", "mouse-press"])
        .args(["--steps", "1024", "--envs", "1", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .args(["--mlflow-uri", &uri, "--mlflow-wait-s", "1"])
        .output()
        .expect("crm train");
    let stderr = String::from_utf8_lossy(&ran.stderr);
    assert!(ran.status.success(), "{stderr}");
    assert!(out.join("crm-ppo.safetensors").is_file());
    assert!(
        stderr.contains(&format!("logging to {uri} is retried")),
        "{stderr}"
    );
    assert!(
        stderr.contains("did not take the run's last records"),
        "{stderr}"
    );
    // A URI that is no URL is refused before training, naming the flag.
    let refused = Command::new(crm())
        .args(["train", "--steps", "512", "--out"])
        .arg(dir.0.join("refused"))
        .args(["--mlflow-uri", "localhost:5000"])
        .output()
        .expect("crm train");
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("--mlflow-uri"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
}

/// `crm-server --mlflow-uri`: its workers log each training job as a run (found again by its
/// tag on a new lease) and each evaluation of the job's checkpoint into that run.
#[test]
fn a_coordinators_jobs_and_their_evaluations_log_to_its_mlflow_server() {
    let dir = TempDir::new("mlflow-service");
    let port = free_port();
    let uri = format!("http://127.0.0.1:{port}");
    let server_dir = dir.0.join("mlflow");
    std::fs::create_dir_all(&server_dir).expect("dir");
    let _mlflow = start_mlflow(&server_dir, port);
    let server = start_server(
        &dir.0.join("data"),
        &["--mlflow-uri", &uri, "--mlflow-experiment", "crm-jobs"],
    );
    let addr = server.http.clone();
    let _worker = start_worker(&format!("http://{}", server.grpc), &[]);
    let id = submit(
        &addr,
        r#"{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 2048, "seed": 3, "envs": 1, "config": {"rollout_steps": 512, "minibatch_size": 128}}"#,
    )["id"]
        .as_i64()
        .expect("id");
    let done = wait_state(&addr, id, "succeeded", 300);
    let checkpoint = done["result"]["checkpoint_id"]
        .as_i64()
        .expect("checkpoint");
    let eval = submit(
        &addr,
        &format!(
            r#"{{"kind": "eval", "checkpoint_id": {checkpoint}, "episodes": 6, "tasks": ["mouse-press"]}}"#
        ),
    )["id"]
        .as_i64()
        .expect("id");
    let evaluated = wait_state(&addr, eval, "succeeded", 300);

    let download = dir.0.join("download");
    std::fs::create_dir_all(&download).expect("dir");
    let run = read_back(&uri, "crm-jobs", &download);
    assert_eq!(run["status"], "FINISHED", "{run}");
    assert_eq!(run["tags"]["mlflow.runName"], format!("job-{id}"));
    assert!(
        run["tags"]["crm.job"]
            .as_str()
            .is_some_and(|t| t.ends_with(&format!("/{id}"))),
        "{run}"
    );
    assert_eq!(run["tags"]["crm.eval.sampled.job"], eval.to_string());
    let stored: Vec<crm_api::Iteration> =
        get(&addr, &format!("/api/v1/runs/{id}/metrics"))["metrics"]
            .as_array()
            .expect("metrics")
            .iter()
            .map(|m| serde_json::from_value(m["data"].clone()).expect("an iteration"))
            .collect();
    assert_eq!(stored.len(), 4);
    for it in &stored {
        for (key, value) in crm_api::tensorboard::scalars(it) {
            let found = run["metrics"][&key]
                .as_array()
                .and_then(|s| s.iter().find(|p| p[0].as_u64() == Some(it.steps)))
                .unwrap_or_else(|| panic!("{key} at step {}", it.steps));
            assert_eq!(found[1].as_f64(), Some(value), "{key} at step {}", it.steps);
        }
    }
    let success = &run["metrics"]["eval/sampled/success_rate"][0];
    assert_eq!(success[0], 2048);
    assert_eq!(success[1], evaluated["result"]["success_rate"]);
    let file = http(
        &addr,
        "GET",
        &format!("/api/v1/checkpoints/{checkpoint}/download"),
        None,
        None,
    );
    assert_eq!(
        std::fs::read(download.join("checkpoint.safetensors")).expect("artifact"),
        file.body
    );
}
