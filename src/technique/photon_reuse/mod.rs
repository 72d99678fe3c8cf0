//! `photon_reuse`: photon paths that stay resident across ticks; each tick verifies them against
//! what changed and retraces only the invalid segments.
//!
//! Paper: P. Moreau, M. Doggett, E. Sintorn, "Path Verification for Dynamic Indirect
//! Illumination", arXiv:2111.06906 [cs.GR], 2021, doi:10.48550/arXiv.2111.06906.
//!
//! # Algorithm (per tick; Figure 3's five steps, then the photon map)
//! Steps 2–4 run in order in `update.rs`.
//! 1. First tick: assign paths to lights in proportion to their power (stratified), and trace
//!    every path from its light (`trace.rs`): photons at every hit, up to B, ending by Russian
//!    roulette, on a light, or leaving the scene. Store them bounce-major (`store.rs`, §4).
//! 2. **Update path origins + DM_C** for lights that moved (`lights.rs`, §3.1): a light's
//!    distribution map (`distribution.rs`) is made the first time it moves; kept paths get the
//!    new origin, their new primary segment is checked against the full scene with an occlusion
//!    ray, and invalid ones free their slot. A light whose intensity or colour alone changed
//!    scales its paths' fluxes by the exact factor (`lights::rescale`, no rays); any other
//!    emission change re-emits its paths; a light that owned no paths (dark when they were
//!    assigned) and now emits has every path assigned and emitted afresh.
//! 3. **Dynamic occlusions** (§3.2–3.3): a bounce-row screen (`verify.rs`) passes on only the
//!    paths with a segment near a moved box or ending on a moved or edited object; those are
//!    tested segment by segment from the light against the old and new world bounds of every
//!    moved surface (a small BVH over the boxes) and against edited materials. In both modes a
//!    segment in a box is then tested exactly against the moved surfaces where they are now (a
//!    small Embree scene; where they were needs no test, see `Changes::with_geometry`).
//!    `naive`: the first segment so crossed, or that ends on a moved object, is re-intersected
//!    and everything after it is traced afresh. `error` (`error.rs`, Algorithm 1): crossed
//!    segments are re-traced and the path is kept while the energy reflected at each new vertex
//!    stays within T of the stored.
//! 4. **Prune and fill** (`lights.rs`, eq. 1) for lights that moved or whose map has not yet
//!    settled, then trace fills and retraces in parallel.
//! 5. Update the photon grid in place for the paths whose photons changed (`grid.rs`: cost in
//!    proportion to their photons; rebuilt only on the first tick, in `off` mode, or when more
//!    than a quarter of the paths changed), with r₀ fixed at the first tick.
//! 6. Render. A full pass (`gather.rs`) takes one camera sample per pixel: camera rays through
//!    specular chains to the first diffuse hit; direct light by next-event estimation, indirect
//!    light by a density estimate over photons from the second bounce on; each pixel's sample
//!    is kept (`pixels.rs`). When only objects moved and the camera stood still, the render
//!    follows the change instead: it resamples the pixels a moved box may cross, forgets the
//!    direct light where a moved box may cast or lift a shadow, splats the photons the grid took
//!    out and put in into the kept photon sums, and restarts only those pixels. A camera move,
//!    a light or material edit, or a rebuilt grid renders in full.
//! 7. **Progressive refinement** on a still tick (nothing changed): a `refine` share of the
//!    paths (of lights that never moved) is emitted afresh and the radius shrinks,
//!    r_k² = r₀² Π_{i≤k} (i + α)/(i + 1) with α = 2/3, as in Knaus and Zwicker's probabilistic
//!    progressive photon mapping (2011); every pass is a full one and the film keeps
//!    accumulating. Any change restores r₀.
//!
//! `reuse: "off"` is the baseline: every path is emitted anew whenever the scene changed, and
//! no distribution map is kept.
//!
//! # Parameters (defaults)
//! | field | default | meaning |
//! |---|---|---|
//! | `paths` | 1 000 000 | N, resident photon paths |
//! | `max_photons` | 7 | B, photons per path (at most 15, the path word's limit) |
//! | `reuse` | `error` | `off`, `naive` or `error` |
//! | `threshold` | 0.001 | T of `error` mode (the paper's 0.1 %) |
//! | `distribution_map` | `{"position": [8, 8], "direction": [64, 64]}` | cells (u, v) on area lights × (θ, φ) |
//! | `gather_photons` | 64 | k: the radius is chosen so a disc of it holds k photons on average: r = √(k·A / (π·M)), A the diffuse area, M the photons gathered |
//! | `radius` | none | overrides r (meters) |
//! | `spp` | 1 | camera samples per pixel per tick |
//! | `refine` | 0.125 | share of the paths emitted afresh each still tick (0: off; at most 0.25) |
//!
//! # Bias and consistency
//! Direct light is unbiased. Indirect light is a photon density estimate: biased by the kernel
//! (blur of width r, light bleeding near corners), consistent as N → ∞ and r → 0. While the
//! scene is still, refinement makes the film's average consistent at fixed N: the kernel bias
//! of pass k falls as r_k² ∝ k^(α−1) = k^(−1/3), and the photon noise of the average as
//! k^(−α) (the passes' maps share all but a `refine` share of their paths, which scales the
//! variance by about 1/`refine`, not the rate), so the MSE falls as O(k^(−2/3)). Measured on
//! the Cornell box at the defaults (`relume bench error`, 1M paths, 256²): 64 still ticks bring
//! the relMSE to 1/16 of the first tick's (1/19 with `refine` 0.25; α = 0.5 and 0.8 do no
//! better): the fresh paths per still tick, not the radius schedule, set the pace. Russian
//! roulette and B truncate paths: B = 7 loses the energy beyond seven bounces. `naive` reuse
//! adds no bias: a kept prefix is a valid sample, a re-intersected segment keeps a direction
//! sampled independently of what it hits, and every retraced tail is a fresh sample. `error`
//! reuse keeps energies that are off by up to T per kept vertex (the paper's trade). Every path
//! carries 1/N_light of its light's power, which is exact only while DM_C = DM_T: after a light
//! moves, the cells pruned or filled over the next ticks are briefly over- or under-weighted.
//!
//! # Light from outside
//! Photons from the sun and the environment start on a disc of the scene's bounding sphere's
//! radius facing their direction, outside the sphere, and are stored and verified as any
//! other path (with their origins). Direct light from them is next-event estimation. They have
//! no distribution map yet: an edit that only scales their emission rescales their paths, and
//! any other (a sun turn of any angle, even 1°) re-emits every path of that light, so a turning
//! sun costs what a rebuild of its share of the paths costs. A moved object in sunlight stays a
//! local change.
//!
//! # Failure modes
//! Small bright lights seen only indirectly give blotchy indirect light at low N; large moving
//! objects near the light invalidate most paths; an area-light cell whose sliver of the shape
//! is tiny may fall back to sampling the whole light; a light that moves every tick never lets
//! its map settle (the prune and fill then run every tick, as in the paper).
mod cells;
mod config;
pub use config::DESCRIPTION;
mod distribution;
mod error;
mod gather;
mod grid;
mod grid_upkeep;
mod lights;
mod near;
mod pixels;
mod stats;
mod store;
#[cfg(test)]
mod test_scenes;
mod trace;
mod update;
mod verify;

