//! Rendering a frame from the photon paths: camera rays follow ideal mirror and glass chains to
//! the first diffuse hit, where direct light comes from next-event estimation and indirect light
//! from a density estimate over the stored photons.
//!
//! The density estimate uses photons from the second bounce on (the first hit of a path is
//! direct light, which NEE already counts; light reaching a diffuse surface through a specular
//! chain is counted by photons) with a uniform disc kernel of radius r:
//! L_o(x, ω_o) ≈ Σ_p f_r(ω_o, ω_p) Φ_p / (π r²) over photons within r whose surface faces the
//! same way as the query's side (normals within 60°), so thin walls and corners do not leak. The paper splats photons in screen space on a GPU; on the CPU a gather through a
//! spatial hash grid (cell size 2r, so a query visits at most 8 cells) is the natural
//! equivalent, and it costs work per pixel rather than per photon.
use super::store::PathStore;
use crate::core::{Rgb, Rng};
use crate::film::PixelAccum;
use crate::scene::{Material, Scene, SceneAccel, SurfaceId};
use crate::technique::camera_chain;
use glam::{IVec3, Vec3};
use rayon::prelude::*;

/// Least cosine between a photon's surface normal and the query's for the photon to count.
const FACING_COSINE: f32 = 0.5;

#[derive(Clone, Copy, Debug)]
struct GridPhoton {
    position: Vec3,
    /// The unit geometric normal of the photon's surface, on the side the photon arrived from.
    /// Gathering needs only this: the Lambertian BRDF is constant on a side, and a query only
    /// accepts photons whose surface faces the way its own does (see [`PhotonGrid::radiance`]).
    facing: Vec3,
    power: Rgb,
}

/// Photons bucketed by a hash of their grid cell.
#[derive(Clone, Debug, Default)]
pub struct PhotonGrid {
    pub radius: f32,
    inv_cell: f32,
    mask: u64,
    /// `starts[b]..starts[b + 1]` are bucket b's photons.
    starts: Vec<u32>,
    /// Total flux of the gathered photons (W), summed in order in f64.
    pub power: [f64; 3],
    photons: Vec<GridPhoton>,
}

fn cell_of(p: Vec3, inv_cell: f32) -> IVec3 {
    (p * inv_cell).floor().as_ivec3()
}

