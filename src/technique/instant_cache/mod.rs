//! `instant_cache`: virtual point lights gathered through an irradiance cache.
//!
//! Paper: K. Debattista, P. Dubla, F. Banterle, L. P. Santos, A. Chalmers, "Instant Caching for
//! Interactive Global Illumination", Computer Graphics Forum 28(8):2216–2228, 2009,
//! doi:10.1111/j.1467-8659.2009.01435.x; the `igi` baseline is Wald et al.'s instant global
//! illumination.
//!
//! # Algorithm (per tick)
//! 1. Shoot VPLs (`vpl.rs`, §3.1): Halton-sequenced photon paths at fixed indices, a VPL at
//!    every diffuse hit; paths end by Russian roulette only, so no light is cut off with
//!    their length (before, a 10-bounce cap lost ρ_S¹⁰ of it: 11% at ρ_S = 0.8); unchanged
//!    scenes give the same VPLs.
//! 2. Per camera sample (`technique/camera_chain.rs`, `cameras.rs`): follow mirrors and glass
//!    to the first diffuse hit; direct light by next-event estimation with a shadow ray.
//!    `temporal` keeps last tick's camera sample where no edit can have changed it (no camera,
//!    material or emitter edit, and no moved object or light shape on or at the end of its ray)
//!    and traces the rest; a kept sample keeps its direct light too while no light changed and
//!    no moved surface lies, or lay, on its shadow ray (resident passes draw from a stream of
//!    the pixel and the pass since the change, so a fresh sample would draw the same). Runs of
//!    32 pixels whose hits and shadow rays no moved box can reach are kept without being read.
//! 3. Indirect diffuse light, by mode:
//!    - `igi` (`igi.rs`): each pixel gathers its n×n-interleaved subset of the VPLs with
//!      visibility rays, then a discontinuity buffer averages the n×n neighbourhood.
//!    - `static` (`cache.rs`, `grid.rs`, `pixels.rs`): an irradiance cache cleared every
//!      tick. In pixel order, a record is made wherever no record has weight w_k(x) > 1 (eq. 5,
//!      with the distance and normal tolerances apart: `cache.rs`); records are computed in
//!      parallel, each with one visibility ray per VPL and G′ (eqs. 2–3), and every pixel
//!      interpolates them (eq. 4). Deciding where records go in pixel order keeps the image
//!      independent of the thread count.
//!    - `temporal` (`temporal.rs`, §3.2, Algorithm 1): the same cache kept across ticks. At
//!      the start of a tick, records unused for `max_age` ticks go; if VPLs changed or
//!      surfaces moved, records on a moved object go (case 5) and the rest
//!      are re-evaluated, ray by ray, for cases 1–4, either at once (`immediate`) or when a
//!      pixel first interpolates them (`on_demand`). New areas get records on demand as in
//!      `static`. The result is exact: every record equals a fresh computation. Camera
//!      samples use the same sub-pixel points every tick (the k-th of a tick's `spp`), so a
//!      still view makes no records after its first tick (its direct light is drawn anew). Each
//!      sample keeps its records and weights (`pixels.rs`): it looks the cache up again only
//!      if its hit changed or one of its records went, and adds this tick's new records that
//!      reach it; otherwise it only re-sums, and on a still tick (no scene change at all) it
//!      keeps last tick's irradiance. VPLs are shot again only when geometry, a light or a
//!      material changed.
//! 4. Radiance = emission seen along the chain + direct + ρ/π · indirect irradiance.
//! 5. Refinement (every mode): a still tick (nothing changed) renders the next VPL generation
//!    g = 1, 2, ... into the accumulated image, as `static` would, with new sub-pixel points:
//!    generation g shoots Halton points g·P + 1..=(g + 1)·P, so G generations together are one
//!    set of G·P paths, G times larger. They use a VPL set, cache and samples of their own,
//!    swapped in for the tick, so the resident generation 0 stays as it was and the next change
//!    finds it (its records stay marked used). After `refine_ticks` generations the view rests:
//!    a still tick traces nothing and adds no pass.
//!
//! # Parameters (defaults)
//! | field | default | meaning |
//! |---|---|---|
//! | `mode` | `temporal` | `igi`, `static` or `temporal` |
//! | `vpls` | 256 | VPLs per tick, on average (⌈vpls·(1 − ρ_S)⌉ paths are shot; at most 4× are kept) |
//! | `interleave` | 4 | n of `igi`'s n×n interleaved sampling |
//! | `caching_radius` | 0.05 | a, in units of the scene's bounding diagonal |
//! | `normal_tolerance` | 40 | θ, degrees a normal may turn before a record stops serving it (the paper's eq. 5 ties it to a: acos(1 − a²), 4.05°) |
//! | `clamp_distance` | 0.01 | min_d of G′'s clamp, in units of the scene's bounding diagonal |
//! | `max_bounces` | none | bounces a VPL path may take; none: until Russian roulette ends it |
//! | `spp` | 1 | camera samples per pixel per tick |
//! | `reevaluation` | `immediate` | `temporal`: re-evaluate invalidated records at the start of the tick, or `on_demand` when first interpolated |
//! | `max_age` | 16 | `temporal`: records unused this many ticks are dropped |
//! | `refine_ticks` | 64 | still ticks that render a new VPL generation (0: a still tick renders generation 0 again) |
//! | `audit` | false | recompute every record after each pass and count those that differ |
//!
//! # Bias and consistency
//! Biased, like every VPL method: G′'s clamp drops light from VPLs closer than 0.8·min_d (dark
//! corners), interpolation blurs irradiance across a record's radius, RGBE rounds each VPL's
//! contribution to about 1%, and 256 VPLs give low-frequency error (splotches) rather than
//! noise. It converges as VPLs → ∞, a → 0 and min_d → 0 (a ρ = 0.8 furnace: −2.7% at 2048
//! VPLs, −0.4% at 32 768, −0.1% at 65 536). No light is cut off with path length: paths end by
//! roulette (`max_bounces` caps them only when asked, and then drops about ρ_S^n of the
//! indirect light). The VPL cap (4 × `vpls`) is a memory guard: when reached, the light is
//! divided among the paths shot (stats `vpl_cap_reached`, `vpl_paths`), never among paths
//! not shot. Only diffuse reflection is cached.
//! Refinement shrinks the VPL error like a VPL set G times larger, and the interpolation
//! error as record positions move with the sub-pixel points; the clamp's bias stays (a still
//! Cornell box at 256²: relMSE 0.018 after one tick, 0.00090 after 64 refinements, against
//! 0.0097 without them; the image mean, −4.9% in its worst channel after one tick, the spread
//! of one set of 118 light paths, is −0.75% after them; `docs/benchmarks.md`, stop 65).
//! `temporal` adds no bias of its own (its records are exact), but its records sit where
//! earlier ticks' pixels put them, so its image differs from `static`'s by where the
//! interpolation error falls, not by how large it is.
//!
//! # Light from outside
//! VPL paths from the sun and the environment start on a disc of the scene's bounding
//! sphere's radius facing their direction; direct light from them is next-event estimation
//! (the environment sampled cosine-weighted about the surface), not VPLs.
//!
//! # Failure modes
//! Small bright VPLs near a surface still show as spots above the clamp distance; glossy
//! transport is not handled; a caching radius too large for fine geometry blurs contact
//! shadows of indirect light. `temporal` degrades to `static`'s cost when many surfaces move
//! (every VPL changes) and a moving light invalidates every VPL it shot. A refining tick costs
//! a `static` tick, and its cache and samples double the cache's memory while the view is
//! still.
mod cache;
mod cameras;
mod config;
pub use config::DESCRIPTION;
mod grid;
mod igi;
mod pixels;
mod rgbe;
mod temporal;
mod vpl;

