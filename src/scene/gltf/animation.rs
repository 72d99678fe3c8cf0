//! glTF animations as relume animations, named as the file names them.
//!
//! relume's tracks hold world transforms with linear translation and scale and slerp rotation
//! between keys (see `scene/animation.rs`), so each animated object, light or camera gets the
//! world transform of its node, composed through every ancestor, at these times:
//! - every key time of every channel on the node or an ancestor (exact for LINEAR channels);
//! - STEP keys twice, the held value just before the key and the new one at it (relume holds
//!   the earlier of two keys at one time, so the jump is exact);
//! - CUBICSPLINE segments at [`CUBIC_SUBSTEPS`] points each, evaluated with the Hermite basis
//!   (linear in between: an approximation, stated in the load report).
//!
//! Morph-target weights are not read (a warning). Animations loop, as glTF viewers play them.
use super::import::{camera_pose, punctual_trs};
use super::nodes::{decompose, NodeInfo};
use super::warnings::Warnings;
use super::Target;
use crate::scene::animation::{Animation, CameraKey, Track, TransformKey};
use crate::scene::load::{invalid, SceneError};
use glam::{Mat4, Quat, Vec3, Vec4};
use gltf::animation::{Interpolation, Property};
use std::collections::{HashMap, HashSet};

/// Points per CUBICSPLINE segment at which the curve is evaluated.
pub const CUBIC_SUBSTEPS: usize = 8;

/// One channel's keys: translation and scale as `xyz0`, rotation as `xyzw`.
struct Channel {
    property: Property,
    interpolation: Interpolation,
    times: Vec<f32>,
    /// One value per key, or (in-tangent, value, out-tangent) per key for CUBICSPLINE.
    values: Vec<Vec4>,
}

impl Channel {
    fn value(&self, k: usize) -> Vec4 {
        match self.interpolation {
            Interpolation::CubicSpline => self.values[3 * k + 1],
            _ => self.values[k],
        }
    }

    /// The channel at time `t`; `left` asks for the limit from below (differs at STEP keys).
    fn sample(&self, t: f32, left: bool) -> Vec4 {
        let n = self.times.len();
        let k = self.times.partition_point(|&x| x <= t);
        if k == 0 {
            return self.value(0);
        }
        let k = k - 1;
        if self.interpolation == Interpolation::Step && left && t == self.times[k] && k > 0 {
            return self.value(k - 1);
        }
        if k + 1 >= n {
            return self.value(n - 1);
        }
        let dt = self.times[k + 1] - self.times[k];
        let s = if dt > 0.0 { (t - self.times[k]) / dt } else { 1.0 };
        match self.interpolation {
            Interpolation::Step => self.value(k),
            Interpolation::Linear if self.property == Property::Rotation => {
                Vec4::from(Quat::from_vec4(self.value(k)).slerp(Quat::from_vec4(self.value(k + 1)), s))
            }
            Interpolation::Linear => self.value(k).lerp(self.value(k + 1), s),
            Interpolation::CubicSpline => {
                let (s2, s3) = (s * s, s * s * s);
                let v = (2.0 * s3 - 3.0 * s2 + 1.0) * self.values[3 * k + 1]
                    + (s3 - 2.0 * s2 + s) * dt * self.values[3 * k + 2]
                    + (-2.0 * s3 + 3.0 * s2) * self.values[3 * (k + 1) + 1]
                    + (s3 - s2) * dt * self.values[3 * (k + 1)];
                if self.property == Property::Rotation {
                    v.normalize_or(Vec4::W)
                } else {
                    v
                }
            }
        }
    }
}

/// Every animation of the file as relume animations with unique names.
pub fn convert(
    doc: &gltf::Document,
    buffers: &[Vec<u8>],
    nodes: &[NodeInfo],
    targets: &[(usize, Target)],
    root: Mat4,
    warnings: &mut Warnings,
) -> Result<Vec<(String, Animation)>, SceneError> {
    let by_index: HashMap<usize, &NodeInfo> = nodes.iter().map(|n| (n.index, n)).collect();
    let mut names = HashSet::new();
    let mut out = Vec::new();
    for anim in doc.animations() {
        let field = format!("animations[{}]", anim.index());
        let channels = read_channels(&anim, buffers, &field, warnings)?;
        let duration = channels.values().flatten().filter_map(|c| c.times.last().copied()).fold(0.0f32, f32::max);
        if duration <= 0.0 {
            warnings.add("animations whose keys all lie at time 0 are not read", &field);
            continue;
        }
        let mut tracks = Vec::new();
        for (node, target) in targets {
            let chain = ancestry(*node, &by_index);
            if !chain.iter().any(|n| channels.contains_key(n)) {
                continue;
            }
            tracks.push(track(&field, target, &chain, &channels, doc, root)?);
        }
        let base = anim.name().filter(|n| !n.is_empty()).map(str::to_string);
        let mut name = base.clone().unwrap_or_else(|| format!("animation{}", anim.index()));
        let mut n = 2;
        while !names.insert(name.clone()) {
            name = format!("{}#{n}", base.clone().unwrap_or_else(|| format!("animation{}", anim.index())));
            n += 1;
        }
        out.push((name, Animation { duration, looping: true, tracks }));
    }
    Ok(out)
}

