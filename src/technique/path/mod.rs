//! `path`: the reference path tracer, with path regeneration. It is the ground truth for every
//! error figure in relume.
//!
//! Paper: J. Novák, V. Havran, C. Dachsbacher, "Path Regeneration for Interactive Path Tracing",
//! Eurographics 2010 Short Papers, pp. 61–64, 2010, doi:10.2312/egsh.20101048.
//!
//! # Algorithm
//! 1. Split the image into queues of consecutive pixels, one packet of `packet_width` lanes per
//!    queue. A queue holds W·max(1, round(T_r / l_a)) pixels, l_a = 1/(1 − ρ_S) the expected
//!    path length in steps, so that it keeps its packet busy for about T_r steps.
//! 2. Each of `spp` passes traces one jittered camera path per pixel.
//! 3. A queue's camera rays are traced first, 16 neighbouring pixels to a coherent packet
//!    (`packets.rs`; the image is bit-identical to tracing them in the lanes' packets).
//!    Each step traces one closest-hit packet and one shadow packet (`lanes.rs`): emission
//!    (MIS-weighted for area lights), next-event estimation to one light chosen by power, BSDF
//!    sampling, Russian roulette by throughput.
//! 4. Regeneration phase (§3.2): while the packet's queue lasts (about T_r steps), a lane whose
//!    path ended takes the next queued pixel's path at once. Then a closing phase of at most l_m + 1
//!    steps lets the remaining paths finish. With `regeneration: false` the lanes of a packet
//!    wait for the longest path before all refill together.
//! 5. Every path is forcibly ended after l_m = ⌈log_{ρ_S} c⌉ scattering vertices (§3.3), ρ_S the
//!    area-weighted mean reflectance and c = `admitted_truncation`.
//! 6. Paths add (radiance, count 1) to their pixel; the film accumulates across ticks until
//!    anything changes (progressive refinement, §4).
//!
//! Differs from the paper: (a) a lane regenerates the path of the next pixel in its queue, not
//! another path of its own pixel until T_r steps pass, which made the estimate length-biased
//! (+1.6% on the furnace; see `lanes.rs`); (b) new paths start with a new camera
//! ray rather than reusing the previous primary hit (§3.2 option), which keeps anti-aliasing and
//! costs at most 1/(2 l_a) of the rays.
//!
//! # Parameters (defaults)
//! | field | default | meaning |
//! |---|---|---|
//! | `spp` | 1 | paths per pixel per tick |
//! | `regeneration` | true | refill ended lanes during the regeneration phase |
//! | `regeneration_steps` | 100 | T_r, the regeneration phase in steps (the paper's value); sets the queue length |
//! | `packet_width` | native | lanes per packet: 1, 8 or 16; none: 16 with AVX-512 kernels, else 8 |
//! | `admitted_truncation` | 0.01 | c, the fraction of paths l_m may cut short |
//! | `max_path_length` | none | overrides l_m (1 = direct light only) |
//! | `preview_filter` | none | edge-preserving bilateral filter on the output (biased; previews) |
//!
//! # Bias and consistency
//! Unbiased except for the forced termination at l_m, which loses the energy carried beyond l_m
//! bounces: about a fraction c of it (set `admitted_truncation` lower for references).
//! Regeneration changes only the order paths are traced in, never which paths: the image is
//! identical with it on or off.
//!
//! # Light from outside
//! The sun and the environment are lights like the others for next-event estimation (the
//! environment sampled cosine-weighted about the surface, so an unoccluded diffuse point gets
//! its exact irradiance from one sample); a path that leaves the scene adds their radiance,
//! weighted against those samples by the power heuristic (camera rays and specular bounces
//! count it whole: the background is the environment). A delta sun is reached by NEE alone.
//!
//! # Failure modes
//! Caustics through glass or mirrors from small lights converge slowly (no light tracing; see
//! `bdpt`); point lights seen only via mirrors are never found; lights hidden behind small
//! openings are noisy.
mod lanes;
mod length;
pub(crate) mod packets;

pub use length::{max_path_length, MAX_PATH_LENGTH, MIN_PATH_LENGTH};

use super::registry::{Parameter, ParameterKind, TechniqueDescription, SPP};
use super::{RenderContext, RenderStats, Technique, TechniqueError, TechniqueStats, UpdateStats};
use crate::embree::Isa;
use crate::film::Film;
use crate::scene::edits::SceneDelta;
use crate::scene::Scene;
use lanes::{PathContext, PathLane};
use packets::LaneSettings;
use serde::{Deserialize, Serialize};

