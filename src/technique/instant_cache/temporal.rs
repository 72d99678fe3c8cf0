//! Temporal instant caching (Debattista et al. §3.2, Algorithm 1): the cache is kept across
//! ticks and only what this tick's edits invalidated is re-evaluated.
//!
//! Per record and VPL (matched to last tick's VPL by key, `vpl.rs`):
//! - **Cases 1–2** (VPL occluded or deoccluded, a light moved, a material changed): a VPL whose
//!   position or normal changed, or which is new, gets its visibility ray traced against the
//!   full scene. A VPL that kept its place but changed intensity keeps its visibility.
//! - **Case 3** (ray now occluded): every other ray that touches a moved surface's new bounds
//!   is traced against a separate scene holding only the moved surfaces where they are now
//!   (the same bottom-level scenes and transforms as the full scene, so the answer is the one
//!   the full scene would give for them). An unchanged VPL that was visible keeps its stored
//!   contribution unless case 3 finds it blocked: its G′ is not worked out again.
//! - **Case 4** (ray deoccluded): a ray that was in shadow and not found occluded by case 3 is
//!   tested against the moved surfaces' old world AABBs; only if it touches one is it traced
//!   against the full scene. (Case 3 runs first for such a ray too: tracing it against the
//!   moved surfaces alone is cheaper, and it usually finds the shadow still there.)
//! - **Case 5** (record on a moved object): removed; the areas are refilled on demand. The
//!   paper finds these records as those inside the moved objects' old bounds; a record here
//!   knows its object, so records on static surfaces inside those bounds (the floor under a
//!   bunny) stay and are refreshed like any other, instead of being recomputed.
//!
//! Invariant (tested): after a refresh every record's contributions and irradiance are
//! bit-identical to a record computed from scratch at its position with this tick's VPLs. The
//! argument: a ray's answer changes only if a moved surface lies on it now (case 3, traced
//! against exactly those surfaces) or lay on it before (then it touched the old bounds and case 4
//! retraces it); a VPL that moved is retraced outright; everything else is untouched geometry.
//! Boxes are widened by [`BOX_SLACK`] of the scene diagonal so a ray grazing a box in Embree's
//! arithmetic is never missed by the slab test's. Before the slab tests, a ray meets a cheaper
//! one: from each VPL's anchor, the cone around each moved box's bounding sphere
//! ([`SphereCone`], computed once a tick per VPL), which a ray that touches the box lies in.
//! A record tests all its rays against the cones in one pass ([`Cones::mark`], laid out so it
//! vectorises), and only the rays in a cone, or to a changed VPL, are looked at one by one:
//! the refresh costs per pair what a copy costs, and per affected ray what its tests cost.
//! Tiny contributions RGBE rounds to zero are indistinguishable from shadow; both give zero
//! whichever way they are classified, except when a VPL's intensity changes, and then such a
//! ray is retraced.
use super::cache::{contribution, Record};
use super::config::InstantCacheStats;
use super::rgbe;
use super::vpl::{irradiance_from, ray_origin, visibility_ray, Vpl};
use crate::embree::{CommittedScene, EmbreeError, Ray};
use crate::scene::edits::{Aabb, MovedSurface, SceneDelta};
use crate::scene::{Camera, Scene, SceneAccel, SurfaceId};
use crate::technique::box_tree::{meets_hull, widened, BoxTree, SphereCone, BOX_SLACK};
use glam::Vec3;
use std::sync::Arc;

/// A record's point, normal and ray origin, and the VPLs' clamping distance.
#[derive(Clone, Copy)]
struct RecordPoint {
    p: Vec3,
    n: Vec3,
    from: Vec3,
    min_distance: f32,
}

/// How a VPL of this tick relates to last tick's VPL with the same key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VplChange {
    /// Identical: last tick's index.
    Same(u32),
    /// Same position and normal, another intensity: its visibility carries over.
    Reweighted(u32),
    /// New or moved: traced against the full scene (cases 1–2).
    Invalidated,
}

/// This tick's VPLs against last tick's.
#[derive(Clone, Debug, Default)]
pub struct VplDiff {
    pub changes: Vec<VplChange>,
    /// Every VPL is `Same` at its old index and none was lost.
    pub identity: bool,
    pub reused: u64,
    pub reweighted: u64,
    pub invalidated: u64,
}

