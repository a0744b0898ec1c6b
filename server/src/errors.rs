//! The coordinator's error kinds in one table: each kind's JSON `code` (REST bodies), its HTTP
//! status and its gRPC code. The REST API (`api::error::ApiError`) and the workers' gRPC
//! service (`grpc`) both answer through it, and a store error maps to a kind once
//! ([`ErrorKind::of_store`]).

use axum::http::StatusCode;
use tonic::Code;

use crate::store::StoreError;

/// What went wrong, as a client sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorKind {
    /// A request value malformed or out of range; the error names the field.
    InvalidField,
    /// A body that could not be read.
    BadBody,
    /// A body over its size limit, or a recording over its cap.
    TooLarge,
    /// An upload that is not one of our checkpoints.
    NotACheckpoint,
    /// A checkpoint of another environment version.
    EnvVersionMismatch,
    NotFound,
    /// A well-formed request that does not fit what is stored (a job's state, a lease).
    Conflict,
    /// An `Idempotency-Key` already used for another request.
    IdempotencyKeyReused,
    /// The coordinator at a limit of its own.
    Unavailable,
    /// A client over its request budget.
    RateLimited,
    /// No token, or an unknown one.
    Unauthorized,
    /// A known token (or worker secret) without the right to this call.
    Forbidden,
    Internal,
}

impl ErrorKind {
    /// The table: `(code, HTTP status, gRPC code)`.
    const fn row(self) -> (&'static str, StatusCode, Code) {
        match self {
            Self::InvalidField => (
                "invalid_field",
                StatusCode::BAD_REQUEST,
                Code::InvalidArgument,
            ),
            Self::BadBody => ("bad_body", StatusCode::BAD_REQUEST, Code::InvalidArgument),
            Self::TooLarge => (
                "too_large",
                StatusCode::PAYLOAD_TOO_LARGE,
                Code::ResourceExhausted,
            ),
            Self::NotACheckpoint => (
                "not_a_checkpoint",
                StatusCode::BAD_REQUEST,
                Code::InvalidArgument,
            ),
            Self::EnvVersionMismatch => (
                "env_version_mismatch",
                StatusCode::UNPROCESSABLE_ENTITY,
                Code::FailedPrecondition,
            ),
            Self::NotFound => ("not_found", StatusCode::NOT_FOUND, Code::NotFound),
            Self::Conflict => ("conflict", StatusCode::CONFLICT, Code::FailedPrecondition),
            Self::IdempotencyKeyReused => (
                "idempotency_key_reused",
                StatusCode::CONFLICT,
                Code::AlreadyExists,
            ),
            Self::Unavailable => (
                "unavailable",
                StatusCode::SERVICE_UNAVAILABLE,
                Code::Unavailable,
            ),
            Self::RateLimited => (
                "rate_limited",
                StatusCode::TOO_MANY_REQUESTS,
                Code::ResourceExhausted,
            ),
            Self::Unauthorized => (
                "unauthorized",
                StatusCode::UNAUTHORIZED,
                Code::Unauthenticated,
            ),
            Self::Forbidden => ("forbidden", StatusCode::FORBIDDEN, Code::PermissionDenied),
            Self::Internal => (
                "internal",
                StatusCode::INTERNAL_SERVER_ERROR,
                Code::Internal,
            ),
        }
    }

    /// The `code` of a REST error body.
    pub const fn code(self) -> &'static str {
        self.row().0
    }

    pub const fn http(self) -> StatusCode {
        self.row().1
    }

    pub const fn grpc(self) -> Code {
        self.row().2
    }

    /// A gRPC status of this kind.
    pub fn status(self, message: impl Into<String>) -> tonic::Status {
        tonic::Status::new(self.grpc(), message)
    }

    /// The kind of a store error.
    pub fn of_store(err: &StoreError) -> Self {
        match err {
            StoreError::NotFound => Self::NotFound,
            StoreError::Conflict(_) => Self::Conflict,
            StoreError::KeyReused(_) => Self::IdempotencyKeyReused,
            StoreError::Sql(_) | StoreError::Migrate(_) | StoreError::Io(_) => Self::Internal,
        }
    }

    /// A body rejection's kind: over the size limit, or unreadable.
    pub fn of_body(status: StatusCode) -> Self {
        if status == StatusCode::PAYLOAD_TOO_LARGE {
            Self::TooLarge
        } else {
            Self::BadBody
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_keeps_rest_and_grpc_in_step() {
        let kinds = [
            ErrorKind::InvalidField,
            ErrorKind::BadBody,
            ErrorKind::TooLarge,
            ErrorKind::NotACheckpoint,
            ErrorKind::EnvVersionMismatch,
            ErrorKind::NotFound,
            ErrorKind::Conflict,
            ErrorKind::IdempotencyKeyReused,
            ErrorKind::Unavailable,
            ErrorKind::RateLimited,
            ErrorKind::Unauthorized,
            ErrorKind::Forbidden,
            ErrorKind::Internal,
        ];
        let codes: std::collections::BTreeSet<_> = kinds.iter().map(|k| k.code()).collect();
        assert_eq!(codes.len(), kinds.len(), "every kind has its own code");
        for kind in kinds {
            let client = kind.http().is_client_error();
            assert_eq!(
                client,
                !matches!(kind, ErrorKind::Internal | ErrorKind::Unavailable),
                "{kind:?}"
            );
            assert_ne!(kind.grpc(), Code::Ok, "{kind:?}");
        }
        assert_eq!(
            ErrorKind::of_store(&StoreError::Conflict("running".into())).grpc(),
            Code::FailedPrecondition
        );
        assert_eq!(
            ErrorKind::of_body(StatusCode::PAYLOAD_TOO_LARGE),
            ErrorKind::TooLarge
        );
    }
}
