//! `relume bench rays`: ray throughput in one run, reported as rates and ratios.
//!
//! 1. Raw Embree throughput on the scene: coherent primary rays in 16-wide packets, incoherent
//!    closest-hit rays (cosine-distributed from first hits) and incoherent occlusion rays (from
//!    first hits to light samples), single rays on every worker. It is measured on each
//!    [`AccelLayout`]: the default (`auto`: flat when nothing is dynamic, else nested), static
//!    geometry nested under an identity instance or flat in the top level, robust or fast
//!    triangle test, and on a frozen copy with every surface static and flat (the ceiling: one
//!    BVH, no instances), so the default layout's choice is a measurement.
//! 2. The `path` technique's achieved ray rate, as a fraction of the raw incoherent rate, and
//!    as a fraction of raw Embree at `path`'s own ray mix: its camera rays at the coherent
//!    rate, its bounce rays at the incoherent closest-hit rate and its shadow rays at the
//!    occlusion rate, so the time raw Embree would need for exactly `path`'s rays (the
//!    harmonic mean weighted by ray counts). That is the ceiling of a tracer whose shading
//!    cost nothing.
//! 3. Path regeneration against none at packet widths 1, 8 and 16 on dark (ρ × 0.5), normal and
//!    bright (ρ_S ≈ 0.8) variants of the scene, as in Novák et al. (2010), Table 1, for `path`
//!    and for `bdpt`'s eye paths.
//!
//! Each measurement repeats until `--seconds` have passed; only rates in one run are compared.
use super::SceneArgs;
use crate::core::{offset_ray_origin, sampling, Rng, ShadingFrame};
use crate::embree::{Device, Intersector, Ray};
use crate::engine::{thread_pool, Session};
use crate::scene::accel::{AccelLayout, StaticLayout};
use crate::scene::{Scene, SceneAccel};
use crate::technique::bdpt::BdptConfig;
use crate::technique::path::{max_path_length, PathConfig};
use crate::technique::{RayCounts, TechniqueConfig, TechniqueStats};
use anyhow::Result;
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct RaysArgs {
    #[command(flatten)]
    pub target: SceneArgs,
    /// Minimum wall time per measurement, seconds.
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// Also write the figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

#[derive(Debug, Serialize)]
pub struct RawThroughput {
    /// `default` (the layout every technique uses), `nested`, `flat`, or `frozen` (every
    /// surface static and flat).
    pub accel: String,
    pub layout: AccelLayout,
    pub coherent_primary_mrays: f64,
    pub incoherent_closest_mrays: f64,
    pub incoherent_occlusion_mrays: f64,
}

#[derive(Debug, Serialize)]
pub struct RegenerationRow {
    /// `path` or `bdpt` (eye paths; bdpt's light subpaths are traced per packet, outside lanes).
    pub technique: String,
    pub variant: String,
    pub mean_reflectance: f32,
    pub max_path_length: u32,
    /// Mean path length in segments (rays per path excluding shadow rays).
    pub mean_path_length: f64,
    /// Paths cut at l_m ÷ paths, to set against c (`admitted_truncation`, 0.01 by default).
    pub truncated_fraction: f64,
    pub packet_width: u32,
    pub no_regeneration_utilisation: f64,
    pub no_regeneration_mrays: f64,
    pub regeneration_utilisation: f64,
    pub regeneration_mrays: f64,
    /// Regeneration rays/s ÷ no-regeneration rays/s.
    pub speedup: f64,
}

#[derive(Debug, Serialize)]
pub struct RaysReport {
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    /// Raw rates per layout; the first row is the default layout.
    pub raw: Vec<RawThroughput>,
    /// The default `path` configuration's rate.
    pub path_mrays: f64,
    pub path_samples_per_second: f64,
    /// path_mrays ÷ the default layout's raw incoherent closest-hit rate.
    pub path_to_raw_ratio: f64,
    /// path_mrays ÷ the best raw incoherent closest-hit rate of any layout.
    pub path_to_best_raw_ratio: f64,
    /// Raw Embree at `path`'s ray mix on the default layout and on the best one (Mrays/s;
    /// see the module doc).
    pub raw_at_path_mix_mrays: f64,
    pub best_raw_at_path_mix_mrays: f64,
    /// path_mrays ÷ raw_at_path_mix_mrays.
    pub path_to_mix_ratio: f64,
    pub regeneration: Vec<RegenerationRow>,
}

/// Repeats `f` (which returns rays traced) until `seconds` pass; returns Mrays/s.
fn rate(seconds: f64, mut f: impl FnMut() -> u64) -> f64 {
    let start = Instant::now();
    let mut rays = 0u64;
    while rays == 0 || start.elapsed().as_secs_f64() < seconds {
        rays += f();
    }
    rays as f64 / start.elapsed().as_secs_f64() / 1e6
}

/// Incoherent test rays: from first hits of camera rays, cosine-distributed bounce directions
/// and shadow segments to light samples.
fn incoherent_rays(scene: &Scene, accel: &SceneAccel) -> (Vec<Ray>, Vec<Ray>) {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut bounce = Vec::new();
    let mut shadow = Vec::new();
    let mut rng = Rng::new(99, 1);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.ray(x as f32 + 0.5, y as f32 + 0.5);
            let Some(hit) = accel.scene().intersect1(&ray) else { continue };
            let Some((surface, prim)) = accel.resolve(&hit) else { continue };
            let sp = scene.surface_point(surface, prim, hit.u, hit.v);
            let n = if sp.n.dot(ray.dir) < 0.0 { sp.n } else { -sp.n };
            let origin = offset_ray_origin(sp.p, n);
            let dir = ShadingFrame::from_normal(n).to_world(sampling::cosine_hemisphere(rng.next_2d()));
            bounce.push(Ray::new(origin, dir));
            if let Some(select) = &scene.light_selection {
                let (li, _, _) = select.sample(rng.next_f32());
                if let Some(s) = scene.lights[li].geometry.sample_incident(origin, n, rng.next_2d()) {
                    shadow.push(Ray::segment(origin, s.wi, s.dist * 0.9999));
                }
            }
        }
    }
    (bounce, shadow)
}

