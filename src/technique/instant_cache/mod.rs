//! `instant_cache`: virtual point lights gathered through an irradiance cache.
//!
//! Paper: K. Debattista, P. Dubla, L. P. Santos, A. Chalmers, "Instant Caching for Interactive
//! Global Illumination" (`shared/papers/instant-caching-interactive-gi.md`); the `igi` baseline
//! is Wald et al.'s instant global illumination.
//!
//! # Algorithm (per tick)
//! 1. Shoot VPLs (`vpl.rs`, §3.1): Halton-sequenced photon paths at fixed indices, a VPL at
//!    every diffuse hit; paths end by Russian roulette only, so no light is cut off with
//!    their length (before, a 10-bounce cap lost ρ_S¹⁰ of it: 11% at ρ_S = 0.8); unchanged
//!    scenes give the same VPLs.
//! 2. Per camera sample (`technique/camera_chain.rs`): follow mirrors and glass to the first
//!    diffuse hit; direct light by next-event estimation with a shadow ray.
//! 3. Indirect diffuse light, by mode:
//!    - `igi` (`igi.rs`): each pixel gathers its n×n-interleaved subset of the VPLs with
//!      visibility rays, then a discontinuity buffer averages the n×n neighbourhood.
//!    - `static` (`cache.rs`, `octree.rs`): an irradiance cache cleared every tick. In pixel
//!      order, a record is made wherever no record has w_k(x) > 1/a (eq. 5); records are
//!      computed in parallel, each with one visibility ray per VPL and G′ (eqs. 2–3), and every
//!      pixel interpolates them (eq. 4). Deciding where records go in pixel order keeps the
//!      image independent of the thread count.
//!    - `temporal` (`temporal.rs`, §3.2, Algorithm 1): the same cache kept across ticks. At
//!      the start of a tick, records unused for `max_age` ticks go; if VPLs changed or
//!      surfaces moved, records on a moved object go (case 5) and the rest
//!      are re-evaluated, ray by ray, for cases 1–4, either at once (`immediate`) or when a
//!      pixel first interpolates them (`on_demand`). New areas get records on demand as in
//!      `static`. The result is exact: every record equals a fresh computation. Camera
//!      samples use the same sub-pixel points every tick (the k-th of a tick's `spp`), so a
//!      still view makes no records after its first tick; direct light still varies. On a
//!      still tick (no scene change at all) a sample that finds the hit it found last tick
//!      keeps last tick's irradiance without a lookup; if any sample's hit differs (a glass
//!      chain that chose another lobe), the pass looks every sample up as usual. VPLs are
//!      shot again only when geometry, a light or a material changed.
//! 4. Radiance = emission seen along the chain + direct + ρ/π · indirect irradiance.
//!
//! # Parameters (defaults)
//! | field | default | meaning |
//! |---|---|---|
//! | `mode` | `temporal` | `igi`, `static` or `temporal` |
//! | `vpls` | 256 | VPLs per tick, on average (⌈vpls·(1 − ρ_S)⌉ paths are shot; at most 4× are kept) |
//! | `interleave` | 4 | n of `igi`'s n×n interleaved sampling |
//! | `caching_radius` | 0.05 | a, in units of the scene's bounding diagonal |
//! | `clamp_distance` | 0.01 | min_d of G′'s clamp, in units of the scene's bounding diagonal |
//! | `max_bounces` | none | bounces a VPL path may take; none: until Russian roulette ends it |
//! | `spp` | 1 | camera samples per pixel per tick |
//! | `reevaluation` | `immediate` | `temporal`: re-evaluate invalidated records at the start of the tick, or `on_demand` when first interpolated |
//! | `max_age` | 16 | `temporal`: records unused this many ticks are dropped |
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
//! `temporal` adds no bias of its own (its records are exact), but its records sit where
//! earlier ticks' pixels put them, so its image differs from `static`'s by where the
//! interpolation error falls, not by how large it is.
//!
//! # Failure modes
//! Small bright VPLs near a surface still show as spots above the clamp distance; glossy
//! transport is not handled; a caching radius too large for fine geometry blurs contact
//! shadows of indirect light. `temporal` degrades to `static`'s cost when many surfaces move
//! (every VPL changes) and a moving light invalidates every VPL it shot.
mod cache;
mod config;
pub use config::DESCRIPTION;
mod igi;
mod octree;
mod rgbe;
mod temporal;
mod vpl;

pub use config::{CacheMode, InstantCacheConfig, InstantCacheStats, Reevaluation, MAX_VPLS};

