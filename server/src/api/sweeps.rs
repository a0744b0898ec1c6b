//! `/api/v1/sweeps`: a grid of training jobs from one base spec and the axes it varies
//! (algorithms, seeds, any config key, tasks, topology mode), with an evaluation spec run on
//! every final checkpoint. The whole sweep is validated before anything is stored: one bad
//! axis value rejects it, naming `axes.KEY[i]`. `GET` aggregates Table I over seeds
//! (`table.rs`); cancelling a sweep cancels its jobs.

use std::collections::HashMap;
use std::sync::Arc;

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use crm_api::{PpoConfig, SacConfig, TrainSpec};
use serde_json::{Map, Value, json};

use super::error::{ApiError, parse_id};
use super::jobs::{Submission, eval_spec, json_body, label, validate};
use super::table;
use crate::AppState;
use crate::store::NewJob;

/// Fields of a training spec that are not axes: a sweep runs in its base's world (one world
/// per table), a fine-tune names one stored checkpoint, and `config` and `sac` vary by key.
const NOT_AXES: [&str; 4] = ["world", "fine_tune", "config", "sac"];

/// The top-level fields of a training spec an axis may vary (read from `TrainSpec` itself),
/// besides `config.KEY` and `sac.KEY`.
fn axis_fields() -> Vec<&'static str> {
    crm_api::fields::field_names::<TrainSpec>()
        .iter()
        .copied()
        .filter(|field| !NOT_AXES.contains(field))
        .collect()
}

/// Every axis name: the fields of [`axis_fields`], then `config.KEY` and `sac.KEY` for each
/// PPO and SAC setting (what the OpenAPI document lists).
pub fn axis_names() -> Vec<String> {
    let nested = |prefix: &str, fields: &[&str]| -> Vec<String> {
        fields
            .iter()
            .map(|field| format!("{prefix}.{field}"))
            .collect()
    };
    axis_fields()
        .into_iter()
        .map(String::from)
        .chain(nested(
            "config",
            crm_api::fields::field_names::<PpoConfig>(),
        ))
        .chain(nested("sac", crm_api::fields::field_names::<SacConfig>()))
        .collect()
}

/// Whether `key` names an axis: a field of [`axes`], or `config.KEY` / `sac.KEY` with KEY a
/// field of `PpoConfig` / `SacConfig`.
fn is_axis(key: &str) -> bool {
    match key.split_once('.') {
        Some(("config", inner)) => crm_api::fields::field_names::<PpoConfig>().contains(&inner),
        Some(("sac", inner)) => crm_api::fields::field_names::<SacConfig>().contains(&inner),
        Some(_) => false,
        None => axis_fields().contains(&key),
    }
}

/// `base` with the axis values of one grid point set (`config.KEY` inside `config`).
fn point(base: &Map<String, Value>, values: &[(&str, &Value)]) -> Value {
    let mut spec = base.clone();
    for (key, value) in values {
        match key.split_once('.') {
            Some((outer, inner)) => {
                let entry = spec
                    .entry(outer.to_string())
                    .or_insert_with(|| Value::Object(Map::new()));
                if !entry.is_object() {
                    *entry = Value::Object(Map::new());
                }
                if let Some(map) = entry.as_object_mut() {
                    map.insert(inner.to_string(), (*value).clone());
                }
            }
            None => {
                spec.insert(key.to_string(), (*value).clone());
            }
        }
    }
    spec.insert("kind".into(), Value::from("train"));
    Value::Object(spec)
}

/// An error of one grid point's job, named by where it came from: the axis value that set
/// the field (`axes.KEY[i]...`) or the base (`base.FIELD`).
fn rename(err: ApiError, chosen: &[(&str, usize)]) -> ApiError {
    let field = err.field.clone().unwrap_or_default();
    let named = chosen.iter().find_map(|(key, index)| {
        let rest = field.strip_prefix(key)?;
        (rest.is_empty() || rest.starts_with(['.', '[']))
            .then(|| format!("axes.{key}[{index}]{rest}"))
    });
    ApiError {
        field: Some(named.unwrap_or_else(|| format!("base.{field}"))),
        ..err
    }
}

/// A validated sweep: the stored request and the jobs to queue.
struct Plan {
    name: String,
    spec: Value,
    jobs: Vec<Submission>,
}