/// Configuration of the `path` technique. Unknown fields are rejected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PathConfig {
    pub spp: u32,
    pub regeneration: bool,
    pub regeneration_steps: u32,
    /// Lanes per packet; `None`: the widest packet Embree's kernels trace natively.
    pub packet_width: Option<u32>,
    pub admitted_truncation: f32,
    pub max_path_length: Option<u32>,
    pub preview_filter: Option<PreviewFilter>,
}

impl Default for PathConfig {
    fn default() -> PathConfig {
        PathConfig {
            spp: 1,
            regeneration: true,
            regeneration_steps: 100,
            packet_width: None,
            admitted_truncation: 0.01,
            max_path_length: None,
            preview_filter: None,
        }
    }
}

/// Bilateral filter settings for previews.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PreviewFilter {
    pub sigma_spatial_px: f32,
    pub sigma_range: f32,
}

impl Default for PreviewFilter {
    fn default() -> PreviewFilter {
        PreviewFilter { sigma_spatial_px: 1.5, sigma_range: 0.25 }
    }
}

/// Largest accepted `spp` per tick.
pub const MAX_SPP: u32 = 1 << 16;

/// What a `path` render did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PathStats {
    pub rays: super::RayCounts,
    /// Paths completed.
    pub paths: u64,
    /// Paths ended at l_m scattering vertices while still carrying light (the forced
    /// termination of §3.3); over `paths`, to set against `admitted_truncation` c.
    #[serde(default)]
    pub truncated_paths: u64,
    /// Lane slots offered (packets traced × lanes).
    pub lane_steps: u64,
    /// Lane slots that carried a live path.
    pub active_lane_steps: u64,
    /// l_m used.
    pub max_path_length: u32,
    /// Pixels in each packet's queue (from T_r and ρ_S).
    pub queue_pixels: u32,
    /// Lanes per packet: `packet_width`, or the width Embree's kernels trace natively.
    #[serde(default)]
    pub packet_width: u32,
    /// ρ_S used for l_m.
    pub mean_reflectance: f32,
    /// Nothing: a path tracer keeps no light transport between ticks.
    #[serde(default)]
    pub memory: super::ResidentMemory,
}

impl PathStats {
    /// Active lanes ÷ lanes over all packets traced.
    pub fn lane_utilisation(&self) -> f64 {
        if self.lane_steps == 0 {
            0.0
        } else {
            self.active_lane_steps as f64 / self.lane_steps as f64
        }
    }

    pub(crate) fn merge(mut self, o: PathStats) -> PathStats {
        self.rays = self.rays.merge(o.rays);
        self.paths += o.paths;
        self.truncated_paths += o.truncated_paths;
        self.lane_steps += o.lane_steps;
        self.active_lane_steps += o.active_lane_steps;
        self
    }
}

/// Pixels per packet queue: W·max(1, round(T_r / l_a)) with l_a = 1/(1 − ρ_S) the expected
/// path length in steps (Novák et al. §5), so the regeneration phase lasts about T_r steps.
pub fn queue_pixels(lanes: u32, regeneration_steps: u32, rho: f32) -> u32 {
    let expected_length = 1.0 / (1.0 - rho.clamp(0.0, 0.95));
    lanes * ((regeneration_steps as f32 / expected_length).round() as u32).max(1)
}

fn invalid(field: &str, message: &str) -> TechniqueError {
    TechniqueError::InvalidConfig { field: field.into(), message: message.into() }
}

