//! Moving lights (Moreau et al. 2019, §3.1 and §4): update path origins, verify the new primary
//! segments, count DM_C, prune over-full cells and fill short ones.
//!
//! Steps for a light that moved this tick, fused into one parallel pass over its paths as the
//! paper fuses its kernels:
//! 1. **Update the origin.** Point and spot: the origin is the light's new position and the
//!    direction points at the path's first photon. Area: the direction is kept and the origin
//!    is where it meets the light's new plane; a miss of the shape invalidates the path. A path
//!    that left the scene straight from the light keeps its direction (from the light's centre
//!    for point and spot lights; moved rigidly with the light for area lights).
//! 2. **Verify the new primary segment against the full scene** with an occlusion ray (the paper
//!    skips this for area lights, which lets light leak through walls). An occluded segment is
//!    re-intersected along its direction and its tail retraced. A first photon on a specular
//!    surface, or one now lit from its other side, keeps the segment and retraces what it
//!    reflected (in a new direction; the roulette that let it go on stands).
//! 3. **DM_C** counts the valid paths per cell; a path whose ray no cell holds is invalid.
//!
//! Then, for a light that moved or whose map has not settled since:
//! 4. **Prune**: in a cell with DM_C > DM_T each path is dropped with probability
//!    (DM_C − DM_T)/DM_C (eq. 1), marked in a first pass, counted out in a second.
//! 5. **Fill**: the freed slots (invalid and pruned paths) are handed to the cells below target,
//!    chosen at random among the missing paths when there are more of those than slots, and
//!    emitted inside their cell.
//!
//! A spot light's falloff makes a path's flux depend on its direction: when the direction
//! changes, the path's photons are rescaled by the exact ratio of the new to the old flux.
//!
//! An edit of a light's intensity or colour alone traces nothing: every flux its paths carry
//! is linear in it, so [`rescale`] multiplies them by the exact factor new/old per channel.
use super::distribution::{DistributionMap, EmissionFrame};
use super::store::PathStore;
use super::trace::{photon_at, surface_normal, Retrace};
use crate::core::{PackedDir, Rgb, Rng};
use crate::embree::Ray;
use crate::scene::{Scene, SceneAccel};
use crate::technique::nee::SHADOW_EPSILON;
use glam::{Affine3A, Vec3};
use rayon::prelude::*;

/// Separates prune and fill random streams from the others keyed by the same numbers.
const PRUNE_STREAM: u64 = 0x0050_5255_4e45; // "PRUNE"
const FILL_STREAM: u64 = 0x4649_4c4c; // "FILL"

/// A light with a distribution map: its frame as of the current tick, its map, and the path
/// slots it owns (its contiguous paths, fixed when they were assigned).
#[derive(Clone, Debug)]
pub struct MappedLight {
    pub frame: EmissionFrame,
    pub map: DistributionMap,
    pub slots: std::ops::Range<usize>,
}

/// Where a path stands after its light moved.
#[derive(Clone, Copy, Debug)]
pub enum Moved {
    /// Valid from the new origin; `retrace` says what the new origin broke, if anything.
    Kept { origin: Vec3, dir: Vec3, scale: Rgb, cell: u32, retrace: Option<Retrace> },
    /// No cell holds the path's ray any more: its slot is refilled.
    Invalid,
}

