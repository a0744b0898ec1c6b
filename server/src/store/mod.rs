//! The sqlite store (sqlx, WAL): workers, jobs and their leases, metric series, episode
//! summaries, checkpoints, rerun recordings (`recordings.rs`) and evaluation videos (`videos.rs`). Migrations in `migrations/` are applied when it opens. Every
//! state change is one statement or one transaction, so a refused request changes nothing.

use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use serde::Serialize;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions};
use sqlx::{ConnectOptions, Connection, SqlitePool};

/// `sqlx::FromRow` by column name for a row struct whose fields are its columns: sqlx's derive
/// without its proc-macro crate (see `migrations.rs`). Every field must be listed (the struct
/// literal refuses a missing one).
macro_rules! from_row {
    ($row:ident { $($field:ident),* $(,)? }) => {
        impl<'r> sqlx::FromRow<'r, sqlx::sqlite::SqliteRow> for $row {
            fn from_row(row: &'r sqlx::sqlite::SqliteRow) -> Result<Self, sqlx::Error> {
                use sqlx::Row;
                Ok(Self {
                    $($field: row.try_get(stringify!($field))?,)*
                })
            }
        }
    };
}
pub(crate) use from_row;

mod checkpoints;
pub(crate) mod migrations;
mod recordings;
mod sweeps;
#[cfg(test)]
mod tests;
mod videos;

pub use checkpoints::{CheckpointRow, NewCheckpoint};
pub use recordings::RecordingRow;
pub use sweeps::SweepRow;
pub use videos::{VideoInfo, VideoRow};

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// A job as stored.
#[derive(Clone, Debug, Serialize)]
pub struct Job {
    pub id: i64,
    pub kind: String,
    pub state: String,
    pub algorithm: String,
    pub task: Option<String>,
    #[serde(serialize_with = "as_json")]
    pub spec: String,
    pub checkpoint_id: Option<i64>,
    pub rerun_of: Option<i64>,
    pub worker_id: Option<String>,
    pub attempts: i64,
    pub lease_expires_at: Option<i64>,
    pub progress: f64,
    pub steps: i64,
    pub steps_per_s: Option<f64>,
    #[serde(serialize_with = "as_json_opt")]
    pub result: Option<String>,
    pub error: Option<String>,
    pub created_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    /// Before training reports: the phase (`{"name", "done", "total"}`), else `None`.
    #[serde(serialize_with = "as_json_opt")]
    pub phase: Option<String>,
    /// The sweep it belongs to.
    pub sweep_id: Option<i64>,
}

crate::store::from_row!(Job {
    id,
    kind,
    state,
    algorithm,
    task,
    spec,
    checkpoint_id,
    rerun_of,
    worker_id,
    attempts,
    lease_expires_at,
    progress,
    steps,
    steps_per_s,
    result,
    error,
    created_at,
    started_at,
    finished_at,
    phase,
    sweep_id
});

/// Stored JSON text goes out as JSON, not as a string.
fn as_json<S: serde::Serializer>(text: &str, s: S) -> Result<S::Ok, S::Error> {
    let value: serde_json::Value =
        serde_json::from_str(text).unwrap_or_else(|_| serde_json::Value::from(text));
    value.serialize(s)
}

