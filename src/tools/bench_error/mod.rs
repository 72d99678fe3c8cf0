//! `relume bench error`: speed against error. Each technique configuration runs the same
//! scene (and animation) with the same seed; every K-th frame is compared with a converged
//! `path` reference (`reference.rs`; `--reference bdpt` where `path` misses light) by relMSE,
//! RMSE, PSNR and FLIP (`metrics.rs`). Tick times are the median of `--repeats` runs. Results
//! go to DIR as CSV, JSON, a Markdown report, plots (`plots.rs`) and false-colour FLIP maps of
//! each configuration's worst frame (`report.rs`).
//!
//! A spec with the suffix `+oidn` (or `+oidn=fast|balanced|high`, and `:noaux` for colour
//! only: `path:spp=1+oidn=fast:noaux`) runs the same technique with
//! the denoise stage and is measured on its denoised frames; `--denoise[=QUALITY]` adds such a
//! twin for every spec, so each technique appears with and without the denoiser.
mod metrics;
mod plots;
mod reference;
mod report;

use super::{progress_bar, SceneArgs, UsageError};
use crate::embree::Device;
use crate::engine::{thread_pool, Frame, Session};
use crate::film::{DenoiseQuality, DenoiseSettings};
use crate::scene::animation::Animation;
use crate::scene::Scene;
use crate::technique::TechniqueConfig;
use crate::tools::plot::DENOISED_MARK;
use anyhow::{Context, Result};
use indicatif::ProgressBar;
use metrics::ImageError;
use reference::{Reference, ReferenceKey};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ErrorArgs {
    #[command(flatten)]
    pub target: SceneArgs,
    /// Technique specs, comma-separated: `photon_reuse:off,photon_reuse:error@0.001,path:spp=4`.
    #[arg(long, default_value = "path:spp=1,photon_reuse:off,photon_reuse:naive,photon_reuse:error@0.001")]
    pub techniques: String,
    /// Animation to play (NAME.anim.json); without it the scene is static and the frames are
    /// successive ticks accumulating.
    #[arg(long)]
    pub anim: Option<PathBuf>,
    #[arg(long, default_value_t = 16)]
    pub frames: u32,
    /// Compare every K-th frame with a reference (frame 0 included).
    #[arg(long, default_value_t = 4)]
    pub every: u32,
    /// Animation frames per second.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
    /// Samples per pixel of the references. The default keeps the references' own relMSE
    /// (estimated and reported) one to two orders of magnitude below the errors measured.
    #[arg(long, default_value_t = 1024)]
    pub ref_spp: u32,
    /// Technique of the references: `path`, or `bdpt` for scenes with light `path` cannot
    /// find (a point light's caustic through glass, as in `scenes/caustic-ball.json`).
    #[arg(long, default_value = "path", value_parser = ["path", "bdpt"])]
    pub reference: String,
    /// Runs per configuration; tick times are their median.
    #[arg(long, default_value_t = 3)]
    pub repeats: u32,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder.
    #[arg(long, default_value = "bench-error")]
    pub out: PathBuf,
    /// Where references are cached.
    #[arg(long, default_value = ".relume-cache/references")]
    pub cache: PathBuf,
    /// Also run every spec with the denoise stage (`+oidn`): `--denoise` (quality high) or
    /// `--denoise=fast|balanced|high`.
    #[arg(long, value_name = "QUALITY", num_args = 0..=1, require_equals = true, default_missing_value = "high")]
    pub denoise: Option<String>,
}

/// One benchmarked configuration: a technique, denoised or not.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchConfig {
    pub technique: TechniqueConfig,
    pub denoise: Option<DenoiseSettings>,
}

impl BenchConfig {
    /// `SPEC[+oidn[=QUALITY][:noaux]]`.
    pub fn parse(spec: &str) -> Result<BenchConfig, UsageError> {
        let (technique, denoise) = match spec.split_once(DENOISED_MARK) {
            None => (spec, None),
            Some((t, "")) => (t, Some(DenoiseSettings::default())),
            Some((t, rest)) => {
                let bad = || {
                    UsageError(format!(
                        "--techniques: '{spec}': after +oidn comes nothing, =QUALITY ({}) or =QUALITY:noaux",
                        DenoiseQuality::NAMES.join(", ")
                    ))
                };
                let rest = rest.strip_prefix('=').ok_or_else(bad)?;
                let (quality, aux) = match rest.split_once(':') {
                    None => (rest, true),
                    Some((q, "noaux")) => (q, false),
                    Some(_) => return Err(bad()),
                };
                let quality = DenoiseQuality::parse(quality).ok_or_else(bad)?;
                (t, Some(DenoiseSettings { quality, aux }))
            }
        };
        let technique = TechniqueConfig::from_spec(technique).map_err(|e| UsageError(format!("--techniques: {e}")))?;
        Ok(BenchConfig { technique, denoise })
    }

