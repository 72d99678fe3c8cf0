//! The lane integrator: W paths traced side by side (one per lane of an Embree packet), with
//! path regeneration (Novák et al. 2010, §3.2).
//!
//! Each packet owns a queue of consecutive pixels, one path each per pass; the queue is long
//! enough (`PathTracer::queue_pixels`) to keep the packet busy for about T_r steps. Each step
//! traces one closest-hit packet and one occlusion packet for the lanes' current segments. With regeneration, a lane whose path ended takes the next queued
//! path at once, so packets stay full while the queue lasts (the regeneration phase); then the
//! remaining paths finish (the closing phase, at most l_m + 1 steps). Without regeneration, ended
//! lanes idle until every lane of the packet has ended, and then all W lanes refill together.
//!
//! Why a queue of pixels rather than restarting the same pixel until T_r steps have passed: with
//! a step budget, the path that straddles the budget's end is length-biased (the inspection
//! paradox), and with a handful of paths per pixel the pixel mean keeps that bias (measured:
//! +1.6% on the furnace). With a fixed count per pixel the estimate is unbiased, and since each
//! path draws from its own random stream, regeneration on or off gives the identical image.
//!
//! Estimator: unidirectional path tracing with next-event estimation; area lights are combined
//! with BSDF sampling by MIS (power heuristic), point and spot lights are sampled directly;
//! Russian roulette by throughput from the second bounce.
use super::PathStats;
use crate::core::{offset_ray_origin, sampling::power_heuristic, Rgb, Rng};
use crate::embree::{Hit, Ray};
use crate::film::PixelAccum;
use crate::scene::{Scene, SceneAccel, SurfaceId};
use crate::technique::nee::sample_next_event;
use glam::Vec3;

/// Widest packet Embree offers.
pub const MAX_LANES: usize = 16;

/// How one chunk of pixels is traced.
#[derive(Clone, Copy, Debug)]
pub struct LaneSettings {
    pub lanes: usize,
    pub regeneration: bool,
    /// l_m: scattering vertices after which a path is forcibly ended.
    pub max_path_length: u32,
}

/// Per-lane path state.
#[derive(Clone)]
struct Lane {
    active: bool,
    /// Pixel offset within the chunk.
    pixel: usize,
    rng: Rng,
    ray: Ray,
    beta: Rgb,
    radiance: Rgb,
    /// Scattering vertices so far on this path.
    depth: u32,
    /// The previous vertex was specular (its emission hits get full weight).
    specular_bounce: bool,
    /// Solid-angle pdf of the BSDF sample that produced `ray`.
    bsdf_pdf: f32,
    prev_point: Vec3,
    eta_scale: f32,
    /// Next-event contribution waiting for its shadow ray.
    pending: Rgb,
    path_done: bool,
}

impl Lane {
    fn idle() -> Lane {
        Lane {
            active: false,
            pixel: 0,
            rng: Rng::new(0, 0),
            ray: Ray::new(Vec3::ZERO, Vec3::Z),
            beta: Rgb::BLACK,
            radiance: Rgb::BLACK,
            depth: 0,
            specular_bounce: false,
            bsdf_pdf: 0.0,
            prev_point: Vec3::ZERO,
            eta_scale: 1.0,
            pending: Rgb::BLACK,
            path_done: false,
        }
    }
}

/// The pixels whose path a packet still has to start in this pass.
struct PathQueue {
    first_pixel: usize,
    len: usize,
    next: usize,
    /// (seed, tick, pass): with the pixel, keys each path's random stream.
    stream: (u64, u64, u64),
}

impl PathQueue {
    /// Starts the next queued path on `lane`; returns false (and idles the lane) when empty.
    fn start_next(&mut self, lane: &mut Lane, scene: &Scene) -> bool {
        if self.next >= self.len {
            lane.active = false;
            return false;
        }
        let offset = self.next;
        self.next += 1;
        let pixel = self.first_pixel + offset;
        let (seed, tick, pass) = self.stream;
        lane.pixel = offset;
        lane.rng = Rng::for_sample(seed, tick, pixel as u64, pass);
        let width = scene.camera.width as usize;
        start_path(lane, scene, pixel % width, pixel / width);
        true
    }
}

