//! End-to-end tests of disk retention against the real `crm-server` and `crm worker` on
//! loopback with a temporary data folder: old checkpoints are removed (files and rows), and
//! `DELETE /api/v1/runs/{id}` removes a finished run with everything it stored while other
//! runs stay as they were.

mod support;

use std::collections::BTreeSet;
use std::path::Path;

use serde_json::Value;
use support::*;

/// A training run long enough for a few checkpoints at one a second, recorded.
fn train(seed: u64) -> String {
    format!(
        r#"{{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 8192, "seed": {seed}, "envs": 2, "config": {{"rollout_steps": 1024}}, "record": {{"every": 1, "max_episodes": 2}}}}"#
    )
}

fn post(addr: &str, body: &str) -> Value {
    submit_as(addr, body, Some(TOKEN))
}

fn files(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().to_string())
                .collect()
        })
        .unwrap_or_default()
}

fn checkpoint_ids(addr: &str, job: i64) -> Vec<i64> {
    get(addr, &format!("/api/v1/runs/{job}"))["checkpoints"]
        .as_array()
        .expect("checkpoints")
        .iter()
        .map(|c| c["id"].as_i64().expect("id"))
        .collect()
}

#[test]
fn old_checkpoints_are_removed_and_a_deleted_run_leaves_nothing_behind() {
    let data = TempDir::new("retention");
    let server = start_server(&data.0, &["--token", TOKEN, "--keep-checkpoints", "1"]);
    let addr = server.http.clone();
    let mut worker = start_worker(
        &format!("http://{}", server.grpc),
        &["--token", TOKEN, "--checkpoint-every-s", "1"],
    );
    let a = post(&addr, &train(1))["id"].as_i64().expect("id");
    let b = post(&addr, &train(2))["id"].as_i64().expect("id");

    // A running run cannot be deleted.
    wait_state(&addr, a, "running", 120);
    let busy = http(
        &addr,
        "DELETE",
        &format!("/api/v1/runs/{a}"),
        None,
        Some(TOKEN),
    );
    assert_eq!(busy.status, 409, "{}", String::from_utf8_lossy(&busy.body));

    for job in [a, b] {
        wait_state(&addr, job, "succeeded", 300);
    }
    // Retention: the newest one per run, which is the final one.
    let mut kept = Vec::new();
    for job in [a, b] {
        let ids = checkpoint_ids(&addr, job);
        let done = get(&addr, &format!("/api/v1/jobs/{job}"));
        let last = done["result"]["checkpoint_id"].as_i64().expect("final");
        assert_eq!(ids, vec![last], "run {job} keeps its final checkpoint only");
        kept.extend(ids);
    }
    let checkpoint_dir = data.0.join("checkpoints");
    let stored = files(&checkpoint_dir);
    assert_eq!(
        stored.len(),
        kept.len(),
        "one file per kept row: {stored:?}"
    );
    // Ids are never reused: a kept id above the kept count means rows were removed.
    let newest = kept.iter().copied().max().unwrap_or(0);
    assert!(
        newest as usize > kept.len() + 1,
        "no checkpoint was removed (ids {kept:?})"
    );

    // An evaluation of run a's final checkpoint belongs to run a.
    let final_a = get(&addr, &format!("/api/v1/jobs/{a}"))["result"]["checkpoint_id"]
        .as_i64()
        .expect("final");
    let eval = post(
        &addr,
        &format!(r#"{{"kind": "eval", "checkpoint_id": {final_a}, "episodes": 2}}"#),
    )["id"]
        .as_i64()
        .expect("id");
    wait_state(&addr, eval, "succeeded", 120);
    let _ = worker.0.kill();
    let _ = worker.0.wait();

    // The run page tells the disk it uses.
    let page_a = get(&addr, &format!("/api/v1/runs/{a}"));
    let disk = page_a["disk_bytes"].as_i64().expect("disk_bytes");
    let recording = page_a["recording"]["size"]
        .as_i64()
        .expect("recording size");
    assert!(disk > recording && recording > 0, "{disk} {recording}");
    let b_before = get(&addr, &format!("/api/v1/runs/{b}"));

    // Without the token: 401, nothing removed. Bad ids: 400 and 404.
    let anonymous = http(&addr, "DELETE", &format!("/api/v1/runs/{a}"), None, None);
    assert_eq!(anonymous.status, 401);
    let wrong = http(
        &addr,
        "DELETE",
        &format!("/api/v1/runs/{a}"),
        None,
        Some("nope"),
    );
    assert_eq!(wrong.status, 401);
    let bad = http(&addr, "DELETE", "/api/v1/runs/zero", None, Some(TOKEN));
    assert_eq!(bad.status, 400);
    let missing = http(&addr, "DELETE", "/api/v1/runs/98765", None, Some(TOKEN));
    assert_eq!(missing.status, 404);
    let not_a_run = http(
        &addr,
        "DELETE",
        &format!("/api/v1/runs/{eval}"),
        None,
        Some(TOKEN),
    );
    assert_eq!(not_a_run.status, 404);
    assert_eq!(files(&checkpoint_dir), stored);

    // Delete run a: its rows and files go, run b stays exactly as it was.
    let deleted = http(
        &addr,
        "DELETE",
        &format!("/api/v1/runs/{a}"),
        None,
        Some(TOKEN),
    );
    assert_eq!(
        deleted.status,
        200,
        "{}",
        String::from_utf8_lossy(&deleted.body)
    );
    assert_eq!(deleted.json()["deleted"], a);
    assert_eq!(deleted.json()["freed_bytes"], disk);
    for path in [
        format!("/api/v1/runs/{a}"),
        format!("/api/v1/jobs/{a}"),
        format!("/api/v1/jobs/{eval}"),
        format!("/api/v1/checkpoints/{final_a}"),
    ] {
        let gone = http(&addr, "GET", &path, None, Some(TOKEN));
        assert_eq!(gone.status, 404, "{path}");
    }
    let left = files(&checkpoint_dir);
    let b_files: BTreeSet<String> = left
        .iter()
        .filter(|f| f.starts_with(&format!("job{b}-")))
        .cloned()
        .collect();
    assert_eq!(left, b_files, "only run b's checkpoint files are left");
    assert_eq!(left.len(), checkpoint_ids(&addr, b).len());
    assert_eq!(
        files(&data.0.join("recordings")),
        BTreeSet::from([format!("job{b}.rrd")])
    );
    assert_eq!(get(&addr, &format!("/api/v1/runs/{b}")), b_before);
    let again = http(
        &addr,
        "DELETE",
        &format!("/api/v1/runs/{a}"),
        None,
        Some(TOKEN),
    );
    assert_eq!(again.status, 404);
}