pub use cameras::RUN as CAMERA_RUN;
pub use config::{
    CacheMode, InstantCacheConfig, InstantCacheStats, Reevaluation, DEFAULT_NORMAL_TOLERANCE, DEFAULT_REFINE_TICKS,
    MAX_VPLS,
};

use super::camera_chain::DiffuseHit;
use super::{RayCounts, RenderContext, RenderStats, Technique, TechniqueError, TechniqueStats, UpdateStats};
use crate::core::Rgb;
use crate::film::Film;
use crate::scene::edits::SceneDelta;
use crate::scene::Scene;
use cache::Cache;
use cameras::{CameraChange, Reuse, Samples, Shaded};
use glam::Vec3;
use pixels::{PassStates, SampleState};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;
use temporal::{Moved, Refresh, TickChanges};
use vpl::Vpl;

/// The scene's extent, fixed at the first tick so that record weights and the clamp distance
/// keep their meaning while objects move.
#[derive(Clone, Copy, Debug)]
struct Extent {
    lo: Vec3,
    hi: Vec3,
    diagonal: f32,
}

/// The `instant_cache` technique.
pub struct InstantCache {
    config: InstantCacheConfig,
    vpls: Vec<Vpl>,
    extent: Option<Extent>,
    cache: Option<Cache>,
    /// On-demand re-evaluation: this tick's changes, for records flagged stale.
    changes: Option<TickChanges>,
    passes: u64,
    /// The photon paths the VPLs come from; `None` until they are first shot.
    vpl_paths: Option<u64>,
    /// `temporal`: nothing this tick can change a cached irradiance (no scene change, so the
    /// same VPLs and records), so a sample that keeps its records keeps its result.
    still: bool,
    /// Each pass's samples and their interpolation (`pixels.rs`), from the last tick (`static`
    /// keeps only their allocations).
    samples: Vec<PassStates>,
    /// What this tick renders: the resident generation, a refinement, or nothing.
    kind: TickKind,
    /// `temporal`: each pass's camera samples from the last resident tick, and what may have
    /// changed them since (`cameras.rs`).
    cameras: Vec<Samples>,
    /// The stream each of `cameras` drew from: its pass counted from the change before it.
    camera_streams: Vec<u64>,
    camera_change: CameraChange,
    /// Refinement generations rendered since the last change.
    generation: u32,
    /// The refinement generation's VPLs, and in `temporal` its cache and samples: swapped with
    /// the resident ones while a refinement tick renders, so those stay as they were.
    refinement: Layer,
}

