//! `relume render`: a still image, or an animation rendered through the same session and tick
//! path the service uses.
use super::{denoise_settings, SceneArgs, UsageError};
use crate::embree::Device;
use crate::engine::{thread_pool, Frame, Session};
use crate::film::{check_exposure, write_image, ImageFormat};
use crate::scene::Scene;
use crate::technique::TechniqueConfig;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    #[command(flatten)]
    pub target: SceneArgs,
    /// Technique spec: `path`, `photon_reuse:error@0.001`, `photon_reuse:naive:paths=200000`...
    #[arg(long, default_value = "path")]
    pub technique: String,
    /// Samples per pixel: for a still, the total; for an animation, per frame.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Output file (.png, .jpg or .exr), or a folder with --anim.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Exposure in stops for PNG/JPEG output (negative darkens: `--exposure -1`).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub exposure: f32,
    /// Animation to render: NAME.anim.json, or for a glTF scene an animation's name in the
    /// file; --out is then a folder.
    #[arg(long)]
    pub anim: Option<PathBuf>,
    /// Frames to render, spread evenly over the animation's duration.
    #[arg(long, default_value_t = 24)]
    pub frames: u32,
    /// Image format of animation frames.
    #[arg(long, default_value = "png")]
    pub format: String,
    /// Denoise the output with Open Image Denoise: `--denoise` (quality high), or
    /// `--denoise=fast|balanced|high`. A still is denoised once, at the end.
    #[arg(long, value_name = "QUALITY", num_args = 0..=1, require_equals = true, default_missing_value = "high")]
    pub denoise: Option<String>,
}

/// The technique configuration for a CLI technique spec (`ID[:VARIANT][@VALUE][:KEY=VALUE]...`,
/// parsed like the service's JSON), with `spp` paths per pixel per tick.
pub fn technique_config(spec: &str, spp: u32) -> Result<TechniqueConfig> {
    let mut config = TechniqueConfig::from_spec(spec).map_err(|e| UsageError(format!("--technique: {e}")))?;
    config.set_spp_per_tick(spp);
    config.validate().map_err(|e| UsageError(format!("--technique: {e}")))?;
    Ok(config)
}

pub fn run(args: RenderArgs) -> Result<()> {
    if args.spp == 0 {
        return Err(UsageError("--spp must be at least 1".into()).into());
    }
    check_exposure(args.exposure).map_err(|m| UsageError(format!("--exposure: {m}")))?;
    match &args.anim {
        Some(anim) => render_animation(&args, anim),
        None => render_still(&args),
    }
}

fn make_session(args: &RenderArgs, spp_per_tick: u32) -> Result<(Session, rayon::ThreadPool, Device)> {
    make_session_of(args, args.target.load_scene()?, spp_per_tick)
}

fn make_session_of(args: &RenderArgs, scene: Scene, spp_per_tick: u32) -> Result<(Session, rayon::ThreadPool, Device)> {
    let config = technique_config(&args.technique, spp_per_tick)?;
    let threads = args.target.threads();
    let pool = thread_pool(threads)?;
    let device = args.target.device()?;
    let session = Session::new(scene, &config, args.seed, &device)?;
    Ok((session, pool, device))
}

fn bar(len: u64, unit: &str, message: String) -> Result<ProgressBar> {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "{{spinner}} {{msg}} [{{bar:30}}] {{pos}}/{{len}} {unit} ({{eta}} left)"
        ))?
        .progress_chars("=> "),
    );
    bar.set_message(message);
    Ok(bar)
}

/// A still: one tick per sample, accumulating progressively.
fn render_still(args: &RenderArgs) -> Result<()> {
    let format = ImageFormat::from_path(&args.out).map_err(|e| UsageError(e.to_string()))?;
    let (mut session, pool, _device) = make_session(args, 1)?;
    let (w, h) = (session.scene().camera.width, session.scene().camera.height);
    let bar = bar(args.spp as u64, "spp", format!("{w}x{h} {}", args.technique))?;
    let started = std::time::Instant::now();
    let mut rays = 0u64;
    let frame = pool.install(|| -> Result<Frame> {
        let mut last = session.tick()?;
        rays += last.stats.rays.total();
        bar.inc(1);
        for _ in 1..args.spp {
            last = session.tick()?;
            rays += last.stats.rays.total();
            bar.inc(1);
        }
        Ok(last)
    })?;
    bar.finish_and_clear();
    let secs = started.elapsed().as_secs_f64();
    let image = match denoise_settings(args.denoise.as_deref())? {
        Some(settings) => {
            let t = std::time::Instant::now();
            let (s, raw) = (&mut session, &frame.image);
            let denoised = pool.install(move || s.denoise_once(settings, raw))?;
            eprintln!("denoised ({}) in {:.0} ms", settings.quality.name(), t.elapsed().as_secs_f64() * 1e3);
            denoised
        }
        None => std::sync::Arc::unwrap_or_clone(frame.image),
    };
    write_image(&image, &args.out, args.exposure)?;
    let mean = image.mean();
    eprintln!(
        "wrote {} ({format:?}): {} spp in {secs:.2} s ({:.1} spp/s), {:.1} Mrays/s, mean radiance [{:.4}, {:.4}, {:.4}], \
         resident technique memory {:.1} MiB",
        args.out.display(),
        frame.spp,
        frame.spp as f64 / secs,
        rays as f64 / secs / 1e6,
        mean.r,
        mean.g,
        mean.b,
        frame.stats.detail.memory().total_bytes as f64 / 1048576.0
    );
    Ok(())
}

/// An animation: each frame queues the animation's edits at its time and renders one tick.
fn render_animation(args: &RenderArgs, anim_path: &std::path::Path) -> Result<()> {
    let format = ImageFormat::from_extension(&args.format).map_err(|e| UsageError(e.to_string()))?;
    if args.frames == 0 {
        return Err(UsageError("--frames must be at least 1".into()).into());
    }
    let loaded = args.target.load()?;
    let anim = args.target.load_animation(&loaded, anim_path)?;
    let (mut session, pool, _device) = make_session_of(args, loaded.scene, args.spp)?;
    if let Some(settings) = denoise_settings(args.denoise.as_deref())? {
        session.set_denoise(Some(settings))?;
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let bar = bar(args.frames as u64, "frames", format!("{} x {} spp", args.technique, args.spp))?;
    let ext = match format {
        ImageFormat::Png => "png",
        ImageFormat::Jpeg => "jpg",
        ImageFormat::Exr => "exr",
        ImageFormat::F32 => "f32",
    };
    let mut total_ms = 0.0;
    pool.install(|| -> Result<()> {
        for i in 0..args.frames {
            let t = anim.duration * i as f32 / args.frames as f32;
            session.queue_edits(anim.edits_at(t))?;
            let frame = session.tick()?;
            total_ms += frame.stats.times.total_ms;
            let file = args.out.join(format!("frame-{i:04}.{ext}"));
            write_image(frame.shown(false), &file, args.exposure)?;
            bar.inc(1);
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    eprintln!(
        "wrote {} frames to {} (mean tick {:.1} ms)",
        args.frames,
        args.out.display(),
        total_ms / args.frames as f64
    );
    Ok(())
}