pub use config::{PhotonReuseConfig, ReuseMode, MAX_PATHS};
pub use distribution::{DistributionMap, MapResolution, MAX_CELLS};
pub use grid::{ChangedPhotons, GridUpdate, PhotonGrid};
pub use stats::PhotonStats;
pub use store::{PathStore, PathWord, StoreMemory};

use super::box_tree::BOX_SLACK;
use super::{RayCounts, RenderContext, RenderStats, Technique, TechniqueError, TechniqueStats, UpdateStats};
use crate::film::Film;
use crate::scene::edits::{self, Aabb, SceneDelta};
use crate::scene::Scene;
use distribution::EmissionFrame;
use lights::MappedLight;
use pixels::{Moves, PixelCache};
use rayon::prelude::*;
use std::time::Instant;
use store::SurfaceIds;
use trace::{Retrace, TracedTail, Tracer};

/// How this tick's render goes, as `update` found it: handed to `render` and spent there.
#[derive(Debug, Default)]
enum Plan {
    /// A full pass over every pixel (the first tick, a still tick, or a change the kept
    /// pixels cannot follow).
    #[default]
    Full,
    /// Only objects moved (or only photons changed) while the camera stood still: the kept
    /// pixels follow what the grid took out and put in (`pixels.rs`).
    Follow { changed: ChangedPhotons, boxes: Vec<Aabb>, moved: Vec<bool> },
}

/// One `update` call's record: the paths it changed (for the grid) and its figures. It lives
/// for that call and its figures go on to `render`; none of it stays in the technique.
#[derive(Default)]
struct TickWork {
    touched: Vec<usize>,
    stats: PhotonStats,
}

/// The `photon_reuse` technique.
pub struct PhotonReuse {
    config: PhotonReuseConfig,
    /// Surface ids of the scene's triangles (their meshes never change in a session).
    surfaces: SurfaceIds,
    store: Option<PathStore>,
    paths_per_light: Vec<u32>,
    /// Retrace passes so far: the key of each pass's random streams.
    retrace_passes: u64,
    /// Distribution maps of lights that have moved at least once.
    maps: Vec<Option<MappedLight>>,
    grid: PhotonGrid,
    /// r₀: the gather radius chosen at the first tick (the grid's cells are r₀ wide).
    base_radius: f32,
    /// Still ticks refined since the last change (k of the radius schedule), r_k / r₀, and
    /// where the next refinement's slice of paths starts.
    refined: u32,
    shrink: f32,
    refine_cursor: usize,
    pixels: PixelCache,
    plan: Plan,
    passes: u64,
}

