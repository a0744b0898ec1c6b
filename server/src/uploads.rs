//! Checkpoints that arrive from outside a training job: `POST /api/v1/checkpoints` and the
//! shipped models (`--models DIR`, registered when a coordinator starts on a new data
//! folder). Each is checked as a worker's upload is ([`crm_api::checkpoint::inspect`]: the
//! safetensors layout, our header format, a known algorithm, this build's environment
//! version), stored once by its SHA-256 and answered with its id.

use std::path::Path;

use crm_api::CheckpointError;
use sha2::{Digest, Sha256};

use crate::AppState;
use crate::store::{CheckpointRow, NewCheckpoint, StoreError};

/// Why an upload was not stored.
#[derive(Debug, thiserror::Error)]
pub enum UploadError {
    #[error("{0}")]
    Checkpoint(#[from] CheckpointError),
    #[error("name: {0}")]
    Name(&'static str),
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("writing the checkpoint: {0}")]
    Io(#[from] std::io::Error),
}

/// Lowercase hex SHA-256.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

pub fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// Checks an upload's label ([`crm_api::check_name`]).
pub fn check_name(name: &str) -> Result<(), UploadError> {
    crm_api::check_name(name).map_err(UploadError::Name)
}

/// Validates `bytes` as a checkpoint and stores it (or finds the same bytes already
/// uploaded): `(row, created)`. Nothing is written for a refused file.
pub async fn store(
    state: &AppState,
    bytes: &[u8],
    name: Option<&str>,
) -> Result<(CheckpointRow, bool), UploadError> {
    if let Some(name) = name {
        check_name(name)?;
    }
    let info = crm_api::checkpoint::inspect(bytes, bytes.len() as u64)?;
    let sha256 = sha256_hex(bytes);
    let store = &state.store;
    if let Some(row) = store.upload_by_hash(&sha256).await? {
        return Ok((row, false));
    }
    let file = format!("sha256-{sha256}.safetensors");
    let path = store.checkpoint_dir().join(&file);
    let partial = store.checkpoint_dir().join(format!("{file}.partial"));
    tokio::fs::write(&partial, bytes).await?;
    tokio::fs::rename(&partial, &path).await?;
    let new = NewCheckpoint {
        job: None,
        algorithm: info.algorithm.name(),
        steps: info.steps as i64,
        size: bytes.len() as i64,
        file: &file,
        sha256: &sha256,
        name,
    };
    Ok(store.add_upload(&new).await?)
}

/// Registers the checkpoints in `dir` (its `*.safetensors` files that are policy checkpoints
/// of this environment, named by their file stem); others are skipped with a log line.
/// Returns how many were stored.
pub async fn register_dir(state: &AppState, dir: &Path) -> anyhow::Result<usize> {
    let mut entries = tokio::fs::read_dir(dir).await?;
    let mut files = Vec::new();
    while let Some(entry) = entries.next_entry().await? {
        let path = entry.path();
        if path.extension().is_some_and(|e| e == "safetensors") {
            files.push(path);
        }
    }
    files.sort();
    let mut stored = 0;
    for path in files {
        let name = path.file_stem().map(|s| s.to_string_lossy().to_string());
        let bytes = tokio::fs::read(&path).await?;
        match store(state, &bytes, name.as_deref()).await {
            Ok((row, _)) => {
                stored += 1;
                tracing::info!(path = %path.display(), checkpoint = row.id, "model registered");
            }
            Err(UploadError::Checkpoint(why)) => {
                tracing::info!(path = %path.display(), %why, "not registered");
            }
            Err(err) => return Err(err.into()),
        }
    }
    Ok(stored)
}
