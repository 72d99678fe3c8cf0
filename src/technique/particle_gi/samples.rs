//! The ray-tracing stage of a `particle_gi` frame (step 3 of `mod.rs`, §4.3 of the paper):
//! camera samples with their direct light (the preliminary trace), indirect irradiance
//! interpolated over each hit's subtriangle from the radiance particles' cached estimates
//! (lists, gathering and estimation made first for particles without one), the shaded
//! radiance, and the aliased pixels that get more samples.
use super::gather::{self, Estimates};
use super::links::Target;
use super::radiance::{self, EstimationLists, RadianceKey, Tessellation};
use super::{ParticleGi, ParticleStats};
use crate::core::{Rgb, Rng};
use crate::technique::camera_chain::{self, CameraSample};
use crate::technique::RenderContext;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::time::Instant;

/// Pending samples per parallel chunk when gathering missing estimates.
const PENDING_CHUNK: usize = 1024;
/// Keys a chunk remembers to drop repeats (a small ring: neighbours share corners).
const RECENT_KEYS: usize = 16;

/// A subtriangle's three radiance particles with a point's barycentric weights.
type Corners = [(RadianceKey, radiance::Vertex, f32); 3];

/// The radiance particles around a camera sample's diffuse hit, on the side it sees.
fn sample_corners(tessellation: &Tessellation, s: &Shaded) -> Option<Corners> {
    let hit = s.sample.hit.as_ref()?;
    let side = u8::from(hit.n.dot(hit.wo) < 0.0);
    tessellation.corners(hit.object, hit.triangle, hit.uv, side)
}

/// The irradiance at a point of a subtriangle: its corners' cached estimates weighted by
/// their barycentric weights; `None` while a corner has no estimate.
fn interpolate(estimates: &Estimates, corners: &Corners) -> Option<Rgb> {
    let mut sum = Rgb::BLACK;
    for (k, _, w) in corners {
        sum += estimates.get(*k)? * *w;
    }
    let weights: f32 = corners.iter().map(|x| x.2).sum();
    Some(if weights > 0.0 { sum / weights } else { Rgb::BLACK })
}

/// One shaded camera sample.
pub(super) struct Sampled {
    pub(super) pixel: usize,
    pub(super) radiance: Rgb,
    /// `radiance` without the sampled direct light.
    steady: Rgb,
    object: Option<u32>,
}

/// One camera sample with its direct light.
pub(super) struct Shaded {
    pixel: usize,
    sample: CameraSample,
    direct: Rgb,
    shadow: bool,
}

impl ParticleGi {
    /// Camera samples `(pixel, sample)` with their direct light (the preliminary trace).
    fn trace(&mut self, ctx: &RenderContext, samples: &[(usize, u64)], stats: &mut ParticleStats) -> Vec<Shaded> {
        let t = Instant::now();
        let scene = ctx.scene;
        let shaded: Vec<Shaded> = samples
            .par_iter()
            .map(|&(pixel, sample)| {
                let mut rng = Rng::for_sample(ctx.seed, ctx.tick, pixel as u64, sample);
                let jitter = rng.next_2d();
                let s = camera_chain::trace(scene, ctx.accel, pixel, jitter, &mut rng);
                let (direct, shadow) = match &s.hit {
                    Some(hit) => camera_chain::direct_light(scene, ctx.accel, hit, &mut rng),
                    None => (Rgb::BLACK, None),
                };
                Shaded { pixel, sample: s, direct, shadow: shadow.is_some() }
            })
            .collect();
        stats.camera_rays += samples.len() as u64;
        stats.specular_rays += shaded.iter().map(|s| s.sample.specular_rays).sum::<u64>();
        stats.shadow_rays += shaded.iter().filter(|s| s.shadow).count() as u64;
        stats.trace_ms += t.elapsed().as_secs_f64() * 1e3;
        shaded
    }

    /// Indirect irradiance at each shaded sample, interpolated over its hit's subtriangle from
    /// the cached estimates; radiance particles without one get their lists, gathering and
    /// estimation first.
    fn indirect(&mut self, ctx: &RenderContext, shaded: &[Shaded], stats: &mut ParticleStats) -> Vec<Rgb> {
        let (Some(g), true) = (self.geometry.as_ref(), self.lighting.is_some()) else {
            return vec![Rgb::BLACK; shaded.len()];
        };
        let t = Instant::now();
        let corners = |s: &Shaded| sample_corners(&g.tessellation, s);
        let estimates = &self.estimates;
        let mut indirect: Vec<Option<Rgb>> =
            shaded.par_iter().map(|s| corners(s).map_or(Some(Rgb::BLACK), |c| interpolate(estimates, &c))).collect();
        let pending: Vec<usize> = (0..shaded.len()).filter(|&i| indirect[i].is_none()).collect();
        if pending.is_empty() {
            stats.preliminary_ms += t.elapsed().as_secs_f64() * 1e3;
            return indirect.into_iter().map(|e| e.unwrap_or(Rgb::BLACK)).collect();
        }
        // After a light move every sample is pending: their corners are gathered in parallel,
        // chunk by chunk, dropping a key just seen (neighbouring samples share corners), and
        // the chunks' few keys are deduplicated in sample order.
        let chunks: Vec<Vec<(RadianceKey, radiance::Vertex)>> = pending
            .par_chunks(PENDING_CHUNK)
            .map(|chunk| {
                let mut recent = [RadianceKey::MAX; RECENT_KEYS];
                let mut out = Vec::new();
                for (k, v, _) in chunk.iter().filter_map(|&i| corners(&shaded[i])).flatten() {
                    if !recent.contains(&k) && estimates.get(k).is_none() {
                        recent[out.len() % RECENT_KEYS] = k;
                        out.push((k, v));
                    }
                }
                out
            })
            .collect();
        let missing = estimates.missing(chunks.into_iter().flatten());
        stats.preliminary_ms += t.elapsed().as_secs_f64() * 1e3;
        self.estimate_missing(ctx, &missing, stats);
        let t = Instant::now();
        let Some(g) = self.geometry.as_ref() else { return vec![Rgb::BLACK; shaded.len()] };
        let estimates = &self.estimates;
        let filled: Vec<Option<Rgb>> = pending
            .par_iter()
            .map(|&i| sample_corners(&g.tessellation, &shaded[i]).and_then(|c| interpolate(estimates, &c)))
            .collect();
        for (&i, value) in pending.iter().zip(filled) {
            indirect[i] = value;
        }
        stats.preliminary_ms += t.elapsed().as_secs_f64() * 1e3;
        indirect.into_iter().map(|e| e.unwrap_or(Rgb::BLACK)).collect()
    }