fn bucket(c: IVec3, mask: u64) -> usize {
    let h = (c.x as i64 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (c.y as i64 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (c.z as i64 as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    (crate::core::rng::mix64(h) & mask) as usize
}

impl PhotonGrid {
    /// Gathers every photon from row 1 on that lies on a diffuse surface. Rows are read in
    /// parallel and keyed in parallel; the order (row, then path) and so the grid are the same
    /// whatever the thread count.
    pub fn build(scene: &Scene, store: &PathStore, radius: f32) -> PhotonGrid {
        let diffuse: Vec<bool> =
            scene.objects.iter().map(|o| !scene.materials[o.material as usize].is_specular()).collect();
        let mut photons = Vec::new();
        for (row_index, row) in store.rows.iter().enumerate().skip(1) {
            let gathered: Vec<GridPhoton> = (0..store.paths)
                .into_par_iter()
                .filter(|&path| store.word[path].photons() as usize > row_index && diffuse[row.object[path] as usize])
                .map(|path| {
                    let [a, b, c] = scene.triangle(SurfaceId::Object(row.object[path]), row.prim[path]);
                    let n = (b - a).cross(c - a).normalize_or_zero();
                    let incoming = row.incoming[path];
                    GridPhoton {
                        position: row.position[path],
                        facing: if n.dot(incoming) < 0.0 { n } else { -n },
                        power: row.power[path],
                    }
                })
                .collect();
            photons.extend(gathered);
        }
        let inv_cell = 1.0 / (2.0 * radius);
        let table = (photons.len().max(1) * 2).next_power_of_two();
        let mask = table as u64 - 1;
        // Counting sort by bucket.
        let keys: Vec<usize> = photons.par_iter().map(|p| bucket(cell_of(p.position, inv_cell), mask)).collect();
        let mut starts = vec![0u32; table + 1];
        for &k in &keys {
            starts[k + 1] += 1;
        }
        for i in 0..table {
            starts[i + 1] += starts[i];
        }
        let mut fill = starts.clone();
        let mut sorted =
            vec![GridPhoton { position: Vec3::ZERO, facing: Vec3::ZERO, power: Rgb::BLACK }; photons.len()];
        for (p, &k) in photons.iter().zip(&keys) {
            sorted[fill[k] as usize] = *p;
            fill[k] += 1;
        }
        let power = photons
            .iter()
            .fold([0.0f64; 3], |s, p| [s[0] + p.power.r as f64, s[1] + p.power.g as f64, s[2] + p.power.b as f64]);
        PhotonGrid { radius, inv_cell, mask, starts, photons: sorted, power }
    }

    pub fn len(&self) -> usize {
        self.photons.len()
    }

    pub fn is_empty(&self) -> bool {
        self.photons.is_empty()
    }

    pub fn memory_bytes(&self) -> u64 {
        (self.photons.len() * std::mem::size_of::<GridPhoton>() + self.starts.len() * 4) as u64
    }

    /// Reflected radiance at `p` (unit normal `n`) towards `wo` from photons within the radius.
    pub fn radiance(&self, material: &Material, p: Vec3, n: Vec3, wo: Vec3) -> Rgb {
        if self.photons.is_empty() {
            return Rgb::BLACK;
        }
        let r2 = self.radius * self.radius;
        let lo = cell_of(p - Vec3::splat(self.radius), self.inv_cell);
        let hi = cell_of(p + Vec3::splat(self.radius), self.inv_cell);
        let mut buckets = [usize::MAX; 8];
        let mut count = 0;
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let b = bucket(IVec3::new(x, y, z), self.mask);
                    if !buckets[..count].contains(&b) && count < 8 {
                        buckets[count] = b;
                        count += 1;
                    }
                }
            }
        }
        // Only photons on a surface facing the same way as this side of the query's: not the
        // other side of a thin wall, nor the inside face of a corner (a box seen from outside
        // would otherwise glow along its edges with the light inside it).
        let n_side = if n.dot(wo) >= 0.0 { n } else { -n };
        let mut sum = Rgb::BLACK;
        for &b in &buckets[..count] {
            for ph in &self.photons[self.starts[b] as usize..self.starts[b + 1] as usize] {
                if (ph.position - p).length_squared() <= r2 && ph.facing.dot(n_side) > FACING_COSINE {
                    sum += material.eval(n, wo, ph.facing) * ph.power;
                }
            }
        }
        sum / (std::f32::consts::PI * r2)
    }
}

/// Ray counts of one render pass.
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderRays {
    pub camera: u64,
    pub specular: u64,
    pub shadow: u64,
}

impl RenderRays {
    pub fn merge(self, o: RenderRays) -> RenderRays {
        RenderRays {
            camera: self.camera + o.camera,
            specular: self.specular + o.specular,
            shadow: self.shadow + o.shadow,
        }
    }
}

/// One sample for each pixel of `chunk` (pixels `first..`), added to the film.
pub fn render_chunk(
    scene: &Scene,
    accel: &SceneAccel,
    grid: &PhotonGrid,
    stream: (u64, u64, u64),
    first: usize,
    chunk: &mut [PixelAccum],
) -> RenderRays {
    let (seed, tick, pass) = stream;
    let mut rays = RenderRays::default();
    for (offset, pixel) in chunk.iter_mut().enumerate() {
        let index = first + offset;
        let mut rng = Rng::for_sample(seed, tick, index as u64, pass);
        let jitter = rng.next_2d();
        let sample = camera_chain::trace(scene, accel, index, jitter, &mut rng);
        rays.camera += 1;
        rays.specular += sample.specular_rays;
        let mut radiance = sample.emitted;
        if let Some(hit) = sample.hit {
            // Diffuse: direct light by NEE, indirect light from the photons.
            let (direct, traced) = camera_chain::direct_light(scene, accel, &hit, &mut rng);
            rays.shadow += u64::from(traced);
            radiance += direct + hit.beta * grid.radiance(hit.material(scene), hit.p, hit.n, hit.wo);
        }
        pixel.add(radiance);
        pixel.count += 1.0;
    }
    rays
}
