//! `relume bench particles`: `particle_gi`'s stages (Chang et al.'s Tables 1 and 2), its relight
//! tick against a Whitted frame of the same view, and, with an animation, its incremental link
//! update against a full rebuild.
//!
//! Tick 0 builds everything (the geometry stage). Tick 1 relights: the first light moves by 2%
//! of the scene's diagonal if it is dynamic (its share of the lighting stage reruns), or is
//! dimmed by 20% if static (a scale of its share: no rays, no walks); nothing geometric
//! reruns either way. The Whitted time is that tick's camera
//! rays, specular chains and shadow rays (the same work a Whitted ray tracer does, measured in
//! the same run). With `--anim`, the animation plays twice, with `incremental` on and off, and
//! the links traced and geometry-stage times per frame are compared.
use super::{progress_bar, quantile, AnimationRun, SceneArgs, UsageError};
use crate::scene::edits::Edit;
use crate::scene::EmitterDesc;
use crate::technique::particle_gi::{ParticleGiConfig, ParticleStats};
use crate::technique::{TechniqueConfig, TechniqueStats};
use anyhow::Result;
use serde::Serialize;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ParticlesArgs {
    #[command(flatten)]
    pub target: SceneArgs,
    /// Animation for the incremental-update comparison (NAME.anim.json).
    #[arg(long)]
    pub anim: Option<PathBuf>,
    #[arg(long, default_value_t = 5)]
    pub frames: u32,
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
    /// Area particles (default: the technique's, 0.15 per pixel).
    #[arg(long)]
    pub particles: Option<u32>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write the report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

#[derive(Debug, Serialize)]
pub struct LinkUpdate {
    pub frames: u32,
    pub links_total: u64,
    pub incremental_links_median: f64,
    pub full_links_median: f64,
    pub incremental_geometry_ms_median: f64,
    pub full_geometry_ms_median: f64,
    /// Full over incremental geometry-stage time (the goal is ≥ 10 for one small object).
    pub speedup: f64,
    /// Every frame's image was identical in both modes.
    pub images_equal: bool,
}

#[derive(Debug, Serialize)]
pub struct ParticlesReport {
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    pub build: ParticleStats,
    pub build_tick_ms: f64,
    pub relight: ParticleStats,
    pub relight_tick_ms: f64,
    /// The relight tick's phases (update, render, resolve, ...).
    pub relight_phases: crate::engine::PhaseTimes,
    pub whitted_ms: f64,
    /// Relight tick over the Whitted frame (goal ≤ 1.5; the paper 1.6–3.2).
    pub relight_ratio: f64,
    pub link_update: Option<LinkUpdate>,
}

fn stats(frame: &crate::engine::Frame) -> Result<ParticleStats> {
    match &frame.stats.detail {
        TechniqueStats::ParticleGi(s) => Ok((**s).clone()),
        _ => anyhow::bail!("particle_gi stats expected"),
    }
}

/// The relight edit: move the first light if it may move, else dim it.
fn relight_edit(run: &AnimationRun) -> Result<Edit> {
    let scene = &run.scene;
    let Some(light) = scene.desc().lights.first() else {
        return Err(UsageError("the scene has no light to relight".into()).into());
    };
    if scene.lights[0].dynamic {
        let diagonal = scene
            .objects
            .iter()
            .flat_map(|o| o.world_positions.iter())
            .fold((glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let step = 0.02 * (diagonal.1 - diagonal.0).length();
        let mut transform = light.transform;
        transform.translation[0] += step;
        return Ok(Edit::Light { name: light.name.clone(), transform: Some(transform), emitter: None });
    }
    let dim = 0.8;
    let emitter = match light.emitter.clone() {
        EmitterDesc::Point { intensity } => EmitterDesc::Point { intensity: intensity * dim },
        EmitterDesc::Spot { intensity, cone_deg, falloff_start_deg } => {
            EmitterDesc::Spot { intensity: intensity * dim, cone_deg, falloff_start_deg }
        }
        EmitterDesc::Rect { radiance } => EmitterDesc::Rect { radiance: radiance * dim },
        EmitterDesc::Disc { radiance, segments } => EmitterDesc::Disc { radiance: radiance * dim, segments },
        EmitterDesc::Mesh { radiance, positions, indices } => {
            EmitterDesc::Mesh { radiance: radiance * dim, positions, indices }
        }
        EmitterDesc::Directional { direction, irradiance, angle_deg } => {
            EmitterDesc::Directional { direction, irradiance: irradiance * dim, angle_deg }
        }
    };
    Ok(Edit::Light { name: light.name.clone(), transform: None, emitter: Some(emitter) })
}

pub fn measure(args: &ParticlesArgs) -> Result<ParticlesReport> {
    if args.frames < 2 || !(args.fps > 0.0 && args.fps.is_finite()) {
        return Err(UsageError("--frames must be at least 2 and --fps positive".into()).into());
    }
    let empty_anim = std::env::temp_dir().join(format!("relume-still-{}.anim.json", std::process::id()));
    let anim_path = match &args.anim {
        Some(a) => a.clone(),
        None => {
            std::fs::write(&empty_anim, r#"{"duration": 1.0, "tracks": []}"#)?;
            empty_anim.clone()
        }
    };
    let run = AnimationRun::load(&args.target, &anim_path);
    let _ = std::fs::remove_file(&empty_anim);
    let run = run?;
    let config = |incremental| {
        TechniqueConfig::ParticleGi(ParticleGiConfig {
            particles: args.particles,
            incremental,
            ..ParticleGiConfig::default()
        })
    };
    let frames = if args.anim.is_some() { 2 * args.frames as u64 } else { 0 };
    let bar = progress_bar(2 + frames, "ticks")?;
    bar.set_message("build and relight");
    let mut session = run.session(&config(true), args.seed)?;
    let relight = relight_edit(&run)?;
    let (build_frame, relight_frame) = run.install(|| -> Result<_> {
        let build = session.tick()?;
        bar.inc(1);
        session.queue_edits(vec![relight])?;
        let relit = session.tick()?;
        bar.inc(1);
        Ok((build, relit))
    })?;
    let (build, relit) = (stats(&build_frame)?, stats(&relight_frame)?);
    let link_update = match &args.anim {
        None => None,
        Some(_) => Some(link_update(args, &run, &config, &build, &bar)?),
    };
    bar.finish_and_clear();
    let relight_tick_ms = relight_frame.stats.times.total_ms;
    Ok(ParticlesReport {
        scene: args.target.scene.display().to_string(),
        width: run.scene.camera.width,
        height: run.scene.camera.height,
        threads: run.threads,
        build_tick_ms: build_frame.stats.times.total_ms,
        relight_ratio: relight_tick_ms / relit.trace_ms.max(1e-9),
        whitted_ms: relit.trace_ms,
        relight_tick_ms,
        relight_phases: relight_frame.stats.times,
        build,
        relight: relit,
        link_update,
    })
}

/// Plays the animation with incremental links and with full link rebuilds, and compares the
/// links traced, the geometry stage's time and the images.
fn link_update(
    args: &ParticlesArgs,
    run: &AnimationRun,
    config: &dyn Fn(bool) -> TechniqueConfig,
    build: &ParticleStats,
    bar: &indicatif::ProgressBar,
) -> Result<LinkUpdate> {
    let mut runs = Vec::new();
    for incremental in [true, false] {
        bar.set_message(if incremental { "incremental links" } else { "full link rebuilds" });
        let mut figures = Vec::new();
        run.play(&config(incremental), args.seed, args.frames, args.fps, |_, frame| {
            figures.push((stats(frame)?, frame.image.clone()));
            bar.inc(1);
            Ok(())
        })?;
        runs.push(figures);
    }
    let moving = |f: &[(ParticleStats, std::sync::Arc<crate::film::LinearImage>)], x: fn(&ParticleStats) -> f64| {
        quantile(&f[1..].iter().map(|(s, _)| x(s)).collect::<Vec<_>>(), 0.5)
    };
    let (inc, full) = (&runs[0], &runs[1]);
    let inc_ms = moving(inc, |s| s.geometry_ms);
    let full_ms = moving(full, |s| s.geometry_ms);
    Ok(LinkUpdate {
        frames: args.frames,
        links_total: build.links_total,
        incremental_links_median: moving(inc, |s| s.links_traced as f64),
        full_links_median: moving(full, |s| s.links_traced as f64),
        incremental_geometry_ms_median: inc_ms,
        full_geometry_ms_median: full_ms,
        speedup: full_ms / inc_ms.max(1e-9),
        images_equal: inc.iter().zip(full).all(|(a, b)| a.1 == b.1),
    })
}

pub fn print_table(r: &ParticlesReport) {
    let b = &r.build;
    println!(
        "relume bench particles: {} at {}x{}, {} threads; {} area particles (ΔA {:.3e} square scene units), {} radiance particles, n_b = {}",
        r.scene, r.width, r.height, r.threads, b.area_particles, b.particle_area, b.radiance_particles, b.bounces
    );
    println!(
        "  geometry stage: {:.1} ms ({} links traced, {:.1} MiB links, {:.1} MiB particles)",
        b.geometry_ms,
        b.links_traced,
        (b.memory.part("scatter_links") + b.memory.part("gather_links")) as f64 / 1048576.0,
        b.memory.part("particles") as f64 / 1048576.0
    );
    let s = &r.relight;
    println!(
        "  relight tick {:.1} ms: emission {:.1}, scattering {:.1}, preliminary {:.1}, lists {:.1}, gathering {:.1} ({} particles), estimation {:.1} ({} radiance particles), final {:.1}",
        r.relight_tick_ms,
        s.emission_ms,
        s.scattering_ms,
        s.preliminary_ms,
        s.geometry_ms,
        s.gathering_ms,
        s.area_particles_gathered,
        s.estimation_ms,
        s.radiance_particles_estimated,
        s.final_ms
    );
    let p = &r.relight_phases;
    println!(
        "  relight phases: commit {:.1}, update {:.1}, render {:.1}, resolve {:.1} ms",
        p.commit_ms, p.update_ms, p.render_ms, p.resolve_ms
    );
    println!("  Whitted frame {:.1} ms; relight / Whitted = {:.2} (goal ≤ 1.5)", r.whitted_ms, r.relight_ratio);
    if let Some(u) = &r.link_update {
        println!(
            "  link update over {} frames: incremental {:.0} of {} links in {:.1} ms, full {:.0} in {:.1} ms: {:.1}x less time; images equal: {}",
            u.frames,
            u.incremental_links_median,
            u.links_total,
            u.incremental_geometry_ms_median,
            u.full_links_median,
            u.full_geometry_ms_median,
            u.speedup,
            u.images_equal
        );
    }
}

pub fn run(args: ParticlesArgs) -> Result<()> {
    let report = measure(&args)?;
    print_table(&report);
    super::write_json_report(args.json.as_deref(), &report)
}
