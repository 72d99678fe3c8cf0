//! The API's own description, served by the binary: `GET /api/openapi.yaml` and the files its
//! relative `$ref`s name (`/api/scene.schema.json`, `/api/examples/tick.response.json`, ...), so
//! a client of a deployed server, or a tool such as Swagger UI, reads the spec that server was
//! built with, without the repository.
//!
//! Invariant (`tests/openapi.rs`): every file under `proto/` is in [`FILES`], byte for byte, and
//! nothing else is. The files are compiled in; a request only looks a name up in that table, so
//! no path a client sends ever reaches the file system.
use super::error::ApiError;
use axum::extract::Path;
use axum::http::header;
use axum::response::{IntoResponse, Response};

/// `(path under proto/, contents)` for each served file.
macro_rules! proto_files {
    ($($name:literal),* $(,)?) => { &[$(($name, include_str!(concat!("../../proto/", $name)))),*] };
}

pub const FILES: &[(&str, &str)] = proto_files![
    "openapi.yaml",
    "scene.schema.json",
    "animation.schema.json",
    "snapshot.schema.json",
    "ws.schema.json",
    "examples/create-session.request.json",
    "examples/create-session.response.json",
    "examples/edits.request.json",
    "examples/edits.response.json",
    "examples/error.response.json",
    "examples/scenes.response.json",
    "examples/stats.response.json",
    "examples/tick.response.json",
    "examples/update-session.request.json",
    "examples/ws-client-edits.json",
    "examples/ws-client-pause.json",
    "examples/ws-client-play.json",
    "examples/ws-client-subscribe.json",
    "examples/ws-client-tick.json",
    "examples/ws-client-update.json",
    "examples/ws-server-edits-accepted.json",
    "examples/ws-server-error.json",
    "examples/ws-server-stats.json",
    "examples/ws-server-updated.json",
];

/// `GET /api/{file}`.
pub async fn file(Path(file): Path<String>) -> Result<Response, ApiError> {
    serve(&file)
}

/// `GET /api/examples/{file}`.
pub async fn example(Path(file): Path<String>) -> Result<Response, ApiError> {
    serve(&format!("examples/{file}"))
}

fn serve(name: &str) -> Result<Response, ApiError> {
    let (_, body) = FILES
        .iter()
        .find(|(n, _)| *n == name)
        .ok_or_else(|| ApiError::not_found(format!("file: no API document {name:?} (start at /api/openapi.yaml)")))?;
    let kind = if name.ends_with(".yaml") { "application/yaml" } else { "application/json" };
    Ok(([(header::CONTENT_TYPE, kind)], *body).into_response())
}