use super::camera_chain::{self, CameraSample, DiffuseHit};
use super::{RayCounts, RenderContext, RenderStats, Technique, TechniqueError, TechniqueStats};
use crate::core::{Rgb, Rng};
use crate::film::Film;
use crate::scene::edits::SceneDelta;
use crate::scene::Scene;
use cache::{Cache, Record};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;
use temporal::{Refresh, TickChanges};
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
    pending: InstantCacheStats,
    /// The photon paths the VPLs come from; `None` until they are first shot.
    vpl_paths: Option<u64>,
    /// `temporal`: nothing this tick can change a cached irradiance (no scene change, so the
    /// same VPLs and records), so a sample that finds its last tick's hit keeps its result.
    still: bool,
    /// `temporal`: each pass's samples and interpolated irradiance, from the last tick.
    last: Vec<LastPass>,
}

/// What one pass of a tick interpolated, kept for the next tick's still check.
#[derive(Default)]
struct LastPass {
    /// Each sample's first diffuse hit: position, facing normal, object.
    hits: Vec<Option<(Vec3, Vec3, u32)>>,
    indirect: Vec<Option<Rgb>>,
}

/// What [`LastPass`] keeps per camera sample.
pub(crate) const LAST_BYTES_PER_SAMPLE: u64 =
    (std::mem::size_of::<Option<(Vec3, Vec3, u32)>>() + std::mem::size_of::<Option<Rgb>>()) as u64;

/// A sample's hit as [`LastPass`] keeps it.
fn hit_key(s: &Shaded) -> Option<(Vec3, Vec3, u32)> {
    s.sample.hit.as_ref().map(|h| (h.p, h.facing(), h.object))
}

/// A pixel's camera sample with its direct light.
struct Shaded {
    sample: CameraSample,
    direct: Rgb,
    shadow: bool,
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
            pending: InstantCacheStats::default(),
            vpl_paths: None,
            still: false,
            last: Vec::new(),
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

    /// Shoots this tick's VPLs (`vpl.rs`) and returns the previous ones.
    fn shoot(&mut self, ctx: &RenderContext) -> Vec<Vpl> {
        let rho = ctx.scene.mean_reflectance();
        // About `vpls` VPLs: a path leaves 1/(1 − ρ_S) on average; at most 4× that are kept.
        let paths = ((self.config.vpls as f32 * (1.0 - rho.clamp(0.0, 0.95))).ceil() as u64).max(1);
        let max_bounces = self.config.max_bounces.unwrap_or(vpl::MAX_VPL_BOUNCES);
        let shot = vpl::shoot(ctx.scene, ctx.accel, paths, 4 * self.config.vpls as usize, max_bounces);
        self.vpl_paths = Some(shot.paths);
        self.pending.vpl_cap_reached = shot.capped;
        self.pending.vpl_rays = shot.rays;
        std::mem::replace(&mut self.vpls, shot.vpls)
    }

    /// `temporal` on a still tick: the last tick's irradiance for pass `k`, when every sample
    /// found the same hit as then (no record can have changed, and none is needed). The records
    /// those samples used are marked used, as interpolating would have.
    fn still_indirect(&mut self, ctx: &RenderContext, k: usize, shaded: &[Shaded]) -> Option<Vec<Option<Rgb>>> {
        let last = self.last.get(k).filter(|_| self.still)?;
        let same = last.hits.len() == shaded.len() && shaded.par_iter().zip(&last.hits).all(|(s, h)| hit_key(s) == *h);
        if !same {
            return None;
        }
        if let Some(cache) = self.cache.as_mut() {
            let tick = ctx.tick;
            cache.records.iter_mut().filter(|r| r.last_used + 1 >= tick).for_each(|r| r.last_used = tick);
            self.pending.records = cache.records.len() as u64;
            self.pending.memory.set("cache", cache.memory_bytes());
        }
        self.pending.samples_reused += shaded.len() as u64;
        Some(last.indirect.clone())
    }

    /// Keeps pass `k`'s samples and irradiance for the next tick's still check (`temporal`).
    fn remember(&mut self, k: usize, shaded: &[Shaded], indirect: &[Option<Rgb>]) {
        if self.config.mode != CacheMode::Temporal {
            return;
        }
        self.last.resize_with(self.config.spp as usize, LastPass::default);
        self.last[k] = LastPass { hits: shaded.iter().map(hit_key).collect(), indirect: indirect.to_vec() };
    }

