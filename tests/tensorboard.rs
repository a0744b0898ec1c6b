//! TensorBoard event files, read back with TensorBoard's own reader (the `tensorboard`
//! package's EventAccumulator, `scripts/tensorboard-scalars.py`, in the venv scripts/test
//! makes): `crm train` writes one beside `metrics.jsonl`, the coordinator serves one per
//! training job, and each holds every series of every iteration with the logged values and the
//! run's settings as text and as TensorBoard hyperparameters.

mod support;

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use support::*;

fn read_back(folder: &Path) -> Value {
    let Ok(python) = std::env::var("CRM_TENSORBOARD_PYTHON") else {
        panic!(
            "CRM_TENSORBOARD_PYTHON is not set: scripts/test installs tensorboard into a venv \
             under ~/.cache and sets it; run the suite with scripts/test"
        );
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/tensorboard-scalars.py");
    let out = Command::new(python)
        .arg(script)
        .arg(folder)
        .output()
        .expect("python");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

/// Every scalar of every iteration is in the file at its step, with its value as a float32.
fn check(read: &Value, iterations: &[crm_api::Iteration]) {
    assert!(!iterations.is_empty());
    let mut checked = 0;
    for it in iterations {
        for (tag, value) in crm_api::tensorboard::scalars(it) {
            let series = read["scalars"][&tag]
                .as_array()
                .unwrap_or_else(|| panic!("no series {tag}"));
            let found = series
                .iter()
                .find(|p| p[0].as_u64() == Some(it.steps))
                .unwrap_or_else(|| panic!("{tag} has no value at step {}", it.steps));
            assert_eq!(
                found[1].as_f64(),
                Some(f64::from(value as f32)),
                "{tag} at step {}",
                it.steps
            );
            checked += 1;
        }
    }
    assert!(checked >= 14 * iterations.len(), "{checked} values");
    let settings = read["texts"]["settings"]
        .as_str()
        .expect("the settings as text");
    assert!(
        settings.contains("\"algorithm\": \"crm-ppo\""),
        "{settings}"
    );
    // The settings as hyperparameters, typed, under dotted keys.
    let hparams = &read["hparams"];
    assert_eq!(hparams["algorithm"], "crm-ppo", "{hparams}");
    assert_eq!(hparams["config.rollout_steps"], 512.0, "{hparams}");
    assert_eq!(hparams["steps"], 2048.0, "{hparams}");
    assert_eq!(hparams["config.norm_obs"], true, "{hparams}");
}

#[test]
fn training_runs_write_event_files_tensorboard_reads() {
    let dir = TempDir::new("tensorboard");
    let config = dir.0.join("ppo.json");
    std::fs::write(&config, r#"{"rollout_steps": 512, "minibatch_size": 128}"#).expect("config");
    let out = dir.0.join("run");
    let ran = Command::new(crm())
        .args([
            "train",
            "--algo",
            "crm-ppo",
            "--task",
            "mouse-press",
            "--steps",
            "2048",
        ])
        .args(["--envs", "1", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("crm train");
    assert!(
        ran.status.success(),
        "{}",
        String::from_utf8_lossy(&ran.stderr)
    );
    let logged: Vec<crm_api::Iteration> = std::fs::read_to_string(out.join("metrics.jsonl"))
        .expect("metrics.jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).expect("an iteration"))
        .collect();
    assert_eq!(logged.len(), 4);
    check(&read_back(&out), &logged);

    // The coordinator's copy of a worker's run.
    let server = start_server(&dir.0.join("data"), &[]);
    let addr = server.http.clone();
    let _worker = start_worker(&format!("http://{}", server.grpc), &[]);
    let job = submit(
        &addr,
        r#"{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 2048, "envs": 1, "config": {"rollout_steps": 512, "minibatch_size": 128}}"#,
    );
    let id = job["id"].as_i64().expect("id");
    wait_state(&addr, id, "succeeded", 240);
    let file = http(
        &addr,
        "GET",
        &format!("/api/v1/jobs/{id}/tensorboard"),
        None,
        None,
    );
    assert_eq!(file.status, 200);
    assert!(
        file.header("content-disposition")
            .is_some_and(|d| d.contains("events.out.tfevents.")),
        "{}",
        file.head
    );
    let folder = dir.0.join("downloaded");
    std::fs::create_dir_all(&folder).expect("folder");
    std::fs::write(folder.join("events.out.tfevents.job"), &file.body).expect("write");
    let stored: Vec<crm_api::Iteration> =
        get(&addr, &format!("/api/v1/runs/{id}/metrics"))["metrics"]
            .as_array()
            .expect("metrics")
            .iter()
            .map(|m| serde_json::from_value(m["data"].clone()).expect("an iteration"))
            .collect();
    assert_eq!(stored.len(), 4);
    check(&read_back(&folder), &stored);
    // A job that is not there is 404, naming it.
    let missing = http(&addr, "GET", "/api/v1/jobs/999/tensorboard", None, None);
    assert_eq!(missing.status, 404);
}