/// α of the radius schedule: each still tick keeps this share of the photon density's growth
/// (Knaus and Zwicker's recommended 2/3, which balances bias and variance).
const REFINE_ALPHA: f32 = 2.0 / 3.0;

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

impl PhotonReuse {
    pub fn new(config: PhotonReuseConfig, scene: &Scene) -> Result<PhotonReuse, TechniqueError> {
        config.validate()?;
        let surfaces = SurfaceIds::of(scene).ok_or_else(|| TechniqueError::TooLarge {
            field: "objects".into(),
            message: "the objects' triangles do not fit photon_reuse's 32-bit surface ids".into(),
        })?;
        Ok(PhotonReuse {
            config,
            surfaces,
            store: None,
            paths_per_light: Vec::new(),
            retrace_passes: 0,
            maps: Vec::new(),
            grid: PhotonGrid::default(),
            base_radius: 0.0,
            refined: 0,
            shrink: 1.0,
            refine_cursor: 0,
            pixels: PixelCache::default(),
            plan: Plan::Full,
            passes: 0,
        })
    }

    /// First tick: assign paths to lights and trace them all.
    fn build(&mut self, ctx: &RenderContext, tick: &mut TickWork) -> PathStore {
        let scene = ctx.scene;
        let n = self.config.paths as usize;
        let with_origins = store::keeps_origins(scene);
        let mut store = PathStore::new(n, self.config.max_photons as usize, with_origins, self.surfaces.clone());
        self.paths_per_light = vec![0; scene.lights.len()];
        self.maps = (0..scene.lights.len()).map(|_| None).collect();
        if let Some(select) = &scene.light_selection {
            for i in 0..n {
                let (light, _, _) = select.sample((i as f32 + 0.5) / n as f32);
                self.paths_per_light[light] += 1;
            }
        }
        store.assign(&self.paths_per_light);
        // A fresh store restarts the passes, so a rebuilt store draws what a first one would.
        self.retrace_passes = 0;
        let all: Vec<(usize, Retrace)> =
            if scene.light_selection.is_some() { (0..n).map(|i| (i, Retrace::Emit)).collect() } else { Vec::new() };
        self.retrace(ctx, &mut store, &all, tick);
        store
    }

    /// A light that owns no paths (it was dark when they were assigned) emits now: only a
    /// new assignment gives it its share.
    fn dark_light_lit(&self, scene: &Scene, delta: &SceneDelta) -> bool {
        delta.lights.iter().any(|c| {
            c.emission_changed
                && self.paths_per_light.get(c.light).is_some_and(|&n| n == 0)
                && scene.lights[c.light].geometry.power().max_component() > 0.0
        })
    }

    /// Traces the given retraces in parallel, in chunks that bound temporary memory; fills and
    /// the rest are timed and counted apart.
    fn retrace(&mut self, ctx: &RenderContext, store: &mut PathStore, work: &[(usize, Retrace)], tick: &mut TickWork) {
        tick.touched.extend(work.iter().map(|&(path, _)| path));
        self.retrace_passes += 1;
        // Mark first (§4's replace flag and segment), so what is pending is visible in the word.
        for &(path, how) in work {
            store.word[path] = store.word[path].retrace(how.first_segment());
        }
        let frames: Vec<Option<&EmissionFrame>> = self.maps.iter().map(|m| m.as_ref().map(|m| &m.frame)).collect();
        let tracer = Tracer {
            scene: ctx.scene,
            accel: ctx.accel,
            seed: ctx.seed,
            paths_per_light: &self.paths_per_light,
            frames: &frames,
            epoch: self.retrace_passes,
        };
        let (fills, others): (Vec<_>, Vec<_>) = work.iter().partition(|(_, r)| matches!(r, Retrace::Fill(_)));
        for (list, is_fill) in [(others, false), (fills, true)] {
            let t = Instant::now();
            let mut rays = 0;
            for chunk in list.chunks(1 << 16) {
                let tails: Vec<TracedTail> =
                    chunk.par_iter().map(|&(path, how)| tracer.trace(store, path, how)).collect();
                rays += tails.iter().map(|t| t.rays).sum::<u64>();
                trace::write_back(store, tails);
            }
            let stats = &mut tick.stats;
            if is_fill {
                stats.fill_rays += rays;
                stats.fill_ms += ms(t);
            } else {
                stats.retrace_rays += rays;
                stats.trace_ms += ms(t);
            }
        }
        let fully = work
            .iter()
            .filter(|(_, r)| matches!(r, Retrace::Emit | Retrace::Fill(_) | Retrace::KeepSegment(0)))
            .count() as u64;
        tick.stats.fully_retraced += fully;
        tick.stats.partly_retraced += work.len() as u64 - fully;
    }
}

