//! Client edits and what applying them changed.
//!
//! Edits arrive in batches; the latest edit per target wins (light and camera edits merge
//! field by field), and the number coalesced is reported, never hidden. A batch is validated
//! as a whole before anything is applied: a bad edit rejects the batch and changes nothing.
//! Applying yields a [`SceneDelta`] with old and new transforms and world bounds of everything
//! that moved, which techniques use to verify or invalidate what they store.
//!
//! An edit whose result equals the current value is not a change: a transform that gives the
//! same `world_from_object` bit for bit (so an unnormalised or negated quaternion of the same
//! rotation counts as the same), a light with the same placement and emitter, a camera with the
//! same fields, a material with the same parameters. It is counted in
//! [`SceneDelta::unchanged`] and goes no further: no film reset, no commit, no invalidation.
//! Animation players re-send every track every frame, so a held pose costs nothing.
use super::load::{check_placement, validate_emitter, validate_material, validate_trs, SceneError};
use super::model::{CameraDesc, EmitterDesc, Material, Trs};
use super::{light, Scene, SurfaceId};
use glam::{Affine3A, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One edit. JSON: `{"target": "object", "name": "bunny-1", "transform": {...}}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "target", rename_all = "snake_case", deny_unknown_fields)]
pub enum Edit {
    /// Moves a dynamic object.
    Object { name: String, transform: Trs },
    /// Moves a dynamic light and/or changes its emission (same emitter type).
    Light {
        name: String,
        #[serde(default)]
        transform: Option<Trs>,
        #[serde(default)]
        emitter: Option<EmitterDesc>,
    },
    /// Changes the camera; the resolution is the session's and cannot be edited.
    Camera {
        #[serde(default)]
        position: Option<[f32; 3]>,
        #[serde(default)]
        look_at: Option<[f32; 3]>,
        #[serde(default)]
        up: Option<[f32; 3]>,
        #[serde(default)]
        vfov_deg: Option<f32>,
    },
    /// Replaces a material's parameters.
    Material { name: String, material: Material },
    /// Changes the environment's radiance (the scene must have an environment).
    Environment {
        #[serde(default)]
        radiance: Option<crate::core::Rgb>,
    },
}

/// An axis-aligned box in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    /// The box of no points: `union` and `with` leave the other operand as it is.
    pub const EMPTY: Aabb = Aabb { min: Vec3::INFINITY, max: Vec3::NEG_INFINITY };

    pub fn of_points(points: impl IntoIterator<Item = Vec3>) -> Aabb {
        points.into_iter().fold(Aabb::EMPTY, |b, p| b.with(p))
    }

    /// This box grown to hold `p`.
    pub fn with(&self, p: Vec3) -> Aabb {
        Aabb { min: self.min.min(p), max: self.max.max(p) }
    }

    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x
    }

    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
}

/// A surface whose placement changed.
#[derive(Clone, Debug, PartialEq)]
pub struct MovedSurface {
    pub surface: SurfaceId,
    pub old_world_from_object: Affine3A,
    pub new_world_from_object: Affine3A,
    pub old_bounds: Aabb,
    pub new_bounds: Aabb,
}

/// What one tick's edits changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneDelta {
    /// Objects and light shapes that moved (Embree instances to update).
    pub moved: Vec<MovedSurface>,
    /// Lights whose transform or emission changed.
    pub lights: Vec<LightChange>,
    /// Materials whose parameters changed, by index.
    pub materials: Vec<usize>,
    /// What each of `materials` was before this tick, in the same order.
    pub previous_materials: Vec<Material>,
    pub camera: bool,
    /// Edits received this tick, and how many of them a later edit to the same target replaced.
    pub received: usize,
    pub coalesced: usize,
    /// Edits (after coalescing) whose result equalled the current value: no change at all.
    pub unchanged: usize,
}

/// How one light changed this tick.
#[derive(Clone, Debug, PartialEq)]
pub struct LightChange {
    pub light: usize,
    /// Its placement before this tick.
    pub old_world_from_object: Affine3A,
    pub moved: bool,
    /// Its emitter's parameters changed (power, cone, shape).
    pub emission_changed: bool,
    /// The emitter changed only in intensity or radiance: every flux it sent out is scaled by
    /// this factor per channel (see [`light::emission_rescale`]).
    pub rescale: Option<crate::core::Rgb>,
}

impl SceneDelta {
    pub fn is_empty(&self) -> bool {
        self.moved.is_empty() && self.lights.is_empty() && self.materials.is_empty() && !self.camera
    }
}

fn err(index: usize, field: &str, message: impl Into<String>) -> SceneError {
    SceneError::Invalid { field: format!("edits[{index}]{field}"), message: message.into() }
}

fn reindex(index: usize, e: SceneError) -> SceneError {
    match e {
        SceneError::Invalid { field, message } => {
            SceneError::Invalid { field: format!("edits[{index}].{field}"), message }
        }
        other => other,
    }
}

/// Merges a batch into one edit per target, in first-seen order; returns them and the number
/// coalesced. Each kept edit remembers the index of the last edit that shaped it (for errors).
pub fn coalesce(edits: Vec<Edit>) -> (Vec<(usize, Edit)>, usize) {
    let received = edits.len();
    let mut order: Vec<String> = Vec::new();
    let mut merged: BTreeMap<String, (usize, Edit)> = BTreeMap::new();
    for (i, e) in edits.into_iter().enumerate() {
        let key = match &e {
            Edit::Object { name, .. } => format!("object/{name}"),
            Edit::Light { name, .. } => format!("light/{name}"),
            Edit::Camera { .. } => "camera".to_string(),
            Edit::Material { name, .. } => format!("material/{name}"),
            Edit::Environment { .. } => "environment".to_string(),
        };
        let next = match (merged.remove(&key), e) {
            (Some((_, Edit::Light { name, transform: t0, emitter: e0 })), Edit::Light { transform, emitter, .. }) => {
                Edit::Light { name, transform: transform.or(t0), emitter: emitter.or(e0) }
            }
            (
                Some((_, Edit::Camera { position: p0, look_at: l0, up: u0, vfov_deg: v0 })),
                Edit::Camera { position, look_at, up, vfov_deg },
            ) => Edit::Camera {
                position: position.or(p0),
                look_at: look_at.or(l0),
                up: up.or(u0),
                vfov_deg: vfov_deg.or(v0),
            },
            (Some((_, Edit::Environment { radiance: r0 })), Edit::Environment { radiance }) => {
                Edit::Environment { radiance: radiance.or(r0) }
            }
            (previous, e) => {
                if previous.is_none() {
                    order.push(key.clone());
                }
                e
            }
        };
        merged.insert(key, (i, next));
    }
    let kept: Vec<(usize, Edit)> = order.into_iter().filter_map(|k| merged.remove(&k)).collect();
    let coalesced = received - kept.len();
    (kept, coalesced)
}

/// Checks a batch against the scene without changing anything.
pub fn validate(scene: &Scene, edits: &[Edit]) -> Result<(), SceneError> {
    let (merged, _) = coalesce(edits.to_vec());
    validate_coalesced(scene, &merged)
}

/// Merges `batch` into the already-coalesced `pending` edits and validates the result as a
/// whole, coalescing once; returns the new pending edits (latest per target). Errors name the
/// field by its index in `batch`: `pending` was valid before, so a fault involves the batch.
pub fn queue(scene: &Scene, pending: &[Edit], batch: Vec<Edit>) -> Result<Vec<Edit>, SceneError> {
    let offset = pending.len();
    let (merged, _) = coalesce(pending.iter().cloned().chain(batch).collect());
    let in_batch: Vec<(usize, Edit)> = merged.into_iter().map(|(i, e)| (i.saturating_sub(offset), e)).collect();
    validate_coalesced(scene, &in_batch)?;
    Ok(in_batch.into_iter().map(|(_, e)| e).collect())
}

fn validate_coalesced(scene: &Scene, edits: &[(usize, Edit)]) -> Result<(), SceneError> {
    for (i, e) in edits {
        let i = *i;
        match e {
            Edit::Object { name, transform } => {
                let idx =
                    scene.object_index(name).ok_or_else(|| err(i, ".name", format!("unknown object '{name}'")))?;
                if !scene.objects[idx].dynamic {
                    return Err(err(
                        i,
                        ".name",
                        format!("object '{name}' is static; only objects with \"dynamic\": true can move"),
                    ));
                }
                validate_trs("transform", transform).map_err(|e| reindex(i, e))?;
                check_placement("transform", &scene.objects[idx].local_bounds, transform).map_err(|e| reindex(i, e))?;
            }
            Edit::Light { name, transform, emitter } => {
                let idx = scene.light_index(name).ok_or_else(|| err(i, ".name", format!("unknown light '{name}'")))?;
                if let Some(t) = transform {
                    let directional = matches!(scene.desc().lights[idx].emitter, EmitterDesc::Directional { .. });
                    if directional && *t != Trs::default() {
                        return Err(err(
                            i,
                            ".transform",
                            format!("light '{name}' is directional and has no placement; edit its emitter's direction"),
                        ));
                    }
                    if !scene.lights[idx].dynamic && *t != scene.desc().lights[idx].transform {
                        return Err(err(
                            i,
                            ".name",
                            format!("light '{name}' is static; only lights with \"dynamic\": true can move"),
                        ));
                    }
                    validate_trs("transform", t).map_err(|e| reindex(i, e))?;
                    if let Some(mesh) = &scene.lights[idx].mesh {
                        check_placement("transform", &mesh.bounds(), t).map_err(|e| reindex(i, e))?;
                    }
                }
                if let Some(em) = emitter {
                    validate_emitter("emitter", em).map_err(|e| reindex(i, e))?;
                    let current = &scene.desc().lights[idx].emitter;
                    if std::mem::discriminant(em) != std::mem::discriminant(current) {
                        return Err(err(i, ".emitter.type", "a light cannot change its emitter type"));
                    }
                    if let (EmitterDesc::Disc { segments: a, .. }, EmitterDesc::Disc { segments: b, .. }) =
                        (em, current)
                    {
                        if a != b {
                            return Err(err(i, ".emitter.segments", "a disc light's tessellation cannot change"));
                        }
                    }
                    if let (
                        EmitterDesc::Mesh { positions: a, indices: ai, .. },
                        EmitterDesc::Mesh { positions: b, indices: bi, .. },
                    ) = (em, current)
                    {
                        if a != b || ai != bi {
                            return Err(err(i, ".emitter.positions", "a mesh light's triangles cannot change"));
                        }
                    }
                }
            }
            Edit::Camera { .. } => {
                let cam = merged_camera(scene.desc().camera.clone(), e);
                super::load::validate_camera(&cam).map_err(|e| reindex(i, e))?;
            }
            Edit::Material { name, material } => {
                scene
                    .material_names
                    .iter()
                    .position(|n| n == name)
                    .ok_or_else(|| err(i, ".name", format!("unknown material '{name}'")))?;
                validate_material("material", material).map_err(|e| reindex(i, e))?;
            }
            Edit::Environment { radiance } => {
                if scene.environment_light().is_none() {
                    return Err(err(
                        i,
                        ".target",
                        "the scene has no environment; give it one (\"environment\") when the session is created",
                    ));
                }
                if let Some(radiance) = radiance {
                    let env = super::EnvironmentDesc { radiance: *radiance };
                    super::load::validate_environment("environment", &env).map_err(|e| reindex(i, e))?;
                }
            }
        }
    }
    Ok(())
}

/// Validates and applies a batch. On error nothing is changed.
pub fn apply(scene: &mut Scene, edits: Vec<Edit>) -> Result<SceneDelta, SceneError> {
    let received = edits.len();
    let (edits, coalesced) = coalesce(edits);
    validate_coalesced(scene, &edits)?;

    // Apply, recording old and new placement; edits that change nothing are only counted.
    let mut delta = SceneDelta { received, coalesced, ..SceneDelta::default() };
    for (_, e) in edits {
        let changed = match e {
            Edit::Object { name, transform } => apply_object(scene, &name, transform, &mut delta),
            Edit::Light { name, transform, emitter } => apply_light(scene, &name, transform, emitter, &mut delta),
            e @ Edit::Camera { .. } => {
                let cam = merged_camera(scene.desc().camera.clone(), &e);
                let changed = cam != scene.desc().camera;
                if changed {
                    scene.set_camera(cam);
                    delta.camera = true;
                }
                changed
            }
            Edit::Material { name, material } => {
                let idx = scene.material_names.iter().position(|n| *n == name).unwrap_or_default();
                let changed = material != scene.materials[idx];
                if changed {
                    delta.previous_materials.push(scene.materials[idx].clone());
                    scene.set_material(idx, material);
                    delta.materials.push(idx);
                }
                changed
            }
            Edit::Environment { radiance } => apply_environment(scene, radiance, &mut delta),
        };
        if !changed {
            delta.unchanged += 1;
        }
    }
    Ok(delta)
}

/// Moves an object (validated); returns false if its placement stays the same.
fn apply_object(scene: &mut Scene, name: &str, transform: Trs, delta: &mut SceneDelta) -> bool {
    let idx = scene.object_index(name).unwrap_or_default();
    let old_xf = scene.objects[idx].world_from_object;
    if transform.world_from_object() == old_xf {
        return false;
    }
    let old_bounds = Aabb::of_points(scene.objects[idx].world_positions.iter().copied());
    scene.set_object_transform(idx, transform);
    let o = &scene.objects[idx];
    delta.moved.push(MovedSurface {
        surface: SurfaceId::Object(idx as u32),
        old_world_from_object: old_xf,
        new_world_from_object: o.world_from_object,
        old_bounds,
        new_bounds: Aabb::of_points(o.world_positions.iter().copied()),
    });
    true
}

/// Moves a light and/or changes its emitter (validated); returns false if neither changes.
fn apply_light(
    scene: &mut Scene,
    name: &str,
    transform: Option<Trs>,
    emitter: Option<EmitterDesc>,
    delta: &mut SceneDelta,
) -> bool {
    let idx = scene.light_index(name).unwrap_or_default();
    let old = scene.desc().lights[idx].clone();
    let old_xf = old.transform.world_from_object();
    let trs = transform.unwrap_or(old.transform);
    let emitter = emitter.unwrap_or_else(|| old.emitter.clone());
    let moved = trs.world_from_object() != old_xf;
    let emission_changed = emitter != old.emitter;
    let rescale = if emission_changed { light::emission_rescale(&old.emitter, &emitter) } else { None };
    if !moved && !emission_changed {
        return false;
    }
    let old_bounds = light_bounds(scene, idx);
    scene.set_light(idx, if moved { trs } else { old.transform }, emitter);
    if moved && scene.lights[idx].mesh.is_some() {
        delta.moved.push(MovedSurface {
            surface: SurfaceId::Light(idx as u32),
            old_world_from_object: old_xf,
            new_world_from_object: trs.world_from_object(),
            old_bounds,
            new_bounds: light_bounds(scene, idx),
        });
    }
    delta.lights.push(LightChange { light: idx, old_world_from_object: old_xf, moved, emission_changed, rescale });
    true
}

/// Changes the environment's radiance (validated: the scene has one); returns false if it
/// stays the same. A change is a light edit of the environment, a rescale where every old
/// channel is positive.
fn apply_environment(scene: &mut Scene, radiance: Option<crate::core::Rgb>, delta: &mut SceneDelta) -> bool {
    let (Some(idx), Some(old)) = (scene.environment_light(), scene.desc().environment) else { return false };
    let new = super::EnvironmentDesc { radiance: radiance.unwrap_or(old.radiance) };
    if new == old {
        return false;
    }
    scene.set_environment(new);
    let rescale = light::channel_ratio(old.radiance, new.radiance);
    delta.lights.push(LightChange {
        light: idx,
        old_world_from_object: Affine3A::IDENTITY,
        moved: false,
        emission_changed: true,
        rescale,
    });
    true
}

/// World bounds of light `idx` (a point for point and spot lights).
/// For a light from outside, a box that every shadow ray towards it from inside the scene's
/// sphere (centre c, radius r) ends in: around the sun, the disc of radius r (widened by its cone)
/// two radii out against its travel; for the environment, the sphere grown to three radii.
pub fn light_bounds(scene: &Scene, idx: usize) -> Aabb {
    let cube = |c: Vec3, half: f32| Aabb { min: c - Vec3::splat(half), max: c + Vec3::splat(half) };
    match &scene.lights[idx].geometry {
        super::LightGeometry::Area { triangles, .. } => Aabb::of_points(triangles.iter().flatten().copied()),
        super::LightGeometry::Directional { travel, cos_max, outside, .. } => {
            let tan = (1.0 - cos_max * cos_max).max(0.0).sqrt() / cos_max;
            cube(outside.center - *travel * (2.0 * outside.radius), outside.radius * (1.0 + 3.0 * tan))
        }
        super::LightGeometry::Environment { outside, .. } => cube(outside.center, 3.0 * outside.radius),
        super::LightGeometry::Point { .. } | super::LightGeometry::Spot { .. } => {
            let p = scene.light_position(idx);
            Aabb { min: p, max: p }
        }
    }
}

fn merged_camera(mut cam: CameraDesc, e: &Edit) -> CameraDesc {
    if let Edit::Camera { position, look_at, up, vfov_deg } = e {
        cam.position = position.unwrap_or(cam.position);
        cam.look_at = look_at.unwrap_or(cam.look_at);
        cam.up = up.unwrap_or(cam.up);
        cam.vfov_deg = vfov_deg.unwrap_or(cam.vfov_deg);
    }
    cam
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obj(name: &str, x: f32) -> Edit {
        Edit::Object { name: name.into(), transform: Trs { translation: [x, 0.0, 0.0], ..Trs::default() } }
    }

    #[test]
    fn latest_edit_per_target_wins_and_is_counted() {
        let (kept, coalesced) = coalesce(vec![obj("a", 1.0), obj("b", 2.0), obj("a", 3.0)]);
        assert_eq!(coalesced, 1);
        assert_eq!(kept.len(), 2);
        assert_eq!(kept[0], (2, obj("a", 3.0)));
        assert_eq!(kept[1], (1, obj("b", 2.0)));
    }

    #[test]
    fn light_edits_merge_field_by_field() {
        let t = Trs { translation: [1.0, 2.0, 3.0], ..Trs::default() };
        let em = EmitterDesc::Point { intensity: crate::core::Rgb::splat(2.0) };
        let (kept, coalesced) = coalesce(vec![
            Edit::Light { name: "l".into(), transform: Some(t), emitter: None },
            Edit::Light { name: "l".into(), transform: None, emitter: Some(em.clone()) },
        ]);
        assert_eq!(coalesced, 1);
        assert_eq!(kept[0].1, Edit::Light { name: "l".into(), transform: Some(t), emitter: Some(em) });
    }
}
