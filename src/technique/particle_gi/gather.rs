//! Indirect light gathering and radiance estimation (Chang et al. §4.3.1–4.3.2), run only for
//! radiance particles the camera needs and whose estimate is not cached.
//!
//! Gathering: Ẽ_i = π/N Σ_k L(end_k) over particle i's N gathering links (cosine-weighted, so
//! the cosine and the pdf cancel); links ending nowhere or on specular surfaces add nothing.
//! Ẽ is indirect irradiance only: the links carry light reflected by surfaces, and emitters are
//! not linked. Estimation at a radiance particle: Σφ̃/ΣΔA over its list, φ̃ = Ẽ·ΔA (W/m²);
//! the shading point multiplies by ρ/π.
//!
//! Beyond the paper, estimates are cached per radiance particle and per lighting share
//! (`lighting.rs`), indexed directly by the radiance key (dense within each object's key
//! space: `id << 1 | side` below twice the object's count). They hold while the field and the lists do: a
//! still view or a camera move estimates only the radiance particles it sees for the first
//! time, and an intensity edit scales its share's estimates like the field. Any other change
//! of the field (a light moved, a material edited, links retraced) gathers again, in place,
//! the estimates stored since the camera last moved whose lists still hold, and forgets the
//! rest: the render then finds the view's estimates ready instead of missing them all.
use super::lighting::Lighting;
use super::links::{LinkSet, NON_DIFFUSE};
use super::particles::AreaParticles;
use super::radiance::{key_parts, EstimationLists, RadianceKey, Tessellation, OBJECT_SHIFT};
use crate::core::Rgb;
use rayon::prelude::*;
use std::f32::consts::PI;

/// Cached estimates Ē (W/m²) per radiance key and share: per object, key k's share g at
/// `k * shares + g` of the object's space.
#[derive(Clone, Debug, Default)]
pub struct Estimates {
    shares: usize,
    values: Vec<Vec<Rgb>>,
    valid: Vec<Vec<bool>>,
    /// Stored since the camera last moved: what a lighting change gathers again in place.
    fresh: Vec<Vec<bool>>,
}

impl Estimates {
    /// An empty cache for the radiance particles of `tessellation` (both sides each).
    pub fn new(tessellation: &Tessellation, shares: usize) -> Estimates {
        let mut e = Estimates { shares, values: Vec::new(), valid: Vec::new(), fresh: Vec::new() };
        for &count in &tessellation.counts {
            e.values.push(vec![Rgb::BLACK; 2 * count as usize * shares]);
            e.valid.push(vec![false; 2 * count as usize]);
            e.fresh.push(vec![false; 2 * count as usize]);
        }
        e
    }

    /// Empties one object's space, sized for its `count` radiance particles (re-tessellated).
    pub fn reset_object(&mut self, object: usize, count: u64) {
        self.values[object] = vec![Rgb::BLACK; 2 * count as usize * self.shares];
        self.valid[object] = vec![false; 2 * count as usize];
        self.fresh[object] = vec![false; 2 * count as usize];
    }

    /// Forgets every estimate (the field or the lists changed).
    pub fn invalidate(&mut self) {
        self.valid.iter_mut().chain(&mut self.fresh).flatten().for_each(|v| *v = false);
    }

    /// The camera moved: the estimates stay valid, but none is fresh.
    pub fn age(&mut self) {
        self.fresh.iter_mut().flatten().for_each(|v| *v = false);
    }

    /// The keys with a valid estimate stored since the camera last moved, in key order.
    pub fn fresh_keys(&self) -> Vec<RadianceKey> {
        let per_object = self.valid.iter().zip(&self.fresh).enumerate();
        per_object
            .flat_map(|(object, (valid, fresh))| {
                let kept = valid.iter().zip(fresh).enumerate().filter(|(_, (&v, &f))| v && f);
                kept.map(move |(k, _)| (object as RadianceKey) << OBJECT_SHIFT | k as RadianceKey)
            })
            .collect()
    }

    /// Multiplies share `g` by `factor`, as [`Lighting::scale`] does the field.
    pub fn scale(&mut self, g: usize, factor: Rgb) {
        for values in &mut self.values {
            for k in (g..values.len()).step_by(self.shares.max(1)) {
                values[k] *= factor;
            }
        }
    }

    fn is_valid(&self, key: RadianceKey) -> Option<bool> {
        let (object, k) = key_parts(key);
        self.valid.get(object)?.get(k).copied()
    }

    /// The estimate of `key`, summed over the shares, if cached.
    pub fn get(&self, key: RadianceKey) -> Option<Rgb> {
        let (object, k) = key_parts(key);
        self.is_valid(key)?
            .then(|| self.values[object][k * self.shares..(k + 1) * self.shares].iter().fold(Rgb::BLACK, |s, &v| s + v))
    }