/// The layouts `bench rays` compares: (name, frozen, layout). The default comes first.
fn raw_layouts() -> Vec<(&'static str, bool, AccelLayout)> {
    let mut out = vec![("default", false, AccelLayout::default())];
    for intersector in [Intersector::Robust, Intersector::Fast] {
        for (name, statics) in [("nested", StaticLayout::Nested), ("flat", StaticLayout::Flat)] {
            let layout = AccelLayout { statics, intersector };
            if layout != AccelLayout::default() {
                out.push((name, false, layout));
            }
        }
        out.push(("frozen", true, AccelLayout { statics: StaticLayout::Flat, intersector }));
    }
    out
}

/// Raw rates on every layout of [`raw_layouts`]; rays are cast from the default accel's hits.
fn raw_rows(scene: &Scene, device: &Device, seconds: f64) -> Result<Vec<RawThroughput>> {
    let rays = incoherent_rays(scene, &SceneAccel::build(device, scene)?);
    let mut frozen = scene.clone();
    frozen.objects.iter_mut().for_each(|o| o.dynamic = false);
    frozen.lights.iter_mut().for_each(|l| l.dynamic = false);
    raw_layouts()
        .into_iter()
        .map(|(name, freeze, layout)| {
            let accel = SceneAccel::build_with(device, if freeze { &frozen } else { scene }, layout)?;
            Ok(raw_throughput(scene, &accel, &rays, seconds, name))
        })
        .collect()
}

fn raw_throughput(
    scene: &Scene,
    accel: &SceneAccel,
    (bounce, shadow): &(Vec<Ray>, Vec<Ray>),
    seconds: f64,
    name: &str,
) -> RawThroughput {
    let committed = accel.scene();
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let coherent = rate(seconds, || {
        (0..h)
            .into_par_iter()
            .map(|y| {
                let mut n = 0u64;
                for x0 in (0..w).step_by(16) {
                    let rays: [Ray; 16] =
                        std::array::from_fn(|i| scene.camera.ray((x0 + i) as f32 + 0.5, y as f32 + 0.5));
                    let active: [bool; 16] = std::array::from_fn(|i| x0 + i < w);
                    let mut hits = [None; 16];
                    committed.intersect16(&rays, &active, true, &mut hits);
                    n += active.iter().filter(|a| **a).count() as u64;
                }
                n
            })
            .sum()
    });
    let closest = rate(seconds, || {
        bounce.par_iter().map(|r| std::hint::black_box(committed.intersect1(r)).map_or(1, |_| 1)).sum()
    });
    let occlusion = rate(seconds, || {
        shadow
            .par_iter()
            .map(|r| {
                std::hint::black_box(committed.occluded1(r));
                1
            })
            .sum()
    });
    RawThroughput {
        accel: name.to_string(),
        layout: accel.layout(),
        coherent_primary_mrays: coherent,
        incoherent_closest_mrays: closest,
        incoherent_occlusion_mrays: occlusion,
    }
}