impl Technique for PhotonReuse {
    fn id(&self) -> &'static str {
        "photon_reuse"
    }

    fn update(&mut self, ctx: &RenderContext, delta: &SceneDelta) -> Result<UpdateStats, TechniqueError> {
        let mut tick = TickWork::default();
        let lit = self.store.is_some() && self.dark_light_lit(ctx.scene, delta);
        if lit {
            self.store = None;
            tick.stats.reassigned = true;
        }
        match self.store.take() {
            None => {
                let store = self.build(ctx, &mut tick);
                self.rebuild_grid(ctx.scene, &store, &mut tick.stats);
                self.plan = Plan::Full;
                self.store = Some(store);
            }
            Some(mut store) => {
                let changed = match self.update_paths(ctx, &mut store, delta, &mut tick) {
                    true => self.refresh_grid(ctx.scene, &store, std::mem::take(&mut tick.touched), &mut tick.stats),
                    false => Some(ChangedPhotons::default()),
                };
                self.plan = self.plan(ctx.scene, delta, changed);
                self.store = Some(store);
            }
        }
        if !delta.is_empty() {
            self.passes = 0;
        }
        let mut stats = tick.stats;
        let Some(store) = self.store.as_ref() else { return Ok(UpdateStats::new(stats)) };
        let p = &mut stats;
        p.paths = store.paths as u64;
        p.untouched = p.paths.saturating_sub(p.partly_retraced + p.fully_retraced);
        p.store = store.memory();
        p.store.distribution_maps = self.maps.iter().flatten().map(|m| m.map.memory_bytes()).sum();
        if let Some((chi2, cells)) = self
            .maps
            .iter()
            .flatten()
            .map(|m| (m.map.chi2(), m.map.target.len() as u64))
            .max_by(|a, b| a.0.total_cmp(&b.0))
        {
            p.distribution_chi2 = chi2;
            p.distribution_cells = cells;
        }
        Ok(UpdateStats::new(stats))
    }

    fn restarts_whole_film(&self, delta: &SceneDelta) -> bool {
        !delta.is_empty() && matches!(self.plan, Plan::Full)
    }

    fn render(
        &mut self,
        ctx: &RenderContext,
        film: &mut Film,
        update: UpdateStats,
    ) -> Result<RenderStats, TechniqueError> {
        let t = Instant::now();
        let mut stats: PhotonStats = update.take();
        let rays = match std::mem::take(&mut self.plan) {
            Plan::Full => {
                let mut rays = gather::RenderRays::default();
                for _ in 0..self.config.spp {
                    let stream = (ctx.seed, ctx.tick, self.passes);
                    rays = rays.merge(self.pixels.full_pass(ctx.scene, ctx.accel, &self.grid, stream, film));
                    self.passes += 1;
                }
                rays
            }
            Plan::Follow { changed, boxes, moved } => {
                let scene = ctx.scene;
                let lights: Vec<Aabb> = (0..scene.lights.len()).map(|l| edits::light_bounds(scene, l)).collect();
                let diagonal = ctx.accel.scene().bounds().map_or(1.0, |(lo, hi)| (hi - lo).length());
                let slack = BOX_SLACK * diagonal;
                let moves = Moves { boxes: &boxes, moved: &moved, lights: &lights, slack };
                let (counts, rays) =
                    self.pixels.follow(scene, ctx.accel, &self.grid, &changed, &moves, (ctx.seed, ctx.tick), film);
                stats.pixels = counts;
                stats.followed = true;
                rays
            }
        };
        stats.render_ms = t.elapsed().as_secs_f64() * 1e3;

        stats.camera_rays = rays.camera;
        stats.specular_rays = rays.specular;
        stats.shadow_rays = rays.shadow;
        stats.radius = self.grid.radius;
        stats.grid_photons = self.grid.len() as u64;
        stats.grid_power = self.grid.power;
        stats.memory = stats.store.resident();
        stats.memory.set("grid", self.grid.memory_bytes());
        stats.memory.set("pixels", self.pixels.memory_bytes());
        // Photon rays count by query: closest-hit (verification, retraces, fills) as secondary,
        // occlusion (primary-segment checks of moved lights, crossing tests) as shadow rays.
        let counts = RayCounts {
            primary: rays.camera,
            secondary: rays.specular + stats.verify_rays + stats.retrace_rays + stats.fill_rays,
            shadow: rays.shadow + stats.origin_rays + stats.crossing_rays,
        };
        Ok(RenderStats { rays: counts, detail: TechniqueStats::PhotonReuse(Box::new(stats)) })
    }
}
