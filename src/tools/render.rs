//! `relume render`: a still image, or an animation rendered through the same session and tick
//! path the service uses.
use super::{scenes_root_for, UsageError};
use crate::embree::Device;
use crate::engine::{thread_pool, Session};
use crate::film::{write_image, ImageFormat};
use crate::scene::Scene;
use crate::technique::path::PathConfig;
use crate::technique::TechniqueConfig;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Scene file (JSON).
    pub scene: PathBuf,
    /// Technique id.
    #[arg(long, default_value = "path")]
    pub technique: String,
    /// Samples per pixel: for a still, the total; for an animation, per frame.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Output file (.png, .jpg or .exr), or a folder with --anim.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Rendering threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Exposure in stops for PNG/JPEG output.
    #[arg(long, default_value_t = 0.0)]
    pub exposure: f32,
}

pub fn technique_config(id: &str) -> Result<TechniqueConfig> {
    match id {
        "path" => Ok(TechniqueConfig::Path(PathConfig::default())),
        other => Err(UsageError(format!("unknown technique '{other}' (available: path)")).into()),
    }
}

pub fn load_scene(path: &std::path::Path, width: Option<u32>, height: Option<u32>) -> Result<Scene> {
    let root = scenes_root_for(path);
    let mut scene = Scene::load(path, &root).map_err(|e| UsageError(format!("{}: {e}", path.display())))?;
    if width.is_some() || height.is_some() {
        let (w, h) = (width.unwrap_or(scene.camera.width), height.unwrap_or(scene.camera.height));
        if w == 0 || h == 0 || w > crate::scene::load::MAX_RESOLUTION || h > crate::scene::load::MAX_RESOLUTION {
            return Err(
                UsageError(format!("--width/--height must lie in 1..={}", crate::scene::load::MAX_RESOLUTION)).into()
            );
        }
        scene.set_resolution(w, h);
    }
    Ok(scene)
}

pub fn run(args: RenderArgs) -> Result<()> {
    let format = ImageFormat::from_path(&args.out).map_err(|e| UsageError(e.to_string()))?;
    let scene = load_scene(&args.scene, args.width, args.height)?;
    let config = technique_config(&args.technique)?;
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = thread_pool(threads)?;
    let device = Device::new(threads).context("creating the Embree device")?;
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut session = Session::new(scene, &config, args.seed, &device)?;

    let bar = ProgressBar::new(args.spp as u64);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{bar:30}] {pos}/{len} spp ({eta} left)")?.progress_chars("=> "),
    );
    bar.set_message(format!("{}x{} {}", w, h, args.technique));
    let mut last = None;
    let mut rays = 0u64;
    let started = std::time::Instant::now();
    pool.install(|| -> Result<()> {
        for _ in 0..args.spp {
            let frame = session.tick()?;
            rays += frame.stats.rays.total();
            last = Some(frame);
            bar.inc(1);
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    let secs = started.elapsed().as_secs_f64();
    let frame = last.ok_or_else(|| UsageError("--spp must be at least 1".into()))?;
    write_image(&frame.image, &args.out, args.exposure)?;
    let mean = frame.image.mean();
    eprintln!(
        "wrote {} ({:?}): {} spp, {:.1} paths/pixel, {:.2} s, {:.1} Mrays/s, mean radiance [{:.4}, {:.4}, {:.4}]",
        args.out.display(),
        format,
        frame.spp,
        frame.stats.paths_per_pixel,
        secs,
        rays as f64 / secs / 1e6,
        mean.r,
        mean.g,
        mean.b
    );
    Ok(())
}
