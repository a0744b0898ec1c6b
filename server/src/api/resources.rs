//! Read-only resources: runs (training jobs with their metric series), evaluations (with
//! per-objective results), workers and the task catalog. Checkpoints are in `checkpoints.rs`.

use std::collections::HashMap;
use std::sync::Arc;

use axum::Json;
use axum::body::Body;
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde_json::json;

use super::error::{ApiError, parse_id};
use crate::AppState;
use crate::store::{Job, JobFilter};

type Res = Result<Response, ApiError>;

async fn job_of_kind(state: &AppState, id: &str, kind: &str) -> Result<Job, ApiError> {
    let what = if kind == "train" { "run" } else { "evaluation" };
    let job = state
        .store
        .job(parse_id(id)?)
        .await
        .map_err(|e| ApiError::store(what, e))?;
    if job.kind != kind {
        return Err(ApiError::not_found(
            "id",
            format!("job {} is not a {what}", job.id),
        ));
    }
    Ok(job)
}

fn filter_of(kind: &str, query: &HashMap<String, String>) -> Result<JobFilter, ApiError> {
    let mut filter = JobFilter {
        kind: Some(kind.into()),
        ..JobFilter::default()
    };
    for (key, value) in query {
        match key.as_str() {
            "algorithm" => filter.algorithm = Some(value.clone()),
            "state" => filter.state = Some(value.clone()),
            other => return Err(ApiError::invalid(other, "unknown query parameter")),
        }
    }
    Ok(filter)
}

pub async fn runs(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Res {
    let runs = state
        .store
        .jobs(&filter_of("train", &query)?)
        .await
        .map_err(|e| ApiError::store("run", e))?;
    Ok(Json(json!({ "runs": runs })).into_response())
}

/// A run with its metric series, checkpoints, evaluations and recent episodes.
pub async fn run(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let job = job_of_kind(&state, &id, "train").await?;
    let store = &state.store;
    let err = |e| ApiError::store("run", e);
    let metrics = store.metrics(job.id).await.map_err(err)?;
    let checkpoints = store.checkpoints(Some(job.id), false).await.map_err(err)?;
    let ids: Vec<i64> = checkpoints.iter().map(|c| c.id).collect();
    let evaluations: Vec<Job> = store
        .jobs(&JobFilter {
            kind: Some("eval".into()),
            ..JobFilter::default()
        })
        .await
        .map_err(err)?
        .into_iter()
        .filter(|e| e.checkpoint_id.is_some_and(|c| ids.contains(&c)))
        .collect();
    let episodes = store.episodes(job.id).await.map_err(err)?;
    let recording = recording_json(&state, job.id).await?;
    // The videos of its evaluations, newest evaluation first.
    let mut videos = Vec::new();
    for evaluation in &evaluations {
        let video = super::videos::video_json(&state, evaluation.id).await?;
        if !video.is_null() {
            videos.push(video);
        }
    }
    // Disk the run uses: its checkpoints and its recording.
    let disk_bytes =
        checkpoints.iter().map(|c| c.size).sum::<i64>() + recording["size"].as_i64().unwrap_or(0);
    Ok(Json(json!({
        "run": job,
        "disk_bytes": disk_bytes,
        "metrics": metrics,
        "checkpoints": checkpoints,
        "evaluations": evaluations,
        "episodes": episodes,
        "recording": recording,
        "videos": videos,
    }))
    .into_response())
}

/// `DELETE /api/v1/runs/{id}`: removes a finished training run with its checkpoints,
/// recording, metrics, episode summaries and the evaluations of its checkpoints; 409 while it
/// (or one of those evaluations) is queued or running.
pub async fn delete_run(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let job = job_of_kind(&state, &id, "train").await?;
    let freed = state
        .store
        .delete_run(job.id)
        .await
        .map_err(|e| ApiError::store("run", e))?;
    tracing::info!(run = job.id, freed, "run deleted");
    state.notify();
    Ok(Json(json!({"deleted": job.id, "freed_bytes": freed})).into_response())
}

/// A job's recording (size, episodes, download path), or null.
async fn recording_json(state: &AppState, job: i64) -> Result<serde_json::Value, ApiError> {
    let row = state
        .store
        .recording(job)
        .await
        .map_err(|e| ApiError::store("recording", e))?;
    Ok(with_download(row, format!("/api/v1/jobs/{job}/recording")))
}

/// A stored file's row as JSON with its download path, or null without a row.
pub(super) fn with_download(row: Option<impl serde::Serialize>, path: String) -> serde_json::Value {
    row.map_or(serde_json::Value::Null, |r| {
        let mut value = json!(r);
        value["download"] = json!(path);
        value
    })
}

/// `GET /api/v1/jobs/{id}/recording`: the job's rerun recording (`.rrd`), for `rerun FILE`
/// or `rerun URL`.
pub async fn recording(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let job = state
        .store
        .job(parse_id(&id)?)
        .await
        .map_err(|e| ApiError::store("job", e))?;
    let row = state
        .store
        .recording(job.id)
        .await
        .map_err(|e| ApiError::store("recording", e))?
        .ok_or_else(|| {
            ApiError::not_found(
                "id",
                format!(
                    "job {} has no recording (see its \"record\" setting)",
                    job.id
                ),
            )
        })?;
    // Streamed (a recording may reach --max-recording-bytes), and only the recorded size:
    // bytes past it belong to an append in progress.
    let file = tokio::fs::File::open(state.store.recording_path(&row))
        .await
        .map_err(ApiError::internal)?;
    let body = Body::from_stream(tokio_util::io::ReaderStream::new(
        tokio::io::AsyncReadExt::take(file, row.size as u64),
    ));
    Ok((
        [
            (header::CONTENT_TYPE, "application/octet-stream".to_string()),
            (header::CONTENT_LENGTH, row.size.to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"job{}.rrd\"", job.id),
            ),
        ],
        body,
    )
        .into_response())
}

