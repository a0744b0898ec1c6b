//! The dashboard's pages (`web/`): one HTML shell, a stylesheet and ES modules, compiled into
//! the binary so the coordinator serves them with no network and no build step. The shell is
//! answered for every page path; a run that does not exist, or a path that is no page, gets
//! status 404 and the shell draws a not-found page. With tokens configured the shell is the
//! login page too: it holds no data, and a run page does not look its run up.

use std::sync::Arc;

use axum::Router;
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;

use crate::AppState;

const INDEX: &str = include_str!("../../web/index.html");

/// Files under `/assets/`: name, content type, text.
const ASSETS: &[(&str, &str, &str)] = &[
    ("style.css", "text/css", include_str!("../../web/style.css")),
    (
        "favicon.svg",
        "image/svg+xml",
        include_str!("../../web/favicon.svg"),
    ),
    (
        "api.js",
        "text/javascript",
        include_str!("../../web/src/api.js"),
    ),
    (
        "app.js",
        "text/javascript",
        include_str!("../../web/src/app.js"),
    ),
    (
        "jobs.js",
        "text/javascript",
        include_str!("../../web/src/jobs.js"),
    ),
    (
        "run.js",
        "text/javascript",
        include_str!("../../web/src/run.js"),
    ),
    (
        "compare.js",
        "text/javascript",
        include_str!("../../web/src/compare.js"),
    ),
    (
        "models.js",
        "text/javascript",
        include_str!("../../web/src/models.js"),
    ),
    (
        "lineage.js",
        "text/javascript",
        include_str!("../../web/src/lineage.js"),
    ),
    (
        "sweeps.js",
        "text/javascript",
        include_str!("../../web/src/sweeps.js"),
    ),
    (
        "topology.js",
        "text/javascript",
        include_str!("../../web/src/topology.js"),
    ),
];

/// The page routes and assets.
pub fn routes() -> Router<Arc<AppState>> {
    Router::new()
        .route("/", get(page))
        .route("/compare", get(page))
        .route("/topology", get(page))
        .route("/models", get(page))
        .route("/sweeps", get(page))
        .route("/sweeps/{id}", get(sweep_page))
        .route("/runs/{id}", get(run_page))
        .route("/assets/{name}", get(asset))
}

fn shell(status: StatusCode) -> Response {
    (
        status,
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        INDEX,
    )
        .into_response()
}

async fn page() -> Response {
    shell(StatusCode::OK)
}

/// Whether a page may say if its run or sweep exists: only on an open coordinator (with
/// tokens, the page is answered before any token is seen, so it tells nothing; the page's
/// own API calls say not found).
fn may_look(state: &AppState) -> bool {
    !state.tokens.enabled()
}

async fn run_page(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Response {
    let found = !may_look(&state)
        || match id.parse::<i64>() {
            Ok(id) if id > 0 => state.store.job(id).await.is_ok_and(|j| j.kind == "train"),
            _ => false,
        };
    shell(if found {
        StatusCode::OK
    } else {
        StatusCode::NOT_FOUND
    })
}

async fn sweep_page(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> Response {
    let found = !may_look(&state)
        || match id.parse::<i64>() {
            Ok(id) if id > 0 => state.store.sweep(id).await.is_ok(),
            _ => false,
        };
    shell(if found {
        StatusCode::OK
    } else {
        StatusCode::NOT_FOUND
    })
}

async fn asset(Path(name): Path<String>) -> Response {
    match ASSETS.iter().find(|(n, _, _)| *n == name) {
        Some((_, mime, text)) => (
            [
                (header::CONTENT_TYPE, *mime),
                (header::CACHE_CONTROL, "no-cache"),
            ],
            *text,
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "no such asset").into_response(),
    }
}

/// Paths outside `/api` that are no page: the shell, which says so, with status 404.
pub async fn not_found() -> Response {
    shell(StatusCode::NOT_FOUND)
}