/// One lane technique's rates over a timed run.
struct LaneRate {
    mrays: f64,
    /// The rays it traced, by kind.
    rays: RayCounts,
    paths_per_second: f64,
    utilisation: f64,
    /// Eye segments per path.
    segments: f64,
    /// Paths cut at l_m ÷ paths.
    truncated: f64,
}

/// Runs a lane technique (`path` or `bdpt`) with `config` for `seconds`.
fn lane_rate(scene: &Scene, config: TechniqueConfig, device: &Device, seconds: f64) -> Result<LaneRate> {
    let mut session = Session::new(scene.clone(), &config, 1, device)?;
    let start = Instant::now();
    let mut rays = RayCounts::default();
    let mut total = crate::technique::path::PathStats::default();
    while total.paths == 0 || start.elapsed().as_secs_f64() < seconds {
        let frame = session.tick()?;
        rays = rays.merge(frame.stats.rays);
        let p = match &frame.stats.detail {
            TechniqueStats::Path(p) => p.clone(),
            TechniqueStats::Bdpt(b) => b.lanes.clone(),
            _ => anyhow::bail!("bench rays measures the lane techniques (path, bdpt) only"),
        };
        total = total.merge(p);
    }
    let secs = start.elapsed().as_secs_f64();
    let paths = total.paths.max(1) as f64;
    Ok(LaneRate {
        mrays: rays.total() as f64 / secs / 1e6,
        rays,
        paths_per_second: total.paths as f64 / secs,
        utilisation: total.lane_utilisation(),
        segments: (total.rays.primary + total.rays.secondary) as f64 / paths,
        truncated: total.truncated_paths as f64 / paths,
    })
}

/// Raw Embree's rate (Mrays/s) for `rays` on the layout `raw`: its camera rays at the coherent
/// rate, bounces at the incoherent closest-hit rate, shadow rays at the occlusion rate.
fn rate_at_mix(raw: &RawThroughput, rays: &RayCounts) -> f64 {
    let seconds = rays.primary as f64 / raw.coherent_primary_mrays
        + rays.secondary as f64 / raw.incoherent_closest_mrays
        + rays.shadow as f64 / raw.incoherent_occlusion_mrays;
    rays.total() as f64 / seconds
}

/// `technique` with `width` lanes and regeneration on or off, other parameters at defaults.
fn lane_config(technique: &str, width: u32, regeneration: bool) -> TechniqueConfig {
    match technique {
        "bdpt" => {
            TechniqueConfig::Bdpt(BdptConfig { packet_width: Some(width), regeneration, ..BdptConfig::default() })
        }
        _ => TechniqueConfig::Path(PathConfig { packet_width: Some(width), regeneration, ..PathConfig::default() }),
    }
}

