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
use crate::scene::edits::Aabb;
use crate::scene::{Material, Scene};
use glam::{Vec3, Vec3A};

/// A bounding-volume hierarchy over the moved boxes: a segment that misses a node's bounds
/// skips all the boxes below it. Built by median split on the longest axis of the centroids.
#[derive(Clone, Debug, Default)]
pub struct BoxTree {
    nodes: Vec<BoxNode>,
    boxes: Vec<Aabb>,
}

#[derive(Clone, Copy, Debug)]
struct BoxNode {
    bounds: Aabb,
    /// Leaf: boxes[first..first + count]; inner: children at `first` and `first + 1`.
    first: u32,
    count: u32,
}

/// Boxes per leaf.
const LEAF_BOXES: usize = 2;

impl BoxTree {
    pub fn new(mut boxes: Vec<Aabb>) -> BoxTree {
        let mut tree = BoxTree { nodes: Vec::new(), boxes: Vec::new() };
        if boxes.is_empty() {
            return tree;
        }
        tree.nodes.push(BoxNode { bounds: boxes[0], first: 0, count: 0 });
        tree.split(0, &mut boxes);
        tree
    }

    fn split(&mut self, node: usize, boxes: &mut [Aabb]) {
        let bounds = boxes.iter().skip(1).fold(boxes[0], |b, x| b.union(x));
        if boxes.len() <= LEAF_BOXES {
            self.nodes[node] = BoxNode { bounds, first: self.boxes.len() as u32, count: boxes.len() as u32 };
            self.boxes.extend_from_slice(boxes);
            return;
        }
        let centre = |b: &Aabb| (b.min + b.max) * 0.5;
        let spread = boxes.iter().fold(Aabb { min: Vec3::INFINITY, max: Vec3::NEG_INFINITY }, |a, b| Aabb {
            min: a.min.min(centre(b)),
            max: a.max.max(centre(b)),
        });
        let extent = spread.max - spread.min;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        boxes.sort_by(|a, b| centre(a)[axis].total_cmp(&centre(b)[axis]));
        let children = self.nodes.len();
        self.nodes[node] = BoxNode { bounds, first: children as u32, count: 0 };
        self.nodes.push(BoxNode { bounds, first: 0, count: 0 });
        self.nodes.push(BoxNode { bounds, first: 0, count: 0 });
        let (left, right) = boxes.split_at_mut(boxes.len() / 2);
        self.split(children, left);
        self.split(children + 1, right);
    }

    /// Does the segment touch any box? Returns the answer and the box and node tests made.
    pub fn hits(&self, origin: Vec3, dir: Vec3, t_max: f32) -> (bool, u64) {
        if self.nodes.is_empty() {
            return (false, 0);
        }
        // With no zero component the reciprocal direction serves every box; otherwise the exact
        // per-axis test handles the parallel slabs.
        let fast = dir.x != 0.0 && dir.y != 0.0 && dir.z != 0.0;
        let (o, inv) = (Vec3A::from(origin), Vec3A::ONE / Vec3A::from(dir));
        let touches = |b: &Aabb| {
            if fast {
                let t0 = (Vec3A::from(b.min) - o) * inv;
                let t1 = (Vec3A::from(b.max) - o) * inv;
                t0.min(t1).max_element().max(0.0) <= t0.max(t1).min_element().min(t_max)
            } else {
                segment_hits_box(origin, dir, t_max, b)
            }
        };
        let mut stack = [0u32; 64];
        let mut top = 1;
        let mut tests = 0u64;
        while top > 0 {
            top -= 1;
            let n = self.nodes[stack[top] as usize];
            // A leaf's own boxes are as cheap to test as its bounds, so only inner nodes cull.
            if n.count == 0 {
                tests += 1;
                if !touches(&n.bounds) {
                    continue;
                }
            }
            if n.count > 0 {
                for b in &self.boxes[n.first as usize..(n.first + n.count) as usize] {
                    tests += 1;
                    if touches(b) {
                        return (true, tests);
                    }
                }
            } else if top + 2 <= stack.len() {
                stack[top] = n.first;
                stack[top + 1] = n.first + 1;
                top += 2;
            }
        }
        (false, tests)
    }
}

/// What changed this tick, prepared for fast per-segment tests.
pub struct Changes {
    /// Old and new world bounds of moved surfaces.
    pub boxes: BoxTree,
    /// `moved[object]`: the object moved this tick.
    pub moved: Vec<bool>,
    /// `previous_material[object]`: the object's material before this tick's edit, if edited.
    pub previous_material: Vec<Option<Material>>,
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

    #[test]
    fn the_box_tree_answers_like_a_linear_scan() {
        let mut rng = crate::core::Rng::new(3, 4);
        let mut v = || rng.next_f32() * 20.0 - 10.0;
        let boxes: Vec<Aabb> = (0..23)
            .map(|_| {
                let c = Vec3::new(v(), v(), v());
                let h = Vec3::new(v().abs(), v().abs(), v().abs()) * 0.1;
                Aabb { min: c - h, max: c + h }
            })
            .collect();
        let tree = BoxTree::new(boxes.clone());
        let (mut hits, mut tree_tests) = (0, 0);
        for i in 0..5000 {
            let o = Vec3::new(v(), v(), v());
            let d = Vec3::new(v(), v(), v()) * if i % 3 == 0 { 0.1 } else { 1.0 };
            let t_max = if i % 7 == 0 { f32::INFINITY } else { 1.0 };
            let linear = boxes.iter().any(|b| segment_hits_box(o, d, t_max, b));
            let (tree_answer, tests) = tree.hits(o, d, t_max);
            assert_eq!(tree_answer, linear, "segment {i}");
            hits += usize::from(linear);
            tree_tests += tests;
        }
        assert!(hits > 100 && hits < 4900, "a poor test set: {hits} hits");
        assert!(tree_tests < 5000 * 23, "the tree made more tests than a linear scan");
        assert_eq!(BoxTree::new(Vec::new()).hits(Vec3::ZERO, Vec3::X, 1.0), (false, 0));
    }
}
