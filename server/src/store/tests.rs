//! Store behaviour under concurrent writers (a coordinator's workers report while users act).

use super::*;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("crm-store-{name}-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    dir
}

fn new_job(spec: &str) -> NewJob<'_> {
    NewJob {
        kind: "train",
        algorithm: "ppo",
        task: None,
        spec,
        checkpoint_id: None,
        rerun_of: None,
        sweep_id: None,
    }
}

/// `delete_run` reads, then writes. With a deferred `BEGIN`, a worker's progress committed
/// in between made it fail with SQLITE_BUSY_SNAPSHOT ("database is locked", code 517): the
/// browser check deleting a run while a worker reported hit it. Write transactions now take
/// the lock first.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn deleting_runs_while_another_job_reports_never_fails() {
    let dir = temp_dir("busy");
    let store = Store::open(&dir).await.expect("open");
    let busy = store.create_job(new_job("{}")).await.expect("job").id;
    let mut runs = Vec::new();
    for _ in 0..40 {
        let id = store.create_job(new_job("{}")).await.expect("job").id;
        store.cancel_job(id).await.expect("cancel");
        runs.push(id);
    }
    let reporter = {
        let store = store.clone();
        tokio::spawn(async move {
            for k in 0..4000u64 {
                store
                    .set_phase(busy, "demonstrations", k, 4000)
                    .await
                    .expect("phase");
            }
        })
    };
    for id in runs {
        store
            .delete_run(id)
            .await
            .expect("deleted while another job reports");
    }
    reporter.await.expect("reporter");
    store.close().await;
    std::fs::remove_dir_all(&dir).ok();
}

/// A training job that starts from a checkpoint (`fine_tune` in its spec) keeps that
/// checkpoint from retention, and the run that made it cannot be deleted while the job waits.
#[tokio::test]
async fn a_checkpoint_a_queued_job_fine_tunes_from_is_kept_and_its_run_stays() {
    let dir = temp_dir("fine-tune");
    let store = Store::open(&dir).await.expect("open");
    let run = store.create_job(new_job("{}")).await.expect("run").id;
    let mut ids = Vec::new();
    for k in 0..3 {
        let file = format!("job{run}-{k}.safetensors");
        let checkpoint = NewCheckpoint {
            job: Some(run),
            algorithm: "ppo",
            steps: k,
            size: 1,
            file: &file,
            sha256: "",
            name: None,
        };
        ids.push(
            store
                .add_checkpoint(&checkpoint)
                .await
                .expect("checkpoint")
                .id,
        );
    }
    store.cancel_job(run).await.expect("cancel");
    let spec = format!(
        r#"{{"algorithm": "ppo", "steps": 10, "fine_tune": {}}}"#,
        ids[0]
    );
    let waiting = store.create_job(new_job(&spec)).await.expect("job").id;
    // Keeping the newest one, the oldest stays: the queued job starts from it.
    assert_eq!(store.prune_checkpoints(run, 1).await.expect("prune"), 1);
    assert!(store.checkpoint(ids[0]).await.is_ok());
    assert!(store.checkpoint(ids[1]).await.is_err());
    match store.delete_run(run).await {
        Err(StoreError::Conflict(why)) => assert!(why.contains(&waiting.to_string()), "{why}"),
        other => panic!("deleted a run a queued job starts from: {other:?}"),
    }
    store.cancel_job(waiting).await.expect("cancel");
    store
        .delete_run(run)
        .await
        .expect("deleted once nothing waits on it");
    store.close().await;
    std::fs::remove_dir_all(&dir).ok();
}

/// A worker holds one lease at a time: asking again while its job runs gets nothing, and the
/// next job goes to it once the first is no longer running.
#[tokio::test]
async fn a_worker_holds_one_lease_at_a_time() {
    let dir = temp_dir("one-lease");
    let store = Store::open(&dir).await.expect("open");
    let worker = store
        .register_worker("w", 2, "test", "secret-w")
        .await
        .expect("worker")
        .id;
    let other = store
        .register_worker("v", 2, "test", "secret-v")
        .await
        .expect("worker")
        .id;
    let first = store.create_job(new_job("{}")).await.expect("job").id;
    let second = store.create_job(new_job("{}")).await.expect("job").id;
    let leased = store
        .lease(&worker, "lease-a", 60_000)
        .await
        .expect("lease");
    assert_eq!(leased.map(|j| j.id), Some(first));
    assert!(
        store
            .lease(&worker, "lease-a", 60_000)
            .await
            .expect("lease")
            .is_none()
    );
    let leased = store.lease(&other, "lease-b", 60_000).await.expect("lease");
    assert_eq!(leased.map(|j| j.id), Some(second));
    store.close().await;
    std::fs::remove_dir_all(&dir).ok();
}

/// Evaluations are leased before training jobs queued earlier (a sweep's evaluation of a
/// finished run does not wait behind the sweep's other training runs); each kind in order.
#[tokio::test]
async fn evaluations_are_leased_before_training_jobs() {
    let dir = temp_dir("eval-first");
    let store = Store::open(&dir).await.expect("open");
    let worker = store
        .register_worker("w", 2, "test", "secret-w")
        .await
        .expect("worker")
        .id;
    let train = store.create_job(new_job("{}")).await.expect("job").id;
    let later_train = store.create_job(new_job("{}")).await.expect("job").id;
    let eval = |_: ()| NewJob {
        kind: "eval",
        ..new_job("{}")
    };
    let first_eval = store.create_job(eval(())).await.expect("job").id;
    let second_eval = store.create_job(eval(())).await.expect("job").id;
    let mut order = Vec::new();
    for k in 0..4 {
        let job = store
            .lease(&worker, &format!("lease-{k}"), 60_000)
            .await
            .expect("lease")
            .expect("a queued job");
        order.push(job.id);
        let hash = format!("lease-{k}");
        store
            .succeed(Lease::new(&worker, job.id, &hash), "{}")
            .await
            .expect("succeed");
    }
    assert_eq!(order, [first_eval, second_eval, train, later_train]);
    store.close().await;
    std::fs::remove_dir_all(&dir).ok();
}

