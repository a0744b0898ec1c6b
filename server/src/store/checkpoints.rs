//! Checkpoints: files under `<data dir>/checkpoints/` with a row each. A training job's
//! checkpoints (uploaded by its worker, pruned by retention) and uploaded ones that belong to
//! no job (`POST /api/v1/checkpoints`, the shipped models registered at start), stored by
//! content hash so the same bytes uploaded twice are one checkpoint.

use std::path::PathBuf;

use serde::Serialize;

use super::{Result, Store, StoreError, now_ms, remove_file};

#[derive(Clone, Debug, Serialize)]
pub struct CheckpointRow {
    pub id: i64,
    /// The training job that saved it; `None` for an uploaded checkpoint.
    pub job_id: Option<i64>,
    pub algorithm: String,
    pub steps: i64,
    pub size: i64,
    #[serde(skip)]
    pub file: String,
    pub created_at: i64,
    /// Hex SHA-256 of the file (absent on rows stored before uploads existed).
    pub sha256: Option<String>,
    /// An uploaded checkpoint's label.
    pub name: Option<String>,
}

crate::store::from_row!(CheckpointRow {
    id,
    job_id,
    algorithm,
    steps,
    size,
    file,
    created_at,
    sha256,
    name
});

/// A checkpoint to record whose bytes are already at `file` in the checkpoint folder.
pub struct NewCheckpoint<'a> {
    /// `None` for an upload.
    pub job: Option<i64>,
    pub algorithm: &'a str,
    pub steps: i64,
    pub size: i64,
    pub file: &'a str,
    pub sha256: &'a str,
    pub name: Option<&'a str>,
}

impl Store {
    /// Records a checkpoint whose bytes are already at `file` in the checkpoint folder.
    pub async fn add_checkpoint(&self, new: &NewCheckpoint<'_>) -> Result<CheckpointRow> {
        let id: i64 = sqlx::query_scalar(
            "INSERT INTO checkpoints (job_id, algorithm, steps, size, file, created_at, sha256, name) \
             VALUES (?, ?, ?, ?, ?, ?, ?, ?) RETURNING id",
        )
        .bind(new.job)
        .bind(new.algorithm)
        .bind(new.steps)
        .bind(new.size)
        .bind(new.file)
        .bind(now_ms())
        .bind(new.sha256)
        .bind(new.name)
        .fetch_one(&self.pool)
        .await?;
        self.checkpoint(id).await
    }

    /// The uploaded checkpoint with these bytes, if one exists.
    pub async fn upload_by_hash(&self, sha256: &str) -> Result<Option<CheckpointRow>> {
        Ok(
            sqlx::query_as("SELECT * FROM checkpoints WHERE job_id IS NULL AND sha256 = ?")
                .bind(sha256)
                .fetch_optional(&self.pool)
                .await?,
        )
    }

    /// Records an upload, or returns the upload with the same hash: `(row, created)`. The
    /// unique index on uploads' hashes decides, so two uploads of the same bytes at once both
    /// end with the one row.
    pub async fn add_upload(&self, new: &NewCheckpoint<'_>) -> Result<(CheckpointRow, bool)> {
        match self.add_checkpoint(new).await {
            Ok(row) => Ok((row, true)),
            Err(StoreError::Sql(sqlx::Error::Database(e))) if e.is_unique_violation() => self
                .upload_by_hash(new.sha256)
                .await?
                .map(|row| (row, false))
                .ok_or(StoreError::NotFound),
            Err(err) => Err(err),
        }
    }

