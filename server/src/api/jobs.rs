//! `/api/v1/jobs`: submit, list, get, cancel and re-run training and evaluation jobs.
//! Submissions are validated field by field against the learner's configuration and the
//! benchmark catalog before anything is stored.

use std::collections::HashMap;
use std::sync::Arc;

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use crm_api::{EvalDocument, EvalSpec, TrainDocument, TrainSpec};
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

use super::error::{ApiError, parse_id};
use crate::AppState;
use crate::errors::ErrorKind;
use crate::store::{JobFilter, NewJob};

const STATES: [&str; 5] = ["queued", "running", "succeeded", "failed", "cancelled"];

fn decode<T: DeserializeOwned>(value: Value, prefix: &str) -> Result<T, ApiError> {
    serde_path_to_error::deserialize(value).map_err(|err| {
        let mut path = err.path().to_string();
        // A missing field is reported at its parent: name the field itself.
        let message = err.inner().to_string();
        if let Some(name) = message
            .strip_prefix("missing field `")
            .and_then(|rest| rest.split('`').next())
        {
            path = match path.as_str() {
                "." => name.to_string(),
                parent => format!("{parent}.{name}"),
            };
        }
        let field = match (prefix, path.as_str()) {
            (p, ".") => p.trim_end_matches('.').to_string(),
            (p, path) => format!("{p}{path}"),
        };
        ApiError::invalid(field, err.inner().to_string())
    })
}

/// A validated submission.
pub(super) struct Submission {
    pub kind: &'static str,
    pub algorithm: String,
    pub task: Option<String>,
    pub spec: String,
    pub checkpoint_id: Option<i64>,
}

/// The tasks column: the task ids joined, or none for random tasks.
pub(super) fn label(task: &Option<String>, tasks: &[String]) -> Option<String> {
    let list = crm_api::jobs::task_list(task, tasks);
    (!list.is_empty()).then(|| list.join(","))
}

/// Checks a job submission (`kind` train or eval) field by field; nothing is stored.
pub(super) async fn validate(state: &AppState, body: Value) -> Result<Submission, ApiError> {
    let Value::Object(mut fields) = body else {
        return Err(ApiError::invalid("body", "expected a JSON object"));
    };
    let kind = match fields.remove("kind") {
        None => return Err(ApiError::invalid("kind", "missing; \"train\" or \"eval\"")),
        Some(Value::String(kind)) => kind,
        Some(_) => return Err(ApiError::invalid("kind", "must be \"train\" or \"eval\"")),
    };
    // The experiment document names its fields where it holds them: every refusal too.
    if crm_api::document::is_document(&fields) {
        // serde would read a struct from an array too: the document's parts are objects.
        for part in ["env", "algorithm", "run"] {
            if fields.get(part).is_some_and(|v| !v.is_object()) {
                return Err(ApiError::invalid(part, "must be an object"));
            }
        }
        return checked(state, &kind, fields, true)
            .await
            .map_err(|mut err| {
                err.field = err.field.map(|f| crm_api::document::document_path(&f));
                err
            });
    }
    checked(state, &kind, fields, false).await
}

