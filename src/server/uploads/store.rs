//! Where uploaded scenes live in the scenes root, and how one becomes visible.
//!
//! An upload named `NAME.glb` is the file `NAME.glb`; one named `NAME.zip` is the folder
//! `NAME.zip/` holding the archive's files. Beside each, the hidden record `.NAME.upload.json`
//! ([`UploadRecord`]) keeps what listing needs (size, SHA-256, triangles, animations, the
//! glTF file inside a folder), so listing never reads a scene.
//!
//! Invariant: nothing a client can open is half written. An upload is received and unpacked
//! under a hidden staging name (`.upload-…`, never listed), validated there, and only then
//! renamed into place (a rename within one file system is atomic); its record follows. A
//! staging name that is dropped before it is committed is removed, so a refused upload leaves
//! nothing behind.
use super::super::error::ApiError;
use super::super::state::valid_name;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// What a finished upload is, as `PUT /v1/scenes/{name}` answers and `GET /v1/scenes` lists.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UploadRecord {
    pub name: String,
    /// Bytes received (the `.glb` or the `.zip` as sent).
    pub bytes: u64,
    /// SHA-256 of the bytes received, in lowercase hex.
    pub sha256: String,
    pub triangles: u64,
    pub animations: Vec<String>,
    /// The glTF file a `.zip` upload opens, relative to its folder (the name itself for a
    /// `.glb`).
    pub scene_file: String,
}

/// The two forms an upload takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Glb,
    Zip,
}

/// The kind of an upload's name: `STEM.glb` or `STEM.zip`, the stem letters, digits, `-` and
/// `_` (so no `/`, `..` or hidden names).
pub fn kind_of(name: &str) -> Option<Kind> {
    match name.rsplit_once('.') {
        Some((stem, "glb")) if valid_name(stem) => Some(Kind::Glb),
        Some((stem, "zip")) if valid_name(stem) => Some(Kind::Zip),
        _ => None,
    }
}

fn record_path(root: &Path, name: &str) -> PathBuf {
    root.join(format!(".{name}.upload.json"))
}

/// The record of the upload `name`, if `name` is an upload.
pub fn read_record(root: &Path, name: &str) -> Option<UploadRecord> {
    kind_of(name)?;
    let text = std::fs::read_to_string(record_path(root, name)).ok()?;
    serde_json::from_str(&text).ok()
}

/// The glTF file a session opens for the scene `name`, if `name` is a `.zip` upload.
pub fn zip_scene_file(root: &Path, name: &str) -> Option<PathBuf> {
    if kind_of(name)? != Kind::Zip {
        return None;
    }
    let record = read_record(root, name)?;
    Some(root.join(name).join(record.scene_file)).filter(|p| p.is_file())
}

/// A hidden staging name in the scenes root (a file or a folder), removed when dropped
/// unless it was committed.
pub struct Staged {
    pub path: PathBuf,
}

impl Staged {
    pub fn new(root: &Path, suffix: &str) -> Staged {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        Staged { path: root.join(format!(".upload-{}-{n}{suffix}", std::process::id())) }
    }

    /// Renames the staged file or folder to `target`, replacing what is there (a folder is
    /// first moved aside, then removed). Returns whether something was replaced.
    fn commit(self, target: &Path) -> std::io::Result<bool> {
        let replaced = target.exists();
        if self.path.is_dir() && target.is_dir() {
            let aside = Staged::new(target.parent().unwrap_or(Path::new(".")), ".old");
            std::fs::rename(target, &aside.path)?;
            std::fs::rename(&self.path, target)?;
            drop(aside);
        } else {
            std::fs::rename(&self.path, target)?;
        }
        std::mem::forget(self);
        Ok(replaced)
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        let removed =
            if self.path.is_dir() { std::fs::remove_dir_all(&self.path) } else { std::fs::remove_file(&self.path) };
        if let Err(e) = removed {
            if e.kind() != std::io::ErrorKind::NotFound {
                tracing::warn!(target: "relume::server", "could not remove {}: {e}", self.path.display());
            }
        }
    }
}

/// Puts a validated upload in place under `record.name`, then its record. One commit at a
/// time, so two uploads of one name never interleave their renames. Returns whether an
/// upload of that name was replaced.
pub fn commit(root: &Path, staged: Staged, record: &UploadRecord) -> Result<bool, ApiError> {
    static COMMITS: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = COMMITS.lock().map_err(|_| ApiError::internal("upload lock poisoned"))?;
    let failed = |e: std::io::Error| ApiError::internal(format!("storing upload {}: {e}", record.name));
    let replaced = staged.commit(&root.join(&record.name)).map_err(failed)?;
    let text = serde_json::to_string_pretty(record).map_err(|e| ApiError::internal(e.to_string()))?;
    let staged_record = Staged::new(root, ".json");
    std::fs::write(&staged_record.path, text).map_err(failed)?;
    staged_record.commit(&record_path(root, &record.name)).map_err(failed)?;
    Ok(replaced)
}

/// Deletes the upload `name` and its record. A bundled scene (one without a record) is not
/// an upload and stays.
pub fn remove(root: &Path, name: &str) -> Result<(), ApiError> {
    let Some(kind) = kind_of(name) else {
        return Err(ApiError::bad_request(format!("name: '{name}' is not an upload's name (NAME.glb or NAME.zip)")));
    };
    if read_record(root, name).is_none() {
        return Err(match root.join(name).exists() {
            true => ApiError::new(
                axum::http::StatusCode::FORBIDDEN,
                "forbidden",
                format!("name: '{name}' is bundled with the server, not uploaded; only uploads can be deleted"),
            ),
            false => ApiError::not_found(format!("name: no uploaded scene '{name}' (see GET /v1/scenes)")),
        });
    }
    let failed = |e: std::io::Error| ApiError::internal(format!("deleting upload {name}: {e}"));
    std::fs::remove_file(record_path(root, name)).map_err(failed)?;
    let target = root.join(name);
    match kind {
        Kind::Glb => std::fs::remove_file(target),
        Kind::Zip => std::fs::remove_dir_all(target),
    }
    .or_else(|e| if e.kind() == std::io::ErrorKind::NotFound { Ok(()) } else { Err(e) })
    .map_err(failed)
}
