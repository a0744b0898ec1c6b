//! Checkpoints: list (of a run, the uploaded ones, or all), one, download, and upload
//! (`POST /api/v1/checkpoints`, the safetensors file as the body: checked as a worker's
//! upload is, stored once by content hash).

use std::collections::HashMap;
use std::sync::Arc;

use axum::Json;
use axum::body::{Body, Bytes};
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::json;

use super::error::{ApiError, parse_id};
use crate::AppState;
use crate::errors::ErrorKind;
use crate::uploads::UploadError;

type Res = Result<Response, ApiError>;

pub async fn list(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Res {
    let mut job = None;
    let mut uploaded = false;
    for (key, value) in &query {
        match key.as_str() {
            "job_id" => {
                job = Some(
                    parse_id(value)
                        .map_err(|_| ApiError::invalid("job_id", "a positive integer"))?,
                )
            }
            "uploaded" => {
                uploaded = match value.as_str() {
                    "true" => true,
                    "false" => false,
                    _ => return Err(ApiError::invalid("uploaded", "true or false")),
                }
            }
            other => return Err(ApiError::invalid(other, "unknown query parameter")),
        }
    }
    let checkpoints = state
        .store
        .checkpoints(job, uploaded)
        .await
        .map_err(|e| ApiError::store("checkpoint", e))?;
    Ok(Json(json!({ "checkpoints": checkpoints })).into_response())
}

/// The stored checkpoint with the id in the path.
async fn stored(state: &AppState, id: &str) -> Result<crate::store::CheckpointRow, ApiError> {
    state
        .store
        .checkpoint(parse_id(id)?)
        .await
        .map_err(|e| ApiError::store("checkpoint", e))
}

pub async fn get(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let row = stored(&state, &id).await?;
    Ok(Json(row).into_response())
}

pub async fn download(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let row = stored(&state, &id).await?;
    // Streamed from disk: a client that stops reading holds one buffer, and its connection
    // is closed once idle (`listen.rs`).
    let file = tokio::fs::File::open(state.store.checkpoint_path(&row))
        .await
        .map_err(ApiError::internal)?;
    let body = Body::from_stream(tokio_util::io::ReaderStream::new(file));
    let name = match (row.job_id, &row.name) {
        (Some(job), _) => format!("{}-job{job}-{}.safetensors", row.algorithm, row.steps),
        (None, Some(name)) => format!("{}.safetensors", file_safe(name)),
        (None, None) => format!("{}-checkpoint{}.safetensors", row.algorithm, row.id),
    };
    Ok((
        [
            (header::CONTENT_TYPE, "application/octet-stream".to_string()),
            (header::CONTENT_LENGTH, row.size.to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{name}\""),
            ),
        ],
        body,
    )
        .into_response())
}

/// `GET /api/v1/checkpoints/{id}/lineage`: how the checkpoint was made, from its file's
/// header (only the header is read).
pub async fn lineage(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let row = stored(&state, &id).await?;
    let path = state.store.checkpoint_path(&row);
    let info = tokio::task::spawn_blocking(move || read_info(&path))
        .await
        .map_err(ApiError::internal)?
        .map_err(ApiError::internal)?;
    Ok(Json(json!({ "checkpoint_id": row.id, "lineage": info.lineage })).into_response())
}

/// The header of a stored checkpoint file: its first bytes only.
fn read_info(path: &std::path::Path) -> anyhow::Result<crm_api::checkpoint::CheckpointInfo> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let len = file.metadata()?.len();
    let mut prefix = [0u8; 8];
    file.read_exact(&mut prefix)?;
    let end = crm_api::checkpoint::header_len(&prefix)
        .ok_or_else(|| anyhow::anyhow!("{}: no valid header length", path.display()))?;
    let mut bytes = prefix.to_vec();
    bytes.resize(usize::try_from(end)?, 0);
    file.read_exact(&mut bytes[8..])?;
    Ok(crm_api::checkpoint::inspect(&bytes, len)?)
}

/// A label as a file name: letters, digits, `-`, `_` and `.`; anything else becomes `_`.
fn file_safe(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// `POST /api/v1/checkpoints?name=LABEL`: 201 with the new checkpoint, 200 with the existing
/// one when the same bytes were uploaded before. A body that is not a checkpoint: 400; one of
/// another environment version: 422; over `max_checkpoint_bytes`: 413. Nothing is stored
/// for a refused body.
pub async fn upload(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
    body: Result<Bytes, BytesRejection>,
) -> Res {
    let mut name = None;
    for (key, value) in &query {
        match key.as_str() {
            "name" => name = Some(value.as_str()),
            other => return Err(ApiError::invalid(other, "unknown query parameter")),
        }
    }
    let body = body.map_err(|rejection| {
        ApiError::body(
            ErrorKind::of_body(rejection.status()),
            format!(
                "{} (checkpoints up to {} bytes)",
                rejection.body_text(),
                state.config.max_checkpoint_bytes
            ),
        )
    })?;
    match crate::uploads::store(&state, &body, name).await {
        Ok((row, created)) => {
            if created {
                tracing::info!(checkpoint = row.id, name = ?row.name, "checkpoint uploaded");
                state.notify();
            }
            let status = if created {
                StatusCode::CREATED
            } else {
                StatusCode::OK
            };
            Ok((status, Json(row)).into_response())
        }
        Err(UploadError::Checkpoint(why)) => Err(ApiError::body(
            if why.is_mismatch() {
                ErrorKind::EnvVersionMismatch
            } else {
                ErrorKind::NotACheckpoint
            },
            why.to_string(),
        )),
        Err(UploadError::Name(why)) => Err(ApiError::invalid("name", why)),
        Err(UploadError::Store(err)) => Err(ApiError::store("checkpoint", err)),
        Err(err @ UploadError::Io(_)) => Err(ApiError::internal(err)),
    }
}
