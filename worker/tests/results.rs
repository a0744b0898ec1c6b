//! `crm results` as a study: its interval estimates against the `rliable` package itself, and a
//! study that is interrupted, continued and extended, whose report rebuilds byte for byte from
//! its files.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

fn crm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_crm"))
}

/// Runs `command` and fails the test, with its stderr, unless it exits 0.
fn succeeded(command: &mut Command, what: &str) -> std::process::Output {
    let out = command.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("crm-results-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// A score matrix like a study's: 5 algorithms x 5 runs x 26 tasks of success rates that are
/// counts out of 38 episodes, from a fixed linear congruential stream.
fn score_file(dir: &Path, reps: usize) -> PathBuf {
    let mut state: u64 = 12345;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 33) as f64 / (1u64 << 31) as f64
    };
    let mut scores = serde_json::Map::new();
    for (k, algorithm) in ["crm-ppo", "ippo", "lppo", "crm-sac", "ppo"]
        .iter()
        .enumerate()
    {
        let skill = 0.9 - 0.15 * k as f64;
        let runs: Vec<Vec<f64>> = (0..5)
            .map(|_| {
                (0..26)
                    .map(|_| {
                        let p = (skill + 0.3 * (next() - 0.5)).clamp(0.0, 1.0);
                        (p * 38.0).round() / 38.0
                    })
                    .collect()
            })
            .collect();
        scores.insert(algorithm.to_string(), json!(runs));
    }
    let path = dir.join("scores.json");
    let body = json!({"scores": scores, "reference": "crm-ppo", "reps": reps, "seed": 3});
    std::fs::write(&path, body.to_string()).expect("write scores");
    path
}

#[test]
fn interval_estimates_agree_with_rliable() {
    let Ok(python) = std::env::var("CRM_RLIABLE_PYTHON") else {
        panic!(
            "CRM_RLIABLE_PYTHON is not set: scripts/test installs rliable==1.2.0 into a venv \
             under ~/.cache and sets it; run the suite with scripts/test"
        );
    };
    let dir = temp("rliable");
    let scores = score_file(&dir, 1000);
    let ours = succeeded(
        crm().args(["results", "--stats-of"]).arg(&scores),
        "crm runs",
    );
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/rliable-figures.py");
    let theirs = succeeded(Command::new(python).arg(script).arg(&scores), "python runs");
    let ours: Value = serde_json::from_slice(&ours.stdout).expect("our JSON");
    let theirs: Value = serde_json::from_slice(&theirs.stdout).expect("rliable's JSON");
    let check = |what: String, a: &Value, b: &Value| {
        let f = |v: &Value, k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{what}.{k}"));
        let (p, q) = (f(a, "point"), f(b, "point"));
        assert!(
            (p - q).abs() <= 1e-9,
            "{what}: point {p} against rliable's {q}"
        );
        for bound in ["low", "high"] {
            let (x, y) = (f(a, bound), f(b, bound));
            assert!(
                (x - y).abs() <= 0.02,
                "{what}: {bound} {x} against rliable's {y}"
            );
        }
    };
    let mut checked = 0;
    for algorithm in ["crm-ppo", "ippo", "lppo", "crm-sac", "ppo"] {
        for figure in ["iqm", "mean", "median", "optimality_gap"] {
            check(
                format!("{algorithm} {figure}"),
                &ours["aggregates"][algorithm][figure],
                &theirs["aggregates"][algorithm][figure],
            );
            checked += 1;
        }
    }
    for other in ["ippo", "lppo", "crm-sac", "ppo"] {
        check(
            format!("P(crm-ppo > {other})"),
            &ours["improvement"][other],
            &theirs["improvement"][other],
        );
        checked += 1;
    }
    assert_eq!(checked, 24);
    // A ragged matrix is refused with the algorithm named.
    std::fs::write(&scores, r#"{"scores": {"ippo": [[0.5, 1.0], [0.5]]}}"#).expect("write");
    let bad = crm()
        .args(["results", "--stats-of"])
        .arg(&scores)
        .output()
        .expect("crm runs");
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("scores.ippo"));
    std::fs::remove_dir_all(&dir).ok();
}

fn study_args(out: &Path, data: &Path, seeds: &str) -> Vec<String> {
    let ppo = out.parent().expect("dir").join("ppo.json");
    std::fs::write(&ppo, r#"{"rollout_steps": 512, "minibatch_size": 128}"#).expect("ppo");
    [
        "results",
        "--steps",
        "4096",
        "--episodes",
        "4",
        "--task",
        "mouse-press",
        "--task",
        "mug-wrap",
        "--algo",
        "crm-ppo",
        "--algo",
        "ppo",
        "--envs",
        "1",
        "--seeds",
        seeds,
        "--reps",
        "300",
        "--settle-s",
        "0.25",
        "--out",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain([
        out.display().to_string(),
        "--data-dir".into(),
        data.display().to_string(),
        "--ppo-config".into(),
        ppo.display().to_string(),
    ])
    .collect()
}

/// The id of a training job of the coordinator at `url` that is running and has reported.
fn running_job(url: &str) -> Option<i64> {
    let mut answer = ureq::get(format!("{url}/api/v1/jobs?kind=train"))
        .call()
        .ok()?;
    let jobs: Value = serde_json::from_str(&answer.body_mut().read_to_string().ok()?).ok()?;
    jobs["jobs"]
        .as_array()?
        .iter()
        .find(|j| j["state"] == "running" && j["steps"].as_i64().unwrap_or(0) > 0)
        .and_then(|j| j["id"].as_i64())
}

fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut all = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("read dir").flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                all.push((path.clone(), std::fs::read(&path).expect("read")));
            }
        }
    }
    all.sort();
    all
}

