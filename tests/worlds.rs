//! Worlds through the service: the coordinator lists the built-in world and those under
//! `--worlds`, refuses an unknown world naming the field and stores nothing, a worker with the
//! same `--worlds` trains in the test world, and evaluating that checkpoint in the built-in
//! world fails with the reason.

mod support;

use std::path::Path;
use std::process::Command;

use support::*;

#[test]
fn jobs_name_a_world_that_workers_run_and_checkpoints_keep_to() {
    let tmp = TempDir::new("worlds-service");
    // DIR/world is the test world, DIR/assets its hand: the coordinator's --worlds is DIR.
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/make-test-world");
    let status = Command::new("python3")
        .arg(&script)
        .arg(&tmp.0)
        .status()
        .expect("python3 runs scripts/make-test-world");
    assert!(status.success());
    let worlds = tmp.0.to_str().expect("utf-8 path");
    let data = tmp.0.join("data");
    let assets = tmp.0.join("assets");
    let env = [("CRM_ASSETS", assets.as_path())];
    let server = start_server_with(&data, &["--worlds", worlds], &env);
    let grpc = format!("http://{}", server.grpc);
    let addr = server.http.clone();

    let listed = get(&addr, "/api/v1/worlds");
    let names: Vec<&str> = listed["worlds"]
        .as_array()
        .expect("worlds")
        .iter()
        .filter_map(|w| w["name"].as_str())
        .collect();
    // `world4/` is the same world with a four-finger hand.
    assert_eq!(names, ["crm", "test-hand", "test-hand4"]);
    assert_eq!(listed["worlds"][1]["tasks"], 3);
    let tasks = get(&addr, "/api/v1/tasks?world=test-hand");
    assert_eq!(tasks["tasks"].as_array().map(Vec::len), Some(3));
    let openapi = get(&addr, "/api/v1/openapi.json");
    let world_enum =
        &openapi["components"]["schemas"]["EvalFlatRequest"]["properties"]["world"]["enum"];
    assert_eq!(
        world_enum,
        &serde_json::json!(["crm", "test-hand", "test-hand4", null])
    );
    // The experiment document's `env` too.
    let document = &openapi["components"]["schemas"]["TrainPpoDocument"]["properties"];
    assert_eq!(&document["env"]["properties"]["world"]["enum"], world_enum);
    // Every world's task ids name the tasks and the palm shifts a cloning may give.
    let imitation = &openapi["components"]["schemas"]["ImitationSpec"]["properties"];
    let ids: Vec<&str> = tasks["tasks"]
        .as_array()
        .expect("tasks")
        .iter()
        .filter_map(|t| t["id"].as_str())
        .chain(["mouse-press"])
        .collect();
    for id in ids {
        assert!(
            imitation["shifts"]["properties"][id]["$ref"].is_string(),
            "{id}: {imitation}"
        );
        assert!(
            imitation["tasks"]["items"]["enum"]
                .as_array()
                .is_some_and(|e| e.iter().any(|v| v == id)),
            "{id}"
        );
    }

    // Refusals name the field and store nothing.
    for (body, field) in [
        (
            r#"{"kind":"train","algorithm":"crm-ppo","steps":256,"world":"atlantis"}"#,
            "world",
        ),
        (
            r#"{"kind":"train","algorithm":"crm-ppo","steps":256,"world":7}"#,
            "world",
        ),
        // A task of the built-in world is not one of the test world's.
        (
            r#"{"kind":"train","algorithm":"crm-ppo","steps":256,"world":"test-hand","task":"mouse-press"}"#,
            "task",
        ),
    ] {
        let reply = http(&addr, "POST", "/api/v1/jobs", Some(body), None);
        assert!(
            (400..500).contains(&reply.status),
            "{body}: {}",
            reply.status
        );
        assert_eq!(reply.json()["error"]["field"], field, "{body}");
    }
    assert_eq!(
        get(&addr, "/api/v1/jobs")["jobs"].as_array().map(Vec::len),
        Some(0)
    );

    let worker = start_worker_with(&grpc, &["--worlds", worlds, "--envs", "2"], &env);
    let job = submit(
        &addr,
        r#"{"kind":"train","algorithm":"crm-ppo","steps":256,"seed":1,"world":"test-hand",
            "tasks":["blocks-lift","mug-wrap"],
            "config":{"rollout_steps":128,"minibatch_size":64,"hidden":[32]}}"#,
    );
    let id = job["id"].as_i64().expect("id");
    let done = wait_state(&addr, id, "succeeded", 120);
    assert_eq!(done["steps"], 256, "{done}");
    let list = get(&addr, &format!("/api/v1/checkpoints?job_id={id}"));
    let checkpoint = list["checkpoints"]
        .as_array()
        .and_then(|c| c.iter().max_by_key(|c| c["steps"].as_i64()))
        .and_then(|c| c["id"].as_i64())
        .expect("a final checkpoint");

    // In its own world the checkpoint evaluates; in the built-in one it is refused.
    let ok = submit(
        &addr,
        &format!(
            r#"{{"kind":"eval","checkpoint_id":{checkpoint},"episodes":2,"world":"test-hand"}}"#
        ),
    );
    wait_state(&addr, ok["id"].as_i64().expect("id"), "succeeded", 120);
    let refused = submit(
        &addr,
        &format!(r#"{{"kind":"eval","checkpoint_id":{checkpoint},"episodes":2}}"#),
    );
    let failed = wait_state(&addr, refused["id"].as_i64().expect("id"), "failed", 120);
    let error = failed["error"].as_str().unwrap_or_default();
    assert!(
        error.contains("test-hand") && error.contains("world"),
        "{failed}"
    );
    drop(worker);
}
