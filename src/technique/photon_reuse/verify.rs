//! Verifying stored paths against what changed this tick (naive mode, Moreau et al. §3.2), and
//! the box tests both modes share.
//!
//! Segments are tested in order from the light against the world AABBs of every surface that
//! moved, both where it was and where it is (a slab test; conservative, so false positives only
//! cost a retrace). The first segment that may be crossed, or that ends on a moved object, is
//! retraced along with everything after it. A photon on an object whose material changed keeps
//! its arrival flux, but everything it reflected is retraced.
use super::store::PathStore;
use super::trace::{path_origin, Retrace};
use crate::scene::{Material, Scene};
use crate::technique::box_tree::BoxTree;
use glam::Vec3;

/// What changed this tick, prepared for fast per-segment tests.
pub struct Changes {
    /// Old and new world bounds of moved surfaces.
    pub boxes: BoxTree,
    /// `moved[object]`: the object moved this tick.
    pub moved: Vec<bool>,
    /// `previous_material[object]`: the object's material before this tick's edit, if edited.
    pub previous_material: Vec<Option<Material>>,
}

/// The retrace a path needs, or `None` if it is still valid. Also returns the box tests made.
/// `first_verified`: segment 0 was already checked against the full scene (its light moved).
pub fn check_path(
    scene: &Scene,
    store: &PathStore,
    path: usize,
    changes: &Changes,
    first_verified: bool,
) -> (Option<Retrace>, u64) {
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
        let (crossed, made) = if k == 0 && first_verified { (false, 0) } else { changes.boxes.hits(start, dir, t_max) };
        tests += made;
        if crossed {
            return (Some(Retrace::KeepSegment(k)), tests);
        }
        if ends_on_photon {
            let object = store.rows[k as usize].object[path] as usize;
            // The segment ends on an object that moved: its end point is stale.
            if changes.moved[object] {
                return (Some(Retrace::KeepSegment(k)), tests);
            }
            // The photon's surface reflects differently now: retrace what it reflected, and draw
            // the roulette again where it ended the path.
            if changes.previous_material[object].is_some() {
                let goes_on = k + 1 < segments || k + 1 < store.max_photons as u32;
                return (goes_on.then_some(Retrace::FreshFrom(k + 1)), tests);
            }
            start = store.rows[k as usize].position[path];
        }
    }
    (None, tests)
}
