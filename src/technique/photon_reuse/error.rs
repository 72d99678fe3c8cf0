//! Error-threshold verification (Moreau et al. 2019, §3.3, Algorithm 1): a segment a moved
//! surface may cross is re-traced against the full scene; the path keeps going while the energy
//! reflected at each new vertex stays within `threshold` of what was stored.
//!
//! For segment k from vertex k−1 (the light for k = 0) towards photon k:
//! 1. Skip rule: if the segment misses every moved box, or passes through one but meets none of
//!    the moved surfaces where they are now (an occlusion ray against them alone, `verify.rs`),
//!    neither end lies on a moved object, and its start did not move, nothing can have
//!    changed: no ray against the full scene. (Where the moved surfaces were needs no test: the
//!    stored segment was traced with them there, so it either ends on one or misses them.)
//! 2. Otherwise trace a ray from the (possibly moved) start towards the stored end. Nothing or a
//!    light hit: the path now ends there (it leaves the scene; lights absorb).
//! 3. At the new end, compare the energy reflected towards the next stored vertex,
//!    E_N = f(−ω_in, ω_out)·|n·ω_out| with the new geometry and material, to E_O, the same with
//!    the stored geometry and the material the stored energies were made with. Within
//!    |E_N − E_O| ≤ T·E_O per channel the stored photon energies are kept untouched, so error
//!    never accumulates over ticks (always against E_O); otherwise the photon moves to the new
//!    end and the path goes on from there (`continuation`): along its stored direction when
//!    the vertex only translated with its object, else from a fresh BSDF sample. A vertex that
//!    is new (on another object, or on a turned one) always goes on from a fresh sample: the
//!    check is made only where its verdict cannot depend on what the stored direction hit.
//! 4. A new end within 10⁻⁴ of the segment's length of the stored one keeps the stored photon,
//!    and the next segment is skipped by rule 1 when its own tests allow.
//!
//! Material edits without motion change the energy reflected at a photon by the exact factor
//! f_new/f_old; the same threshold decides whether that photon's tail is retraced. Specular
//! vertices only pass when nothing about them changed: their f is a delta.
//!
//! Russian roulette: a path that roulette ended at a photon that moved, or whose material
//! changed, draws its roulette again there (a fresh tail). Keeping the old verdict would bias
//! the estimate low: the path would go on with probability q_old·q_new instead of q_new.
use super::store::PathStore;
use super::trace::{leaving, path_origin, photon_at, photon_normals, put_photon, surface_normal, Photon, Retrace};
use super::verify::{Changes, Crossing, VerifyWork};
use crate::core::{PackedDir, Rgb};
use crate::embree::Ray;
use crate::scene::{Material, Scene, SceneAccel, SurfaceId, Transport};
use glam::Vec3;

/// A new end this close to the stored one (relative to the segment's length) is the same.
const SAME_PLACE: f32 = 1e-4;

/// What verification decided for a path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    Valid,
    Retrace(Retrace),
    /// The path now ends after `photons` photons: leaving along `escape`, or absorbed (zero).
    End {
        photons: u32,
        escape: Vec3,
    },
}

/// Verification of one path: its outcome, the photons that moved (row, new photon) with their
/// stored energies kept, and what the check cost.
#[derive(Clone, Debug)]
pub struct Checked {
    pub outcome: Outcome,
    pub moved: Vec<(u32, Photon)>,
    pub work: VerifyWork,
}

/// Energy reflected at photon `p` (lying on `material`) towards `out`, per unit arriving flux.
fn reflected(scene: &Scene, material: &Material, p: &Photon, out: Vec3) -> Rgb {
    let normals = photon_normals(scene, p);
    material.eval(normals, -p.incoming, out, Transport::Importance) * normals.geometric.dot(out).abs()
}

fn within(new: Rgb, old: Rgb, threshold: f32) -> bool {
    let ok = |n: f32, o: f32| (n - o).abs() <= threshold * o;
    ok(new.r, old.r) && ok(new.g, old.g) && ok(new.b, old.b)
}

