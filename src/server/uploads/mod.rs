//! `PUT /v1/scenes/{name}` and `DELETE /v1/scenes/{name}`: scenes uploaded to the scenes root.
//!
//! A `.glb`, or a `.zip` of a `.gltf` with its files, is streamed to a staging file as it
//! arrives (never held in memory), hashed (SHA-256) on the way, and cut off at
//! `--upload-limit` bytes (413; up to [`DRAIN_BYTES`] more are read and dropped first, so the
//! client gets the answer) or when no byte has come for the request timeout (408). It is
//! then validated off the async runtime: an archive is unpacked as hostile input
//! ([`archive`]), and the scene is imported under the server's scene budget. Only a scene that
//! imports is put in place ([`store`]), and the answer is its [`store::UploadRecord`]: 201 for
//! a new name, 200 for a replaced one. A refused upload answers 4xx naming what is wrong and
//! leaves nothing behind.
//!
//! Sessions open an upload by its name (`"scene": "city.zip"`), as they open a bundled scene.
pub mod archive;
pub mod store;

use super::error::ApiError;
use super::routes::Shared;
use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::Json;
use futures_util::StreamExt;
use sha2::{Digest, Sha256};
use std::path::Path as FsPath;
use store::{Kind, Staged, UploadRecord};
use tokio::io::AsyncWriteExt;

pub async fn put_scene(
    State(s): State<Shared>,
    Path(name): Path<String>,
    headers: HeaderMap,
    body: Body,
) -> Result<(StatusCode, Json<UploadRecord>), ApiError> {
    let Some(kind) = store::kind_of(&name) else {
        return Err(ApiError::bad_request(format!(
            "name: '{name}' is not an upload's name: NAME.glb or NAME.zip, NAME of letters, digits, '-' and '_'"
        )));
    };
    let limit = s.config.limits.upload_limit;
    let declared = headers
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit.saturating_add(DRAIN_BYTES)) {
        return Err(over_limit(limit));
    }
    let root = s.config.scenes_root.clone();
    let staged = Staged::new(&root, if kind == Kind::Zip { ".zip" } else { ".glb" });
    let (bytes, sha256) = receive(body, &staged.path, limit, s.config.limits.request_timeout).await?;
    let state = s.clone();
    let validated = tokio::task::spawn_blocking(move || {
        let received = Received { name, kind, staged, bytes, sha256 };
        place(&state.config.scenes_root, received, &state.config.limits)
    });
    let (record, replaced) =
        validated.await.map_err(|e| ApiError::internal(format!("validating an upload: {e}")))??;
    let status = if replaced { StatusCode::OK } else { StatusCode::CREATED };
    Ok((status, Json(record)))
}

pub async fn delete_scene(State(s): State<Shared>, Path(name): Path<String>) -> Result<StatusCode, ApiError> {
    let root = s.config.scenes_root.clone();
    tokio::task::spawn_blocking(move || store::remove(&root, &name))
        .await
        .map_err(|e| ApiError::internal(format!("deleting an upload: {e}")))??;
    Ok(StatusCode::NO_CONTENT)
}

/// How much of a refused body is still read (and dropped) before the answer, so that a client
/// still sending it gets the answer instead of a reset connection; a body larger than that
/// past the limit is refused unread, and its connection closed.
const DRAIN_BYTES: u64 = 16 << 20;

fn over_limit(limit: u64) -> ApiError {
    ApiError::too_large(format!("body: larger than the upload limit of {limit} bytes (--upload-limit)"))
}

/// Writes the body to `path` as it arrives, at most `limit` bytes, and returns its length and
/// SHA-256; a pause longer than `idle` between chunks ends it with 408.
async fn receive(body: Body, path: &FsPath, limit: u64, idle: std::time::Duration) -> Result<(u64, String), ApiError> {
    let mut file = tokio::fs::File::create(path).await.map_err(not_stored)?;
    let mut stream = body.into_data_stream();
    let (mut hash, mut bytes) = (Sha256::new(), 0u64);
    loop {
        let chunk = match tokio::time::timeout(idle, stream.next()).await {
            Err(_) => {
                return Err(ApiError::new(
                    StatusCode::REQUEST_TIMEOUT,
                    "timeout",
                    format!("body: no bytes for {idle:?} after {bytes} bytes"),
                ))
            }
            Ok(None) => break,
            Ok(Some(Err(e))) => {
                return Err(ApiError::bad_request(format!("body: ended early after {bytes} bytes: {e}")))
            }
            Ok(Some(Ok(chunk))) => chunk,
        };
        bytes += chunk.len() as u64;
        if bytes > limit {
            drain(&mut stream, idle).await;
            return Err(over_limit(limit));
        }
        hash.update(&chunk);
        file.write_all(&chunk).await.map_err(not_stored)?;
    }
    file.flush().await.map_err(not_stored)?;
    let hex = hash.finalize().iter().map(|b| format!("{b:02x}")).collect();
    Ok((bytes, hex))
}