pub async fn run_metrics(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let job = job_of_kind(&state, &id, "train").await?;
    let metrics = state
        .store
        .metrics(job.id)
        .await
        .map_err(|e| ApiError::store("run", e))?;
    Ok(Json(json!({ "run_id": job.id, "metrics": metrics })).into_response())
}

/// `GET /api/v1/jobs/{id}/tensorboard`: a training job's series as a TensorBoard event file
/// (every iteration's scalars by environment step, the job's settings as text), made from the
/// stored metrics; for `tensorboard --logdir`.
pub async fn tensorboard(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let job = job_of_kind(&state, &id, "train").await?;
    let metrics = state
        .store
        .metrics(job.id)
        .await
        .map_err(|e| ApiError::store("run", e))?;
    let iterations: Vec<crm_api::Iteration> = metrics
        .iter()
        .filter_map(|m| serde_json::from_str(&m.data).ok())
        .collect();
    let settings: serde_json::Value = serde_json::from_str(&job.spec).unwrap_or_default();
    let start = job.started_at.unwrap_or(job.created_at) as f64 / 1000.0;
    let bytes = crm_api::tensorboard::file(&settings, &iterations, start);
    let name = crm_api::tensorboard::file_name(start, &format!("crm-job{}", job.id));
    Ok((
        [
            (header::CONTENT_TYPE, "application/octet-stream".to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{name}\""),
            ),
        ],
        bytes,
    )
        .into_response())
}

pub async fn evaluations(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Res {
    let evaluations = state
        .store
        .jobs(&filter_of("eval", &query)?)
        .await
        .map_err(|e| ApiError::store("evaluation", e))?;
    Ok(Json(json!({ "evaluations": evaluations })).into_response())
}

pub async fn evaluation(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Res {
    let job = job_of_kind(&state, &id, "eval").await?;
    let recording = recording_json(&state, job.id).await?;
    let episodes = state
        .store
        .episodes(job.id)
        .await
        .map_err(|e| ApiError::store("evaluation", e))?;
    let mut value = json!(job);
    value["recording"] = recording;
    value["video"] = super::videos::video_json(&state, job.id).await?;
    value["episodes"] = json!(episodes);
    Ok(Json(value).into_response())
}

pub async fn workers(State(state): State<Arc<AppState>>) -> Res {
    let workers = state
        .store
        .workers()
        .await
        .map_err(|e| ApiError::store("worker", e))?;
    let now = crate::store::now_ms();
    let alive_ms = 3 * 1000 * i64::from(state.config.heartbeat_interval_s);
    let workers: Vec<_> = workers
        .into_iter()
        .map(|w| {
            let alive = now - w.last_heartbeat <= alive_ms;
            let mut value = serde_json::to_value(&w).unwrap_or_default();
            value["alive"] = json!(alive);
            value
        })
        .collect();
    Ok(Json(json!({ "workers": workers })).into_response())
}

/// The catalog of the built-in world, or of `?world=NAME`.
pub async fn tasks(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Res {
    if let Some(key) = query.keys().find(|k| k.as_str() != "world") {
        return Err(ApiError::invalid(key.clone(), "unknown query parameter"));
    }
    match query.get("world") {
        None => Ok(Json(&*state.catalog).into_response()),
        Some(name) => {
            let world = state
                .worlds
                .iter()
                .find(|w| &w.name == name)
                .ok_or_else(|| {
                    ApiError::not_found("world", format!("no world {name:?} (GET /api/v1/worlds)"))
                })?;
            Ok(Json(&world.catalog).into_response())
        }
    }
}

/// The worlds jobs may name: the built-in one and those under `--worlds`.
pub async fn worlds(State(state): State<Arc<AppState>>) -> Res {
    let worlds: Vec<_> = state.worlds.iter().map(|w| w.summary()).collect();
    Ok(Json(json!({ "worlds": worlds })).into_response())
}
