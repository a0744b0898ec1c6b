//! `GET /api/v1/events`: server-sent events for live pages. Each `changed` event carries a
//! counter that grows whenever a job is queued, changes state, reports progress or uploads a
//! checkpoint; a page re-reads what it shows. Bursts are coalesced (at most about three events
//! a second), and the stream ends when the coordinator shuts down.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::response::sse::{Event, KeepAlive, Sse};
use tokio_stream::StreamExt;
use tokio_stream::wrappers::WatchStream;

use crate::{AppState, SHUTDOWN};

pub async fn events(
    State(state): State<Arc<AppState>>,
) -> Sse<impl tokio_stream::Stream<Item = Result<Event, Infallible>>> {
    let stream = WatchStream::from_changes(state.events.subscribe())
        .take_while(|version| *version != SHUTDOWN)
        .throttle(Duration::from_millis(300))
        .map(|version| Ok(Event::default().event("changed").data(version.to_string())));
    Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
}