/// Runs Algorithm 1 on `path`. `mask`: the screen's bits (segments that need the box tree).
pub fn check_path(
    scene: &Scene,
    accel: &SceneAccel,
    store: &PathStore,
    path: usize,
    changes: &Changes,
    threshold: f32,
    mask: u16,
) -> Checked {
    let photons = store.word[path].photons();
    let escape = store.escape[path].get();
    let check = PathCheck {
        scene,
        accel,
        store,
        path,
        changes,
        threshold,
        photons,
        escape,
        segments: photons + u32::from(escape != Vec3::ZERO),
    };
    let mut out = Checked { outcome: Outcome::Valid, moved: Vec::new(), work: VerifyWork::default() };
    let mut at = Cursor { start: path_origin(scene, store, path), start_object: None, updated: None };
    for k in 0..check.segments {
        // Only the end's position and object are read until a ray is needed.
        let stored_end = (k < photons).then(|| {
            (store.rows[k as usize].position[path], store.surfaces.object(store.rows[k as usize].surface[path]))
        });
        let (dir, t_max) = match stored_end {
            Some((position, _)) => (position - at.start, 1.0),
            None => (escape, f32::INFINITY),
        };
        let end_moved = stored_end.is_some_and(|(_, o)| changes.moved[o as usize]);
        let start_on_moved = at.start_object.is_some_and(|o| changes.moved[o as usize]);
        // A segment with a moved end, or from a start that moved, is traced whatever crosses it.
        let traced = end_moved || at.updated.is_some() || start_on_moved;
        let crossing = if traced { Crossing::default() } else { changes.crosses(mask, k, at.start, dir, t_max) };
        out.work.count(crossing);
        if !crossing.crossed && !traced {
            let Some((end_position, end_object)) = stored_end else { break };
            if let Some(outcome) = check.untraced_end(k, end_position, end_object) {
                out.outcome = outcome;
                return out;
            }
            at = Cursor { start: end_position, start_object: Some(end_object), updated: None };
            continue;
        }
        // The escape segment met no object; a moved one now lies on it (the exact test, from a
        // start that did not move), so a full-scene ray could only find an object: retrace it.
        if stored_end.is_none() && !traced && changes.object_crosses(&crossing) {
            out.outcome = Outcome::Retrace(Retrace::KeepSegment(k));
            return out;
        }
        let Some(next) = check.traced_segment(k, &at, stored_end.is_some(), dir, &mut out) else { return out };
        at = next;
    }
    out
}

/// What every step of one path's check reads.
struct PathCheck<'a> {
    scene: &'a Scene,
    accel: &'a SceneAccel,
    store: &'a PathStore,
    path: usize,
    changes: &'a Changes,
    threshold: f32,
    photons: u32,
    escape: Vec3,
    segments: u32,
}

/// Where the walk along a path stands before a segment: its start (the light's origin, or
/// vertex k−1) with its object, and vertex k−1 if this tick moved it (otherwise the store has
/// it).
struct Cursor {
    start: Vec3,
    start_object: Option<u32>,
    updated: Option<Photon>,
}

/// A segment's ray found its end on an object: the stored end, the photon there now, the
/// segment's unit direction, and whether the new end is the stored place (and, further, the
/// stored triangle in the orientation it was sampled with).
struct Found {
    end: Photon,
    new: Photon,
    dir_n: Vec3,
    same_place: bool,
    oriented: bool,
}

