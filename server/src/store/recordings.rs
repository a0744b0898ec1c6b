//! Rerun recordings: one `.rrd` file per job under `<data dir>/recordings/`, grown by appends
//! of whole recorded episodes (rerun streams concatenate), with its size and episode count in
//! the `recordings` table.

use std::path::PathBuf;

use serde::Serialize;
use tokio::io::{AsyncSeekExt, AsyncWriteExt};

use super::{Result, Store, now_ms};

/// A job's recording as stored.
#[derive(Clone, Debug, Serialize)]
pub struct RecordingRow {
    pub job_id: i64,
    /// File name under `<data dir>/recordings/`.
    #[serde(skip)]
    pub file: String,
    pub size: i64,
    pub episodes: i64,
    pub updated_at: i64,
}

crate::store::from_row!(RecordingRow {
    job_id,
    file,
    size,
    episodes,
    updated_at
});

impl Store {
    pub fn recording_path(&self, row: &RecordingRow) -> PathBuf {
        self.recordings.join(&row.file)
    }

    pub async fn recording(&self, job: i64) -> Result<Option<RecordingRow>> {
        Ok(sqlx::query_as("SELECT * FROM recordings WHERE job_id = ?")
            .bind(job)
            .fetch_optional(&self.pool)
            .await?)
    }

    /// Appends `bytes` (whole rerun streams holding `episodes` episodes) to the job's
    /// recording and returns the row after it. The file is written before the row, so a
    /// crash between the two leaves bytes past the recorded size, which the next append
    /// truncates away.
    pub async fn append_recording(
        &self,
        job: i64,
        bytes: &[u8],
        episodes: i64,
    ) -> Result<RecordingRow> {
        let file = format!("job{job}.rrd");
        let path = self.recordings.join(&file);
        let size = self.recording(job).await?.map_or(0, |r| r.size);
        let mut out = tokio::fs::OpenOptions::new()
            .create(true)
            .write(true)
            .truncate(false)
            .open(&path)
            .await?;
        out.set_len(size as u64).await?;
        out.seek(std::io::SeekFrom::Start(size as u64)).await?;
        out.write_all(bytes).await?;
        out.sync_all().await?;
        sqlx::query("INSERT INTO recordings (job_id, file, size, episodes, updated_at) VALUES (?1, ?2, ?3, ?4, ?5) ON CONFLICT (job_id) DO UPDATE SET size = ?3, episodes = recordings.episodes + ?4, updated_at = ?5")
            .bind(job)
            .bind(&file)
            .bind(size + bytes.len() as i64)
            .bind(episodes)
            .bind(now_ms())
            .execute(&self.pool)
            .await?;
        self.recording(job)
            .await?
            .ok_or(super::StoreError::NotFound)
    }
}
