//! Command-line tools built on the library: rendering, benchmarks and the server's entry point. These use `anyhow`, as
//! binaries do; the library modules below them return typed errors.
pub mod bench;
pub mod bench_error;
pub mod bench_reuse;
pub mod load;
pub mod render;
pub mod serve;

use std::path::{Path, PathBuf};

/// The scene a command renders, at what size, on how many threads (shared by render and bench).
#[derive(clap::Args, Debug, Clone)]
pub struct SceneArgs {
    /// Scene file (JSON).
    pub scene: PathBuf,
    /// Image width (default: the scene camera's).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height (default: the scene camera's).
    #[arg(long)]
    pub height: Option<u32>,
    /// Rendering threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

impl SceneArgs {
    pub fn threads(&self) -> usize {
        threads_or_all_cores(self.threads)
    }
}

/// Writes a report as pretty JSON when the command was given `--json FILE`.
pub fn write_json_report<T: serde::Serialize>(path: Option<&Path>, report: &T) -> anyhow::Result<()> {
    use anyhow::Context;
    if let Some(path) = path {
        std::fs::write(path, serde_json::to_string_pretty(report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The requested thread count, or one per core.
pub fn threads_or_all_cores(requested: Option<usize>) -> usize {
    requested.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// A mistake in the command line or its input files (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// The scenes root for a scene file: the nearest ancestor folder named `scenes`, else the
/// scene's own folder. Mesh paths may not leave it.
pub fn scenes_root_for(scene: &Path) -> PathBuf {
    let dir = scene.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
    let dir = if dir.as_os_str().is_empty() { PathBuf::from(".") } else { dir };
    dir.ancestors().find(|a| a.file_name().is_some_and(|n| n == "scenes")).map(Path::to_path_buf).unwrap_or(dir)
}
