//! Summaries and files of `relume bench error`: `results.csv`, `results.json`, `report.md` and
//! `errors/<config>.png` (the FLIP map of each configuration's worst measured frame, in magma).
use super::{ConfigSummary, ErrorReport, FrameResult};
use crate::tools::quantile;
use anyhow::{Context, Result};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// One frame list per configuration from its repeats: times are the per-frame medians, the rest
/// comes from the first run.
pub fn merge_repeats(mut runs: Vec<Vec<FrameResult>>) -> Vec<FrameResult> {
    let rest = runs.split_off(1.min(runs.len()));
    let Some(mut first) = runs.pop() else { return Vec::new() };
    for (i, f) in first.iter_mut().enumerate() {
        let at = |r: &Vec<FrameResult>| r.get(i).cloned();
        let all: Vec<FrameResult> = std::iter::once(f.clone()).chain(rest.iter().filter_map(at)).collect();
        f.tick_ms = quantile(&all.iter().map(|x| x.tick_ms).collect::<Vec<_>>(), 0.5);
        for (stage, ms) in f.stages_ms.iter_mut() {
            *ms =
                quantile(&all.iter().map(|x| x.stages_ms.get(stage).copied().unwrap_or(0.0)).collect::<Vec<_>>(), 0.5);
        }
    }
    first
}

/// Per-configuration summaries, with the Pareto front of (tick time, HDR-FLIP) marked.
pub fn summarise(labels: &[String], frames: &[FrameResult]) -> Vec<ConfigSummary> {
    let mut out: Vec<ConfigSummary> = labels
        .iter()
        .map(|label| {
            let label = label.clone();
            let mine: Vec<&FrameResult> = frames.iter().filter(|f| f.config == label).collect();
            let errors: Vec<(u32, super::ImageError)> =
                mine.iter().filter_map(|f| f.error.map(|e| (f.frame, e))).collect();
            let mean = |g: fn(&super::ImageError) -> f64| {
                errors.iter().map(|(_, e)| g(e)).sum::<f64>() / errors.len().max(1) as f64
            };
            let stages: BTreeMap<&'static str, f64> = mine
                .first()
                .map(|f| f.stages_ms.keys().copied().collect::<Vec<_>>())
                .unwrap_or_default()
                .into_iter()
                .map(|k| (k, quantile(&mine.iter().map(|f| f.stages_ms[k]).collect::<Vec<_>>(), 0.5)))
                .collect();
            ConfigSummary {
                config: label,
                tick_ms_median: quantile(&mine.iter().map(|f| f.tick_ms).collect::<Vec<_>>(), 0.5),
                rays_per_frame_median: quantile(&mine.iter().map(|f| f.rays as f64).collect::<Vec<_>>(), 0.5),
                rel_mse: mean(|e| e.rel_mse),
                rmse: mean(|e| e.rmse),
                psnr_db: mean(|e| e.psnr_db),
                flip_ldr: mean(|e| e.flip_ldr),
                flip_hdr: mean(|e| e.flip_hdr),
                stages_ms_median: stages,
                worst_frame: errors.iter().max_by(|a, b| a.1.flip_hdr.total_cmp(&b.1.flip_hdr)).map_or(0, |w| w.0),
                pareto: false,
            }
        })
        .collect();
    let points: Vec<(f64, f64)> = out.iter().map(|s| (s.tick_ms_median, s.flip_hdr)).collect();
    for (i, s) in out.iter_mut().enumerate() {
        let (t, e) = points[i];
        s.pareto = !points.iter().enumerate().any(|(j, &(t2, e2))| j != i && t2 <= t && e2 <= e && (t2 < t || e2 < e));
    }
    out
}

/// A file-name-safe form of a configuration label.
pub fn file_stem(label: &str) -> String {
    label.chars().map(|c| if c.is_ascii_alphanumeric() || c == '.' || c == '-' { c } else { '_' }).collect()
}

#[derive(serde::Serialize)]
struct CsvRow<'a> {
    config: &'a str,
    frame: u32,
    time_s: f32,
    tick_ms: f64,
    apply_commit_ms: f64,
    update_ms: f64,
    render_ms: f64,
    resolve_ms: f64,
    rays: u64,
    memory_bytes: u64,
    rel_mse: Option<f64>,
    rmse: Option<f64>,
    psnr_db: Option<f64>,
    flip_ldr: Option<f64>,
    flip_hdr: Option<f64>,
    mean_bias: Option<f64>,
}