    pub fn label(&self) -> String {
        let t = self.technique.label();
        match self.denoise {
            None => t,
            Some(d) if d == DenoiseSettings::default() => format!("{t}{DENOISED_MARK}"),
            Some(d) if d.aux => format!("{t}{DENOISED_MARK}={}", d.quality.name()),
            Some(d) => format!("{t}{DENOISED_MARK}={}:noaux", d.quality.name()),
        }
    }
}

/// The specs of `--techniques`, each followed by its denoised twin when `--denoise` asks (unless
/// a spec names that twin itself). Results are grouped by label, so a spec that repeats an
/// earlier configuration is refused.
fn bench_configs(techniques: &str, denoise: Option<&str>) -> Result<Vec<BenchConfig>, UsageError> {
    let twin = super::denoise_settings(denoise)?;
    let mut given = Vec::new();
    let mut labels = std::collections::HashSet::new();
    for spec in techniques.split(',').map(str::trim) {
        let config = BenchConfig::parse(spec)?;
        let label = config.label();
        if !labels.insert(label.clone()) {
            return Err(UsageError(format!("--techniques: '{spec}' repeats an earlier configuration ({label})")));
        }
        given.push(config);
    }
    let mut out = Vec::new();
    for config in given {
        let denoised = twin
            .filter(|_| config.denoise.is_none())
            .map(|d| BenchConfig { denoise: Some(d), ..config.clone() })
            .filter(|t| !labels.contains(&t.label()));
        out.push(config);
        out.extend(denoised);
    }
    Ok(out)
}

/// One frame of one configuration.
#[derive(Clone, Debug, Serialize)]
pub struct FrameResult {
    pub config: String,
    pub frame: u32,
    pub time_s: f32,
    /// Median over the repeats.
    pub tick_ms: f64,
    pub stages_ms: BTreeMap<&'static str, f64>,
    pub rays: u64,
    pub memory_bytes: u64,
    /// Against the reference, on measured frames only.
    pub error: Option<ImageError>,
}

/// A configuration's summary: medians of times and rays, means of errors.
#[derive(Clone, Debug, Serialize)]
pub struct ConfigSummary {
    pub config: String,
    pub tick_ms_median: f64,
    pub rays_per_frame_median: f64,
    pub rel_mse: f64,
    pub rmse: f64,
    pub psnr_db: f64,
    pub flip_ldr: f64,
    pub flip_hdr: f64,
    pub stages_ms_median: BTreeMap<&'static str, f64>,
    /// The measured frame with the largest HDR-FLIP.
    pub worst_frame: u32,
    pub pareto: bool,
}

#[derive(Debug, Serialize)]
pub struct ErrorReport {
    pub scene: String,
    pub animation: Option<String>,
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    pub ref_spp: u32,
    /// The references' technique.
    pub reference: String,
    /// Largest estimated relMSE of a reference's own noise.
    pub reference_rel_mse: f64,
    pub summaries: Vec<ConfigSummary>,
    pub frames: Vec<FrameResult>,
}

