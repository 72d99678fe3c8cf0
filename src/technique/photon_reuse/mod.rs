//! `photon_reuse`: photon paths that stay resident across ticks; each tick verifies them against
//! what changed and retraces only the invalid segments.
//!
//! Paper: P. Moreau, M. Doggett, E. Sintorn, "Path Verification for Dynamic Indirect
//! Illumination" (`shared/papers/path-verification-dynamic-indirect-illumination.md`).
//!
//! # Algorithm (per tick)
//! 1. First tick: assign paths to lights in proportion to their power (stratified), and trace
//!    every path from its light (`trace.rs`): photons at every hit, up to B, ending by Russian
//!    roulette, on a light, or leaving the scene. Store them bounce-major (`store.rs`, §4).
//! 2. Later ticks, `reuse: "naive"` (§3.2): paths of a light that moved or changed are emitted
//!    anew. Every other path is tested segment by segment, from the light, against the old and new
//!    world bounds of every moved surface (through a small BVH over those boxes); the first segment that may be crossed, or that ends on
//!    a moved object, is re-intersected along its stored direction and everything after it is
//!    traced afresh (`verify.rs`). Photons on an object whose material changed keep their
//!    arrival flux; what they reflected is retraced. `reuse: "off"` is the baseline: every path
//!    is retraced whenever the scene changed.
//! 3. Rebuild the photon grid if any path changed, with the radius fixed at the first tick.
//! 4. Render (`gather.rs`): camera rays through specular chains to the first diffuse hit; direct
//!    light by next-event estimation, indirect light by a density estimate over photons from the
//!    second bounce on. The film accumulates while nothing changes.
//!
//! # Parameters (defaults)
//! | field | default | meaning |
//! |---|---|---|
//! | `paths` | 1 000 000 | N, resident photon paths |
//! | `max_photons` | 7 | B, photons per path (at most 15, the path word's limit) |
//! | `reuse` | `naive` | `off` (retrace all on change) or `naive` (verify, retrace from the first invalid segment) |
//! | `gather_photons` | 64 | k: the radius is chosen so a disc of it holds k photons on average: r = √(k·A / (π·M)), A the diffuse area, M the photons gathered |
//! | `radius` | none | overrides r (meters) |
//! | `spp` | 1 | camera samples per pixel per tick |
//!
//! # Bias and consistency
//! Direct light is unbiased. Indirect light is a photon density estimate: biased by the kernel
//! (blur of width r, light bleeding near corners), consistent as N → ∞ and r → 0. Russian
//! roulette and B truncate paths: B = 7 loses the energy beyond seven bounces. Reuse does not
//! add bias: a kept prefix is a valid sample, a re-intersected segment keeps a direction that
//! was sampled independently of what it hits, and every retraced tail is a fresh sample.
//!
//! # Failure modes
//! Small bright lights seen only indirectly give blotchy indirect light at low N; a moving light
//! retraces all its paths until distribution maps land (`error` mode and the distribution maps
//! of §3.1 are not built yet); large moving objects near the light invalidate most paths.
mod gather;
mod store;
mod trace;
mod verify;

pub use gather::PhotonGrid;
pub use store::{PathStore, PathWord, StoreMemory};
pub use verify::segment_hits_box;

use super::{RayCounts, RenderContext, RenderStats, Technique, TechniqueError, TechniqueStats};
use crate::film::Film;
use crate::scene::edits::SceneDelta;
use crate::scene::{Scene, SurfaceId};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;
use trace::{Retrace, TracedTail};
use verify::{BoxTree, Changes};

/// How paths are reused from tick to tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReuseMode {
    /// Baseline: retrace every path whenever the scene changed.
    Off,
    /// Retrace from the first segment a moved surface's bounds may cross (§3.2).
    Naive,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PhotonReuseConfig {
    pub paths: u32,
    pub max_photons: u32,
    pub reuse: ReuseMode,
    pub gather_photons: u32,
    pub radius: Option<f32>,
    pub spp: u32,
}

impl Default for PhotonReuseConfig {
    fn default() -> PhotonReuseConfig {
        PhotonReuseConfig {
            paths: 1_000_000,
            max_photons: 7,
            reuse: ReuseMode::Naive,
            gather_photons: 64,
            radius: None,
            spp: 1,
        }
    }
}

/// Largest accepted path count.
pub const MAX_PATHS: u32 = 16_000_000;