impl VplDiff {
    /// Matches `new` to `old` by key; both are in key order, as `vpl::shoot` deposits them.
    pub fn between(old: &[Vpl], new: &[Vpl]) -> VplDiff {
        let mut diff = VplDiff { identity: old.len() == new.len(), ..VplDiff::default() };
        let mut j = 0;
        for (i, v) in new.iter().enumerate() {
            while j < old.len() && old[j].key < v.key {
                j += 1;
            }
            let change = match old.get(j) {
                Some(o) if o.key == v.key && o.position == v.position && o.normal == v.normal => {
                    if o.intensity == v.intensity {
                        VplChange::Same(j as u32)
                    } else {
                        VplChange::Reweighted(j as u32)
                    }
                }
                _ => VplChange::Invalidated,
            };
            match change {
                VplChange::Same(o) => {
                    diff.reused += 1;
                    diff.identity &= o as usize == i;
                }
                VplChange::Reweighted(_) => diff.reweighted += 1,
                VplChange::Invalidated => diff.invalidated += 1,
            }
            diff.identity &= matches!(change, VplChange::Same(_));
            diff.changes.push(change);
        }
        diff
    }
}

/// The work one record's refresh did, by case.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Refresh {
    pub vpl_rays: u64,
    pub occlusion_box_tests: u64,
    pub occlusion_rays: u64,
    pub deocclusion_box_tests: u64,
    pub deocclusion_rays: u64,
    /// Contributions re-valued because their VPL changed intensity only.
    pub reweighted: u64,
    /// Contributions cases 3 and 4 changed.
    pub occluded: u64,
    pub deoccluded: u64,
}

impl Refresh {
    /// Adds one record's re-evaluation to the tick's figures.
    pub fn count(self, stats: &mut InstantCacheStats) {
        stats.records_refreshed += 1;
        stats.records_invalidated_vpl += u64::from(self.vpl_rays + self.reweighted > 0);
        stats.records_invalidated_occluded += u64::from(self.occluded > 0);
        stats.records_invalidated_deoccluded += u64::from(self.deoccluded > 0);
        stats.visibility_rays_vpl += self.vpl_rays;
        stats.visibility_rays_occlusion += self.occlusion_rays;
        stats.occlusion_box_tests += self.occlusion_box_tests;
        stats.visibility_rays_deocclusion += self.deocclusion_rays;
        stats.deocclusion_box_tests += self.deocclusion_box_tests;
    }
}

impl std::ops::AddAssign for Refresh {
    fn add_assign(&mut self, o: Refresh) {
        self.vpl_rays += o.vpl_rays;
        self.occlusion_box_tests += o.occlusion_box_tests;
        self.occlusion_rays += o.occlusion_rays;
        self.deocclusion_box_tests += o.deocclusion_box_tests;
        self.deocclusion_rays += o.deocclusion_rays;
        self.reweighted += o.reweighted;
        self.occluded += o.occluded;
        self.deoccluded += o.deoccluded;
    }
}

/// What one tick changed, prepared for the per-ray tests.
pub struct TickChanges {
    pub vpls: VplDiff,
    /// Per VPL of this tick, last tick's index (`u32::MAX` when `Invalidated`) and whether it
    /// is `Same`: [`VplDiff::changes`] laid out for a loop without branches.
    old_index: Vec<u32>,
    same: Vec<bool>,
    old_vpls: Vec<Vpl>,
    moved: Arc<Moved>,
    /// Per VPL of this tick, the moved surfaces' new and old bounds seen from its anchor: a
    /// cheap pre-test before the trees.
    new_cones: Cones,
    old_cones: Cones,
}

/// The surfaces a tick's edits moved, as the cache and the kept camera samples test rays
/// against them.
pub struct Moved {
    /// The moved surfaces at their new placement (`None` if nothing moved).
    pub now: Option<CommittedScene>,
    /// Their new and old world bounds, widened by [`BOX_SLACK`] of the diagonal, in the order
    /// of the edits and as trees.
    new_bounds: Vec<Aabb>,
    old_bounds: Vec<Aabb>,
    pub new_boxes: BoxTree,
    old_boxes: BoxTree,
    /// Each surface's old and new bounds together: one test for "where it is or was".
    swept_boxes: BoxTree,
    /// `objects[object]`: the object moved this tick.
    pub objects: Vec<bool>,
    /// A light's shape moved this tick.
    pub light_shapes: bool,
    /// The film rectangles (`[x0, y0, x1, y1]` in pixels, widened by a pixel) the new bounds
    /// project into, so a camera ray through a pixel outside all of them meets no moved
    /// surface; `None` when a box reaches to or behind the camera plane (any pixel may).
    screen: Option<Vec<[f32; 4]>>,
    width: usize,
}