/// [`validate`] past `kind`: the flat form, or the document (`crm_api::document`).
async fn checked(
    state: &AppState,
    kind: &str,
    mut fields: Map<String, Value>,
    document: bool,
) -> Result<Submission, ApiError> {
    let world = match document {
        true => world_of(state, fields.get("env").and_then(|env| env.get("world")))?,
        false => world_of(state, fields.get("world"))?,
    };
    let catalog = &world.catalog;
    let check_task = |task: &Option<String>, tasks: &[String], topology: &Option<String>| {
        check_task(catalog, task, tasks, topology)
    };
    match kind {
        "train" => {
            let spec: TrainSpec = match document {
                true => decode::<TrainDocument>(Value::Object(fields), "")?.into(),
                false => decode(Value::Object(fields), "")?,
            };
            spec.validate().map_err(ApiError::spec)?;
            check_task(&spec.task, &spec.tasks, &spec.topology)?;
            check_imitation(catalog, &spec)?;
            check_fine_tune(state, &spec).await?;
            Ok(Submission {
                kind: "train",
                algorithm: spec.algorithm.name().to_string(),
                task: label(&spec.task, &spec.tasks),
                spec: serde_json::to_string(&spec).map_err(ApiError::internal)?,
                checkpoint_id: None,
            })
        }
        "eval" => {
            let checkpoint_id = match fields.remove("checkpoint_id") {
                Some(Value::Number(n)) => n.as_i64().filter(|id| *id > 0),
                None => return Err(ApiError::invalid("checkpoint_id", "missing")),
                Some(_) => None,
            }
            .ok_or_else(|| ApiError::invalid("checkpoint_id", "must be a positive integer"))?;
            let spec = match document {
                true => {
                    let doc: EvalDocument = decode(Value::Object(fields), "")?;
                    checked_eval(catalog, doc.into())?
                }
                false => eval_spec(catalog, Value::Object(fields))?,
            };
            let checkpoint = stored_checkpoint(state, "checkpoint_id", checkpoint_id).await?;
            Ok(Submission {
                kind: "eval",
                algorithm: checkpoint.algorithm,
                task: label(&spec.task, &spec.tasks),
                spec: serde_json::to_string(&spec).map_err(ApiError::internal)?,
                checkpoint_id: Some(checkpoint_id),
            })
        }
        other => Err(ApiError::invalid(
            "kind",
            format!("{other:?}: must be \"train\" or \"eval\""),
        )),
    }
}

/// The world a submission names (`world`; absent: the built-in one), or a 400 naming it.
pub(super) fn world_of<'a>(
    state: &'a AppState,
    value: Option<&Value>,
) -> Result<&'a crm_api::worlds::WorldEntry, ApiError> {
    let name = match value {
        None | Some(Value::Null) => crm_api::worlds::BUILTIN,
        Some(Value::String(name)) => name.as_str(),
        Some(_) => {
            return Err(ApiError::invalid(
                "world",
                "must be a world's name (a string)",
            ));
        }
    };
    state.worlds.iter().find(|w| w.name == name).ok_or_else(|| {
        let known: Vec<&str> = state.worlds.iter().map(|w| w.name.as_str()).collect();
        ApiError::invalid(
            "world",
            format!(
                "unknown world {name:?}; this coordinator has {}",
                known.join(", ")
            ),
        )
    })
}

/// A task id of the catalog, or a 400 naming `field`.
fn known_task(catalog: &crm_api::Catalog, field: String, id: &str) -> Result<(), ApiError> {
    match catalog.task(id) {
        Some(_) => Ok(()),
        None => Err(ApiError::invalid(
            field,
            format!("unknown task {id:?} (GET /api/v1/tasks lists them)"),
        )),
    }
}

/// Checks task ids and a topology name against the catalog, naming the field.
pub(super) fn check_task(
    catalog: &crm_api::Catalog,
    task: &Option<String>,
    tasks: &[String],
    topology: &Option<String>,
) -> Result<(), ApiError> {
    let named = task.iter().map(|t| ("task".to_string(), t));
    let listed = tasks
        .iter()
        .enumerate()
        .map(|(k, t)| (format!("tasks[{k}]"), t));
    for (field, id) in named.chain(listed) {
        known_task(catalog, field, id)?;
    }
    match topology.as_deref() {
        None | Some("task") | Some("auto") => Ok(()),
        Some(name) if catalog.topologies.iter().any(|t| t == name) => Ok(()),
        Some(name) => Err(ApiError::invalid(
            "topology",
            format!(
                "unknown topology {name:?}: \"task\", \"auto\" or one of {}",
                catalog.topologies.join(", ")
            ),
        )),
    }
}

