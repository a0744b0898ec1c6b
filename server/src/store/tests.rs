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
