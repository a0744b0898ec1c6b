//! A resumed run is the same run, for every learner: `crm train` killed with SIGKILL after a
//! checkpoint, or stopped by SIGTERM (it checkpoints at the iteration's end and exits 0), and
//! resumed from its checkpoint writes the same metrics, line for line (wall-clock aside), and
//! the same final tensors, bit for bit, as the same run never interrupted.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("crm-resume-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

fn train(dir: &Path, config: &Path, algorithm: &str, resume: bool) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_crm"));
    command
        .args([
            "train", "--algo", algorithm, "--steps", "6144", "--seed", "3",
        ])
        .args(["--envs", "3", "--task", "mouse-press", "--task", "mug-wrap"])
        .args([
            "--task",
            "valve-twist",
            "--curriculum",
            "--settle-s",
            "0.25",
        ])
        .args(["--checkpoint-every", "1", "--config"])
        .arg(config)
        .arg("--out")
        .arg(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    if resume {
        command
            .arg("--resume")
            .arg(dir.join(format!("{algorithm}.safetensors")));
    }
    command
}

/// The metrics log without its wall-clock fields.
fn metrics(dir: &Path) -> Vec<Value> {
    std::fs::read_to_string(dir.join("metrics.jsonl"))
        .expect("metrics.jsonl")
        .lines()
        .map(|line| {
            let mut value: Value = serde_json::from_str(line).expect("a JSON line");
            let map = value.as_object_mut().expect("an object");
            map.remove("wall_s");
            map.remove("steps_per_s");
            value
        })
        .collect()
}

/// A checkpoint's tensors by name, as raw bytes.
fn tensors(path: &Path) -> BTreeMap<String, Vec<u8>> {
    let bytes = std::fs::read(path).expect("checkpoint");
    let file = safetensors::SafeTensors::deserialize(&bytes).expect("safetensors");
    file.tensors()
        .into_iter()
        .map(|(name, view)| (name, view.data().to_vec()))
        .collect()
}

/// How the run is interrupted.
#[derive(Clone, Copy, PartialEq)]
enum Stop {
    Kill,
    Term,
}

/// Small PPO iterations, so that the run checkpoints many times.
const PPO: &str = r#"{"rollout_steps": 384, "minibatch_size": 128}"#;

fn check_resume_is_the_same_run(algorithm: &str, config_json: &str, stop: Stop) {
    let dir = temp(&format!("{algorithm}-{}", stop == Stop::Term));
    let config = dir.join("config.json");
    std::fs::write(&config, config_json).expect("config");
    let whole = dir.join("whole");
    let out = train(&whole, &config, algorithm, false)
        .output()
        .expect("crm train");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // The same run, killed once a few checkpoints are written, then resumed.
    let cut = dir.join("cut");
    let mut child = train(&cut, &config, algorithm, false)
        .stderr(Stdio::null())
        .spawn()
        .expect("crm train");
    let checkpoint = cut.join(format!("{algorithm}.safetensors"));
    let started = Instant::now();
    loop {
        let lines = std::fs::read_to_string(cut.join("metrics.jsonl"))
            .map(|t| t.lines().count())
            .unwrap_or(0);
        if lines >= 5 && checkpoint.exists() {
            break;
        }
        assert!(
            child.try_wait().expect("wait").is_none(),
            "the run ended before it was killed"
        );
        assert!(started.elapsed() < Duration::from_secs(300), "too slow");
        std::thread::sleep(Duration::from_millis(5));
    }
    match stop {
        Stop::Kill => {
            child.kill().expect("SIGKILL");
            child.wait().expect("reap");
        }
        Stop::Term => {
            let sent = Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status()
                .expect("kill -TERM");
            assert!(sent.success());
            let asked = Instant::now();
            let status = loop {
                if let Some(status) = child.try_wait().expect("wait") {
                    break status;
                }
                assert!(
                    asked.elapsed() < Duration::from_secs(30),
                    "no exit within 30 s of SIGTERM"
                );
                std::thread::sleep(Duration::from_millis(10));
            };
            assert!(status.success(), "SIGTERM exits 0: {status}");
        }
    }
    let header = crm_learn::Checkpoint::read_header(&checkpoint).expect("header");
    let state = header
        .state
        .expect("an unfinished run's checkpoint keeps its state");
    assert!(
        state.iteration >= 4 && header.steps < 6144,
        "{:?}",
        state.iteration
    );
    let out = train(&cut, &config, algorithm, true)
        .output()
        .expect("crm train --resume");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let (a, b) = (metrics(&whole), metrics(&cut));
    assert_eq!(a.len(), b.len(), "as many iterations");
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert_eq!(x, y, "iteration {}", k + 1);
    }
    let final_a = tensors(&whole.join(format!("{algorithm}.safetensors")));
    let final_b = tensors(&checkpoint);
    assert!(!final_a.is_empty());
    assert!(
        final_a.keys().all(|name| !name.starts_with("state.")),
        "a finished run's checkpoint is the policy alone"
    );
    assert!(final_a == final_b, "the final tensors differ");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_crm_ppo_run_killed_and_resumed_is_the_same_run() {
    check_resume_is_the_same_run("crm-ppo", PPO, Stop::Kill);
}

#[test]
fn an_lppo_run_killed_and_resumed_is_the_same_run() {
    check_resume_is_the_same_run("lppo", PPO, Stop::Kill);
}

#[test]
fn an_ippo_run_stopped_by_sigterm_and_resumed_is_the_same_run() {
    check_resume_is_the_same_run("ippo", PPO, Stop::Term);
}

/// CRM-SAC's state holds its replay buffer: learning starts before the kill and the ring of
/// 1,000 transitions has wrapped by then, so the resumed run samples from a restored ring.
#[test]
fn a_crm_sac_run_killed_and_resumed_is_the_same_run() {
    let sac = r#"{"rollout_steps": 384, "learning_starts": 500, "buffer_size": 1000,
        "batch_size": 64, "hidden": [64, 64], "updates_per_step": 0.125}"#;
    check_resume_is_the_same_run("crm-sac", sac, Stop::Kill);
}
