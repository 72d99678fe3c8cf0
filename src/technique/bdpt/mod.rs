//! `bdpt`: bidirectional path tracing with light-subpath permutation and path regeneration.
//!
//! Papers: E. Veach, "Robust Monte Carlo Methods for Light Transport Simulation" (1997), ch. 10;
//! J. Novák, V. Havran, C. Dachsbacher, "Path Regeneration for Interactive Path Tracing",
//! Eurographics 2010 Short Papers, pp. 61–64, 2010, doi:10.2312/egsh.20101048, §3.4.
//!
//! # Algorithm (per pass)
//! 1. Split the image into packet queues as `path` does (`path/packets.rs`), and trace a batch
//!    of `light_batch` light subpaths per queue (`vertex.rs`): a light by power, a point and
//!    direction by its emission distribution, BSDF sampling, Russian roulette, at most l_m
//!    surface vertices; lights absorb.
//! 2. Connect every non-specular light subpath vertex to the camera (t = 1, `splat.rs`) and
//!    splat it, weighted, onto the pixel it projects to; the film averages splats over passes.
//! 3. Trace eye subpaths W at a time with regeneration, exactly as `path`: a regeneration
//!    phase refills ended lanes from the queue, a closing phase of at most l_m + 1 steps ends.
//! 4. At every eye vertex t (`lane.rs`), evaluate the strategies ending there: (0, t) when it
//!    is on a light; (1, t), a light sample (next-event estimation); and (s, t) for s ≥ 2, a
//!    connection to each vertex of one light subpath of the batch. With `permute` (the
//!    paper's §3.4) that light subpath is picked at random at every bounce instead of being
//!    the eye path's own, which breaks the correlation between an eye path's connections.
//! 5. Each strategy is weighted by the power heuristic over all strategies that make the same
//!    path (`vertex.rs::mis_weight`), with the camera's density scaled by the light subpaths
//!    traced per eye sample (the sample counts of Veach §9.2.2); specular vertices are never
//!    connected, and a light seen directly is left to the eye path (no (1, 1)).
//!
//! # Why permutation keeps the estimate unbiased
//! The light subpaths of a batch are independent and identically distributed. For a fixed eye
//! vertex, the connection estimator's expectation over a light subpath drawn from that
//! distribution is the same whichever member of the batch is used, and choosing the member
//! uniformly at random (independently of the light subpaths' contents) is again a draw from it.
//! Reusing batch members across eye vertices and pixels correlates the estimates but does not
//! change any expectation (linearity). The MIS weights depend only on the vertices of the path
//! being weighted, not on which subpath supplied them, so they still sum to one.
//!
//! # Parameters (defaults)
//! | field | default | meaning |
//! |---|---|---|
//! | `spp` | 1 | eye paths per pixel per tick |
//! | `regeneration` | true | refill ended lanes during the regeneration phase |
//! | `regeneration_steps` | 100 | T_r; sets the queue length |
//! | `packet_width` | native | lanes per packet: 1, 8 or 16; none: 16 with AVX-512 kernels, else 8 |
//! | `admitted_truncation` | 0.01 | c of l_m = ⌈log_{ρ_S} c⌉ |
//! | `max_path_length` | none | overrides l_m (surface vertices of a full path) |
//! | `light_batch` | 32 | light subpaths traced per packet queue |
//! | `light_per_eye_path` | false | instead, one light subpath per eye path, its own unless permuting (Veach's and the paper's choice) |
//! | `permute` | true | pick a random light subpath at every eye bounce (§3.4) |
//! | `light_tracing_only` | false | light tracing alone: t = 1 only, unweighted, a light subpath per pixel |
//!
//! The shared batch correlates the pixels of a queue and gives light tracing few samples. On
//! the Cornell box (128², 1–4 spp, `relume bench error`) one light subpath per eye path lowers
//! relMSE from 0.0579 to 0.0445 at 1.5× the tick, on uplight from 0.159 to 0.130 at 1.4×: the
//! batch stays the default as the more efficient at equal time. Where light tracing carries
//! the image (a point light's caustic, `scenes/caustic-ball.json`) one per eye path is 5×
//! lower (0.81 against 4.17 at 1 spp).
//!
//! # Bias and consistency
//! Biased only by the truncation at l_m surface vertices, as `path`. The weights sum to 1
//! over the strategies used for every path, so caustics of point and spot lights seen through
//! a specular chain (light → glass → diffuse → camera), which only t = 1 can make, are
//! estimated without bias. `light_tracing_only` splats the light's own vertex too (an area light
//! seen directly) and is unbiased on its own, up to the same truncation.
//!
//! Russian roulette on light subpaths uses the product of BSDF weights since the light, so it
//! does not depend on the light's power or the scene's units (`vertex.rs::light_subpath`).
//!
//! # Light from outside
//! Light subpaths never start on the sun or the environment (a subpath that picks one is
//! empty): their light reaches the image through the eye subpath alone, by (1, t) next-event
//! samples and (0, t) escapes weighted against each other as in `path`. This stays unbiased,
//! but sunlight caustics (sun → glass → diffuse) are found only by (0, t) through a non-delta
//! sun, not by light tracing.
//!
//! # Failure modes
//! Caustics seen through a mirror or glass (light → specular → diffuse → specular → camera)
//! have no connectable strategy at a point light and stay missing, as in every unbiased
//! tracer without path-space regularisation. Splats land on pixels other than the queue's, so
//! a pass's splats are gathered and added after it (memory: one f64 RGB per pixel, on first
//! splat). A small `light_batch` correlates the noise between pixels; with the default batch
//! of 32 per queue, light tracing has few samples per pixel and the weights lean on eye paths.
mod lane;
mod splat;
mod vertex;