impl PathCheck<'_> {
    fn material_of(&self, object: u32) -> &Material {
        &self.scene.materials[self.scene.objects[object as usize].material as usize]
    }

    /// The material the stored energies at an object were computed with.
    fn stored_material_of(&self, object: u32) -> &Material {
        self.changes.previous_material[object as usize].as_ref().unwrap_or(self.material_of(object))
    }

    /// The stored direction leaving photon k (at `at`), if the path goes on from it.
    fn next_out(&self, k: u32, at: Vec3) -> Option<Vec3> {
        (k + 1 < self.segments).then(|| match k + 1 < self.photons {
            true => (self.store.rows[k as usize + 1].position[self.path] - at).normalize_or_zero(),
            false => self.escape,
        })
    }

    /// Roulette ended the path at photon k (it has no next segment, and could have had one).
    fn ended_by_roulette(&self, k: u32) -> bool {
        k + 1 == self.segments && k + 1 < self.store.max_photons as u32
    }

    /// Rule 1 held for segment k, so its end stands; only the material there may have changed,
    /// and then its exact factor decides. Returns the outcome if the path stops being valid.
    fn untraced_end(&self, k: u32, end_position: Vec3, end_object: u32) -> Option<Outcome> {
        let old = self.changes.previous_material[end_object as usize].as_ref()?;
        // A new material at a photon where roulette ended the path changes the roulette.
        if self.ended_by_roulette(k) {
            return Some(Outcome::Retrace(Retrace::FreshFrom(k + 1)));
        }
        let wo = self.next_out(k, end_position)?;
        let e = photon_at(self.store, self.path, k as usize);
        let current = self.material_of(e.object);
        let same = !old.is_specular()
            && !current.is_specular()
            && within(reflected(self.scene, current, &e, wo), reflected(self.scene, old, &e, wo), self.threshold);
        (!same).then_some(Outcome::Retrace(Retrace::FreshFrom(k + 1)))
    }

    /// Rule 2 for segment k: a visibility ray along it (Algorithm 1, line 5), then rules 3–4 at
    /// the end it finds. Returns where the next segment starts, or `None` once `out.outcome`
    /// is decided.
    fn traced_segment(&self, k: u32, at: &Cursor, has_end: bool, dir: Vec3, out: &mut Checked) -> Option<Cursor> {
        let found = self.trace(k, at, has_end, dir, out)?;
        self.judge(k, found, out)
    }

    /// Traces segment k's ray and finds the photon at its end now; `None` with `out.outcome`
    /// set when the path now ends or (the escape segment) stays valid or is blocked.
    fn trace(&self, k: u32, at: &Cursor, has_end: bool, dir: Vec3, out: &mut Checked) -> Option<Found> {
        let (scene, accel) = (self.scene, self.accel);
        let dir_n = dir.normalize_or_zero();
        let ray_origin = match at.start_object {
            None => at.start,
            Some(_) => {
                leaving(scene, &at.updated.unwrap_or_else(|| photon_at(self.store, self.path, k as usize - 1)), dir_n)
            }
        };
        out.work.scene_rays += 1;
        let hit = accel.scene().intersect1(&Ray::new(ray_origin, dir_n));
        if !has_end {
            // The escape segment: valid while it still meets no object (nothing, or a light).
            if hit.and_then(|h| accel.resolve(&h)).is_some_and(|(surface, _)| matches!(surface, SurfaceId::Object(_))) {
                out.outcome = Outcome::Retrace(Retrace::KeepSegment(k));
            }
            return None;
        }
        let end = photon_at(self.store, self.path, k as usize);
        let resolved = hit.and_then(|h| accel.resolve(&h).map(|r| (h, r)));
        let Some((h, (SurfaceId::Object(object), prim))) = resolved else {
            // The segment now leaves the scene or ends on a light: the path ends here.
            out.outcome = Outcome::End { photons: k, escape: dir_n };
            return None;
        };
        let sp = scene.surface_point(SurfaceId::Object(object), prim, h.u, h.v);
        let same_place = object == end.object && (sp.p - end.position).length() <= SAME_PLACE * dir.length();
        // On a turned object the same place can lie on another triangle (or on its own, turned):
        // the photon takes the triangle hit now, and stays the stored one only if that is the
        // same triangle with the orientation it was sampled with.
        let changes = self.changes;
        let oriented =
            same_place && prim == end.prim && (!changes.moved[object as usize] || changes.translated[object as usize]);
        let new = if same_place {
            Photon { incoming: dir_n, prim, ..end }
        } else {
            Photon { position: sp.p, incoming: dir_n, object, prim, power: end.power }
        };
        Some(Found { end, new, dir_n, same_place, oriented })
    }

    /// Rules 3–4 at segment k's new end: keep the stored energies (and go on) or decide how the
    /// path is retraced.
    fn judge(&self, k: u32, found: Found, out: &mut Checked) -> Option<Cursor> {
        let Found { end, new, dir_n, same_place, oriented } = found;
        let mut retrace = |from: Retrace| {
            out.moved.push((k, new));
            out.outcome = Outcome::Retrace(from);
            None
        };
        // A path that Russian roulette ended at the old end must draw its roulette again where
        // it ends now, unless the roulette there is the same draw (see `keeps_verdict`):
        // keeping the old verdict would end it with probability (1−q_old) and continue it only
        // with q_old·q_new, losing energy.
        let same_material = self.stored_material_of(end.object) == self.material_of(new.object);
        let keeps = keeps_verdict(self.scene, self.changes, &end, &new, same_place, same_material);
        if self.ended_by_roulette(k) && !keeps {
            return retrace(Retrace::FreshFrom(k + 1));
        }
        // A vertex that is new (moved away from where it was, other than by translating with
        // its object and material) goes on from a fresh sample whatever lay beyond it: keeping
        // the continuations that pass the energy check would keep every escaping one (same
        // direction, exact energy) and few that hit geometry, a selection by outcome.
        if !(same_place || keeps) && self.next_out(k, end.position).is_some() {
            return retrace(Retrace::FreshFrom(k + 1));
        }
        // Compare the energy reflected at the new end with the stored (lines 11–12).
        let unchanged_ray = oriented && (dir_n - end.incoming).length() <= SAME_PLACE;
        if let (Some(old_out), Some(new_out)) = (self.next_out(k, end.position), self.next_out(k, new.position)) {
            let (old_m, new_m) = (self.stored_material_of(end.object), self.material_of(new.object));
            let close = if old_m.is_specular() || new_m.is_specular() {
                unchanged_ray && old_m == new_m
            } else {
                within(
                    reflected(self.scene, new_m, &new, new_out),
                    reflected(self.scene, old_m, &end, old_out),
                    self.threshold,
                )
            };
            if !close {
                return retrace(continuation(same_place && same_material, keeps, k + 1));
            }
        }
        // Store the new end unless it is the stored one (then the stored photon stays exact).
        let stored = if unchanged_ray { end } else { new };
        if stored != end {
            out.moved.push((k, stored));
        }
        Some(Cursor {
            start: stored.position,
            start_object: Some(stored.object),
            updated: (stored != end).then_some(stored),
        })
    }
}

