//! Scripted animations (`NAME.anim.json`, documented by `proto/animation.schema.json`).
//!
//! An animation is a set of keyframe tracks, one per target (object, light or camera). Object
//! and light tracks interpolate TRS transforms (translation and scale linearly, rotation by
//! slerp); camera tracks interpolate position and look-at linearly. Sampling an animation at a
//! time yields the same [`Edit`]s a client would send, so animations drive sessions through the
//! ordinary edit path. Times are seconds; with `loop`, time wraps at `duration`, otherwise it
//! holds the last keyframe.
use super::edits::{Aabb, Edit};
use super::load::{check_placement, invalid, parse_json, validate_trs, SceneError};
use super::model::Trs;
use super::Scene;
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Animation {
    /// Seconds.
    pub duration: f32,
    #[serde(default, rename = "loop")]
    pub looping: bool,
    pub tracks: Vec<Track>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "target", rename_all = "snake_case", deny_unknown_fields)]
pub enum Track {
    Object { name: String, keyframes: Vec<TransformKey> },
    Light { name: String, keyframes: Vec<TransformKey> },
    Camera { keyframes: Vec<CameraKey> },
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransformKey {
    pub time: f32,
    pub transform: Trs,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraKey {
    pub time: f32,
    pub position: [f32; 3],
    pub look_at: [f32; 3],
}

trait Keyed {
    fn time(&self) -> f32;
}

impl Keyed for TransformKey {
    fn time(&self) -> f32 {
        self.time
    }
}

impl Keyed for CameraKey {
    fn time(&self) -> f32 {
        self.time
    }
}

/// The two keys around `t` and the blend factor between them.
fn bracket<K: Keyed + Copy>(keys: &[K], t: f32) -> Option<(K, K, f32)> {
    let first = *keys.first()?;
    if t <= first.time() || keys.len() == 1 {
        return Some((first, first, 0.0));
    }
    for w in keys.windows(2) {
        if t <= w[1].time() {
            let span = w[1].time() - w[0].time();
            let s = if span > 0.0 { (t - w[0].time()) / span } else { 1.0 };
            return Some((w[0], w[1], s));
        }
    }
    let last = *keys.last()?;
    Some((last, last, 0.0))
}

/// Linear interpolation that returns a held value exactly (`a·(1−s) + a·s` need not be `a`).
fn lerp3(a: [f32; 3], b: [f32; 3], s: f32) -> [f32; 3] {
    if a == b {
        return a;
    }
    Vec3::from(a).lerp(Vec3::from(b), s).to_array()
}

/// TRS interpolation: linear translation and scale, slerp rotation (shortest arc). Between two
/// equal keys (a hold) the key itself comes back bit for bit, so a held pose is no edit.
pub fn interpolate_trs(a: &Trs, b: &Trs, s: f32) -> Trs {
    if a == b {
        return *a;
    }
    let (qa, qb) = (Quat::from_array(a.rotation).normalize(), Quat::from_array(b.rotation).normalize());
    Trs {
        translation: lerp3(a.translation, b.translation, s),
        rotation: qa.slerp(qb, s).normalize().to_array(),
        scale: lerp3(a.scale, b.scale, s),
    }
}

/// Checks an object or light track (its target exists and is dynamic, its transforms are valid
/// and keep its shape within the world's coordinates, as an edit must) and returns its keyframe
/// times. `target` is whether the target is dynamic and its shape's object-space bounds (`None`
/// for a punctual light), or `None` when no target has that name.
fn transform_track_times(
    field: &str,
    kind: &str,
    name: &str,
    target: Option<(bool, Option<Aabb>)>,
    keys: &[TransformKey],
) -> Result<Vec<f32>, SceneError> {
    let bounds = match target {
        None => return Err(invalid(format!("{field}.name"), format!("unknown {kind} '{name}'"))),
        Some((false, _)) => {
            return Err(invalid(
                format!("{field}.name"),
                format!("{kind} '{name}' is static; animate only dynamic {kind}s"),
            ))
        }
        Some((true, bounds)) => bounds,
    };
    for (k, key) in keys.iter().enumerate() {
        let field = format!("{field}.keyframes[{k}].transform");
        validate_trs(&field, &key.transform)?;
        if let Some(b) = &bounds {
            check_placement(&field, b, &key.transform)?;
        }
    }
    Ok(keys.iter().map(|k| k.time).collect())
}

impl Animation {
    pub fn load(path: &Path) -> Result<Animation, SceneError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| SceneError::Io { path: path.display().to_string(), message: e.to_string() })?;
        parse_json(&text)
    }