/// 507: the scenes folder takes no more (read-only, full, or not this process's to write).
fn not_stored(e: std::io::Error) -> ApiError {
    ApiError::new(
        StatusCode::INSUFFICIENT_STORAGE,
        "insufficient_storage",
        format!("body: this server's scenes folder cannot store the upload ({e}); see --scenes"),
    )
}

/// Reads and drops at most [`DRAIN_BYTES`] more of a refused body, while it keeps coming.
async fn drain(stream: &mut axum::body::BodyDataStream, idle: std::time::Duration) {
    let mut dropped = 0u64;
    while dropped <= DRAIN_BYTES {
        match tokio::time::timeout(idle, stream.next()).await {
            Ok(Some(Ok(chunk))) => dropped += chunk.len() as u64,
            _ => return,
        }
    }
}

/// An upload received whole into its staging file.
struct Received {
    name: String,
    kind: Kind,
    staged: Staged,
    bytes: u64,
    sha256: String,
}

/// Validates a received upload (unpacking an archive first) and puts it in place: its record,
/// and whether it replaced an upload of the same name. Blocking.
fn place(root: &FsPath, r: Received, limits: &super::Limits) -> Result<(UploadRecord, bool), ApiError> {
    let (staged, scene_file) = match r.kind {
        Kind::Glb => (r.staged, None),
        Kind::Zip => {
            let folder = Staged::new(root, "");
            std::fs::create_dir(&folder.path).map_err(|e| ApiError::internal(format!("unpacking: {e}")))?;
            let files = archive::extract(&r.staged.path, &folder.path, limits.upload_limit)?;
            let scene = the_scene_file(&files)?;
            (folder, Some(scene))
        }
    };
    let path = match &scene_file {
        Some(f) => staged.path.join(f),
        None => staged.path.clone(),
    };
    let (triangles, animations) = import(&path, root, limits)?;
    let scene_file = scene_file.map_or_else(|| r.name.clone(), |f| f.to_string_lossy().replace('\\', "/"));
    let record = UploadRecord { name: r.name, bytes: r.bytes, sha256: r.sha256, triangles, animations, scene_file };
    let replaced = store::commit(root, staged, &record)?;
    Ok((record, replaced))
}

/// The one `.gltf` or `.glb` file among an archive's files.
fn the_scene_file(files: &[std::path::PathBuf]) -> Result<std::path::PathBuf, ApiError> {
    let scenes: Vec<&std::path::PathBuf> = files.iter().filter(|f| crate::scene::gltf::is_gltf_path(f)).collect();
    match scenes.as_slice() {
        [one] => Ok((*one).clone()),
        [] => Err(ApiError::invalid("body: the archive holds no .gltf or .glb file")),
        many => Err(ApiError::invalid(format!(
            "body: the archive holds {} glTF files ({}); an upload is one scene",
            many.len(),
            many.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
        ))),
    }
}

/// Imports the scene at `path` under the server's scene budget, as a session would, and
/// returns its triangle count and animation names.
fn import(path: &FsPath, root: &FsPath, limits: &super::Limits) -> Result<(u64, Vec<String>), ApiError> {
    let options = crate::scene::gltf::ImportOptions {
        budget: limits.scene_budget(),
        max_buffer_bytes: limits.upload_limit,
        ..Default::default()
    };
    let imported =
        crate::scene::gltf::import_file(path, root, &options).map_err(|e| super::create::scene_error("body: ", e))?;
    let dir = path.parent().unwrap_or(root);
    let triangles = crate::scene::load::count_triangles(&imported.desc, dir, root)
        .map_err(|e| super::create::scene_error("body: ", e))?;
    Ok((triangles, imported.animations.into_iter().map(|(name, _)| name).collect()))
}
