//! End-to-end tests of idempotent job submission (`Idempotency-Key` on POST /api/v1/jobs)
//! against the real `crm-server` on loopback with a temporary data folder: retries across a
//! `kill -9` of the coordinator create exactly one job per key.

mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use support::*;

/// A training submission, distinct per `n` (no worker runs: the jobs stay queued).
fn train(n: usize) -> String {
    format!(
        r#"{{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": {}, "envs": 1}}"#,
        1000 + n
    )
}

fn submit_with_key(addr: &str, key: &str, body: &str) -> std::io::Result<Reply> {
    try_http(
        addr,
        "POST",
        "/api/v1/jobs",
        Some(body),
        &[("Idempotency-Key", key)],
    )
}

fn job_count(addr: &str) -> usize {
    get(addr, "/api/v1/jobs?limit=10000")["jobs"]
        .as_array()
        .expect("jobs")
        .len()
}

#[test]
fn a_retried_key_returns_the_first_job_and_another_request_under_it_is_refused() {
    let data = TempDir::new("idem");
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();

    let first = submit_with_key(&addr, "run-42", &train(0)).expect("submit");
    assert_eq!(
        first.status,
        201,
        "{}",
        String::from_utf8_lossy(&first.body)
    );
    assert_eq!(first.header("idempotent-replayed"), None);
    let id = first.json()["id"].as_i64().expect("id");

    // The same request, with defaults written out, is the same request: replayed.
    let same = r#"{"kind": "train", "algorithm": "crm-ppo", "task": "mouse-press", "steps": 1000, "envs": 1, "seed": 0, "objective": "scripted"}"#;
    let again = submit_with_key(&addr, "run-42", same).expect("retry");
    assert_eq!(again.status, 201);
    assert_eq!(again.header("idempotent-replayed").as_deref(), Some("true"));
    assert_eq!(again.json()["id"], id);
    assert_eq!(again.json()["state"], "queued");

    // The job moves on; a replay shows it as it is now.
    let cancelled = http(
        &addr,
        "POST",
        &format!("/api/v1/jobs/{id}/cancel"),
        None,
        None,
    );
    assert_eq!(cancelled.status, 200);
    let later = submit_with_key(&addr, "run-42", &train(0)).expect("retry");
    assert_eq!(later.json()["id"], id);
    assert_eq!(later.json()["state"], "cancelled");

    // Another request under the key: 409 naming the header, nothing stored.
    let other = submit_with_key(&addr, "run-42", &train(1)).expect("other body");
    assert_eq!(other.status, 409);
    assert_eq!(other.json()["error"]["field"], "Idempotency-Key");
    assert_eq!(job_count(&addr), 1);

    // Malformed keys: 400 naming the header, nothing stored.
    for key in ["has space", &"k".repeat(256)] {
        let bad = submit_with_key(&addr, key, &train(2)).expect("bad key");
        assert_eq!(bad.status, 400, "{key:?}");
        assert_eq!(bad.json()["error"]["field"], "Idempotency-Key");
    }
    // An invalid body is refused before the key is looked at; the key stays free.
    let invalid =
        submit_with_key(&addr, "run-43", r#"{"kind": "train", "steps": 5}"#).expect("invalid body");
    assert_eq!(invalid.status, 400);
    assert_eq!(job_count(&addr), 1);
    let fresh = submit_with_key(&addr, "run-43", &train(3)).expect("fresh key");
    assert_eq!(fresh.status, 201);
    assert_ne!(fresh.json()["id"], id);
    assert_eq!(job_count(&addr), 2);
}

#[test]
fn retries_after_a_kill_9_create_exactly_one_job_per_key() {
    let data = TempDir::new("idem-kill");
    let mut server = start_server(&data.0, &[]);
    let addr = server.http.clone();

    // Eight submitters, each with its own keys, until the coordinator dies under them.
    let answered: Arc<Mutex<BTreeMap<String, i64>>> = Arc::default();
    let unanswered: Arc<Mutex<BTreeSet<(String, usize)>>> = Arc::default();
    let threads: Vec<_> = (0..8)
        .map(|t| {
            let (addr, answered, unanswered) = (addr.clone(), answered.clone(), unanswered.clone());
            std::thread::spawn(move || {
                for k in 0..10_000 {
                    let n = t * 10_000 + k;
                    let key = format!("key-{n}");
                    match submit_with_key(&addr, &key, &train(n)) {
                        Ok(reply) if reply.status == 201 => {
                            let id = reply.json()["id"].as_i64().expect("id");
                            answered.lock().expect("lock").insert(key, id);
                        }
                        _ => {
                            // No answer: the client cannot know whether the job exists.
                            unanswered.lock().expect("lock").insert((key, n));
                            return;
                        }
                    }
                }
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(1500));
    server.proc.0.kill().expect("kill -9 the coordinator");
    server.proc.0.wait().ok();
    for thread in threads {
        thread.join().expect("submitter");
    }
    let answered = answered.lock().expect("lock").clone();
    let unanswered = unanswered.lock().expect("lock").clone();
    assert!(
        answered.len() > 20,
        "only {} submits answered",
        answered.len()
    );
    assert_eq!(
        unanswered.len(),
        8,
        "each submitter stops at its first failure"
    );

    // Restart on the same data folder and retry every unanswered submit, and a few answered.
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();
    let mut ids = answered.clone();
    for (key, n) in &unanswered {
        let reply = submit_with_key(&addr, key, &train(*n)).expect("retry");
        assert_eq!(
            reply.status,
            201,
            "{}",
            String::from_utf8_lossy(&reply.body)
        );
        ids.insert(key.clone(), reply.json()["id"].as_i64().expect("id"));
    }
    for (key, id) in answered.iter().take(5) {
        let n: usize = key["key-".len()..].parse().expect("n");
        let reply = submit_with_key(&addr, key, &train(n)).expect("retry");
        assert_eq!(
            reply.json()["id"],
            *id,
            "{key} answered {id} before the kill"
        );
        assert_eq!(reply.header("idempotent-replayed").as_deref(), Some("true"));
    }

    // Exactly one job per key: as many jobs as keys, each key's job distinct.
    let distinct: BTreeSet<i64> = ids.values().copied().collect();
    assert_eq!(distinct.len(), ids.len(), "two keys share a job");
    assert_eq!(job_count(&addr), ids.len(), "jobs without a key, or twice");
}