    pub async fn checkpoint(&self, id: i64) -> Result<CheckpointRow> {
        sqlx::query_as("SELECT * FROM checkpoints WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .ok_or(StoreError::NotFound)
    }

    /// Checkpoints, newest first: of one job, the uploaded ones (`uploaded`), or all.
    pub async fn checkpoints(
        &self,
        job: Option<i64>,
        uploaded: bool,
    ) -> Result<Vec<CheckpointRow>> {
        Ok(sqlx::query_as(
            "SELECT * FROM checkpoints WHERE (?1 IS NULL OR job_id = ?1) \
             AND (NOT ?2 OR job_id IS NULL) ORDER BY id DESC",
        )
        .bind(job)
        .bind(uploaded)
        .fetch_all(&self.pool)
        .await?)
    }

    /// The newest checkpoint of a job, to resume from.
    pub async fn latest_checkpoint(&self, job: i64) -> Result<Option<CheckpointRow>> {
        Ok(
            sqlx::query_as("SELECT * FROM checkpoints WHERE job_id = ? ORDER BY id DESC LIMIT 1")
                .bind(job)
                .fetch_optional(&self.pool)
                .await?,
        )
    }

    /// Retention: removes the checkpoints of `job` older than its newest `keep`, except one
    /// that is the job's final checkpoint, that an evaluation job names or that a training
    /// job starts from (`fine_tune`). Rows go first, in
    /// one transaction, then their files; returns how many were removed.
    pub async fn prune_checkpoints(&self, job: i64, keep: u32) -> Result<usize> {
        let mut tx = self.write_tx().await?;
        let old: Vec<(i64, String)> = sqlx::query_as(
            "SELECT id, file FROM checkpoints WHERE job_id = ?1 \
             AND id NOT IN (SELECT id FROM checkpoints WHERE job_id = ?1 ORDER BY id DESC LIMIT ?2) \
             AND id NOT IN (SELECT checkpoint_id FROM jobs WHERE checkpoint_id IS NOT NULL) \
             AND id NOT IN (SELECT json_extract(spec, '$.fine_tune') FROM jobs \
                            WHERE json_extract(spec, '$.fine_tune') IS NOT NULL) \
             AND id IS NOT (SELECT json_extract(result, '$.checkpoint_id') FROM jobs WHERE id = ?1)",
        )
        .bind(job)
        .bind(i64::from(keep.max(1)))
        .fetch_all(&mut *tx)
        .await?;
        for (id, _) in &old {
            sqlx::query("DELETE FROM checkpoints WHERE id = ?")
                .bind(id)
                .execute(&mut *tx)
                .await?;
        }
        tx.commit().await?;
        for (_, file) in &old {
            remove_file(&self.checkpoints.join(file)).await;
        }
        Ok(old.len())
    }

    pub fn checkpoint_path(&self, row: &CheckpointRow) -> PathBuf {
        self.checkpoints.join(&row.file)
    }
}

#[cfg(test)]
mod tests {
    use std::borrow::Cow;
    use std::str::FromStr;

    use sqlx::migrate::Migrator;
    use sqlx::sqlite::SqliteConnectOptions;
    use sqlx::{ConnectOptions, Connection};

    use super::*;

    /// The migration that made `job_id` nullable.
    const UPLOADS: i64 = 20261123000003;

    #[tokio::test]
    async fn a_store_from_before_uploads_keeps_its_checkpoints_and_their_evaluations() {
        let dir = std::env::temp_dir().join(format!("crm-store-upgrade-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).expect("temp dir");
        // A store as the coordinator left it before uploads existed, with a run, one of its
        // checkpoints and an evaluation of that checkpoint.
        let options = SqliteConnectOptions::from_str("sqlite:")
            .expect("options")
            .filename(dir.join("crm-grasp.sqlite"))
            .create_if_missing(true)
            .foreign_keys(true);
        let mut conn = options.connect().await.expect("connect");
        let all = crate::store::migrations::migrator()
            .await
            .expect("migrations");
        let before = Migrator {
            migrations: Cow::Owned(
                all.migrations
                    .iter()
                    .filter(|m| m.version < UPLOADS)
                    .cloned()
                    .collect(),
            ),
            ..all
        };
        before.run(&mut conn).await.expect("old migrations");
        for sql in [
            "INSERT INTO jobs (kind, state, algorithm, spec, created_at) VALUES ('train', 'succeeded', 'crm-ppo', '{}', 1)",
            "INSERT INTO checkpoints (job_id, algorithm, steps, size, file, created_at) VALUES (1, 'crm-ppo', 4096, 10, 'job1.safetensors', 2)",
            "INSERT INTO jobs (kind, state, algorithm, spec, checkpoint_id, created_at) VALUES ('eval', 'succeeded', 'crm-ppo', '{}', 1, 3)",
        ] {
            sqlx::query(sql).execute(&mut conn).await.expect(sql);
        }
        conn.close().await.expect("close");

        let store = Store::open(&dir).await.expect("upgraded");
        assert!(!store.created());
        let old = store.checkpoint(1).await.expect("kept");
        assert_eq!((old.job_id, old.steps, old.sha256), (Some(1), 4096, None));
        assert_eq!(store.job(2).await.expect("eval").checkpoint_id, Some(1));
        let new = NewCheckpoint {
            job: None,
            algorithm: "ppo",
            steps: 1,
            size: 1,
            file: "sha256-ab.safetensors",
            sha256: "ab",
            name: Some("mine"),
        };
        let (upload, created) = store.add_upload(&new).await.expect("upload");
        assert!(created);
        assert_eq!((upload.id, upload.job_id), (2, None));
        let (again, created) = store.add_upload(&new).await.expect("again");
        assert!(!created);
        assert_eq!(again.id, upload.id);
        assert_eq!(
            store.checkpoints(None, true).await.expect("uploads").len(),
            1
        );
        let broken: Vec<(String,)> =
            sqlx::query_as("SELECT \"table\" FROM pragma_foreign_key_check")
                .fetch_all(&store.pool)
                .await
                .expect("check");
        assert!(broken.is_empty(), "{broken:?}");
        store.close().await;
        std::fs::remove_dir_all(&dir).ok();
    }
}