/// Whether vertex k's roulette verdict and sampled direction still hold at its new place
/// `new`: it kept its material and either stayed, or moved with its object, which only
/// translated, and lies on a face of the same orientation (so its normal, its BSDF weights and
/// its roulette probability are those it was sampled with; another face of a moved box is
/// not: a direction sampled above the top face may point into the box from its side).
fn keeps_verdict(
    scene: &Scene,
    changes: &Changes,
    end: &Photon,
    new: &Photon,
    same_place: bool,
    same_material: bool,
) -> bool {
    let same_face = || surface_normal(scene, new).dot(surface_normal(scene, end)) >= 1.0 - 1e-6;
    same_material
        && (same_place || (new.object == end.object && changes.translated[new.object as usize] && same_face()))
}

/// How a path goes on from vertex k when its energy check failed; `next` = k + 1.
/// - The vertex and its material stayed: a fresh direction, and its roulette verdict stands.
/// - The vertex keeps its verdict after moving with its object (`keeps_verdict`): the stored
///   direction is re-intersected from the new place with its stored flux. Drawing a fresh
///   direction here would resample exactly the continuations that hit geometry, since one that
///   escaped passes the check unchanged (same direction, same weight): a selection by outcome
///   that thinned the flux landing on surfaces (−0.35% at T = 0.001 on the Cornell box before
///   this rule). Likewise a path roulette ended there stays ended: redrawing only those would
///   continue paths with probability q(2 − q) instead of q.
/// - Otherwise (the vertex stayed but its material changed): a fresh direction and roulette.
fn continuation(stayed: bool, keeps: bool, next: u32) -> Retrace {
    if stayed {
        Retrace::Redirect(next)
    } else if keeps {
        Retrace::KeepSegment(next)
    } else {
        Retrace::FreshFrom(next)
    }
}