pub fn run(args: ErrorArgs) -> Result<()> {
    if args.frames == 0 || args.every == 0 || args.repeats == 0 || args.ref_spp == 0 {
        return Err(UsageError("--frames, --every, --repeats and --ref-spp must be at least 1".into()).into());
    }
    if !(args.fps > 0.0 && args.fps.is_finite()) {
        return Err(UsageError("--fps must be a positive number".into()).into());
    }
    let configs = bench_configs(&args.techniques, args.denoise.as_deref())?;
    let inputs = Inputs::load(&args)?;
    let threads = args.target.threads();
    let pool = thread_pool(threads)?;
    let device = args.target.device()?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let references = pool.install(|| references(&args, &inputs, &device))?;
    let bench = Bench { args: &args, inputs: &inputs, pool: &pool, device: &device, references: &references };

    // Every configuration, repeated; errors from the first run (the seed makes them the same).
    let run_bar = progress_bar(configs.len() as u64 * args.repeats as u64 * args.frames as u64, "frames")?;
    let mut frames: Vec<FrameResult> = Vec::new();
    let mut error_maps: ErrorMaps = BTreeMap::new();
    for config in &configs {
        run_bar.set_message(config.label());
        let runs = (0..args.repeats)
            .map(|repeat| bench.run_config(config, repeat, &run_bar, &mut error_maps))
            .collect::<Result<Vec<_>>>()?;
        frames.extend(report::merge_repeats(runs));
    }
    run_bar.finish_and_clear();

    let scene = &inputs.scene;
    let reference_rel_mse = references.iter().map(|(_, r)| r.self_rel_mse).fold(0.0, f64::max);
    let labels: Vec<String> = configs.iter().map(BenchConfig::label).collect();
    let summaries = report::summarise(&labels, &frames);
    let report = ErrorReport {
        scene: args.target.scene.display().to_string(),
        animation: args.anim.as_ref().map(|p| p.display().to_string()),
        width: scene.camera.width,
        height: scene.camera.height,
        threads,
        ref_spp: args.ref_spp,
        reference: args.reference.clone(),
        reference_rel_mse,
        summaries,
        frames,
    };
    let (w, h) = (scene.camera.width, scene.camera.height);
    report::write_all(&args.out, &report, &error_maps, (w, h))?;
    plots::write_all(&args.out, &report)?;
    report::print_table(&report);
    println!("wrote {}", args.out.display());
    Ok(())
}

/// Per configuration, its worst frame's error map: (frame, HDR-FLIP, false-colour pixels).
type ErrorMaps = BTreeMap<String, (u32, f64, Vec<u8>)>;

/// The scene and animation, with the files' bytes that key their references.
struct Inputs {
    scene: Scene,
    scene_file: Vec<u8>,
    animation: Option<Animation>,
    animation_file: Option<Vec<u8>>,
}

impl Inputs {
    fn load(args: &ErrorArgs) -> Result<Inputs> {
        let scene = args.target.load_scene()?;
        let scene_file = std::fs::read(&args.target.scene)?;
        let (animation, animation_file) = match &args.anim {
            Some(p) => {
                let a = Animation::load(p).map_err(|e| UsageError(format!("{}: {e}", p.display())))?;
                a.validate(&scene).map_err(|e| UsageError(format!("{}: {e}", p.display())))?;
                (Some(a), Some(std::fs::read(p)?))
            }
            None => (None, None),
        };
        Ok(Inputs { scene, scene_file, animation, animation_file })
    }

    /// The animation time of `frame` (0 for a static scene).
    fn time_of(&self, args: &ErrorArgs, frame: u32) -> f32 {
        if self.animation.is_some() {
            frame as f32 / args.fps
        } else {
            0.0
        }
    }
}

/// References for every measured frame's time (one when the scene is static), from the cache
/// or rendered.
fn references(args: &ErrorArgs, inputs: &Inputs, device: &Device) -> Result<Vec<(f32, Reference)>> {
    let mut times: Vec<f32> = (0..args.frames).step_by(args.every as usize).map(|f| inputs.time_of(args, f)).collect();
    times.dedup();
    let bar = progress_bar(times.len() as u64 * (args.ref_spp / 2).max(1) as u64 * 2, "spp")?;
    bar.set_message(format!("references ({})", args.reference));
    let scene = &inputs.scene;
    let references = times
        .iter()
        .map(|&time| {
            let key = ReferenceKey {
                scene_file: &inputs.scene_file,
                animation_file: inputs.animation_file.as_deref(),
                time,
                width: scene.camera.width,
                height: scene.camera.height,
                spp: args.ref_spp,
                seed: args.seed,
                technique: &args.reference,
            };
            let (r, _) = reference::reference(&args.cache, &key, scene, inputs.animation.as_ref(), device, &bar)?;
            Ok((time, r))
        })
        .collect::<Result<Vec<_>>>()?;
    bar.finish_and_clear();
    Ok(references)
}

/// What every configuration's runs share.
struct Bench<'a> {
    args: &'a ErrorArgs,
    inputs: &'a Inputs,
    pool: &'a rayon::ThreadPool,
    device: &'a Device,
    references: &'a [(f32, Reference)],
}

