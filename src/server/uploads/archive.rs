//! Unpacks an uploaded `.zip` (a `.gltf` with its buffers and textures) into a folder, as
//! hostile input: every entry's path must stay inside the folder (no absolute paths, no `..`,
//! no symbolic links), encrypted entries are refused, and the bytes written are bounded twice
//! before they are written: in all by the upload limit, and per entry by a compression ratio
//! that no real scene file reaches (a zip bomb's does). An entry that inflates past the size its
//! header declares is refused as it is read, so a lying header writes at most one byte more.
use super::super::error::ApiError;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Entries an archive may hold.
pub const MAX_ENTRIES: usize = 10_000;

/// The largest ratio of inflated to compressed size an entry may have once it is past
/// [`RATIO_FLOOR`] bytes. Deflate reaches about 1 000:1 on a run of one byte, the material
/// zip bombs are made of; a scene's JSON, buffers and images stay far below 100:1.
pub const MAX_RATIO: u64 = 200;

/// Entries up to this size are never judged by their ratio (a small, very regular file, such
/// as a glTF's JSON, may compress well).
pub const RATIO_FLOOR: u64 = 1 << 20;

/// Unpacks `zip` into the existing folder `dest`, writing at most `max_bytes` in all, and
/// returns the files it wrote, relative to `dest`. On an error some files may be written:
/// the caller removes `dest`.
pub fn extract(zip: &Path, dest: &Path, max_bytes: u64) -> Result<Vec<PathBuf>, ApiError> {
    let file = std::fs::File::open(zip).map_err(|e| ApiError::internal(format!("reopening an upload: {e}")))?;
    let mut archive =
        zip::ZipArchive::new(file).map_err(|e| ApiError::invalid(format!("body: not a readable zip archive: {e}")))?;
    if archive.len() > MAX_ENTRIES {
        return Err(ApiError::too_large(format!(
            "body: the archive holds {} entries, more than the {MAX_ENTRIES} allowed",
            archive.len()
        )));
    }
    let mut written = 0u64;
    let mut files = Vec::new();
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).map_err(|e| ApiError::invalid(format!("archive entry {i}: {e}")))?;
        let shown = entry.name().map_or_else(|_| format!("#{i}"), |n| n.to_string());
        let Some(relative) = entry.enclosed_name() else {
            return Err(ApiError::invalid(format!("archive entry '{shown}': its path leaves the archive's folder")));
        };
        if entry.is_symlink() {
            return Err(ApiError::invalid(format!("archive entry '{shown}': symbolic links are not allowed")));
        }
        if entry.encrypted() {
            return Err(ApiError::invalid(format!("archive entry '{shown}': encrypted entries are not allowed")));
        }
        let target = dest.join(&relative);
        if entry.is_dir() {
            create_dir(&target)?;
            continue;
        }
        check_size(&shown, entry.size(), entry.compressed_size(), written, max_bytes)?;
        if let Some(parent) = target.parent() {
            create_dir(parent)?;
        }
        written += copy_bounded(&mut entry, &shown, &target)?;
        files.push(relative);
    }
    Ok(files)
}

/// Refuses an entry whose declared size would take the archive past `max_bytes`, or whose
/// ratio marks a zip bomb.
fn check_size(name: &str, size: u64, compressed: u64, written: u64, max_bytes: u64) -> Result<(), ApiError> {
    if written.saturating_add(size) > max_bytes {
        return Err(ApiError::too_large(format!(
            "archive entry '{name}': unpacking it takes the archive past the upload limit of {max_bytes} bytes (--upload-limit)"
        )));
    }
    if size > RATIO_FLOOR && size / compressed.max(1) > MAX_RATIO {
        return Err(ApiError::too_large(format!(
            "archive entry '{name}': {compressed} bytes inflate to {size}, more than {MAX_RATIO} times (a zip bomb?)"
        )));
    }
    Ok(())
}

/// Copies an entry to `target`, reading at most one byte past its declared size: an entry that
/// inflates to more than its header said is refused.
fn copy_bounded(entry: &mut zip::read::ZipFile<'_, std::fs::File>, name: &str, target: &Path) -> Result<u64, ApiError> {
    let declared = entry.size();
    let mut out = std::fs::File::create(target).map_err(|e| ApiError::internal(format!("unpacking: {e}")))?;
    let copied = std::io::copy(&mut entry.take(declared + 1), &mut out)
        .map_err(|e| ApiError::invalid(format!("archive entry '{name}': {e}")))?;
    if copied > declared {
        return Err(ApiError::invalid(format!(
            "archive entry '{name}': inflates past the {declared} bytes its header declares"
        )));
    }
    Ok(copied)
}

fn create_dir(path: &Path) -> Result<(), ApiError> {
    std::fs::create_dir_all(path).map_err(|e| ApiError::internal(format!("unpacking: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_entry_is_judged_at_the_exact_bounds_of_the_limit_and_the_ratio() {
        let (limit, compressed) = (10 * RATIO_FLOOR, RATIO_FLOOR / 64);
        // The ratio: MAX_RATIO times the compressed size passes, one byte more is a bomb;
        // at or under the floor, no ratio is a bomb.
        assert!(check_size("a", MAX_RATIO * compressed, compressed, 0, u64::MAX).is_ok());
        let bomb = check_size("a", (MAX_RATIO + 1) * compressed, compressed, 0, u64::MAX).expect_err("a bomb");
        assert!(bomb.detail.contains("zip bomb"), "{}", bomb.detail);
        assert!(check_size("a", RATIO_FLOOR, 1, 0, u64::MAX).is_ok());
        // The limit counts what earlier entries wrote: reaching it passes, passing it does not.
        assert!(check_size("b", 4 * RATIO_FLOOR, RATIO_FLOOR, limit - 4 * RATIO_FLOOR, limit).is_ok());
        let over = check_size("b", 4 * RATIO_FLOOR, RATIO_FLOOR, limit - 4 * RATIO_FLOOR + 1, limit).expect_err("over");
        assert!(over.detail.contains("--upload-limit") && over.detail.contains("'b'"), "{}", over.detail);
    }
}