    /// Lists, gathering and estimation for the radiance particles `missing`, whose estimates
    /// are then cached.
    fn estimate_missing(
        &mut self,
        ctx: &RenderContext,
        missing: &[(RadianceKey, radiance::Vertex)],
        stats: &mut ParticleStats,
    ) {
        let (Some(g), true) = (self.geometry.as_mut(), self.lighting.is_some()) else { return };
        let t = Instant::now();
        let (radius, cosine) = (self.config.estimation_radius * g.spacing, self.config.estimation_cosine);
        let built: Vec<(RadianceKey, radiance::EstimationList)> = missing
            .par_iter()
            .filter(|(k, _)| !g.lists.contains(*k))
            .map(|(k, v)| (*k, EstimationLists::build(ctx.scene, &g.particles, &g.grids, v, radius, cosine)))
            .collect();
        stats.lists_built += built.len() as u64;
        built.into_iter().for_each(|(k, l)| g.lists.insert(k, l));
        stats.geometry_ms += t.elapsed().as_secs_f64() * 1e3;
        let keys: Vec<RadianceKey> = missing.iter().map(|(k, _)| *k).collect();
        self.gather_and_store(ctx, &keys, stats);
    }

    /// Gathering (with the lazy links it needs) and estimation for the radiance particles
    /// `keys`, whose lists exist; their estimates are then cached.
    pub(super) fn gather_and_store(&mut self, ctx: &RenderContext, keys: &[RadianceKey], stats: &mut ParticleStats) {
        let (Some(g), Some(lighting)) = (self.geometry.as_mut(), self.lighting.as_ref()) else { return };
        let t = Instant::now();
        let wanted = gather::particles_to_gather(&g.lists, keys, g.particles.len());
        let lazily = g.gather.ensure(Target::new(ctx, &g.particles, &g.grids), wanted.iter().copied());
        stats.links_traced += lazily;
        stats.links_built_lazily += lazily;
        stats.geometry_ms += t.elapsed().as_secs_f64() * 1e3;

        let t = Instant::now();
        let gathered = gather::gather(&g.gather, lighting, &wanted, &g.particles);
        stats.area_particles_gathered += wanted.len() as u64;
        stats.gathering_ms += t.elapsed().as_secs_f64() * 1e3;

        let t = Instant::now();
        let values = gather::estimate(&g.lists, keys, &gathered, &g.particles.areas, lighting.shares);
        self.estimates.store(keys, &values);
        stats.radiance_particles_estimated += keys.len() as u64;
        stats.estimation_ms += t.elapsed().as_secs_f64() * 1e3;
    }

    /// Each shaded sample's pixel, radiance (emission, direct light, and ρ/π times the indirect
    /// irradiance) and its noise-free part (without the sampled direct light), with the object hit.
    pub(super) fn shade(
        &mut self,
        ctx: &RenderContext,
        samples: &[(usize, u64)],
        stats: &mut ParticleStats,
    ) -> Vec<Sampled> {
        let shaded = self.trace(ctx, samples, stats);
        let indirect = self.indirect(ctx, &shaded, stats);
        let t = Instant::now();
        let out = shaded
            .par_iter()
            .zip(indirect)
            .map(|(s, e)| {
                let reflected = match &s.sample.hit {
                    Some(hit) => hit.beta * hit.material(ctx.scene).diffuse_reflectance() * e * FRAC_1_PI,
                    None => Rgb::BLACK,
                };
                let steady = s.sample.emitted + reflected;
                Sampled { pixel: s.pixel, radiance: steady + s.direct, steady, object: s.sample.hit.map(|h| h.object) }
            })
            .collect();
        stats.final_ms += t.elapsed().as_secs_f64() * 1e3;
        out
    }

    /// Pixels that differ from the right or lower neighbour (the paper's aliased pixels): they
    /// see another object, or their noise-free radiance differs by more than the relative
    /// contrast. The sampled direct light is left out, or its noise would mark most pixels.
    pub(super) fn aliased(&self, first: &[Sampled], width: usize) -> Vec<usize> {
        let contrast = self.config.supersample_contrast;
        let y: Vec<f32> = first.iter().map(|s| s.steady.luminance()).collect();
        let differs = |a: usize, b: usize| {
            first[a].object != first[b].object || (y[a] - y[b]).abs() > contrast * y[a].max(y[b]).max(1e-6)
        };
        let mut marked = vec![false; y.len()];
        for i in 0..y.len() {
            for j in [i + 1, i + width] {
                let same_row = j != i + 1 || (i + 1) % width != 0;
                if j < y.len() && same_row && differs(i, j) {
                    marked[i] = true;
                    marked[j] = true;
                }
            }
        }
        (0..y.len()).filter(|&i| marked[i]).collect()
    }
}