    /// Checks the animation on its own and against the scene it will drive.
    pub fn validate(&self, scene: &Scene) -> Result<(), SceneError> {
        if !(self.duration.is_finite() && self.duration > 0.0) {
            return Err(invalid("duration", "must be a positive number of seconds"));
        }
        for (i, track) in self.tracks.iter().enumerate() {
            let field = format!("tracks[{i}]");
            let times: Vec<f32> = match track {
                Track::Object { name, keyframes } => {
                    let target = scene
                        .object_index(name)
                        .map(|i| (scene.objects[i].dynamic, Some(scene.objects[i].local_bounds)));
                    transform_track_times(&field, "object", name, target, keyframes)?
                }
                Track::Light { name, keyframes } => {
                    let target = scene.light_index(name).map(|i| {
                        let light = &scene.lights[i];
                        (light.dynamic, light.mesh.as_ref().map(|m| m.bounds()))
                    });
                    transform_track_times(&field, "light", name, target, keyframes)?
                }
                Track::Camera { keyframes } => {
                    for (k, key) in keyframes.iter().enumerate() {
                        let mut cam = scene.desc().camera.clone();
                        cam.position = key.position;
                        cam.look_at = key.look_at;
                        super::load::validate_camera(&cam).map_err(|e| match e {
                            SceneError::Invalid { field: f, message } => {
                                invalid(format!("{field}.keyframes[{k}].{f}"), message)
                            }
                            other => other,
                        })?;
                    }
                    keyframes.iter().map(|k| k.time).collect()
                }
            };
            if times.is_empty() {
                return Err(invalid(format!("{field}.keyframes"), "needs at least one keyframe"));
            }
            for (k, w) in times.windows(2).enumerate() {
                if w[1].is_nan() || w[0].is_nan() || w[1] < w[0] {
                    return Err(invalid(
                        format!("{field}.keyframes[{}].time", k + 1),
                        "keyframe times must not decrease",
                    ));
                }
            }
            if let Some(k) = times.iter().position(|t| !(t.is_finite() && *t >= 0.0 && *t <= self.duration)) {
                return Err(invalid(
                    format!("{field}.keyframes[{k}].time"),
                    format!("must lie in [0, duration = {}]", self.duration),
                ));
            }
        }
        Ok(())
    }

    /// The animation's local time for wall time `t`.
    pub fn local_time(&self, t: f32) -> f32 {
        if self.looping {
            t.rem_euclid(self.duration)
        } else {
            t.clamp(0.0, self.duration)
        }
    }

    /// The edits that put every animated target where it is at time `t` (seconds).
    pub fn edits_at(&self, t: f32) -> Vec<Edit> {
        let t = self.local_time(t);
        self.tracks
            .iter()
            .filter_map(|track| match track {
                Track::Object { name, keyframes } => bracket(keyframes, t).map(|(a, b, s)| Edit::Object {
                    name: name.clone(),
                    transform: interpolate_trs(&a.transform, &b.transform, s),
                }),
                Track::Light { name, keyframes } => bracket(keyframes, t).map(|(a, b, s)| Edit::Light {
                    name: name.clone(),
                    transform: Some(interpolate_trs(&a.transform, &b.transform, s)),
                    emitter: None,
                }),
                Track::Camera { keyframes } => bracket(keyframes, t).map(|(a, b, s)| Edit::Camera {
                    position: Some(lerp3(a.position, b.position, s)),
                    look_at: Some(lerp3(a.look_at, b.look_at, s)),
                    up: None,
                    vfov_deg: None,
                }),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(time: f32, x: f32, angle: f32) -> TransformKey {
        TransformKey {
            time,
            transform: Trs {
                translation: [x, 0.0, 0.0],
                rotation: Quat::from_rotation_y(angle).to_array(),
                scale: [1.0; 3],
            },
        }
    }

    #[test]
    fn interpolates_translation_linearly_and_rotation_by_slerp() {
        let anim = Animation {
            duration: 2.0,
            looping: true,
            tracks: vec![Track::Object { name: "o".into(), keyframes: vec![key(0.0, 0.0, 0.0), key(2.0, 4.0, 1.0)] }],
        };
        let Edit::Object { transform, .. } = &anim.edits_at(0.5)[0] else { panic!("object edit expected") };
        assert!((transform.translation[0] - 1.0).abs() < 1e-6);
        let angle = Quat::from_array(transform.rotation).angle_between(Quat::IDENTITY);
        assert!((angle - 0.25).abs() < 1e-5, "slerp angle {angle}");
        // Looping wraps; 2.5 s is 0.5 s.
        assert_eq!(anim.edits_at(2.5), anim.edits_at(0.5));
        // Before the first and after the last key, the ends hold.
        let held = Animation { looping: false, ..anim.clone() };
        let Edit::Object { transform, .. } = &held.edits_at(9.0)[0] else { panic!("object edit expected") };
        assert_eq!(transform.translation[0], 4.0);
    }
}
