//! Each pass's camera samples with their direct light, `temporal`'s camera samples kept from
//! tick to tick, and their radiance added to the film.
//!
//! `temporal` looks through the same sub-pixel point of a pixel every tick, so a camera sample
//! traced last tick is what a fresh trace finds unless the camera, a material, an emitter or a
//! surface on its ray changed (a moved light's shape is a moved surface). A sample is kept
//! when it met no emission and no mirror or glass (its ray ends at its diffuse hit, or leaves
//! the scene, or meets a light's back side: a miss is kept only while no light's shape moved),
//! its hit is not on a moved object, and no moved surface now lies on its ray
//! before the hit: a pixel outside the film rectangles the moved surfaces' new bounds project
//! to needs no test; elsewhere the ray is tested against those bounds, and where it touches
//! one, traced against those surfaces alone where they are now (`temporal::Moved`). A sample's
//! sub-pixel point and stream are made only when needed.
//!
//! Direct light is kept too, when a fresh sample would draw the same: `temporal`'s resident
//! passes draw from a stream of the pixel and the pass since the last change (not of the tick),
//! so the k-th pass of every changing tick draws alike, and a kept camera sample drew no random
//! number (so direct light starts where a fresh trace would leave the stream). A kept sample
//! keeps its direct light when its pass drew from the same stream last tick, no light changed
//! (light selection, sampling and emission are as before), and its shadow ray, if it traced
//! one, touches neither the new nor the old bounds of a moved surface (its answer can change
//! only if a moved surface lies on it now or lay on it before). Otherwise the light is sampled
//! again: still ticks with `refine_ticks: 0` draw a new stream each pass, so a still view
//! converges.
//!
//! The kept samples are summarised by runs of [`RUN`] pixels of a row ([`RunBounds`]): the box
//! of their hits and shadow-ray origins, the box of their shadow rays' ends, and whether one of
//! them can never be kept or is a miss. A tick that may keep direct light skips a run without
//! reading its samples when no moved surface's new or old bounds meet the hull of its two boxes
//! (so none lies on a shadow ray, and no hit is on a moved object, whose hits lie in its old
//! bounds), no miss can be changed by a light's moved shape, and its pixels lie outside the
//! moved surfaces' film rectangles: its samples then pass every per-sample test, so the cost of
//! a small move follows the pixels near it and the shadows it crosses, not the image. A run
//! whose samples were looked at gets its summary again.
//!
//! Invariant (audited with `audit: true`, stat `audit_cameras_mismatched`): a kept sample
//! equals a fresh trace of its camera ray in every field, and kept direct light equals a
//! fresh sample of it, shadow ray included.
use super::temporal::Moved;
use super::CacheMode;
use crate::core::{Rgb, Rng};
use crate::embree::Ray;
use crate::film::Film;
use crate::scene::edits::Aabb;
use crate::scene::Scene;
use crate::technique::camera_chain::{self, CameraSample};
use crate::technique::RenderContext;
use glam::Vec2;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

/// A pixel's camera sample with its direct light.
#[derive(Clone, Copy, Debug, Default)]
pub struct Shaded {
    pub sample: CameraSample,
    pub direct: Rgb,
    /// The shadow ray its direct light traced, if it traced one.
    pub shadow: Option<Ray>,
}

/// Bytes a kept camera sample holds, with its share of its run's summary.
pub const SHADED_BYTES: u64 = (std::mem::size_of::<Shaded>() + std::mem::size_of::<RunBounds>().div_ceil(RUN)) as u64;

/// Pixels in a run, the unit a tick skips (the last run of the image may be shorter).
pub const RUN: usize = 32;

/// One pass's camera samples, by pixel, and their runs' summaries, kept from tick to tick. Only
/// [`shade`] writes them, so there is always one summary per run of the samples.
#[derive(Default)]
pub struct Samples {
    shaded: Vec<Shaded>,
    runs: Vec<RunBounds>,
}

impl Samples {
    pub fn shaded(&self) -> &[Shaded] {
        &self.shaded
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.shaded.capacity() * std::mem::size_of::<Shaded>() + self.runs.capacity() * std::mem::size_of::<RunBounds>()
    }
}

