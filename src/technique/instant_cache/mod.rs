//! `instant_cache`: virtual point lights gathered through an irradiance cache.
//!
//! Paper: K. Debattista, P. Dubla, L. P. Santos, A. Chalmers, "Instant Caching for Interactive
//! Global Illumination" (`shared/papers/instant-caching-interactive-gi.md`); the `igi` baseline
//! is Wald et al.'s instant global illumination.
//!
//! # Algorithm (per tick)
//! 1. Shoot VPLs (`vpl.rs`, §3.1): Halton-sequenced photon paths at fixed indices, a VPL at
//!    every diffuse hit, until `vpls` are placed; unchanged scenes give the same VPLs.
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
//! 4. Radiance = emission seen along the chain + direct + ρ/π · indirect irradiance.
//!
//! # Parameters (defaults)
//! | field | default | meaning |
//! |---|---|---|
//! | `mode` | `static` | `igi` or `static` (`temporal`, the cache kept across ticks, is not built yet) |
//! | `vpls` | 256 | VPLs per tick, on average (⌈vpls·(1 − ρ_S)⌉ paths are shot; at most 4× are kept) |
//! | `interleave` | 4 | n of `igi`'s n×n interleaved sampling |
//! | `caching_radius` | 0.05 | a, in units of the scene's bounding diagonal |
//! | `clamp_distance` | 0.01 | min_d of G′'s clamp, in units of the scene's bounding diagonal |
//! | `admitted_truncation` | 0.01 | c of the VPL paths' length l_m (as `path`) |
//! | `spp` | 1 | camera samples per pixel per tick |
//!
//! # Bias and consistency
//! Biased, like every VPL method: G′'s clamp drops light from VPLs closer than 0.8·min_d (dark
//! corners), interpolation blurs irradiance across a record's radius, RGBE rounds each VPL's
//! contribution to about 1%, and 256 VPLs give low-frequency error (splotches) rather than
//! noise. It converges as VPLs → ∞, a → 0 and min_d → 0. Only diffuse reflection is cached.
//!
//! # Failure modes
//! Small bright VPLs near a surface still show as spots above the clamp distance; glossy
//! transport is not handled; a caching radius too large for fine geometry blurs contact
//! shadows of indirect light.
mod cache;
mod igi;
mod octree;
mod rgbe;
mod vpl;

use super::camera_chain::{self, CameraSample, DiffuseHit};
use super::path::max_path_length;
use super::{RayCounts, RenderContext, RenderStats, Technique, TechniqueError, TechniqueStats};
use crate::core::{Rgb, Rng};
use crate::film::Film;
use crate::scene::edits::SceneDelta;
use crate::scene::Scene;
use cache::Cache;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f32::consts::FRAC_1_PI;
use std::time::Instant;
use vpl::Vpl;

/// How indirect light is gathered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CacheMode {
    /// Instant global illumination: interleaved VPL subsets and a discontinuity buffer.
    Igi,
    /// The instant cache, rebuilt every tick.
    Static,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InstantCacheConfig {
    pub mode: CacheMode,
    pub vpls: u32,
    pub interleave: u32,
    pub caching_radius: f32,
    pub clamp_distance: f32,
    pub admitted_truncation: f32,
    pub spp: u32,
}

impl Default for InstantCacheConfig {
    fn default() -> InstantCacheConfig {
        InstantCacheConfig {
            mode: CacheMode::Static,
            vpls: 256,
            interleave: 4,
            caching_radius: 0.05,
            clamp_distance: 0.01,
            admitted_truncation: 0.01,
            spp: 1,
        }
    }
}

/// Most VPLs a tick may shoot.
pub const MAX_VPLS: u32 = 65_536;

