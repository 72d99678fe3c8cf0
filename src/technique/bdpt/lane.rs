//! The `bdpt` eye path as one lane of the shared packet driver (`path/packets.rs`): each step
//! extends the eye subpath by the vertex the packet hit and evaluates every strategy ending
//! there, (0, t) when it is a light, (1, t) by sampling a light, and (s, t) for s ≥ 2 against
//! the vertices of one light subpath of the batch, each weighted by the power heuristic.
use super::vertex::{hit_vertex, material, mis_weight, scatter, CameraDensity, Vertex, VertexKind};
use crate::core::{offset_ray_origin, Rgb, Rng};
use crate::embree::{Hit, Ray};
use crate::scene::{Scene, SceneAccel, Transport};
use crate::technique::nee::{escaped_radiance, sample_next_event, shadow_segment};
use crate::technique::path::packets::{LanePath, ShadowTest};
use glam::Vec3;

/// What a `bdpt` lane reads while shading.
pub struct BdptContext<'a> {
    pub scene: &'a Scene,
    pub accel: &'a SceneAccel,
    /// l_m: the most surface vertices a full path may have.
    pub max_path_length: u32,
    /// This packet's light subpaths.
    pub batch: &'a [Vec<Vertex>],
    /// Pick a light subpath at random at every bounce (§3.4), or keep one per eye path.
    pub permute: bool,
    /// With one light subpath per eye path: the first pixel of the queue, so that pixel p's own
    /// subpath is `batch[p - first]`. `None`: a shared batch, each eye path's own picked at random.
    pub own_from: Option<usize>,
    /// The camera's density for the weights against the t = 1 strategies.
    pub camera: CameraDensity<'a>,
}

#[derive(Clone)]
pub struct BdptLane {
    rng: Rng,
    ray: Ray,
    /// Solid-angle density of the BSDF sample that produced `ray`.
    pdf_dir: f32,
    beta: Rgb,
    eye: Vec<Vertex>,
    radiance: Rgb,
    /// The light subpath this eye path connects to when not permuting.
    own_light_path: usize,
    done: bool,
    /// The eye path ended at l_m surface vertices.
    truncated: bool,
}

impl LanePath for BdptLane {
    type Context<'c> = BdptContext<'c>;

    fn idle() -> BdptLane {
        BdptLane {
            rng: Rng::new(0, 0),
            ray: Ray::new(Vec3::ZERO, Vec3::Z),
            pdf_dir: 0.0,
            beta: Rgb::BLACK,
            eye: Vec::new(),
            radiance: Rgb::BLACK,
            own_light_path: 0,
            done: false,
            truncated: false,
        }
    }

    fn start(&mut self, ctx: &BdptContext<'_>, rng: Rng, x: usize, y: usize) {
        self.rng = rng;
        let j = self.rng.next_2d();
        self.ray = ctx.scene.camera.ray(x as f32 + j.x, y as f32 + j.y);
        // The camera's density of this direction weighs the path against light tracing (t = 1).
        self.pdf_dir = ctx.camera.pdf_dir(self.ray.dir);
        self.beta = Rgb::WHITE;
        self.eye.clear();
        self.eye.push(ctx.camera.vertex());
        self.radiance = Rgb::BLACK;
        let drawn = (self.rng.next_u32() as usize) % ctx.batch.len().max(1);
        let pixel = y * ctx.scene.camera.width as usize + x;
        self.own_light_path = ctx.own_from.map_or(drawn, |first| pixel - first);
        self.done = false;
        self.truncated = false;
    }

    fn ray(&self) -> Ray {
        self.ray
    }

    fn at_camera(&self) -> bool {
        self.eye.len() == 1
    }