use super::path::packets::{trace_chunk, LaneSettings};
use super::path::{LanePlan, PathConfig, PathStats};
use super::registry::{Parameter, ParameterKind, TechniqueDescription, SPP};
use super::{RenderContext, RenderStats, Technique, TechniqueError, TechniqueStats, UpdateStats};
use crate::core::{Rgb, Rng};
use crate::film::{Film, PixelAccum};
use crate::scene::edits::SceneDelta;
use crate::scene::Scene;
use lane::{BdptContext, BdptLane};
use serde::{Deserialize, Serialize};
use vertex::CameraDensity;

/// Configuration of the `bdpt` technique. Unknown fields are rejected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BdptConfig {
    pub spp: u32,
    pub regeneration: bool,
    pub regeneration_steps: u32,
    /// Lanes per packet; `None`: the widest packet Embree's kernels trace natively.
    pub packet_width: Option<u32>,
    pub admitted_truncation: f32,
    pub max_path_length: Option<u32>,
    pub light_batch: u32,
    /// One light subpath per eye path (the paper's choice) instead of `light_batch` per queue.
    pub light_per_eye_path: bool,
    pub permute: bool,
    /// Light tracing alone: only the t = 1 strategies, unweighted, one light subpath per pixel.
    pub light_tracing_only: bool,
}

impl Default for BdptConfig {
    fn default() -> BdptConfig {
        let p = PathConfig::default();
        BdptConfig {
            spp: p.spp,
            regeneration: p.regeneration,
            regeneration_steps: p.regeneration_steps,
            packet_width: p.packet_width,
            admitted_truncation: p.admitted_truncation,
            max_path_length: p.max_path_length,
            light_batch: 32,
            light_per_eye_path: false,
            permute: true,
            light_tracing_only: false,
        }
    }
}

/// Largest accepted light batch.
pub const MAX_LIGHT_BATCH: u32 = 4096;

