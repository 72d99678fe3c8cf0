//! `relume bench icache`: `instant_cache`'s modes over the same animation, in one process, with
//! the same seed and VPL set, as in Debattista et al.'s Tables 3 and 4.
//!
//! Runs `igi`, `static`, `temporal` (immediate re-evaluation) and `temporal` with on-demand
//! re-evaluation (or those `--modes` names), each in a fresh session over F frames. Frame 0
//! builds everything and is reported apart as `initial`; frames 1.. are summarised by median
//! and p95. The indirect component is VPL shooting, invalidation and the cache (or IGI's gather
//! and filter): what the paper's Table 4 times. The tick is also split by stage: camera samples
//! and direct light, then the indirect stages, with the time spent computing records apart.
//! `--audit` recomputes every record after each frame and reports the records that differ from
//! a fresh computation (it should be 0; it slows the run down). `--plot DIR` draws the indirect
//! time of every frame and the stage split, per mode.
use super::plot::{write_both, Lines, StackedBars};
use super::{progress_bar, quantile, AnimationArgs, Frames};
use crate::technique::instant_cache::{CacheMode, InstantCacheConfig, InstantCacheStats, Reevaluation};
use crate::technique::{TechniqueConfig, TechniqueStats};
use anyhow::Result;
use serde::Serialize;

#[derive(clap::Args, Debug)]
pub struct IcacheArgs {
    #[command(flatten)]
    pub run: AnimationArgs,
    #[arg(long, default_value_t = 256)]
    pub vpls: u32,
    /// θ of the caches, in degrees (default: `instant_cache`'s).
    #[arg(long)]
    pub normal_tolerance: Option<f32>,
    /// Still ticks that refine the view (default: `instant_cache`'s); 0 measures a still
    /// scene's resident ticks.
    #[arg(long)]
    pub refine_ticks: Option<u32>,
    /// Check every record against a fresh computation after each frame (slow).
    #[arg(long)]
    pub audit: bool,
    /// The modes to run, comma-separated (default: all four; the ratios need `igi` and
    /// `static`).
    #[arg(long, value_delimiter = ',', default_values_t = Mode::ALL)]
    pub modes: Vec<Mode>,
    /// Also draw the run into DIR (created if missing), as PNG and SVG: `icache_indirect_by_frame`
    /// (each mode's indirect milliseconds per frame, frame 0 building everything) and
    /// `icache_stages` (each mode's median tick by stage).
    #[arg(long, value_name = "DIR")]
    pub plot: Option<std::path::PathBuf>,
}

/// A configuration `bench icache` compares.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Igi,
    Static,
    Temporal,
    /// `temporal` with on-demand re-evaluation.
    TemporalOnDemand,
}

impl Mode {
    const ALL: [Mode; 4] = [Mode::Igi, Mode::Static, Mode::Temporal, Mode::TemporalOnDemand];

    fn label(self) -> &'static str {
        match self {
            Mode::Igi => "igi",
            Mode::Static => "static",
            Mode::Temporal => "temporal",
            Mode::TemporalOnDemand => "temporal-on-demand",
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.label())
    }
}

#[derive(Debug, Serialize)]
pub struct FrameFigures {
    pub tick_ms: f64,
    /// VPL shooting, invalidation and the indirect component.
    pub indirect_ms: f64,
    pub rays: u64,
    pub visibility_rays: u64,
    pub records: u64,
    pub records_created: u64,
    pub stats: InstantCacheStats,
}

#[derive(Debug, Serialize)]
pub struct Summary {
    pub tick_ms_median: f64,
    pub tick_ms_p95: f64,
    pub indirect_ms_median: f64,
    pub indirect_ms_p95: f64,
    /// The tick by stage (medians of `camera_ms`, `vpl_ms`, `invalidate_ms`, `indirect_ms` and
    /// `records_ms`): camera samples and direct light, then the indirect component: shooting
    /// VPLs, the start-of-tick invalidation (`temporal`'s ageing, case 5 and immediate
    /// re-evaluation), and the cache's or the gather's work for the pixels, of which computing
    /// records is a part.
    pub stage_ms_median: StageSplit,
    pub rays_median: f64,
    pub visibility_rays_median: f64,
    pub records_median: f64,
    pub records_created_median: f64,
    pub memory_bytes: u64,
    /// Frames of a still view that rested (refinement done: `idle`), and their indirect
    /// milliseconds (median); the medians above include them.
    pub resting_frames: usize,
    pub resting_indirect_ms_median: f64,
    /// With `--audit`: records, over all frames, that differed from a fresh computation.
    pub audit_mismatched: u64,
    pub audit_off_surface: u64,
}