fn as_json_opt<S: serde::Serializer>(text: &Option<String>, s: S) -> Result<S::Ok, S::Error> {
    match text {
        Some(text) => as_json(text, s),
        None => s.serialize_none(),
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Worker {
    pub id: String,
    pub name: String,
    pub cores: i64,
    pub version: String,
    pub registered_at: i64,
    pub last_heartbeat: i64,
}

crate::store::from_row!(Worker {
    id,
    name,
    cores,
    version,
    registered_at,
    last_heartbeat
});

#[derive(Clone, Debug, Serialize)]
pub struct Metric {
    pub steps: i64,
    pub iteration: i64,
    pub wall_s: f64,
    #[serde(serialize_with = "as_json")]
    pub data: String,
}

crate::store::from_row!(Metric {
    steps,
    iteration,
    wall_s,
    data
});

/// Filters for listing jobs.
#[derive(Clone, Debug, Default)]
pub struct JobFilter {
    pub kind: Option<String>,
    pub state: Option<String>,
    pub algorithm: Option<String>,
    pub limit: i64,
}

/// A new job.
#[derive(Clone, Copy)]
pub struct NewJob<'a> {
    pub kind: &'a str,
    pub algorithm: &'a str,
    pub task: Option<&'a str>,
    pub spec: &'a str,
    pub checkpoint_id: Option<i64>,
    pub rerun_of: Option<i64>,
    /// The sweep it belongs to.
    pub sweep_id: Option<i64>,
}

/// Why a state change was refused.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("not found")]
    NotFound,
    #[error("job is {0}")]
    Conflict(String),
    /// An idempotency key already names another request.
    #[error("the idempotency key was used for another request (job {0})")]
    KeyReused(i64),
    #[error(transparent)]
    Sql(#[from] sqlx::Error),
    #[error(transparent)]
    Migrate(#[from] sqlx::migrate::MigrateError),
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

pub type Result<T, E = StoreError> = std::result::Result<T, E>;

/// A worker's claim on a job: the worker, the job, and the hash of the lease's secret.
#[derive(Clone, Copy, Debug)]
pub struct Lease<'a> {
    pub worker: &'a str,
    pub job: i64,
    pub hash: &'a str,
}

impl<'a> Lease<'a> {
    pub fn new(worker: &'a str, job: i64, hash: &'a str) -> Self {
        Self { worker, job, hash }
    }
}

/// The store: a connection pool and the checkpoint folder.
#[derive(Clone)]
pub struct Store {
    pool: SqlitePool,
    checkpoints: PathBuf,
    recordings: PathBuf,
    /// Whether `open` created the database (a new data folder).
    created: bool,
}

const JOB_COLUMNS: &str = "id, kind, state, algorithm, task, spec, checkpoint_id, rerun_of, worker_id, attempts, lease_expires_at, progress, steps, steps_per_s, result, error, created_at, started_at, finished_at, phase, sweep_id";

impl Store {
    /// Opens (creating) `<data_dir>/crm-grasp.sqlite` and applies the migrations.
    pub async fn open(data_dir: &Path) -> Result<Self> {
        std::fs::create_dir_all(data_dir.join("checkpoints"))?;
        std::fs::create_dir_all(data_dir.join("recordings"))?;
        let path = data_dir.join("crm-grasp.sqlite");
        let created = !path.exists();
        let options = SqliteConnectOptions::from_str("sqlite:")?
            .filename(&path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(10));
        // Migrations run on their own connection with foreign keys off: rebuilding a table
        // (SQLite's way to change a column) drops one that other rows reference.
        let mut conn = options.clone().foreign_keys(false).connect().await?;
        migrations::migrator().await?.run(&mut conn).await?;
        conn.close().await?;
        let pool = SqlitePoolOptions::new()
            .max_connections(8)
            .connect_with(options)
            .await?;
        Ok(Self {
            pool,
            checkpoints: data_dir.join("checkpoints"),
            recordings: data_dir.join("recordings"),
            created,
        })
    }

    /// A write transaction. `BEGIN IMMEDIATE` takes the write lock first (waiting up to the
    /// busy timeout): with sqlx's plain deferred `BEGIN`, a transaction that reads before it
    /// writes fails with SQLITE_BUSY_SNAPSHOT (517, "database is locked", which no timeout
    /// waits out) when another connection commits in between, as a worker's progress does.
    async fn write_tx(&self) -> Result<sqlx::Transaction<'static, sqlx::Sqlite>> {
        Ok(self.pool.begin_with("BEGIN IMMEDIATE").await?)
    }

    /// Whether this store was created by `open` (a new data folder).
    pub fn created(&self) -> bool {
        self.created
    }

    pub fn checkpoint_dir(&self) -> &Path {
        &self.checkpoints
    }

    pub async fn close(&self) {
        self.pool.close().await;
    }

    // ---- workers ----

    /// Registers a worker; `secret_hash` is the hash of the secret it was given
    /// ([`crate::secrets`]), which every later call naming the worker must match.
    pub async fn register_worker(
        &self,
        name: &str,
        cores: i64,
        version: &str,
        secret_hash: &str,
    ) -> Result<Worker> {
        let now = now_ms();
        let count: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM workers")
            .fetch_one(&self.pool)
            .await?;
        // Unique within this coordinator even for registrations in the same millisecond.
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let serial = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let id = format!("w{}-{:x}{serial:x}", count + 1, now & 0xFFFF_FFFF);
        sqlx::query("INSERT INTO workers (id, name, cores, version, registered_at, last_heartbeat, secret_hash) VALUES (?, ?, ?, ?, ?, ?, ?)")
            .bind(&id).bind(name).bind(cores).bind(version).bind(now).bind(now).bind(secret_hash)
            .execute(&self.pool)
            .await?;
        self.worker(&id).await
    }

    pub async fn worker(&self, id: &str) -> Result<Worker> {
        sqlx::query_as("SELECT * FROM workers WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .ok_or(StoreError::NotFound)
    }

    /// Whether `secret_hash` is the hash of worker `id`'s secret; an unknown worker is
    /// [`StoreError::NotFound`]. A worker registered before secrets existed has none and
    /// matches nothing.
    pub async fn worker_secret_matches(&self, id: &str, secret_hash: &str) -> Result<bool> {
        let stored: Option<Option<String>> =
            sqlx::query_scalar("SELECT secret_hash FROM workers WHERE id = ?")
                .bind(id)
                .fetch_optional(&self.pool)
                .await?;
        let stored = stored.ok_or(StoreError::NotFound)?;
        Ok(stored.is_some_and(|s| crate::secrets::same(&s, secret_hash)))
    }

    pub async fn workers(&self) -> Result<Vec<Worker>> {
        Ok(
            sqlx::query_as("SELECT * FROM workers ORDER BY registered_at")
                .fetch_all(&self.pool)
                .await?,
        )
    }

    async fn touch_worker(&self, id: &str) -> Result<()> {
        let done = sqlx::query("UPDATE workers SET last_heartbeat = ? WHERE id = ?")
            .bind(now_ms())
            .bind(id)
            .execute(&self.pool)
            .await?;
        if done.rows_affected() == 0 {
            return Err(StoreError::NotFound);
        }
        Ok(())
    }

    // ---- jobs ----

    pub async fn create_job(&self, job: NewJob<'_>) -> Result<Job> {
        let id = insert_job(&self.pool, &job).await?;
        self.job(id).await
    }

    /// Creates a job once per idempotency `key`: the job and the key are stored in one
    /// transaction, so a submit that raced another with the same key, or that is retried after
    /// a crash, finds the first one's job. Returns the job and whether it was created now; the
    /// key with another `request` (the canonical submission) is [`StoreError::KeyReused`].
    pub async fn create_job_once(
        &self,
        job: NewJob<'_>,
        key: &str,
        request: &str,
    ) -> Result<(Job, bool)> {
        if let Some(found) = self.keyed_job(key, request).await? {
            return Ok((found, false));
        }
        let mut tx = self.write_tx().await?;
        let id = insert_job(&mut *tx, &job).await?;
        let keyed = sqlx::query(
            "INSERT INTO idempotency_keys (key, request, job_id, created_at) VALUES (?, ?, ?, ?)",
        )
        .bind(key)
        .bind(request)
        .bind(id)
        .bind(now_ms())
        .execute(&mut *tx)
        .await;
        match keyed {
            Ok(_) => {
                tx.commit().await?;
                Ok((self.job(id).await?, true))
            }
            Err(sqlx::Error::Database(db)) if db.is_unique_violation() => {
                // Another submit with this key won the race: drop this job, answer with its.
                tx.rollback().await?;
                let found = self.keyed_job(key, request).await?;
                Ok((found.ok_or(StoreError::NotFound)?, false))
            }
            Err(other) => Err(other.into()),
        }
    }

    /// The job stored under idempotency `key`, if any; the key with another request is an
    /// error.
    async fn keyed_job(&self, key: &str, request: &str) -> Result<Option<Job>> {
        let row: Option<(String, i64)> =
            sqlx::query_as("SELECT request, job_id FROM idempotency_keys WHERE key = ?")
                .bind(key)
                .fetch_optional(&self.pool)
                .await?;
        match row {
            None => Ok(None),
            Some((stored, job)) if stored == request => Ok(Some(self.job(job).await?)),
            Some((_, job)) => Err(StoreError::KeyReused(job)),
        }
    }

    pub async fn job(&self, id: i64) -> Result<Job> {
        sqlx::query_as(&format!("SELECT {JOB_COLUMNS} FROM jobs WHERE id = ?"))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .ok_or(StoreError::NotFound)
    }

    pub async fn jobs(&self, filter: &JobFilter) -> Result<Vec<Job>> {
        Ok(sqlx::query_as(&format!(
            "SELECT {JOB_COLUMNS} FROM jobs WHERE (?1 IS NULL OR kind = ?1) AND (?2 IS NULL OR state = ?2) AND (?3 IS NULL OR algorithm = ?3) ORDER BY id DESC LIMIT ?4"
        ))
        .bind(&filter.kind)
        .bind(&filter.state)
        .bind(&filter.algorithm)
        .bind(if filter.limit > 0 { filter.limit } else { 1000 })
        .fetch_all(&self.pool)
        .await?)
    }

    /// Cancels a queued or running job; a finished one is a conflict.
    pub async fn cancel_job(&self, id: i64) -> Result<Job> {
        let done = sqlx::query("UPDATE jobs SET state = 'cancelled', finished_at = ?, lease_expires_at = NULL WHERE id = ? AND state IN ('queued', 'running')")
            .bind(now_ms())
            .bind(id)
            .execute(&self.pool)
            .await?;
        let job = self.job(id).await?;
        if done.rows_affected() == 0 {
            return Err(StoreError::Conflict(job.state));
        }
        Ok(job)
    }

    /// Puts running jobs whose lease expired back in the queue; returns how many.
    pub async fn requeue_expired(&self) -> Result<u64> {
        let done = sqlx::query("UPDATE jobs SET state = 'queued', worker_id = NULL, lease_expires_at = NULL, phase = NULL WHERE state = 'running' AND lease_expires_at < ?")
            .bind(now_ms())
            .execute(&self.pool)
            .await?;
        Ok(done.rows_affected())
    }

    /// Leases a queued job to `worker` for `ttl_ms`: the oldest evaluation, else the oldest
    /// training job (an evaluation takes minutes and its result is what a study or a user
    /// waits on; behind a sweep's training jobs it would wait hours). None while `worker`
    /// holds a lease already (one job per worker: a second lease would only starve the
    /// first). `lease_hash` is the hash of the lease's secret, which every call about the job
    /// must then match.
    pub async fn lease(&self, worker: &str, lease_hash: &str, ttl_ms: i64) -> Result<Option<Job>> {
        self.touch_worker(worker).await?;
        self.requeue_expired().await?;
        let now = now_ms();
        let id: Option<i64> = sqlx::query_scalar(
            "UPDATE jobs SET state = 'running', worker_id = ?1, lease_hash = ?4, attempts = attempts + 1, lease_expires_at = ?2, started_at = COALESCE(started_at, ?3) WHERE id = (SELECT id FROM jobs WHERE state = 'queued' ORDER BY kind = 'train', id LIMIT 1) AND NOT EXISTS (SELECT 1 FROM jobs WHERE worker_id = ?1 AND state = 'running') RETURNING id",
        )
        .bind(worker)
        .bind(now + ttl_ms)
        .bind(now)
        .bind(lease_hash)
        .fetch_optional(&self.pool)
        .await?;
        match id {
            Some(id) => Ok(Some(self.job(id).await?)),
            None => Ok(None),
        }
    }

    /// Extends a lease; `false` when the job is no longer this lease's (cancelled, re-leased,
    /// finished).
    pub async fn heartbeat(&self, lease: Lease<'_>, ttl_ms: i64) -> Result<bool> {
        self.touch_worker(lease.worker).await?;
        if lease.job == 0 {
            return Ok(true);
        }
        let done = sqlx::query("UPDATE jobs SET lease_expires_at = ? WHERE id = ? AND worker_id = ? AND lease_hash = ? AND state = 'running'")
            .bind(now_ms() + ttl_ms)
            .bind(lease.job)
            .bind(lease.worker)
            .bind(lease.hash)
            .execute(&self.pool)
            .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Whether the lease is the job's current one.
    pub async fn holds(&self, lease: Lease<'_>) -> Result<bool> {
        let held: Option<i64> = sqlx::query_scalar(
            "SELECT id FROM jobs WHERE id = ? AND worker_id = ? AND lease_hash = ? AND state = 'running'",
        )
        .bind(lease.job)
        .bind(lease.worker)
        .bind(lease.hash)
        .fetch_optional(&self.pool)
        .await?;
        Ok(held.is_some())
    }

    /// Records a training iteration (replacing one at the same step after a resume).
    pub async fn add_metric(&self, job: i64, it: &crm_api::Iteration, progress: f64) -> Result<()> {
        let data = serde_json::to_string(it).unwrap_or_default();
        let mut tx = self.write_tx().await?;
        sqlx::query("INSERT OR REPLACE INTO metrics (job_id, steps, iteration, wall_s, data) VALUES (?, ?, ?, ?, ?)")
            .bind(job).bind(it.steps as i64).bind(it.iteration as i64).bind(it.wall_s).bind(data)
            .execute(&mut *tx)
            .await?;
        sqlx::query(
            "UPDATE jobs SET progress = ?, steps = ?, steps_per_s = ?, phase = NULL WHERE id = ?",
        )
        .bind(progress)
        .bind(it.steps as i64)
        .bind(it.steps_per_s)
        .bind(job)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(())
    }

    /// Records the phase a job is in before training (`{"name", "done", "total"}`).
    pub async fn set_phase(&self, job: i64, name: &str, done: u64, total: u64) -> Result<()> {
        let phase = serde_json::json!({"name": name, "done": done, "total": total});
        sqlx::query("UPDATE jobs SET phase = ? WHERE id = ?")
            .bind(phase.to_string())
            .bind(job)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    pub async fn set_progress(&self, job: i64, progress: f64) -> Result<()> {
        sqlx::query("UPDATE jobs SET progress = ? WHERE id = ?")
            .bind(progress)
            .bind(job)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    pub async fn metrics(&self, job: i64) -> Result<Vec<Metric>> {
        Ok(sqlx::query_as(
            "SELECT steps, iteration, wall_s, data FROM metrics WHERE job_id = ? ORDER BY steps",
        )
        .bind(job)
        .fetch_all(&self.pool)
        .await?)
    }

    /// Keeps the latest `keep` episode summaries of a job.
    pub async fn add_episode(&self, job: i64, data: &str, keep: i64) -> Result<()> {
        sqlx::query("INSERT INTO episodes (job_id, data, created_at) VALUES (?, ?, ?)")
            .bind(job)
            .bind(data)
            .bind(now_ms())
            .execute(&self.pool)
            .await?;
        sqlx::query("DELETE FROM episodes WHERE job_id = ?1 AND id <= (SELECT id FROM episodes WHERE job_id = ?1 ORDER BY id DESC LIMIT 1 OFFSET ?2)")
            .bind(job)
            .bind(keep)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    pub async fn episodes(&self, job: i64) -> Result<Vec<serde_json::Value>> {
        let rows: Vec<String> =
            sqlx::query_scalar("SELECT data FROM episodes WHERE job_id = ? ORDER BY id")
                .bind(job)
                .fetch_all(&self.pool)
                .await?;
        Ok(rows
            .iter()
            .filter_map(|r| serde_json::from_str(r).ok())
            .collect())
    }

    /// Ends a job under its current lease: `state` is `succeeded` or `failed`.
    /// How many jobs are queued and how many running: the workers the queue wants.
    pub async fn open_jobs(&self) -> Result<(u64, u64)> {
        let (queued, running): (i64, i64) = sqlx::query_as(
            "SELECT COALESCE(SUM(state = 'queued'), 0), COALESCE(SUM(state = 'running'), 0) FROM jobs",
        )
        .fetch_one(&self.pool)
        .await?;
        Ok((queued as u64, running as u64))
    }

    /// Gives a running job back to the queue at once (its worker was preempted or is
    /// stopping): the next lease resumes a training job from its newest checkpoint, and an
    /// evaluation from `eval_progress` (the worker's JSON of where it stood), keeping the
    /// episode summaries stored so far.
    pub async fn release(&self, lease: Lease<'_>, eval_progress: Option<&str>) -> Result<()> {
        let done = sqlx::query("UPDATE jobs SET state = 'queued', worker_id = NULL, lease_expires_at = NULL, phase = NULL, eval_progress = COALESCE(?4, eval_progress), eval_episodes_mark = CASE WHEN ?4 IS NULL THEN eval_episodes_mark ELSE (SELECT MAX(id) FROM episodes WHERE job_id = ?1) END WHERE id = ?1 AND worker_id = ?2 AND lease_hash = ?3 AND state = 'running'")
            .bind(lease.job)
            .bind(lease.worker)
            .bind(lease.hash)
            .bind(eval_progress)
            .execute(&self.pool)
            .await?;
        if done.rows_affected() == 0 {
            let now: Option<String> = sqlx::query_scalar("SELECT state FROM jobs WHERE id = ?")
                .bind(lease.job)
                .fetch_optional(&self.pool)
                .await?;
            return Err(now.map_or(StoreError::NotFound, StoreError::Conflict));
        }
        Ok(())
    }

    /// A leased evaluation's progress to go on from (`None`: from the start). The episode
    /// summaries stored after it (from a lease that was lost) are removed, as the new lease
    /// sends them again.
    pub async fn eval_resume(&self, job: i64) -> Result<Option<String>> {
        let mut tx = self.write_tx().await?;
        let (progress, mark): (Option<String>, Option<i64>) =
            sqlx::query_as("SELECT eval_progress, eval_episodes_mark FROM jobs WHERE id = ?")
                .bind(job)
                .fetch_optional(&mut *tx)
                .await?
                .unwrap_or((None, None));
        let stale = match (&progress, mark) {
            (None, _) => sqlx::query("DELETE FROM episodes WHERE job_id = ?").bind(job),
            (Some(_), mark) => sqlx::query("DELETE FROM episodes WHERE job_id = ? AND id > ?")
                .bind(job)
                .bind(mark.unwrap_or(0)),
        };
        stale.execute(&mut *tx).await?;
        tx.commit().await?;
        Ok(progress)
    }

    pub async fn finish(
        &self,
        lease: Lease<'_>,
        state: &str,
        result: Option<&str>,
        error: Option<&str>,
    ) -> Result<()> {
        let mut tx = self.write_tx().await?;
        finish_row(&mut tx, lease, state, result, error).await?;
        tx.commit().await?;
        Ok(())
    }

    /// Deletes a finished training run: its job, metrics, episode summaries, checkpoints,
    /// recording, idempotency keys, and the evaluation jobs of its checkpoints (with theirs).
    /// A queued or running run, or one whose checkpoint an unfinished evaluation uses, is a
    /// conflict and nothing changes. Rows go in one transaction, then the files; returns the
    /// bytes freed.
    pub async fn delete_run(&self, id: i64) -> Result<u64> {
        let mut tx = self.write_tx().await?;
        let state: Option<String> = sqlx::query_scalar("SELECT state FROM jobs WHERE id = ?")
            .bind(id)
            .fetch_optional(&mut *tx)
            .await?;
        let state = state.ok_or(StoreError::NotFound)?;
        if state == "queued" || state == "running" {
            return Err(StoreError::Conflict(state));
        }
        let evals: Vec<(i64, String)> = sqlx::query_as(
            "SELECT id, state FROM jobs WHERE checkpoint_id IN (SELECT id FROM checkpoints WHERE job_id = ?)",
        )
        .bind(id)
        .fetch_all(&mut *tx)
        .await?;
        if let Some((eval, state)) = evals.iter().find(|(_, s)| s == "queued" || s == "running") {
            return Err(StoreError::Conflict(format!(
                "in use: evaluation job {eval} is {state}"
            )));
        }
        let fine_tuning: Option<(i64, String)> = sqlx::query_as(
            "SELECT id, state FROM jobs WHERE state IN ('queued', 'running') \
             AND json_extract(spec, '$.fine_tune') IN (SELECT id FROM checkpoints WHERE job_id = ?)",
        )
        .bind(id)
        .fetch_optional(&mut *tx)
        .await?;
        if let Some((job, state)) = fine_tuning {
            return Err(StoreError::Conflict(format!(
                "in use: training job {job}, which starts from its checkpoint, is {state}"
            )));
        }
        let mut files: Vec<(PathBuf, i64)> = sqlx::query_as::<_, (String, i64)>(
            "SELECT file, size FROM checkpoints WHERE job_id = ?",
        )
        .bind(id)
        .fetch_all(&mut *tx)
        .await?
        .into_iter()
        .map(|(file, size)| (self.checkpoints.join(file), size))
        .collect();
        let jobs: Vec<i64> = evals.iter().map(|(e, _)| *e).chain([id]).collect();
        for job in &jobs {
            let recording: Option<(String, i64)> =
                sqlx::query_as("SELECT file, size FROM recordings WHERE job_id = ?")
                    .bind(job)
                    .fetch_optional(&mut *tx)
                    .await?;
            files.extend(recording.map(|(file, size)| (self.recordings.join(file), size)));
            let video: Option<(String, i64)> =
                sqlx::query_as("SELECT file, size FROM videos WHERE job_id = ?")
                    .bind(job)
                    .fetch_optional(&mut *tx)
                    .await?;
            files.extend(video.map(|(file, size)| (self.recordings.join(file), size)));
            for table in [
                "metrics",
                "episodes",
                "recordings",
                "videos",
                "idempotency_keys",
            ] {
                sqlx::query(&format!("DELETE FROM {table} WHERE job_id = ?"))
                    .bind(job)
                    .execute(&mut *tx)
                    .await?;
            }
            // A re-run keeps its own copy of the parameters; only the back-reference goes.
            sqlx::query("UPDATE jobs SET rerun_of = NULL WHERE rerun_of = ?")
                .bind(job)
                .execute(&mut *tx)
                .await?;
        }
        for eval in evals.iter().map(|(e, _)| e) {
            sqlx::query("DELETE FROM jobs WHERE id = ?")
                .bind(eval)
                .execute(&mut *tx)
                .await?;
        }
        sqlx::query("DELETE FROM checkpoints WHERE job_id = ?")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        sqlx::query("DELETE FROM jobs WHERE id = ?")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        tx.commit().await?;
        let mut freed = 0u64;
        for (path, size) in files {
            remove_file(&path).await;
            freed += size.max(0) as u64;
        }
        Ok(freed)
    }
}

/// Ends a job the worker holds, inside `tx`; a job not running on `worker` is a conflict
/// (or not found).
async fn finish_row(
    tx: &mut sqlx::SqliteConnection,
    lease: Lease<'_>,
    state: &str,
    result: Option<&str>,
    error: Option<&str>,
) -> Result<()> {
    let done = sqlx::query("UPDATE jobs SET state = ?, result = ?, error = ?, finished_at = ?, lease_expires_at = NULL, progress = CASE WHEN ? = 'succeeded' THEN 1.0 ELSE progress END WHERE id = ? AND worker_id = ? AND lease_hash = ? AND state = 'running'")
        .bind(state).bind(result).bind(error).bind(now_ms()).bind(state).bind(lease.job).bind(lease.worker).bind(lease.hash)
        .execute(&mut *tx)
        .await?;
    if done.rows_affected() == 0 {
        let now: Option<String> = sqlx::query_scalar("SELECT state FROM jobs WHERE id = ?")
            .bind(lease.job)
            .fetch_optional(&mut *tx)
            .await?;
        return Err(now.map_or(StoreError::NotFound, StoreError::Conflict));
    }
    Ok(())
}

/// Queues a new job; returns its id.
pub(crate) async fn insert_job<'e>(
    conn: impl sqlx::Executor<'e, Database = sqlx::Sqlite>,
    job: &NewJob<'_>,
) -> Result<i64> {
    Ok(sqlx::query_scalar("INSERT INTO jobs (kind, state, algorithm, task, spec, checkpoint_id, rerun_of, sweep_id, created_at) VALUES (?, 'queued', ?, ?, ?, ?, ?, ?, ?) RETURNING id")
        .bind(job.kind).bind(job.algorithm).bind(job.task).bind(job.spec)
        .bind(job.checkpoint_id).bind(job.rerun_of).bind(job.sweep_id).bind(now_ms())
        .fetch_one(conn)
        .await?)
}

/// Removes a file whose row is gone; a file already missing is fine, another failure is
/// logged (the row is the truth: an orphan file wastes disk, a row without its file would
/// break downloads).
async fn remove_file(path: &Path) {
    match tokio::fs::remove_file(path).await {
        Ok(()) => {}
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => {}
        Err(err) => tracing::warn!(path = %path.display(), %err, "could not remove file"),
    }
}
