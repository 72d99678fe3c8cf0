//! The `path` integrator as one lane of the packet driver (`packets.rs`): unidirectional path
//! tracing with next-event estimation; area lights are combined with BSDF sampling by MIS (power
//! heuristic), point and spot lights are sampled directly; Russian roulette by throughput from
//! the second bounce.
use super::packets::{LanePath, ShadowTest};
use crate::core::{offset_ray_origin, sampling::power_heuristic, Rgb, Rng};
use crate::embree::{Hit, Ray};
use crate::scene::{Scene, SceneAccel, SurfaceId, Transport};
use crate::technique::nee::{escaped_radiance, sample_next_event};
use glam::Vec3;

/// What a `path` lane reads while shading.
pub struct PathContext<'a> {
    pub scene: &'a Scene,
    pub accel: &'a SceneAccel,
    /// l_m: scattering vertices after which a path is forcibly ended.
    pub max_path_length: u32,
}

/// One camera path's state.
#[derive(Clone)]
pub struct PathLane {
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
    /// The geometric normal at the previous vertex on the side the path arrived from (what
    /// next-event estimation sampled the environment about).
    prev_side: Vec3,
    eta_scale: f32,
    path_done: bool,
    /// Ended by l_m.
    truncated: bool,
}

impl LanePath for PathLane {
    type Context<'c> = PathContext<'c>;

    fn idle() -> PathLane {
        PathLane {
            rng: Rng::new(0, 0),
            ray: Ray::new(Vec3::ZERO, Vec3::Z),
            beta: Rgb::BLACK,
            radiance: Rgb::BLACK,
            depth: 0,
            specular_bounce: false,
            bsdf_pdf: 0.0,
            prev_point: Vec3::ZERO,
            prev_side: Vec3::ZERO,
            eta_scale: 1.0,
            path_done: false,
            truncated: false,
        }
    }
    /// Starts a new camera path for pixel (`x`, `y`) with a jittered film position.
    fn start(&mut self, ctx: &PathContext<'_>, rng: Rng, x: usize, y: usize) {
        let lane = self;
        lane.rng = rng;
        let j = lane.rng.next_2d();
        lane.ray = ctx.scene.camera.ray(x as f32 + j.x, y as f32 + j.y);
        lane.beta = Rgb::WHITE;
        lane.radiance = Rgb::BLACK;
        lane.depth = 0;
        lane.specular_bounce = false;
        lane.bsdf_pdf = 0.0;
        lane.prev_point = lane.ray.origin;
        lane.prev_side = Vec3::ZERO;
        lane.eta_scale = 1.0;
        lane.path_done = false;
        lane.truncated = false;
    }

    fn ray(&self) -> Ray {
        self.ray
    }

    fn at_camera(&self) -> bool {
        self.depth == 0
    }

    fn done(&self) -> bool {
        self.path_done
    }

    fn truncated(&self) -> bool {
        self.truncated
    }

    fn add(&mut self, radiance: Rgb) {
        self.radiance += radiance;
    }

    fn radiance(&self) -> Rgb {
        self.radiance
    }

    fn shade(&mut self, ctx: &PathContext<'_>, hit: Option<Hit>, lane_index: usize, shadows: &mut Vec<ShadowTest>) {
        if let Some((ray, contribution)) = shade(self, hit, ctx.scene, ctx.accel, ctx.max_path_length) {
            shadows.push(ShadowTest { ray, lane: lane_index, contribution });
        }
    }
}

/// Processes one hit of a lane's path; returns the shadow ray for next-event estimation and the
/// contribution it carries if unoccluded.
fn shade(lane: &mut PathLane, hit: Option<Hit>, scene: &Scene, accel: &SceneAccel, max_len: u32) -> Option<(Ray, Rgb)> {
    let Some((h, (surface, prim))) = hit.and_then(|h| Some((h, accel.resolve(&h)?))) else {
        // The path leaves the scene: the lights outside it, weighted against NEE's samples.
        if !scene.infinite_lights.is_empty() {
            let nee_reached = lane.depth > 0 && !lane.specular_bounce;
            let le = escaped_radiance(scene, lane.ray.dir, nee_reached.then_some((lane.bsdf_pdf, lane.prev_side)));
            lane.radiance += lane.beta * le;
        }
        lane.path_done = true;
        return None;
    };
    let sp = scene.surface_point(surface, prim, h.u, h.v);
    // Camera rays are normalized and BSDF samples are unit vectors: no normalize needed.
    let wo = -lane.ray.dir;
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
        lane.truncated = true;
        return None;
    }
    let material = &scene.materials[scene.objects[oi as usize].material as usize];
    let n = sp.n;
    let normals = sp.normals();

    // Next-event estimation towards one light chosen by power.
    let mut shadow = None;
    if !material.is_specular() {
        if let Some(ne) = sample_next_event(scene, material, sp.p, normals, wo, &mut lane.rng, true) {
            shadow = Some((ne.shadow, lane.beta * ne.contribution));
        }
    }

    // Continue the path by sampling the BSDF.
    let u = lane.rng.next_2d();
    let uc = lane.rng.next_f32();
    let Some(bs) = material.sample(normals, wo, u, uc, Transport::Radiance) else {
        lane.path_done = true;
        return shadow;
    };
    lane.beta *= bs.weight;
    lane.specular_bounce = bs.specular;
    lane.bsdf_pdf = bs.pdf;
    lane.prev_point = sp.p;
    lane.prev_side = if n.dot(wo) >= 0.0 { n } else { -n };
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