    /// The distinct keys of `keys` (each with what goes with it) that have no cached
    /// estimate, in key order.
    pub fn missing<T>(&self, keys: impl Iterator<Item = (RadianceKey, T)>) -> Vec<(RadianceKey, T)> {
        // Dedup by a flag per key, not by sorting every sample's corners: after a light move
        // every sample misses, and the distinct keys are a small fraction of them.
        let mut seen: Vec<Vec<bool>> = self.valid.iter().map(|v| vec![false; v.len()]).collect();
        let mut missing: Vec<(RadianceKey, T)> = keys
            .filter(|(k, _)| {
                let (object, i) = key_parts(*k);
                let first = self.valid.get(object).and_then(|v| v.get(i)) == Some(&false) && !seen[object][i];
                if first {
                    seen[object][i] = true;
                }
                first
            })
            .collect();
        missing.sort_unstable_by_key(|(k, _)| *k);
        missing
    }

    /// Stores the estimates of `keys` (`values` as [`estimate`] returns them).
    pub fn store(&mut self, keys: &[RadianceKey], values: &[Rgb]) {
        let shares = self.shares;
        for (n, &key) in keys.iter().enumerate() {
            let (object, k) = key_parts(key);
            self.values[object][k * shares..(k + 1) * shares].copy_from_slice(&values[n * shares..(n + 1) * shares]);
            (self.valid[object][k], self.fresh[object][k]) = (true, true);
        }
    }

    pub fn cached(&self) -> u64 {
        self.valid.iter().flatten().filter(|&&v| v).count() as u64
    }

    pub fn memory_bytes(&self) -> u64 {
        let values: usize = self.values.iter().map(Vec::len).sum();
        let flags: usize = self.valid.iter().chain(&self.fresh).map(Vec::len).sum();
        (values * std::mem::size_of::<Rgb>() + flags) as u64
    }
}

/// Ẽ per share for each particle in `needed` (dense, particle i's share g at
/// `i * shares + g`, zero elsewhere), each link's radiance weighted by its shading factor.
pub fn gather(links: &LinkSet, lighting: &Lighting, needed: &[u32], particles: &AreaParticles) -> Vec<Rgb> {
    let (per, shares) = (links.per_particle(), lighting.shares);
    let values: Vec<Rgb> = needed
        .par_iter()
        .flat_map_iter(|&i| {
            let ends = links.ends_of(i as usize);
            (0..shares).map(move |g| {
                let sum = ends.iter().enumerate().filter(|(_, &e)| e < NON_DIFFUSE).fold(Rgb::BLACK, |s, (k, &e)| {
                    s + lighting.radiance[e as usize * shares + g] * links.receive_factor(particles, i as usize, k)
                });
                sum * (PI / per as f32)
            })
        })
        .collect();
    let mut dense = vec![Rgb::BLACK; particles.len() * shares];
    for (&i, v) in needed.iter().zip(values.chunks_exact(shares)) {
        dense[i as usize * shares..(i as usize + 1) * shares].copy_from_slice(v);
    }
    dense
}

/// The area particles in the lists of `keys`, each once, in index order.
pub fn particles_to_gather(lists: &EstimationLists, keys: &[RadianceKey], particles: usize) -> Vec<u32> {
    let mut wanted = vec![false; particles];
    for k in keys {
        if let Some(l) = lists.get(*k) {
            l.particles.iter().for_each(|&i| wanted[i as usize] = true);
        }
    }
    (0..particles as u32).filter(|&i| wanted[i as usize]).collect()
}

/// Ē (W/m²) per share at each radiance particle of `keys` (key n's share g at
/// `n * shares + g`): Σ Ẽ_m ΔA_m / Σ ΔA_m over its list.
pub fn estimate(
    lists: &EstimationLists,
    keys: &[RadianceKey],
    gathered: &[Rgb],
    areas: &[f32],
    shares: usize,
) -> Vec<Rgb> {
    keys.par_iter()
        .flat_map_iter(|k| {
            let list = lists.get(*k).map_or(&[][..], |l| &l.particles[..]);
            let area: f32 = list.iter().map(|&i| areas[i as usize]).sum();
            (0..shares).map(move |g| {
                let flux =
                    list.iter().fold(Rgb::BLACK, |f, &i| f + gathered[i as usize * shares + g] * areas[i as usize]);
                if area > 0.0 {
                    flux / area
                } else {
                    Rgb::BLACK
                }
            })
        })
        .collect()
}
