//! The lighting stage (Chang et al. §4.2): flux from the lights onto the area particles, then
//! scattered along the links. Run whenever lights, materials or geometry change.
//!
//! Emission (§4.2.1): a point or spot light gives each front-facing particle it sees
//! I·ΔA_i·cos θ/d² (the paper's Φ/4π · ΔA cos θ/d²); an area light is sampled `samples` times
//! per particle (E = mean L cos θ/pdf, flux E·ΔA); visibility by occlusion rays.
//! Scattering (§4.2.2): every directly lit particle i sends ρ_i φ_i/n_s² along each of its
//! n_s² scattering links; from each end the packet walks n_b more bounces, each time reflecting
//! ρ of itself into the end of one random link. φ_i is the direct flux plus all deposits, and
//! L_i = ρ_i/π · φ_i/ΔA_i (direct and indirect reflected radiance). The walks' random links are
//! seeded by (seed, particle, link), never by the tick, so the same scene gives the same field.
use super::links::{LinkSet, NON_DIFFUSE};
use super::particles::AreaParticles;
use crate::core::{offset_ray_origin, Rgb, Rng};
use crate::embree::Ray;
use crate::scene::{Scene, SceneAccel};
use crate::technique::nee::SHADOW_EPSILON;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;

/// Partial sums of the scattering step.
const SCATTER_CHUNKS: usize = 8;

/// The flux field over the area particles.
#[derive(Clone, Debug, Default)]
pub struct FluxField {
    /// Reflected radiance L = ρ/π · φ/ΔA per particle.
    pub radiance: Vec<Rgb>,
    pub lit: u64,
    pub deposits: u64,
}

/// Direct flux per particle from every light, and the visibility rays traced.
pub fn emit(scene: &Scene, accel: &SceneAccel, particles: &AreaParticles, samples: u32, seed: u64) -> (Vec<Rgb>, u64) {
    let results: Vec<(Rgb, u64)> = (0..particles.len())
        .into_par_iter()
        .map(|i| {
            let (p, n) = (particles.position[i], particles.normal[i]);
            let origin = offset_ray_origin(p, n);
            let mut rng = Rng::new(seed ^ 0x454D_4954, i as u64); // "EMIT"
            let (mut irradiance, mut rays) = (Rgb::BLACK, 0u64);
            for light in &scene.lights {
                let count = if light.geometry.is_delta() { 1 } else { samples };
                let mut sum = Rgb::BLACK;
                for _ in 0..count {
                    let Some(s) = light.geometry.sample_incident(origin, rng.next_2d()) else { continue };
                    let cos = s.wi.dot(n);
                    if cos <= 0.0 || s.pdf <= 0.0 || s.li.is_black() {
                        continue;
                    }
                    rays += 1;
                    let shadow = Ray { origin, dir: s.wi, tnear: 0.0, tfar: s.dist * (1.0 - SHADOW_EPSILON) };
                    if !accel.scene().occluded1(&shadow) {
                        sum += s.li * (cos / s.pdf);
                    }
                }
                irradiance += sum / count as f32;
            }
            (irradiance * particles.areas[i], rays)
        })
        .collect();
    let rays = results.iter().map(|r| r.1).sum();
    (results.into_iter().map(|r| r.0).collect(), rays)
}

/// Scatters the direct flux along the scattering links: the first bounce through every link,
/// then `bounces` single-link bounces. Returns the field.
pub fn scatter(
    scene: &Scene,
    particles: &AreaParticles,
    links: &LinkSet,
    direct: Vec<Rgb>,
    bounces: u32,
    seed: u64,
) -> FluxField {
    let per = links.per_particle();
    let rho: Vec<Rgb> = (0..particles.len()).map(|i| particles.reflectance(scene, i)).collect();
    let lit: Vec<usize> = (0..particles.len()).filter(|&i| !direct[i].is_black()).collect();
    // A fixed number of partial sums, added in order: the result does not depend on threads.
    let chunk = lit.len().div_ceil(SCATTER_CHUNKS).max(1);
    let partial: Vec<(Vec<Rgb>, u64)> = lit
        .par_chunks(chunk)
        .map(|sources| {
            let mut acc = vec![Rgb::BLACK; particles.len()];
            let mut count = 0u64;
            for &i in sources {
                let packet = rho[i] * direct[i] / per as f32;
                for k in 0..per {
                    let mut at = links.ends[i * per + k];
                    if at >= NON_DIFFUSE {
                        continue;
                    }
                    let mut carried = packet;
                    acc[at as usize] += carried;
                    count += 1;
                    let mut rng = Rng::new(seed ^ 0x5343_4154, (i * per + k) as u64); // "SCAT"
                    for _ in 0..bounces {
                        carried = rho[at as usize] * carried;
                        let pick = (rng.next_u32() as usize) % per;
                        let next = links.ends[at as usize * per + pick];
                        if next >= NON_DIFFUSE || carried.is_black() {
                            break;
                        }
                        acc[next as usize] += carried;
                        count += 1;
                        at = next;
                    }
                }
            }
            (acc, count)
        })
        .collect();
    let mut deposited = vec![Rgb::BLACK; particles.len()];
    let mut deposits = 0;
    for (acc, count) in partial {
        deposited.iter_mut().zip(acc).for_each(|(x, y)| *x += y);
        deposits += count;
    }
    // φ = direct + scattered flux (W); L = ρ/π · φ/ΔA.
    let radiance =
        (0..particles.len()).map(|i| rho[i] * FRAC_1_PI * (direct[i] + deposited[i]) / particles.areas[i]).collect();
    FluxField { radiance, lit: lit.len() as u64, deposits }
}