impl InstantCacheConfig {
    pub fn validate(&self) -> Result<(), TechniqueError> {
        let bad = |field: &str, message: &str| {
            Err(TechniqueError::InvalidConfig { field: field.into(), message: message.into() })
        };
        if self.vpls == 0 || self.vpls > MAX_VPLS {
            return bad("vpls", &format!("must lie in 1..={MAX_VPLS}"));
        }
        if self.interleave == 0 || self.interleave > 16 {
            return bad("interleave", "must lie in 1..=16");
        }
        if !(self.caching_radius > 0.0 && self.caching_radius <= 1.0) {
            return bad("caching_radius", "must lie in (0, 1] (a fraction of the scene's diagonal)");
        }
        if !(self.clamp_distance >= 0.0 && self.clamp_distance <= 1.0) {
            return bad("clamp_distance", "must lie in [0, 1] (a fraction of the scene's diagonal)");
        }
        if !(self.admitted_truncation > 0.0 && self.admitted_truncation < 1.0) {
            return bad("admitted_truncation", "must lie in (0, 1)");
        }
        if self.spp == 0 || self.spp > super::path::MAX_SPP {
            return bad("spp", &format!("must lie in 1..={}", super::path::MAX_SPP));
        }
        Ok(())
    }
}

/// Per-tick figures of `instant_cache`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct InstantCacheStats {
    pub vpls: u64,
    pub vpl_paths: u64,
    pub vpl_rays: u64,
    /// Records in the cache after this tick, and those made this tick.
    pub records: u64,
    pub records_created: u64,
    /// Rays from cache records or pixels towards VPLs.
    pub visibility_rays: u64,
    pub camera_rays: u64,
    pub specular_rays: u64,
    pub shadow_rays: u64,
    pub vpl_ms: f64,
    /// The indirect component: record creation and interpolation, or the IGI gather and filter.
    pub indirect_ms: f64,
    pub render_ms: f64,
    pub vpl_bytes: u64,
    pub cache_bytes: u64,
}

/// The `instant_cache` technique.
pub struct InstantCache {
    config: InstantCacheConfig,
    vpls: Vec<Vpl>,
    cache: Option<Cache>,
    passes: u64,
    pending: InstantCacheStats,
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
        Ok(InstantCache { config, vpls: Vec::new(), cache: None, passes: 0, pending: InstantCacheStats::default() })
    }

    /// The scene's bounds and diagonal.
    fn bounds(ctx: &RenderContext) -> (glam::Vec3, glam::Vec3, f32) {
        let (lo, hi) = ctx.accel.scene().bounds().unwrap_or((glam::Vec3::ZERO, glam::Vec3::ONE));
        (lo, hi, (hi - lo).length().max(f32::MIN_POSITIVE))
    }

    /// Indirect irradiance per pixel from the cache (records made on demand, in pixel order).
    fn cached_indirect(&mut self, ctx: &RenderContext, shaded: &[Shaded], min_distance: f32) -> Vec<Option<Rgb>> {
        let (lo, hi, _) = Self::bounds(ctx);
        let cache = self.cache.get_or_insert_with(|| Cache::new(lo, hi, self.config.caching_radius));
        cache.clear();
        let mut wanted = Vec::new();
        for s in shaded {
            if let Some(hit) = &s.sample.hit {
                let n = hit.facing();
                if !cache.covers(hit.p, n) {
                    let (placeholder, _) = cache::compute_record(ctx.accel, &[], hit.p, n, min_distance);
                    wanted.push(cache.insert(placeholder));
                }
            }
        }
        let computed: Vec<(cache::Record, u64)> = wanted
            .par_iter()
            .map(|&i| {
                let r = &cache.records[i as usize];
                cache::compute_record(ctx.accel, &self.vpls, r.position, r.normal, min_distance)
            })
            .collect();
        for (&i, (record, rays)) in wanted.iter().zip(computed) {
            self.pending.visibility_rays += rays;
            cache.records[i as usize] = record;
        }
        self.pending.records_created += wanted.len() as u64;
        self.pending.records = cache.records.len() as u64;
        self.pending.cache_bytes = cache.memory_bytes();
        let cache = &*cache;
        shaded
            .par_iter()
            .map(|s| s.sample.hit.as_ref().map(|h| cache.irradiance(h.p, h.facing()).unwrap_or(Rgb::BLACK)))
            .collect()
    }

    /// Indirect irradiance per pixel by IGI's interleaved gather and discontinuity buffer.
    fn igi_indirect(&mut self, ctx: &RenderContext, shaded: &[Shaded], min_distance: f32) -> Vec<Option<Rgb>> {
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
        self.pending.visibility_rays += gathered.iter().map(|g| g.1).sum::<u64>();
        let raw: Vec<Rgb> = gathered.into_iter().map(|g| g.0).collect();
        let filtered = igi::filter(&hits, &raw, width, n);
        hits.iter().zip(filtered).map(|(h, e)| h.map(|_| e)).collect()
    }
}