/// What a run's samples touch: `from` holds their hits and shadow-ray origins, `to` their
/// shadow rays' ends (both empty when there are none); `never` if one of them cannot be kept
/// (emission, a specular chain, a shadow ray without a finite end), `misses` if one is a miss.
#[derive(Clone, Copy, Debug)]
struct RunBounds {
    from: Aabb,
    to: Aabb,
    never: bool,
    misses: bool,
}

impl RunBounds {
    /// A run not summarised yet: never skipped.
    const UNKNOWN: RunBounds = RunBounds { from: Aabb::EMPTY, to: Aabb::EMPTY, never: true, misses: true };

    /// The summary of `run`'s samples.
    fn of(run: &[Shaded]) -> RunBounds {
        let mut r = RunBounds { from: Aabb::EMPTY, to: Aabb::EMPTY, never: false, misses: false };
        for s in run {
            r.never |= s.sample.specular_rays > 0 || !s.sample.emitted.is_black();
            match &s.sample.hit {
                Some(hit) => r.from = r.from.with(hit.p),
                None => r.misses = true,
            }
            if let Some(ray) = &s.shadow {
                let end = ray.origin + ray.dir * ray.tfar;
                r.never |= !end.is_finite();
                (r.from, r.to) = (r.from.with(ray.origin), r.to.with(end));
            }
        }
        r
    }

    /// Does every sample of this run (pixels `pixels`) pass [`still_valid`] and keep its direct
    /// light under `reuse`, by the run's summary alone?
    fn settled(&self, reuse: &Reuse, pixels: std::ops::Range<usize>) -> bool {
        let moved = reuse.moved;
        if !reuse.direct || self.never || (self.misses && moved.light_shapes) || moved.may_show(pixels) {
            return false;
        }
        // No hit and no shadow ray: nothing a moved surface could touch.
        if self.from.is_empty() {
            return true;
        }
        let to = if self.to.is_empty() { &self.from } else { &self.to };
        moved.clear_of(&self.from, to)
    }
}

/// What may have changed last tick's camera samples.
pub enum CameraChange {
    /// Trace every sample: the camera, a material or an emitter changed.
    All,
    /// At most these surfaces moved; `lights`: a light changed too (its direct light is sampled
    /// again).
    Moved { moved: Arc<Moved>, lights: bool },
}

/// How a pass's camera samples were made.
#[derive(Clone, Copy, Debug, Default)]
pub struct CameraCounts {
    pub kept: u64,
    /// Samples that kept their direct light, and shadow rays traced.
    pub direct_kept: u64,
    pub shadow_rays: u64,
    /// Kept samples or direct light a fresh trace disagrees with (`audit` only).
    pub mismatched: u64,
    /// Runs kept on their summary alone.
    pub settled_runs: u64,
}

/// A pass's shading: its counts, and per sample whether its camera sample was kept (so its
/// hit is last tick's, and what was kept of it need not be read again).
pub struct Shading {
    pub counts: CameraCounts,
    pub kept: Vec<bool>,
}

/// What happened to one sample, as bits.
const KEPT: u8 = 1;
const DIRECT_KEPT: u8 = 2;
const SHADOW_RAY: u8 = 4;
const MISMATCHED: u8 = 8;

impl Shading {
    fn new(outcomes: &[u8], settled_runs: u64) -> Shading {
        let count = |bit: u8| outcomes.iter().filter(|&&o| o & bit != 0).count() as u64;
        let counts = CameraCounts {
            kept: count(KEPT),
            direct_kept: count(DIRECT_KEPT),
            shadow_rays: count(SHADOW_RAY),
            mismatched: count(MISMATCHED),
            settled_runs,
        };
        Shading { counts, kept: outcomes.iter().map(|&o| o & KEPT != 0).collect() }
    }
}

/// What a pass may keep of last tick's samples of the same pass.
#[derive(Clone, Copy)]
pub struct Reuse<'a> {
    /// The surfaces moved since (`temporal::Moved`).
    pub moved: &'a Moved,
    /// Direct light may be kept: the same stream as last tick, and no light changed.
    pub direct: bool,
}

