//! The instant cache (Debattista et al. §3.1): irradiance records computed from the VPLs at a
//! sparse set of points and interpolated elsewhere (eq. 4).
//!
//! A record holds its position, its shading normal (on the side it was seen from; the geometric
//! normal on flat-shaded meshes, and the irradiance is about it), its irradiance and,
//! per VPL, that VPL's contribution packed as RGBE (4 bytes), so one VPL's visibility can later
//! be re-evaluated alone. Weights follow eq. 5 without the harmonic mean distance, with the
//! distance and the normal given their own tolerances (as Tabellion and Lamorlette do):
//! w_k(x) = (‖x − x_k‖ / (a·D) + √(1 − n·n_k) / √(1 − cos θ))⁻¹, where D is the scene's
//! bounding diagonal (so `caching_radius` a is scale-free) and θ is `normal_tolerance`. Records
//! with w_k(x) > 1 are used, and where none is, a new one is made (on demand). The paper's
//! single tolerance is θ = acos(1 − a²) (4.05° at a = 0.05): its weights are these times 1/a,
//! which the interpolation's normalisation cancels.
use super::grid::RecordGrid;
use super::rgbe;
use super::vpl::{irradiance_from, ray_origin, visibility_ray, Vpl};
use crate::core::Rgb;
use crate::scene::SceneAccel;
use glam::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    pub position: Vec3,
    pub normal: Vec3,
    /// The object the record lies on.
    pub object: u32,
    /// The sum of `contributions`, unpacked, in VPL order.
    pub irradiance: Rgb,
    /// Per VPL, its irradiance contribution (zero when occluded), RGBE.
    pub contributions: Vec<u32>,
    /// The last tick that interpolated from this record (`temporal` ages records by it).
    pub last_used: u64,
    /// Flagged by `temporal`'s on-demand re-evaluation: this tick's changes are not applied yet.
    pub stale: bool,
}

impl Record {
    /// A record at `p` with the given contributions; its irradiance is their sum ([`rgbe::sum`]).
    pub fn new(p: Vec3, n: Vec3, object: u32, contributions: Vec<u32>, tick: u64) -> Record {
        let irradiance = rgbe::sum(&contributions);
        Record { position: p, normal: n, object, irradiance, contributions, last_used: tick, stale: false }
    }
}

/// One VPL's contribution to the record at `p` (unit normal `n`), RGBE, and the visibility rays
/// traced for it (0 or 1).
pub fn contribution(accel: &SceneAccel, vpl: &Vpl, p: Vec3, n: Vec3, min_distance: f32) -> (u32, u64) {
    let Some((e, _, _)) = irradiance_from(vpl, p, n, min_distance) else { return (0, 0) };
    if accel.scene().occluded1(&visibility_ray(ray_origin(p, n), vpl)) {
        (0, 1)
    } else {
        (rgbe::pack(e), 1)
    }
}

/// Lanes per packet of a new record's visibility rays (they share an origin, so Embree's
/// packet kernels traverse them together; chosen by `bench icache`: 8 beat 1 and 16 here).
const RECORD_PACKET: usize = 8;

/// Computes a record at `p` (unit normal `n` facing the viewer) from every VPL, with one
/// visibility ray each, traced in packets of [`RECORD_PACKET`]. Returns the record and the
/// rays traced.
pub fn compute_record(
    accel: &SceneAccel,
    vpls: &[Vpl],
    p: Vec3,
    n: Vec3,
    object: u32,
    min_distance: f32,
    tick: u64,
) -> (Record, u64) {
    let mut contributions = vec![0u32; vpls.len()];
    let lit: Vec<(usize, Rgb)> = vpls
        .iter()
        .enumerate()
        .filter_map(|(i, vpl)| irradiance_from(vpl, p, n, min_distance).map(|(e, _, _)| (i, e)))
        .collect();
    let from = ray_origin(p, n);
    let mut rays = [crate::embree::Ray::new(p, n); RECORD_PACKET];
    let mut occluded = [false; RECORD_PACKET];
    for chunk in lit.chunks(RECORD_PACKET) {
        let active: [bool; RECORD_PACKET] = std::array::from_fn(|k| k < chunk.len());
        for (ray, &(i, _)) in rays.iter_mut().zip(chunk) {
            *ray = visibility_ray(from, &vpls[i]);
        }
        accel.scene().occluded_lanes(&rays, &active, &mut occluded);
        for (&(i, e), &blocked) in chunk.iter().zip(&occluded) {
            contributions[i] = if blocked { 0 } else { rgbe::pack(e) };
        }
    }
    (Record::new(p, n, object, contributions, tick), lit.len() as u64)
}

/// Bytes the grid keeps per record.
pub const KEY_BYTES: u64 = std::mem::size_of::<Key>() as u64;

/// What the grid keeps of a record: enough to weigh it without touching the record.
#[derive(Clone, Copy, Debug)]
struct Key {
    index: u32,
    position: Vec3,
    normal: Vec3,
}

