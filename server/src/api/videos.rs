//! Evaluation videos: `GET /api/v1/jobs/{id}/video` serves a job's GIF (inline, so the
//! dashboard's `<img>` plays it), and [`video_json`] describes it inside the run and
//! evaluation views.

use std::sync::Arc;

use super::error::{ApiError, parse_id};
use crate::AppState;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};

/// A job's video (size, episodes, frames, frame size, download path), or null.
pub async fn video_json(state: &AppState, job: i64) -> Result<serde_json::Value, ApiError> {
    let row = state
        .store
        .video(job)
        .await
        .map_err(|e| ApiError::store("video", e))?;
    Ok(super::resources::with_download(
        row,
        format!("/api/v1/jobs/{job}/video"),
    ))
}

/// `GET /api/v1/jobs/{id}/video`: the evaluation's video of its first episodes (GIF).
pub async fn video(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let job = state
        .store
        .job(parse_id(&id)?)
        .await
        .map_err(|e| ApiError::store("job", e))?;
    let row = state
        .store
        .video(job.id)
        .await
        .map_err(|e| ApiError::store("video", e))?
        .ok_or_else(|| {
            ApiError::not_found(
                "id",
                format!(
                    "job {} has no video (an evaluation's \"video\" setting asks for one)",
                    job.id
                ),
            )
        })?;
    let bytes = tokio::fs::read(state.store.video_path(&row))
        .await
        .map_err(ApiError::internal)?;
    Ok((
        [
            (header::CONTENT_TYPE, "image/gif".to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("inline; filename=\"job{}.gif\"", job.id),
            ),
        ],
        bytes,
    )
        .into_response())
}
