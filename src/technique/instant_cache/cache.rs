//! The instant cache (Debattista et al. §3.1): irradiance records computed from the VPLs at a
//! sparse set of points and interpolated elsewhere (eq. 4).
//!
//! A record holds its position, its normal (on the side it was seen from), its irradiance and,
//! per VPL, that VPL's contribution packed as RGBE (4 bytes), so one VPL's visibility can later
//! be re-evaluated alone. Weights follow eq. 5 without the harmonic mean distance:
//! w_k(x) = (‖x − x_k‖ + √(1 − n·n_k))⁻¹, distances in units of the scene's bounding diagonal so
//! `caching_radius` a is scale-free; records with w_k(x) > 1/a are used, and where none is, a
//! new one is made (on demand).
use super::octree::Octree;
use super::rgbe;
use super::vpl::{irradiance_from, visibility_ray, Vpl};
use crate::core::Rgb;
use crate::scene::SceneAccel;
use glam::Vec3;

#[derive(Clone, Debug)]
pub struct Record {
    pub position: Vec3,
    pub normal: Vec3,
    pub irradiance: Rgb,
    /// Per VPL, its irradiance contribution (zero when occluded), RGBE.
    pub contributions: Vec<u32>,
}

/// Computes a record at `p` (unit normal `n` facing the viewer) from every VPL, with one
/// visibility ray each. Returns the record and the rays traced.
pub fn compute_record(accel: &SceneAccel, vpls: &[Vpl], p: Vec3, n: Vec3, min_distance: f32) -> (Record, u64) {
    let mut irradiance = Rgb::BLACK;
    let mut rays = 0;
    let contributions = vpls
        .iter()
        .map(|vpl| {
            let Some((e, _, _)) = irradiance_from(vpl, p, n, min_distance) else { return 0 };
            rays += 1;
            if accel.scene().occluded1(&visibility_ray(p, n, vpl)) {
                return 0;
            }
            let packed = rgbe::pack(e);
            irradiance += rgbe::unpack(packed);
            packed
        })
        .collect();
    (Record { position: p, normal: n, irradiance, contributions }, rays)
}

/// Records and the octree over them.
pub struct Cache {
    pub records: Vec<Record>,
    octree: Octree,
    /// The scene's bounding diagonal: the unit of the weight's distance.
    scale: f32,
    /// a, in units of `scale`.
    radius: f32,
}

impl Cache {
    /// An empty cache over the scene bounds `(lo, hi)` with caching radius `radius` (relative).
    pub fn new(lo: Vec3, hi: Vec3, radius: f32) -> Cache {
        let scale = (hi - lo).length().max(f32::MIN_POSITIVE);
        let octree = Octree::new((lo + hi) * 0.5, (hi - lo).max_element() * 0.5, radius * scale);
        Cache { records: Vec::new(), octree, scale, radius }
    }

    pub fn clear(&mut self) {
        self.records.clear();
        self.octree.clear();
    }

    pub fn insert(&mut self, record: Record) -> u32 {
        let index = self.records.len() as u32;
        self.octree.insert(index, record.position);
        self.records.push(record);
        index
    }

    /// Eq. 5's weight of `record` at `p` with unit normal `n`.
    fn weight(&self, record: &Record, p: Vec3, n: Vec3) -> f32 {
        let d = (p - record.position).length() / self.scale;
        1.0 / (d + (1.0 - n.dot(record.normal)).max(0.0).sqrt()).max(1e-12)
    }

    /// Calls `f(index, weight)` for every record with w > 1/a at `p`.
    fn near(&self, p: Vec3, n: Vec3, mut f: impl FnMut(u32, f32)) {
        let threshold = 1.0 / self.radius;
        self.octree.query(p, self.radius * self.scale, |i| {
            let w = self.weight(&self.records[i as usize], p, n);
            if w > threshold {
                f(i, w);
            }
        });
    }

    /// Is `p` covered by a record (some w > 1/a)?
    pub fn covers(&self, p: Vec3, n: Vec3) -> bool {
        let mut any = false;
        self.near(p, n, |_, _| any = true);
        any
    }

    /// Eq. 4's interpolated irradiance at `p`, or `None` where no record covers it.
    pub fn irradiance(&self, p: Vec3, n: Vec3) -> Option<Rgb> {
        let (mut sum, mut weights) = (Rgb::BLACK, 0.0f32);
        self.near(p, n, |i, w| {
            sum += self.records[i as usize].irradiance * w;
            weights += w;
        });
        (weights > 0.0).then(|| sum / weights)
    }

    pub fn memory_bytes(&self) -> u64 {
        let records: u64 =
            self.records.iter().map(|r| (std::mem::size_of::<Record>() + r.contributions.len() * 4) as u64).sum();
        records + self.octree.memory_bytes()
    }
}
