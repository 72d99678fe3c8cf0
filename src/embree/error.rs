//! Errors reported by Embree or by argument checks in front of it.
use thiserror::Error;

/// An Embree failure. `code` is Embree's `RTCError` name where Embree reported one.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum EmbreeError {
    #[error("embree {code}: {context}")]
    Device { code: &'static str, context: String },
    #[error("invalid geometry: {0}")]
    InvalidGeometry(String),
    #[error("unknown geometry id {0}")]
    UnknownGeometry(u32),
    #[error("the Embree library loaded is {found}; relume was built against the {headers} headers and needs 4.x at least as new")]
    LibraryVersion { found: String, headers: String },
    #[error("scene is still shared by {0} other holder(s); it cannot be edited while tracing")]
    SceneShared(usize),
}

/// Maps Embree's numeric error code to its name.
pub(crate) fn error_name(code: u32) -> &'static str {
    use super::sys::*;
    match code {
        RTC_ERROR_NONE => "RTC_ERROR_NONE",
        RTC_ERROR_UNKNOWN => "RTC_ERROR_UNKNOWN",
        RTC_ERROR_INVALID_ARGUMENT => "RTC_ERROR_INVALID_ARGUMENT",
        RTC_ERROR_INVALID_OPERATION => "RTC_ERROR_INVALID_OPERATION",
        RTC_ERROR_OUT_OF_MEMORY => "RTC_ERROR_OUT_OF_MEMORY",
        RTC_ERROR_UNSUPPORTED_CPU => "RTC_ERROR_UNSUPPORTED_CPU",
        RTC_ERROR_CANCELLED => "RTC_ERROR_CANCELLED",
        _ => "RTC_ERROR_(unrecognised)",
    }
}
