//! The plots the benchmarks and the load client write, each as PNG and SVG (plotters): a value
//! per frame (or second) as one line per configuration ([`Lines`]), and a median time per stage
//! as one stacked bar per configuration ([`StackedBars`]). `bench error`, `bench icache`, `bench
//! reuse` and `load` draw their data with them.
use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

const SIZE: (u32, u32) = (960, 600);

/// What a configuration's spec and label append for the denoise stage (`bench error`'s
/// `path:spp=1+oidn`): the plots tell a denoised twin from its configuration by it.
pub const DENOISED_MARK: &str = "+oidn";

/// The `i`-th colour of a ten-colour palette (matplotlib's `tab10`), repeating.
pub fn colour(i: usize) -> RGBColor {
    const PALETTE: [RGBColor; 10] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(127, 127, 127),
        RGBColor(188, 189, 34),
        RGBColor(23, 190, 207),
    ];
    PALETTE[i % PALETTE.len()]
}

/// A label's configuration (the label less its denoise suffix) and whether it is the denoised
/// twin ([`DENOISED_MARK`]).
fn family_of(label: &str) -> (&str, bool) {
    label.split_once(DENOISED_MARK).map_or((label, false), |(head, _)| (head, true))
}

/// A configuration run with the denoise stage.
pub fn denoised(label: &str) -> bool {
    family_of(label).1
}

/// One colour per label, shared by a configuration and its denoised twin, so ten
/// configurations with their twins take five colours, not ten that repeat. Families take the
/// palette in order of first appearance.
pub fn family_colours<'a>(labels: impl IntoIterator<Item = &'a str>) -> Vec<RGBColor> {
    let mut families: Vec<&str> = Vec::new();
    labels
        .into_iter()
        .map(|label| {
            let family = family_of(label).0;
            let i = families.iter().position(|&f| f == family).unwrap_or_else(|| {
                families.push(family);
                families.len() - 1
            });
            colour(i)
        })
        .collect()
}

/// A plotting error as an `anyhow` error.
pub fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plotting: {e}")
}

/// A plot that can be drawn on any plotters backend.
pub trait Plot {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<()>;
}

/// Makes `--plot`'s directory (if asked for one) before a run, so a directory that cannot be
/// made fails at once, as a usage error naming the flag, not after the run.
pub fn make_dir(dir: Option<&Path>) -> Result<(), super::UsageError> {
    match dir {
        Some(dir) => {
            std::fs::create_dir_all(dir).map_err(|e| super::UsageError(format!("--plot {}: {e}", dir.display())))
        }
        None => Ok(()),
    }
}

/// After a run, draws into `--plot`'s directory (made by [`make_dir`] before it), if one was
/// asked for, and says where.
pub fn draw_into(dir: Option<&Path>, draw: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    if let Some(dir) = dir {
        draw(dir)?;
        println!("  wrote the plots to {}", dir.display());
    }
    Ok(())
}