/// Records and the grid over them.
pub struct Cache {
    pub records: Vec<Record>,
    grid: RecordGrid<Key>,
    /// a·D: how far a record reaches, in scene units.
    reach: f32,
    /// 1/√(1 − cos θ): the normal term's scale.
    normal_scale: f32,
    /// Since the last [`Cache::take_renumbering`]: each record index then → its index now, or
    /// [`GONE`]; `None` while no record went.
    renumbering: Option<Vec<u32>>,
}

/// A record that [`Cache::retain`] removed, in a renumbering.
pub const GONE: u32 = u32::MAX;

impl Cache {
    /// An empty cache over the scene bounds `(lo, hi)` with caching radius `radius` (relative
    /// to their diagonal) and normal tolerance `normal_tolerance_deg` (degrees, in (0, 90]).
    pub fn new(lo: Vec3, hi: Vec3, radius: f32, normal_tolerance_deg: f32) -> Cache {
        let reach = radius * (hi - lo).length().max(f32::MIN_POSITIVE);
        let grid = RecordGrid::new(lo, hi, reach);
        let normal_scale = 1.0 / (1.0 - normal_tolerance_deg.to_radians().cos()).max(f32::EPSILON).sqrt();
        Cache { records: Vec::new(), grid, reach, normal_scale, renumbering: None }
    }

    pub fn clear(&mut self) {
        self.records.clear();
        self.grid.clear();
        self.renumbering = None;
    }

    /// Keeps the records for which `keep` holds and returns how many went. Kept records keep
    /// their order; their indices close up, as [`Cache::take_renumbering`] then tells.
    pub fn retain(&mut self, mut keep: impl FnMut(&Record) -> bool) -> u64 {
        let before = self.records.len();
        let kept: Vec<bool> = self.records.iter().map(&mut keep).collect();
        if kept.iter().any(|&k| !k) {
            let mut next = 0u32;
            let step: Vec<u32> = kept
                .iter()
                .map(|&k| {
                    next += u32::from(k);
                    if k {
                        next - 1
                    } else {
                        GONE
                    }
                })
                .collect();
            let mut flags = kept.iter();
            self.records.retain(|_| flags.next().copied().unwrap_or(true));
            self.renumbering = Some(match self.renumbering.take() {
                Some(earlier) => earlier.into_iter().map(|i| if i == GONE { GONE } else { step[i as usize] }).collect(),
                None => step,
            });
        }
        if self.records.len() < before {
            self.grid.clear();
            for (i, r) in self.records.iter().enumerate() {
                self.grid.insert(Key { index: i as u32, position: r.position, normal: r.normal }, r.position);
            }
        }
        (before - self.records.len()) as u64
    }

    /// How record indices changed since the last call: index then → index now, or [`GONE`];
    /// `None` if no record went (records made since then take the indices after the old ones).
    pub fn take_renumbering(&mut self) -> Option<Vec<u32>> {
        self.renumbering.take()
    }

    pub fn insert(&mut self, record: Record) -> u32 {
        let index = self.records.len() as u32;
        self.grid.insert(Key { index, position: record.position, normal: record.normal }, record.position);
        self.records.push(record);
        index
    }

    /// Calls `f(index, w)` for every record with weight w > 1 at `p` (unit normal `n`) until
    /// `f` returns false. A record farther than a·D cannot qualify, so the square roots wait
    /// for the distance test. Returns false if `f` stopped it.
    fn visit(&self, p: Vec3, n: Vec3, mut f: impl FnMut(u32, f32) -> bool) -> bool {
        self.grid
            .query(p, self.reach, |key| self.weight(p, n, key.position, key.normal).is_none_or(|w| f(key.index, w)))
    }

    /// The weight w_k(x) at `p` (unit normal `n`) of a record at `position` with `normal`, if
    /// it is above 1.
    pub fn weight(&self, p: Vec3, n: Vec3, position: Vec3, normal: Vec3) -> Option<f32> {
        let reach = self.reach;
        let d2 = (p - position).length_squared();
        if d2 >= reach * reach {
            return None;
        }
        let inverse = d2.sqrt() / reach + (1.0 - n.dot(normal)).max(0.0).sqrt() * self.normal_scale;
        // A NaN (from a degenerate normal) is not rejected: records are ruled out only by
        // `inverse ≥ 1`, and the full lookup and the new-record append share this test, so
        // they agree on such a record too.
        (inverse < 1.0 || inverse.is_nan()).then(|| 1.0 / inverse.max(1e-12))
    }

    /// How far a record reaches: a·D, in scene units.
    pub fn reach(&self) -> f32 {
        self.reach
    }

    /// Calls `f(index, w)` for every record with w > 1 at `p`.
    pub fn near(&self, p: Vec3, n: Vec3, mut f: impl FnMut(u32, f32)) {
        self.visit(p, n, |i, w| {
            f(i, w);
            true
        });
    }

