//! Indirect light gathering and radiance estimation (Chang et al. §4.3.1–4.3.2), run each tick
//! only for what the camera needs.
//!
//! Gathering: Ẽ_i = π/N Σ_k L(end_k) over particle i's N gathering links (cosine-weighted, so
//! the cosine and the pdf cancel); links ending nowhere or on specular surfaces add nothing.
//! Ẽ is indirect irradiance only: the links carry light reflected by surfaces, and emitters are
//! not linked. Estimation at a radiance particle: Σφ̃/ΣΔA over its list, φ̃ = Ẽ·ΔA (W/m²);
//! the shading point multiplies by ρ/π.
use super::lighting::FluxField;
use super::links::{LinkSet, NON_DIFFUSE};
use super::radiance::{EstimationLists, RadianceKey};
use crate::core::Rgb;
use rayon::prelude::*;
use std::f32::consts::PI;

/// Ẽ for each particle in `needed` (a dense array, zero elsewhere).
pub fn gather(links: &LinkSet, field: &FluxField, needed: &[u32], particles: usize) -> Vec<Rgb> {
    let per = links.per_particle();
    let values: Vec<Rgb> = needed
        .par_iter()
        .map(|&i| {
            let ends = &links.ends[i as usize * per..(i as usize + 1) * per];
            let sum =
                ends.iter().filter(|&&e| e < NON_DIFFUSE).fold(Rgb::BLACK, |s, &e| s + field.radiance[e as usize]);
            sum * (PI / per as f32)
        })
        .collect();
    let mut dense = vec![Rgb::BLACK; particles];
    for (&i, v) in needed.iter().zip(values) {
        dense[i as usize] = v;
    }
    dense
}

/// The area particles in the lists of `keys`, each once, in index order.
pub fn particles_to_gather(lists: &EstimationLists, keys: &[RadianceKey], particles: usize) -> Vec<u32> {
    let mut wanted = vec![false; particles];
    for k in keys {
        if let Some(l) = lists.lists.get(k) {
            l.particles.iter().for_each(|&i| wanted[i as usize] = true);
        }
    }
    (0..particles as u32).filter(|&i| wanted[i as usize]).collect()
}

/// Ē (W/m²) at each radiance particle of `keys`, in the same order: Σ Ẽ_m ΔA_m / Σ ΔA_m over
/// its list.
pub fn estimate(lists: &EstimationLists, keys: &[RadianceKey], gathered: &[Rgb], areas: &[f32]) -> Vec<Rgb> {
    keys.par_iter()
        .map(|k| {
            let (flux, area) = lists.lists.get(k).map_or((Rgb::BLACK, 0.0), |l| {
                l.particles.iter().fold((Rgb::BLACK, 0.0f32), |(f, a), &i| {
                    (f + gathered[i as usize] * areas[i as usize], a + areas[i as usize])
                })
            });
            if area > 0.0 {
                flux / area
            } else {
                Rgb::BLACK
            }
        })
        .collect()
}
