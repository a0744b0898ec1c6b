//! The REST API under `/api/v1` (axum): jobs, runs with their metric series, evaluations,
//! checkpoints, workers and the task catalog; `GET /healthz`; the OpenAPI document at
//! `/api/v1/openapi.json`; for the dashboard, SVG charts, comparisons, the topology table and
//! server-sent events. Errors are JSON `{"error": {"code", "message", "field"}}`.

mod checkpoints;
mod compare;
mod curves;
mod error;
mod events;
mod jobs;
pub mod rate;
mod resources;
mod sweeps;
mod videos;

pub use sweeps::axis_names;
mod table;

use std::sync::Arc;
use std::time::Duration;

use axum::extract::{Request, State};
use axum::http::{HeaderMap, Method};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};

pub use error::ApiError;

use crate::AppState;
use crate::auth::{Scope, Verdict};

/// The OpenAPI document, kept beside the code and checked against the routes by a test.
pub const OPENAPI: &str = include_str!("../../openapi.json");

/// The REST router with its limits and logging.
pub fn router(state: Arc<AppState>) -> Router {
    let api = Router::new()
        .route("/jobs", get(jobs::list).post(jobs::create))
        .route("/jobs/{id}", get(jobs::get))
        .route("/jobs/{id}/cancel", post(jobs::cancel))
        .route("/jobs/{id}/rerun", post(jobs::rerun))
        .route("/jobs/{id}/recording", get(resources::recording))
        .route("/jobs/{id}/tensorboard", get(resources::tensorboard))
        .route("/jobs/{id}/video", get(videos::video))
        .route("/sweeps", get(sweeps::list).post(sweeps::create))
        .route("/sweeps/{id}", get(sweeps::get))
        .route("/sweeps/{id}/cancel", post(sweeps::cancel))
        .route("/runs", get(resources::runs))
        .route(
            "/runs/{id}",
            get(resources::run).delete(resources::delete_run),
        )
        .route("/runs/{id}/metrics", get(resources::run_metrics))
        .route("/evaluations", get(resources::evaluations))
        .route("/evaluations/{id}", get(resources::evaluation))
        .route(
            "/checkpoints",
            get(checkpoints::list).post(checkpoints::upload).layer(
                axum::extract::DefaultBodyLimit::max(
                    usize::try_from(state.config.max_checkpoint_bytes).unwrap_or(usize::MAX),
                ),
            ),
        )
        .route("/checkpoints/{id}", get(checkpoints::get))
        .route("/checkpoints/{id}/download", get(checkpoints::download))
        .route("/checkpoints/{id}/lineage", get(checkpoints::lineage))
        .route("/workers", get(resources::workers))
        .route("/tasks", get(resources::tasks))
        .route("/worlds", get(resources::worlds))
        .route("/charts", get(curves::chart))
        .route("/compare", get(compare::compare))
        .route("/topology", get(compare::topology))
        .route("/events", get(events::events))
        .route("/openapi.json", get(openapi))
        .fallback(not_found)
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            require_token,
        ))
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            rate::limit,
        ));
    Router::new()
        .nest("/api/v1", api)
        .route("/healthz", get(healthz))
        .merge(crate::web::routes())
        .fallback(crate::web::not_found)
        .with_state(state.clone())
        .layer(axum::extract::DefaultBodyLimit::max(
            state.config.max_body_bytes,
        ))
        .layer(tower::limit::GlobalConcurrencyLimitLayer::new(
            state.config.max_concurrent_requests,
        ))
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            axum::http::StatusCode::REQUEST_TIMEOUT,
            Duration::from_secs(60),
        ))
        .layer(tower_http::trace::TraceLayer::new_for_http())
}

async fn healthz(State(state): State<Arc<AppState>>) -> Response {
    match state
        .store
        .jobs(&crate::store::JobFilter {
            limit: 1,
            ..Default::default()
        })
        .await
    {
        Ok(_) => Json(serde_json::json!({"status": "ok", "version": env!("CARGO_PKG_VERSION")}))
            .into_response(),
        Err(err) => ApiError::internal(err).into_response(),
    }
}

async fn openapi(State(state): State<Arc<AppState>>) -> Response {
    (
        [("content-type", "application/json")],
        document(&state.worlds),
    )
        .into_response()
}