/// What a tick renders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TickKind {
    /// Generation 0, which follows every change: every tick but those below.
    Resident,
    /// A still tick (nothing changed) refining the view with the next VPL generation.
    Refine,
    /// A still tick after `refine_ticks` refinements: nothing is added.
    Idle,
}

/// One generation's VPLs, cache and per-sample state.
#[derive(Default)]
struct Layer {
    vpls: Vec<Vpl>,
    cache: Option<Cache>,
    samples: Vec<PassStates>,
}

impl InstantCache {
    pub fn new(config: InstantCacheConfig, _scene: &Scene) -> Result<InstantCache, TechniqueError> {
        config.validate()?;
        Ok(InstantCache {
            config,
            vpls: Vec::new(),
            extent: None,
            cache: None,
            changes: None,
            passes: 0,
            vpl_paths: None,
            still: false,
            samples: Vec::new(),
            kind: TickKind::Resident,
            cameras: Vec::new(),
            camera_streams: Vec::new(),
            camera_change: CameraChange::All,
            generation: 0,
            refinement: Layer::default(),
        })
    }

    fn extent(&mut self, ctx: &RenderContext) -> Extent {
        *self.extent.get_or_insert_with(|| {
            let (lo, hi) = ctx.accel.scene().bounds().unwrap_or((Vec3::ZERO, Vec3::ONE));
            Extent { lo, hi, diagonal: (hi - lo).length().max(f32::MIN_POSITIVE) }
        })
    }

    fn min_distance(&mut self, ctx: &RenderContext) -> f32 {
        self.config.clamp_distance * self.extent(ctx).diagonal
    }

    /// Shoots VPL generation `generation` (`vpl.rs`; 0 is the resident one) and returns it.
    fn shoot(&mut self, ctx: &RenderContext, generation: u32, stats: &mut InstantCacheStats) -> Vec<Vpl> {
        let rho = ctx.scene.mean_reflectance();
        // About `vpls` VPLs: a path leaves 1/(1 − ρ_S) on average; at most 4× that are kept.
        let paths = ((self.config.vpls as f32 * (1.0 - rho.clamp(0.0, 0.95))).ceil() as u64).max(1);
        let max_bounces = self.config.max_bounces.unwrap_or(vpl::MAX_VPL_BOUNCES);
        let first = u64::from(generation) * paths;
        let shot = vpl::shoot(ctx.scene, ctx.accel, first, paths, 4 * self.config.vpls as usize, max_bounces);
        if generation == 0 {
            self.vpl_paths = Some(shot.paths);
        }
        stats.vpl_paths = shot.paths;
        stats.vpl_cap_reached = shot.capped;
        stats.vpl_rays = shot.rays;
        shot.vpls
    }

