//! `relume bench reuse`: photon path reuse modes over the same animation, in one process, with
//! the same seed, as in Moreau et al.'s Figures 7 and 8.
//!
//! Each mode runs a fresh session over F frames of the animation at `--fps`. Frame 0 builds
//! every path (reported apart as `initial`); frames 1.. are summarised by median and p95.
//! `rays_traced` counts rays traced for photon paths (origin checks, verification, retraced and
//! filled segments); camera and shadow rays are the same in every mode and left out.
//! `verify` time is origin updates with DM_C, the bounce-row screen, dynamic occlusions and
//! pruning; `trace` is fills and retraces. `screened` counts the paths the screen passed on to
//! the per-path checks. `--plot DIR` draws each mode's tick per frame and its median tick by
//! stage.
use super::plot::{write_both, Lines, StackedBars};
use super::{progress_bar, AnimationArgs, Frames};
use crate::technique::photon_reuse::{PhotonReuseConfig, ReuseMode};
use crate::technique::{TechniqueConfig, TechniqueStats};
use anyhow::Result;
use serde::Serialize;
use std::collections::BTreeMap;

#[derive(clap::Args, Debug)]
pub struct ReuseArgs {
    #[command(flatten)]
    pub run: AnimationArgs,
    /// Photon paths; several, comma-separated (`1000000,4000000`), also measure how each mode's
    /// tick grows with the number of paths.
    #[arg(long, value_delimiter = ',', default_value = "1000000")]
    pub paths: Vec<u32>,
    /// Also draw the run (the modes at the first `--paths`) into DIR (created if missing), as
    /// PNG and SVG: `reuse_tick_by_frame` (each mode's tick milliseconds per frame, frame 0
    /// building everything) and `reuse_stages` (each mode's median tick by stage).
    #[arg(long, value_name = "DIR")]
    pub plot: Option<std::path::PathBuf>,
}

/// A tick's stages as `stages_ms` names them, in the order they run.
const STAGES: [&str; 9] =
    ["apply_and_commit", "origins_and_dm", "screen", "verify", "prune", "fill", "trace", "grid", "render"];

#[derive(Debug, Serialize)]
pub struct FrameFigures {
    pub rays_traced: u64,
    pub paths_retraced: u64,
    pub tick_ms: f64,
    pub stages_ms: BTreeMap<&'static str, f64>,
    /// Photons the grid took out and put in (every photon when it was rebuilt).
    pub grid_photons_changed: u64,
    pub screened: u64,
    pub grid_rebuilt: bool,
}

#[derive(Debug, Serialize)]
pub struct Summary {
    pub rays_per_tick_median: f64,
    pub rays_per_tick_p95: f64,
    pub tick_ms_median: f64,
    pub tick_ms_p95: f64,
    pub verify_ms_median: f64,
    pub trace_plus_verify_ms_median: f64,
    pub grid_ms_median: f64,
    pub render_ms_median: f64,
    pub grid_photons_changed_median: f64,
    pub memory_bytes: u64,
}

pub type ModeReport = super::ModeReport<FrameFigures, Summary>;

#[derive(Debug, Serialize)]
pub struct ReuseReport {
    pub scene: String,
    pub animation: String,
    pub paths: u32,
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    /// The modes at the first `--paths`.
    pub modes: Vec<ModeReport>,
    /// The modes at each further `--paths`, in order.
    pub larger: Vec<SizeReport>,
}

#[derive(Debug, Serialize)]
pub struct SizeReport {
    pub paths: u32,
    pub modes: Vec<ModeReport>,
}

/// Verification work of a frame: origin updates and DM_C, the screen, dynamic occlusions, prune.
fn verify_ms(f: &FrameFigures) -> f64 {
    f.stages_ms["origins_and_dm"] + f.stages_ms["screen"] + f.stages_ms["verify"] + f.stages_ms["prune"]
}

pub fn measure(args: &ReuseArgs) -> Result<ReuseReport> {
    let run = args.run.start()?;
    let Some((&first, rest)) = args.paths.split_first() else { anyhow::bail!("--paths: give at least one count") };
    let bar = progress_bar(3 * args.paths.len() as u64 * args.run.frames as u64, "frames")?;
    let modes = measure_size(args, &run, first, &bar)?;
    let larger = rest
        .iter()
        .map(|&paths| Ok(SizeReport { paths, modes: measure_size(args, &run, paths, &bar)? }))
        .collect::<Result<Vec<_>>>()?;
    bar.finish_and_clear();
    Ok(ReuseReport {
        scene: args.run.target.scene.display().to_string(),
        animation: args.run.anim.display().to_string(),
        paths: first,
        width: run.scene.camera.width,
        height: run.scene.camera.height,
        threads: run.threads,
        modes,
        larger,
    })
}

