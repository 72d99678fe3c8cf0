//! The packet driver shared by `path` and `bdpt`: W eye paths traced side by side (one per lane
//! of an Embree packet), with path regeneration (Novák et al. 2010, §3.2).
//!
//! Each packet owns a queue of consecutive pixels, one path each per pass; the queue is long
//! enough (`queue_pixels`) to keep the packet busy for about T_r steps. Each step traces one
//! closest-hit packet for the lanes' current rays, lets each lane shade its hit (which may ask
//! for any number of shadow tests), and traces those tests in packets of W. With regeneration, a
//! lane whose path ended takes the next queued path at once, so packets stay full while the
//! queue lasts (the regeneration phase); then the remaining paths finish (the closing phase, at
//! most l_m + 1 steps). Without regeneration, ended lanes idle until every lane of the packet
//! has ended, and then all W lanes refill together.
//!
//! Why a queue of pixels rather than restarting the same pixel until T_r steps have passed: with
//! a step budget, the path that straddles the budget's end is length-biased (the inspection
//! paradox), and with a handful of paths per pixel the pixel mean keeps that bias (measured:
//! +1.6% on the furnace). With a fixed count per pixel the estimate is unbiased, and since each
//! path draws from its own random stream, regeneration on or off gives the identical image.
use super::PathStats;
use crate::core::{Rgb, Rng};
use crate::embree::{Hit, Ray};
use crate::film::PixelAccum;
use crate::scene::Scene;
use glam::Vec3;

/// Widest packet Embree offers.
pub const MAX_LANES: usize = 16;

/// How one chunk of pixels is traced.
#[derive(Clone, Copy, Debug)]
pub struct LaneSettings {
    pub lanes: usize,
    pub regeneration: bool,
}

/// An occlusion test a lane asked for: `contribution` is added to its path if `ray` is clear.
#[derive(Clone, Copy, Debug)]
pub struct ShadowTest {
    pub ray: Ray,
    pub lane: usize,
    pub contribution: Rgb,
}

/// One eye path as a lane traces it. `Context` is what shading reads (scene, accel, settings,
/// and for `bdpt` the batch of light subpaths).
pub trait LanePath: Clone {
    type Context<'c>: Sync;

    fn idle() -> Self;
    /// Starts the path of pixel (`x`, `y`) drawing from `rng`.
    fn start(&mut self, ctx: &Self::Context<'_>, rng: Rng, x: usize, y: usize);
    /// The ray to trace this step.
    fn ray(&self) -> Ray;
    /// No scattering vertex yet: the current ray leaves the camera.
    fn at_camera(&self) -> bool;
    /// Shades the current ray's hit; `lane` is this lane's index, for its shadow tests.
    fn shade(&mut self, ctx: &Self::Context<'_>, hit: Option<Hit>, lane: usize, shadows: &mut Vec<ShadowTest>);
    fn done(&self) -> bool;
    /// The path ended because it reached l_m, not by roulette, escape or absorption.
    fn truncated(&self) -> bool;
    /// Adds radiance to the path's estimate.
    fn add(&mut self, radiance: Rgb);
    fn radiance(&self) -> Rgb;
}

/// The pixels whose path a packet still has to start in this pass.
struct PathQueue {
    first_pixel: usize,
    len: usize,
    next: usize,
    /// (seed, tick, pass): with the pixel, keys each path's random stream.
    stream: (u64, u64, u64),
}

/// A lane: its path, whether it is live, and which queued pixel it traces.
#[derive(Clone)]
struct Lane<P> {
    path: P,
    active: bool,
    pixel: usize,
}

impl PathQueue {
    /// Starts the next queued path on `lane`; returns false (and idles the lane) when empty.
    fn start_next<P: LanePath>(&mut self, lane: &mut Lane<P>, ctx: &P::Context<'_>, scene: &Scene) -> bool {
        if self.next >= self.len {
            lane.active = false;
            return false;
        }
        let offset = self.next;
        self.next += 1;
        let pixel = self.first_pixel + offset;
        let (seed, tick, pass) = self.stream;
        lane.pixel = offset;
        lane.active = true;
        let width = scene.camera.width as usize;
        lane.path.start(ctx, Rng::for_sample(seed, tick, pixel as u64, pass), pixel % width, pixel / width);
        true
    }
}

/// Traces one pass (one path per pixel) for pixels `first..first + accum.len()` and adds them to
/// `accum`. `stream` is (seed, tick, pass).
pub fn trace_chunk<P: LanePath>(
    scene: &Scene,
    committed: &crate::embree::CommittedScene,
    ctx: &P::Context<'_>,
    settings: &LaneSettings,
    stream: (u64, u64, u64),
    first: usize,
    accum: &mut [PixelAccum],
) -> PathStats {
    let w = settings.lanes.clamp(1, MAX_LANES);
    let mut stats = PathStats::default();
    let mut queue = PathQueue { first_pixel: first, len: accum.len(), next: 0, stream };
    let mut lanes: Vec<Lane<P>> = vec![Lane { path: P::idle(), active: false, pixel: 0 }; w];
    let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); MAX_LANES];
    let mut active = [false; MAX_LANES];
    let mut hits: [Option<Hit>; MAX_LANES] = [None; MAX_LANES];
    let mut shadows: Vec<ShadowTest> = Vec::new();

