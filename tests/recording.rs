//! Rerun recordings end to end: `crm record` writes one episode of the shipped model and
//! reads it back; a training job and an evaluation job that ask for recordings store them with
//! the job (downloadable over REST) and they hold the entities and transition entries the
//! viewer shows; a job whose viewer is unreachable still succeeds; bad `record` settings are
//! refused naming the field.

mod support;

use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::Command;

use serde_json::{Value, json};
use support::{TempDir, crm, get, http, start_server, start_worker, wait_state};

/// `crm record --inspect PATH` as JSON, or why not.
fn try_inspect(path: &Path) -> Result<Value, String> {
    let out = Command::new(crm())
        .args(["record", "--inspect"])
        .arg(path)
        .output()
        .map_err(|e| format!("run crm record --inspect: {e}"))?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    serde_json::from_slice(&out.stdout).map_err(|e| format!("inspect prints JSON: {e}"))
}

fn inspect(path: &Path) -> Value {
    try_inspect(path).unwrap_or_else(|e| panic!("{e}"))
}

/// The entities every recorded episode holds (`/crm/transitions` only when the machine moved:
/// an untrained policy's episode may time out in `approach`).
fn assert_episode_entities(summary: &Value) {
    let entities = summary["entities"].as_object().expect("entities");
    for path in [
        "/world/table",
        "/world/object/part_0",
        "/world/hand/palm",
        "/world/hand/thumb/link_0",
        "/world/hand/index/link_2",
        "/world/hand/little/link_2",
        "/world/contacts",
        "/world/contacts/forces",
        "/world/grasp_location",
        "/crm/stage",
        "/crm/stage_index",
        "/crm/reward/intra",
        "/crm/reward/transition",
        "/crm/episode",
    ] {
        assert!(
            entities.contains_key(path),
            "{path} missing: {:?}",
            entities.keys()
        );
    }
    let palm = &entities["/world/hand/palm"];
    assert!(palm["rows"].as_u64().expect("rows") > 10);
    assert!(
        palm["timelines"]
            .as_array()
            .expect("timelines")
            .contains(&json!("step"))
    );
}

#[test]
fn crm_record_writes_an_episode_that_reads_back() {
    let dir = TempDir::new("record-cli");
    let out = dir.0.join("episode.rrd");
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/crm-ppo.safetensors");
    let run = Command::new(crm())
        .args([
            "record",
            "--task",
            "valve-twist",
            "--seed",
            "1",
            "--checkpoint",
        ])
        .arg(&model)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("run crm record");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: Value = serde_json::from_slice(&run.stdout).expect("JSON");
    assert_eq!(report["task"], "valve-twist");
    let summary = inspect(&out);
    assert_eq!(
        summary["recordings"].as_array().expect("recordings").len(),
        1
    );
    assert_eq!(summary["bytes"], report["bytes"]);
    assert_episode_entities(&summary);
    assert!(
        summary["entities"]
            .as_object()
            .expect("entities")
            .contains_key("/crm/transitions")
    );
    // Every transition of the episode is a text entry, in order, with event and reward.
    let transitions = report["transitions"].as_array().expect("transitions");
    let texts: Vec<&str> = summary["transitions"]
        .as_array()
        .expect("texts")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    assert!(!transitions.is_empty());
    assert_eq!(texts.len(), transitions.len(), "{texts:?}");
    for (text, t) in texts.iter().zip(transitions) {
        let expected = format!(
            "{} -> {} on {}, transition reward {:+.1}",
            t["from"].as_str().expect("from"),
            t["to"].as_str().expect("to"),
            t["event"].as_str().expect("event"),
            t["reward"].as_f64().expect("reward")
        );
        assert_eq!(*text, expected);
    }
    assert_eq!(summary["stages"][0], "approach");

    // Bad input: exit code 2, a message, nothing written.
    let refused = dir.0.join("refused.rrd");
    for (args, says) in [
        (
            vec!["--connect", "rerun+http://127.0.0.1:1/proxy"],
            "--connect",
        ),
        (vec!["--connect", "not a url"], "--connect"),
    ] {
        let run = Command::new(crm())
            .args(["record", "--checkpoint"])
            .arg(&model)
            .args(&args)
            .output()
            .expect("run crm record");
        assert_eq!(run.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&run.stderr).contains(says));
    }
    let not_rrd = dir.0.join("not.rrd");
    std::fs::write(&not_rrd, b"hello").expect("write");
    let run = Command::new(crm())
        .args(["record", "--inspect"])
        .arg(&not_rrd)
        .output()
        .expect("run");
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("not a rerun recording"));
    assert!(!refused.exists());
}

