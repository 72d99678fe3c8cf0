//! Verifying stored paths against what changed this tick (naive mode, Moreau et al. §3.2).
//!
//! Segments are tested in order from the light against the world AABBs of every surface that
//! moved, both where it was and where it is (a slab test; conservative, so false positives only
//! cost a retrace). The first segment that may be crossed, or that ends on a moved object, is
//! retraced along with everything after it. A photon on an object whose material changed keeps
//! its arrival flux, but everything it reflected is retraced.
use super::store::PathStore;
use super::trace::{path_origin, Retrace};
use crate::scene::edits::Aabb;
use crate::scene::Scene;
use glam::Vec3;

/// What changed this tick, prepared for fast per-segment tests.
pub struct Changes {
    /// Old and new world bounds of moved surfaces.
    pub boxes: Vec<Aabb>,
    /// `moved[object]`: the object moved this tick.
    pub moved: Vec<bool>,
    /// `material_changed[object]`: the object's material was edited this tick.
    pub material_changed: Vec<bool>,
}

/// Does the segment `origin + t·dir`, t ∈ [0, t_max], touch the box? (Slab test; touching a
/// face counts, which keeps the test conservative.)
pub fn segment_hits_box(origin: Vec3, dir: Vec3, t_max: f32, b: &Aabb) -> bool {
    let (mut near, mut far) = (0.0f32, t_max);
    for axis in 0..3 {
        let (o, d, lo, hi) = (origin[axis], dir[axis], b.min[axis], b.max[axis]);
        if d == 0.0 {
            // Parallel to this slab: inside it or never.
            if o < lo || o > hi {
                return false;
            }
            continue;
        }
        let (t0, t1) = ((lo - o) / d, (hi - o) / d);
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
        if near > far {
            return false;
        }
    }
    true
}

/// The retrace a path needs, or `None` if it is still valid. Also returns the box tests made.
pub fn check_path(scene: &Scene, store: &PathStore, path: usize, changes: &Changes) -> (Option<Retrace>, u64) {
    let photons = store.word[path].photons();
    let escaped = store.escape[path] != Vec3::ZERO;
    let segments = photons + u32::from(escaped);
    let mut start = path_origin(scene, store, path);
    let mut tests = 0u64;
    for k in 0..segments {
        let ends_on_photon = k < photons;
        let (dir, t_max) = if ends_on_photon {
            let end = store.rows[k as usize].position[path];
            (end - start, 1.0)
        } else {
            (store.escape[path], f32::INFINITY)
        };
        // A moved surface may now cross the segment (where it was, or where it is).
        tests += changes.boxes.len() as u64;
        if changes.boxes.iter().any(|b| segment_hits_box(start, dir, t_max, b)) {
            return (
                Some(if ends_on_photon || k == 0 { Retrace::KeepSegment(k) } else { Retrace::FreshFrom(k) }),
                tests,
            );
        }
        if ends_on_photon {
            let object = store.rows[k as usize].object[path] as usize;
            // The segment ends on an object that moved: its end point is stale.
            if changes.moved[object] {
                return (Some(Retrace::KeepSegment(k)), tests);
            }
            // The photon's surface reflects differently now: retrace what it reflected.
            if changes.material_changed[object] {
                return ((k + 1 < segments).then_some(Retrace::FreshFrom(k + 1)), tests);
            }
            start = store.rows[k as usize].position[path];
        }
    }
    (None, tests)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slab_test_against_analytic_cases() {
        let b = Aabb { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) };
        assert!(segment_hits_box(Vec3::new(-5.0, 0.0, 0.0), Vec3::new(10.0, 0.0, 0.0), 1.0, &b));
        assert!(!segment_hits_box(Vec3::new(-5.0, 0.0, 0.0), Vec3::new(3.0, 0.0, 0.0), 1.0, &b), "stops short");
        assert!(!segment_hits_box(Vec3::new(-5.0, 2.0, 0.0), Vec3::new(10.0, 0.0, 0.0), 1.0, &b), "passes above");
        assert!(segment_hits_box(Vec3::new(-5.0, 1.0, 0.0), Vec3::new(10.0, 0.0, 0.0), 1.0, &b), "grazes the face");
        assert!(segment_hits_box(Vec3::ZERO, Vec3::X, 0.1, &b), "starts inside");
        assert!(segment_hits_box(Vec3::new(0.0, 0.0, -9.0), Vec3::Z, f32::INFINITY, &b), "infinite escape ray");
        assert!(!segment_hits_box(Vec3::new(0.0, 0.0, 9.0), Vec3::Z, f32::INFINITY, &b), "escape ray pointing away");
    }
}