fn read_channels(
    anim: &gltf::Animation,
    buffers: &[Vec<u8>],
    field: &str,
    warnings: &mut Warnings,
) -> Result<HashMap<usize, Vec<Channel>>, SceneError> {
    use gltf::animation::util::ReadOutputs;
    let mut out: HashMap<usize, Vec<Channel>> = HashMap::new();
    for ch in anim.channels() {
        let here = format!("{field}.channels[{}]", ch.index());
        let property = ch.target().property();
        let reader = ch.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let times: Vec<f32> =
            reader.read_inputs().ok_or_else(|| invalid(format!("{here}.sampler"), "input cannot be read"))?.collect();
        let values: Vec<Vec4> = match reader.read_outputs() {
            Some(ReadOutputs::Translations(v)) | Some(ReadOutputs::Scales(v)) => {
                v.map(|p| Vec3::from(p).extend(0.0)).collect()
            }
            Some(ReadOutputs::Rotations(r)) => r.into_f32().map(Vec4::from).collect(),
            Some(ReadOutputs::MorphTargetWeights(_)) => {
                warnings.add("morph-target weight channels are not read", &here);
                continue;
            }
            None => return Err(invalid(format!("{here}.sampler"), "output cannot be read")),
        };
        let interpolation = ch.sampler().interpolation();
        let per_key = if interpolation == Interpolation::CubicSpline { 3 } else { 1 };
        if times.is_empty() || values.len() != per_key * times.len() {
            return Err(invalid(
                format!("{here}.sampler"),
                format!("{} keys need {} output values, found {}", times.len(), per_key * times.len(), values.len()),
            ));
        }
        if let Some(k) = times.iter().position(|t| !(t.is_finite() && *t >= 0.0)) {
            return Err(invalid(format!("{here}.sampler.input[{k}]"), "key times must be finite and not negative"));
        }
        if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(invalid(format!("{here}.sampler.input[{}]", k + 1), "key times must increase"));
        }
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            return Err(invalid(format!("{here}.sampler.output[{k}]"), "is not a finite number"));
        }
        if interpolation == Interpolation::CubicSpline {
            warnings.add(
                format!("CUBICSPLINE channels are sampled at {CUBIC_SUBSTEPS} points per segment, linear between"),
                &here,
            );
        }
        out.entry(ch.target().node().index()).or_default().push(Channel { property, interpolation, times, values });
    }
    Ok(out)
}

/// The node and its ancestors, root first.
fn ancestry(node: usize, by_index: &HashMap<usize, &NodeInfo>) -> Vec<usize> {
    let mut chain = vec![node];
    while let Some(parent) = by_index.get(chain.last().unwrap_or(&node)).and_then(|n| n.parent) {
        chain.push(parent);
    }
    chain.reverse();
    chain
}

/// The times to key at, each with whether it is a STEP key's left limit.
fn sample_times(chain: &[usize], channels: &HashMap<usize, Vec<Channel>>) -> Vec<(f32, bool)> {
    let mut times = Vec::new();
    for ch in chain.iter().filter_map(|n| channels.get(n)).flatten() {
        for (k, w) in ch.times.iter().enumerate() {
            times.push((*w, false));
            if ch.interpolation == Interpolation::Step && k > 0 {
                times.push((*w, true));
            }
            if ch.interpolation == Interpolation::CubicSpline && k + 1 < ch.times.len() {
                let dt = ch.times[k + 1] - w;
                times.extend((1..CUBIC_SUBSTEPS).map(|i| (w + dt * i as f32 / CUBIC_SUBSTEPS as f32, false)));
            }
        }
    }
    // Left limits sort before the value at the same time.
    times.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
    times.dedup();
    times
}

/// The world matrix at the end of `chain` at time `t`.
fn world_at(
    chain: &[usize],
    channels: &HashMap<usize, Vec<Channel>>,
    doc: &gltf::Document,
    root: Mat4,
    t: f32,
    left: bool,
) -> Mat4 {
    let mut world = root;
    for n in chain {
        let Some(node) = doc.nodes().nth(*n) else { continue };
        let (t0, r0, s0) = node.transform().decomposed();
        let (mut tr, mut rot, mut sc) = (Vec3::from(t0), Quat::from_array(r0).normalize(), Vec3::from(s0));
        for ch in channels.get(n).into_iter().flatten() {
            let v = ch.sample(t, left);
            match ch.property {
                Property::Translation => tr = v.truncate(),
                Property::Rotation => rot = Quat::from_vec4(v).normalize(),
                Property::Scale => sc = v.truncate(),
                Property::MorphTargetWeights => {}
            }
        }
        world *= Mat4::from_scale_rotation_translation(sc, rot, tr);
    }
    world
}

fn track(
    field: &str,
    target: &Target,
    chain: &[usize],
    channels: &HashMap<usize, Vec<Channel>>,
    doc: &gltf::Document,
    root: Mat4,
) -> Result<Track, SceneError> {
    let times = sample_times(chain, channels);
    let worlds = times.iter().map(|&(t, left)| (t, world_at(chain, channels, doc, root, t, left)));
    let transform_keys = |worlds: &mut dyn Iterator<Item = (f32, Mat4)>, punctual: bool| {
        worlds
            .map(|(time, w)| {
                let transform = if punctual { Some(punctual_trs(&w)) } else { decompose(&w) };
                transform.map(|transform| TransformKey { time, transform }).ok_or_else(|| {
                    invalid(field, format!("the pose at {time} s has shear, which a moving object cannot have"))
                })
            })
            .collect::<Result<Vec<_>, _>>()
    };
    Ok(match target {
        Target::Object(name) => {
            Track::Object { name: name.clone(), keyframes: transform_keys(&mut worlds.into_iter(), false)? }
        }
        Target::Light { name, punctual } => {
            Track::Light { name: name.clone(), keyframes: transform_keys(&mut worlds.into_iter(), *punctual)? }
        }
        Target::Camera { focus } => Track::Camera {
            keyframes: worlds
                .map(|(time, w)| {
                    let (position, look_at, _) = camera_pose(&w, *focus);
                    CameraKey { time, position, look_at }
                })
                .collect(),
        },
    })
}