    /// `temporal`, at the start of a tick: ages the cache and applies what changed since the
    /// VPLs `old_vpls` (cases 1–5), at once or by flagging records for on-demand re-evaluation.
    fn invalidate(
        &mut self,
        ctx: &RenderContext,
        delta: &SceneDelta,
        old_vpls: Vec<Vpl>,
    ) -> Result<(), TechniqueError> {
        let min_distance = self.min_distance(ctx);
        let diagonal = self.extent(ctx).diagonal;
        let Some(cache) = self.cache.as_mut() else { return Ok(()) };
        let stats = &mut self.pending;
        stats.records_dropped_stale = cache.retain(|r| !r.stale);
        self.changes = None;
        let (tick, max_age) = (ctx.tick, self.config.max_age as u64);
        stats.records_aged_out = cache.retain(|r| tick.saturating_sub(r.last_used) <= max_age);
        let Some(changes) = TickChanges::new(ctx.scene, ctx.accel, delta, old_vpls, &self.vpls, diagonal)? else {
            return Ok(());
        };
        stats.vpls_reused = changes.vpls.reused;
        stats.vpls_reweighted = changes.vpls.reweighted;
        stats.vpls_invalidated = changes.vpls.invalidated;
        stats.records_removed_moved = cache.retain(|r| !changes.removes(r));
        match self.config.reevaluation {
            Reevaluation::Immediate => {
                let vpls = &self.vpls;
                let works: Vec<Refresh> =
                    cache.records.par_iter_mut().map(|r| changes.refresh(ctx.accel, vpls, r, min_distance)).collect();
                works.into_iter().for_each(|w| count_refresh(stats, w));
            }
            Reevaluation::OnDemand => {
                cache.records.iter_mut().for_each(|r| r.stale = true);
                self.changes = Some(changes);
            }
        }
        Ok(())
    }

    /// Indirect irradiance per pixel from the cache: in pixel order, pixels no record covers
    /// get a new one; then new and flagged records are computed in parallel and interpolated.
    fn cached_indirect(&mut self, ctx: &RenderContext, shaded: &[Shaded]) -> Vec<Option<Rgb>> {
        let min_distance = self.min_distance(ctx);
        let extent = self.extent(ctx);
        let cache = self.cache.get_or_insert_with(|| Cache::new(extent.lo, extent.hi, self.config.caching_radius));
        if self.config.mode == CacheMode::Static {
            cache.clear();
        }
        let (vpls, changes, tick) = (&self.vpls, self.changes.as_ref(), ctx.tick);
        // Coverage by records kept from earlier ticks does not depend on pixel order, so it is
        // found in parallel; the rest is decided in pixel order, which keeps the image
        // independent of the thread count. Flagged records (on demand) must be known before
        // interpolation, so then every covering record is marked, not just the first found.
        let first_new = cache.records.len();
        let flagged_used = AtomicFlags::new(if changes.is_some() { first_new } else { 0 });
        let covered_by_kept: Vec<bool> = shaded
            .par_iter()
            .map(|s| match &s.sample.hit {
                None => true,
                Some(hit) if changes.is_some() => {
                    let mut covered = false;
                    cache.near(hit.p, hit.facing(), |i, _| {
                        covered = true;
                        flagged_used.set(i);
                    });
                    covered
                }
                Some(hit) => cache.covers(hit.p, hit.facing()),
            })
            .collect();
        for (s, _) in shaded.iter().zip(&covered_by_kept).filter(|(_, &covered)| !covered) {
            let Some(hit) = &s.sample.hit else { continue };
            let n = hit.facing();
            if !cache.covers(hit.p, n) {
                cache.insert(Record::new(hit.p, n, hit.object, Vec::new(), tick));
            }
        }
        let flagged_used = flagged_used.into_vec();
        let works: Vec<(u64, Option<Refresh>)> = cache
            .records
            .par_iter_mut()
            .enumerate()
            .filter(|(i, r)| *i >= first_new || (r.stale && flagged_used.get(*i) == Some(&true)))
            .map(|(i, r)| {
                if i >= first_new {
                    let (fresh, rays) =
                        cache::compute_record(ctx.accel, vpls, r.position, r.normal, r.object, min_distance, tick);
                    *r = fresh;
                    (rays, None)
                } else {
                    r.stale = false;
                    (0, changes.map(|c| c.refresh(ctx.accel, vpls, r, min_distance)))
                }
            })
            .collect();
        let used = AtomicFlags::new(cache.records.len());
        let indirect: Vec<Option<Rgb>> = shaded
            .par_iter()
            .map(|s| {
                let h = s.sample.hit.as_ref()?;
                let (mut sum, mut weights) = (Rgb::BLACK, 0.0f32);
                cache.near(h.p, h.facing(), |i, w| {
                    used.set(i);
                    sum += cache.records[i as usize].irradiance * w;
                    weights += w;
                });
                Some(if weights > 0.0 { sum / weights } else { Rgb::BLACK })
            })
            .collect();
        let used = used.into_vec();
        for (r, _) in cache.records.iter_mut().zip(&used).filter(|(_, &u)| u) {
            r.last_used = tick;
        }
        let stats = &mut self.pending;
        stats.records_created += (cache.records.len() - first_new) as u64;
        stats.records_reused += used[..first_new].iter().filter(|&&u| u).count() as u64;
        for (rays, refresh) in works {
            stats.visibility_rays_new += rays;
            if let Some(w) = refresh {
                count_refresh(stats, w);
            }
        }
        stats.records = cache.records.len() as u64;
        stats.samples_interpolated += shaded.len() as u64;
        stats.memory.set("cache", cache.memory_bytes());
        indirect
    }

