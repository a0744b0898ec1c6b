//! The API's error: a kind (`crate::errors`, which gives its HTTP status and code) and
//! `{"error": {"code", "message", "field"}}`.

use axum::Json;
use axum::response::{IntoResponse, Response};

use crate::errors::ErrorKind;
use crate::store::StoreError;

#[derive(Debug)]
pub struct ApiError {
    pub kind: ErrorKind,
    pub message: String,
    pub field: Option<String>,
}

impl ApiError {
    /// A request value that is malformed or out of range; names the field.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            kind: ErrorKind::InvalidField,
            message: message.into(),
            field: Some(field.into()),
        }
    }

    /// A job document's field out of its domain (`TrainSpec::validate`, `EvalSpec::validate`).
    pub fn spec(err: crm_api::SpecError) -> Self {
        Self::invalid(err.field, err.message)
    }

    pub fn not_found(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            kind: ErrorKind::NotFound,
            message: message.into(),
            field: Some(field.into()),
        }
    }

    pub fn conflict(message: impl Into<String>) -> Self {
        Self {
            kind: ErrorKind::Conflict,
            message: message.into(),
            field: None,
        }
    }

    /// A well-formed value that does not fit what is stored (a fine-tune from another
    /// algorithm's checkpoint); names the field.
    pub fn conflict_with(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: Some(field.into()),
            ..Self::conflict(message)
        }
    }

    /// 503: the coordinator is at a limit of its own; `field` names what.
    pub fn unavailable(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            kind: ErrorKind::Unavailable,
            message: message.into(),
            field: Some(field.into()),
        }
    }

    /// 429: a client over its request budget (`api/rate.rs`).
    pub fn rate_limited() -> Self {
        Self {
            kind: ErrorKind::RateLimited,
            message: "too many requests from this address; retry after the seconds in Retry-After"
                .into(),
            field: None,
        }
    }

    pub fn unauthorized() -> Self {
        Self {
            kind: ErrorKind::Unauthorized,
            message: "this call needs the header `Authorization: Bearer <token>`".into(),
            field: Some("authorization".into()),
        }
    }

    /// A known token without the scope the call needs.
    pub fn forbidden(scope: crate::auth::Scope) -> Self {
        Self {
            kind: ErrorKind::Forbidden,
            message: format!(
                "this token may not {}; this call needs a token with the {} scope",
                match scope {
                    crate::auth::Scope::Read => "read",
                    crate::auth::Scope::Submit => "submit or change anything",
                    crate::auth::Scope::Worker => "act as a worker",
                },
                scope.name()
            ),
            field: Some("authorization".into()),
        }
    }

    pub fn internal(err: impl std::fmt::Display) -> Self {
        tracing::error!(%err, "internal error");
        Self {
            kind: ErrorKind::Internal,
            message: err.to_string(),
            field: None,
        }
    }

    /// An error of `kind` about the request's body.
    pub fn body(kind: ErrorKind, message: impl Into<String>) -> Self {
        Self {
            kind,
            message: message.into(),
            field: Some("body".into()),
        }
    }

    /// A store error on the resource named `what` (`job`, `checkpoint`).
    /// Its kind is [`ErrorKind::of_store`]'s, as the gRPC service's is.
    pub fn store(what: &str, err: StoreError) -> Self {
        let kind = ErrorKind::of_store(&err);
        let (message, field) = match err {
            StoreError::NotFound => (format!("no such {what}"), Some("id")),
            StoreError::Conflict(state) => (format!("the {what} is {state}"), None),
            StoreError::KeyReused(job) => (
                format!(
                    "this Idempotency-Key was used for another request, which created job {job}; use a new key for a new job"
                ),
                Some("Idempotency-Key"),
            ),
            other => return Self::internal(other),
        };
        Self {
            kind,
            message,
            field: field.map(str::to_string),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = serde_json::json!({
            "error": {"code": self.kind.code(), "message": self.message, "field": self.field}
        });
        (self.kind.http(), Json(body)).into_response()
    }
}

/// A path id that must be a positive integer.
pub fn parse_id(text: &str) -> Result<i64, ApiError> {
    text.parse::<i64>()
        .ok()
        .filter(|id| *id > 0)
        .ok_or_else(|| ApiError::invalid("id", format!("{text:?} is not a positive integer id")))
}
