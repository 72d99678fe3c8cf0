//! Segment-against-box tests for what moved this tick, shared by the techniques that verify
//! stored rays against moved objects (`photon_reuse` path segments, `instant_cache` visibility
//! rays).
//!
//! Boxes are world-space AABBs in scene units. Tests are conservative: touching a face counts,
//! so a false positive only costs a more exact test later, never a missed change.
use crate::scene::edits::Aabb;
use glam::{Vec3, Vec3A};

/// Widening of moved boxes, as a fraction of the scene's bounding diagonal, so a ray that
/// grazes a box in Embree's arithmetic (rays transformed into instance space) is never missed
/// by the slab test's world-space arithmetic.
pub const BOX_SLACK: f32 = 1e-4;

/// `b` widened by `slack` on every side.
pub fn widened(b: &Aabb, slack: f32) -> Aabb {
    Aabb { min: b.min - Vec3::splat(slack), max: b.max + Vec3::splat(slack) }
}

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
        let spread = Aabb::of_points(boxes.iter().map(centre));
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
        self.hits_below(0, &Segment::new(origin, dir, t_max))
    }

    /// Does the segment touch a box below node `root` (a [`CoverBox`]'s node, or 0 for all)?
    /// Returns the answer and the box and node tests made.
    pub fn hits_below(&self, root: u32, segment: &Segment) -> (bool, u64) {
        let Some(&root_node) = self.nodes.get(root as usize) else { return (false, 0) };
        let touches = |b: &Aabb| segment.touches(b);
        let leaf = |n: &BoxNode| {
            let boxes = &self.boxes[n.first as usize..(n.first + n.count) as usize];
            let met = boxes.iter().position(touches);
            (met.is_some(), met.map_or(boxes.len(), |k| k + 1) as u64)
        };
        // A tree of one leaf (one or two moved boxes, the common case) needs no stack.
        if root_node.count > 0 {
            return leaf(&root_node);
        }
        let mut stack = [root; 64];
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
                let (met, leaf_tests) = leaf(&n);
                tests += leaf_tests;
                if met {
                    return (true, tests);
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

/// One box of a [`BoxTree::cover`]: a moved box itself (`below` is `None`), or the bounds of
/// the tree node `below`, whose boxes a segment that touches it must still be tested against
/// ([`BoxTree::hits_below`]).
#[derive(Clone, Copy, Debug)]
pub struct CoverBox {
    pub bounds: Aabb,
    pub below: Option<u32>,
}

impl BoxTree {
    /// At most `n` boxes (n ≥ 1) that together cover every box: the boxes themselves when there
    /// are no more than `n`, otherwise the tree's top nodes, opened widest first. A segment that
    /// touches a box touches the cover, so the cover is a conservative pre-test.
    pub fn cover(&self, n: usize) -> Vec<CoverBox> {
        if self.boxes.len() <= n {
            return self.boxes.iter().map(|&bounds| CoverBox { bounds, below: None }).collect();
        }
        let extent = |i: u32| {
            let b = self.nodes[i as usize].bounds;
            (b.max - b.min).length_squared()
        };
        let mut front = vec![0u32];
        while front.len() < n {
            let inner = front.iter().enumerate().filter(|(_, &i)| self.nodes[i as usize].count == 0);
            let Some((at, &widest)) = inner.max_by(|a, b| extent(*a.1).total_cmp(&extent(*b.1))) else { break };
            let first = self.nodes[widest as usize].first;
            front[at] = first;
            front.push(first + 1);
        }
        front.iter().map(|&i| CoverBox { bounds: self.nodes[i as usize].bounds, below: Some(i) }).collect()
    }

    /// Does any box overlap `query` (touching counts)?
    pub fn overlaps(&self, query: &Aabb) -> bool {
        let meets = |b: &Aabb| b.min.cmple(query.max).all() && query.min.cmple(b.max).all();
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let Some(n) = self.nodes.get(n as usize) else { continue };
            if !meets(&n.bounds) {
                continue;
            }
            if n.count > 0 {
                if self.boxes[n.first as usize..(n.first + n.count) as usize].iter().any(meets) {
                    return true;
                }
            } else {
                stack.extend([n.first, n.first + 1]);
            }
        }
        false
    }
}

/// A box's bounding sphere seen from a fixed point, the apex: the cone of directions towards
/// it (unit `axis`, half-angle β as its sine and cosine) and the distance `near` from the apex
/// to the sphere. A segment from the apex can touch the box only if its direction lies in the
/// cone and it is at least `near` long. The radius is padded by 10⁻⁴ against rounding.
#[derive(Clone, Copy, Debug)]
pub struct SphereCone {
    pub axis: Vec3,
    pub sin: f32,
    pub cos: f32,
    pub near: f32,
}

impl SphereCone {
    /// The cone of `b` from `apex`; `None` when the apex lies in the sphere (every direction
    /// may reach the box).
    pub fn new(apex: Vec3, b: &Aabb) -> Option<SphereCone> {
        let centre = (b.min + b.max) * 0.5 - apex;
        let (distance, radius) = (centre.length(), (b.max - b.min).length() * 0.5 * (1.0 + 1e-4));
        if distance <= radius {
            return None;
        }
        let sin = radius / distance;
        Some(SphereCone { axis: centre / distance, sin, cos: (1.0 - sin * sin).sqrt(), near: distance - radius })
    }

    /// Might the segment from the apex to `apex + d` touch the box? (Conservative: the angle
    /// test has a relative margin of 10⁻⁵.)
    #[inline]
    pub fn may_reach(&self, d: Vec3) -> bool {
        let (s, length2) = (d.dot(self.axis), d.length_squared());
        s > 0.0 && s * s >= length2 * self.cos * self.cos * (1.0 - 1e-5) && length2 >= self.near * self.near
    }
}

/// A segment prepared for many box tests: with no zero component of the direction, one
/// reciprocal serves every box; otherwise the exact per-axis test handles the parallel slabs.
/// Both tests are monotone in the box, so a box that contains another is touched whenever the
/// inner one is.
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    origin: Vec3,
    dir: Vec3,
    t_max: f32,
    o: Vec3A,
    inv: Vec3A,
    fast: bool,
}