impl BdptConfig {
    /// The eye-path settings `bdpt` shares with `path`.
    fn eye_settings(&self) -> PathConfig {
        PathConfig {
            spp: self.spp,
            regeneration: self.regeneration,
            regeneration_steps: self.regeneration_steps,
            packet_width: self.packet_width,
            admitted_truncation: self.admitted_truncation,
            max_path_length: self.max_path_length,
            preview_filter: None,
        }
    }

    pub fn validate(&self) -> Result<(), TechniqueError> {
        self.eye_settings().validate()?;
        if self.light_batch == 0 || self.light_batch > MAX_LIGHT_BATCH {
            return Err(TechniqueError::InvalidConfig {
                field: "light_batch".into(),
                message: format!("must lie in 1..={MAX_LIGHT_BATCH}"),
            });
        }
        Ok(())
    }
}

/// What a `bdpt` render did: the eye-path lane figures (as `path` reports them) and the light
/// subpaths traced.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BdptStats {
    pub lanes: PathStats,
    pub light_subpaths: u64,
    pub light_subpath_rays: u64,
    /// Visibility rays from light subpath vertices to the camera (t = 1).
    #[serde(default)]
    pub camera_rays: u64,
    /// Of those, the ones that reached the camera and were splatted.
    #[serde(default)]
    pub camera_splats: u64,
    /// The film's splat buffer; light subpaths live for one pass.
    #[serde(default)]
    pub memory: super::ResidentMemory,
}

/// Separates light-subpath random streams from eye-path streams keyed by the same numbers.
const LIGHT_STREAM: u64 = 0x4c49_4748_5400; // "LIGHT"

/// The `bdpt` technique.
pub struct Bdpt {
    config: BdptConfig,
    /// Passes traced since the film was last reset; keys the sample streams.
    passes: u64,
}

impl Bdpt {
    pub fn new(config: BdptConfig, _scene: &Scene) -> Result<Bdpt, TechniqueError> {
        config.validate()?;
        Ok(Bdpt { config, passes: 0 })
    }
}

impl Technique for Bdpt {
    fn id(&self) -> &'static str {
        "bdpt"
    }

    fn update(&mut self, _ctx: &RenderContext, delta: &SceneDelta) -> Result<UpdateStats, TechniqueError> {
        if !delta.is_empty() {
            self.passes = 0;
        }
        Ok(UpdateStats::default())
    }

    fn render(&mut self, ctx: &RenderContext, film: &mut Film, _: UpdateStats) -> Result<RenderStats, TechniqueError> {
        let LanePlan { max_path_length: l_m, mean_reflectance: rho, settings, queue } =
            self.config.eye_settings().lane_plan(ctx.scene, ctx.accel.scene().device().isa());
        let pixels = film.width as usize * film.height as usize;
        let one_per_pixel = self.config.light_per_eye_path || self.config.light_tracing_only;
        let queues = pixels.div_ceil(queue as usize);
        let light_subpaths = if one_per_pixel { pixels } else { queues * self.config.light_batch as usize };
        let plan = PassPlan {
            ctx,
            config: &self.config,
            settings,
            l_m,
            camera: CameraDensity {
                camera: &ctx.scene.camera,
                light_per_eye_sample: light_subpaths as f32 / pixels.max(1) as f32,
            },
        };
        let mut total = BdptStats::default();
        for _ in 0..self.config.spp {
            let pass = film.accumulate_passes(
                1,
                &mut self.passes,
                queue as usize,
                |pass, first, chunk| plan.trace_queue(pass, first, chunk),
                PassOutput::merge,
            );
            film.add_splats(&pass.splats);
            total = total.merge(pass.stats);
        }
        total.lanes.max_path_length = l_m;
        total.lanes.queue_pixels = queue;
        total.lanes.packet_width = settings.lanes as u32;
        total.lanes.mean_reflectance = rho;
        total.memory.set("splats", film.splat_bytes());
        let mut rays = total.lanes.rays;
        rays.secondary += total.light_subpath_rays;
        rays.shadow += total.camera_rays;
        Ok(RenderStats { rays, detail: TechniqueStats::Bdpt(Box::new(total)) })
    }
}

