//! End-to-end tests of the training service: the real `crm-server` and `crm worker`
//! binaries on loopback ports with a temporary data folder, driven through REST and gRPC.

mod support;

use support::*;

const TRAIN: &str = r#"{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 4096, "seed": 3, "envs": 2, "config": {"rollout_steps": 1024, "learning_rate": 0.0003}}"#;

fn error_field(reply: &Reply) -> String {
    reply.json()["error"]["field"]
        .as_str()
        .unwrap_or("")
        .to_string()
}

#[test]
fn a_job_trains_on_a_worker_is_evaluated_and_survives_a_restart() {
    let data = TempDir::new("train");
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();
    let _worker = start_worker(
        &format!("http://{}", server.grpc),
        &["--checkpoint-every-s", "2"],
    );

    let job = submit(&addr, TRAIN);
    let id = job["id"].as_i64().expect("id");
    assert_eq!(job["state"], "queued");
    let done = wait_state(&addr, id, "succeeded", 240);
    assert_eq!(done["progress"], 1.0);
    assert!(done["worker_id"].as_str().is_some());

    // Metrics and a checkpoint are stored.
    let run = get(&addr, &format!("/api/v1/runs/{id}"));
    let metrics = run["metrics"].as_array().expect("metrics");
    assert_eq!(metrics.len(), 4, "one entry per iteration of 1024 steps");
    assert_eq!(metrics[3]["steps"], 4096);
    assert!(metrics[0]["data"]["stage_mix"].is_object());
    // Per-task training success: this run's one task, once its episodes end.
    let last = &metrics[3]["data"]["task_success"]["mouse-press"];
    assert!(
        last.as_f64().is_some_and(|s| (0.0..=1.0).contains(&s)),
        "{}",
        metrics[3]["data"]
    );
    let checkpoint = done["result"]["checkpoint_id"]
        .as_i64()
        .expect("checkpoint id");
    let meta = get(&addr, &format!("/api/v1/checkpoints/{checkpoint}"));
    assert_eq!(meta["steps"], 4096);
    let file = http(
        &addr,
        "GET",
        &format!("/api/v1/checkpoints/{checkpoint}/download"),
        None,
        None,
    );
    assert_eq!(file.status, 200);
    assert_eq!(file.body.len() as i64, meta["size"].as_i64().expect("size"));
    // A safetensors file: 8-byte header length, then a JSON header with our metadata.
    let header_len = u64::from_le_bytes(file.body[..8].try_into().expect("8 bytes")) as usize;
    let header = String::from_utf8_lossy(&file.body[8..8 + header_len]);
    assert!(header.contains("crm-grasp-checkpoint/1"), "{header}");

    // Evaluate that checkpoint remotely, the job given as an experiment document (stored in
    // the flat form that earlier clients send).
    let eval = submit(
        &addr,
        &format!(
            r#"{{"kind": "eval", "checkpoint_id": {checkpoint}, "env": {{"task": "mouse-press"}}, "run": {{"episodes": 3, "seed": 1}}}}"#
        ),
    );
    let eval_id = eval["id"].as_i64().expect("id");
    let evaluated = wait_state(&addr, eval_id, "succeeded", 240);
    assert_eq!(evaluated["spec"]["episodes"], 3, "{evaluated}");
    assert_eq!(evaluated["spec"]["task"], "mouse-press", "{evaluated}");
    let result = &evaluated["result"];
    assert_eq!(result["episodes"], 3);
    assert_eq!(result["per_objective"]["press"]["episodes"], 3);
    // Per task too, and every episode's ending (a failure with its cause) is counted.
    assert_eq!(result["per_task"]["mouse-press"]["episodes"], 3);
    assert_eq!(
        result["per_task"]["mouse-press"]["success_rate"],
        result["per_objective"]["press"]["success_rate"]
    );
    let ended: u64 = result["outcomes"]
        .as_object()
        .expect("outcomes")
        .iter()
        .map(|(outcome, n)| {
            assert!(outcome != "failure", "a failure names its cause: {outcome}");
            n.as_u64().expect("count")
        })
        .sum();
    assert_eq!(ended, 3);
    // One task: its row counts the same endings.
    assert_eq!(
        result["per_task"]["mouse-press"]["outcomes"],
        result["outcomes"]
    );
    assert!(result["success_rate"].as_f64().is_some());
    // The paper's protocol is the default; the report says so and gives simulated time.
    assert_eq!(result["objective"], "scripted");
    assert!(result["mean_sim_seconds"].as_f64().expect("seconds") > 0.0);
    let listed = get(&addr, "/api/v1/evaluations");
    assert_eq!(listed["evaluations"][0]["id"], eval_id);
    let run = get(&addr, &format!("/api/v1/runs/{id}"));
    assert_eq!(run["evaluations"][0]["id"], eval_id);
    assert_eq!(
        run["episodes"].as_array().map(Vec::len),
        Some(0),
        "training sends no episode summaries"
    );
    let workers = get(&addr, "/api/v1/workers");
    assert_eq!(workers["workers"][0]["alive"], true);

    // A job that clones the oracle before PPO (a fresh lease runs the imitation first).
    let cloned = submit(
        &addr,
        r#"{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 64, "seed": 3, "envs": 1, "config": {"rollout_steps": 64}, "imitation": {"episodes": 4, "epochs": 40}}"#,
    );
    let cloned_id = cloned["id"].as_i64().expect("id");
    let done = wait_state(&addr, cloned_id, "succeeded", 240);
    assert_eq!(done["spec"]["imitation"]["episodes"], 4, "{done}");
    let checkpoint_id = done["result"]["checkpoint_id"].as_i64().expect("id");
    let eval = submit(
        &addr,
        &format!(
            r#"{{"kind": "eval", "checkpoint_id": {checkpoint_id}, "episodes": 3, "task": "mouse-press", "seed": 1, "deterministic": true}}"#
        ),
    );
    let evaluated = wait_state(&addr, eval["id"].as_i64().expect("id"), "succeeded", 240);
    // Its deterministic palm action is the mean cloning fit, all a press needs (sampled at
    // the start's noise, std 1, a 64-step clone presses in about a third of its episodes).
    assert!(
        evaluated["result"]["success_rate"].as_f64().expect("rate") > 0.0,
        "the clone presses: {}",
        evaluated["result"]
    );
    // A job may start from a stored checkpoint (`fine_tune`) and teach it one task, the
    // other tasks anchored by the starting policy's own episodes.
    let tuned = submit(
        &addr,
        &format!(
            r#"{{"kind": "train", "algorithm": "crm-ppo", "tasks": ["mouse-press", "stapler-press"], "steps": 64, "seed": 3, "envs": 1, "config": {{"rollout_steps": 64}}, "fine_tune": {checkpoint_id}, "start_log_std": -2.3, "imitation": {{"episodes": 2, "epochs": 2, "tasks": ["stapler-press"], "shifts": {{"stapler-press": [0, 0, 0.002]}}, "stages": ["grasp"], "anchor_episodes": 2}}}}"#
        ),
    );
    let tuned = wait_state(&addr, tuned["id"].as_i64().expect("id"), "succeeded", 240);
    assert_eq!(tuned["result"]["fine_tuned_from"], checkpoint_id, "{tuned}");
    assert_eq!(tuned["spec"]["imitation"]["anchor_episodes"], 2, "{tuned}");
    assert_eq!(tuned["spec"]["start_log_std"], -2.3, "{tuned}");
    for (body, status) in [
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "fine_tune": 0}"#.to_string(),
            400,
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "fine_tune": 99999}"#
                .to_string(),
            404,
        ),
        (
            format!(
                r#"{{"kind": "train", "algorithm": "lppo", "steps": 10, "fine_tune": {checkpoint_id}}}"#
            ),
            409,
        ),
    ] {
        let reply = http(&addr, "POST", "/api/v1/jobs", Some(&body), None);
        assert_eq!(reply.status, status, "{body}: {}", reply.json());
        assert_eq!(error_field(&reply), "fine_tune", "{body}");
    }

    // Refused requests change nothing.
    let before = get(&addr, "/api/v1/jobs");
    let cases = [
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": -1}"#,
            "steps",
        ),
        (
            r#"{"kind": "train", "algorithm": "dqn", "steps": 10}"#,
            "algorithm",
        ),
        (r#"{"kind": "train", "algorithm": "lppo"}"#, "steps"),
        (
            r#"{"kind": "train", "algorithm": "crm-sac", "steps": 10, "sac": {"tau": 2}}"#,
            "sac.tau",
        ),
        (
            r#"{"kind": "train", "algorithm": "lppo", "steps": 10, "task": "nope"}"#,
            "task",
        ),
        (
            r#"{"kind": "train", "algorithm": "lppo", "steps": 10, "config": {"gamma": 3}}"#,
            "config.gamma",
        ),
        (
            r#"{"kind": "train", "algorithm": "lppo", "steps": 10, "config": {"gama": 0.9}}"#,
            "config.gama",
        ),
        (
            r#"{"kind": "train", "algorithm": "lppo", "steps": 10, "topology": "claw"}"#,
            "topology",
        ),
        (
            r#"{"kind": "train", "algorithm": "lppo", "steps": 10, "tasks": ["mug-wrap", "nope"]}"#,
            "tasks[1]",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "imitation": {"episodes": 0}}"#,
            "imitation.episodes",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "imitation": {"episodes": 5, "noise": 2}}"#,
            "imitation.noise",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-sac", "steps": 10, "imitation": {"episodes": 5}}"#,
            "imitation",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "imitation": {"episodes": 5, "tasks": ["mug-wrap", "nope"]}}"#,
            "imitation.tasks[1]",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "imitation": {"episodes": 5, "shifts": {"nope": [0, 0, 0]}}}"#,
            "imitation.shifts",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "imitation": {"episodes": 5, "stages": ["grasp", "success"]}}"#,
            "imitation.stages",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "imitation": {"episodes": 5, "shifts": {"mug-wrap": [0.1000000000000001, 0, 0]}}}"#,
            "imitation.shifts",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "imitation": {"episodes": 5, "anchor_episodes": 100001}}"#,
            "imitation.anchor_episodes",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "start_log_std": -5.5}"#,
            "start_log_std",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-sac", "steps": 10, "start_log_std": -1}"#,
            "start_log_std",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "objective": "telekinesis"}"#,
            "objective",
        ),
        (
            r#"{"kind": "eval", "checkpoint_id": 1, "objective": 3}"#,
            "objective",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "hold_s": 0}"#,
            "hold_s",
        ),
        (
            r#"{"kind": "eval", "checkpoint_id": 1, "hold_s": 60}"#,
            "hold_s",
        ),
        // One f64 step past a bound (schemathesis's find: an f32 field read 8 for this).
        (
            r#"{"kind": "train", "algorithm": "ppo", "steps": 1, "hold_s": 8.000000000000002}"#,
            "hold_s",
        ),
        (
            r#"{"kind": "eval", "checkpoint_id": 1, "hold_s": 0.09999999999999999}"#,
            "hold_s",
        ),
        (
            r#"{"kind": "train", "algorithm": "lppo", "steps": 10, "config": {"gamma": 1.0000000000000002}}"#,
            "config.gamma",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-sac", "steps": 10, "sac": {"early_stop_success": 1.0000000000000002}}"#,
            "sac.early_stop_success",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "imitation": {"episodes": 5, "noise": 1.0000000000000002}}"#,
            "imitation.noise",
        ),
        (
            r#"{"kind": "train", "algorithm": "crm-ppo", "steps": 10, "start_log_std": -1, "config": {"init_log_std": -1}}"#,
            "start_log_std",
        ),
        // The experiment document names each refused field where it holds it.
        (
            r#"{"kind": "train", "algorithm": {"name": "lppo", "config": {"gamma": 2}}, "run": {"steps": 10}}"#,
            "algorithm.config.gamma",
        ),
        (
            r#"{"kind": "train", "algorithm": {"name": "crm-ppo"}, "env": {"tasks": ["mug-wrap", "nope"]}, "run": {"steps": 10}}"#,
            "env.tasks[1]",
        ),
        (
            r#"{"kind": "train", "algorithm": {"name": "crm-ppo"}, "run": {"steps": 10, "imitation": {"episodes": 5, "stages": ["grasp", "success"]}}}"#,
            "run.imitation.stages",
        ),
        (
            r#"{"kind": "train", "algorithm": {"name": "crm-ppo"}, "env": {"world": "mars"}, "run": {"steps": 10}}"#,
            "env.world",
        ),
        (
            r#"{"kind": "train", "algorithm": {"name": "crm-ppo"}, "run": {"steps": 0}}"#,
            "run.steps",
        ),
        (
            r#"{"kind": "eval", "checkpoint_id": 1, "env": {"hold_s": 60}, "run": {}}"#,
            "env.hold_s",
        ),
        (r#"{"kind": "fly"}"#, "kind"),
        ("not json", "body"),
    ];
    for (body, field) in cases {
        let reply = http(&addr, "POST", "/api/v1/jobs", Some(body), None);
        assert_eq!(reply.status, 400, "{body}");
        assert_eq!(error_field(&reply), field, "{body}: {}", reply.json());
    }
    // An evaluation of a checkpoint that does not exist: 404 naming the field.
    let missing = http(
        &addr,
        "POST",
        "/api/v1/jobs",
        Some(r#"{"kind": "eval", "checkpoint_id": 999}"#),
        None,
    );
    assert_eq!(missing.status, 404);
    assert_eq!(error_field(&missing), "checkpoint_id");
    assert_eq!(
        http(&addr, "GET", "/api/v1/jobs/12345", None, None).status,
        404
    );
    assert_eq!(
        http(&addr, "GET", "/api/v1/jobs/abc", None, None).status,
        400
    );
    let conflict = http(
        &addr,
        "POST",
        &format!("/api/v1/jobs/{id}/cancel"),
        None,
        None,
    );
    assert_eq!(conflict.status, 409);
    assert_eq!(conflict.json()["error"]["code"], "conflict");
    let huge = format!(r#"{{"kind": "train", "pad": "{}"}}"#, "x".repeat(400_000));
    assert_eq!(
        http(&addr, "POST", "/api/v1/jobs", Some(&huge), None).status,
        413
    );
    assert_eq!(get(&addr, "/api/v1/jobs"), before);

    // Restart the coordinator on the same data: everything is still there.
    let metrics_before = get(&addr, &format!("/api/v1/runs/{id}/metrics"));
    drop(server);
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();
    assert_eq!(get(&addr, "/api/v1/jobs"), before);
    assert_eq!(
        get(&addr, &format!("/api/v1/runs/{id}/metrics")),
        metrics_before
    );
    let file_again = http(
        &addr,
        "GET",
        &format!("/api/v1/checkpoints/{checkpoint}/download"),
        None,
        None,
    );
    assert_eq!(file_again.body, file.body);
    let openapi = get(&addr, "/api/v1/openapi.json");
    assert!(openapi["paths"]["/api/v1/jobs"]["post"].is_object());
}

#[test]
fn a_killed_workers_job_is_requeued_and_resumed_from_its_checkpoint() {
    let data = TempDir::new("requeue");
    let server = start_server(
        &data.0,
        &["--lease-ttl-s", "3", "--heartbeat-interval-s", "1"],
    );
    let addr = server.http.clone();
    let grpc = format!("http://{}", server.grpc);
    let mut first = start_worker(&grpc, &["--checkpoint-every-s", "1", "--name", "first"]);
    // mouse-press is easy under the paper's protocol: keep the early stop from ending the
    // job before the kill.
    let body = TRAIN.replace("4096", "40960").replace(
        r#""learning_rate""#,
        r#""early_stop_window": 1000000, "learning_rate""#,
    );
    let id = submit(&addr, &body)["id"].as_i64().expect("id");
    // Kill the first worker once it has uploaded a checkpoint.
    let saved = wait_for(240, "a first checkpoint", || {
        let list = get(&addr, &format!("/api/v1/checkpoints?job_id={id}"));
        list["checkpoints"][0]["steps"].as_i64()
    });
    first.0.kill().expect("kill");
    first.0.wait().ok();
    // The lease runs out and the job goes back to the queue.
    wait_state(&addr, id, "queued", 30);
    let _second = start_worker(&grpc, &["--checkpoint-every-s", "30", "--name", "second"]);
    let done = wait_state(&addr, id, "succeeded", 300);
    assert_eq!(done["attempts"], 2);
    let resumed = done["result"]["resumed_from_steps"]
        .as_i64()
        .expect("resumed");
    assert!(
        resumed >= saved,
        "resumed from {resumed}, a checkpoint at {saved} existed"
    );
    assert_eq!(done["result"]["steps"], 40960);
    let workers = get(&addr, "/api/v1/workers");
    let names = worker_names(&workers);
    assert_eq!(names, ["first", "second"]);
}

#[test]
fn tokens_guard_workers_and_every_call() {
    let data = TempDir::new("token");
    let server = start_server(&data.0, &["--token", "s3cret"]);
    let addr = server.http.clone();
    let reply = http(&addr, "POST", "/api/v1/jobs", Some(TRAIN), None);
    assert_eq!(reply.status, 401);
    assert_eq!(error_field(&reply), "authorization");
    let reply = http(&addr, "POST", "/api/v1/jobs", Some(TRAIN), Some("wrong"));
    assert_eq!(reply.status, 401);
    // Reads need the token too: none, a wrong one or a prefix of it gets 401; GET and HEAD
    // alike. Only `/healthz` and the dashboard's pages answer without one.
    for token in [None, Some("wrong"), Some("s3cre")] {
        for method in ["GET", "HEAD"] {
            let reply = http(&addr, method, "/api/v1/jobs", None, token);
            assert_eq!(reply.status, 401, "{method} with {token:?}");
        }
    }
    assert_eq!(http(&addr, "GET", "/healthz", None, None).status, 200);
    assert_eq!(http(&addr, "GET", "/", None, None).status, 200);
    assert_eq!(
        http(&addr, "GET", "/runs/999", None, None).status,
        200,
        "no lookup without a token"
    );
    assert_eq!(
        get(&addr, "/api/v1/jobs")["jobs"].as_array().map(Vec::len),
        Some(0)
    );
    let reply = http(&addr, "POST", "/api/v1/jobs", Some(TRAIN), Some("s3cret"));
    assert_eq!(reply.status, 201);
    assert_eq!(
        http(&addr, "HEAD", "/api/v1/jobs", None, Some("s3cret")).status,
        200
    );
    // A worker refused at registration exits 2 with the coordinator's reason: a wrong token,
    // or a name that would read otherwise than it is (a right-to-left override).
    let refused = |args: &[&str]| {
        let out = std::process::Command::new(crm())
            .args([
                "worker",
                "--coordinator",
                &format!("http://{}", server.grpc),
            ])
            .args(args)
            .output()
            .expect("run worker");
        assert_eq!(out.status.code(), Some(2));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let stderr = refused(&["--token", "wrong"]);
    assert!(stderr.contains("refused"), "{stderr}");
    let stderr = refused(&["--token", "s3cret", "--name", "gpu\u{202E}1"]);
    assert!(
        stderr.contains("name") && stderr.contains("bidirectional"),
        "{stderr}"
    );
    assert_eq!(
        get(&addr, "/api/v1/workers")["workers"]
            .as_array()
            .map(Vec::len),
        Some(0)
    );
    let job = get(&addr, "/api/v1/jobs")["jobs"][0].clone();
    assert_eq!(job["state"], "queued");
}

#[test]
fn a_job_building_demonstrations_shows_its_phase_and_can_be_cancelled_in_it() {
    let data = TempDir::new("phase");
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();
    let _worker = start_worker(&format!("http://{}", server.grpc), &[]);
    let job = submit(
        &addr,
        r#"{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 64, "seed": 1, "envs": 1, "imitation": {"episodes": 20000, "epochs": 1}}"#,
    );
    let id = job["id"].as_i64().expect("id");
    // The oracle's episodes are counted while they run: some done, not all.
    let phase = wait_for(120, "a demonstrations phase under way", || {
        let job = get(&addr, &format!("/api/v1/jobs/{id}"));
        let phase = &job["phase"];
        let done = phase["done"].as_u64().unwrap_or(0);
        (phase["name"] == "demonstrations" && done > 0 && done < 20000).then(|| phase.clone())
    });
    assert_eq!(phase["total"], 20000, "{phase}");
    let run = get(&addr, &format!("/api/v1/runs/{id}"));
    assert_eq!(run["run"]["phase"]["name"], "demonstrations");
    // Cancelling stops the phase: the job ends cancelled, with no training step taken.
    let cancelled = http(
        &addr,
        "POST",
        &format!("/api/v1/jobs/{id}/cancel"),
        None,
        None,
    );
    assert_eq!(cancelled.status, 200);
    let done = wait_state(&addr, id, "cancelled", 60);
    assert_eq!(done["steps"], 0, "{done}");
    // The worker is free again: a job after it runs.
    let next = submit(
        &addr,
        r#"{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 64, "seed": 2, "envs": 1, "config": {"rollout_steps": 64}}"#,
    );
    wait_state(&addr, next["id"].as_i64().expect("id"), "succeeded", 120);
}

/// Reads what the coordinator sends on `stream` until it closes it (or 8 s pass); returns
/// the text and whether it closed.
fn until_closed(stream: &mut std::net::TcpStream) -> (String, bool) {
    use std::io::Read;
    stream
        .set_read_timeout(Some(std::time::Duration::from_secs(8)))
        .expect("timeout");
    let mut text = Vec::new();
    let mut buf = [0u8; 1024];
    loop {
        match stream.read(&mut buf) {
            Ok(0) => return (String::from_utf8_lossy(&text).into_owned(), true),
            Ok(n) => text.extend(&buf[..n]),
            Err(err) if err.kind() == std::io::ErrorKind::ConnectionReset => {
                return (String::from_utf8_lossy(&text).into_owned(), true);
            }
            Err(_) => return (String::from_utf8_lossy(&text).into_owned(), false),
        }
    }
}

/// Connections are bounded in time and number: a request whose headers never end, and a
/// connection that sends nothing (REST or gRPC), are closed after their timeouts; one beyond the cap is
/// answered 503 with `Retry-After` and closed, and the coordinator answers again once the
/// others are gone.
#[test]
fn connections_are_bounded_in_time_and_number() {
    use std::io::Write;
    use std::net::TcpStream;
    let data = TempDir::new("hygiene");
    let server = start_server(
        &data.0,
        &[
            "--max-connections",
            "3",
            "--header-timeout-s",
            "1",
            "--idle-timeout-s",
            "2",
        ],
    );
    let addr = server.http.clone();
    let started = std::time::Instant::now();
    let mut slow = TcpStream::connect(&addr).expect("connect");
    slow.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
        .expect("half a request");
    let mut silent = TcpStream::connect(&addr).expect("connect");
    let mut third = TcpStream::connect(&addr).expect("connect");
    // A gRPC connection that sends nothing is closed when idle too.
    let mut grpc_silent = TcpStream::connect(&server.grpc).expect("connect");
    std::thread::sleep(std::time::Duration::from_millis(200));
    let mut beyond = TcpStream::connect(&addr).expect("connect");
    let (reply, closed) = until_closed(&mut beyond);
    assert!(closed, "{reply}");
    assert!(reply.starts_with("HTTP/1.1 503"), "{reply}");
    assert!(reply.to_lowercase().contains("retry-after: 1"), "{reply}");
    assert!(reply.contains("\"field\":\"connection\""), "{reply}");
    for stream in [&mut slow, &mut silent, &mut third, &mut grpc_silent] {
        let (_, closed) = until_closed(stream);
        assert!(closed, "a stalled connection stays open");
    }
    assert!(started.elapsed() < std::time::Duration::from_secs(6));
    assert_eq!(get(&addr, "/healthz")["status"], "ok");
}

/// Event streams are capped: with `--max-event-streams 1` a second stream is answered 503 with
/// `Retry-After`, naming `events`, while the first stays open.
#[test]
fn event_streams_beyond_the_cap_are_answered_503() {
    use std::io::{Read, Write};
    let data = TempDir::new("streams");
    let server = start_server(&data.0, &["--max-event-streams", "1"]);
    let addr = server.http.clone();
    let mut first = std::net::TcpStream::connect(&addr).expect("connect");
    write!(first, "GET /api/v1/events HTTP/1.1\r\nHost: {addr}\r\n\r\n").expect("request");
    first
        .set_read_timeout(Some(std::time::Duration::from_secs(10)))
        .expect("timeout");
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        first
            .read_exact(&mut byte)
            .expect("the first stream's head");
        head.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&head);
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    let second = http(&addr, "GET", "/api/v1/events", None, None);
    assert_eq!(second.status, 503);
    assert_eq!(second.header("retry-after").as_deref(), Some("5"));
    assert_eq!(second.json()["error"]["field"], "events");
    drop(first);
}