impl Technique for InstantCache {
    fn id(&self) -> &'static str {
        "instant_cache"
    }

    fn update(&mut self, ctx: &RenderContext, delta: &SceneDelta) -> Result<(), TechniqueError> {
        self.pending = InstantCacheStats::default();
        let t = Instant::now();
        let rho = ctx.scene.mean_reflectance();
        let l_m = max_path_length(rho, self.config.admitted_truncation);
        // About `vpls` VPLs: a path leaves 1/(1 − ρ_S) on average; at most 4× that are kept.
        let paths = ((self.config.vpls as f32 * (1.0 - rho.clamp(0.0, 0.95))).ceil() as u64).max(1);
        let (vpls, rays) = vpl::shoot(ctx.scene, ctx.accel, paths, 4 * self.config.vpls as usize, l_m);
        self.vpls = vpls;
        self.pending.vpls = self.vpls.len() as u64;
        self.pending.vpl_paths = paths;
        self.pending.vpl_rays = rays;
        self.pending.vpl_bytes = (self.vpls.len() * std::mem::size_of::<Vpl>()) as u64;
        self.pending.vpl_ms = t.elapsed().as_secs_f64() * 1e3;
        if !delta.is_empty() {
            self.passes = 0;
        }
        Ok(())
    }

    fn render(&mut self, ctx: &RenderContext, film: &mut Film) -> Result<RenderStats, TechniqueError> {
        let start = Instant::now();
        let scene = ctx.scene;
        let pixels = (scene.camera.width * scene.camera.height) as usize;
        let (_, _, diagonal) = Self::bounds(ctx);
        let min_distance = self.config.clamp_distance * diagonal;
        for _ in 0..self.config.spp {
            let pass = self.passes;
            let shaded: Vec<Shaded> = (0..pixels)
                .into_par_iter()
                .map(|i| {
                    let mut rng = Rng::for_sample(ctx.seed, ctx.tick, i as u64, pass);
                    let sample = camera_chain::trace(scene, ctx.accel, i, &mut rng);
                    let (direct, shadow) = match &sample.hit {
                        Some(hit) => camera_chain::direct_light(scene, ctx.accel, hit, &mut rng),
                        None => (Rgb::BLACK, false),
                    };
                    Shaded { sample, direct, shadow }
                })
                .collect();
            let t = Instant::now();
            let indirect = match self.config.mode {
                CacheMode::Igi => self.igi_indirect(ctx, &shaded, min_distance),
                CacheMode::Static => self.cached_indirect(ctx, &shaded, min_distance),
            };
            self.pending.indirect_ms += t.elapsed().as_secs_f64() * 1e3;
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
        let mut stats = std::mem::take(&mut self.pending);
        stats.render_ms = start.elapsed().as_secs_f64() * 1e3;
        let rays = RayCounts {
            primary: stats.camera_rays,
            secondary: stats.specular_rays + stats.vpl_rays,
            shadow: stats.shadow_rays + stats.visibility_rays,
        };
        Ok(RenderStats { rays, detail: TechniqueStats::InstantCache(Box::new(stats)) })
    }
}