impl Moved {
    pub fn new(scene: &Scene, accel: &SceneAccel, delta: &SceneDelta, diagonal: f32) -> Result<Moved, EmbreeError> {
        let slack = BOX_SLACK * diagonal;
        let now = if delta.moved.is_empty() {
            None
        } else {
            let surfaces: Vec<_> = delta.moved.iter().map(|m| m.surface).collect();
            Some(accel.subset(scene, &surfaces)?)
        };
        let mut objects = vec![false; scene.objects.len()];
        for m in &delta.moved {
            if let SurfaceId::Object(i) = m.surface {
                objects[i as usize] = true;
            }
        }
        let boxes =
            |b: fn(&MovedSurface) -> &Aabb| -> Vec<Aabb> { delta.moved.iter().map(|m| widened(b(m), slack)).collect() };
        let (new_bounds, old_bounds) = (boxes(|m| &m.new_bounds), boxes(|m| &m.old_bounds));
        let (new_boxes, old_boxes) = (BoxTree::new(new_bounds.clone()), BoxTree::new(old_bounds.clone()));
        let swept_boxes = BoxTree::new(new_bounds.iter().zip(&old_bounds).map(|(a, b)| a.union(b)).collect());
        let light_shapes = delta.moved.iter().any(|m| matches!(m.surface, SurfaceId::Light(_)));
        let screen = new_bounds.iter().map(|b| film_rect(&scene.camera, b)).collect();
        let width = scene.camera.width as usize;
        Ok(Moved {
            now,
            new_bounds,
            old_bounds,
            new_boxes,
            old_boxes,
            swept_boxes,
            objects,
            light_shapes,
            screen,
            width,
        })
    }

    /// May the camera ray through any point of a pixel of `pixels` (row-major indices) meet a
    /// moved surface where it is now?
    pub fn may_show(&self, pixels: std::ops::Range<usize>) -> bool {
        self.screen.as_ref().is_none_or(|rects| meets_rects(rects, self.width, pixels))
    }

    /// Is every segment from a point of `from` to a point of `to` clear of every moved
    /// surface's new and old bounds? (The hull test, exact on the boxes.)
    pub fn clear_of(&self, from: &Aabb, to: &Aabb) -> bool {
        !self.new_bounds.iter().chain(&self.old_bounds).any(|b| meets_hull(from, to, b))
    }

    /// May a moved surface lie on the segment of `ray`, where it is now or where it was? (A
    /// slab test against the box around both of its widened bounds: conservative.)
    pub fn on_ray(&self, ray: &Ray) -> bool {
        self.swept_boxes.hits(ray.origin, ray.dir, ray.tfar).0
    }
}

/// Does the bounding rectangle of `pixels` (row-major indices into rows `width` wide) meet one
/// of `rects` (film rectangles, `[x0, y0, x1, y1]` in pixels)? A pixel (x, y) covers [x, x + 1)
/// × [y, y + 1); pixels on several rows are bounded by whole rows.
fn meets_rects(rects: &[[f32; 4]], width: usize, pixels: std::ops::Range<usize>) -> bool {
    let (Some(last), w) = (pixels.end.checked_sub(1).filter(|&l| l >= pixels.start), width.max(1)) else {
        return false;
    };
    let (y0, y1) = (pixels.start / w, last / w);
    let (x0, x1) = if y0 == y1 { (pixels.start % w, last % w) } else { (0, w - 1) };
    let (x0, x1, y0, y1) = (x0 as f32, x1 as f32, y0 as f32, y1 as f32);
    rects.iter().any(|r| x1 + 1.0 >= r[0] && x0 <= r[2] && y1 + 1.0 >= r[1] && y0 <= r[3])
}

/// The film rectangle a box projects into, widened by a pixel; `None` when a corner is not in
/// front of the camera or a coordinate is not finite. A pinhole's projection of a box in front
/// of it lies in the hull of its corners' projections.
fn film_rect(camera: &Camera, b: &Aabb) -> Option<[f32; 4]> {
    let mut r = [f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY];
    for k in 0..8 {
        let corner = Vec3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        );
        let (x, y) = camera.film_point(corner).filter(|(x, y)| x.is_finite() && y.is_finite())?;
        r = [r[0].min(x - 1.0), r[1].min(y - 1.0), r[2].max(x + 1.0), r[3].max(y + 1.0)];
    }
    Some(r)
}