impl Segment {
    pub fn new(origin: Vec3, dir: Vec3, t_max: f32) -> Segment {
        let fast = dir.x != 0.0 && dir.y != 0.0 && dir.z != 0.0;
        Segment { origin, dir, t_max, o: Vec3A::from(origin), inv: Vec3A::ONE / Vec3A::from(dir), fast }
    }

    /// Does the segment touch `b`?
    #[inline]
    pub fn touches(&self, b: &Aabb) -> bool {
        if self.fast {
            let t0 = (Vec3A::from(b.min) - self.o) * self.inv;
            let t1 = (Vec3A::from(b.max) - self.o) * self.inv;
            t0.min(t1).max_element().max(0.0) <= t0.max(t1).min_element().min(self.t_max)
        } else {
            segment_hits_box(self.origin, self.dir, self.t_max, b)
        }
    }
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

/// Does box `b` meet the convex hull of the boxes `a` and `l`, the region every segment from a
/// point of `a` to a point of `l` sweeps? (Exact; touching counts; a point is a box with
/// `min == max`.) The hull is the union over s ∈ [0, 1] of the boxes (1 − s)·a + s·l, whose
/// faces move linearly with s: each of the six face conditions against `b` bounds s on one
/// side, so the test intersects six half-lines with [0, 1].
pub fn meets_hull(a: &Aabb, l: &Aabb, b: &Aabb) -> bool {
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for axis in 0..3 {
        // (1 − s)·a.min + s·l.min ≤ b.max, and (1 − s)·a.max + s·l.max ≥ b.min.
        let low_face = (l.min[axis] - a.min[axis], b.max[axis] - a.min[axis], true);
        let high_face = (l.max[axis] - a.max[axis], b.min[axis] - a.max[axis], false);
        for (k, c, at_most) in [low_face, high_face] {
            if k == 0.0 {
                if (at_most && c < 0.0) || (!at_most && c > 0.0) {
                    return false;
                }
            } else if (k > 0.0) == at_most {
                hi = hi.min(c / k);
            } else {
                lo = lo.max(c / k);
            }
        }
    }
    lo <= hi
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every segment from a cone's apex that touches the box passes `may_reach` (random boxes,
    /// apexes and segments, including ones ending just inside the box), and the cone is not
    /// loose everywhere: most segments that miss the box's sphere by a wide angle are refused.
    #[test]
    fn a_sphere_cone_admits_every_segment_that_touches_its_box() {
        let mut rng = crate::core::Rng::new(17, 0);
        let r =
            |rng: &mut crate::core::Rng, s: f32| (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * s;
        let (mut touching, mut refused) = (0, 0);
        for _ in 0..400 {
            let (c, h) = (r(&mut rng, 10.0), r(&mut rng, 2.0).abs() + Vec3::splat(0.01));
            let b = Aabb { min: c - h, max: c + h };
            let apex = r(&mut rng, 20.0);
            let Some(cone) = SphereCone::new(apex, &b) else { continue };
            for _ in 0..200 {
                let target = c + r(&mut rng, 4.0) * h;
                let d = (target - apex) * (0.5 + rng.next_f32());
                let touches = segment_hits_box(apex, d, 1.0, &b);
                touching += usize::from(touches);
                assert!(!touches || cone.may_reach(d), "apex {apex}, box {b:?}, segment {d}");
                refused += usize::from(!cone.may_reach(-d));
            }
        }
        assert!(touching > 5_000, "too few touching segments: {touching}");
        assert!(refused > 5_000, "segments pointing away are not refused: {refused}");
    }

    /// Whether any of `n` segments from random points of `a` to random points of `l` touches
    /// `b`.
    fn sampled_hull_meets(a: &Aabb, l: &Aabb, b: &Aabb, rng: &mut crate::core::Rng, n: usize) -> bool {
        let mut point_of =
            |x: &Aabb| x.min + (x.max - x.min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        (0..n).any(|_| {
            let (p, q) = (point_of(a), point_of(l));
            segment_hits_box(p, q - p, 1.0, b)
        })
    }

    #[test]
    fn the_hull_test_is_exact_against_sampled_segments() {
        // Conservative: whenever a sampled segment from a into l touches b, meets_hull says
        // so. Tight: when it says so for boxes of real size, dense sampling finds a segment.
        // Half the cases start from a point (a box with min == max), half from a box.
        // Negative control, by hand: the high face moving from a's low corner (a box start
        // treated as its corner) fails the conservative assertion.
        let mut rng = crate::core::Rng::for_sample(3, 0, 0, 0);
        let random_box = |rng: &mut crate::core::Rng, size: f32, least: f32| {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0;
            let h = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * size + Vec3::splat(least);
            Aabb { min: c - h, max: c + h }
        };
        let (mut met, mut missed) = (0, 0);
        for case in 0..2000 {
            let a = if case % 2 == 0 { random_box(&mut rng, 0.0, 0.0) } else { random_box(&mut rng, 1.0, 0.0) };
            let (l, b) = (random_box(&mut rng, 2.0, 0.2), random_box(&mut rng, 1.5, 0.2));
            let exact = meets_hull(&a, &l, &b);
            let sampled = sampled_hull_meets(&a, &l, &b, &mut rng, 4000);
            assert!(exact || !sampled, "a segment from {a:?} into {l:?} touches {b:?}, but meets_hull says no");
            if exact {
                met += 1;
                missed += usize::from(!sampled);
            }
        }
        assert!(met > 100, "too few meeting cases to tell: {met}");
        assert!(missed * 20 < met, "meets_hull said yes {missed} times of {met} where no segment was found");
    }

    #[test]
    fn the_hull_is_tighter_than_the_boxes_union() {
        // A box beside the hull of a point under a light, but inside their bounding box: the
        // union test flags it, the hull test does not.
        let light = Aabb { min: Vec3::new(-1.0, 10.0, -1.0), max: Vec3::new(1.0, 10.0, 1.0) };
        let p = Vec3::new(-5.0, 0.0, 0.0);
        let p = Aabb { min: p, max: p };
        let aside = Aabb { min: Vec3::new(-1.0, 1.0, -0.5), max: Vec3::new(0.0, 2.0, 0.5) };
        assert!(!meets_hull(&p, &light, &aside));
        let on_the_way = Aabb { min: Vec3::new(-4.0, 2.0, -0.5), max: Vec3::new(-3.0, 3.0, 0.5) };
        assert!(meets_hull(&p, &light, &on_the_way));
    }

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