    /// Does some record have w > 1 at `p`? (Stops at the first.)
    pub fn covers(&self, p: Vec3, n: Vec3) -> bool {
        !self.visit(p, n, |_, _| false)
    }

    pub fn memory_bytes(&self) -> u64 {
        let records: u64 =
            self.records.iter().map(|r| (std::mem::size_of::<Record>() + r.contributions.len() * 4) as u64).sum();
        records + self.grid.memory_bytes()
    }
}

/// What [`audit`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Audit {
    pub records: u64,
    /// Records whose contributions or irradiance differ from a fresh computation.
    pub mismatched: u64,
    /// Records with no surface within `reach` below them.
    pub off_surface: u64,
    /// A hash of the checked records' positions, normals and contributions, in position order.
    pub digest: u64,
}

/// Recomputes every record that is not stale from scratch with `vpls` and compares bit for
/// bit; also checks that a surface still lies under each record (a probe ray from `reach`
/// above it along its normal, back down `2·reach`).
pub fn audit(accel: &SceneAccel, cache: &Cache, vpls: &[Vpl], min_distance: f32, reach: f32) -> Audit {
    use rayon::prelude::*;
    use std::hash::{Hash, Hasher};
    let checked: Vec<&Record> = cache.records.iter().filter(|r| !r.stale).collect();
    let (mismatched, off_surface) = checked
        .par_iter()
        .map(|r| {
            let (fresh, _) = compute_record(accel, vpls, r.position, r.normal, r.object, min_distance, r.last_used);
            let mismatched = fresh.contributions != r.contributions || fresh.irradiance != r.irradiance;
            let probe = crate::embree::Ray::segment(r.position + r.normal * reach, -r.normal, 2.0 * reach);
            (u64::from(mismatched), u64::from(!accel.scene().occluded1(&probe)))
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    let mut keys: Vec<([u32; 6], &[u32])> = checked
        .iter()
        .map(|r| {
            let (p, n) = (r.position.to_array().map(f32::to_bits), r.normal.to_array().map(f32::to_bits));
            ([p[0], p[1], p[2], n[0], n[1], n[2]], r.contributions.as_slice())
        })
        .collect();
    keys.sort_unstable();
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    keys.hash(&mut hasher);
    Audit { records: checked.len() as u64, mismatched, off_surface, digest: hasher.finish() }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random unit vectors near +z (within about 25°), so normal terms span the tolerance.
    fn near_z(rng: &mut crate::core::Rng) -> Vec3 {
        Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 2.0).normalize()
    }

    #[test]
    fn the_papers_tolerance_is_the_single_tolerance_of_eq_5() {
        // Property: with θ = acos(1 − a²), the records used and their relative weights are eq. 5's
        // with one tolerance a (w = (d/D + √(1 − n·n_k))⁻¹ > 1/a), checked by brute force on random
        // records. Negative control: θ = 10° uses records eq. 5 would not.
        let (a, extent) = (0.05f32, Vec3::ONE);
        let diagonal = extent.length();
        let theta = (1.0 - a * a).acos().to_degrees();
        let mut rng = crate::core::Rng::new(11, 12);
        let mut cache = Cache::new(Vec3::ZERO, extent, a, theta);
        let mut wide = Cache::new(Vec3::ZERO, extent, a, 10.0);
        let mut records = Vec::new();
        for _ in 0..2000 {
            let (p, n) = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()), near_z(&mut rng));
            cache.insert(Record::new(p, n, 0, Vec::new(), 0));
            wide.insert(Record::new(p, n, 0, Vec::new(), 0));
            records.push((p, n));
        }
        let mut extra = 0;
        for _ in 0..300 {
            let (x, n) = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()), near_z(&mut rng));
            let eq5: Vec<(u32, f32)> = records
                .iter()
                .enumerate()
                .map(|(i, (p, m))| (i as u32, (x - *p).length() / diagonal + (1.0 - n.dot(*m)).max(0.0).sqrt()))
                .filter(|&(_, inverse)| (inverse - a).abs() > 1e-5)
                .collect();
            let mut found = Vec::new();
            cache.near(x, n, |i, w| found.push((i, w)));
            for &(i, inverse) in &eq5 {
                let hit = found.iter().find(|f| f.0 == i);
                assert_eq!(hit.is_some(), inverse < a, "record {i}: 1/w = {inverse}");
                if let Some(&(_, w)) = hit {
                    // Weights scaled by 1/a, which the interpolation's normalisation cancels.
                    assert!((w * inverse - a).abs() <= 1e-3 * a, "record {i}: w = {w}, eq. 5: {}", 1.0 / inverse);
                }
            }
            let mut wider = 0;
            wide.near(x, n, |_, _| wider += 1);
            extra += wider - found.len();
        }
        assert!(extra > 0, "θ = 10° should reach records eq. 5 does not");
    }
}