    /// What this tick renders (`TickKind`), given its delta.
    fn tick_kind(&self, delta: &SceneDelta) -> TickKind {
        if !delta.is_empty() || self.passes == 0 || self.config.refine_ticks == 0 {
            TickKind::Resident
        } else if self.generation < self.config.refine_ticks {
            TickKind::Refine
        } else {
            TickKind::Idle
        }
    }

    /// The mode this tick renders in: a refinement generation is rendered as `static` would.
    fn mode(&self) -> CacheMode {
        match (self.config.mode, self.kind) {
            (CacheMode::Temporal, TickKind::Refine) => CacheMode::Static,
            (mode, _) => mode,
        }
    }

    /// Swaps the refinement generation's VPLs (and in `temporal` its cache and samples) with
    /// the resident ones; `static` and `igi` rebuild their cache every tick, so they share it.
    fn swap_layers(&mut self) {
        std::mem::swap(&mut self.vpls, &mut self.refinement.vpls);
        if self.config.mode == CacheMode::Temporal {
            std::mem::swap(&mut self.cache, &mut self.refinement.cache);
            std::mem::swap(&mut self.samples, &mut self.refinement.samples);
        }
    }

    /// `temporal`, at the start of a tick: ages the cache and applies what changed since the
    /// VPLs `old_vpls` (cases 1–5), at once or by flagging records for on-demand re-evaluation.
    fn invalidate(
        &mut self,
        ctx: &RenderContext,
        moved: &Arc<Moved>,
        old_vpls: Vec<Vpl>,
        stats: &mut InstantCacheStats,
    ) {
        let min_distance = self.min_distance(ctx);
        let Some(cache) = self.cache.as_mut() else { return };
        stats.records_dropped_stale = cache.retain(|r| !r.stale);
        self.changes = None;
        let (tick, max_age) = (ctx.tick, self.config.max_age as u64);
        stats.records_aged_out = cache.retain(|r| tick.saturating_sub(r.last_used) <= max_age);
        let Some(changes) = TickChanges::new(moved, old_vpls, &self.vpls) else { return };
        stats.vpls_reused = changes.vpls.reused;
        stats.vpls_reweighted = changes.vpls.reweighted;
        stats.vpls_invalidated = changes.vpls.invalidated;
        stats.records_removed_moved = cache.retain(|r| !changes.removes(r));
        match self.config.reevaluation {
            Reevaluation::Immediate => {
                let vpls = &self.vpls;
                let works: Vec<Refresh> =
                    cache.records.par_iter_mut().map(|r| changes.refresh(ctx.accel, vpls, r, min_distance)).collect();
                works.into_iter().for_each(|w| w.count(stats));
            }
            Reevaluation::OnDemand => {
                cache.records.iter_mut().for_each(|r| r.stale = true);
                self.changes = Some(changes);
            }
        }
    }

