//! Plots of `relume bench error`, each as PNG and SVG (plotters):
//! - `time_vs_error`: median tick time against mean HDR-FLIP, one point per configuration, the
//!   Pareto front joined;
//! - `rays_per_frame`: rays traced per frame over the run, per configuration (Moreau et al.'s
//!   Figure 7);
//! - `error_by_frame`: relMSE of each measured frame, per configuration: how a still view
//!   converges, or how error builds up over an animation;
//! - `stage_times`: median time per tick stage, stacked, per configuration (their Figure 8).
use super::{ErrorReport, FrameResult};
use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

const SIZE: (u32, u32) = (960, 600);
const STAGES: [&str; 4] = ["apply_commit", "update", "render", "resolve"];

fn colour(i: usize) -> RGBColor {
    const PALETTE: [RGBColor; 8] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(127, 127, 127),
    ];
    PALETTE[i % PALETTE.len()]
}

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plotting: {e}")
}

/// A plot that can be drawn on any plotters backend.
trait Plot {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<()>;
}

/// Draws `plot` into `<stem>.png` and `<stem>.svg` under `dir`.
fn both<P: Plot>(dir: &Path, stem: &str, plot: &P) -> Result<()> {
    let png = dir.join(format!("{stem}.png"));
    let root = BitMapBackend::new(&png, SIZE).into_drawing_area();
    plot.draw(&root)?;
    root.present().map_err(err)?;
    let svg = dir.join(format!("{stem}.svg"));
    let root = SVGBackend::new(&svg, SIZE).into_drawing_area();
    plot.draw(&root)?;
    root.present().map_err(err)?;
    Ok(())
}

pub fn write_all(dir: &Path, r: &ErrorReport) -> Result<()> {
    both(dir, "time_vs_error", &TimeVsError(r))?;
    both(dir, "rays_per_frame", &PerFrame { report: r, caption: "Rays traced per frame", unit: "rays", value: rays })?;
    let error = PerFrame { report: r, caption: "Error of each measured frame", unit: "relMSE", value: rel_mse };
    both(dir, "error_by_frame", &error)?;
    both(dir, "stage_times", &StageTimes(r))?;
    Ok(())
}

/// The legend every plot draws, top right.
fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(chart: &mut ChartContext<'a, DB, CT>) -> Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)
}

struct TimeVsError<'a>(&'a ErrorReport);
/// A value of each frame, per configuration, on a log scale.
struct PerFrame<'a> {
    report: &'a ErrorReport,
    caption: &'static str,
    unit: &'static str,
    /// The frame's value, if it has one.
    value: fn(&FrameResult) -> Option<f64>,
}

fn rays(f: &FrameResult) -> Option<f64> {
    Some((f.rays as f64).max(1.0))
}

fn rel_mse(f: &FrameResult) -> Option<f64> {
    f.error.as_ref().map(|e| e.rel_mse).filter(|e| *e > 0.0)
}
struct StageTimes<'a>(&'a ErrorReport);

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
        // Denoised configurations (`+oidn`) are triangles, the raw ones circles.
        for (i, x) in s.iter().enumerate() {
            let c = colour(i);
            let label = format!("{}{}", if x.pareto { "★ " } else { "" }, x.config);
            let at = (x.tick_ms_median, x.flip_hdr);
            if x.config.contains("+oidn") {
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

impl Plot for PerFrame<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<()> {
        let r = self.report;
        area.fill(&WHITE).map_err(err)?;
        let frames = r.frames.iter().map(|f| f.frame).max().unwrap_or(0) as f64 + 1.0;
        let values: Vec<f64> = r.frames.iter().filter_map(self.value).collect();
        let hi = values.iter().copied().fold(f64::MIN_POSITIVE, f64::max) * 2.0;
        let lo = values.iter().copied().fold(hi, f64::min) / 2.0;
        let mut chart = ChartBuilder::on(area)
            .caption(self.caption, ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(72)
            .build_cartesian_2d(0.0..frames, (lo..hi).log_scale())
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("frame")
            .y_desc(format!("{} (log)", self.unit))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(err)?;
        for (i, s) in r.summaries.iter().enumerate() {
            let c = colour(i);
            let value = self.value;
            let points =
                r.frames.iter().filter(|f| f.config == s.config).filter_map(|f| Some((f.frame as f64, value(f)?)));
            chart
                .draw_series(LineSeries::new(points, ShapeStyle::from(&c).stroke_width(2)))
                .map_err(err)?
                .label(s.config.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c));
        }
        legend(&mut chart)
    }
}

impl Plot for StageTimes<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<()> {
        let s = &self.0.summaries;
        area.fill(&WHITE).map_err(err)?;
        let total = |x: &super::ConfigSummary| {
            STAGES.iter().map(|k| x.stages_ms_median.get(k).copied().unwrap_or(0.0)).sum::<f64>()
        };
        let t_max = s.iter().map(total).fold(1e-3, f64::max) * 1.25;
        let mut chart = ChartBuilder::on(area)
            .caption("Median time per tick stage", ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..s.len() as f64, 0.0..t_max)
            .map_err(err)?;
        let labels: Vec<String> = s.iter().map(|x| x.config.clone()).collect();
        // One bar per configuration, centred on i + 0.5, where its label goes.
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * s.len() + 1)
            .x_desc("configuration")
            .y_desc("ms")
            .x_label_formatter(&|v| {
                let i = v - 0.5;
                if (i - i.round()).abs() < 1e-6 && i >= 0.0 {
                    labels.get(i.round() as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .draw()
            .map_err(err)?;
        for (k, stage) in STAGES.iter().enumerate() {
            let c = colour(k);
            let bars = s.iter().enumerate().map(|(i, x)| {
                let below: f64 = STAGES[..k].iter().map(|st| x.stages_ms_median.get(st).copied().unwrap_or(0.0)).sum();
                let mine = x.stages_ms_median.get(stage).copied().unwrap_or(0.0);
                Rectangle::new([(i as f64 + 0.2, below), (i as f64 + 0.8, below + mine)], c.mix(0.85).filled())
            });
            chart
                .draw_series(bars)
                .map_err(err)?
                .label(*stage)
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], c.filled()));
        }
        legend(&mut chart)
    }
}