impl TickChanges {
    /// The changes between last tick's `old_vpls` and this tick's `vpls`, with the surfaces
    /// `moved`, or `None` when no record can be affected.
    pub fn new(moved: &Arc<Moved>, old_vpls: Vec<Vpl>, vpls: &[Vpl]) -> Option<TickChanges> {
        let diff = VplDiff::between(&old_vpls, vpls);
        if diff.identity && moved.now.is_none() {
            return None;
        }
        let old_index = diff
            .changes
            .iter()
            .map(|c| match *c {
                VplChange::Same(o) | VplChange::Reweighted(o) => o,
                VplChange::Invalidated => u32::MAX,
            })
            .collect();
        let same = diff.changes.iter().map(|c| matches!(c, VplChange::Same(_))).collect();
        Some(TickChanges {
            old_index,
            same,
            vpls: diff,
            old_vpls,
            new_cones: Cones::new(vpls, &moved.new_bounds),
            old_cones: Cones::new(vpls, &moved.old_bounds),
            moved: Arc::clone(moved),
        })
    }

    /// Case 5: the record lies on an object that moved.
    pub fn removes(&self, record: &Record) -> bool {
        self.moved.objects.get(record.object as usize).copied().unwrap_or(true)
    }

    /// Re-evaluates what this tick invalidated in `record` (cases 1–4), leaving it as a fresh
    /// computation with `vpls` would make it.
    pub fn refresh(&self, accel: &SceneAccel, vpls: &[Vpl], record: &mut Record, min_distance: f32) -> Refresh {
        let (p, n) = (record.position, record.normal);
        let from = ray_origin(p, n);
        let at = RecordPoint { p, n, from, min_distance };
        let mut work = Refresh::default();
        let (mut in_new, mut in_old) = (vec![false; vpls.len()], vec![false; vpls.len()]);
        if self.moved.now.is_some() {
            self.new_cones.mark(from, &mut in_new);
            self.old_cones.mark(from, &mut in_old);
        }
        let (mut contributions, open) = self.triage(&record.contributions, &in_new, &in_old);
        for k in open.into_iter().map(|k| k as usize) {
            let (vpl, before, cones) = (&vpls[k], contributions[k], (in_new[k], in_old[k]));
            contributions[k] = match self.vpls.changes[k] {
                VplChange::Invalidated => self.retrace(accel, vpl, &at, &mut work),
                VplChange::Same(_) if before != 0 => {
                    if self.still_visible(accel, vpl, from, true, cones, &mut work) {
                        before
                    } else {
                        work.occluded += 1;
                        0
                    }
                }
                VplChange::Same(o) | VplChange::Reweighted(o) => {
                    self.reevaluate(accel, (vpl, &self.old_vpls[o as usize]), &at, (before, cones), &mut work)
                }
            };
        }
        // Unchanged contributions sum to the same bits: only a changed record is re-summed.
        if contributions != record.contributions {
            *record = Record::new(p, n, record.object, contributions, record.last_used);
        }
        work
    }

    /// Each VPL's contribution before (0 for a new VPL), and the VPLs whose contribution may
    /// have changed: every VPL not `Same`, and a `Same` one whose ray lies in the new cones (if
    /// it was seen) or the old ones (if it was not). The rest keep their contribution without
    /// G′ or a ray. One pass without branches: which VPLs are open follows the shadows, which
    /// a branch would mispredict.
    fn triage(&self, before: &[u32], in_new: &[bool], in_old: &[bool]) -> (Vec<u32>, Vec<u32>) {
        let count = self.old_index.len().min(in_new.len()).min(in_old.len());
        let (mut contributions, mut open) = (vec![0u32; count], vec![0u32; count]);
        let mut opened = 0;
        for k in 0..count {
            let c = before.get(self.old_index[k] as usize).copied().unwrap_or(0);
            contributions[k] = c;
            open[opened] = k as u32;
            opened += usize::from(!self.same[k] | if c != 0 { in_new[k] } else { in_old[k] });
        }
        open.truncate(opened);
        (contributions, open)
    }