/// Traces one pass (one path per pixel) for pixels `first..first + accum.len()` and adds them to
/// `accum`. `stream` is (seed, tick, pass).
pub fn trace_chunk(
    scene: &Scene,
    accel: &SceneAccel,
    settings: &LaneSettings,
    stream: (u64, u64, u64),
    first: usize,
    accum: &mut [PixelAccum],
) -> PathStats {
    let w = settings.lanes.clamp(1, MAX_LANES);
    let mut stats = PathStats::default();
    let committed = accel.scene();
    let mut queue = PathQueue { first_pixel: first, len: accum.len(), next: 0, stream };
    let mut lanes: Vec<Lane> = vec![Lane::idle(); w];
    let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); MAX_LANES];
    let mut active = [false; MAX_LANES];
    let mut hits: [Option<Hit>; MAX_LANES] = [None; MAX_LANES];
    let mut shadow_rays = [Ray::new(Vec3::ZERO, Vec3::Z); MAX_LANES];
    let mut shadow_active = [false; MAX_LANES];
    let mut occluded = [false; MAX_LANES];

    loop {
        let mut coherent = false;
        if lanes.iter().all(|l| !l.active) {
            // Start of the chunk, or (without regeneration) the whole packet has ended: refill.
            let mut any = false;
            for lane in lanes.iter_mut() {
                any |= queue.start_next(lane, scene);
            }
            if !any {
                break;
            }
            coherent = true;
        }

        // Trace the current segment of every live lane.
        let mut live = 0;
        for i in 0..w {
            active[i] = lanes[i].active;
            rays[i] = lanes[i].ray;
            if lanes[i].active {
                live += 1;
                if lanes[i].depth == 0 {
                    stats.rays.primary += 1;
                } else {
                    stats.rays.secondary += 1;
                }
            }
        }
        stats.lane_steps += w as u64;
        stats.active_lane_steps += live;
        committed.intersect_lanes(&rays[..w], &active[..w], coherent, &mut hits[..w]);

        // Shade: emission, next-event estimation, BSDF sampling, Russian roulette.
        for i in 0..w {
            shadow_active[i] = false;
            if lanes[i].active {
                if let Some(shadow) = shade(&mut lanes[i], hits[i], scene, accel, settings.max_path_length) {
                    shadow_rays[i] = shadow;
                    shadow_active[i] = true;
                    stats.rays.shadow += 1;
                }
            }
        }
        if shadow_active[..w].iter().any(|a| *a) {
            committed.occluded_lanes(&shadow_rays[..w], &shadow_active[..w], &mut occluded[..w]);
        }

        // Resolve next-event contributions, record ended paths, regenerate.
        for i in 0..w {
            let lane = &mut lanes[i];
            if shadow_active[i] && !occluded[i] {
                lane.radiance += lane.pending;
            }
            if lane.active && lane.path_done {
                let pixel = &mut accum[lane.pixel];
                pixel.add(lane.radiance);
                pixel.count += 1.0;
                stats.paths += 1;
                lane.active = false;
                if settings.regeneration {
                    queue.start_next(lane, scene);
                }
            }
        }
    }
    stats
}

/// Starts a new camera path for pixel (`x`, `y`) with a jittered film position.
fn start_path(lane: &mut Lane, scene: &Scene, x: usize, y: usize) {
    let j = lane.rng.next_2d();
    lane.ray = scene.camera.ray(x as f32 + j.x, y as f32 + j.y);
    lane.active = true;
    lane.beta = Rgb::WHITE;
    lane.radiance = Rgb::BLACK;
    lane.depth = 0;
    lane.specular_bounce = false;
    lane.bsdf_pdf = 0.0;
    lane.prev_point = lane.ray.origin;
    lane.eta_scale = 1.0;
    lane.pending = Rgb::BLACK;
    lane.path_done = false;
}

/// Processes one hit of a lane's path; returns the shadow ray for next-event estimation.
fn shade(lane: &mut Lane, hit: Option<Hit>, scene: &Scene, accel: &SceneAccel, max_len: u32) -> Option<Ray> {
    lane.pending = Rgb::BLACK;
    let Some((h, (surface, prim))) = hit.and_then(|h| Some((h, accel.resolve(&h)?))) else {
        lane.path_done = true;
        return None;
    };
    let sp = scene.surface_point(surface, prim, h.u, h.v);
    let wo = -lane.ray.dir.normalize();
    lane.depth += 1;

    // Emission: lights are black absorbers that end the path.
    if let SurfaceId::Light(li) = surface {
        let light = &scene.lights[li as usize];
        let le = light.geometry.emitted(sp.n, wo);
        if !le.is_black() {
            let weight = if lane.depth == 1 || lane.specular_bounce {
                1.0
            } else {
                let pmf = scene.light_selection.as_ref().map_or(0.0, |d| d.pmf(li as usize));
                power_heuristic(lane.bsdf_pdf, pmf * light.geometry.pdf_incident(lane.prev_point, sp.p, sp.n))
            };
            lane.radiance += lane.beta * le * weight;
        }
        lane.path_done = true;
        return None;
    }
    let SurfaceId::Object(oi) = surface else { return None };
    if lane.depth > max_len {
        lane.path_done = true;
        return None;
    }
    let material = &scene.materials[scene.objects[oi as usize].material as usize];
    let n = sp.n;

    // Next-event estimation towards one light chosen by power.
    let mut shadow = None;
    if !material.is_specular() {
        if let Some(ne) = sample_next_event(scene, material, sp.p, n, wo, &mut lane.rng, true) {
            lane.pending = lane.beta * ne.contribution;
            shadow = Some(ne.shadow);
        }
    }

    // Continue the path by sampling the BSDF.
    let u = lane.rng.next_2d();
    let uc = lane.rng.next_f32();
    let Some(bs) = material.sample(n, wo, u, uc) else {
        lane.path_done = true;
        return shadow;
    };
    lane.beta *= bs.weight;
    lane.specular_bounce = bs.specular;
    lane.bsdf_pdf = bs.pdf;
    lane.prev_point = sp.p;
    if bs.eta != 1.0 {
        lane.eta_scale *= bs.eta * bs.eta;
    }
    // Russian roulette by throughput (pbrt-v4), from the second bounce on.
    let rr = lane.beta.max_component() * lane.eta_scale;
    if lane.depth > 1 && rr < 1.0 {
        let q = (1.0 - rr).max(0.0);
        if lane.rng.next_f32() < q {
            lane.path_done = true;
            return shadow;
        }
        lane.beta = lane.beta / (1.0 - q);
    }
    if lane.beta.is_black() {
        lane.path_done = true;
        return shadow;
    }
    let side = if n.dot(bs.wi) >= 0.0 { n } else { -n };
    lane.ray = Ray::new(offset_ray_origin(sp.p, side), bs.wi);
    shadow
}