pub fn measure(args: &RaysArgs) -> Result<RaysReport> {
    let scene = args.target.load_scene()?;
    let threads = args.target.threads();
    let pool = thread_pool(threads)?;
    let device = args.target.device()?;
    let variants = [("dark", 0.5f32), ("normal", 1.0), ("bright", 0.8 / scene.mean_reflectance().max(1e-3))];
    let widths = [1u32, 8, 16];
    let techniques = ["path", "bdpt"];
    let bar = ProgressBar::new((raw_layouts().len() + 1 + techniques.len() * variants.len() * widths.len() * 2) as u64);
    bar.set_style(indicatif::ProgressStyle::with_template("{msg:32} [{bar:30}] {pos}/{len}")?.progress_chars("=> "));
    pool.install(|| -> Result<RaysReport> {
        bar.set_message("raw Embree throughput");
        let raw = raw_rows(&scene, &device, args.seconds)?;
        bar.inc(raw.len() as u64);
        bar.set_message("path, default configuration");
        let default_path = lane_rate(&scene, TechniqueConfig::Path(PathConfig::default()), &device, args.seconds)?;
        let (path_mrays, path_sps) = (default_path.mrays, default_path.paths_per_second);
        let at_mix: Vec<f64> = raw.iter().map(|r| rate_at_mix(r, &default_path.rays)).collect();
        bar.inc(1);
        let mut rows = Vec::new();
        for technique in techniques {
            for (name, factor) in variants {
                let variant = scene.with_reflectance_scaled(factor);
                let rho = variant.mean_reflectance();
                for width in widths {
                    bar.set_message(format!("{technique}, {name}, {width} lanes"));
                    let no = lane_rate(&variant, lane_config(technique, width, false), &device, args.seconds)?;
                    bar.inc(1);
                    let pr = lane_rate(&variant, lane_config(technique, width, true), &device, args.seconds)?;
                    bar.inc(1);
                    rows.push(RegenerationRow {
                        technique: technique.to_string(),
                        variant: name.to_string(),
                        mean_reflectance: rho,
                        max_path_length: max_path_length(rho, PathConfig::default().admitted_truncation),
                        mean_path_length: no.segments,
                        truncated_fraction: pr.truncated,
                        packet_width: width,
                        no_regeneration_utilisation: no.utilisation,
                        no_regeneration_mrays: no.mrays,
                        regeneration_utilisation: pr.utilisation,
                        regeneration_mrays: pr.mrays,
                        speedup: pr.mrays / no.mrays,
                    });
                }
            }
        }
        bar.finish_and_clear();
        Ok(RaysReport {
            scene: args.target.scene.display().to_string(),
            width: scene.camera.width,
            height: scene.camera.height,
            threads,
            path_to_raw_ratio: path_mrays / raw[0].incoherent_closest_mrays,
            path_to_best_raw_ratio: path_mrays / raw.iter().map(|r| r.incoherent_closest_mrays).fold(0.0, f64::max),
            raw_at_path_mix_mrays: at_mix[0],
            best_raw_at_path_mix_mrays: at_mix.iter().copied().fold(0.0, f64::max),
            path_to_mix_ratio: path_mrays / at_mix[0],
            raw,
            path_mrays,
            path_samples_per_second: path_sps,
            regeneration: rows,
        })
    })
}

pub fn print_table(r: &RaysReport) {
    println!("relume bench rays: {} at {}x{}, {} threads", r.scene, r.width, r.height, r.threads);
    println!();
    println!("raw Embree throughput (Mrays/s)");
    println!("  accel    static  triangles  coherent primary (16-wide)  incoherent closest  incoherent occlusion");
    for row in &r.raw {
        println!(
            "  {:<8} {:<7} {:<10} {:>26.2} {:>19.2} {:>21.2}",
            row.accel,
            match row.layout.statics {
                StaticLayout::Flat => "flat",
                StaticLayout::Nested => "nested",
                StaticLayout::FlatWhenStill => "auto",
            },
            format!("{:?}", row.layout.intersector).to_lowercase(),
            row.coherent_primary_mrays,
            row.incoherent_closest_mrays,
            row.incoherent_occlusion_mrays
        );
    }
    println!();
    println!(
        "path (default configuration)          {:>8.2} Mrays/s, {:.0} paths/s",
        r.path_mrays, r.path_samples_per_second
    );
    println!("  achieved / default raw incoherent   {:>8.2}", r.path_to_raw_ratio);
    println!("  achieved / best raw incoherent      {:>8.2}", r.path_to_best_raw_ratio);
    println!(
        "  raw Embree at path's ray mix        {:>8.2} Mrays/s (best layout {:.2}); achieved / it {:.2}",
        r.raw_at_path_mix_mrays, r.best_raw_at_path_mix_mrays, r.path_to_mix_ratio
    );
    println!();
    println!("regeneration (PR) vs none (NO)");
    println!("  technique variant  rho_S  l_m  l_a  cut@l_m  lanes  NO util  NO Mrays/s  PR util  PR Mrays/s  speedup");
    for row in &r.regeneration {
        println!(
            "  {:<9} {:<7} {:>5.2} {:>4} {:>4.1} {:>8.4} {:>6} {:>8.2} {:>11.2} {:>8.2} {:>11.2} {:>8.2}",
            row.technique,
            row.variant,
            row.mean_reflectance,
            row.max_path_length,
            row.mean_path_length,
            row.truncated_fraction,
            row.packet_width,
            row.no_regeneration_utilisation,
            row.no_regeneration_mrays,
            row.regeneration_utilisation,
            row.regeneration_mrays,
            row.speedup
        );
    }
}

pub fn rays(args: RaysArgs) -> Result<()> {
    let report = measure(&args)?;
    print_table(&report);
    super::write_json_report(args.json.as_deref(), &report)
}