    /// A ray to a VPL that was in shadow and may no longer be, or that changed intensity: G′
    /// and visibility are worked out again. Takes the contribution before, and whether the ray
    /// lies in the new and the old cones.
    fn reevaluate(
        &self,
        accel: &SceneAccel,
        (vpl, old_vpl): (&Vpl, &Vpl),
        at: &RecordPoint,
        (before, cones): (u32, (bool, bool)),
        work: &mut Refresh,
    ) -> u32 {
        let RecordPoint { p, n, from, min_distance } = *at;
        let Some((e, _, _)) = irradiance_from(vpl, p, n, min_distance) else { return 0 };
        let visible_before = before != 0;
        if !visible_before && old_vpl.intensity != vpl.intensity {
            // Shadow and a contribution too small for RGBE look alike; only the latter can
            // become visible by a change of intensity.
            let was_tiny =
                irradiance_from(old_vpl, p, n, min_distance).is_some_and(|(e_old, _, _)| rgbe::pack(e_old) == 0);
            if was_tiny {
                return self.retrace(accel, vpl, at, work);
            }
        }
        let visible = self.still_visible(accel, vpl, from, visible_before, cones, work);
        let now = if visible { rgbe::pack(e) } else { 0 };
        work.reweighted += u64::from(now != before && visible_before && visible);
        match (visible_before, visible) {
            (true, false) => work.occluded += 1,
            (false, true) => work.deoccluded += 1,
            _ => {}
        }
        now
    }

    /// Cases 1–2: the VPL changed; trace its visibility ray against the full scene.
    fn retrace(&self, accel: &SceneAccel, vpl: &Vpl, at: &RecordPoint, work: &mut Refresh) -> u32 {
        let (c, rays) = contribution(accel, vpl, at.p, at.n, at.min_distance);
        work.vpl_rays += rays;
        c
    }

    /// Cases 3–4 for a ray to an unchanged VPL (`k`: its index this tick) that was
    /// `visible_before`.
    fn still_visible(
        &self,
        accel: &SceneAccel,
        vpl: &Vpl,
        from: Vec3,
        visible_before: bool,
        (in_new, in_old): (bool, bool),
        work: &mut Refresh,
    ) -> bool {
        let Some(moved_now) = &self.moved.now else { return visible_before };
        // Case 3: a moved surface now lies on the ray.
        if in_new {
            let ray = visibility_ray(from, vpl);
            let (near_new, tests) = self.moved.new_boxes.hits(ray.origin, ray.dir, ray.tfar);
            work.occlusion_box_tests += tests;
            if near_new {
                work.occlusion_rays += 1;
                if moved_now.occluded1(&ray) {
                    return false;
                }
            }
        }
        if visible_before {
            return true;
        }
        // Case 4: the shadow may have come from a moved surface where it was.
        if !in_old {
            return false;
        }
        let ray = visibility_ray(from, vpl);
        let (near_old, tests) = self.moved.old_boxes.hits(ray.origin, ray.dir, ray.tfar);
        work.deocclusion_box_tests += tests;
        if !near_old {
            return false;
        }
        work.deocclusion_rays += 1;
        !accel.scene().occluded1(&ray)
    }
}

/// The cones ([`SphereCone`]) of some boxes seen from each VPL's anchor, one column per box
/// with one entry per VPL, so one record's tests against every VPL run as one loop the compiler
/// vectorises.
struct Cones {
    columns: Vec<ConeColumn>,
}

/// One box's cones, per VPL: the apex, the axis, cos² β (less the test's 10⁻⁵ margin) and the
/// squared distance to the sphere; an apex inside the sphere reaches every direction.
#[derive(Default)]
struct ConeColumn {
    apex: [Vec<f32>; 3],
    axis: [Vec<f32>; 3],
    cos2: Vec<f32>,
    near2: Vec<f32>,
    inside: Vec<bool>,
}

impl Cones {
    fn new(vpls: &[Vpl], boxes: &[Aabb]) -> Cones {
        let column = |b: &Aabb| {
            let mut c = ConeColumn::default();
            for v in vpls {
                let cone = SphereCone::new(v.anchor, b);
                let axis = cone.map_or(Vec3::ZERO, |c| c.axis);
                for i in 0..3 {
                    c.apex[i].push(v.anchor[i]);
                    c.axis[i].push(axis[i]);
                }
                c.cos2.push(cone.map_or(0.0, |c| c.cos * c.cos * (1.0 - 1e-5)));
                c.near2.push(cone.map_or(0.0, |c| c.near * c.near));
                c.inside.push(cone.is_none());
            }
            c
        };
        Cones { columns: boxes.iter().map(column).collect() }
    }