    /// With `audit`: checks every record against a fresh computation (not timed as indirect).
    fn audit(&mut self, ctx: &RenderContext) {
        let min_distance = self.min_distance(ctx);
        let reach = 10.0 * super::box_tree::BOX_SLACK * self.extent(ctx).diagonal;
        let Some(cache) = &self.cache else { return };
        let audit = cache::audit(ctx.accel, cache, &self.vpls, min_distance, reach);
        self.pending.audit_records += audit.records;
        self.pending.audit_mismatched += audit.mismatched;
        self.pending.audit_off_surface += audit.off_surface;
        self.pending.audit_digest = audit.digest;
    }

    /// Indirect irradiance per pixel by IGI's interleaved gather and discontinuity buffer.
    fn igi_indirect(&mut self, ctx: &RenderContext, shaded: &[Shaded]) -> Vec<Option<Rgb>> {
        let min_distance = self.min_distance(ctx);
        let width = ctx.scene.camera.width as usize;
        let n = self.config.interleave as usize;
        let camera = ctx.scene.camera.ray(0.5 * width as f32, 0.0).origin;
        let hits: Vec<Option<(DiffuseHit, f32)>> =
            shaded.iter().map(|s| s.sample.hit.map(|h| (h, (h.p - camera).length()))).collect();
        let gathered: Vec<(Rgb, u64)> = hits
            .par_iter()
            .enumerate()
            .map(|(i, h)| match h {
                Some((hit, _)) => {
                    let subset = (i % width) % n + n * ((i / width) % n);
                    igi::subset_irradiance(ctx.accel, &self.vpls, hit, subset, n * n, min_distance)
                }
                None => (Rgb::BLACK, 0),
            })
            .collect();
        self.pending.visibility_rays_new += gathered.iter().map(|g| g.1).sum::<u64>();
        let raw: Vec<Rgb> = gathered.into_iter().map(|g| g.0).collect();
        let filtered = igi::filter(&hits, &raw, width, n);
        hits.iter().zip(filtered).map(|(h, e)| h.map(|_| e)).collect()
    }
}

/// One flag per record, set from many threads.
struct AtomicFlags(Vec<AtomicBool>);

impl AtomicFlags {
    fn new(len: usize) -> AtomicFlags {
        AtomicFlags((0..len).map(|_| AtomicBool::new(false)).collect())
    }

    fn set(&self, i: u32) {
        if let Some(flag) = self.0.get(i as usize) {
            flag.store(true, Ordering::Relaxed);
        }
    }

    fn into_vec(self) -> Vec<bool> {
        self.0.into_iter().map(AtomicBool::into_inner).collect()
    }
}

/// Adds one record's re-evaluation to the tick's figures.
fn count_refresh(stats: &mut InstantCacheStats, w: Refresh) {
    stats.records_refreshed += 1;
    stats.records_invalidated_vpl += u64::from(w.vpl_rays + w.reweighted > 0);
    stats.records_invalidated_occluded += u64::from(w.occluded > 0);
    stats.records_invalidated_deoccluded += u64::from(w.deoccluded > 0);
    stats.visibility_rays_vpl += w.vpl_rays;
    stats.visibility_rays_occlusion += w.occlusion_rays;
    stats.occlusion_box_tests += w.occlusion_box_tests;
    stats.visibility_rays_deocclusion += w.deocclusion_rays;
    stats.deocclusion_box_tests += w.deocclusion_box_tests;
}