#[derive(Debug, Serialize)]
pub struct StageSplit {
    pub camera: f64,
    pub vpls: f64,
    pub invalidate: f64,
    pub pixels: f64,
    pub records: f64,
}

pub type ModeReport = super::ModeReport<FrameFigures, Summary>;

/// The medians (and p95s) of a mode's frames after the first.
fn summarize(frames: &Frames<FrameFigures>) -> Summary {
    let median = |figure: fn(&FrameFigures) -> f64| frames.quantile(figure, 0.5);
    let resting: Vec<f64> = frames.0.iter().filter(|f| f.stats.idle).map(|f| f.indirect_ms).collect();
    Summary {
        tick_ms_median: median(|f| f.tick_ms),
        tick_ms_p95: frames.quantile(|f| f.tick_ms, 0.95),
        indirect_ms_median: median(|f| f.indirect_ms),
        indirect_ms_p95: frames.quantile(|f| f.indirect_ms, 0.95),
        stage_ms_median: StageSplit {
            camera: median(|f| f.stats.camera_ms),
            vpls: median(|f| f.stats.vpl_ms),
            invalidate: median(|f| f.stats.invalidate_ms),
            pixels: median(|f| f.stats.indirect_ms),
            records: median(|f| f.stats.records_ms),
        },
        rays_median: median(|f| f.rays as f64),
        visibility_rays_median: median(|f| f.visibility_rays as f64),
        records_median: median(|f| f.records as f64),
        records_created_median: median(|f| f.records_created as f64),
        memory_bytes: frames.0.last().map_or(0, |f| f.stats.memory.total_bytes),
        resting_frames: resting.len(),
        resting_indirect_ms_median: quantile(&resting, 0.5),
        audit_mismatched: frames.0.iter().map(|f| f.stats.audit_mismatched).sum(),
        audit_off_surface: frames.0.iter().map(|f| f.stats.audit_off_surface).sum(),
    }
}

#[derive(Debug, Serialize)]
pub struct IcacheReport {
    pub scene: String,
    pub animation: String,
    pub vpls: u32,
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    pub modes: Vec<ModeReport>,
}

/// The configurations compared, by label, in the order asked.
fn configurations(args: &IcacheArgs) -> Vec<(&'static str, InstantCacheConfig)> {
    let defaults = InstantCacheConfig::default();
    let normal_tolerance = args.normal_tolerance.unwrap_or(defaults.normal_tolerance);
    let refine_ticks = args.refine_ticks.unwrap_or(defaults.refine_ticks);
    let base = InstantCacheConfig { vpls: args.vpls, audit: args.audit, normal_tolerance, refine_ticks, ..defaults };
    let config = |mode: Mode| match mode {
        Mode::Igi => InstantCacheConfig { mode: CacheMode::Igi, audit: false, ..base.clone() },
        Mode::Static => InstantCacheConfig { mode: CacheMode::Static, ..base.clone() },
        Mode::Temporal => InstantCacheConfig { mode: CacheMode::Temporal, ..base.clone() },
        Mode::TemporalOnDemand => {
            InstantCacheConfig { mode: CacheMode::Temporal, reevaluation: Reevaluation::OnDemand, ..base.clone() }
        }
    };
    let mut modes: Vec<Mode> = Vec::new();
    for &m in &args.modes {
        if !modes.contains(&m) {
            modes.push(m);
        }
    }
    modes.into_iter().map(|m| (m.label(), config(m))).collect()
}

pub fn measure(args: &IcacheArgs) -> Result<IcacheReport> {
    let run = args.run.start()?;
    let configs = configurations(args);
    let bar = progress_bar(configs.len() as u64 * args.run.frames as u64, "frames")?;
    let mut reports = Vec::new();
    for (label, config) in configs {
        bar.set_message(label);
        let config = TechniqueConfig::InstantCache(config);
        let mut figures = Vec::new();
        args.run.play(&run, &config, |_, frame| {
            let TechniqueStats::InstantCache(s) = &frame.stats.detail else {
                anyhow::bail!("instant_cache stats expected");
            };
            figures.push(FrameFigures {
                tick_ms: frame.stats.times.total_ms,
                indirect_ms: s.vpl_ms + s.invalidate_ms + s.indirect_ms,
                rays: frame.stats.rays.total(),
                visibility_rays: s.visibility_rays,
                records: s.records,
                records_created: s.records_created,
                stats: (**s).clone(),
            });
            bar.inc(1);
            Ok(())
        })?;
        reports.push(ModeReport::new(label.to_string(), figures, summarize)?);
    }
    bar.finish_and_clear();
    Ok(IcacheReport {
        scene: args.run.target.scene.display().to_string(),
        animation: args.run.anim.display().to_string(),
        vpls: args.vpls,
        width: run.scene.camera.width,
        height: run.scene.camera.height,
        threads: run.threads,
        modes: reports,
    })
}

