//! Evaluation videos: one GIF per job under `<data dir>/recordings/`, its size, episodes,
//! frames and frame size in the `videos` table. A new upload replaces the file (written to a
//! temporary name and renamed, then the row), so a reader sees the old video or the new.

use std::path::PathBuf;

use serde::Serialize;

use super::{Result, Store, now_ms};

/// A job's video as stored.
#[derive(Clone, Debug, Serialize)]
pub struct VideoRow {
    pub job_id: i64,
    /// File name under `<data dir>/recordings/`.
    #[serde(skip)]
    pub file: String,
    pub size: i64,
    pub episodes: i64,
    pub frames: i64,
    pub width: i64,
    pub height: i64,
    pub updated_at: i64,
}

crate::store::from_row!(VideoRow {
    job_id,
    file,
    size,
    episodes,
    frames,
    width,
    height,
    updated_at
});

/// What a worker says of the video it uploads.
#[derive(Clone, Copy, Debug)]
pub struct VideoInfo {
    pub episodes: i64,
    pub frames: i64,
    pub width: i64,
    pub height: i64,
}

impl Store {
    pub fn video_path(&self, row: &VideoRow) -> PathBuf {
        self.recordings.join(&row.file)
    }

    pub async fn video(&self, job: i64) -> Result<Option<VideoRow>> {
        Ok(sqlx::query_as("SELECT * FROM videos WHERE job_id = ?")
            .bind(job)
            .fetch_optional(&self.pool)
            .await?)
    }

    /// Stores `bytes` as the job's video, replacing an earlier one.
    pub async fn put_video(&self, job: i64, bytes: &[u8], info: VideoInfo) -> Result<VideoRow> {
        let file = format!("job{job}.gif");
        let path = self.recordings.join(&file);
        let partial = self.recordings.join(format!("job{job}.gif.partial"));
        tokio::fs::write(&partial, bytes).await?;
        tokio::fs::File::open(&partial).await?.sync_all().await?;
        tokio::fs::rename(&partial, &path).await?;
        sqlx::query(
            "INSERT INTO videos (job_id, file, size, episodes, frames, width, height, updated_at) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8) ON CONFLICT (job_id) DO UPDATE SET \
             size = ?3, episodes = ?4, frames = ?5, width = ?6, height = ?7, updated_at = ?8",
        )
        .bind(job)
        .bind(&file)
        .bind(bytes.len() as i64)
        .bind(info.episodes)
        .bind(info.frames)
        .bind(info.width)
        .bind(info.height)
        .bind(now_ms())
        .execute(&self.pool)
        .await?;
        self.video(job).await?.ok_or(super::StoreError::NotFound)
    }
}
