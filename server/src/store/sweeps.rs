//! Sweeps: a grid of training jobs from one base spec and the axes it varies, stored with
//! the sweep's request. The jobs are created together or not at all; when a training job of
//! a sweep with an evaluation spec succeeds, the evaluation of its final checkpoint is queued
//! in the same transaction, so a crash between the two cannot lose it.

use serde::Serialize;

use super::{
    JOB_COLUMNS, Job, Lease, NewJob, Result, Store, StoreError, as_json, finish_row, insert_job,
    now_ms,
};

/// A sweep as stored.
#[derive(Clone, Debug, Serialize)]
pub struct SweepRow {
    pub id: i64,
    pub name: String,
    /// The validated request: `{"name", "base", "axes", "eval"}`.
    #[serde(serialize_with = "as_json")]
    pub spec: String,
    pub created_at: i64,
}

crate::store::from_row!(SweepRow {
    id,
    name,
    spec,
    created_at
});

impl Store {
    /// Stores a sweep and queues its jobs, all in one transaction.
    pub async fn create_sweep(
        &self,
        name: &str,
        spec: &str,
        jobs: &[NewJob<'_>],
    ) -> Result<SweepRow> {
        let mut tx = self.write_tx().await?;
        let id: i64 = sqlx::query_scalar(
            "INSERT INTO sweeps (name, spec, created_at) VALUES (?, ?, ?) RETURNING id",
        )
        .bind(name)
        .bind(spec)
        .bind(now_ms())
        .fetch_one(&mut *tx)
        .await?;
        for job in jobs {
            let job = NewJob {
                sweep_id: Some(id),
                ..*job
            };
            insert_job(&mut *tx, &job).await?;
        }
        tx.commit().await?;
        self.sweep(id).await
    }

    pub async fn sweep(&self, id: i64) -> Result<SweepRow> {
        sqlx::query_as("SELECT * FROM sweeps WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .ok_or(StoreError::NotFound)
    }

    /// Sweeps, newest first.
    pub async fn sweeps(&self, limit: i64) -> Result<Vec<SweepRow>> {
        Ok(
            sqlx::query_as("SELECT * FROM sweeps ORDER BY id DESC LIMIT ?")
                .bind(limit)
                .fetch_all(&self.pool)
                .await?,
        )
    }

    /// A sweep's jobs (training and evaluation), oldest first.
    pub async fn sweep_jobs(&self, id: i64) -> Result<Vec<Job>> {
        Ok(sqlx::query_as(&format!(
            "SELECT {JOB_COLUMNS} FROM jobs WHERE sweep_id = ? ORDER BY id"
        ))
        .bind(id)
        .fetch_all(&self.pool)
        .await?)
    }

    /// Cancels a sweep's queued and running jobs; returns how many.
    pub async fn cancel_sweep(&self, id: i64) -> Result<u64> {
        self.sweep(id).await?;
        let done = sqlx::query("UPDATE jobs SET state = 'cancelled', finished_at = ?, lease_expires_at = NULL WHERE sweep_id = ? AND state IN ('queued', 'running')")
            .bind(now_ms())
            .bind(id)
            .execute(&self.pool)
            .await?;
        Ok(done.rows_affected())
    }

    /// Ends a job the worker holds as succeeded with `result`. A training job of a sweep
    /// whose request has an evaluation spec queues the evaluation of its final checkpoint
    /// (`result.checkpoint_id`) in the same transaction; returns that job's id.
    pub async fn succeed(&self, lease: Lease<'_>, result: &str) -> Result<Option<i64>> {
        let job = lease.job;
        let mut tx = self.write_tx().await?;
        finish_row(&mut tx, lease, "succeeded", Some(result), None).await?;
        let (kind, sweep): (String, Option<i64>) =
            sqlx::query_as("SELECT kind, sweep_id FROM jobs WHERE id = ?")
                .bind(job)
                .fetch_one(&mut *tx)
                .await?;
        let mut follow = None;
        if let (Some(sweep), "train") = (sweep, kind.as_str()) {
            let spec: String = sqlx::query_scalar("SELECT spec FROM sweeps WHERE id = ?")
                .bind(sweep)
                .fetch_one(&mut *tx)
                .await?;
            let spec: serde_json::Value = serde_json::from_str(&spec).unwrap_or_default();
            let result: serde_json::Value = serde_json::from_str(result).unwrap_or_default();
            let checkpoint = result["checkpoint_id"].as_i64();
            let eval = &spec["eval"];
            if let (Some(checkpoint), Some(_)) = (checkpoint, eval.as_object()) {
                let algorithm: Option<String> =
                    sqlx::query_scalar("SELECT algorithm FROM checkpoints WHERE id = ?")
                        .bind(checkpoint)
                        .fetch_optional(&mut *tx)
                        .await?;
                if let Some(algorithm) = algorithm {
                    let eval_spec = eval.to_string();
                    let task = spec["eval_label"].as_str();
                    let new = NewJob {
                        kind: "eval",
                        algorithm: &algorithm,
                        task,
                        spec: &eval_spec,
                        checkpoint_id: Some(checkpoint),
                        rerun_of: None,
                        sweep_id: Some(sweep),
                    };
                    follow = Some(insert_job(&mut *tx, &new).await?);
                }
            }
        }
        tx.commit().await?;
        Ok(follow)
    }
}
