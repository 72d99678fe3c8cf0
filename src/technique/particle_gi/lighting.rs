//! The lighting stage (Chang et al. §4.2): flux from the lights onto the area particles, then
//! scattered along the links, kept per light so a light edit redoes only that light's share.
//!
//! Emission (§4.2.1): a point or spot light gives each front-facing particle it sees
//! I·ΔA_i·cos θ/d² (the paper's Φ/4π · ΔA cos θ/d²); an area light is sampled `samples` times
//! per particle (E = mean L cos θ/pdf, flux E·ΔA); visibility by occlusion rays.
//! Scattering (§4.2.2): every directly lit particle i sends ρ_i φ_i/n_s² along each of its
//! n_s² scattering links; from each end the packet walks n_b more bounces, each time reflecting
//! ρ of itself into the end of one random link. φ_i is the direct flux plus all deposits, and
//! L_i = ρ_i/π · φ_i/ΔA_i (direct and indirect reflected radiance).
//!
//! # Shares (beyond the paper)
//! Transport is linear in the emitted flux, so the field is kept as the sum of per-light
//! shares: light l belongs to share l mod G, G = min(lights, [`MAX_SHARES`]). An intensity or
//! colour edit of a light alone in its share multiplies that share by the exact factor new/old
//! (no rays, no walks); a light move re-emits and re-scatters its share only; a material edit
//! keeps every share's direct flux (which does not depend on ρ) and re-scatters. A walk visits
//! the same particles for every share (its random links are seeded by (seed, particle, link),
//! never by the tick or the light), so one walk carries all the shares being recomputed.
//! Emission samples are seeded by (seed, light, particle): the same scene gives the same field
//! whichever edits led to it.
use super::links::{LinkSet, NON_DIFFUSE};
use super::particles::AreaParticles;
use crate::core::{offset_ray_origin, Rgb, Rng};
use crate::embree::Ray;
use crate::scene::{Normals, Scene, SceneAccel};
use crate::technique::nee::SHADOW_EPSILON;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::time::Instant;

/// Most shares kept: lights beyond share a slot, and an edit to one recomputes the slot.
pub const MAX_SHARES: usize = 8;

/// Partial sums of the scattering step, at most; fewer when they would exceed
/// [`SCATTER_BYTES`] between them. Fixed by sizes only, so results never depend on threads.
const SCATTER_CHUNKS: usize = 8;
const SCATTER_BYTES: usize = 256 << 20;

/// Direct flux and reflected radiance per particle and share (W and W/(m² sr)), interleaved:
/// particle i's share g at `i * shares + g`.
#[derive(Clone, Debug, Default)]
pub struct Lighting {
    pub shares: usize,
    direct: Vec<Rgb>,
    pub radiance: Vec<Rgb>,
}

/// What one lighting run did.
#[derive(Clone, Copy, Debug, Default)]
pub struct LightingWork {
    pub emission_rays: u64,
    pub lit: u64,
    pub deposits: u64,
    pub emission_ms: f64,
    pub scattering_ms: f64,
}

/// The number of shares for `lights` lights.
pub fn share_count(lights: usize) -> usize {
    lights.clamp(1, MAX_SHARES)
}

/// Whether light `light`'s share holds that light alone.
pub fn alone_in_share(light: usize, lights: usize) -> bool {
    light < lights && lights <= MAX_SHARES
}

/// The inputs every lighting run reads.
pub struct Inputs<'a> {
    pub scene: &'a Scene,
    pub accel: &'a SceneAccel,
    pub particles: &'a AreaParticles,
    pub samples: u32,
    pub bounces: u32,
    pub seed: u64,
}

impl Lighting {
    /// A field with no flux yet, for `particles` particles and `lights` lights' shares.
    pub fn new(particles: usize, lights: usize) -> Lighting {
        let shares = share_count(lights);
        let zeros = vec![Rgb::BLACK; particles * shares];
        Lighting { shares, direct: zeros.clone(), radiance: zeros }
    }