pub fn write_all(
    dir: &Path,
    report: &ErrorReport,
    error_maps: &BTreeMap<String, (u32, f64, Vec<u8>)>,
    (width, height): (u32, u32),
) -> Result<()> {
    let mut csv = csv::Writer::from_path(dir.join("results.csv"))?;
    for f in &report.frames {
        let stage = |k: &str| f.stages_ms.get(k).copied().unwrap_or(0.0);
        csv.serialize(CsvRow {
            config: &f.config,
            frame: f.frame,
            time_s: f.time_s,
            tick_ms: f.tick_ms,
            apply_commit_ms: stage("apply_commit"),
            update_ms: stage("update"),
            render_ms: stage("render"),
            resolve_ms: stage("resolve"),
            rays: f.rays,
            memory_bytes: f.memory_bytes,
            rel_mse: f.error.map(|e| e.rel_mse),
            rmse: f.error.map(|e| e.rmse),
            psnr_db: f.error.map(|e| e.psnr_db),
            flip_ldr: f.error.map(|e| e.flip_ldr),
            flip_hdr: f.error.map(|e| e.flip_hdr),
            mean_bias: f.error.map(|e| e.mean_bias),
        })?;
    }
    csv.flush()?;
    std::fs::write(dir.join("results.json"), serde_json::to_string_pretty(report)?)?;
    let errors = dir.join("errors");
    std::fs::create_dir_all(&errors)?;
    for (label, (_, _, rgb)) in error_maps {
        let path = errors.join(format!("{}.png", file_stem(label)));
        image::save_buffer(&path, rgb, width, height, image::ExtendedColorType::Rgb8)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    std::fs::write(dir.join("report.md"), markdown(report))?;
    Ok(())
}

fn markdown(r: &ErrorReport) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# relume bench error: {}\n", r.scene);
    let _ = writeln!(
        md,
        "{} at {}×{}, {} threads; references: `{}` at {} spp, own relMSE ≤ {:.2e} (estimated from \
         two independent halves).\n",
        r.animation.as_deref().unwrap_or("static scene"),
        r.width,
        r.height,
        r.threads,
        r.reference,
        r.ref_spp,
        r.reference_rel_mse
    );
    md.push_str(&table(r));
    md.push_str(
        "\n★ marks the Pareto front of tick time against HDR-FLIP. Times are medians over frames \
         (each the median of the repeats); errors are means over the measured frames.\n\n\
         ![tick time against error](time_vs_error.png)\n\n![rays per frame](rays_per_frame.png)\n\n\
         ![error by frame](error_by_frame.png)\n\n![stage times](stage_times.png)\n\nWorst frames, FLIP error in magma (black: none, yellow: \
         large):\n\n",
    );
    for s in &r.summaries {
        let _ = writeln!(md, "- `{}` frame {}: ![](errors/{}.png)", s.config, s.worst_frame, file_stem(&s.config));
    }
    md
}

/// The summary as a Markdown table (also printed).
pub fn table(r: &ErrorReport) -> String {
    let mut t = String::from(
        "| configuration | tick ms | rays/frame | relMSE | RMSE | PSNR dB | FLIP (LDR) | FLIP (HDR) |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for s in &r.summaries {
        let _ = writeln!(
            t,
            "| {}{} | {:.1} | {:.0} | {:.4} | {:.4} | {:.1} | {:.4} | {:.4} |",
            if s.pareto { "★ " } else { "" },
            s.config,
            s.tick_ms_median,
            s.rays_per_frame_median,
            s.rel_mse,
            s.rmse,
            s.psnr_db,
            s.flip_ldr,
            s.flip_hdr
        );
    }
    t
}

pub fn print_table(r: &ErrorReport) {
    println!(
        "relume bench error: {} ({}), {}x{}, {} threads, references {} {} spp (own relMSE {:.2e})",
        r.scene,
        r.animation.as_deref().unwrap_or("static"),
        r.width,
        r.height,
        r.threads,
        r.reference,
        r.ref_spp,
        r.reference_rel_mse
    );
    print!("{}", table(r));
}