/// A lease is its secret: a worker whose lease expired and whose job went to another worker
/// can no longer heartbeat, report or finish it, and a worker's secret matches only itself.
#[tokio::test]
async fn a_stale_or_foreign_lease_is_refused() {
    let dir = temp_dir("stale-lease");
    let store = Store::open(&dir).await.expect("open");
    let old = store
        .register_worker("old", 2, "test", "secret-old")
        .await
        .expect("worker")
        .id;
    let new = store
        .register_worker("new", 2, "test", "secret-new")
        .await
        .expect("worker")
        .id;
    assert!(
        store
            .worker_secret_matches(&old, "secret-old")
            .await
            .expect("query")
    );
    assert!(
        !store
            .worker_secret_matches(&old, "secret-new")
            .await
            .expect("query")
    );
    assert!(matches!(
        store.worker_secret_matches("nobody", "x").await,
        Err(StoreError::NotFound)
    ));
    let job = store.create_job(new_job("{}")).await.expect("job").id;
    let leased = store.lease(&old, "first", 0).await.expect("lease");
    assert_eq!(leased.map(|j| j.id), Some(job));
    let first = Lease {
        worker: &old,
        job,
        hash: "first",
    };
    assert!(store.holds(first).await.expect("holds"));
    let forged = Lease {
        worker: &new,
        job,
        hash: "first",
    };
    assert!(
        !store.holds(forged).await.expect("holds"),
        "another worker with the token"
    );
    let guessed = Lease {
        worker: &old,
        job,
        hash: "guess",
    };
    assert!(
        !store.holds(guessed).await.expect("holds"),
        "the worker without the token"
    );
    // The lease expires (ttl 0) and the job goes to the other worker under a new secret.
    std::thread::sleep(std::time::Duration::from_millis(5));
    let leased = store.lease(&new, "second", 60_000).await.expect("lease");
    assert_eq!(leased.map(|j| j.id), Some(job));
    assert!(!store.holds(first).await.expect("holds"));
    assert!(!store.heartbeat(first, 60_000).await.expect("heartbeat"));
    assert!(matches!(
        store.succeed(first, "{}").await,
        Err(StoreError::Conflict(state)) if state == "running"
    ));
    let second = Lease {
        worker: &new,
        job,
        hash: "second",
    };
    store
        .succeed(second, "{}")
        .await
        .expect("the current lease finishes");
    assert_eq!(store.job(job).await.expect("job").state, "succeeded");
    store.close().await;
    std::fs::remove_dir_all(&dir).ok();
}

/// An evaluation given back with its progress keeps the episode summaries stored up to then;
/// a lease lost after that (its worker killed) drops the summaries stored since, and an
/// evaluation never given back starts again with none.
#[tokio::test]
async fn an_evaluations_progress_keeps_its_episodes_and_a_lost_lease_drops_the_rest() {
    let dir = temp_dir("eval-progress");
    let store = Store::open(&dir).await.expect("open");
    let worker = store
        .register_worker("w", 2, "test", "secret-w")
        .await
        .expect("worker")
        .id;
    let eval = store
        .create_job(NewJob {
            kind: "eval",
            ..new_job("{}")
        })
        .await
        .expect("job")
        .id;
    store.lease(&worker, "a", 60_000).await.expect("lease");
    assert_eq!(store.eval_resume(eval).await.expect("resume"), None);
    for k in 0..3 {
        store
            .add_episode(eval, &format!("{{\"k\": {k}}}"), 200)
            .await
            .expect("episode");
    }
    store
        .release(Lease::new(&worker, eval, "a"), Some(r#"{"done": 3}"#))
        .await
        .expect("release");
    store.lease(&worker, "b", 0).await.expect("lease");
    assert_eq!(
        store.eval_resume(eval).await.expect("resume").as_deref(),
        Some(r#"{"done": 3}"#)
    );
    assert_eq!(store.episodes(eval).await.expect("episodes").len(), 3);
    // The second lease stores two more, then is lost (a lease of 0 ms expires at once).
    for k in 3..5 {
        store
            .add_episode(eval, &format!("{{\"k\": {k}}}"), 200)
            .await
            .expect("episode");
    }
    let again = store.lease(&worker, "c", 60_000).await.expect("lease");
    assert_eq!(again.map(|j| j.id), Some(eval));
    assert!(store.eval_resume(eval).await.expect("resume").is_some());
    assert_eq!(
        store.episodes(eval).await.expect("episodes").len(),
        3,
        "the lost lease's summaries are dropped"
    );
    // Another evaluation, never given back: a new lease starts it again with none.
    let other = store
        .create_job(NewJob {
            kind: "eval",
            ..new_job("{}")
        })
        .await
        .expect("job")
        .id;
    store
        .succeed(Lease::new(&worker, eval, "c"), "{}")
        .await
        .expect("succeed");
    store.lease(&worker, "d", 0).await.expect("lease");
    store.add_episode(other, "{}", 200).await.expect("episode");
    store.lease(&worker, "e", 60_000).await.expect("lease");
    assert_eq!(store.eval_resume(other).await.expect("resume"), None);
    assert!(store.episodes(other).await.expect("episodes").is_empty());
    store.close().await;
    std::fs::remove_dir_all(&dir).ok();
}