/// What one pass needs to trace a queue.
struct PassPlan<'a> {
    ctx: &'a RenderContext<'a>,
    config: &'a BdptConfig,
    settings: LaneSettings,
    l_m: u32,
    camera: CameraDensity<'a>,
}

/// One pass's figures and its splats.
#[derive(Default)]
struct PassOutput {
    stats: BdptStats,
    splats: Vec<(u32, Rgb)>,
}

impl PassOutput {
    /// Queue order is kept, so every pixel sums its splats in the same order whatever the
    /// scheduling, and images repeat bit for bit.
    fn merge(mut self, o: PassOutput) -> PassOutput {
        self.splats.extend(o.splats);
        PassOutput { stats: self.stats.merge(o.stats), splats: self.splats }
    }
}

impl PassPlan<'_> {
    /// One queue of one pass: its light subpaths, their splats (t = 1), then its eye paths.
    fn trace_queue(&self, pass: u64, first: usize, chunk: &mut [PixelAccum]) -> PassOutput {
        let (ctx, config) = (self.ctx, self.config);
        let one_per_pixel = config.light_per_eye_path || config.light_tracing_only;
        let batch_size = if one_per_pixel { chunk.len() as u64 } else { config.light_batch as u64 };
        let mut light_rays = 0;
        let batch: Vec<_> = (0..batch_size)
            .map(|k| {
                // Each light subpath from its own stream.
                let stream = (first as u64) << 16 | k;
                let mut rng = Rng::for_sample(ctx.seed, ctx.tick, stream, pass ^ LIGHT_STREAM);
                let (path, rays) = vertex::light_subpath(ctx.scene, ctx.accel, self.l_m as usize, &mut rng);
                light_rays += rays;
                path
            })
            .collect();
        let weighted = !config.light_tracing_only;
        let splats = splat::splat_light_subpaths(ctx.scene, ctx.accel, &self.camera, &batch, weighted);
        let mut stats = BdptStats {
            light_subpaths: batch.len() as u64,
            light_subpath_rays: light_rays,
            camera_rays: splats.rays,
            camera_splats: splats.splats.len() as u64,
            ..Default::default()
        };
        if weighted {
            let lane_ctx = BdptContext {
                scene: ctx.scene,
                accel: ctx.accel,
                max_path_length: self.l_m,
                batch: &batch,
                permute: config.permute,
                own_from: config.light_per_eye_path.then_some(first),
                camera: self.camera,
            };
            stats.lanes = trace_chunk::<BdptLane>(
                ctx.scene,
                ctx.accel.scene(),
                &lane_ctx,
                &self.settings,
                (ctx.seed, ctx.tick, pass),
                first,
                chunk,
            );
        }
        PassOutput { stats, splats: splats.splats }
    }
}

impl BdptStats {
    fn merge(self, o: BdptStats) -> BdptStats {
        BdptStats {
            lanes: self.lanes.merge(o.lanes),
            light_subpaths: self.light_subpaths + o.light_subpaths,
            light_subpath_rays: self.light_subpath_rays + o.light_subpath_rays,
            camera_rays: self.camera_rays + o.camera_rays,
            camera_splats: self.camera_splats + o.camera_splats,
            memory: self.memory,
        }
    }
}

/// The registry's description (`technique/registry.rs`).
pub const DESCRIPTION: TechniqueDescription = TechniqueDescription {
    id: "bdpt",
    summary: "Bidirectional path tracing with power-heuristic MIS and light-subpath permutation",
    shorthand: None,
    parameters: &[
        SPP,
        Parameter {
            name: "permute",
            kind: ParameterKind::Boolean,
            help: "share light subpaths across pixels (Novák et al.)",
        },
    ],
    test_specs: &["bdpt:spp=2"],
};
