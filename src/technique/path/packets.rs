//! The packet driver shared by `path` and `bdpt`: W eye paths traced side by side (one per lane
//! of an Embree packet), with path regeneration (Novák et al. 2010, §3.2).
//!
//! Each packet owns a queue of consecutive pixels, one path each per pass; the queue is long
//! enough (`queue_pixels`) to keep the packet busy for about T_r steps. The queue's paths are
//! started up front and their camera rays traced ahead, 16 consecutive pixels to a coherent
//! packet (`camera_prepass`), so a lane's first step only looks its hit up. Each step traces one
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

/// The paths a packet still has to start in this pass, one per pixel of its queue, already
/// started, with their camera rays' hits traced ahead (`camera_prepass`).
struct PathQueue<P> {
    paths: Vec<P>,
    primary_hits: Vec<Option<Hit>>,
    next: usize,
}

/// A lane: its path, whether it is live, and which queued pixel it traces.
#[derive(Clone)]
struct Lane<P> {
    path: P,
    active: bool,
    pixel: usize,
}

impl<P: LanePath> PathQueue<P> {
    /// Starts the path of every pixel `first..first + len` (`stream` is (seed, tick, pass);
    /// with the pixel it keys each path's random stream) and traces their camera rays.
    fn new(
        scene: &Scene,
        committed: &crate::embree::CommittedScene,
        ctx: &P::Context<'_>,
        stream: (u64, u64, u64),
        first: usize,
        len: usize,
    ) -> PathQueue<P> {
        let (seed, tick, pass) = stream;
        let width = scene.camera.width as usize;
        let start = |pixel: usize| {
            let mut path = P::idle();
            path.start(ctx, Rng::for_sample(seed, tick, pixel as u64, pass), pixel % width, pixel / width);
            path
        };
        let paths: Vec<P> = (first..first + len).map(start).collect();
        let primary_hits = camera_prepass(committed, &paths);
        PathQueue { paths, primary_hits, next: 0 }
    }

    /// Starts the next queued path on `lane`; returns false (and idles the lane) when empty.
    fn start_next(&mut self, lane: &mut Lane<P>) -> bool {
        let Some(path) = self.paths.get_mut(self.next) else {
            lane.active = false;
            return false;
        };
        std::mem::swap(&mut lane.path, path);
        lane.pixel = self.next;
        lane.active = true;
        self.next += 1;
        true
    }
}

/// Traces the camera rays of started `paths` ahead of their lanes, [`MAX_LANES`] consecutive
/// pixels to a coherent packet, where Embree traverses them together (`relume bench rays`:
/// coherent 16-wide primaries trace several times faster than incoherent rays). The hits are
/// the ones the lanes' own packets would find, so the image does not change.
fn camera_prepass<P: LanePath>(committed: &crate::embree::CommittedScene, paths: &[P]) -> Vec<Option<Hit>> {
    let mut hits = vec![None; paths.len()];
    for (group, out) in paths.chunks(MAX_LANES).zip(hits.chunks_mut(MAX_LANES)) {
        let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); MAX_LANES];
        let mut active = [false; MAX_LANES];
        for (k, path) in group.iter().enumerate() {
            rays[k] = path.ray();
            active[k] = true;
        }
        let mut packet: [Option<Hit>; MAX_LANES] = [None; MAX_LANES];
        committed.intersect_lanes(&rays, &active, true, &mut packet);
        out.copy_from_slice(&packet[..out.len()]);
    }
    hits
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
    let mut queue = PathQueue::<P>::new(scene, committed, ctx, stream, first, accum.len());
    let mut lanes: Vec<Lane<P>> = vec![Lane { path: P::idle(), active: false, pixel: 0 }; w];
    let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); MAX_LANES];
    let mut active = [false; MAX_LANES];
    let mut hits: [Option<Hit>; MAX_LANES] = [None; MAX_LANES];
    let mut shadows: Vec<ShadowTest> = Vec::new();

    loop {
        if lanes.iter().all(|l| !l.active) {
            // Start of the chunk, or (without regeneration) the whole packet has ended: refill.
            let mut any = false;
            for lane in lanes.iter_mut() {
                any |= queue.start_next(lane);
            }
            if !any {
                break;
            }
        }

        // Trace the current segment of every live lane; camera rays were traced ahead.
        let mut live = 0;
        for i in 0..w {
            let lane = &lanes[i];
            let at_camera = lane.active && lane.path.at_camera();
            active[i] = lane.active && !at_camera;
            rays[i] = lane.path.ray();
            live += u64::from(lane.active);
            stats.rays.primary += u64::from(at_camera);
            stats.rays.secondary += u64::from(active[i]);
        }
        stats.lane_steps += w as u64;
        stats.active_lane_steps += live;
        if active[..w].contains(&true) {
            committed.intersect_lanes(&rays[..w], &active[..w], false, &mut hits[..w]);
        }
        for (i, lane) in lanes.iter().enumerate() {
            if lane.active && lane.path.at_camera() {
                hits[i] = queue.primary_hits[lane.pixel];
            }
        }

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
                    queue.start_next(lane);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::embree::Device;
    use crate::scene::SceneAccel;
    use crate::technique::path::lanes::{PathContext, PathLane};
    use std::path::Path;

    #[test]
    fn the_camera_prepass_finds_what_each_camera_ray_finds_alone() {
        // Every queued path's pre-traced hit is the hit of its own camera ray traced as a single
        // ray: the same geometry and triangle, and the same distance and barycentrics bit for
        // bit. A queue longer than one packet, and not a multiple of it, checks the grouping.
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        let mut scene = crate::scene::Scene::load(&root.join("cornell-box.json"), &root).expect("scene");
        scene.set_resolution(40, 40);
        let device = Device::new(1).expect("device");
        let accel = SceneAccel::build(&device, &scene).expect("accel");
        let ctx = PathContext { scene: &scene, accel: &accel, max_path_length: 4 };
        let (first, len) = (40 * 17 + 3, 3 * MAX_LANES + 5);
        let queue = PathQueue::<PathLane>::new(&scene, accel.scene(), &ctx, (7, 2, 1), first, len);
        let mut hits = 0;
        for (path, prepass) in queue.paths.iter().zip(&queue.primary_hits) {
            let alone = accel.scene().intersect1(&path.ray());
            assert_eq!(*prepass, alone);
            hits += usize::from(alone.is_some());
        }
        assert_eq!(queue.primary_hits.len(), len);
        assert!(hits > len / 2, "the rays mostly miss: {hits} of {len} hit");
    }
}
