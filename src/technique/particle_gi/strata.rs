//! Cones bounding the link directions of each stratum, so the incremental link update can skip
//! whole strata that no moved box can reach.
//!
//! Link k of a set with n_s² links takes its local direction from the square cell k of the
//! n_s × n_s grid, jittered within the cell and mapped by the concentric map and Malley's
//! method (`links.rs`). Each cell's image on the hemisphere is a fixed region, the same for
//! every particle, so one bounding cone per cell serves every particle: its axis is the
//! direction of the cell's centre, and its half-angle α bounds the region. The farthest point
//! of the region from the axis lies on its boundary (the angular distance to an axis has no
//! maximum inside a region that stays within a hemisphere around it), so α is the largest
//! angle among boundary samples no more than 4·10⁻³ apart, plus that gap and a margin for
//! rounding. The cones of each n_s are computed once per process ([`StratumCones::of`]).
//! Angles in radians.
use crate::core::sampling::cosine_hemisphere;
use glam::{Vec2, Vec3};
use std::sync::OnceLock;

/// The widest angle between neighbouring boundary samples.
const GAP: f32 = 4e-3;
/// Added to every half-angle, for the rounding of the directions and of the box cones.
const MARGIN: f32 = 1e-4;
/// The most strata a set has (`gather_links` ≤ 32).
pub const MAX_STRATA: usize = 1024;

/// Bounding cones of the n² strata, as arrays (axis components, cos α, sin α).
#[derive(Clone, Debug, Default)]
pub struct StratumCones {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    cos: Vec<f32>,
    sin: Vec<f32>,
}

impl StratumCones {
    /// The cones of an n × n set (n ≤ 32), computed on first use.
    pub fn of(n: u32) -> &'static StratumCones {
        static CONES: [OnceLock<StratumCones>; 33] = [const { OnceLock::new() }; 33];
        CONES[n as usize].get_or_init(|| StratumCones::new(n))
    }

    fn new(n: u32) -> StratumCones {
        let n = n as usize;
        let mut cones = StratumCones::default();
        for k in 0..n * n {
            let corner = Vec2::new((k % n) as f32, (k / n) as f32) / n as f32;
            let boundary = cell_boundary(corner, 1.0 / n as f32);
            let axis = cosine_hemisphere(corner + Vec2::splat(0.5 / n as f32));
            let widest = boundary.iter().map(|d| angle(axis, *d)).fold(0.0f32, f32::max);
            let alpha = (widest + GAP + MARGIN).min(std::f32::consts::FRAC_PI_2);
            cones.x.push(axis.x);
            cones.y.push(axis.y);
            cones.z.push(axis.z);
            cones.cos.push(alpha.cos());
            cones.sin.push(alpha.sin());
        }
        cones
    }

    /// Marks in `mask` (one byte per stratum, non-zero: marked) every stratum whose cone meets
    /// the cone of unit local axis `axis` and half-angle β (given as cos β, sin β, β ≤ π/2):
    /// two cones meet when the angle between their axes is at most α + β, that is when their
    /// axes' dot product is at least cos(α + β) (α + β < π). The loop is branch-free, so it
    /// runs several strata per instruction.
    pub fn mark(&self, axis: Vec3, cos_beta: f32, sin_beta: f32, mask: &mut [u8]) {
        let n = self.x.len();
        let (x, y, z, ca, sa, mask) =
            (&self.x[..n], &self.y[..n], &self.z[..n], &self.cos[..n], &self.sin[..n], &mut mask[..n]);
        for k in 0..n {
            let meets = x[k] * axis.x + y[k] * axis.y + z[k] * axis.z >= ca[k] * cos_beta - sa[k] * sin_beta - MARGIN;
            mask[k] |= u8::from(meets);
        }
    }
}

