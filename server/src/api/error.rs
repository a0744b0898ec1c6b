//! The API's error: an HTTP status and `{"error": {"code", "message", "field"}}`.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};

use crate::store::StoreError;

#[derive(Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
    pub field: Option<String>,
}

impl ApiError {
    /// A request value that is malformed or out of range; names the field.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            status: StatusCode::BAD_REQUEST,
            code: "invalid_field",
            message: message.into(),
            field: Some(field.into()),
        }
    }

    pub fn not_found(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            status: StatusCode::NOT_FOUND,
            code: "not_found",
            message: message.into(),
            field: Some(field.into()),
        }
    }

    pub fn conflict(message: impl Into<String>) -> Self {
        Self {
            status: StatusCode::CONFLICT,
            code: "conflict",
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
            status: StatusCode::SERVICE_UNAVAILABLE,
            code: "unavailable",
            message: message.into(),
            field: Some(field.into()),
        }
    }

    /// 429: a client over its request budget (`api/rate.rs`).
    pub fn rate_limited() -> Self {
        Self {
            status: StatusCode::TOO_MANY_REQUESTS,
            code: "rate_limited",
            message: "too many requests from this address; retry after the seconds in Retry-After"
                .into(),
            field: None,
        }
    }

    pub fn unauthorized() -> Self {
        Self {
            status: StatusCode::UNAUTHORIZED,
            code: "unauthorized",
            message: "this call needs the header `Authorization: Bearer <token>`".into(),
            field: Some("authorization".into()),
        }
    }

    /// A known token without the scope the call needs.
    pub fn forbidden(scope: crate::auth::Scope) -> Self {
        Self {
            status: StatusCode::FORBIDDEN,
            code: "forbidden",
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
            status: StatusCode::INTERNAL_SERVER_ERROR,
            code: "internal",
            message: err.to_string(),
            field: None,
        }
    }

    /// A store error on the resource named `what` (`job`, `checkpoint`).
    pub fn store(what: &str, err: StoreError) -> Self {
        match err {
            StoreError::NotFound => Self::not_found("id", format!("no such {what}")),
            StoreError::Conflict(state) => Self::conflict(format!("the {what} is {state}")),
            StoreError::KeyReused(job) => Self {
                status: StatusCode::CONFLICT,
                code: "idempotency_key_reused",
                message: format!(
                    "this Idempotency-Key was used for another request, which created job {job}; use a new key for a new job"
                ),
                field: Some("Idempotency-Key".into()),
            },
            other => Self::internal(other),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = serde_json::json!({
            "error": {"code": self.code, "message": self.message, "field": self.field}
        });
        (self.status, Json(body)).into_response()
    }
}

/// A path id that must be a positive integer.
pub fn parse_id(text: &str) -> Result<i64, ApiError> {
    text.parse::<i64>()
        .ok()
        .filter(|id| *id > 0)
        .ok_or_else(|| ApiError::invalid("id", format!("{text:?} is not a positive integer id")))
}