#[test]
fn a_study_survives_interruption_extends_and_rebuilds_its_report_byte_for_byte() {
    let dir = temp("study");
    let (out, data) = (dir.join("docs"), dir.join("data"));
    let study = out.join("results").join("builtin");
    // Interrupted mid-training: stopped while its first training job runs.
    let log = dir.join("first.log");
    let mut first = crm()
        .args(study_args(&out, &data, "1"))
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).expect("log"))
        .spawn()
        .expect("crm results");
    let started = Instant::now();
    let mut interrupted = None;
    while interrupted.is_none() {
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "no training job ran in 5 minutes"
        );
        if let Some(status) = first.try_wait().expect("wait") {
            panic!("crm results ended before it was interrupted: {status}");
        }
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        if let Some(url) = text
            .split_whitespace()
            .find(|w| w.starts_with("http://") && !w.ends_with('/'))
        {
            interrupted = running_job(url.trim_end_matches(','));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    // SIGTERM (a batch system's time limit): the local worker ends its job at the
    // iteration's end with a checkpoint and gives it back, and the command stops.
    let sent = Command::new("kill")
        .args(["-TERM", &first.id().to_string()])
        .status()
        .expect("kill -TERM");
    assert!(sent.success());
    let asked = Instant::now();
    let status = loop {
        if let Some(status) = first.try_wait().expect("wait") {
            break status;
        }
        assert!(
            asked.elapsed() < Duration::from_secs(30),
            "no exit within 30 s of SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(!status.success(), "an interrupted study is no success");
    assert!(text.contains("run the same command to continue"), "{text}");
    assert!(
        !study.join("crm-ppo/seed-0/run.json").exists(),
        "interrupted before any run landed"
    );
    // The same command continues it: the interrupted job is leased again and resumes from
    // the checkpoint its worker uploaded when it stopped.
    succeeded(crm().args(study_args(&out, &data, "1")), "crm results");
    let resumed: Value = serde_json::from_slice(
        &std::fs::read(study.join("crm-ppo/seed-0/run.json")).expect("run.json"),
    )
    .expect("json");
    assert_eq!(resumed["leases"], 2, "{resumed}");
    assert!(
        resumed["resumed_from_steps"]
            .as_u64()
            .is_some_and(|s| s > 0),
        "{resumed}"
    );
    // Once finished, the same command trains nothing and changes no run.
    let kept = std::fs::read(study.join("crm-ppo/seed-0/checkpoint.safetensors")).expect("kept");
    let done = succeeded(crm().args(study_args(&out, &data, "1")), "crm results");
    assert!(!String::from_utf8_lossy(&done.stderr).contains("sweep "));
    assert_eq!(
        std::fs::read(study.join("crm-ppo/seed-0/checkpoint.safetensors")).expect("read"),
        kept
    );
    for name in [
        "run.json",
        "eval.json",
        "eval-deterministic.json",
        "curve.csv",
        "checkpoint.safetensors",
    ] {
        assert!(study.join("ppo/seed-0").join(name).is_file(), "{name}");
    }
    let deterministic: Value = serde_json::from_slice(
        &std::fs::read(study.join("ppo/seed-0/eval-deterministic.json")).expect("read"),
    )
    .expect("json");
    assert_eq!(deterministic["deterministic"], true);
    // Extended by a seed: only the new seed's runs train.
    let extended = succeeded(crm().args(study_args(&out, &data, "2")), "crm results");
    let stderr = String::from_utf8_lossy(&extended.stderr);
    assert!(stderr.contains("seed 1, crm-ppo, ppo"), "{stderr}");
    assert!(!stderr.contains("seed 0,"), "{stderr}");
    let text = std::fs::read_to_string(out.join("RESULTS.md")).expect("RESULTS.md");
    assert!(text.contains("runs finished: 4 of 4"), "{text}");
    assert!(
        text.contains("| objective | crm-ppo | paper | ppo | paper |"),
        "{text}"
    );
    for row in ["| press |", "| wrap_grasp |", "| overall |"] {
        assert!(text.contains(row), "{row} in {text}");
    }
    assert!(text.contains("| crm-ppo | sampled | 2 |"), "{text}");
    assert!(text.contains("| ppo | deterministic | 2 |"), "{text}");
    assert!(text.contains("| ppo | 0."), "P(CRM-PPO > ppo) in {text}");
    assert!(text.contains("Ordering by IQM"), "{text}");
    // The settings printed are those of the learners the study has: no SAC here.
    assert!(text.contains("- PPO settings (crm-ppo, ppo): `"), "{text}");
    assert!(!text.contains("SAC settings"), "{text}");
    // Other settings on the same study are refused, naming the setting.
    let mut other = study_args(&out, &data, "2");
    let steps = other.iter().position(|a| a == "--steps").expect("--steps") + 1;
    other[steps] = "8192".into();
    let refused = crm().args(other).output().expect("crm results");
    assert_eq!(refused.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(stderr.contains("steps = 4096"), "{stderr}");
    // `--redo ppo` trains flat PPO's runs again (after a fix to it) and leaves CRM-PPO's
    // alone; the study does not record the flag, so its command again redoes nothing.
    let run = |path: &str| -> Value {
        serde_json::from_slice(&std::fs::read(study.join(path)).expect("run.json")).expect("json")
    };
    let old_job = run("ppo/seed-0/run.json")["train_job"]
        .as_i64()
        .expect("id");
    let kept = std::fs::read(study.join("crm-ppo/seed-0/checkpoint.safetensors")).expect("kept");
    let mut redo = study_args(&out, &data, "2");
    redo.extend(["--redo".to_string(), "ppo".to_string()]);
    let redone = succeeded(crm().args(&redo), "crm results --redo ppo");
    let stderr = String::from_utf8_lossy(&redone.stderr);
    assert!(stderr.contains("--redo ppo: "), "{stderr}");
    assert!(
        stderr.contains("seed 0, ppo") && stderr.contains("seed 1, ppo"),
        "{stderr}"
    );
    assert!(!stderr.contains("crm-ppo"), "{stderr}");
    assert_ne!(
        run("ppo/seed-0/run.json")["train_job"].as_i64(),
        Some(old_job)
    );
    let file = run("study.json");
    assert!(
        file["superseded"]["ppo"]
            .as_array()
            .is_some_and(|ids| ids.contains(&Value::from(old_job))),
        "{file}"
    );
    assert!(
        !file["command"]
            .as_str()
            .expect("command")
            .contains("--redo"),
        "{file}"
    );
    assert_eq!(
        std::fs::read(study.join("crm-ppo/seed-0/checkpoint.safetensors")).expect("read"),
        kept
    );
    let again = succeeded(crm().args(study_args(&out, &data, "2")), "crm results");
    assert!(!String::from_utf8_lossy(&again.stderr).contains("sweep "));
    // An algorithm the study does not have is refused, naming the flag, before anything of
    // the others is set aside.
    let mut other = study_args(&out, &data, "2");
    other.extend(["--redo", "ppo", "--redo", "lppo"].map(String::from));
    let refused = crm().args(other).output().expect("crm results");
    assert_eq!(refused.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("--redo lppo: the study builtin has no lppo runs"),
        "{stderr}"
    );
    assert!(study.join("ppo/seed-0/run.json").is_file(), "{stderr}");
    // The report and every plot rebuild byte for byte from the files alone.
    let before = files(&out);
    std::fs::remove_file(out.join("RESULTS.md")).expect("remove");
    for plot in ["success.png", "episode_length.png", "profile.png"] {
        std::fs::remove_file(study.join(plot)).expect(plot);
    }
    succeeded(
        crm()
            .args(["results", "--report-only", "--reps", "300", "--out"])
            .arg(&out),
        "crm results --report-only",
    );
    assert!(files(&out) == before, "the rebuilt report differs");
    std::fs::remove_dir_all(&dir).ok();
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("read dir").flatten() {
        let path = entry.path();
        let target = to.join(entry.file_name());
        if path.is_dir() {
            copy_tree(&path, &target);
        } else {
            std::fs::copy(&path, &target).expect("copy");
        }
    }
}

#[test]
fn the_committed_report_rebuilds_byte_for_byte_from_the_committed_runs() {
    let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs");
    let out = temp("committed");
    copy_tree(&docs.join("results"), &out.join("results"));
    succeeded(
        crm().args(["results", "--report-only", "--out"]).arg(&out),
        "crm results --report-only",
    );
    let ours = std::fs::read_to_string(out.join("RESULTS.md")).expect("rebuilt");
    let committed = std::fs::read_to_string(docs.join("RESULTS.md")).expect("committed");
    assert!(
        ours == committed,
        "docs/RESULTS.md is not what `crm results --report-only` writes from docs/results/: \
         run it and commit the result"
    );
    let mut plots = 0;
    for (path, bytes) in files(&out.join("results")) {
        if path.extension().is_some_and(|e| e == "png") {
            let relative = path.strip_prefix(&out).expect("inside");
            let committed = std::fs::read(docs.join(relative)).expect("a committed plot");
            assert!(committed == bytes, "{} differs", relative.display());
            plots += 1;
        }
    }
    assert!(plots >= 3, "the plots of at least one study");
    std::fs::remove_dir_all(&out).ok();
}