impl PhotonReuseConfig {
    pub fn validate(&self) -> Result<(), TechniqueError> {
        let bad = |field: &str, message: String| Err(TechniqueError::InvalidConfig { field: field.into(), message });
        if self.paths == 0 || self.paths > MAX_PATHS {
            return bad("paths", format!("must lie in 1..={MAX_PATHS}"));
        }
        if self.max_photons == 0 || self.max_photons > PathWord::MAX_PHOTONS {
            return bad("max_photons", format!("must lie in 1..={}", PathWord::MAX_PHOTONS));
        }
        if self.gather_photons == 0 {
            return bad("gather_photons", "must be at least 1".into());
        }
        if let Some(r) = self.radius {
            if !(r.is_finite() && r > 0.0) {
                return bad("radius", "must be a positive number of meters".into());
            }
        }
        if self.spp == 0 || self.spp > super::path::MAX_SPP {
            return bad("spp", format!("must lie in 1..={}", super::path::MAX_SPP));
        }
        Ok(())
    }
}

/// Per-tick figures of `photon_reuse`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhotonStats {
    pub paths: u64,
    pub untouched: u64,
    pub partly_retraced: u64,
    pub fully_retraced: u64,
    /// Rays traced for photon paths this tick (new and retraced segments).
    pub retrace_rays: u64,
    /// Segment-against-box tests made by verification.
    pub verify_box_tests: u64,
    pub camera_rays: u64,
    pub specular_rays: u64,
    pub shadow_rays: u64,
    pub verify_ms: f64,
    pub trace_ms: f64,
    pub grid_ms: f64,
    pub render_ms: f64,
    pub radius: f32,
    pub grid_photons: u64,
    pub memory: StoreMemory,
    pub grid_bytes: u64,
}

/// The `photon_reuse` technique.
pub struct PhotonReuse {
    config: PhotonReuseConfig,
    store: Option<PathStore>,
    paths_per_light: Vec<u32>,
    grid: PhotonGrid,
    passes: u64,
    pending: PhotonStats,
}

impl PhotonReuse {
    pub fn new(config: PhotonReuseConfig, _scene: &Scene) -> Result<PhotonReuse, TechniqueError> {
        config.validate()?;
        Ok(PhotonReuse {
            config,
            store: None,
            paths_per_light: Vec::new(),
            grid: PhotonGrid::default(),
            passes: 0,
            pending: PhotonStats::default(),
        })
    }

    /// First tick: assign paths to lights and trace them all.
    fn build(&mut self, ctx: &RenderContext) {
        let scene = ctx.scene;
        let n = self.config.paths as usize;
        let with_origins = scene.lights.iter().any(|l| l.mesh.is_some());
        let mut store = PathStore::new(n, self.config.max_photons as usize, with_origins);
        self.paths_per_light = vec![0; scene.lights.len()];
        if let Some(select) = &scene.light_selection {
            for i in 0..n {
                let (light, _, _) = select.sample((i as f32 + 0.5) / n as f32);
                store.light[i] = light as u16;
                self.paths_per_light[light] += 1;
            }
        }
        let all: Vec<(usize, Retrace)> =
            if scene.light_selection.is_some() { (0..n).map(|i| (i, Retrace::Emit)).collect() } else { Vec::new() };
        self.pending.fully_retraced = all.len() as u64;
        self.retrace(ctx, &mut store, &all);
        self.store = Some(store);
    }

    /// Traces the given retraces in parallel, in chunks that bound temporary memory.
    fn retrace(&mut self, ctx: &RenderContext, store: &mut PathStore, work: &[(usize, Retrace)]) {
        let t = Instant::now();
        for chunk in work.chunks(1 << 16) {
            let tails: Vec<TracedTail> = chunk
                .par_iter()
                .map(|&(path, how)| {
                    let light = store.light[path] as usize;
                    trace::trace(
                        ctx.scene,
                        ctx.accel,
                        store,
                        path,
                        how,
                        self.paths_per_light.get(light).copied().unwrap_or(1),
                        ctx.seed,
                    )
                })
                .collect();
            self.pending.retrace_rays += tails.iter().map(|t| t.rays).sum::<u64>();
            trace::write_back(store, tails);
        }
        self.pending.trace_ms += t.elapsed().as_secs_f64() * 1e3;
    }