    /// Re-emits the direct flux of the shares marked in `emit`.
    pub fn emit(&mut self, inputs: &Inputs, emit: &[bool]) -> LightingWork {
        let t = Instant::now();
        let rays = if emit.contains(&true) { emit_flux(inputs, &mut self.direct, emit) } else { 0 };
        LightingWork { emission_rays: rays, emission_ms: t.elapsed().as_secs_f64() * 1e3, ..LightingWork::default() }
    }

    /// The particles with direct flux in a share marked in `shares`: where walks start.
    pub fn lit(&self, shares: &[bool]) -> Vec<u32> {
        let lit = |i: &usize| (0..self.shares).any(|g| shares[g] && !self.direct[i * self.shares + g].is_black());
        (0..self.direct.len() / self.shares.max(1)).filter(lit).map(|i| i as u32).collect()
    }

    /// Re-scatters the shares marked in `scatter` from their kept direct flux along `links`
    /// (built for every particle the walks from [`Lighting::lit`] reach).
    pub fn scatter(&mut self, inputs: &Inputs, links: &LinkSet, scatter: &[bool]) -> LightingWork {
        let t = Instant::now();
        let (deposited, mut work) = scatter_flux(inputs, links, &self.direct, self.shares, scatter);
        let marked: Vec<usize> = (0..self.shares).filter(|&g| scatter[g]).collect();
        let (particles, scene) = (inputs.particles, inputs.scene);
        for i in 0..particles.len() {
            let rho = particles.reflectance(scene, i) * FRAC_1_PI / particles.areas[i];
            for (m, &g) in marked.iter().enumerate() {
                let k = i * self.shares + g;
                self.radiance[k] = rho * (self.direct[k] + deposited[i * marked.len() + m]);
            }
        }
        work.scattering_ms = t.elapsed().as_secs_f64() * 1e3;
        work
    }

    /// Multiplies share `g` by `factor` per channel: an intensity edit of its only light.
    pub fn scale(&mut self, g: usize, factor: Rgb) {
        for k in (g..self.radiance.len()).step_by(self.shares) {
            self.direct[k] *= factor;
            self.radiance[k] *= factor;
        }
    }

    pub fn memory_bytes(&self) -> u64 {
        ((self.direct.len() + self.radiance.len()) * std::mem::size_of::<Rgb>()) as u64
    }
}

/// Direct flux per particle from the lights of the marked shares, written into `direct`.
/// Returns the visibility rays traced.
fn emit_flux(inputs: &Inputs, direct: &mut [Rgb], redo: &[bool]) -> u64 {
    let shares = redo.len();
    let lights: Vec<usize> = (0..inputs.scene.lights.len()).filter(|l| redo[l % shares]).collect();
    direct
        .par_chunks_mut(shares)
        .enumerate()
        .map(|(i, out)| {
            let normals = inputs.particles.normals(i);
            let origin = offset_ray_origin(inputs.particles.position[i], normals.geometric);
            (0..shares).filter(|&g| redo[g]).for_each(|g| out[g] = Rgb::BLACK);
            let mut rays = 0u64;
            for &l in &lights {
                let (irradiance, traced) = irradiance_from(inputs, l, i, origin, normals);
                out[l % shares] += irradiance * inputs.particles.areas[i];
                rays += traced;
            }
            rays
        })
        .sum()
}

/// Irradiance from light `l` at particle `i` (seen from `origin` with `normals`), about its
/// shading normal, and the rays traced.
fn irradiance_from(inputs: &Inputs, l: usize, i: usize, origin: glam::Vec3, normals: Normals) -> (Rgb, u64) {
    let n = normals.geometric;
    let light = &inputs.scene.lights[l];
    let mut rng = Rng::new(inputs.seed ^ 0x454D_4954 ^ ((l as u64) << 32), i as u64); // "EMIT"
    let count = if light.geometry.is_delta() { 1 } else { inputs.samples };
    let (mut sum, mut rays) = (Rgb::BLACK, 0u64);
    for _ in 0..count {
        let Some(s) = light.geometry.sample_incident(origin, n, rng.next_2d()) else { continue };
        let cos = s.wi.dot(n);
        if cos <= 0.0 || s.pdf <= 0.0 || s.li.is_black() {
            continue;
        }
        rays += 1;
        let shadow = Ray { origin, dir: s.wi, tnear: 0.0, tfar: s.dist * (1.0 - SHADOW_EPSILON) };
        if !inputs.accel.scene().occluded1(&shadow) {
            sum += s.li * (cos * normals.diffuse_factor(s.wi) / s.pdf);
        }
    }
    (sum / count as f32, rays)
}