fn submit(addr: &str, body: &Value) -> Value {
    support::submit(addr, &body.to_string())
}

#[test]
fn jobs_store_their_recordings_with_the_run() {
    let data = TempDir::new("record-jobs");
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();
    let _worker = start_worker(&format!("http://{}", server.grpc), &[]);

    // Refused settings name the field, and nothing is queued.
    for (record, field) in [
        (json!({"connect": "nowhere"}), "record.connect"),
        (json!({"every": "often"}), "record.every"),
        (json!({"max_episodes": 100000}), "record.max_episodes"),
        (json!({"colour": 1}), "record"),
    ] {
        let body = json!({"kind": "train", "algorithm": "crm-ppo", "steps": 100, "record": record});
        let reply = http(&addr, "POST", "/api/v1/jobs", Some(&body.to_string()), None);
        assert_eq!(reply.status, 400);
        let error = reply.json();
        assert!(
            error["error"]["field"]
                .as_str()
                .expect("field")
                .starts_with(field),
            "{error}"
        );
    }
    assert_eq!(
        get(&addr, "/api/v1/jobs")["jobs"]
            .as_array()
            .expect("jobs")
            .len(),
        0
    );

    let train = submit(
        &addr,
        // Environment 0 runs 2,048 steps: at least three episodes of at most 600 steps, so the
        // first and the third are recorded and finished.
        &json!({"kind": "train", "algorithm": "crm-ppo", "task": "valve-twist", "steps": 4096,
                "envs": 2, "config": {"rollout_steps": 1024},
                "record": {"every": 2, "max_episodes": 2}}),
    );
    let id = train["id"].as_i64().expect("id");
    let done = wait_state(&addr, id, "succeeded", 300);
    let run = get(&addr, &format!("/api/v1/runs/{id}"));
    let recording = &run["recording"];
    assert_eq!(recording["episodes"], 2, "{recording}");
    let reply = http(
        &addr,
        "GET",
        &format!("/api/v1/jobs/{id}/recording"),
        None,
        None,
    );
    assert_eq!(reply.status, 200);
    assert_eq!(
        reply.body.len() as u64,
        recording["size"].as_u64().expect("size")
    );
    let file = data.0.join("train.rrd");
    std::fs::write(&file, &reply.body).expect("write");
    let summary = inspect(&file);
    // Two episodes of environment 0 and the training series.
    let recordings = summary["recordings"].as_array().expect("recordings");
    assert_eq!(recordings.len(), 3, "{recordings:?}");
    assert_episode_entities(&summary);
    let series = &summary["entities"]["/training/success_rate"];
    assert_eq!(series["rows"], 4, "one row per iteration: {summary}");
    assert!(
        series["timelines"]
            .as_array()
            .expect("timelines")
            .contains(&json!("iteration"))
    );

    // An evaluation records too.
    let checkpoint = done["result"]["checkpoint_id"]
        .as_i64()
        .expect("checkpoint");
    let eval = submit(
        &addr,
        &json!({"kind": "eval", "checkpoint_id": checkpoint, "episodes": 3, "task": "valve-twist",
                "record": {}}),
    );
    let eval_id = eval["id"].as_i64().expect("id");
    wait_state(&addr, eval_id, "succeeded", 300);
    let evaluation = get(&addr, &format!("/api/v1/evaluations/{eval_id}"));
    assert_eq!(evaluation["recording"]["episodes"], 3, "{evaluation}");

    // An unreachable viewer does not fail the job; nothing is recorded.
    let port = support::free_port();
    let live = submit(
        &addr,
        &json!({"kind": "eval", "checkpoint_id": checkpoint, "episodes": 2, "task": "valve-twist",
                "record": {"connect": format!("rerun+http://127.0.0.1:{port}/proxy")}}),
    );
    let live_id = live["id"].as_i64().expect("id");
    wait_state(&addr, live_id, "succeeded", 300);
    assert_eq!(support::recording_status(&addr, live_id), 404);
}