impl PathConfig {
    pub fn validate(&self) -> Result<(), TechniqueError> {
        if self.spp == 0 || self.spp > MAX_SPP {
            return Err(invalid("spp", &format!("must lie in 1..={MAX_SPP}")));
        }
        if self.packet_width.is_some_and(|w| ![1, 8, 16].contains(&w)) {
            return Err(invalid(
                "packet_width",
                "must be 1, 8 or 16 (or null: the width Embree's kernels trace natively)",
            ));
        }
        if self.regeneration_steps == 0 || self.regeneration_steps > 4096 {
            return Err(invalid("regeneration_steps", "must lie in 1..=4096"));
        }
        if !(self.admitted_truncation > 0.0 && self.admitted_truncation < 1.0) {
            return Err(invalid("admitted_truncation", "must lie in (0, 1)"));
        }
        if let Some(l) = self.max_path_length {
            if l == 0 || l > MAX_PATH_LENGTH {
                return Err(invalid("max_path_length", &format!("must lie in 1..={MAX_PATH_LENGTH}")));
            }
        }
        if let Some(f) = self.preview_filter {
            if !(f.sigma_spatial_px > 0.0
                && f.sigma_spatial_px <= 16.0
                && f.sigma_range > 0.0
                && f.sigma_range.is_finite())
            {
                return Err(invalid("preview_filter", "sigmas must be positive (spatial at most 16 px)"));
            }
        }
        Ok(())
    }
}

/// The `path` technique.
pub struct PathTracer {
    config: PathConfig,
    /// Passes traced since the film was last reset; keys the sample streams.
    passes: u64,
}

impl PathTracer {
    pub fn new(config: PathConfig, _scene: &Scene) -> Result<PathTracer, TechniqueError> {
        config.validate()?;
        Ok(PathTracer { config, passes: 0 })
    }

    pub fn config(&self) -> &PathConfig {
        &self.config
    }
}

/// What a pass of eye-path lanes needs (shared by `path` and `bdpt`).
pub(crate) struct LanePlan {
    /// l_m and ρ_S.
    pub max_path_length: u32,
    pub mean_reflectance: f32,
    pub settings: LaneSettings,
    /// Pixels per packet queue.
    pub queue: u32,
}

impl PathConfig {
    /// The lane plan for `scene` under this configuration, with packets as wide as
    /// `packet_width` or else as `isa`'s kernels trace natively.
    pub(crate) fn lane_plan(&self, scene: &Scene, isa: Isa) -> LanePlan {
        let rho = scene.mean_reflectance();
        let lanes = self.packet_width.unwrap_or(isa.packet_lanes());
        LanePlan {
            max_path_length: self.max_path_length.unwrap_or_else(|| max_path_length(rho, self.admitted_truncation)),
            mean_reflectance: rho,
            settings: LaneSettings { lanes: lanes as usize, regeneration: self.regeneration },
            queue: queue_pixels(lanes, self.regeneration_steps, rho),
        }
    }
}

impl Technique for PathTracer {
    fn id(&self) -> &'static str {
        "path"
    }

    fn update(&mut self, _ctx: &RenderContext, delta: &SceneDelta) -> Result<UpdateStats, TechniqueError> {
        if !delta.is_empty() {
            self.passes = 0;
        }
        Ok(UpdateStats::default())
    }

    fn render(&mut self, ctx: &RenderContext, film: &mut Film, _: UpdateStats) -> Result<RenderStats, TechniqueError> {
        let LanePlan { max_path_length: l_m, mean_reflectance: rho, settings, queue } =
            self.config.lane_plan(ctx.scene, ctx.accel.scene().device().isa());
        let lane_context = PathContext { scene: ctx.scene, accel: ctx.accel, max_path_length: l_m };
        let mut total = film.accumulate_passes(
            self.config.spp,
            &mut self.passes,
            queue as usize,
            |pass, first, chunk| {
                packets::trace_chunk::<PathLane>(
                    ctx.scene,
                    ctx.accel.scene(),
                    &lane_context,
                    &settings,
                    (ctx.seed, ctx.tick, pass),
                    first,
                    chunk,
                )
            },
            PathStats::merge,
        );
        total.max_path_length = l_m;
        total.queue_pixels = queue;
        total.packet_width = settings.lanes as u32;
        total.mean_reflectance = rho;
        Ok(RenderStats { rays: total.rays, detail: TechniqueStats::Path(total) })
    }

    fn preview_filter(&self) -> Option<PreviewFilter> {
        self.config.preview_filter
    }
}

/// The registry's description (`technique/registry.rs`).
pub const DESCRIPTION: TechniqueDescription = TechniqueDescription {
    id: "path",
    summary: "Reference path tracer: next-event estimation with MIS, Russian roulette, packets with path regeneration",
    shorthand: None,
    parameters: &[
        SPP,
        Parameter {
            name: "regeneration",
            kind: ParameterKind::Boolean,
            help: "refill finished packet lanes with new paths",
        },
    ],
    test_specs: &["path:spp=4"],
};
