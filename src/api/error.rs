//! The one API error type: a status, a stable code and a message, always as JSON
//! `{"error": {"code": "...", "message": "..."}}`.
//!
//! Extractor rejections (bad JSON, wrong content type, bad path or query) are turned into
//! this type by the extractors in [`super::extract`], so a client never sees plain text.
//! Details of 5xx errors are logged, never sent.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use crate::service::dispatch::{BulkError, CancelError, ControlError};
use crate::store::fault::Cause;
use crate::store::writer::WriteError;

/// An error answer.
#[derive(Debug, Clone)]
pub struct ApiError {
    /// The HTTP status.
    pub status: StatusCode,
    /// A stable, machine-readable code (`invalid_job`, `not_found`, ...).
    pub code: &'static str,
    /// What went wrong, for people.
    pub message: String,
    /// Seconds to wait before asking again, sent as `Retry-After` (with 429 and 503).
    pub retry_after: Option<u64>,
}

/// The JSON body of every error.
#[derive(Serialize, ToSchema)]
#[schema(example = json!({"error": {"code": "not_found", "message": "job 42 does not exist"}}))]
pub struct ErrorBody {
    /// The error.
    pub error: ErrorDetail,
}

/// The code and message of an error.
#[derive(Serialize, ToSchema)]
pub struct ErrorDetail {
    /// Stable, machine-readable code.
    pub code: String,
    /// Human-readable explanation.
    pub message: String,
}

impl ApiError {
    /// An error with this status, code and message.
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        ApiError { status, code, message: message.into(), retry_after: None }
    }

    /// The error with `Retry-After: secs`.
    pub fn retry_after(mut self, secs: u64) -> Self {
        self.retry_after = Some(secs);
        self
    }

    /// 404 for a missing resource.
    pub fn not_found(message: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, "not_found", message)
    }

    /// 400 for a malformed request.
    pub fn bad_request(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, code, message)
    }

    /// 422 for a well-formed request that asks for something invalid.
    pub fn invalid(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(StatusCode::UNPROCESSABLE_ENTITY, code, message)
    }

    /// 409 for a request that conflicts with the current state.
    pub fn conflict(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(StatusCode::CONFLICT, code, message)
    }

    /// 503 for a service that cannot answer now; `cause` is logged, not sent.
    pub fn unavailable(cause: impl std::fmt::Display) -> Self {
        tracing::error!(%cause, "request failed: service unavailable");
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "unavailable",
            "the service cannot answer now; retry later",
        )
    }
}

/// Seconds a client is told to wait while the store cannot commit.
pub const STORE_RETRY_SECS: u64 = 5;

impl ApiError {
    /// 503 for a request the database failed: `store_full` or `store_unavailable` (with
    /// `Retry-After`) when the store itself fails ([`crate::store::fault`]), else
    /// `unavailable`; `e` is logged, never sent.
    pub fn store(e: &sqlx::Error) -> Self {
        match Cause::of(e) {
            Some(cause) => {
                tracing::error!(cause = %e, store = cause.as_str(), "request failed: the store cannot commit");
                Self::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    cause.api_code(),
                    format!("rackd cannot record anything now: {}; retry later", cause.words()),
                )
                .retry_after(STORE_RETRY_SECS)
            }
            None => Self::unavailable(e),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = ErrorBody { error: ErrorDetail { code: self.code.to_owned(), message: self.message } };
        let mut response = (self.status, axum::Json(body)).into_response();
        if self.status == StatusCode::UNAUTHORIZED {
            response.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        if let Some(secs) = self.retry_after {
            response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from(secs));
        }
        response
    }
}

impl From<WriteError> for ApiError {
    fn from(e: WriteError) -> Self {
        match e {
            WriteError::NotFound(_) | WriteError::AlarmNotFound(_) => Self::not_found(e.to_string()),
            WriteError::AlreadyAcknowledged { .. } => Self::conflict("already_acknowledged", e.to_string()),
            WriteError::Conflict(_) => Self::conflict("reference_conflict", e.to_string()),
            WriteError::Reserved { .. } | WriteError::Taken(_) => {
                Self::conflict("location_reserved", e.to_string())
            }
            WriteError::Unexpected { .. } | WriteError::Illegal(_) => {
                Self::conflict("invalid_state", e.to_string())
            }
            WriteError::Refused(_) => Self::conflict("bulk_refused", e.to_string()),
            WriteError::Sequence(_) => Self::conflict("sequence_conflict", e.to_string()),
            WriteError::UnknownDependency(_) => Self::invalid("unknown_dependency", e.to_string()),
            WriteError::DependencyCycle(_) => Self::invalid("dependency_cycle", e.to_string()),
            WriteError::Overloaded => Self::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "overloaded",
                "rackd is taking in more jobs than it can store right now; retry in a second",
            )
            .retry_after(1),
            WriteError::Database(cause) => Self::store(&cause),
            WriteError::Closed | WriteError::Fenced(_) => Self::unavailable(e),
        }
    }
}

impl From<CancelError> for ApiError {
    fn from(e: CancelError) -> Self {
        let message = e.to_string();
        match e {
            CancelError::NotFound(_) => Self::not_found(message),
            CancelError::Ended { .. } => Self::conflict("job_ended", message),
            CancelError::Refused { .. } | CancelError::Unconfigured { .. } => {
                Self::conflict("job_on_device", message)
            }
            CancelError::Unavailable { .. } => {
                Self::new(StatusCode::SERVICE_UNAVAILABLE, "unavailable", message)
            }
            CancelError::Store(cause) => Self::unavailable(cause),
        }
    }
}

impl From<ControlError> for ApiError {
    fn from(e: ControlError) -> Self {
        let message = e.to_string();
        match e {
            ControlError::NotFound(_) => Self::not_found(message),
            ControlError::NotFailed { .. } => Self::conflict("job_not_failed", message),
            ControlError::Store(cause) => Self::from(cause),
        }
    }
}

impl From<BulkError> for ApiError {
    fn from(e: BulkError) -> Self {
        let message = e.to_string();
        match e {
            BulkError::TooMany { .. } => Self::invalid("bulk_too_large", message),
            BulkError::Refused(_) => Self::conflict("bulk_refused", message),
            BulkError::Unavailable { .. } => {
                Self::new(StatusCode::SERVICE_UNAVAILABLE, "unavailable", message)
            }
            BulkError::Store(cause) => Self::from(cause),
        }
    }
}

impl From<sqlx::Error> for ApiError {
    fn from(e: sqlx::Error) -> Self {
        Self::store(&e)
    }
}