    /// Indirect irradiance per pixel from the cache (`pixels.rs`): samples keep their records
    /// or clear them; in pixel order, samples no record covers get a new one; samples that
    /// cleared their list or that new records reach look up; new and flagged records are
    /// computed in parallel; each sample interpolates its records. `kept`: per sample, its
    /// camera sample was kept (`cameras.rs`). `renumbering`: how record indices changed since
    /// the last tick's passes.
    fn cached_indirect(
        &mut self,
        ctx: &RenderContext,
        k: usize,
        (shaded, kept): (&[Shaded], &[bool]),
        renumbering: Option<&[u32]>,
        stats: &mut InstantCacheStats,
    ) -> Vec<Option<Rgb>> {
        let min_distance = self.min_distance(ctx);
        let extent = self.extent(ctx);
        let temporal = self.mode() == CacheMode::Temporal;
        let cache = self.cache.get_or_insert_with(|| {
            Cache::new(extent.lo, extent.hi, self.config.caching_radius, self.config.normal_tolerance)
        });
        if !temporal {
            cache.clear();
        }
        // `static` keeps the states too, for their allocations, but not their lists.
        self.samples.resize_with(self.config.spp as usize, PassStates::default);
        let mut states = std::mem::take(&mut self.samples[k].states);
        if states.len() != shaded.len() {
            states = vec![SampleState::default(); shaded.len()];
        }
        // No record changed or went: samples that keep their records keep their irradiance.
        let still = self.still && renumbering.is_none();
        if still {
            if let Some(indirect) = pixels::all_kept(&states, kept) {
                stats.records_reused += pixels::mark_used(cache, None, cache.records.len(), ctx.tick);
                stats.samples_reused += indirect.iter().filter(|e| e.is_some()).count() as u64;
                self.samples[k].states = states;
                return indirect;
            }
        }
        let previous = if self.config.audit && temporal { states.clone() } else { Vec::new() };
        let first_new = cache.records.len();
        let hit = |i: usize| pixels::hit_key(&shaded[i].sample);
        let needs = pixels::keep_lists(&mut states, (hit, kept), renumbering, temporal);
        let cells = pixels::NewRecords::new(extent.lo, extent.hi, cache.reach());
        let (new, coverage_tests) = pixels::place_records(cache, &states, &needs, ctx.tick, cells);
        let looked = pixels::look_up(cache, &mut states, &needs, &new);
        let t = Instant::now();
        let works = compute_records(ctx, cache, &self.vpls, self.changes.as_ref(), first_new, &states, min_distance);
        stats.records_ms += t.elapsed().as_secs_f64() * 1e3;
        let looked_up = looked.iter().filter(|&&l| l).count() as u64;
        let lookups = looked_up + coverage_tests;
        let out = pixels::interpolate_all(&cache.records, &mut states, &looked, still);
        stats.records_reused += pixels::mark_used(cache, (looked_up > 0).then_some(&out.used), first_new, ctx.tick);
        stats.records_created += new.count;
        for (rays, refresh) in works {
            stats.visibility_rays_new += rays;
            if let Some(w) = refresh {
                w.count(stats);
            }
        }
        stats.samples_reused += out.kept;
        stats.samples_interpolated += out.hits - out.kept;
        stats.samples_looked_up += looked_up;
        stats.cache_lookups += lookups;
        if self.config.audit {
            let audit = pixels::audit(cache, &states, hit, &previous, renumbering);
            stats.audit_samples_mismatched += audit.mismatched;
            stats.audit_samples_needed += audit.needed;
        }
        self.samples[k] = PassStates { states, bytes: out.bytes };
        out.indirect
    }

    /// With `audit`: checks every record against a fresh computation (not timed as indirect).
    fn audit(&mut self, ctx: &RenderContext, stats: &mut InstantCacheStats) {
        let min_distance = self.min_distance(ctx);
        let reach = 10.0 * super::box_tree::BOX_SLACK * self.extent(ctx).diagonal;
        let Some(cache) = &self.cache else { return };
        let audit = cache::audit(ctx.accel, cache, &self.vpls, min_distance, reach);
        stats.audit_records += audit.records;
        stats.audit_mismatched += audit.mismatched;
        stats.audit_off_surface += audit.off_surface;
        stats.audit_digest = audit.digest;
    }