/// Steps 1–2 for one path of a light that moved from `old_world_from_object`; `paths_of_light`
/// is how many paths share the light's power. Returns the outcome and the rays traced.
pub fn update_origin(
    scene: &Scene,
    accel: &SceneAccel,
    store: &PathStore,
    path: usize,
    frame: &EmissionFrame,
    old_world_from_object: Affine3A,
    paths_of_light: u32,
) -> (Moved, u64) {
    let light = store.light_of(path);
    let geometry = &scene.lights[light].geometry;
    let photons = store.word[path].photons();
    let old_power = store.emit_power[path];
    if old_power.is_black() {
        return (Moved::Invalid, 0);
    }
    let position = scene.light_position(light);
    let first = (photons > 0).then(|| photon_at(store, path, 0));
    let placed = match (&first, frame.is_area(), &store.origin) {
        (Some(p), false, _) => Some((position, (p.position - position).normalize_or_zero())),
        (None, false, _) => Some((position, store.emit_dir[path].get())),
        (Some(p), true, _) => {
            frame.origin_on_plane(p.position, store.emit_dir[path].get()).map(|o| (o, store.emit_dir[path].get()))
        }
        (None, true, Some(origins)) => {
            let moved = frame.world_from_object() * old_world_from_object.inverse();
            Some((
                moved.transform_point3(origins[path]),
                moved.transform_vector3(store.emit_dir[path].get()).normalize(),
            ))
        }
        (None, true, None) => None,
    };
    let Some((origin, dir)) = placed.filter(|(_, d)| *d != Vec3::ZERO) else { return (Moved::Invalid, 0) };
    let Some(cell) = frame.cell_of(origin, dir) else { return (Moved::Invalid, 0) };
    let new_power = geometry.emission_weight(dir) / paths_of_light.max(1) as f32;
    let per = |new: f32, old: f32| if old > 0.0 { new / old } else { 1.0 };
    let scale = Rgb::new(per(new_power.r, old_power.r), per(new_power.g, old_power.g), per(new_power.b, old_power.b));
    if new_power.is_black() {
        return (Moved::Invalid, 0);
    }
    // The new primary segment, against the full scene.
    let ray = match &first {
        Some(p) => Ray::segment(origin, p.position - origin, 1.0 - SHADOW_EPSILON),
        None => Ray::new(origin, dir),
    };
    let occluded = accel.scene().occluded1(&ray);
    let retrace = if occluded {
        Some(Retrace::KeepSegment(0))
    } else {
        first.and_then(|p| {
            let reflects = photons > 1 || store.escape[path] != PackedDir::NONE;
            let n = surface_normal(scene, &p);
            let material = &scene.materials[scene.objects[p.object as usize].material as usize];
            let flipped = n.dot(p.incoming).signum() != n.dot(dir).signum();
            (reflects && (material.is_specular() || flipped)).then_some(Retrace::Redirect(1))
        })
    };
    (Moved::Kept { origin, dir, scale, cell, retrace }, 1)
}

/// Writes a kept path's new origin into the store. Returns whether its photons changed (their
/// flux is rescaled unless `scale` is 1); their positions never do.
pub fn apply_moved(store: &mut PathStore, path: usize, origin: Vec3, dir: Vec3, scale: Rgb, cell: u32) -> bool {
    if let Some(origins) = &mut store.origin {
        origins[path] = origin;
    }
    store.emit_dir[path] = PackedDir::new(dir);
    store.word[path] = store.word[path].with_cell(cell).with_reused_light(true);
    if store.word[path].photons() > 0 {
        store.rows[0].incoming[path] = PackedDir::new(dir);
    }
    if scale == Rgb::WHITE {
        return false;
    }
    store.emit_power[path] *= scale;
    for row in store.rows.iter_mut().take(store.word[path].photons() as usize) {
        row.power[path] *= scale;
    }
    true
}

/// What balancing one light's map did.
#[derive(Clone, Debug, Default)]
pub struct Balance {
    pub work: Vec<(usize, Retrace)>,
    pub pruned: u64,
    pub filled: u64,
}

/// Steps 3–5 for one light: counts the valid paths (`valid[i]` for `slots[i]`), prunes, and
/// fills the freed slots. The map's DM_C is left as it will be once the fills are traced.
pub fn balance(lm: &mut MappedLight, store: &PathStore, valid: &[bool], seed: u64, tick: u64, light: usize) -> Balance {
    let (map, slots) = (&mut lm.map, lm.slots.clone());
    map.current.iter_mut().for_each(|c| *c = 0);
    for (slot, &ok) in slots.clone().zip(valid) {
        if ok {
            map.current[store.word[slot].cell() as usize] += 1;
        }
    }
    // Prune: mark with the counts as they were, then count the marked paths out.
    let pruned: Vec<bool> = slots
        .clone()
        .into_par_iter()
        .zip(valid)
        .map(|(slot, &ok)| {
            let cell = store.word[slot].cell() as usize;
            let (c, t) = (map.current[cell], map.target[cell]);
            ok && c > t && {
                let mut rng = Rng::for_sample(seed, tick, slot as u64, PRUNE_STREAM);
                rng.next_f32() < (c - t) as f32 / c as f32
            }
        })
        .collect();
    let mut free = Vec::new();
    let mut out = Balance::default();
    for ((slot, &ok), &cut) in slots.zip(valid).zip(&pruned) {
        if cut {
            map.current[store.word[slot].cell() as usize] -= 1;
            out.pruned += 1;
        }
        if cut || !ok {
            free.push(slot);
        }
    }
    // Fill: one missing path per free slot, at random when slots are short.
    let mut missing: Vec<u32> = Vec::new();
    for (cell, (&t, &c)) in map.target.iter().zip(&map.current).enumerate() {
        missing.extend(std::iter::repeat_n(cell as u32, t.saturating_sub(c) as usize));
    }
    let mut rng = Rng::for_sample(seed, tick, light as u64, FILL_STREAM);
    if missing.len() > free.len() {
        for i in 0..free.len() {
            let j = i + (rng.next_u32() as usize % (missing.len() - i));
            missing.swap(i, j);
        }
        missing.truncate(free.len());
    }
    for (k, &slot) in free.iter().enumerate() {
        match missing.get(k) {
            Some(&cell) => {
                map.current[cell as usize] += 1;
                out.work.push((slot, Retrace::Fill(cell)));
                out.filled += 1;
            }
            None => out.work.push((slot, Retrace::Emit)),
        }
    }
    out
}

