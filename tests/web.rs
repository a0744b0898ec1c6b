//! The dashboard in real headless Chromium: the real coordinator and a real worker on loopback
//! ports with a temporary database, seeded through the REST API with three short training runs
//! (two seeds of one configuration and another algorithm), their evaluations and evaluations
//! with forced topologies; then `web/tests/dashboard.mjs` (playwright-core driving Debian's
//! `/usr/bin/chromium`) loads every page, submits a job through the form, compares runs and
//! deletes one from its page; a small sweep shows its Table I. Every page must load without
//! a console error or a refused request (but where a check provokes one on purpose) and
//! declare an icon that loads.
//!
//! Needs `node`, `npm ci --prefix web` and Chromium (`scripts/test` installs them). Set
//! `CRM_SKIP_BROWSER=1` to skip on a machine without them; `CRM_SCREENSHOTS=DIR` keeps a PNG
//! of each page.

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};
use support::{TempDir, get, start_server, start_worker, wait_state};

fn submit(addr: &str, body: &Value) -> i64 {
    support::submit(addr, &body.to_string())["id"]
        .as_i64()
        .expect("job id")
}

fn train(algorithm: &str, seed: u64) -> Value {
    let mut body = json!({
        "kind": "train", "algorithm": algorithm, "task": "mouse-press", "steps": 3072,
        "seed": seed, "envs": 2, "config": {"rollout_steps": 1024, "learning_rate": 0.0003},
    });
    if seed == 0 && algorithm == "crm-ppo" {
        body["record"] = json!({"every": 1, "max_episodes": 2});
    }
    body
}

/// The repository's root and `web/` folder, once the browser's parts are there; `None` (the
/// test skipped) with `CRM_SKIP_BROWSER=1`.
fn browser() -> Option<(PathBuf, PathBuf)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let web = root.join("web");
    if std::env::var("CRM_SKIP_BROWSER").is_ok_and(|v| v == "1") {
        eprintln!("CRM_SKIP_BROWSER=1: the browser test is skipped");
        return None;
    }
    assert!(
        web.join("node_modules/playwright-core").exists(),
        "run the tests with `scripts/test`, which installs Node.js, Chromium and playwright-core (or `npm ci --prefix web` and `apt-get install chromium`), or set CRM_SKIP_BROWSER=1"
    );
    Some((root, web))
}