    fn done(&self) -> bool {
        self.done
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

    fn shade(&mut self, ctx: &BdptContext<'_>, hit: Option<Hit>, lane: usize, shadows: &mut Vec<ShadowTest>) {
        let scene = ctx.scene;
        let prev = self.eye[self.eye.len() - 1];
        let Some(mut v) = hit_vertex(scene, ctx.accel, &self.ray, hit, &prev, self.beta, self.pdf_dir) else {
            // (0, t) for the lights outside: weighed against (1, t) alone (see `escaped_weight`).
            if !scene.infinite_lights.is_empty() {
                let nee_reached = self.eye.len() > 1 && self.pdf_dir > 0.0;
                let side = if prev.n.dot(prev.wo) >= 0.0 { prev.n } else { -prev.n };
                let bsdf = nee_reached.then_some((self.pdf_dir, side));
                self.radiance += self.beta * escaped_radiance(scene, self.ray.dir, bsdf);
            }
            self.done = true;
            return;
        };
        // (0, t): the eye subpath found a light by itself. Lights absorb: the path ends.
        if let VertexKind::Light(l) = v.kind {
            let le = scene.lights[l as usize].geometry.emitted(v.n, v.wo);
            if !le.is_black() {
                self.eye.push(v);
                self.radiance += self.beta * le * mis_weight(scene, &ctx.camera, &self.eye, &[]);
            }
            self.done = true;
            return;
        }
        let surfaces = self.eye.len() as u32; // surface vertices once `v` is added
        let Some(m) = material(scene, &v) else { return };
        if surfaces > ctx.max_path_length {
            self.done = true;
            self.truncated = true;
            return;
        }
        v.delta = m.is_specular();
        self.eye.push(v);
        if !v.delta {
            self.connect_to_a_light_sample(ctx, lane, shadows);
            self.connect_to_a_light_subpath(ctx, lane, shadows);
        }
        // Extend the eye subpath by sampling the BSDF.
        let Some((next, weight, fwd, rev, _)) = scatter(scene, &v, Transport::Radiance, &mut self.rng) else {
            self.done = true;
            return;
        };
        let t = self.eye.len();
        self.eye[t - 2].pdf_rev = super::vertex::to_area(rev, &self.eye[t - 1], &self.eye[t - 2]);
        self.beta *= weight;
        // Russian roulette by throughput from the second bounce, as `path` does.
        let q = self.beta.max_component().min(1.0);
        if surfaces > 1 && q < 1.0 {
            if self.rng.next_f32() >= q {
                self.done = true;
                return;
            }
            self.beta = self.beta / q;
        }
        if self.beta.is_black() {
            self.done = true;
            return;
        }
        self.ray = next;
        self.pdf_dir = fwd;
    }
}

impl BdptLane {
    /// (1, t): next-event estimation, weighted against the other strategies.
    fn connect_to_a_light_sample(&mut self, ctx: &BdptContext<'_>, lane: usize, shadows: &mut Vec<ShadowTest>) {
        let scene = ctx.scene;
        let e = self.eye[self.eye.len() - 1];
        let Some(m) = material(scene, &e) else { return };
        let Some(ne) = sample_next_event(scene, m, e.p, e.normals(), e.wo, &mut self.rng, false) else { return };
        let geometry = &scene.lights[ne.light].geometry;
        if geometry.is_infinite() {
            let side = if e.n.dot(e.wo) >= 0.0 { e.n } else { -e.n };
            let w = escaped_weight(geometry, ne.light_pmf, m.pdf(e.n, e.wo, ne.shadow.dir), (ne.shadow.dir, side));
            shadows.push(ShadowTest { ray: ne.shadow, lane, contribution: self.beta * ne.contribution * w });
            return;
        }
        let sampled = Vertex {
            kind: VertexKind::Light(ne.light as u32),
            p: ne.light_point,
            n: ne.light_normal,
            ns: ne.light_normal,
            wo: Vec3::ZERO,
            beta: Rgb::WHITE,
            pdf_fwd: ne.light_pmf * geometry.pdf_position(),
            pdf_rev: 0.0,
            delta: false,
        };
        let w = mis_weight(scene, &ctx.camera, &self.eye, &[sampled]);
        shadows.push(ShadowTest { ray: ne.shadow, lane, contribution: self.beta * ne.contribution * w });
    }

    /// (s, t), s ≥ 2: connections to the vertices of one light subpath of the batch, chosen
    /// at random at this bounce when permuting (§3.4).
    fn connect_to_a_light_subpath(&mut self, ctx: &BdptContext<'_>, lane: usize, shadows: &mut Vec<ShadowTest>) {
        if ctx.batch.is_empty() {
            return;
        }
        let scene = ctx.scene;
        let index = if ctx.permute { (self.rng.next_u32() as usize) % ctx.batch.len() } else { self.own_light_path };
        let light_path = &ctx.batch[index];
        let e = self.eye[self.eye.len() - 1];
        let Some(me) = material(scene, &e) else { return };
        let eye_surfaces = self.eye.len() as u32 - 1;
        for s in 2..=light_path.len() {
            if eye_surfaces + s as u32 - 1 > ctx.max_path_length {
                break;
            }
            let l = light_path[s - 1];
            let Some(ml) = material(scene, &l) else { continue };
            if l.delta {
                continue;
            }
            let d = l.p - e.p;
            let dist2 = d.length_squared();
            if dist2 <= 0.0 {
                continue;
            }
            let dist = dist2.sqrt();
            let dir = d / dist;
            let f = me.eval(e.normals(), e.wo, dir, Transport::Radiance)
                * ml.eval(l.normals(), l.wo, -dir, Transport::Importance);
            if f.is_black() {
                continue;
            }
            let g = e.n.dot(dir).abs() * l.n.dot(dir).abs() / dist2;
            let w = mis_weight(scene, &ctx.camera, &self.eye, &light_path[..s]);
            // Both ends leave their surface on the side they connect from, so a segment between
            // the two sides of one thin wall crosses it and is occluded.
            let from = offset_ray_origin(e.p, if e.n.dot(dir) >= 0.0 { e.n } else { -e.n });
            let to = offset_ray_origin(l.p, if l.n.dot(l.wo) >= 0.0 { l.n } else { -l.n });
            let Some(ray) = shadow_segment(from, to) else { continue };
            shadows.push(ShadowTest { ray, lane, contribution: self.beta * f * l.beta * (g * w) });
        }
    }
}

/// The (1, t) weight of a sample towards a light from outside. Light subpaths never start on
/// these lights (see `vertex::light_subpath`), so their paths have two strategies, (1, t) and
/// (0, t), weighed by the power heuristic as `path` does; a delta sun has only (1, t).
fn escaped_weight(geometry: &crate::scene::LightGeometry, pmf: f32, bsdf_pdf: f32, (wi, side): (Vec3, Vec3)) -> f32 {
    if geometry.is_delta() {
        1.0
    } else {
        crate::core::sampling::power_heuristic(pmf * geometry.pdf_direction(wi, side), bsdf_pdf)
    }
}
