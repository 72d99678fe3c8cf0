//! API errors: every failure answers JSON `{error, detail}` with a 4xx for client faults and a
//! 500 (plus a log line) for internal ones. Nothing panics or exits on bad input.
use super::protocol::ErrorBody;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use std::sync::atomic::{AtomicU64, Ordering};

/// The `error` code of an answer, kept on the response so `/metrics` counts rejections by
/// code (`relume_rejected_requests_total{reason=CODE}`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ErrorCode(pub &'static str);

/// An error answer. `error` is a stable machine-readable code; `detail` is for people.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ApiError {
    pub status: StatusCode,
    pub error: &'static str,
    pub detail: String,
}

impl ApiError {
    pub fn new(status: StatusCode, error: &'static str, detail: impl Into<String>) -> ApiError {
        ApiError { status, error, detail: detail.into() }
    }

    pub fn bad_request(detail: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::BAD_REQUEST, "bad_request", detail)
    }

    pub fn invalid(detail: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid", detail)
    }

    pub fn too_large(detail: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, "too_large", detail)
    }

    pub fn not_found(detail: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::NOT_FOUND, "not_found", detail)
    }

    /// A 500 whose answer names only a reference: what went wrong inside (paths, library
    /// messages) goes to the log under that reference, never to the client.
    pub fn internal(detail: impl Into<String>) -> ApiError {
        static NEXT_REFERENCE: AtomicU64 = AtomicU64::new(1);
        let reference = NEXT_REFERENCE.fetch_add(1, Ordering::Relaxed);
        tracing::error!(target: "relume::server", reference, "internal error: {}", detail.into());
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            format!("an internal error occurred; the server logged it as reference {reference}"),
        )
    }
}

impl IntoResponse for ApiError {
    /// A 503 (a draining node, the connection limit, a missing denoiser) says when to try
    /// again: `Retry-After: 1`, time enough for a proxy to pick another node.
    fn into_response(self) -> Response {
        let unavailable = self.status == StatusCode::SERVICE_UNAVAILABLE;
        let code = ErrorCode(self.error);
        let mut resp =
            (self.status, Json(ErrorBody { error: self.error.to_string(), detail: self.detail })).into_response();
        resp.extensions_mut().insert(code);
        if unavailable {
            resp.headers_mut().insert(axum::http::header::RETRY_AFTER, axum::http::HeaderValue::from_static("1"));
        }
        resp
    }
}

impl From<crate::scene::SceneError> for ApiError {
    fn from(e: crate::scene::SceneError) -> ApiError {
        ApiError::invalid(e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_internal_error_answers_a_reference_and_keeps_its_detail_in_the_log() {
        let secret = "rtcCommitScene failed in /srv/relume/scenes/private.glb";
        let (a, b) = (ApiError::internal(secret), ApiError::internal(secret));
        assert_eq!((a.status, a.error), (StatusCode::INTERNAL_SERVER_ERROR, "internal"));
        for e in [&a, &b] {
            assert!(!e.detail.contains("private.glb") && !e.detail.contains("rtc"), "{}", e.detail);
            assert!(e.detail.contains("reference "), "{}", e.detail);
        }
        // Each answer names its own reference, so a log line can be found from it.
        assert_ne!(a.detail, b.detail);
        // Control: any other error passes its detail through, as a client fault should.
        assert_eq!(ApiError::invalid(secret).detail, secret);
    }
}