async fn plan(state: &AppState, body: Value) -> Result<Plan, ApiError> {
    let Value::Object(mut fields) = body else {
        return Err(ApiError::invalid("body", "expected a JSON object"));
    };
    let name = match fields.remove("name") {
        Some(Value::String(name)) => {
            crm_api::check_name(&name).map_err(|why| ApiError::invalid("name", why))?;
            name
        }
        None => "sweep".to_string(),
        Some(_) => return Err(ApiError::invalid("name", "a string of 1 to 128 characters")),
    };
    let base = match fields.remove("base") {
        Some(Value::Object(base)) => base,
        None => Map::new(),
        Some(_) => return Err(ApiError::invalid("base", "a training spec object")),
    };
    if base.contains_key("kind") {
        return Err(ApiError::invalid(
            "base.kind",
            "a sweep's jobs are training jobs: leave kind out",
        ));
    }
    let axes = match fields.remove("axes") {
        Some(Value::Object(axes)) if !axes.is_empty() => axes,
        _ => {
            return Err(ApiError::invalid(
                "axes",
                "an object of axis name to a list of values",
            ));
        }
    };
    let eval = match fields.remove("eval") {
        None | Some(Value::Null) => None,
        Some(Value::Object(eval)) => {
            if eval.contains_key("kind") || eval.contains_key("checkpoint_id") {
                return Err(ApiError::invalid(
                    "eval",
                    "leave kind and checkpoint_id out: the sweep's final checkpoints are evaluated",
                ));
            }
            let in_eval = |e: ApiError| ApiError {
                field: Some(format!("eval.{}", e.field.clone().unwrap_or_default())),
                ..e
            };
            let world = super::jobs::world_of(state, eval.get("world")).map_err(in_eval)?;
            let spec = eval_spec(&world.catalog, Value::Object(eval)).map_err(in_eval)?;
            Some(spec)
        }
        Some(_) => {
            return Err(ApiError::invalid(
                "eval",
                "an evaluation spec object, or null",
            ));
        }
    };
    if let Some(key) = fields.keys().next() {
        return Err(ApiError::invalid(
            key.clone(),
            "unknown field (name, base, axes, eval)",
        ));
    }
    // Each axis: a known key and a non-empty list of distinct values.
    let mut lists: Vec<(&str, &Vec<Value>)> = Vec::new();
    let mut total = 1usize;
    for (key, values) in &axes {
        if !is_axis(key) {
            return Err(ApiError::invalid(
                format!("axes.{key}"),
                format!(
                    "unknown axis: one of {}, config.KEY or sac.KEY (a PPO or SAC setting)",
                    axis_fields().join(", ")
                ),
            ));
        }
        let Value::Array(values) = values else {
            return Err(ApiError::invalid(format!("axes.{key}"), "a list of values"));
        };
        if values.is_empty() {
            return Err(ApiError::invalid(
                format!("axes.{key}"),
                "must list at least one value",
            ));
        }
        // Over the grid's limit on its own: refused before the repeat check (quadratic).
        if values.len() > state.config.max_sweep_jobs {
            return Err(ApiError::invalid(
                "axes",
                format!(
                    "axes.{key} alone has {} values; a sweep may have at most {} jobs (--max-sweep-jobs)",
                    values.len(),
                    state.config.max_sweep_jobs
                ),
            ));
        }
        if let Some(k) = (1..values.len()).find(|&k| values[..k].contains(&values[k])) {
            return Err(ApiError::invalid(
                format!("axes.{key}[{k}]"),
                "repeats an earlier value",
            ));
        }
        total = total.saturating_mul(values.len());
        lists.push((key.as_str(), values));
    }
    let max = state.config.max_sweep_jobs;
    if total > max {
        return Err(ApiError::invalid(
            "axes",
            format!("{total} training jobs; a sweep may have at most {max} (--max-sweep-jobs)"),
        ));
    }
    // The base on its own (an axis may override one of its fields, but not make a malformed
    // base valid), with stand-ins for what the axes may give: an algorithm and a budget.
    let mut alone = base.clone();
    alone
        .entry("algorithm")
        .or_insert_with(|| Value::from("crm-ppo"));
    alone.entry("steps").or_insert_with(|| Value::from(1));
    alone.insert("kind".into(), Value::from("train"));
    validate(state, Value::Object(alone))
        .await
        .map_err(|e| rename(e, &[]))?;
    // Every grid point, in order (the last axis varies fastest), validated as a job.
    let mut jobs = Vec::with_capacity(total);
    for n in 0..total {
        let mut rest = n;
        let mut chosen = vec![("", 0usize); lists.len()];
        for (slot, (key, values)) in lists.iter().enumerate().rev() {
            chosen[slot] = (key, rest % values.len());
            rest /= values.len();
        }
        let values: Vec<(&str, &Value)> = chosen
            .iter()
            .zip(&lists)
            .map(|((key, i), (_, values))| (*key, &values[*i]))
            .collect();
        let job = validate(state, point(&base, &values))
            .await
            .map_err(|e| rename(e, &chosen))?;
        jobs.push(job);
    }
    let eval_label = eval.as_ref().and_then(|e| label(&e.task, &e.tasks));
    let spec = json!({
        "name": name,
        "base": base,
        "axes": axes,
        "eval": eval,
        "eval_label": eval_label,
    });
    Ok(Plan { name, spec, jobs })
}

