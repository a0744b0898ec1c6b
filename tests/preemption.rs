//! Workers that a cluster can start and stop: SIGTERM ends a training job at the iteration's
//! end with a checkpoint and gives it back at once (no lease to wait out), the worker exits 0,
//! and the next worker's resumed run is the same run as one never interrupted; `--max-jobs`,
//! `--idle-exit-s` and a name from the scheduler's environment.

mod support;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;
use support::*;

/// A job long enough to be stopped midway (the early stop cannot end it first).
const TRAIN: &str = r#"{"kind": "train", "algorithm": "crm-ppo", "tasks": ["mouse-press", "mug-wrap"], "steps": 6144, "seed": 5, "envs": 2, "curriculum": true, "config": {"rollout_steps": 512, "minibatch_size": 128, "early_stop_window": 1000000}}"#;

/// A run's metrics without their wall-clock fields.
fn metrics(addr: &str, id: i64) -> Vec<Value> {
    get(addr, &format!("/api/v1/runs/{id}/metrics"))["metrics"]
        .as_array()
        .expect("metrics")
        .iter()
        .map(|m| without_wall_clock(&m["data"]))
        .collect()
}

fn exit_within(proc: &mut Proc, secs: u64) -> std::process::ExitStatus {
    let started = Instant::now();
    loop {
        if let Some(status) = proc.0.try_wait().expect("wait") {
            return status;
        }
        assert!(
            started.elapsed() < Duration::from_secs(secs),
            "the worker did not exit within {secs} s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_preempted_workers_job_is_given_back_and_resumed_as_the_same_run() {
    let data = TempDir::new("preempt");
    // The default lease of 30 s: a job given back is queued long before it would expire.
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();
    let grpc = format!("http://{}", server.grpc);
    let mut first = start_worker(&grpc, &["--checkpoint-every-s", "1000", "--name", "first"]);
    let id = submit(&addr, TRAIN)["id"].as_i64().expect("id");
    wait_for(240, "three iterations", || {
        (metrics(&addr, id).len() >= 3).then_some(())
    });
    let sent = Command::new("kill")
        .args(["-TERM", &first.0.id().to_string()])
        .status()
        .expect("kill -TERM");
    assert!(sent.success());
    let asked = Instant::now();
    let status = exit_within(&mut first, 25);
    assert!(status.success(), "SIGTERM exits 0: {status}");
    let job = wait_state(&addr, id, "queued", 5);
    assert!(
        asked.elapsed() < Duration::from_secs(20),
        "given back, not left to its lease"
    );
    assert_eq!(job["attempts"], 1);
    let saved = get(&addr, &format!("/api/v1/checkpoints?job_id={id}"));
    let stopped_at = saved["checkpoints"][0]["steps"]
        .as_i64()
        .expect("the stopping worker's checkpoint");
    assert!(stopped_at > 0 && stopped_at < 6144, "{saved}");

    // A worker named by the scheduler runs it on, then the same job again from scratch, and
    // leaves after its two jobs.
    let mut second = Proc(
        Command::new(crm())
            .args(["worker", "--coordinator", &grpc, "--poll-s", "0.2"])
            .args(["--max-jobs", "2", "--checkpoint-every-s", "1000"])
            .env("SLURM_JOB_ID", "4242")
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("crm worker"),
    );
    let done = wait_state(&addr, id, "succeeded", 300);
    assert_eq!(done["attempts"], 2);
    assert_eq!(done["result"]["resumed_from_steps"], stopped_at);
    let reference = submit(&addr, TRAIN)["id"].as_i64().expect("id");
    wait_state(&addr, reference, "succeeded", 300);
    assert!(
        exit_within(&mut second, 30).success(),
        "--max-jobs 2 exits 0"
    );
    let (resumed, whole) = (metrics(&addr, id), metrics(&addr, reference));
    assert_eq!(resumed.len(), 12, "one entry per iteration");
    assert_eq!(resumed.len(), whole.len());
    for (k, (a, b)) in resumed.iter().zip(&whole).enumerate() {
        assert_eq!(a, b, "iteration {}", k + 1);
    }
    let download = |job: i64| {
        let checkpoint = get(&addr, &format!("/api/v1/jobs/{job}"))["result"]["checkpoint_id"]
            .as_i64()
            .expect("final checkpoint");
        let file = http(
            &addr,
            "GET",
            &format!("/api/v1/checkpoints/{checkpoint}/download"),
            None,
            None,
        );
        safetensors::SafeTensors::deserialize(&file.body)
            .expect("safetensors")
            .tensors()
            .into_iter()
            .map(|(name, view)| (name, view.data().to_vec()))
            .collect::<std::collections::BTreeMap<_, _>>()
    };
    assert!(
        download(id) == download(reference),
        "the final tensors differ"
    );

    // An idle worker leaves by itself.
    let mut idle = start_worker(&grpc, &["--idle-exit-s", "1", "--name", "idle"]);
    assert!(exit_within(&mut idle, 20).success());
    let workers = get(&addr, "/api/v1/workers");
    let names = worker_names(&workers);
    assert_eq!(names, ["first", "slurm-4242", "idle"]);
}

/// CRM-SAC's whole state (its replay buffer) can outgrow the coordinator's checkpoint limit:
/// the worker then uploads the policy alone and the run goes on, rather than failing.
#[test]
fn a_checkpoint_over_the_coordinators_limit_goes_up_as_the_policy_alone() {
    const SAC: &str = r#"{"kind": "train", "algorithm": "crm-sac", "task": "mouse-press", "steps": 6144, "seed": 2, "envs": 2, "sac": {"rollout_steps": 384, "learning_starts": 500, "buffer_size": 100000, "batch_size": 64, "hidden": [64, 64], "early_stop_window": 1000000}}"#;
    let data = TempDir::new("preempt-limit");
    // The policy of [64, 64] networks is about 150 kB; with its state the checkpoint passes
    // 400 kB after the first iterations.
    let server = start_server(&data.0, &["--max-checkpoint-bytes", "400000"]);
    let addr = server.http.clone();
    let grpc = format!("http://{}", server.grpc);
    let _worker = start_worker(&grpc, &["--checkpoint-every-s", "1", "--name", "w"]);
    let id = submit(&addr, SAC)["id"].as_i64().expect("id");
    let done = wait_state(&addr, id, "succeeded", 300);
    assert_eq!(done["attempts"], 1, "{done}");
    let saved = get(&addr, &format!("/api/v1/checkpoints?job_id={id}"));
    let saved = saved["checkpoints"].as_array().expect("checkpoints");
    let mid_run = saved
        .iter()
        .find(|c| c["steps"].as_i64().is_some_and(|s| s > 0 && s < 6144))
        .unwrap_or_else(|| panic!("a checkpoint uploaded mid-run: {saved:?}"));
    let file = http(
        &addr,
        "GET",
        &format!("/api/v1/checkpoints/{}/download", mid_run["id"]),
        None,
        None,
    );
    assert!(file.body.len() <= 400_000, "{}", file.body.len());
    let (_, metadata) = safetensors::SafeTensors::read_metadata(&file.body).expect("safetensors");
    let header = &metadata.metadata().as_ref().expect("metadata")["crm_grasp"];
    let header: Value = serde_json::from_str(header).expect("header");
    assert_eq!(header["steps"], mid_run["steps"]);
    assert!(header.get("state").is_none(), "the policy alone: {header}");
}

/// An evaluation stopped by SIGTERM stops after its current episode and is given back with
/// where it stood: the next worker goes on from there, the episodes done kept, and the report
/// and the stored episodes are those of an evaluation never interrupted.
#[test]
fn a_preempted_evaluation_goes_on_from_its_episodes_done() {
    let data = TempDir::new("preempt-eval");
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let server = start_server(&data.0, &["--models", models.to_str().expect("utf-8 path")]);
    let addr = server.http.clone();
    let grpc = format!("http://{}", server.grpc);
    let shipped = get(&addr, "/api/v1/checkpoints?uploaded=true")["checkpoints"][0]["id"]
        .as_i64()
        .expect("the shipped model");
    let eval = format!(
        r#"{{"kind": "eval", "checkpoint_id": {shipped}, "episodes": 300, "seed": 4, "tasks": ["mouse-press", "mug-wrap", "valve-twist"]}}"#
    );
    let episodes = |id: i64| -> Vec<Value> {
        get(&addr, &format!("/api/v1/evaluations/{id}"))["episodes"]
            .as_array()
            .cloned()
            .unwrap_or_default()
    };
    let mut first = start_worker(&grpc, &["--name", "first"]);
    let id = submit(&addr, &eval)["id"].as_i64().expect("id");
    wait_for(240, "twenty episodes", || {
        (episodes(id).len() >= 20).then_some(())
    });
    let sent = Command::new("kill")
        .args(["-TERM", &first.0.id().to_string()])
        .status()
        .expect("kill -TERM");
    assert!(sent.success());
    assert!(exit_within(&mut first, 25).success(), "SIGTERM exits 0");
    let job = wait_state(&addr, id, "queued", 5);
    assert_eq!(job["attempts"], 1);
    let done = episodes(id).len();
    assert!((20..300).contains(&done), "{done} episodes kept");

    let mut second = start_worker(&grpc, &["--max-jobs", "2", "--name", "second"]);
    let finished = wait_state(&addr, id, "succeeded", 300);
    assert_eq!(finished["attempts"], 2);
    let reference = submit(&addr, &eval)["id"].as_i64().expect("id");
    let whole = wait_state(&addr, reference, "succeeded", 300);
    assert!(exit_within(&mut second, 30).success());
    // It went on from the episodes done (all of them stored, or the newest 200).
    let mut result = finished["result"].clone();
    let from = result
        .as_object_mut()
        .and_then(|r| r.remove("resumed_from_episodes"))
        .and_then(|v| v.as_u64())
        .expect("resumed_from_episodes");
    assert!(
        from as usize == done || (done == 200 && from >= 200),
        "{from} vs {done}"
    );
    assert_eq!(result, whole["result"], "the same report");
    assert_eq!(result["episodes"], 300);
    // The episode summaries: none twice, none missing (the newest 200 are kept).
    assert_eq!(episodes(id), episodes(reference));
}