/// The OpenAPI document for these worlds: `world` names them and the task enums hold every
/// world's task ids (the compiled-in document is the built-in world's).
pub fn document(worlds: &[crm_api::worlds::WorldEntry]) -> String {
    if worlds.len() <= 1 {
        return OPENAPI.to_string();
    }
    let Ok(mut doc) = serde_json::from_str::<serde_json::Value>(OPENAPI) else {
        return OPENAPI.to_string();
    };
    let names: Vec<serde_json::Value> = worlds.iter().map(|w| w.name.clone().into()).collect();
    let mut ids: Vec<String> = Vec::new();
    for task in worlds.iter().flat_map(|w| &w.catalog.tasks) {
        if !ids.contains(&task.id) {
            ids.push(task.id.clone());
        }
    }
    widen(&mut doc, &names, &ids);
    doc.to_string()
}

/// Sets every `world` property's enum to `names` and every task enum (and the task-keyed
/// `shifts`) to `ids` (each enum keeping the `null` it allowed: absent and null mean the
/// built-in world, or random tasks).
fn widen(value: &mut serde_json::Value, names: &[serde_json::Value], ids: &[String]) {
    use serde_json::Value;
    let keeping_null = |old: &Value, mut list: Vec<Value>| -> Value {
        if old.as_array().is_some_and(|a| a.contains(&Value::Null)) {
            list.push(Value::Null);
        }
        Value::Array(list)
    };
    let with_ids =
        |old: &Value| keeping_null(old, ids.iter().map(|id| Value::from(id.as_str())).collect());
    match value {
        Value::Object(map) => {
            if let Some(Value::Object(props)) = map.get_mut("properties") {
                if let Some(world) = props.get_mut("world").and_then(Value::as_object_mut) {
                    let old = world.get("enum").cloned().unwrap_or(Value::Null);
                    world.insert("enum".into(), keeping_null(&old, names.to_vec()));
                }
                if let Some(task) = props.get_mut("task").and_then(Value::as_object_mut)
                    && let Some(old) = task.get("enum").cloned()
                {
                    task.insert("enum".into(), with_ids(&old));
                }
                if let Some(items) = props
                    .get_mut("tasks")
                    .and_then(|t| t.get_mut("items"))
                    .and_then(Value::as_object_mut)
                    && let Some(old) = items.get("enum").cloned()
                {
                    items.insert("enum".into(), with_ids(&old));
                }
                // A map keyed by task id (the oracle's palm shifts): one property per id.
                if let Some(keyed) = props
                    .get_mut("shifts")
                    .and_then(|t| t.get_mut("properties"))
                    .and_then(Value::as_object_mut)
                    && let Some(schema) = keyed.values().next().cloned()
                {
                    *keyed = ids.iter().map(|id| (id.clone(), schema.clone())).collect();
                }
            }
            for child in map.values_mut() {
                widen(child, names, ids);
            }
        }
        Value::Array(list) => {
            for child in list {
                widen(child, names, ids);
            }
        }
        _ => {}
    }
}

async fn not_found() -> ApiError {
    ApiError::not_found("route", "no such API route")
}

/// With tokens configured, a read (`GET`, `HEAD`) needs the read scope and anything else
/// the submit scope (`crate::auth`): 401 without a known token, 403 with one lacking the scope.
/// A read may carry its token in the `crm_token` cookie instead of the header.
async fn require_token(
    State(state): State<Arc<AppState>>,
    headers: HeaderMap,
    request: Request,
    next: Next,
) -> Response {
    let scope = if request.method() == Method::GET || request.method() == Method::HEAD {
        Scope::Read
    } else {
        Scope::Submit
    };
    let header = crate::auth::bearer(headers.get("authorization").and_then(|v| v.to_str().ok()));
    // The dashboard's pages read with the `crm_token` cookie its login sets (links, images
    // and the event stream cannot send a header); a cookie never submits, so another site
    // cannot make a browser change anything.
    let cookie = match (header, scope) {
        (None, Scope::Read) => crate::auth::cookie(&headers),
        _ => None,
    };
    match state.tokens.check(header.or(cookie.as_deref()), scope) {
        Verdict::Allowed => next.run(request).await,
        Verdict::Unauthenticated => ApiError::unauthorized().into_response(),
        Verdict::Forbidden => ApiError::forbidden(scope).into_response(),
    }
}