/// Every mode over the animation with `paths` resident paths.
fn measure_size(
    args: &ReuseArgs,
    run: &super::AnimationRun,
    paths: u32,
    bar: &indicatif::ProgressBar,
) -> Result<Vec<ModeReport>> {
    let mut reports = Vec::new();
    for mode in [ReuseMode::Off, ReuseMode::Naive, ReuseMode::Error] {
        let name = serde_json::to_value(mode)?.as_str().unwrap_or("?").to_string();
        bar.set_message(format!("{name}, {paths} paths"));
        let config =
            TechniqueConfig::PhotonReuse(PhotonReuseConfig { paths, reuse: mode, ..PhotonReuseConfig::default() });
        let mut figures = Vec::new();
        let mut memory = 0;
        args.run.play(run, &config, |_, frame| {
            let TechniqueStats::PhotonReuse(s) = &frame.stats.detail else {
                anyhow::bail!("photon_reuse stats expected");
            };
            memory = s.memory.total_bytes;
            let t = &frame.stats.times;
            let stages = [
                t.apply_ms + t.commit_ms,
                s.origins_ms,
                s.screen_ms,
                s.verify_ms - s.screen_ms,
                s.prune_ms,
                s.fill_ms,
                s.trace_ms,
                s.grid_ms,
                s.render_ms,
            ];
            let stages = STAGES.into_iter().zip(stages).collect();
            figures.push(FrameFigures {
                rays_traced: s.photon_rays(),
                paths_retraced: s.partly_retraced + s.fully_retraced,
                tick_ms: t.total_ms,
                stages_ms: stages,
                grid_photons_changed: s.grid_added + s.grid_removed,
                screened: s.screened,
                grid_rebuilt: s.grid_rebuilt,
            });
            bar.inc(1);
            Ok(())
        })?;
        let summary = |frames: &Frames<FrameFigures>| {
            let median = |figure: fn(&FrameFigures) -> f64| frames.quantile(figure, 0.5);
            Summary {
                rays_per_tick_median: median(|f| f.rays_traced as f64),
                rays_per_tick_p95: frames.quantile(|f| f.rays_traced as f64, 0.95),
                tick_ms_median: median(|f| f.tick_ms),
                tick_ms_p95: frames.quantile(|f| f.tick_ms, 0.95),
                verify_ms_median: median(verify_ms),
                trace_plus_verify_ms_median: median(|f| verify_ms(f) + f.stages_ms["fill"] + f.stages_ms["trace"]),
                grid_ms_median: median(|f| f.stages_ms["grid"]),
                render_ms_median: median(|f| f.stages_ms["render"]),
                grid_photons_changed_median: median(|f| f.grid_photons_changed as f64),
                memory_bytes: memory,
            }
        };
        reports.push(ModeReport::new(name, figures, summary)?);
    }
    Ok(reports)
}

pub fn print_table(r: &ReuseReport) {
    println!(
        "relume bench reuse: {} with {} at {}x{}, {} paths, {} threads",
        r.scene, r.animation, r.width, r.height, r.paths, r.threads
    );
    println!(
        "  mode    rays/tick (median, p95)   tick ms (median, p95)   verify ms   trace+verify ms   grid ms   grid photons changed   render ms   memory MiB"
    );
    for m in &r.modes {
        let s = &m.summary;
        println!(
            "  {:<7} {:>10.0} {:>12.0} {:>12.1} {:>10.1} {:>11.2} {:>15.1} {:>9.1} {:>22.0} {:>11.1} {:>12.1}",
            m.mode,
            s.rays_per_tick_median,
            s.rays_per_tick_p95,
            s.tick_ms_median,
            s.tick_ms_p95,
            s.verify_ms_median,
            s.trace_plus_verify_ms_median,
            s.grid_ms_median,
            s.grid_photons_changed_median,
            s.render_ms_median,
            s.memory_bytes as f64 / 1048576.0
        );
    }
    let Some(off) = r.modes.iter().find(|m| m.mode == "off") else { return };
    for m in r.modes.iter().filter(|m| m.mode != "off") {
        let (o, n) = (&off.summary, &m.summary);
        println!(
            "  {} vs off: whole tick {:.2}x faster, {:.1}x fewer rays per tick, {:.1}x less trace+verify time, verification {:.1}% of the off tick",
            m.mode,
            o.tick_ms_median / n.tick_ms_median.max(1e-9),
            o.rays_per_tick_median / n.rays_per_tick_median.max(1.0),
            o.trace_plus_verify_ms_median / n.trace_plus_verify_ms_median.max(1e-9),
            100.0 * n.verify_ms_median / o.tick_ms_median.max(1e-9)
        );
    }
    for size in &r.larger {
        let growth: Vec<String> = size
            .modes
            .iter()
            .filter_map(|m| {
                let base = r.modes.iter().find(|b| b.mode == m.mode)?;
                let g = m.summary.tick_ms_median / base.summary.tick_ms_median.max(1e-9);
                Some(format!("{} {:.2}x ({:.1} ms)", m.mode, g, m.summary.tick_ms_median))
            })
            .collect();
        println!("  {} -> {} paths, median tick grows: {}", r.paths, size.paths, growth.join(", "));
    }
}

/// Writes `--plot`'s two plots into `dir`, which exists.
fn plot(dir: &std::path::Path, r: &ReuseReport) -> Result<()> {
    let series = r.modes.iter().map(|m| m.per_frame(|f| f.tick_ms)).collect();
    let caption = format!("Whole tick per frame ({}x{}, {} photon paths)", r.width, r.height, r.paths);
    write_both(dir, "reuse_tick_by_frame", &Lines { caption, x: "frame", unit: "ms".into(), series })?;
    let bars = r
        .modes
        .iter()
        .map(|m| {
            let frames = Frames(&m.frames);
            (m.mode.clone(), STAGES.iter().map(|&st| frames.quantile(|f| f.stages_ms[st], 0.5)).collect())
        })
        .collect();
    let caption = "Median tick by stage (frames 1 on)".to_string();
    write_both(
        dir,
        "reuse_stages",
        &StackedBars { caption, stages: STAGES.map(|s| s.replace('_', " ")).to_vec(), bars },
    )
}

pub fn run(args: ReuseArgs) -> Result<()> {
    super::plot::make_dir(args.plot.as_deref())?;
    let report = measure(&args)?;
    print_table(&report);
    super::write_json_report(args.run.json.as_deref(), &report)?;
    super::plot::draw_into(args.plot.as_deref(), |dir| plot(dir, &report))?;
    Ok(())
}