/// Draws `plot` into `<stem>.png` and `<stem>.svg` under `dir`.
pub fn write_both<P: Plot>(dir: &Path, stem: &str, plot: &P) -> Result<()> {
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

/// The legend every plot draws, top right.
pub fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(chart: &mut ChartContext<'a, DB, CT>) -> Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)
}

/// A positive value per frame (or second), one line per configuration, on a log scale.
pub struct Lines {
    pub caption: String,
    /// What the points' x values count, whole numbers (`frame`), for the x axis.
    pub x: &'static str,
    /// What the values are, for the y axis.
    pub unit: String,
    /// Per configuration: its label and its (frame, value) points; values ≤ 0 are left out.
    pub series: Vec<(String, Vec<(f64, f64)>)>,
}

impl Plot for Lines {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<()> {
        area.fill(&WHITE).map_err(err)?;
        let points = || self.series.iter().flat_map(|(_, p)| p.iter()).filter(|p| p.1 > 0.0);
        let frames = points().map(|p| p.0).fold(0.0, f64::max) + 1.0;
        let hi = points().map(|p| p.1).fold(f64::MIN_POSITIVE, f64::max) * 2.0;
        let lo = points().map(|p| p.1).fold(hi, f64::min) / 2.0;
        let mut chart = ChartBuilder::on(area)
            .caption(&self.caption, ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(72)
            .build_cartesian_2d(
                0.0..frames,
                (lo..hi).log_scale().with_key_points(log_labels(lo, hi)).with_light_points(log_steps(
                    lo,
                    hi,
                    &UNIT_STEPS,
                )),
            )
            .map_err(err)?;
        // Frames and seconds are whole numbers: a label between two is left blank.
        let whole = |v: &f64| if v.fract() == 0.0 { format!("{v:.0}") } else { String::new() };
        chart
            .configure_mesh()
            .x_desc(self.x)
            .x_label_formatter(&whole)
            .y_desc(format!("{} (log)", self.unit))
            .y_label_formatter(&|v| readable(*v))
            .draw()
            .map_err(err)?;
        // A denoised twin is drawn dashed in its configuration's colour.
        let colours = family_colours(self.series.iter().map(|(label, _)| label.as_str()));
        for ((label, points), c) in self.series.iter().zip(colours) {
            let points = points.iter().copied().filter(|p| p.1 > 0.0);
            let style = ShapeStyle::from(&c).stroke_width(2);
            let dashed = denoised(label);
            let drawn = if dashed {
                chart.draw_series(DashedLineSeries::new(points, 8, 5, style))
            } else {
                chart.draw_series(LineSeries::new(points, style))
            };
            // The legend's sample is one 18-pixel dash for a solid line.
            let (dash, gap) = if dashed { (6, 3) } else { (18, 1) };
            drawn.map_err(err)?.label(label.clone()).legend(move |(x, y)| {
                plotters::element::DashedPathElement::new(vec![(x, y), (x + 18, y)], dash, gap, style)
            });
        }
        legend(&mut chart)
    }
}

/// A log axis's label: plain decimals from 0.001 to 99 999 ("0.002", "50"), else
/// scientific ("1e-5"). Labels are m × 10^k with a one-digit m, so this is exact.
fn readable(v: f64) -> String {
    let exponent = v.abs().log10().floor();
    if (-3.0..5.0).contains(&exponent) {
        format!("{v:.0$}", (-exponent).max(0.0) as usize)
    } else {
        format!("{v:.0e}")
    }
}

/// A linear axis's label without trailing zeros ("10", "2.5"), to three decimals.
fn plain(v: f64) -> String {
    let text = format!("{v:.3}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Every mantissa of a decade: a log axis's light lines, and its labels when the range is short.
const UNIT_STEPS: [u32; 9] = [1, 2, 3, 4, 5, 6, 7, 8, 9];

/// The values m × 10^k in `lo..=hi` for each mantissa m in `mantissas`, ascending.
fn log_steps(lo: f64, hi: f64, mantissas: &[u32]) -> Vec<f64> {
    let (first, last) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let decades = (first..=last).map(|k| 10f64.powi(k));
    let values = decades.flat_map(|d| mantissas.iter().map(move |&m| f64::from(m) * d));
    values.filter(|v| (lo..=hi).contains(v)).collect()
}

/// The labelled values of a log axis over `lo..hi`: the powers of ten when it spans at least
/// three, otherwise 1-2-5 steps, or every unit step (at least three when `hi ≥ 4 lo`). (Plotters'
/// own labels are the powers of ten, so a range inside one decade got one label or none.)
fn log_labels(lo: f64, hi: f64) -> Vec<f64> {
    [&[1][..], &[1, 2, 5]]
        .iter()
        .map(|m| log_steps(lo, hi, m))
        .find(|v| v.len() >= 3)
        .unwrap_or_else(|| log_steps(lo, hi, &UNIT_STEPS))
}

/// Median milliseconds per stage, one bar per configuration with its stages stacked.
pub struct StackedBars {
    pub caption: String,
    /// The stages, bottom to top.
    pub stages: Vec<String>,
    /// Per configuration: its label and its milliseconds per stage, in `stages` order.
    pub bars: Vec<(String, Vec<f64>)>,
}

impl Plot for StackedBars {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<()> {
        area.fill(&WHITE).map_err(err)?;
        let n = self.bars.len();
        let t_max = self.bars.iter().map(|(_, ms)| ms.iter().sum::<f64>()).fold(1e-3, f64::max) * 1.25;
        let mut chart = ChartBuilder::on(area)
            .caption(&self.caption, ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..n as f64, 0.0..t_max)
            .map_err(err)?;
        // One bar per configuration, centred on i + 0.5, where its label goes.
        let label_at = |v: &f64| {
            let i = v - 0.5;
            let on_bar = (i - i.round()).abs() < 1e-6 && i >= 0.0;
            on_bar.then(|| self.bars.get(i.round() as usize).map(|b| b.0.clone())).flatten().unwrap_or_default()
        };
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * n + 1)
            .x_desc("configuration")
            .y_desc("ms")
            .y_label_formatter(&|v| plain(*v))
            .x_label_formatter(&label_at)
            .draw()
            .map_err(err)?;
        for (k, stage) in self.stages.iter().enumerate() {
            let c = colour(k);
            let bars = self.bars.iter().enumerate().map(|(i, (_, ms))| {
                let below: f64 = ms[..k.min(ms.len())].iter().sum();
                let mine = ms.get(k).copied().unwrap_or(0.0);
                Rectangle::new([(i as f64 + 0.2, below), (i as f64 + 0.8, below + mine)], c.mix(0.85).filled())
            });
            chart
                .draw_series(bars)
                .map_err(err)?
                .label(stage.clone())
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], c.filled()));
        }
        legend(&mut chart)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_configuration_and_its_denoised_twin_share_a_colour_and_families_differ() {
        // `bench error --denoise` lists each configuration next to its `+oidn` twin: five
        // techniques make ten labels. Colouring by index repeated the eight-colour palette, so
        // `path` and the ninth label looked alike; by family, twins match and the five differ.
        let labels = ["path:spp=1", "path:spp=1+oidn", "bdpt", "bdpt+oidn=fast", "photon_reuse", "instant_cache"];
        let c = family_colours(labels);
        assert_eq!(c[0], c[1], "a twin takes its configuration's colour");
        assert_eq!(c[2], c[3], "whatever its quality");
        let distinct = [c[0], c[2], c[4], c[5]];
        for (i, a) in distinct.iter().enumerate() {
            assert!(distinct[i + 1..].iter().all(|b| b != a), "families {distinct:?} share a colour");
        }
        assert!(denoised(labels[3]) && !denoised(labels[2]));
        let ten: Vec<String> = (0..10).map(|i| format!("t{i}")).collect();
        let c = family_colours(ten.iter().map(String::as_str));
        assert!((0..10).all(|i| c[i + 1..].iter().all(|b| *b != c[i])), "ten families need ten colours");
    }

    #[test]
    fn a_log_axis_has_three_labels_whatever_its_span() {
        // Powers of ten alone (plotters' choice, and the negative control below) label a range
        // inside one decade once or not at all; 1-2-5 or unit steps fill it, and a wide range
        // keeps only the powers of ten. `Lines` pads its values by 2× each way, so its ranges
        // are at least 4× wide, as these are.
        for (lo, hi) in [(0.002, 0.008), (0.0026, 0.0104), (0.2, 3.0), (1e-4, 0.5), (3e-7, 40.0)] {
            let labels = log_labels(lo, hi);
            assert!(labels.len() >= 3, "{lo}..{hi}: {labels:?}");
            assert!(labels.iter().all(|v| (lo..=hi).contains(v)) && labels.windows(2).all(|w| w[0] < w[1]));
            let spans_decades = log_steps(lo, hi, &[1]).len() >= 3;
            assert_eq!(
                spans_decades,
                labels.iter().all(|v| (v.log10() - v.log10().round()).abs() < 1e-9),
                "{lo}..{hi}: {labels:?}"
            );
        }
        assert!(log_steps(0.002, 0.008, &[1]).len() < 3, "powers of ten alone must fail the first range");
    }

    #[test]
    fn log_labels_read_as_plain_numbers_in_the_usual_range() {
        // Each label parses back to its value, and only values outside 0.001..100 000 keep
        // scientific notation. Negative control: the old `{:.0e}` labels ("5e1" for 50 ms)
        // fail the second assertion.
        for v in log_steps(1e-7, 1e7, &[1, 2, 5]) {
            let text = readable(v);
            let back: f64 = text.parse().expect("a label parses as a number");
            assert!((back - v).abs() <= 1e-9 * v, "{v} reads as {text}");
            assert_eq!(text.contains('e'), !(1e-3..1e5).contains(&(v * (1.0 + 1e-12))), "{v} reads as {text}");
        }
        assert_eq!(readable(50.0), "50");
        assert_eq!([plain(10.0), plain(2.5), plain(0.30000000000000004)], ["10", "2.5", "0.3"]);
    }
}