impl Technique for InstantCache {
    fn id(&self) -> &'static str {
        "instant_cache"
    }

    fn update(&mut self, ctx: &RenderContext, delta: &SceneDelta) -> Result<(), TechniqueError> {
        self.pending = InstantCacheStats::default();
        let t = Instant::now();
        // VPLs depend on geometry, lights and materials, not on the camera: a tick that changes
        // none of them keeps them (the Halton set would give the same ones again).
        let transport_changed = !(delta.moved.is_empty() && delta.lights.is_empty() && delta.materials.is_empty());
        let old_vpls = match self.vpl_paths {
            Some(_) if !transport_changed => self.vpls.clone(),
            _ => self.shoot(ctx),
        };
        self.pending.vpls = self.vpls.len() as u64;
        self.pending.vpl_paths = self.vpl_paths.unwrap_or(0);
        self.pending.memory.set("vpls", (self.vpls.len() * std::mem::size_of::<Vpl>()) as u64);
        self.pending.vpl_ms = t.elapsed().as_secs_f64() * 1e3;
        if self.config.mode == CacheMode::Temporal {
            let t = Instant::now();
            self.invalidate(ctx, delta, old_vpls)?;
            self.pending.invalidate_ms = t.elapsed().as_secs_f64() * 1e3;
        }
        self.still = self.config.mode == CacheMode::Temporal && delta.is_empty() && self.changes.is_none();
        if !delta.is_empty() {
            self.passes = 0;
        }
        Ok(())
    }

    fn render(&mut self, ctx: &RenderContext, film: &mut Film) -> Result<RenderStats, TechniqueError> {
        let start = Instant::now();
        let scene = ctx.scene;
        let pixels = (scene.camera.width * scene.camera.height) as usize;
        for pass_in_tick in 0..self.config.spp as u64 {
            let pass = self.passes;
            let shaded: Vec<Shaded> = (0..pixels)
                .into_par_iter()
                .map(|i| {
                    let mut rng = Rng::for_sample(ctx.seed, ctx.tick, i as u64, pass);
                    let jitter = match self.config.mode {
                        // The same sub-pixel points every tick, so a still view finds its records.
                        CacheMode::Temporal => Rng::for_sample(ctx.seed, 0, i as u64, pass_in_tick).next_2d(),
                        CacheMode::Igi | CacheMode::Static => rng.next_2d(),
                    };
                    let sample = camera_chain::trace(scene, ctx.accel, i, jitter, &mut rng);
                    let (direct, shadow) = match &sample.hit {
                        Some(hit) => camera_chain::direct_light(scene, ctx.accel, hit, &mut rng),
                        None => (Rgb::BLACK, false),
                    };
                    Shaded { sample, direct, shadow }
                })
                .collect();
            let t = Instant::now();
            let k = pass_in_tick as usize;
            let indirect = match self.config.mode {
                CacheMode::Igi => self.igi_indirect(ctx, &shaded),
                CacheMode::Static | CacheMode::Temporal => match self.still_indirect(ctx, k, &shaded) {
                    Some(kept) => kept,
                    None => {
                        let indirect = self.cached_indirect(ctx, &shaded);
                        self.remember(k, &shaded, &indirect);
                        indirect
                    }
                },
            };
            self.pending.indirect_ms += t.elapsed().as_secs_f64() * 1e3;
            if self.config.audit {
                self.audit(ctx);
            }
            let radiance: Vec<Rgb> = shaded
                .iter()
                .zip(&indirect)
                .map(|(s, e)| {
                    let reflected = match (&s.sample.hit, e) {
                        (Some(hit), Some(e)) => hit.beta * hit.material(scene).diffuse_reflectance() * *e * FRAC_1_PI,
                        _ => Rgb::BLACK,
                    };
                    s.sample.emitted + s.direct + reflected
                })
                .collect();
            self.pending.camera_rays += pixels as u64;
            self.pending.specular_rays += shaded.iter().map(|s| s.sample.specular_rays).sum::<u64>();
            self.pending.shadow_rays += shaded.iter().filter(|s| s.shadow).count() as u64;
            film.accumulate_chunks(
                scene.camera.width as usize,
                |first, chunk| {
                    for (k, px) in chunk.iter_mut().enumerate() {
                        px.add(radiance[first + k]);
                        px.count += 1.0;
                    }
                },
                |(), ()| (),
            );
            self.passes += 1;
            film.passes += 1;
        }
        if self.config.mode == CacheMode::Temporal {
            let samples: usize = self.last.iter().map(|l| l.hits.len()).sum();
            self.pending.memory.set("last_tick", samples as u64 * LAST_BYTES_PER_SAMPLE);
        }
        let mut stats = std::mem::take(&mut self.pending);
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