/// `POST /api/v1/sweeps`: validates the whole grid, then stores the sweep and queues its
/// training jobs together; 201 with the sweep and its jobs.
pub async fn create(
    State(state): State<Arc<AppState>>,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let value = json_body(body)?;
    let plan = plan(&state, value).await?;
    let jobs: Vec<NewJob> = plan
        .jobs
        .iter()
        .map(|j| NewJob {
            kind: j.kind,
            algorithm: &j.algorithm,
            task: j.task.as_deref(),
            spec: &j.spec,
            checkpoint_id: None,
            rerun_of: None,
            sweep_id: None,
        })
        .collect();
    let sweep = state
        .store
        .create_sweep(&plan.name, &plan.spec.to_string(), &jobs)
        .await
        .map_err(|e| ApiError::store("sweep", e))?;
    tracing::info!(sweep = sweep.id, jobs = jobs.len(), "sweep submitted");
    state.notify();
    let jobs = state
        .store
        .sweep_jobs(sweep.id)
        .await
        .map_err(|e| ApiError::store("sweep", e))?;
    Ok((
        StatusCode::CREATED,
        Json(json!({"sweep": sweep, "jobs": jobs})),
    )
        .into_response())
}

pub async fn list(
    State(state): State<Arc<AppState>>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    let mut limit = 100;
    for (key, value) in &query {
        match key.as_str() {
            "limit" => {
                limit = value
                    .parse()
                    .ok()
                    .filter(|n| (1..=10_000).contains(n))
                    .ok_or_else(|| ApiError::invalid("limit", "an integer in 1..=10000"))?
            }
            other => return Err(ApiError::invalid(other, "unknown query parameter")),
        }
    }
    let sweeps = state
        .store
        .sweeps(limit)
        .await
        .map_err(|e| ApiError::store("sweep", e))?;
    Ok(Json(json!({ "sweeps": sweeps })).into_response())
}

/// `GET /api/v1/sweeps/{id}`: the sweep, its jobs, progress and Table I over seeds.
pub async fn get(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let sweep = state
        .store
        .sweep(parse_id(&id)?)
        .await
        .map_err(|e| ApiError::store("sweep", e))?;
    let jobs = state
        .store
        .sweep_jobs(sweep.id)
        .await
        .map_err(|e| ApiError::store("sweep", e))?;
    let spec: Value = serde_json::from_str(&sweep.spec).unwrap_or_default();
    let body = table::summary(&spec, &jobs);
    Ok(Json(json!({
        "sweep": sweep,
        "jobs": jobs,
        "progress": body.progress,
        "table": body.table,
    }))
    .into_response())
}

/// `POST /api/v1/sweeps/{id}/cancel`: cancels the sweep's queued and running jobs.
pub async fn cancel(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let id = parse_id(&id)?;
    let cancelled = state
        .store
        .cancel_sweep(id)
        .await
        .map_err(|e| ApiError::store("sweep", e))?;
    tracing::info!(sweep = id, cancelled, "sweep cancelled");
    state.notify();
    Ok(Json(json!({"sweep": id, "cancelled": cancelled})).into_response())
}