    /// Sets `reach[k]` if the segment from VPL k's anchor to `to` may touch a box: the test of
    /// [`SphereCone::may_reach`], for every VPL at once.
    fn mark(&self, to: Vec3, reach: &mut [bool]) {
        reach.fill(false);
        for c in &self.columns {
            let n = reach.len().min(c.cos2.len());
            let (ax, ay, az) = (&c.apex[0][..n], &c.apex[1][..n], &c.apex[2][..n]);
            let (nx, ny, nz) = (&c.axis[0][..n], &c.axis[1][..n], &c.axis[2][..n]);
            let (cos2, near2, inside) = (&c.cos2[..n], &c.near2[..n], &c.inside[..n]);
            for k in 0..n {
                let d = [to.x - ax[k], to.y - ay[k], to.z - az[k]];
                let s = d[0] * nx[k] + d[1] * ny[k] + d[2] * nz[k];
                let length2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                reach[k] |= inside[k] | ((s > 0.0) & (s * s >= length2 * cos2[k]) & (length2 >= near2[k]));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_of_pixels_meets_a_rectangle_when_one_of_its_pixels_does() {
        // Property: a run of pixels meets a film rectangle if any of its pixels does (so a run
        // that does not needs none of its pixels tested), and within one row exactly then.
        // Checked against the pixels one by one, on random rectangles and runs, some across
        // rows. Negative control, by hand: bounding a run by its first pixel's column alone
        // fails the first assertion.
        let mut rng = crate::core::Rng::new(7, 8);
        let (width, height) = (37usize, 23usize);
        let (mut met, mut missed) = (0, 0);
        for _ in 0..3000 {
            let mut u = |s: f32| rng.next_f32() * s;
            let (x, y) = (u(width as f32 + 6.0) - 3.0, u(height as f32 + 6.0) - 3.0);
            let rects = [[x, y, x + u(16.0), y + u(10.0)]];
            let start = (u((width * height) as f32) as usize).min(width * height - 1);
            let len = 1 + u(if start % 3 == 0 { 80.0 } else { 20.0 }) as usize;
            let run = start..(start + len).min(width * height);
            let any = run.clone().any(|i| meets_rects(&rects, width, i..i + 1));
            let whole = meets_rects(&rects, width, run.clone());
            assert!(whole || !any, "{run:?} has a pixel in {rects:?}, but the run does not meet it");
            if run.start / width == (run.end - 1) / width {
                assert_eq!(whole, any, "{run:?} lies in one row: exact against {rects:?}");
            }
            (met, missed) = (met + usize::from(any), missed + usize::from(!whole));
        }
        assert!(met > 300 && missed > 300, "too few runs on either side: {met} met, {missed} missed");
    }

    #[test]
    fn a_box_in_front_of_the_camera_projects_inside_its_film_rectangle() {
        // Property: every point of a box in front of the camera crosses the film inside the
        // box's rectangle with a pixel to spare, so the camera ray through any point of a pixel
        // outside the rectangle misses the box; a box reaching behind the camera has none.
        // Negative control, by hand: dropping the pixel of margin fails the margin assertion.
        let camera = Camera {
            position: Vec3::new(0.3, 1.0, 4.0),
            forward: Vec3::NEG_Z,
            right: Vec3::X,
            up: Vec3::Y,
            tan_half_vfov: 0.5,
            width: 64,
            height: 48,
        };
        let mut rng = crate::core::Rng::new(5, 6);
        let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let mut behind = 0;
        for _ in 0..200 {
            let min = Vec3::new(u(-3.0, 3.0), u(-2.0, 3.0), u(-6.0, 4.0));
            let b = Aabb { min, max: min + Vec3::new(u(0.0, 1.5), u(0.0, 1.5), u(0.0, 1.5)) };
            let Some(r) = film_rect(&camera, &b) else {
                assert!(b.max.z >= camera.position.z, "{b:?} lies in front of the camera but has no rectangle");
                behind += 1;
                continue;
            };
            for _ in 0..50 {
                let p = Vec3::new(u(b.min.x, b.max.x), u(b.min.y, b.max.y), u(b.min.z, b.max.z));
                let (x, y) = camera.film_point(p).expect("a point of a box in front is in front");
                let inside = x - 1.0 >= r[0] && x + 1.0 <= r[2] && y - 1.0 >= r[1] && y + 1.0 <= r[3];
                assert!(inside, "{p:?} crosses the film at ({x}, {y}), outside {r:?} less a pixel");
            }
        }
        assert!((10..150).contains(&behind), "{behind} of 200 boxes reached behind the camera");
    }
}