/// Writes what verification decided without tracing: moved photons (energies kept) and
/// shortened paths. Returns the retrace still to do.
pub fn apply(store: &mut PathStore, path: usize, checked: Checked) -> Option<Retrace> {
    for (row, p) in checked.moved {
        let power = store.rows[row as usize].power[path];
        put_photon(store, row as usize, path, &Photon { power, ..p });
    }
    match checked.outcome {
        Outcome::Valid => None,
        Outcome::Retrace(r) => Some(r),
        Outcome::End { photons, escape } => {
            store.word[path] = store.word[path].with_photons(photons);
            store.escape[path] = PackedDir::new(escape);
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::scene::edits::{self, Edit, SceneDelta};
    use crate::scene::{Scene, SceneAccel, SurfaceId, Trs};
    use crate::technique::photon_reuse::{PhotonReuse, PhotonReuseConfig, ReuseMode};
    use crate::technique::{RenderContext, Technique};
    use glam::{Quat, Vec3};

    const SEGMENTS: u32 = 16;

    /// A closed sphere of `SEGMENTS` segments about +Z, dynamic, lit by a point light at its
    /// centre: turned by one segment, it is the same surface with every triangle renumbered.
    fn lit_sphere() -> Scene {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        let desc = serde_json::from_value(serde_json::json!({
            "camera": {"position": [0, 0, 0.5], "look_at": [0, 0, -1], "vfov_deg": 60, "resolution": [4, 4]},
            "materials": {"half": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
            "objects": [{"name": "ball", "shape": {"type": "sphere", "segments": SEGMENTS}, "material": "half",
                         "dynamic": true}],
            "lights": [{"name": "bulb", "emitter": {"type": "point", "intensity": [1, 1, 1]}}]
        }))
        .expect("scene description");
        Scene::from_desc(desc, &root, &root).expect("valid scene")
    }

    /// Whether `p` lies on triangle [a, b, c] (in its plane, inside its edges).
    fn on_triangle(p: Vec3, [a, b, c]: [Vec3; 3]) -> bool {
        let n = (b - a).cross(c - a);
        let inside = |u: Vec3, v: Vec3| (v - u).cross(p - u).dot(n) >= -1e-4 * n.length_squared();
        (p - a).dot(n.normalize()).abs() <= 1e-4 && inside(a, b) && inside(b, c) && inside(c, a)
    }

    #[test]
    fn a_photon_kept_in_place_on_a_turned_mesh_takes_the_triangle_now_there() {
        // Property: after the sphere turns by one segment, error mode finds every photon on it
        // in the same place (the surface did not change), and each stored photon's triangle is
        // the one it lies on now, so its normal and ray offsets are right. Before the fix the
        // photon kept its old triangle, which had turned away. Negative control: pairing each
        // photon with the next triangle fails the same check.
        let device = crate::embree::Device::new(2).expect("device");
        let mut scene = lit_sphere();
        let mut accel = SceneAccel::build(&device, &scene).expect("accel");
        let config = PhotonReuseConfig { paths: 4000, reuse: ReuseMode::Error, refine: 0.0, ..Default::default() };
        let mut technique = PhotonReuse::new(config, &scene).expect("technique");
        let ctx = RenderContext { scene: &scene, accel: &accel, seed: 3, tick: 0 };
        technique.update(&ctx, &SceneDelta::default()).expect("first tick");
        let before = technique.store.as_ref().expect("store").rows[0].position.clone();

        let turn = Quat::from_rotation_z(std::f32::consts::TAU / SEGMENTS as f32).to_array();
        let edit = Edit::Object { name: "ball".into(), transform: Trs { rotation: turn, ..Trs::default() } };
        let delta = edits::apply(&mut scene, vec![edit]).expect("valid edit");
        let moved: Vec<_> = delta.moved.iter().map(|m| m.surface).collect();
        accel.update_instances(&scene, &moved).expect("commit");
        let ctx = RenderContext { scene: &scene, accel: &accel, seed: 3, tick: 1 };
        technique.update(&ctx, &delta).expect("turned tick");

        let store = technique.store.as_ref().expect("store");
        let triangles = scene.objects[0].mesh.triangles.len() as u32;
        let (mut kept, mut wrong, mut wrong_next, mut photons) = (0, 0, 0, 0);
        for (path, first_before) in before.iter().enumerate() {
            for k in 0..store.word[path].photons() as usize {
                let (object, prim) = store.surfaces.object_and_prim(store.rows[k].surface[path]);
                let p = store.rows[k].position[path];
                photons += 1;
                kept += usize::from(k == 0 && p == *first_before);
                wrong += usize::from(!on_triangle(p, scene.triangle(SurfaceId::Object(object), prim)));
                let next = (prim + 1) % triangles;
                wrong_next += usize::from(!on_triangle(p, scene.triangle(SurfaceId::Object(object), next)));
            }
        }
        assert!(kept > store.paths / 2, "only {kept} first photons stayed in place: the test is weak");
        assert_eq!(wrong, 0, "{wrong} of {photons} photons lie off their stored triangle");
        assert!(wrong_next > photons / 2, "the neighbouring triangle passed for {wrong_next} of {photons}");
    }
}