    /// Which paths this tick's changes invalidate, and how to retrace them.
    fn invalid_paths(&mut self, scene: &Scene, store: &PathStore, delta: &SceneDelta) -> Vec<(usize, Retrace)> {
        let changed_light: Vec<bool> = (0..scene.lights.len()).map(|l| delta.lights.contains(&l)).collect();
        let transport_changed = !delta.moved.is_empty() || !delta.lights.is_empty() || !delta.materials.is_empty();
        if !transport_changed {
            return Vec::new();
        }
        if self.config.reuse == ReuseMode::Off {
            return (0..store.paths).map(|i| (i, Retrace::Emit)).collect();
        }
        let mut boxes = Vec::new();
        let mut moved = vec![false; scene.objects.len()];
        for m in &delta.moved {
            boxes.push(m.old_bounds);
            boxes.push(m.new_bounds);
            if let SurfaceId::Object(o) = m.surface {
                moved[o as usize] = true;
            }
        }
        let mut changes =
            Changes { boxes: BoxTree::new(boxes), moved, material_changed: vec![false; scene.objects.len()] };
        for (o, object) in scene.objects.iter().enumerate() {
            changes.material_changed[o] = delta.materials.contains(&(object.material as usize));
        }
        let checked: Vec<(Option<Retrace>, u64)> = (0..store.paths)
            .into_par_iter()
            .map(|i| {
                if changed_light[store.light[i] as usize] {
                    (Some(Retrace::Emit), 0)
                } else {
                    verify::check_path(scene, store, i, &changes)
                }
            })
            .collect();
        self.pending.verify_box_tests = checked.iter().map(|c| c.1).sum();
        checked.into_iter().enumerate().filter_map(|(i, (r, _))| r.map(|r| (i, r))).collect()
    }
}

impl Technique for PhotonReuse {
    fn id(&self) -> &'static str {
        "photon_reuse"
    }

    fn update(&mut self, ctx: &RenderContext, delta: &SceneDelta) -> Result<(), TechniqueError> {
        self.pending = PhotonStats::default();
        let mut rebuilt = false;
        match self.store.take() {
            None => {
                self.build(ctx);
                rebuilt = true;
            }
            Some(mut store) => {
                // Verify against what changed, then retrace what failed.
                let t = Instant::now();
                let work = self.invalid_paths(ctx.scene, &store, delta);
                self.pending.verify_ms = t.elapsed().as_secs_f64() * 1e3;
                self.pending.fully_retraced =
                    work.iter().filter(|(_, r)| *r == Retrace::Emit || *r == Retrace::KeepSegment(0)).count() as u64;
                self.pending.partly_retraced = work.len() as u64 - self.pending.fully_retraced;
                if !work.is_empty() {
                    self.retrace(ctx, &mut store, &work);
                    rebuilt = true;
                }
                self.store = Some(store);
            }
        }
        if let Some(store) = &self.store {
            if rebuilt {
                let t = Instant::now();
                let radius = if self.grid.radius > 0.0 { self.grid.radius } else { 1.0 };
                let first = PhotonGrid::build(ctx.scene, store, radius);
                let radius = match self.config.radius {
                    Some(r) => r,
                    None if self.grid.radius > 0.0 => self.grid.radius,
                    None => {
                        let area: f32 = ctx
                            .scene
                            .objects
                            .iter()
                            .filter(|o| !ctx.scene.materials[o.material as usize].is_specular())
                            .map(|o| o.area)
                            .sum();
                        (self.config.gather_photons as f32 * area / (std::f32::consts::PI * first.len().max(1) as f32))
                            .sqrt()
                    }
                };
                self.grid = if radius == first.radius { first } else { PhotonGrid::build(ctx.scene, store, radius) };
                self.pending.grid_ms = t.elapsed().as_secs_f64() * 1e3;
            }
            self.pending.paths = store.paths as u64;
            self.pending.untouched = self.pending.paths - self.pending.partly_retraced - self.pending.fully_retraced;
            self.pending.memory = store.memory();
        }
        if !delta.is_empty() {
            self.passes = 0;
        }
        Ok(())
    }

    fn render(&mut self, ctx: &RenderContext, film: &mut Film) -> Result<RenderStats, TechniqueError> {
        let t = Instant::now();
        let width = ctx.scene.camera.width as usize;
        let mut rays = gather::RenderRays::default();
        for _ in 0..self.config.spp {
            let pass = self.passes;
            let grid = &self.grid;
            rays = rays.merge(film.accumulate_chunks(
                width,
                |first, chunk| {
                    gather::render_chunk(ctx.scene, ctx.accel, grid, (ctx.seed, ctx.tick, pass), first, chunk)
                },
                gather::RenderRays::merge,
            ));
            self.passes += 1;
            film.passes += 1;
        }
        let mut stats = std::mem::take(&mut self.pending);
        stats.render_ms = t.elapsed().as_secs_f64() * 1e3;
        stats.camera_rays = rays.camera;
        stats.specular_rays = rays.specular;
        stats.shadow_rays = rays.shadow;
        stats.radius = self.grid.radius;
        stats.grid_photons = self.grid.len() as u64;
        stats.grid_bytes = self.grid.memory_bytes();
        let counts =
            RayCounts { primary: rays.camera, secondary: rays.specular + stats.retrace_rays, shadow: rays.shadow };
        Ok(RenderStats { rays: counts, detail: TechniqueStats::PhotonReuse(stats) })
    }
}