/// An evaluation's parameters (an eval submission without `kind` and `checkpoint_id`),
/// checked against the catalog.
pub(super) fn eval_spec(catalog: &crm_api::Catalog, fields: Value) -> Result<EvalSpec, ApiError> {
    checked_eval(catalog, decode(fields, "")?)
}

/// An evaluation's parameters, checked against the catalog.
fn checked_eval(catalog: &crm_api::Catalog, spec: EvalSpec) -> Result<EvalSpec, ApiError> {
    spec.validate().map_err(ApiError::spec)?;
    check_task(catalog, &spec.task, &spec.tasks, &spec.topology)?;
    Ok(spec)
}

/// The world's tasks an imitation names (the rest of it is `TrainSpec::validate`'s).
fn check_imitation(catalog: &crm_api::Catalog, spec: &TrainSpec) -> Result<(), ApiError> {
    let Some(imitation) = &spec.imitation else {
        return Ok(());
    };
    for (k, id) in imitation.tasks.iter().enumerate() {
        known_task(catalog, format!("imitation.tasks[{k}]"), id)?;
    }
    for id in imitation.shifts.keys() {
        known_task(catalog, "imitation.shifts".to_string(), id)?;
    }
    Ok(())
}

/// The stored checkpoint `id` that `field` names, or a 404 naming `field`.
async fn stored_checkpoint(
    state: &AppState,
    field: &str,
    id: i64,
) -> Result<crate::store::CheckpointRow, ApiError> {
    state
        .store
        .checkpoint(id)
        .await
        .map_err(|_| ApiError::not_found(field, format!("no checkpoint {id}")))
}

/// A fine-tune names a stored checkpoint of the job's algorithm (404 when there is none,
/// 409 when it holds another algorithm's policy: the request is well formed, the stored
/// checkpoint does not fit it). Whether its machine and observation layout fit the job's
/// world is the worker's check, which reads the file.
async fn check_fine_tune(state: &AppState, spec: &TrainSpec) -> Result<(), ApiError> {
    let Some(id) = spec.fine_tune else {
        return Ok(());
    };
    // A positive id: `TrainSpec::validate` ran first.
    let checkpoint = stored_checkpoint(state, "fine_tune", id).await?;
    if checkpoint.algorithm != spec.algorithm.name() {
        return Err(ApiError::conflict_with(
            "fine_tune",
            format!(
                "checkpoint {id} is a {} policy, not {}",
                checkpoint.algorithm,
                spec.algorithm.name()
            ),
        ));
    }
    Ok(())
}

/// The header that makes a submit safe to retry.
const IDEMPOTENCY_KEY: &str = "idempotency-key";
/// Longest idempotency key accepted.
const MAX_KEY_LEN: usize = 255;

/// The request's idempotency key: 1 to 255 visible ASCII characters, or none.
fn idempotency_key(headers: &HeaderMap) -> Result<Option<String>, ApiError> {
    let mut values = headers.get_all(IDEMPOTENCY_KEY).iter();
    let Some(value) = values.next() else {
        return Ok(None);
    };
    let bad = |why: &str| ApiError::invalid("Idempotency-Key", why.to_string());
    if values.next().is_some() {
        return Err(bad("give the header once"));
    }
    let key = value
        .to_str()
        .map_err(|_| bad("must be visible ASCII characters"))?;
    if key.is_empty() || key.len() > MAX_KEY_LEN {
        return Err(bad(&format!("must be 1 to {MAX_KEY_LEN} characters")));
    }
    if !key.bytes().all(|b| b.is_ascii_graphic()) {
        return Err(bad("must be visible ASCII characters (no spaces)"));
    }
    Ok(Some(key.to_string()))
}

/// A request's JSON body, or the error naming `body` (over the size limit: 413).
pub(super) fn json_body(body: Result<Bytes, BytesRejection>) -> Result<Value, ApiError> {
    let body = body.map_err(|e| ApiError::body(ErrorKind::of_body(e.status()), e.body_text()))?;
    serde_json::from_slice(&body).map_err(|e| ApiError::invalid("body", format!("not JSON: {e}")))
}

