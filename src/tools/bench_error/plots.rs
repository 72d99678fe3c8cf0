//! Plots of `relume bench error`, each as PNG and SVG (`tools/plot.rs`):
//! - `time_vs_error`: median tick time against mean HDR-FLIP, one point per configuration, the
//!   Pareto front joined;
//! - `rays_per_frame`: rays traced per frame over the run, per configuration (Moreau et al.'s
//!   Figure 7);
//! - `error_by_frame`: relMSE of each measured frame, per configuration: how a still view
//!   converges, or how error builds up over an animation;
//! - `stage_times`: median time per tick stage, stacked, per configuration (their Figure 8).
use super::{ErrorReport, FrameResult};
use crate::tools::plot::{denoised, err, family_colours, legend, write_both, Lines, Plot, StackedBars};
use anyhow::Result;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

const STAGES: [&str; 4] = ["apply_commit", "update", "render", "resolve"];

/// Writes the four plots into `dir`.
pub fn write_all(dir: &Path, r: &ErrorReport) -> Result<()> {
    write_both(dir, "time_vs_error", &TimeVsError(r))?;
    // A frame that traced no ray is drawn at 1, the bottom of the log scale.
    let rays = per_frame(r, "Rays traced per frame", "rays", |f| Some((f.rays as f64).max(1.0)));
    write_both(dir, "rays_per_frame", &rays)?;
    let error = per_frame(r, "Error of each measured frame", "relMSE", |f| f.error.as_ref().map(|e| e.rel_mse));
    write_both(dir, "error_by_frame", &error)?;
    write_both(dir, "stage_times", &stage_times(r))
}

/// A value of each frame (`value`, where it has one), one line per configuration.
fn per_frame(r: &ErrorReport, caption: &str, unit: &str, value: fn(&FrameResult) -> Option<f64>) -> Lines {
    let series = r
        .summaries
        .iter()
        .map(|s| {
            let frames = r.frames.iter().filter(|f| f.config == s.config);
            (s.config.clone(), frames.filter_map(|f| Some((f.frame as f64, value(f)?))).collect())
        })
        .collect();
    Lines { caption: caption.into(), x: "frame", unit: unit.into(), series }
}

/// Median milliseconds per tick stage, per configuration.
fn stage_times(r: &ErrorReport) -> StackedBars {
    let bars = r
        .summaries
        .iter()
        .map(|x| (x.config.clone(), STAGES.iter().map(|k| x.stages_ms_median.get(k).copied().unwrap_or(0.0)).collect()))
        .collect();
    StackedBars { caption: "Median time per tick stage".into(), stages: STAGES.map(String::from).to_vec(), bars }
}

/// Median tick time against mean HDR-FLIP, one point per configuration.
struct TimeVsError<'a>(&'a ErrorReport);

impl Plot for TimeVsError<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<()> {
        let s = &self.0.summaries;
        area.fill(&WHITE).map_err(err)?;
        let t_max = s.iter().map(|x| x.tick_ms_median).fold(1e-3, f64::max) * 1.15;
        let e_max = s.iter().map(|x| x.flip_hdr).fold(1e-4, f64::max) * 1.15;
        let mut chart = ChartBuilder::on(area)
            .caption("Tick time against error (HDR-FLIP, lower is better)", ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..t_max, 0.0..e_max)
            .map_err(err)?;
        chart.configure_mesh().x_desc("median tick time (ms)").y_desc("mean HDR-FLIP").draw().map_err(err)?;
        let mut front: Vec<(f64, f64)> =
            s.iter().filter(|x| x.pareto).map(|x| (x.tick_ms_median, x.flip_hdr)).collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(front, ShapeStyle::from(&BLACK.mix(0.5)).stroke_width(2)))
            .map_err(err)?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.mix(0.5)));
        // Denoised configurations (`+oidn`) are triangles in their raw twin's colour, the raw
        // ones circles.
        let colours = family_colours(s.iter().map(|x| x.config.as_str()));
        for (x, c) in s.iter().zip(colours) {
            let label = format!("{}{}", if x.pareto { "★ " } else { "" }, x.config);
            let at = (x.tick_ms_median, x.flip_hdr);
            if denoised(&x.config) {
                chart
                    .draw_series(std::iter::once(TriangleMarker::new(at, 9, c.filled())))
                    .map_err(err)?
                    .label(label)
                    .legend(move |(px, py)| TriangleMarker::new((px + 9, py), 7, c.filled()));
            } else {
                chart
                    .draw_series(std::iter::once(Circle::new(at, 7, c.filled())))
                    .map_err(err)?
                    .label(label)
                    .legend(move |(px, py)| Circle::new((px + 9, py), 6, c.filled()));
            }
        }
        legend(&mut chart)
    }
}