impl Bench<'_> {
    /// One run of `config` over every frame; the first (`repeat` 0) also measures the errors
    /// and keeps the worst frame's error map.
    fn run_config(
        &self,
        config: &BenchConfig,
        repeat: u32,
        bar: &ProgressBar,
        error_maps: &mut ErrorMaps,
    ) -> Result<Vec<FrameResult>> {
        let (args, inputs) = (self.args, self.inputs);
        let label = config.label();
        let mut session = Session::new(inputs.scene.clone(), &config.technique, args.seed, self.device)?;
        if let Some(settings) = config.denoise {
            session.set_denoise(Some(settings))?;
        }
        self.pool.install(|| {
            (0..args.frames)
                .map(|frame| {
                    let time = inputs.time_of(args, frame);
                    if let Some(a) = &inputs.animation {
                        session.queue_edits(a.edits_at(time))?;
                    }
                    let f = session.tick()?;
                    let reference = self.references.iter().find(|(t, _)| *t == time).map(|(_, r)| r);
                    let error = match (repeat, frame % args.every == 0, reference) {
                        (0, true, Some(r)) => {
                            let (e, map) = metrics::compare(f.shown(false), &r.image);
                            let worst = error_maps.get(&label).map_or(-1.0, |w| w.1);
                            if e.flip_hdr > worst {
                                error_maps.insert(label.clone(), (frame, e.flip_hdr, metrics::false_colour(&map)));
                            }
                            Some(e)
                        }
                        _ => None,
                    };
                    bar.inc(1);
                    Ok(frame_result(&label, frame, time, &f, error))
                })
                .collect()
        })
    }
}

/// One frame's measurements.
fn frame_result(label: &str, frame: u32, time: f32, f: &Frame, error: Option<ImageError>) -> FrameResult {
    let t = &f.stats.times;
    FrameResult {
        config: label.to_string(),
        frame,
        time_s: time,
        tick_ms: t.total_ms,
        stages_ms: BTreeMap::from([
            ("apply_commit", t.drain_ms + t.apply_ms + t.commit_ms),
            ("update", t.update_ms),
            ("render", t.render_ms),
            ("resolve", t.resolve_ms),
            ("denoise", t.denoise_ms),
        ]),
        rays: f.stats.rays.total() + f.stats.aux_rays,
        memory_bytes: f.stats.detail.memory().total_bytes,
        error,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn oidn_suffixes_parse_into_denoise_settings_and_labels_round_trip() {
        let c = BenchConfig::parse("path:spp=1+oidn=fast:noaux").expect("spec");
        assert_eq!(c.denoise, Some(DenoiseSettings { quality: DenoiseQuality::Fast, aux: false }));
        assert_eq!(BenchConfig::parse(&c.label()).expect("label"), c);
        let d = BenchConfig::parse("bdpt+oidn").expect("spec");
        assert_eq!(d.denoise, Some(DenoiseSettings::default()));
        assert!(d.label().ends_with("+oidn"));
        for bad in ["path+oidn=ultra", "path+oidnx", "path+oidn=fast:aux"] {
            assert!(BenchConfig::parse(bad).is_err(), "{bad} parsed");
        }
    }

    #[test]
    fn denoise_adds_a_twin_of_every_spec_without_one() {
        let all = bench_configs("path,bdpt+oidn=fast", Some("high")).expect("specs");
        let labels: Vec<String> = all.iter().map(BenchConfig::label).collect();
        assert_eq!(all.len(), 3, "{labels:?}");
        assert_eq!(all[0].denoise, None);
        assert_eq!(all[1].denoise, Some(DenoiseSettings::default()));
        assert_eq!(all[2].denoise.map(|d| d.quality), Some(DenoiseQuality::Fast));
        // A spec naming a twin itself gets no second one.
        let named = bench_configs("path,path+oidn", Some("high")).expect("specs");
        assert_eq!(named.iter().map(BenchConfig::label).collect::<Vec<_>>(), ["path:spp=1", "path:spp=1+oidn"]);
    }

    #[test]
    fn a_repeated_configuration_is_refused_and_distinct_ones_are_not() {
        // `path` and `path:spp=1` are one configuration (spp defaults to 1); configurations that
        // differ only in a field outside the label's head are two (their results were merged
        // under one label before labels carried every field).
        let e = bench_configs("path,path:spp=1", None).expect_err("a repeat");
        assert!(e.to_string().contains("'path:spp=1' repeats an earlier configuration"), "{e}");
        let radii = "instant_cache,instant_cache:caching_radius=0.07,instant_cache:caching_radius=0.1";
        let all = bench_configs(radii, None).expect("three configurations");
        let labels: std::collections::HashSet<String> = all.iter().map(BenchConfig::label).collect();
        assert_eq!(labels.len(), 3, "{labels:?}");
    }
}