/// Scales every flux light `l`'s paths carry, their segment-0 flux and every photon's, by
/// `factor` per channel. No rays. Returns the paths it changed.
pub fn rescale(store: &mut PathStore, l: usize, factor: Rgb) -> Vec<usize> {
    let paths: Vec<usize> = store.paths_of(l).collect();
    let photons: Vec<u32> = paths.iter().map(|&i| store.word[i].photons()).collect();
    for &i in &paths {
        store.emit_power[i] *= factor;
    }
    store.rows.par_iter_mut().enumerate().for_each(|(k, row)| {
        for (&i, &n) in paths.iter().zip(&photons) {
            if (k as u32) < n {
                row.power[i] *= factor;
            }
        }
    });
    paths
}

#[cfg(test)]
mod tests {
    use crate::scene::edits::{self, Edit, SceneDelta};
    use crate::scene::{Scene, SceneAccel, Trs};
    use crate::technique::photon_reuse::{PhotonReuse, PhotonReuseConfig, ReuseMode};
    use crate::technique::{RenderContext, Technique};
    use glam::Vec3;
    use std::path::Path;

    /// The Cornell box (its area light makes every path store its origin) with a movable spot
    /// light in the middle of the room.
    fn cornell_with_a_bulb() -> Scene {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        let text = std::fs::read_to_string(root.join("cornell-box.json")).expect("bundled scene");
        let mut doc: serde_json::Value = serde_json::from_str(&text).expect("scene JSON");
        doc["lights"].as_array_mut().expect("lights").push(serde_json::json!({
            "name": "spot", "dynamic": true,
            "emitter": { "type": "spot", "intensity": [20000.0, 20000.0, 20000.0], "cone_deg": 30.0 },
            "transform": { "translation": [278.0, 300.0, 279.5] }
        }));
        doc["camera"]["resolution"] = serde_json::json!([16, 16]);
        let desc = serde_json::from_value(doc).expect("scene");
        Scene::from_desc(desc, &root, &root).expect("valid scene")
    }

    #[test]
    fn every_path_of_a_moved_spot_light_starts_at_its_new_position() {
        // A spot light that moves and turns leaves paths outside its cone (no power: invalid);
        // their slots are filled, and the fill took its origin from the path's stored origin,
        // where the light had been, whenever an area light made the store keep origins.
        let device = crate::embree::Device::new(2).expect("device");
        let mut scene = cornell_with_a_bulb();
        let mut accel = SceneAccel::build(&device, &scene).expect("accel");
        let config = PhotonReuseConfig { paths: 20_000, reuse: ReuseMode::Naive, ..PhotonReuseConfig::default() };
        let mut technique = PhotonReuse::new(config, &scene).expect("technique");
        let spot = scene.light_index("spot").expect("spot");
        let mut last = crate::technique::photon_reuse::PhotonStats::default();
        for tick in 0..3u64 {
            let delta = match tick {
                0 => SceneDelta::default(),
                _ => {
                    // Up 20 and turned 50° each tick: every kept direction leaves the 30° cone.
                    let was = scene.desc().lights[spot].transform;
                    let turned = glam::Quat::from_rotation_x(0.87) * glam::Quat::from_array(was.rotation);
                    let at = [was.translation[0], was.translation[1] + 20.0, was.translation[2]];
                    let transform = Trs { translation: at, rotation: turned.to_array(), ..was };
                    let edit = Edit::Light { name: "spot".into(), transform: Some(transform), emitter: None };
                    edits::apply(&mut scene, vec![edit]).expect("valid edit")
                }
            };
            let moved: Vec<_> = delta.moved.iter().map(|m| m.surface).collect();
            accel.update_instances(&scene, &moved).expect("commit");
            let ctx = RenderContext { scene: &scene, accel: &accel, seed: 5, tick };
            last = technique.update(&ctx, &delta).expect("update").take();
        }
        let here = Vec3::from(scene.desc().lights[spot].transform.translation);
        let store = technique.store.as_ref().expect("store");
        let origins = store.origin.as_ref().expect("origins are stored with an area light");
        let ours: Vec<usize> = store.paths_of(spot).collect();
        let stale = ours.iter().filter(|&&p| origins[p].distance(here) > 1e-3).count();
        assert!(last.filled > 0, "no path was filled: the test would not see a fill");
        assert_eq!(stale, 0, "{stale} of the spot's {} paths start elsewhere than its position", ours.len());
    }
}