/// The directions of the boundary of the cell `[corner, corner + size]²`, in order around it,
/// no two neighbours more than [`GAP`] apart: each edge is bisected where its image is coarser
/// (it is steepest at the horizon, where the cosine-weighted map's height has an infinite slope).
fn cell_boundary(corner: Vec2, size: f32) -> Vec<Vec3> {
    let at = |c: Vec2| cosine_hemisphere(corner + c * size);
    let corners = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y, Vec2::ZERO];
    let mut points = vec![at(Vec2::ZERO)];
    for edge in corners.windows(2) {
        // Pending pieces of the edge, as parameter intervals, nearest the edge's start on top.
        let mut pending = vec![(edge[0], edge[1])];
        while let Some((a, b)) = pending.pop() {
            let (da, db) = (at(a), at(b));
            if angle(da, db) > GAP && (b - a).length() > 1e-7 {
                let mid = (a + b) * 0.5;
                pending.push((mid, b));
                pending.push((a, mid));
            } else {
                points.push(db);
            }
        }
    }
    points
}

/// The angle between unit vectors, robust near 0.
fn angle(a: Vec3, b: Vec3) -> f32 {
    2.0 * ((a - b).length() * 0.5).min(1.0).asin()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::Rng;

    /// Every jittered direction of every stratum (jitters drawn at random and pushed to the
    /// cell's edges and corners) lies in its cone, and each cone is tight: some direction
    /// comes within 85% of its half-angle, so a cone twice too wide would fail.
    #[test]
    fn every_direction_of_a_stratum_lies_in_its_cone() {
        for n in [1u32, 4, 16, 32] {
            let cones = StratumCones::new(n);
            let mut rng = Rng::new(11, u64::from(n));
            for k in 0..(n * n) as usize {
                let axis = Vec3::new(cones.x[k], cones.y[k], cones.z[k]);
                let alpha = cones.sin[k].atan2(cones.cos[k]);
                let mut widest = 0.0f32;
                for s in 0..400 {
                    let j = match s {
                        0..4 => Vec2::new((s & 1) as f32, (s >> 1) as f32 * (1.0 - f32::EPSILON)),
                        _ => Vec2::new(rng.next_f32(), rng.next_f32()),
                    };
                    let u =
                        Vec2::new(((k as u32 % n) as f32 + j.x) / n as f32, ((k as u32 / n) as f32 + j.y) / n as f32);
                    let d = cosine_hemisphere(u);
                    widest = widest.max(angle(axis, d));
                    assert!(angle(axis, d) <= alpha, "n {n} stratum {k}: {d} lies outside the cone");
                }
                assert!(widest >= 0.85 * (alpha - MARGIN) || n == 1, "n {n} stratum {k}: cone {alpha} for {widest}");
            }
        }
    }

    /// A cone marks the strata whose directions it can hold: directions drawn in a narrow cone
    /// around a random axis all fall in marked strata, and a narrow cone marks few strata.
    #[test]
    fn a_narrow_cone_marks_the_strata_of_its_directions_and_few_others() {
        let n = 16u32;
        let cones = StratumCones::new(n);
        let mut rng = Rng::new(5, 0);
        for _ in 0..200 {
            let axis = cosine_hemisphere(Vec2::new(rng.next_f32(), rng.next_f32()));
            let beta = 0.05f32;
            let mut mask = [0u8; MAX_STRATA];
            cones.mark(axis, beta.cos(), beta.sin(), &mut mask);
            let count = mask.iter().filter(|&&m| m != 0).count();
            assert!(count < 40, "a cone of 0.05 rad marks {count} of 256 strata");
            for _ in 0..4000 {
                let u = Vec2::new(rng.next_f32(), rng.next_f32());
                let d = cosine_hemisphere(u);
                if angle(axis, d) <= beta {
                    let k = ((u.y * n as f32) as usize).min(15) * 16 + ((u.x * n as f32) as usize).min(15);
                    assert!(mask[k] != 0, "stratum {k} of a direction in the cone is not marked");
                }
            }
        }
    }
}