/// Is the kept sample `s` of pixel `pixel` still what a fresh trace of its camera ray (`ray`,
/// made only if needed) finds after `moved`?
fn still_valid(moved: &Moved, pixel: usize, ray: impl FnOnce() -> Ray, s: &CameraSample) -> bool {
    if s.specular_rays > 0 || !s.emitted.is_black() {
        return false;
    }
    let end = match &s.hit {
        Some(hit) if moved.objects.get(hit.object as usize).copied().unwrap_or(true) => return false,
        Some(hit) => Some(hit.p),
        // A ray that met a light's back side ends without emission or hit, as a miss does: if
        // a light's shape moved, what it hid may show now.
        None if moved.light_shapes => return false,
        None => None,
    };
    let Some(now) = &moved.now else { return true };
    if !moved.may_show(pixel..pixel + 1) {
        return true;
    }
    let ray = ray();
    let tfar = end.map_or(f32::INFINITY, |p| (p - ray.origin).length() / ray.dir.length());
    !moved.new_boxes.hits(ray.origin, ray.dir, tfar).0 || !now.occluded1(&Ray { tfar, ..ray })
}

/// The `tick` key of `temporal`'s resident streams, which no tick reaches: they depend on the
/// pixel and the pass since the last change only.
const RESIDENT_STREAM: u64 = u64::MAX;

/// Pass `pass` (the `pass_in_tick`-th of its tick; passes count from the last change) of camera
/// samples with their direct light, written over `samples`. With `reuse` (`temporal`, and
/// `samples` holding last tick's samples of this pass), what is still valid is kept: a run the
/// summary settles is not read (with `audit`, its samples are checked against fresh traces).
pub fn shade(
    ctx: &RenderContext,
    mode: CacheMode,
    (pass, pass_in_tick): (u64, u64),
    samples: &mut Samples,
    reuse: Option<Reuse>,
    audit: bool,
) -> Shading {
    let scene = ctx.scene;
    let pixels = (scene.camera.width * scene.camera.height) as usize;
    let runs = pixels.div_ceil(RUN);
    let reuse = reuse.filter(|_| samples.shaded.len() == pixels);
    samples.shaded.resize(pixels, Shaded::default());
    samples.runs.resize(runs, RunBounds::UNKNOWN);
    let mut outcomes = vec![0u8; pixels];
    let settled_runs = samples
        .shaded
        .par_chunks_mut(RUN)
        .zip(samples.runs.par_iter_mut())
        .zip(outcomes.par_chunks_mut(RUN))
        .enumerate()
        .map(|(r, ((run, bounds), outcomes))| {
            let first = r * RUN;
            let settled = reuse.is_some_and(|m| bounds.settled(&m, first..first + run.len()));
            if settled && !audit {
                outcomes.fill(KEPT | DIRECT_KEPT);
                return 1;
            }
            for (k, (s, outcome)) in run.iter_mut().zip(outcomes.iter_mut()).enumerate() {
                let i = first + k;
                let rng = &mut SampleRng::new(ctx, mode, i, (pass, pass_in_tick));
                *outcome = shade_one(ctx, i, s, rng, reuse, (settled, audit));
            }
            if !settled {
                *bounds = RunBounds::of(run);
            }
            u64::from(settled)
        })
        .sum();
    Shading::new(&outcomes, settled_runs)
}

/// A sample's sub-pixel point and random stream, made when first needed: `temporal`'s are
/// functions of the pixel and the pass, so a sample kept with its direct light makes neither.
/// `igi` and `static` draw the point from the stream of the tick.
struct SampleRng {
    rng: Option<Rng>,
    jitter: Option<Vec2>,
    key: (u64, u64, u64, u64),
}