pub fn print_table(r: &IcacheReport, audit: bool) {
    println!(
        "relume bench icache: {} with {} at {}x{}, {} VPLs, {} threads",
        r.scene, r.animation, r.width, r.height, r.vpls, r.threads
    );
    println!("  mode                tick ms (median, p95)   indirect ms (median, p95)   rays/tick   vis. rays   records  created  memory MiB");
    for m in &r.modes {
        let s = &m.summary;
        println!(
            "  {:<18} {:>10.1} {:>10.1} {:>14.1} {:>12.1} {:>11.0} {:>11.0} {:>9.0} {:>8.0} {:>11.1}",
            m.mode,
            s.tick_ms_median,
            s.tick_ms_p95,
            s.indirect_ms_median,
            s.indirect_ms_p95,
            s.rays_median,
            s.visibility_rays_median,
            s.records_median,
            s.records_created_median,
            s.memory_bytes as f64 / 1048576.0
        );
    }
    println!("  ms by stage (medians)   camera | indirect: shoot VPLs  invalidate  pixels (of which records)");
    for m in &r.modes {
        let st = &m.summary.stage_ms_median;
        println!(
            "  {:<21} {:>8.2} | {:>20.2} {:>11.2} {:>7.2} {:>17.2}",
            m.mode, st.camera, st.vpls, st.invalidate, st.pixels, st.records
        );
    }
    for m in r.modes.iter().filter(|m| m.summary.resting_frames > 0) {
        println!(
            "  {}: a still view refined for {} frames, then rested for {} (indirect {:.3} ms, median)",
            m.mode,
            m.frames.len() - m.summary.resting_frames,
            m.summary.resting_frames,
            m.summary.resting_indirect_ms_median
        );
    }
    let find = |name: &str| r.modes.iter().find(|m| m.mode == name).map(|m| &m.summary);
    let (Some(igi), Some(stat)) = (find("igi"), find("static")) else { return };
    for name in ["temporal", "temporal-on-demand"] {
        let Some(t) = find(name) else { continue };
        println!(
            "  {name}: indirect {:.1}x faster than igi, {:.1}x faster than static; tick {:.1}x and {:.1}x",
            igi.indirect_ms_median / t.indirect_ms_median.max(1e-9),
            stat.indirect_ms_median / t.indirect_ms_median.max(1e-9),
            igi.tick_ms_median / t.tick_ms_median.max(1e-9),
            stat.tick_ms_median / t.tick_ms_median.max(1e-9)
        );
    }
    if audit {
        for m in &r.modes {
            println!(
                "  audit {}: {} records differed from a fresh computation, {} lay off every surface",
                m.mode, m.summary.audit_mismatched, m.summary.audit_off_surface
            );
        }
    }
}

/// Writes `--plot`'s two plots into `dir`, which exists.
fn plot(dir: &std::path::Path, r: &IcacheReport) -> Result<()> {
    let series = r.modes.iter().map(|m| m.per_frame(|f| f.indirect_ms)).collect();
    let caption = format!("Indirect light per frame ({}x{}, {} VPLs)", r.width, r.height, r.vpls);
    write_both(dir, "icache_indirect_by_frame", &Lines { caption, x: "frame", unit: "ms".into(), series })?;
    let stages = ["camera and direct light", "shoot VPLs", "invalidate", "pixels less records", "records"];
    let bars = r
        .modes
        .iter()
        .map(|m| {
            let s = &m.summary.stage_ms_median;
            (m.mode.clone(), vec![s.camera, s.vpls, s.invalidate, (s.pixels - s.records).max(0.0), s.records])
        })
        .collect();
    let caption = "Median tick by stage (frames 1 on)".to_string();
    write_both(dir, "icache_stages", &StackedBars { caption, stages: stages.map(String::from).to_vec(), bars })
}

pub fn run(args: IcacheArgs) -> Result<()> {
    super::plot::make_dir(args.plot.as_deref())?;
    let report = measure(&args)?;
    print_table(&report, args.audit);
    super::write_json_report(args.run.json.as_deref(), &report)?;
    super::plot::draw_into(args.plot.as_deref(), |dir| plot(dir, &report))?;
    Ok(())
}
