//! End-to-end tests of sweeps against the real `crm-server` and `crm worker` on loopback
//! with a temporary data folder: a bad sweep is refused whole (nothing stored) with the field
//! named; a 2 x 2 sweep runs its training jobs and the evaluation of each final checkpoint,
//! and its Table I is the mean and population std of those evaluations, computed here by
//! hand; cancelling a sweep cancels its jobs.

mod support;

use serde_json::{Value, json};
use support::*;

fn post(addr: &str, path: &str, body: &Value) -> Reply {
    http(addr, "POST", path, Some(&body.to_string()), Some(TOKEN))
}

fn job_count(addr: &str) -> usize {
    get(addr, "/api/v1/jobs?limit=10000")["jobs"]
        .as_array()
        .map_or(0, Vec::len)
}

/// Mean and population std.
fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

fn close(a: &Value, b: f64) -> bool {
    a.as_f64().is_some_and(|a| (a - b).abs() < 1e-9)
}

#[test]
fn a_sweep_is_validated_whole_runs_its_grid_and_aggregates_table_one() {
    let data = TempDir::new("sweeps");
    let server = start_server(&data.0, &["--token", TOKEN, "--max-sweep-jobs", "4"]);
    let addr = server.http.clone();
    let base =
        json!({"task": "mouse-press", "steps": 1024, "envs": 1, "config": {"rollout_steps": 512}});
    let eval = json!({"episodes": 4, "task": "mouse-press", "seed": 7});

    // Refused whole, naming the field; nothing stored.
    let bad = [
        (
            json!({"base": base, "axes": {"colour": ["red"]}}),
            "axes.colour",
            400,
        ),
        (
            json!({"base": base, "axes": {"config.colour": [1]}}),
            "axes.config.colour",
            400,
        ),
        // Every field of the training spec is an axis (settle_s included), checked as a job.
        (
            json!({"base": base, "axes": {"algorithm": ["lppo"], "settle_s": [0.5, 9.0]}}),
            "axes.settle_s[1]",
            400,
        ),
        (
            json!({"base": base, "axes": {"seed": []}}),
            "axes.seed",
            400,
        ),
        (
            json!({"base": base, "axes": {"algorithm": ["crm-ppo", "dqn"]}}),
            "axes.algorithm[1]",
            400,
        ),
        (
            json!({"base": base, "axes": {"algorithm": ["lppo"], "config.gamma": [0.9, 2.0]}}),
            "axes.config.gamma[1]",
            400,
        ),
        (
            json!({"base": base, "axes": {"seed": [0, 0]}, "eval": eval}),
            "axes.seed[1]",
            400,
        ),
        (
            json!({"base": base, "axes": {"algorithm": ["lppo"], "seed": [0, 1, 2, 3, 4]}}),
            "axes",
            400,
        ),
        (
            json!({"base": {"algorithm": "crm-sac", "steps": 10, "imitation": {"episodes": 2}}, "axes": {"seed": [0]}}),
            "base.imitation",
            400,
        ),
        (
            json!({"base": {"task": "mouse-press"}, "axes": {"algorithm": ["lppo"]}}),
            "base.steps",
            400,
        ),
        (
            json!({"base": base, "axes": {"algorithm": ["lppo"]}, "eval": {"episodes": 0}}),
            "eval.episodes",
            400,
        ),
        (
            json!({"base": base, "axes": {"algorithm": ["lppo"]}, "eval": {"checkpoint_id": 1}}),
            "eval",
            400,
        ),
    ];
    for (body, field, status) in bad {
        let reply = post(&addr, "/api/v1/sweeps", &body);
        assert_eq!(
            reply.status,
            status,
            "{body}: {}",
            String::from_utf8_lossy(&reply.body)
        );
        assert_eq!(reply.json()["error"]["field"], field, "{body}");
    }
    let unauthorized = http(&addr, "POST", "/api/v1/sweeps", Some("{}"), None);
    assert_eq!(unauthorized.status, 401);
    assert_eq!(get(&addr, "/api/v1/sweeps")["sweeps"], json!([]));
    assert_eq!(job_count(&addr), 0);

    // Two algorithms x two seeds.
    let body = json!({"name": "two by two", "base": base, "eval": eval,
                      "axes": {"algorithm": ["crm-ppo", "lppo"], "seed": [0, 1]}});
    let created = post(&addr, "/api/v1/sweeps", &body);
    assert_eq!(
        created.status,
        201,
        "{}",
        String::from_utf8_lossy(&created.body)
    );
    let created = created.json();
    let id = created["sweep"]["id"].as_i64().expect("id");
    let jobs = created["jobs"].as_array().expect("jobs");
    let grid: Vec<(String, i64)> = jobs
        .iter()
        .map(|j| {
            (
                j["algorithm"].as_str().unwrap_or("").to_string(),
                j["spec"]["seed"].as_i64().unwrap_or(-1),
            )
        })
        .collect();
    assert_eq!(
        grid,
        [
            ("crm-ppo".into(), 0),
            ("crm-ppo".into(), 1),
            ("lppo".into(), 0),
            ("lppo".into(), 1)
        ]
    );
    let _worker = start_worker(&format!("http://{}", server.grpc), &["--token", TOKEN]);
    let done = wait_for(600, "the sweep's 4 runs and 4 evaluations", || {
        let sweep = get(&addr, &format!("/api/v1/sweeps/{id}"));
        (sweep["progress"]["finished"] == 8).then_some(sweep)
    });
    assert_eq!(done["progress"]["succeeded"], 8, "{}", done["jobs"]);
    assert_eq!(done["progress"]["fraction"], 1.0);
    let jobs = done["jobs"].as_array().expect("jobs");
    let rows = done["table"]["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 2);
    for (row, algorithm) in rows.iter().zip(["crm-ppo", "lppo"]) {
        assert_eq!(row["config"], json!({"algorithm": algorithm}));
        // By hand: the evaluations of this algorithm's final checkpoints.
        let mut success = Vec::new();
        let mut length = Vec::new();
        let mut press = Vec::new();
        for run in jobs
            .iter()
            .filter(|j| j["kind"] == "train" && j["algorithm"] == algorithm)
        {
            let checkpoint = &run["result"]["checkpoint_id"];
            let eval = jobs
                .iter()
                .find(|j| j["kind"] == "eval" && &j["checkpoint_id"] == checkpoint)
                .expect("an evaluation of the final checkpoint");
            assert_eq!(eval["spec"]["episodes"], 4);
            assert_eq!(eval["spec"]["seed"], 7);
            let report = &eval["result"];
            success.push(report["success_rate"].as_f64().expect("success"));
            length.push(report["mean_episode_length"].as_f64().expect("length"));
            press.push(
                report["per_objective"]["press"]["success_rate"]
                    .as_f64()
                    .expect("press"),
            );
        }
        assert_eq!(success.len(), 2);
        let (m, s) = mean_std(&success);
        assert!(
            close(&row["overall"]["success"]["mean"], m)
                && close(&row["overall"]["success"]["std"], s),
            "{row}"
        );
        let (m, s) = mean_std(&length);
        assert!(
            close(&row["overall"]["length"]["mean"], m)
                && close(&row["overall"]["length"]["std"], s),
            "{row}"
        );
        let (m, s) = mean_std(&press);
        let cell = &row["per_objective"]["press"]["success"];
        assert!(close(&cell["mean"], m) && close(&cell["std"], s), "{row}");
        assert_eq!(row["evaluated"], 2);
    }
    let listed = get(&addr, "/api/v1/sweeps");
    assert_eq!(listed["sweeps"][0]["name"], "two by two");

    // Cancelling a sweep cancels its jobs (the worker is busy with nothing else).
    let other = post(
        &addr,
        "/api/v1/sweeps",
        &json!({"base": {"task": "mouse-press", "steps": 1_000_000, "envs": 1}, "axes": {"algorithm": ["ppo"], "seed": [5, 6]}}),
    );
    assert_eq!(other.status, 201);
    let other = other.json()["sweep"]["id"].as_i64().expect("id");
    let cancelled = post(&addr, &format!("/api/v1/sweeps/{other}/cancel"), &json!({}));
    assert_eq!(cancelled.status, 200);
    assert_eq!(cancelled.json()["cancelled"], 2);
    let after = get(&addr, &format!("/api/v1/sweeps/{other}"));
    assert!(
        after["jobs"]
            .as_array()
            .expect("jobs")
            .iter()
            .all(|j| j["state"] == "cancelled"),
        "{after}"
    );
    assert_eq!(
        http(&addr, "GET", "/api/v1/sweeps/999", None, Some(TOKEN)).status,
        404
    );
}

/// `crm results`' cell: `success ± std (length ± std)` over the runs' (success, length).
fn cell(runs: &[(f64, f64)]) -> String {
    let stats = |values: Vec<f64>| {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        (mean, std)
    };
    let (sm, ss) = stats(runs.iter().map(|r| r.0).collect());
    let (lm, ls) = stats(runs.iter().map(|r| r.1).collect());
    format!("{sm:.2} ± {ss:.2} ({lm:.0} ± {ls:.0})")
}

#[test]
fn crm_results_runs_its_study_as_sweeps_and_writes_the_evaluations_numbers() {
    let data = TempDir::new("results");
    let out = TempDir::new("results-out");
    let server = start_server(&data.0, &["--token", TOKEN]);
    let addr = server.http.clone();
    let _worker = start_worker(&format!("http://{}", server.grpc), &["--token", TOKEN]);
    let url = format!("http://{addr}");
    let run = std::process::Command::new(crm())
        .args([
            "results",
            "--coordinator",
            &url,
            "--token",
            TOKEN,
            "--steps",
            "1024",
            "--seeds",
            "2",
        ])
        .args([
            "--algo",
            "crm-ppo",
            "--algo",
            "ippo",
            "--episodes",
            "4",
            "--task",
            "mouse-press",
            "--envs",
            "1",
            "--reps",
            "200",
        ])
        .arg("--out")
        .arg(&out.0)
        .output()
        .expect("run crm results");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(out.0.join("RESULTS.md")).expect("RESULTS.md");
    for png in ["success.png", "episode_length.png", "profile.png"] {
        let bytes = std::fs::read(out.0.join("results/builtin").join(png)).expect("a plot");
        assert!(bytes.starts_with(b"\x89PNG"), "{png}");
    }
    // The study ran as one sweep per seed, named after it; its numbers are the sweeps'
    // sampled evaluations, cell by cell.
    let sweeps = get(&addr, "/api/v1/sweeps");
    let ids: Vec<i64> = sweeps["sweeps"]
        .as_array()
        .expect("sweeps")
        .iter()
        .filter(|s| s["name"] == "crm results: builtin")
        .filter_map(|s| s["id"].as_i64())
        .collect();
    assert_eq!(ids.len(), 2, "{sweeps}");
    let mut evals: Vec<(String, Value)> = Vec::new();
    for id in ids {
        let sweep = get(&addr, &format!("/api/v1/sweeps/{id}"));
        for job in sweep["jobs"].as_array().expect("jobs") {
            if job["kind"] == "eval" {
                assert_eq!(job["state"], "succeeded", "{job}");
                let algorithm = job["algorithm"].as_str().expect("algorithm").to_string();
                evals.push((algorithm, job["result"].clone()));
            }
        }
    }
    assert_eq!(evals.len(), 4);
    let line = |objective: &str| -> Vec<String> {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("| {objective} |")))
            .unwrap_or_else(|| panic!("no {objective} row in\n{text}"));
        line.split('|')
            .map(|c| c.trim().trim_matches('*').to_string())
            .collect()
    };
    for objective in ["overall", "press"] {
        let cells = line(objective);
        for (k, algorithm) in ["crm-ppo", "ippo"].iter().enumerate() {
            let runs: Vec<(f64, f64)> = evals
                .iter()
                .filter(|(a, _)| a == algorithm)
                .map(|(_, r)| {
                    let row = if objective == "overall" {
                        r
                    } else {
                        &r["per_objective"][objective]
                    };
                    (
                        row["success_rate"].as_f64().expect("success"),
                        row["mean_episode_length"].as_f64().expect("length"),
                    )
                })
                .collect();
            // | objective | ours | paper | ours | paper |
            assert_eq!(cells[2 + 2 * k], cell(&runs), "{objective}, {algorithm}");
        }
    }
    assert!(
        text.contains("| crm-ppo | paper | ippo | paper |"),
        "{text}"
    );
    // The paper's press numbers stand beside ours.
    assert_eq!(line("press")[3], "0.96 (167)");

    // An unreachable coordinator: exit 2, naming the address.
    let out = std::process::Command::new(crm())
        .args([
            "results",
            "--coordinator",
            "http://127.0.0.1:9",
            "--steps",
            "10",
        ])
        .output()
        .expect("run crm results");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("http://127.0.0.1:9"));
}