impl SampleRng {
    fn new(ctx: &RenderContext, mode: CacheMode, i: usize, (pass, pass_in_tick): (u64, u64)) -> SampleRng {
        let key = (ctx.seed, i as u64, pass, pass_in_tick);
        match mode {
            CacheMode::Temporal => SampleRng { rng: None, jitter: None, key },
            CacheMode::Igi | CacheMode::Static => {
                let mut rng = Rng::for_sample(ctx.seed, ctx.tick, i as u64, pass);
                let jitter = rng.next_2d();
                SampleRng { rng: Some(rng), jitter: Some(jitter), key }
            }
        }
    }

    /// The sub-pixel point: the same every tick in `temporal`, so a still view finds its records.
    fn jitter(&mut self) -> Vec2 {
        let (seed, i, _, pass_in_tick) = self.key;
        *self.jitter.get_or_insert_with(|| Rng::for_sample(seed, 0, i, pass_in_tick).next_2d())
    }

    fn rng(&mut self) -> &mut Rng {
        let (seed, i, pass, _) = self.key;
        self.rng.get_or_insert_with(|| Rng::for_sample(seed, RESIDENT_STREAM, i, pass))
    }
}

/// Shades pixel `i`'s sample `s`, keeping what `reuse` allows; `settled`: its run's summary
/// already showed that the sample and its direct light are kept. Returns what happened, as bits.
fn shade_one(
    ctx: &RenderContext,
    i: usize,
    s: &mut Shaded,
    r: &mut SampleRng,
    reuse: Option<Reuse>,
    (settled, audit): (bool, bool),
) -> u8 {
    let (scene, accel) = (ctx.scene, ctx.accel);
    let keep = settled
        || reuse.is_some_and(|m| still_valid(m.moved, i, || camera_chain::camera_ray(scene, i, r.jitter()), &s.sample));
    let mut outcome = if keep { KEPT } else { 0 };
    if keep && audit {
        let jitter = r.jitter();
        if camera_chain::trace(scene, accel, i, jitter, &mut r.rng().clone()) != s.sample {
            outcome |= MISMATCHED;
        }
    }
    if !keep {
        let jitter = r.jitter();
        s.sample = camera_chain::trace(scene, accel, i, jitter, r.rng());
    }
    let keep_direct =
        settled || keep && reuse.is_some_and(|m| m.direct && s.shadow.is_none_or(|ray| !m.moved.on_ray(&ray)));
    if !keep_direct {
        (s.direct, s.shadow) = direct_light(ctx, &s.sample, r.rng());
        outcome |= if s.shadow.is_some() { SHADOW_RAY } else { 0 };
    } else {
        outcome |= DIRECT_KEPT;
        if audit && direct_light(ctx, &s.sample, r.rng()) != (s.direct, s.shadow) {
            outcome |= MISMATCHED;
        }
    }
    outcome
}

/// Direct light at the sample's diffuse hit, and the shadow ray traced, if any.
fn direct_light(ctx: &RenderContext, sample: &CameraSample, rng: &mut Rng) -> (Rgb, Option<Ray>) {
    match &sample.hit {
        Some(hit) => camera_chain::direct_light(ctx.scene, ctx.accel, hit, rng),
        None => (Rgb::BLACK, None),
    }
}

/// Adds each sample's radiance (the emission along its chain, its direct light and ρ/π times
/// its indirect irradiance) to its pixel, in parallel rows, and returns the specular rays the
/// samples' chains traced.
pub fn accumulate(film: &mut Film, scene: &Scene, shaded: &[Shaded], indirect: &[Option<Rgb>]) -> u64 {
    film.accumulate_chunks(
        scene.camera.width as usize,
        |first, chunk| {
            let mut specular = 0;
            for ((px, s), e) in chunk.iter_mut().zip(&shaded[first..]).zip(&indirect[first..]) {
                let reflected = match (&s.sample.hit, e) {
                    (Some(hit), Some(e)) => hit.beta * hit.material(scene).diffuse_reflectance() * *e * FRAC_1_PI,
                    _ => Rgb::BLACK,
                };
                px.add(s.sample.emitted + s.direct + reflected);
                px.count += 1.0;
                specular += s.sample.specular_rays;
            }
            specular
        },
        |a, b| a + b,
    )
}
