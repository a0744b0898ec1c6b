//! `GET /api/v1/events`: server-sent events for live pages. Each `changed` event carries a
//! counter that grows whenever a job is queued, changes state, reports progress or uploads a
//! checkpoint; a page re-reads what it shows. Bursts are coalesced (at most about three events
//! a second), and the stream ends when the coordinator shuts down. At most
//! `--max-event-streams` are open at once.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::http::header;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use tokio_stream::StreamExt;
use tokio_stream::wrappers::WatchStream;

use super::error::ApiError;
use crate::{AppState, SHUTDOWN};

/// At most `--max-event-streams` streams are open; one beyond is answered 503 with
/// `Retry-After` (the dashboard's `EventSource` retries by itself).
pub async fn events(State(state): State<Arc<AppState>>) -> Response {
    let Ok(permit) = state.event_streams.clone().try_acquire_owned() else {
        return (
            [(header::RETRY_AFTER, "5")],
            ApiError::unavailable("events", "too many open event streams; retry later"),
        )
            .into_response();
    };
    let stream = WatchStream::from_changes(state.events.subscribe())
        .take_while(|version| *version != SHUTDOWN)
        .throttle(Duration::from_millis(300))
        .map(move |version| {
            // The stream holds its place under the cap until it ends.
            let _held = &permit;
            Ok::<_, Infallible>(Event::default().event("changed").data(version.to_string()))
        });
    Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
        .into_response()
}