/// A viewer started in its own process group. pip's `rerun` is a Python wrapper that starts
/// the viewer binary as its child, so killing the wrapper alone (`support::Proc`) left the
/// viewer running after every test run: the whole group is killed instead.
struct Viewer(std::process::Child);

impl Drop for Viewer {
    fn drop(&mut self) {
        let group = format!("-{}", self.0.id());
        Command::new("kill")
            .args(["-KILL", "--", &group])
            .status()
            .ok();
        self.0.wait().ok();
    }
}

/// The rerun CLI of the pip package (`pip install rerun-sdk==0.36.3`): `RERUN_BIN`, else
/// `rerun` on the PATH.
fn rerun_cli() -> Option<std::path::PathBuf> {
    if let Some(path) = std::env::var_os("RERUN_BIN") {
        return Some(path.into());
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("rerun"))
        .find(|p| p.is_file())
}

#[test]
fn a_job_streams_live_to_a_viewer() {
    if std::env::var("CRM_SKIP_VIEWER").is_ok_and(|v| v == "1") {
        eprintln!("CRM_SKIP_VIEWER=1: the live viewer test is skipped");
        return;
    }
    let rerun = rerun_cli().expect(
        "the rerun CLI is needed: run the tests with `scripts/test`, which installs it (or `pip install rerun-sdk==0.36.3`, or set RERUN_BIN), or set CRM_SKIP_VIEWER=1",
    );
    let dir = TempDir::new("record-live");
    let saved = dir.0.join("live.rrd");
    let port = support::free_port();
    // A headless viewer: its gRPC proxy saves what it receives.
    let _viewer = Viewer(
        Command::new(rerun)
            .args(["--port", &port.to_string(), "--save"])
            .arg(&saved)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .process_group(0)
            .spawn()
            .expect("start rerun"),
    );
    support::wait_for(60, "the viewer to listen", || {
        std::net::TcpStream::connect(("127.0.0.1", port)).ok()
    });

    let data = TempDir::new("record-live-data");
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();
    let _worker = start_worker(&format!("http://{}", server.grpc), &[]);
    let job = submit(
        &addr,
        &json!({"kind": "train", "algorithm": "crm-ppo", "task": "valve-twist", "steps": 2048,
                "envs": 1, "config": {"rollout_steps": 1024},
                "record": {"every": 1, "max_episodes": 1,
                           "connect": format!("rerun+http://127.0.0.1:{port}/proxy")}}),
    );
    let id = job["id"].as_i64().expect("id");
    wait_state(&addr, id, "succeeded", 300);
    // Streamed, not stored.
    assert_eq!(support::recording_status(&addr, id), 404);
    // The viewer got the episode and the training series.
    let summary = support::wait_for(60, "the viewer to save the stream", || {
        let summary = try_inspect(&saved).ok()?;
        let entities = summary["entities"].as_object()?;
        (entities.contains_key("/crm/episode") && entities.contains_key("/training/success_rate"))
            .then_some(summary)
    });
    assert_episode_entities(&summary);
}
