//! The bytes behind a glTF document's buffers: the GLB binary chunk, `data:` URIs (base64)
//! and external files, which must lie inside the scenes root exactly as OBJ mesh paths must.
//!
//! Invariant: every returned buffer holds at least the `byteLength` its document declares, so
//! the accessor readers never see a buffer shorter than the document promised.
use super::super::load::{invalid, resolve_mesh_path, SceneError};
use base64::Engine;
use std::path::Path;

/// Where external buffer files resolve: the folder of the glTF file and the scenes root it
/// must stay in. `None` for a document with no folder (sent inline), which may then only use
/// the GLB chunk and `data:` URIs.
pub struct FileContext<'a> {
    pub dir: &'a Path,
    pub root: &'a Path,
}

/// Reads every buffer of `doc`; `blob` is the GLB binary chunk, if any. `max_bytes` bounds
/// the declared total, checked before anything is read.
pub fn load(
    doc: &gltf::Document,
    mut blob: Option<Vec<u8>>,
    files: Option<&FileContext>,
    max_bytes: u64,
) -> Result<Vec<Vec<u8>>, SceneError> {
    let declared: u64 = doc.buffers().map(|b| b.length() as u64).sum();
    if declared > max_bytes {
        return Err(SceneError::TooLarge {
            field: "buffers".into(),
            message: format!("{declared} bytes of buffers exceed the limit of {max_bytes}"),
        });
    }
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let field = format!("buffers[{}]", buffer.index());
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => {
                blob.take().ok_or_else(|| invalid(&field, "refers to the GLB binary chunk, which is missing"))?
            }
            gltf::buffer::Source::Uri(uri) => read_uri(&format!("{field}.uri"), uri, files, max_bytes)?,
        };
        if data.len() < buffer.length() {
            return Err(invalid(
                format!("{field}.byteLength"),
                format!("declares {} bytes but the data holds {}", buffer.length(), data.len()),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

fn read_uri(field: &str, uri: &str, files: Option<&FileContext>, max_bytes: u64) -> Result<Vec<u8>, SceneError> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest
            .split_once(";base64,")
            .ok_or_else(|| invalid(field, "a data: URI must be base64 (data:…;base64,…)"))?;
        return base64::engine::general_purpose::STANDARD
            .decode(payload)
            .map_err(|e| invalid(field, format!("invalid base64 in data: URI: {e}")));
    }
    if uri.contains("://") {
        return Err(invalid(field, format!("'{uri}': only relative file paths and data: URIs are read")));
    }
    let Some(files) = files else {
        return Err(invalid(field, format!("'{uri}': an inline glTF cannot refer to files; use a .glb or data: URIs")));
    };
    let decoded = percent_encoding::percent_decode_str(uri).decode_utf8_lossy().into_owned();
    let path = resolve_mesh_path(field, &decoded, files.dir, files.root)?;
    let io = |e: std::io::Error| SceneError::Io { path: path.display().to_string(), message: e.to_string() };
    let size = std::fs::metadata(&path).map_err(io)?.len();
    if size > max_bytes {
        return Err(SceneError::TooLarge {
            field: field.into(),
            message: format!("'{uri}' holds {size} bytes, over the limit of {max_bytes}"),
        });
    }
    std::fs::read(&path).map_err(io)
}