#[test]
fn the_dashboard_works_in_chromium() {
    let Some((root, web)) = browser() else {
        return;
    };

    let data = TempDir::new("web");
    // The shipped models are registered on this new data folder (the models page lists them).
    let models = root.join("models");
    let server = start_server(&data.0, &["--models", models.to_str().expect("utf-8 path")]);
    let addr = server.http.clone();
    let mut worker = start_worker(&format!("http://{}", server.grpc), &[]);

    let runs = [
        submit(&addr, &train("crm-ppo", 0)),
        submit(&addr, &train("crm-ppo", 1)),
        submit(&addr, &train("lppo", 0)),
    ];
    let mut checkpoints = Vec::new();
    for &id in &runs {
        let done = wait_state(&addr, id, "succeeded", 300);
        checkpoints.push(
            done["result"]["checkpoint_id"]
                .as_i64()
                .expect("checkpoint"),
        );
    }
    let catalog = get(&addr, "/api/v1/tasks");
    let topologies: Vec<String> = catalog["topologies"]
        .as_array()
        .expect("topologies")
        .iter()
        .filter_map(|t| t.as_str().map(String::from))
        .collect();
    let mut evals = Vec::new();
    for (k, &checkpoint) in checkpoints.iter().enumerate() {
        // Run a's evaluation films its first episode (the run page plays it).
        let mut body = json!({"kind": "eval", "checkpoint_id": checkpoint, "episodes": 6,
                              "tasks": ["mouse-press", "valve-twist"]});
        if k == 0 {
            body["video"] = json!({"episodes": 1});
        }
        evals.push(submit(&addr, &body));
    }
    for topology in &topologies[..2] {
        evals.push(submit(
            &addr,
            &json!({"kind": "eval", "checkpoint_id": checkpoints[0], "episodes": 3,
                    "task": "mouse-press", "topology": topology}),
        ));
    }
    for &id in &evals {
        wait_state(&addr, id, "succeeded", 300);
    }
    // A sweep: two algorithms, one seed, each final checkpoint evaluated.
    let sweep = support::submit_to(
        &addr,
        "/api/v1/sweeps",
        &json!({"name": "browser sweep", "base": {"task": "mouse-press", "steps": 2048, "envs": 2, "config": {"rollout_steps": 1024}},
                "axes": {"algorithm": ["crm-ppo", "lppo"], "seed": [4]}, "eval": {"episodes": 3, "task": "mouse-press"}})
        .to_string(),
    )["sweep"]["id"]
        .as_i64()
        .expect("sweep id");
    support::wait_for(300, "the sweep's jobs", || {
        let sweep = get(&addr, &format!("/api/v1/sweeps/{sweep}"));
        (sweep["progress"]["succeeded"] == 4).then_some(())
    });
    // Without a worker, the job the browser submits stays queued until it cancels it.
    let _ = worker.0.kill();
    let _ = worker.0.wait();
    // One more worker, kept busy building demonstrations for a long imitation job: the pages
    // show its phase (the browser cancels it last).
    let _busy = start_worker(&format!("http://{}", server.grpc), &[]);
    let phase_job = submit(
        &addr,
        &json!({"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 64,
                "envs": 1, "imitation": {"episodes": 100000, "epochs": 1}}),
    );
    support::wait_for(120, "the imitation job's phase", || {
        let job = get(&addr, &format!("/api/v1/jobs/{phase_job}"));
        (job["phase"]["name"] == "demonstrations").then_some(())
    });

    let out = Command::new("node")
        .arg(web.join("tests/dashboard.mjs"))
        .current_dir(&web)
        .env("CRM_BASE", format!("http://{addr}"))
        .env(
            "CRM_SEED",
            json!({"runs": runs, "sweep": sweep, "phase_job": phase_job}).to_string(),
        )
        .env("CRM_MODEL", models.join("crm-ppo.safetensors"))
        .output()
        .expect("run node (is Node.js installed?)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "browser checks failed:\n{stdout}\n{stderr}"
    );
    assert!(
        stdout.contains("12 of 12 browser checks passed"),
        "{stdout}"
    );
    println!("{stdout}");
}

/// With tokens, the dashboard asks for a read token once (its login page) and keeps working:
/// jobs, live updates, a checkpoint download, a reload (`web/tests/login.mjs`).
#[test]
fn the_dashboard_signs_in_with_a_read_token_in_chromium() {
    let Some((root, web)) = browser() else {
        return;
    };
    let data = TempDir::new("web-login");
    let models = root.join("models");
    let (read, submit) = ("read-7f3a9c", "submit-2b81de");
    let server = start_server(
        &data.0,
        &[
            "--models",
            models.to_str().expect("utf-8 path"),
            "--read-token",
            read,
            "--submit-token",
            submit,
            "--worker-token",
            "worker-c04e51",
        ],
    );
    let addr = server.http.clone();
    let listed = support::http(&addr, "GET", "/api/v1/checkpoints", None, Some(read)).json();
    let checkpoint = listed["checkpoints"][0]["id"]
        .as_i64()
        .expect("a shipped model");
    let out = Command::new("node")
        .arg(web.join("tests/login.mjs"))
        .current_dir(&web)
        .env("CRM_BASE", format!("http://{addr}"))
        .env("CRM_READ_TOKEN", read)
        .env("CRM_SUBMIT_TOKEN", submit)
        .env("CRM_CHECKPOINT", checkpoint.to_string())
        .output()
        .expect("run node (is Node.js installed?)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "login checks failed:\n{stdout}\n{stderr}"
    );
    assert!(stdout.contains("login: ok"), "{stdout}");
}