/// Scatters the marked shares' direct flux along the scattering links: the first bounce
/// through every link, then `bounces` single-link bounces. Returns the deposits per particle
/// and marked share (`i * marked + m`, the m-th marked share).
fn scatter_flux(
    inputs: &Inputs,
    links: &LinkSet,
    direct: &[Rgb],
    shares: usize,
    redo: &[bool],
) -> (Vec<Rgb>, LightingWork) {
    let particles = inputs.particles;
    let per = links.per_particle();
    let marked: Vec<usize> = (0..shares).filter(|&g| redo[g]).collect();
    let width = marked.len();
    let rho: Vec<Rgb> = (0..particles.len()).map(|i| particles.reflectance(inputs.scene, i)).collect();
    let lit: Vec<usize> =
        (0..particles.len()).filter(|&i| marked.iter().any(|&g| !direct[i * shares + g].is_black())).collect();
    let bytes = (particles.len() * width * std::mem::size_of::<Rgb>()).max(1);
    let chunks = (SCATTER_BYTES / bytes).clamp(1, SCATTER_CHUNKS);
    let chunk = lit.len().div_ceil(chunks).max(1);
    let partial: Vec<(Vec<Rgb>, u64)> = lit
        .par_chunks(chunk)
        .map(|sources| {
            let mut acc = vec![Rgb::BLACK; particles.len() * width];
            let mut count = 0u64;
            let mut packets = vec![Rgb::BLACK; width];
            for &i in sources {
                for (m, &g) in marked.iter().enumerate() {
                    packets[m] = rho[i] * direct[i * shares + g] / per as f32;
                }
                for k in 0..per {
                    count += walk(inputs, links, &rho, (i, k), &packets, &mut acc);
                }
            }
            (acc, count)
        })
        .collect();
    let mut deposited = vec![Rgb::BLACK; particles.len() * width];
    let mut deposits = 0;
    // Added in chunk order: the result does not depend on threads.
    for (acc, count) in partial {
        deposited.iter_mut().zip(acc).for_each(|(x, y)| *x += y);
        deposits += count;
    }
    (deposited, LightingWork { lit: lit.len() as u64, deposits, ..LightingWork::default() })
}

/// One scattering link's walk from particle `i` through link `k`: deposits the packets,
/// times the reflectances and shading factors met, at each particle reached. Returns the
/// deposits made.
fn walk(
    inputs: &Inputs,
    links: &LinkSet,
    rho: &[Rgb],
    (i, k): (usize, usize),
    packets: &[Rgb],
    acc: &mut [Rgb],
) -> u64 {
    let (bounces, seed, particles) = (inputs.bounces, inputs.seed, inputs.particles);
    let per = links.per_particle();
    let width = packets.len();
    let mut at = links.ends_of(i)[k];
    if at >= NON_DIFFUSE {
        return 0;
    }
    let deposit = |acc: &mut [Rgb], at: u32, throughput: Rgb| {
        let base = at as usize * width;
        for (m, p) in packets.iter().enumerate() {
            acc[base + m] += throughput * *p;
        }
    };
    let mut throughput = Rgb::splat(links.deposit_factor(particles, i, k, at as usize));
    deposit(acc, at, throughput);
    let mut count = 1;
    let mut rng = Rng::new(seed ^ 0x5343_4154, (i * per + k) as u64); // "SCAT"
    for _ in 0..bounces {
        throughput = rho[at as usize] * throughput;
        let pick = (rng.next_u32() as usize) % per;
        let next = links.ends_of(at as usize)[pick];
        if next >= NON_DIFFUSE || throughput.is_black() {
            break;
        }
        throughput *= links.deposit_factor(particles, at as usize, pick, next as usize);
        deposit(acc, next, throughput);
        count += 1;
        at = next;
    }
    count
}