    loop {
        let mut coherent = false;
        if lanes.iter().all(|l| !l.active) {
            // Start of the chunk, or (without regeneration) the whole packet has ended: refill.
            let mut any = false;
            for lane in lanes.iter_mut() {
                any |= queue.start_next(lane, ctx, scene);
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
            rays[i] = lanes[i].path.ray();
            if lanes[i].active {
                live += 1;
                if lanes[i].path.at_camera() {
                    stats.rays.primary += 1;
                } else {
                    stats.rays.secondary += 1;
                }
            }
        }
        stats.lane_steps += w as u64;
        stats.active_lane_steps += live;
        committed.intersect_lanes(&rays[..w], &active[..w], coherent, &mut hits[..w]);

        // Shade, then trace the shadow tests the lanes asked for, W at a time.
        shadows.clear();
        for (i, lane) in lanes.iter_mut().enumerate() {
            if lane.active {
                lane.path.shade(ctx, hits[i], i, &mut shadows);
            }
        }
        stats.rays.shadow += shadows.len() as u64;
        trace_shadows(committed, &shadows, w, &mut lanes);

        // Record ended paths and regenerate.
        for lane in lanes.iter_mut() {
            if lane.active && lane.path.done() {
                record(lane, accum, &mut stats);
                if settings.regeneration {
                    queue.start_next(lane, ctx, scene);
                }
            }
        }
    }
    stats
}

/// Traces the lanes' shadow tests W at a time and adds each clear test's contribution to its
/// lane's path.
fn trace_shadows<P: LanePath>(
    committed: &crate::embree::CommittedScene,
    shadows: &[ShadowTest],
    w: usize,
    lanes: &mut [Lane<P>],
) {
    for batch in shadows.chunks(w) {
        let mut shadow_rays = [Ray::new(Vec3::ZERO, Vec3::Z); MAX_LANES];
        let mut shadow_active = [false; MAX_LANES];
        let mut occluded = [false; MAX_LANES];
        for (k, s) in batch.iter().enumerate() {
            shadow_rays[k] = s.ray;
            shadow_active[k] = true;
        }
        committed.occluded_lanes(&shadow_rays[..w], &shadow_active[..w], &mut occluded[..w]);
        for (k, s) in batch.iter().enumerate() {
            if !occluded[k] {
                lanes[s.lane].path.add(s.contribution);
            }
        }
    }
}

/// Adds an ended path to its pixel and the stats, and idles its lane.
fn record<P: LanePath>(lane: &mut Lane<P>, accum: &mut [PixelAccum], stats: &mut PathStats) {
    let pixel = &mut accum[lane.pixel];
    pixel.add(lane.path.radiance());
    pixel.count += 1.0;
    stats.paths += 1;
    stats.truncated_paths += lane.path.truncated() as u64;
    lane.active = false;
}
