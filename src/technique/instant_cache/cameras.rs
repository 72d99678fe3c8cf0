//! Each pass's camera samples with their direct light, and `temporal`'s camera samples kept
//! from tick to tick.
//!
//! `temporal` looks through the same sub-pixel point of a pixel every tick, so a camera sample
//! traced last tick is what a fresh trace finds unless the camera, a material, an emitter or a
//! surface on its ray changed (a moved light's shape is a moved surface). A sample is kept
//! when it met no emission and no mirror or glass (its ray ends at its diffuse hit, or leaves
//! the scene, or meets a light's back side: a miss is kept only while no light's shape moved),
//! its hit is not on a moved object, and no moved surface now lies on its ray
//! before the hit: the ray is tested against the moved surfaces' new bounds, and where it
//! touches one, traced against those surfaces alone where they are now (`temporal::Moved`).
//! Direct light is sampled afresh every tick either way; a kept sample drew no random number,
//! so the sample's stream is where a fresh trace would leave it and the image is the same.
//!
//! Invariant (audited with `audit: true`, stat `audit_cameras_mismatched`): a kept sample
//! equals a fresh trace of its camera ray in every field.
use super::temporal::Moved;
use super::CacheMode;
use crate::core::{Rgb, Rng};
use crate::embree::Ray;
use crate::technique::camera_chain::{self, CameraSample};
use crate::technique::RenderContext;
use rayon::prelude::*;
use std::sync::Arc;

/// A pixel's camera sample with its direct light.
#[derive(Clone, Copy, Debug, Default)]
pub struct Shaded {
    pub sample: CameraSample,
    pub direct: Rgb,
    pub shadow: bool,
}

/// Bytes a kept camera sample holds.
pub const SHADED_BYTES: u64 = std::mem::size_of::<Shaded>() as u64;

/// What may have changed last tick's camera samples.
pub enum CameraChange {
    /// Trace every sample: the camera, a material or an emitter changed.
    All,
    /// At most these surfaces moved.
    Moved(Arc<Moved>),
}

/// How a pass's camera samples were made.
#[derive(Clone, Copy, Debug, Default)]
pub struct CameraCounts {
    pub kept: u64,
    /// Kept samples a fresh trace disagrees with (`audit` only).
    pub mismatched: u64,
}

/// Is the kept sample `s` of `ray` still what a fresh trace finds after `moved`?
fn still_valid(moved: &Moved, ray: &Ray, s: &CameraSample) -> bool {
    if s.specular_rays > 0 || !s.emitted.is_black() {
        return false;
    }
    let tfar = match &s.hit {
        Some(hit) if moved.objects.get(hit.object as usize).copied().unwrap_or(true) => return false,
        Some(hit) => (hit.p - ray.origin).length() / ray.dir.length(),
        // A ray that met a light's back side ends without emission or hit, as a miss does: if
        // a light's shape moved, what it hid may show now.
        None if moved.light_shapes => return false,
        None => f32::INFINITY,
    };
    let Some(now) = &moved.now else { return true };
    !moved.new_boxes.hits(ray.origin, ray.dir, tfar).0 || !now.occluded1(&Ray { tfar, ..*ray })
}

/// Pass `pass` (the `pass_in_tick`-th of its tick) of camera samples with their direct light,
/// written over `shaded`. With `moved` (`temporal`, and `shaded` holding last tick's samples of
/// this pass), samples still valid after it are kept rather than traced.
pub fn shade(
    ctx: &RenderContext,
    mode: CacheMode,
    (pass, pass_in_tick): (u64, u64),
    shaded: &mut Vec<Shaded>,
    moved: Option<&Moved>,
    audit: bool,
) -> CameraCounts {
    let scene = ctx.scene;
    let pixels = (scene.camera.width * scene.camera.height) as usize;
    let moved = moved.filter(|_| shaded.len() == pixels);
    shaded.resize(pixels, Shaded::default());
    let (kept, mismatched) = shaded
        .par_iter_mut()
        .enumerate()
        .map(|(i, s)| {
            let mut rng = Rng::for_sample(ctx.seed, ctx.tick, i as u64, pass);
            let jitter = match mode {
                // The same sub-pixel points every tick, so a still view finds its records.
                CacheMode::Temporal => Rng::for_sample(ctx.seed, 0, i as u64, pass_in_tick).next_2d(),
                CacheMode::Igi | CacheMode::Static => rng.next_2d(),
            };
            let keep = moved.is_some_and(|m| still_valid(m, &camera_chain::camera_ray(scene, i, jitter), &s.sample));
            let mismatched =
                keep && audit && camera_chain::trace(scene, ctx.accel, i, jitter, &mut rng.clone()) != s.sample;
            if !keep {
                s.sample = camera_chain::trace(scene, ctx.accel, i, jitter, &mut rng);
            }
            (s.direct, s.shadow) = match &s.sample.hit {
                Some(hit) => camera_chain::direct_light(scene, ctx.accel, hit, &mut rng),
                None => (Rgb::BLACK, false),
            };
            (u64::from(keep), u64::from(mismatched))
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    CameraCounts { kept, mismatched }
}