    /// Renders this tick's `spp` passes into `film` with the VPLs, cache and samples in place.
    fn render_passes(&mut self, ctx: &RenderContext, film: &mut Film, stats: &mut InstantCacheStats) {
        let scene = ctx.scene;
        // Taken once: every pass's kept lists date from the last tick's passes.
        let renumbering = self.cache.as_mut().and_then(Cache::take_renumbering);
        for pass_in_tick in 0..self.config.spp as usize {
            let mode = self.mode();
            // Only `temporal`'s resident generation keeps its samples for the next tick.
            let resident = mode == CacheMode::Temporal && self.kind == TickKind::Resident;
            let mut samples = match self.cameras.get_mut(pass_in_tick).filter(|_| resident) {
                Some(kept) => std::mem::take(kept),
                None => Samples::default(),
            };
            let reuse = match &self.camera_change {
                CameraChange::Moved { moved, lights } if resident => Some(Reuse {
                    moved: moved.as_ref(),
                    direct: !lights && self.camera_streams.get(pass_in_tick) == Some(&self.passes),
                }),
                _ => None,
            };
            let stream = (self.passes, pass_in_tick as u64);
            let t = Instant::now();
            let cameras::Shading { counts, kept } =
                cameras::shade(ctx, mode, stream, &mut samples, reuse, self.config.audit);
            let shaded = samples.shaded();
            stats.camera_ms += t.elapsed().as_secs_f64() * 1e3;
            stats.camera_samples_kept += counts.kept;
            stats.direct_samples_kept += counts.direct_kept;
            stats.camera_runs_settled += counts.settled_runs;
            stats.audit_cameras_mismatched += counts.mismatched;
            let t = Instant::now();
            let indirect = match self.mode() {
                CacheMode::Igi => {
                    let hits: Vec<Option<DiffuseHit>> = shaded.iter().map(|s| s.sample.hit).collect();
                    let (n, min_distance) = (self.config.interleave as usize, self.min_distance(ctx));
                    let (indirect, rays) = igi::indirect(ctx, &self.vpls, &hits, n, min_distance);
                    stats.visibility_rays_new += rays;
                    indirect
                }
                CacheMode::Static | CacheMode::Temporal => {
                    self.cached_indirect(ctx, pass_in_tick, (shaded, &kept), renumbering.as_deref(), stats)
                }
            };
            stats.indirect_ms += t.elapsed().as_secs_f64() * 1e3;
            if self.config.audit {
                self.audit(ctx, stats);
            }
            stats.camera_rays += shaded.len() as u64 - counts.kept;
            stats.specular_rays += cameras::accumulate(film, scene, shaded, &indirect);
            stats.shadow_rays += counts.shadow_rays;
            if resident {
                self.cameras.resize_with(self.config.spp as usize, Samples::default);
                self.cameras[pass_in_tick] = samples;
                self.camera_streams.resize(self.config.spp as usize, u64::MAX);
                self.camera_streams[pass_in_tick] = self.passes;
            }
            self.passes += 1;
            film.passes += 1;
        }
        let bytes = self.cameras.iter().map(Samples::bytes).sum::<usize>();
        stats.memory.set("cameras", bytes as u64);
    }
}

/// Computes the records made this pass (from `first_new` on) and re-evaluates flagged
/// (on-demand) records some sample uses, in parallel. Returns each one's new-record rays and
/// refresh.
///
/// The new records are the cache's tail, so they are split on their own: one parallel pass over
/// all records with a filter would leave rayon's last piece, and one worker, with all of them.
fn compute_records(
    ctx: &RenderContext,
    cache: &mut Cache,
    vpls: &[Vpl],
    changes: Option<&TickChanges>,
    first_new: usize,
    states: &[SampleState],
    min_distance: f32,
) -> Vec<(u64, Option<Refresh>)> {
    let tick = ctx.tick;
    let (old, new) = cache.records.split_at_mut(first_new);
    let mut works: Vec<(u64, Option<Refresh>)> = new
        .par_iter_mut()
        .with_max_len(RECORDS_PER_JOB)
        .map(|r| {
            let (fresh, rays) =
                cache::compute_record(ctx.accel, vpls, r.position, r.normal, r.object, min_distance, tick);
            *r = fresh;
            (rays, None)
        })
        .collect();
    if let Some(changes) = changes {
        let flagged_used = pixels::used(first_new, states);
        let refreshed = old
            .par_iter_mut()
            .with_max_len(RECORDS_PER_JOB)
            .zip(flagged_used.par_iter())
            .filter(|(r, &used)| r.stale && used)
            .map(|(r, _)| {
                r.stale = false;
                (0, Some(changes.refresh(ctx.accel, vpls, r, min_distance)))
            });
        works.par_extend(refreshed);
    }
    works
}

/// Records per parallel job in [`compute_records`]: few enough that two workers share a
/// pass's hundred-odd new records evenly.
const RECORDS_PER_JOB: usize = 8;