/// Submits a job. With an `Idempotency-Key` header, a retry with the same key and the same
/// request (compared after validation, so defaults written out or left out are the same
/// request) answers with the job the first submit created, in its current state, and the
/// header `Idempotent-Replayed: true`; the same key with another request is 409.
pub async fn create(
    State(state): State<Arc<AppState>>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let key = idempotency_key(&headers)?;
    let value = json_body(body)?;
    let submission = validate(&state, value).await?;
    let new = NewJob {
        kind: submission.kind,
        algorithm: &submission.algorithm,
        task: submission.task.as_deref(),
        spec: &submission.spec,
        checkpoint_id: submission.checkpoint_id,
        rerun_of: None,
        sweep_id: None,
    };
    let (job, created) = match &key {
        Some(key) => {
            let request = serde_json::json!({
                "kind": submission.kind,
                "checkpoint_id": submission.checkpoint_id,
                "spec": submission.spec,
            })
            .to_string();
            state.store.create_job_once(new, key, &request).await
        }
        None => state.store.create_job(new).await.map(|job| (job, true)),
    }
    .map_err(|e| ApiError::store("job", e))?;
    if !created {
        tracing::info!(job = job.id, "idempotent submit replayed");
        let replayed = [("idempotent-replayed", "true")];
        return Ok((StatusCode::CREATED, replayed, Json(job)).into_response());
    }
    tracing::info!(job = job.id, kind = job.kind, "job submitted");
    state.notify();
    Ok((StatusCode::CREATED, Json(job)).into_response())
}

pub async fn list(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    let mut filter = JobFilter::default();
    for (key, value) in query {
        match key.as_str() {
            "state" if STATES.contains(&value.as_str()) => filter.state = Some(value),
            "state" => {
                return Err(ApiError::invalid(
                    "state",
                    format!("one of {}", STATES.join(", ")),
                ));
            }
            "kind" if value == "train" || value == "eval" => filter.kind = Some(value),
            "kind" => return Err(ApiError::invalid("kind", "\"train\" or \"eval\"")),
            "algorithm" if crm_api::Algorithm::parse(&value).is_some() => {
                filter.algorithm = Some(value)
            }
            "algorithm" => return Err(ApiError::invalid("algorithm", "unknown algorithm")),
            "limit" => {
                filter.limit = value
                    .parse()
                    .ok()
                    .filter(|n| (1..=10_000).contains(n))
                    .ok_or_else(|| ApiError::invalid("limit", "an integer in 1..=10000"))?;
            }
            other => return Err(ApiError::invalid(other, "unknown query parameter")),
        }
    }
    let jobs = state
        .store
        .jobs(&filter)
        .await
        .map_err(|e| ApiError::store("job", e))?;
    Ok(Json(serde_json::json!({ "jobs": jobs })).into_response())
}

pub async fn get(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let job = state
        .store
        .job(parse_id(&id)?)
        .await
        .map_err(|e| ApiError::store("job", e))?;
    Ok(Json(job).into_response())
}

pub async fn cancel(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let job = state
        .store
        .cancel_job(parse_id(&id)?)
        .await
        .map_err(|e| ApiError::store("job", e))?;
    tracing::info!(job = job.id, "job cancelled");
    Ok(Json(job).into_response())
}

/// Queues a copy of a job's parameters as a new job.
pub async fn rerun(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let old = state
        .store
        .job(parse_id(&id)?)
        .await
        .map_err(|e| ApiError::store("job", e))?;
    let job = state
        .store
        .create_job(NewJob {
            kind: &old.kind,
            algorithm: &old.algorithm,
            task: old.task.as_deref(),
            spec: &old.spec,
            checkpoint_id: old.checkpoint_id,
            rerun_of: Some(old.id),
            sweep_id: None,
        })
        .await
        .map_err(|e| ApiError::store("job", e))?;
    state.notify();
    Ok((StatusCode::CREATED, Json(job)).into_response())
}