impl Technique for InstantCache {
    fn id(&self) -> &'static str {
        "instant_cache"
    }

    fn update(&mut self, ctx: &RenderContext, delta: &SceneDelta) -> Result<UpdateStats, TechniqueError> {
        let mut stats = InstantCacheStats::default();
        self.kind = self.tick_kind(delta);
        let t = Instant::now();
        // VPLs depend on geometry, lights and materials, not on the camera: a tick that changes
        // none of them keeps them (the Halton set would give the same ones again).
        let transport_changed = !(delta.moved.is_empty() && delta.lights.is_empty() && delta.materials.is_empty());
        stats.vpl_paths = self.vpl_paths.unwrap_or(0);
        let old_vpls = match self.vpl_paths {
            Some(_) if !transport_changed => self.vpls.clone(),
            _ => {
                let shot = self.shoot(ctx, 0, &mut stats);
                std::mem::replace(&mut self.vpls, shot)
            }
        };
        self.generation = match self.kind {
            TickKind::Resident => 0,
            TickKind::Refine => self.generation + 1,
            TickKind::Idle => self.generation,
        };
        match self.kind {
            TickKind::Refine => self.refinement.vpls = self.shoot(ctx, self.generation, &mut stats),
            // A change ends the refinement; its generation's memory goes.
            TickKind::Resident if !delta.is_empty() => self.refinement = Layer::default(),
            TickKind::Resident | TickKind::Idle => {}
        }
        stats.generation = self.generation;
        stats.idle = self.kind == TickKind::Idle;
        let rendered = if self.kind == TickKind::Refine { &self.refinement.vpls } else { &self.vpls };
        stats.vpls = rendered.len() as u64;
        stats.memory.set("vpls", ((self.vpls.len() + self.refinement.vpls.len()) * size_of::<Vpl>()) as u64);
        stats.vpl_ms = t.elapsed().as_secs_f64() * 1e3;
        if self.config.mode == CacheMode::Temporal {
            let t = Instant::now();
            let moved = Arc::new(Moved::new(ctx.scene, ctx.accel, delta, self.extent(ctx).diagonal)?);
            self.invalidate(ctx, &moved, old_vpls, &mut stats);
            // A moved light's shape is among the moved surfaces; a changed emitter may be a new shape.
            let emitters = delta.lights.iter().any(|l| l.emission_changed);
            let camera_change = delta.camera || !delta.materials.is_empty() || emitters;
            self.camera_change = match camera_change {
                true => CameraChange::All,
                false => CameraChange::Moved { moved, lights: !delta.lights.is_empty() },
            };
            // The resident records stay in use while still ticks render other generations.
            if let (TickKind::Refine | TickKind::Idle, Some(cache)) = (self.kind, self.cache.as_mut()) {
                pixels::mark_used(cache, None, cache.records.len(), ctx.tick);
            }
            stats.invalidate_ms = t.elapsed().as_secs_f64() * 1e3;
        }
        self.still = self.mode() == CacheMode::Temporal && delta.is_empty() && self.changes.is_none();
        if !delta.is_empty() {
            self.passes = 0;
        }
        Ok(UpdateStats::new(stats))
    }

    fn render(
        &mut self,
        ctx: &RenderContext,
        film: &mut Film,
        update: UpdateStats,
    ) -> Result<RenderStats, TechniqueError> {
        let start = Instant::now();
        let mut stats: InstantCacheStats = update.take();
        match self.kind {
            TickKind::Resident => self.render_passes(ctx, film, &mut stats),
            TickKind::Refine => {
                self.swap_layers();
                self.render_passes(ctx, film, &mut stats);
                self.swap_layers();
            }
            TickKind::Idle => {}
        }
        if self.config.mode != CacheMode::Igi {
            stats.records = self.cache.as_ref().map_or(0, |c| c.records.len() as u64);
            stats.memory.set("cache", self.cache.as_ref().map_or(0, Cache::memory_bytes));
            stats.memory.set("samples", pixels::samples_bytes(&self.samples));
        }
        let layer = &self.refinement;
        let cache = layer.cache.as_ref().map_or(0, Cache::memory_bytes);
        stats.memory.set("refinement", cache + pixels::samples_bytes(&layer.samples));
        stats.render_ms = start.elapsed().as_secs_f64() * 1e3;
        stats.visibility_rays = stats.visibility_rays_new
            + stats.visibility_rays_vpl
            + stats.visibility_rays_occlusion
            + stats.visibility_rays_deocclusion;
        let rays = RayCounts {
            primary: stats.camera_rays,
            secondary: stats.specular_rays + stats.vpl_rays,
            shadow: stats.shadow_rays + stats.visibility_rays,
        };
        Ok(RenderStats { rays, detail: TechniqueStats::InstantCache(Box::new(stats)) })
    }
}
