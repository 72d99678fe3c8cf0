//! Subpath vertices, their densities in area measure, light subpaths, and the MIS weight of a
//! connection strategy (Veach 1997, §10.2; the ratio form of pbrt's `MISWeight`).
//!
//! A vertex stores the throughput `beta` of its subpath up to it, the density `pdf_fwd` with
//! which its own subpath sampled it and `pdf_rev` with which the other direction would have
//! (both per unit area, so they compare across strategies), and whether it is specular
//! (`delta`: it cannot be connected to). Directions point away from the vertex.
use crate::core::{offset_ray_origin, Rgb, Rng};
use crate::embree::Ray;
use crate::scene::camera::Camera;
use crate::scene::{Material, Normals, Scene, SceneAccel, SurfaceId, Transport};
use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VertexKind {
    Camera,
    /// On light `l` (the start of a light subpath, or where an eye subpath hit an area light).
    Light(u32),
    Surface(u32),
}

#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    pub kind: VertexKind,
    pub p: Vec3,
    /// Unit geometric normal; zero for the camera and point and spot lights.
    pub n: Vec3,
    /// Unit shading normal (equal to `n` except on smooth-shaded meshes).
    pub ns: Vec3,
    /// Unit direction towards the previous vertex of its subpath (zero at the subpath's start).
    pub wo: Vec3,
    pub beta: Rgb,
    pub pdf_fwd: f32,
    pub pdf_rev: f32,
    pub delta: bool,
}

impl Vertex {
    pub fn normals(&self) -> Normals {
        Normals::new(self.n, self.ns)
    }
}

pub fn material<'a>(scene: &'a Scene, v: &Vertex) -> Option<&'a Material> {
    match v.kind {
        VertexKind::Surface(o) => Some(&scene.materials[scene.objects[o as usize].material as usize]),
        _ => None,
    }
}

/// A solid-angle density at `from` towards `to`, turned into a density per unit area at `to`.
pub fn to_area(pdf_dir: f32, from: &Vertex, to: &Vertex) -> f32 {
    let d = to.p - from.p;
    let dist2 = d.length_squared();
    if dist2 == 0.0 {
        return 0.0;
    }
    let cos = if to.n == Vec3::ZERO { 1.0 } else { to.n.dot(d).abs() / dist2.sqrt() };
    pdf_dir * cos / dist2
}

/// Density per unit area with which `from` samples `to`, having been reached from `prev` (for a
/// surface; a light samples by its emission distribution and needs no `prev`).
pub fn pdf_area(scene: &Scene, from: &Vertex, prev: Option<&Vertex>, to: &Vertex) -> f32 {
    let next = (to.p - from.p).normalize_or_zero();
    let pdf_dir = match from.kind {
        VertexKind::Surface(_) => {
            let (Some(m), Some(prev)) = (material(scene, from), prev) else { return 0.0 };
            m.pdf(from.n, (prev.p - from.p).normalize_or_zero(), next)
        }
        VertexKind::Light(l) => scene.lights[l as usize].geometry.pdf_emission_direction(from.n, next),
        VertexKind::Camera => 0.0,
    };
    to_area(pdf_dir, from, to)
}

/// The pinhole as the t = 1 strategies see it. Per pass, every pixel starts one eye path and
/// the pass traces `light_per_eye_sample` times as many light subpaths; the power heuristic
/// compares sample count × density (Veach 1997, §9.2.2), so the camera's direction density
/// enters every weight divided by that ratio, and the same quantity scales a splat.
#[derive(Clone, Copy)]
pub struct CameraDensity<'a> {
    pub camera: &'a Camera,
    pub light_per_eye_sample: f32,
}

impl CameraDensity<'_> {
    /// The camera's density of the unit direction `dir` (image-wide, see
    /// [`Camera::pdf_direction`]) divided by the light subpaths per eye sample.
    pub fn pdf_dir(&self, dir: Vec3) -> f32 {
        self.camera.pdf_direction(dir.dot(self.camera.forward)) / self.light_per_eye_sample
    }

    /// [`CameraDensity::pdf_dir`] towards `p`; 0 outside the image.
    pub fn pdf_dir_to(&self, p: Vec3) -> f32 {
        match self.camera.raster(p) {
            Some(_) => self.pdf_dir((p - self.camera.position).normalize()),
            None => 0.0,
        }
    }

    /// The camera's vertex: the pinhole, which is not specular (it can be connected to).
    pub fn vertex(&self) -> Vertex {
        Vertex {
            kind: VertexKind::Camera,
            p: self.camera.position,
            n: Vec3::ZERO,
            ns: Vec3::ZERO,
            wo: Vec3::ZERO,
            beta: Rgb::WHITE,
            pdf_fwd: 1.0,
            pdf_rev: 0.0,
            delta: false,
        }
    }
}

/// Density per unit area of choosing light vertex `v` as a light subpath's start.
pub fn pdf_light_origin(scene: &Scene, v: &Vertex) -> f32 {
    let VertexKind::Light(l) = v.kind else { return 0.0 };
    let pmf = scene.light_selection.as_ref().map_or(0.0, |d| d.pmf(l as usize));
    pmf * scene.lights[l as usize].geometry.pdf_position()
}

fn is_delta_light(scene: &Scene, v: &Vertex) -> bool {
    matches!(v.kind, VertexKind::Light(l) if scene.lights[l as usize].geometry.is_delta())
}

/// The power-heuristic weight of strategy (s, t) = (`light.len()`, `eye.len()`) for the path the
/// two subpaths make when connected, among the strategies `bdpt` uses: every (s', t') with
/// s' + t' = s + t and t' ≥ 1, except (1, 1) (a light seen directly is left to the eye path,
/// with weight 1). `eye[0]` is the camera's vertex.
pub fn mis_weight(scene: &Scene, camera: &CameraDensity, eye: &[Vertex], light: &[Vertex]) -> f32 {
    let (s, t) = (light.len(), eye.len());
    if s + t == 2 {
        return 1.0;
    }
    let remap = |x: f32| if x != 0.0 { x } else { 1.0 };
    // The connection changes the reverse densities of the (up to) four vertices next to it.
    let mut e_last = eye[t - 1];
    let mut e_prev = if t >= 2 { Some(eye[t - 2]) } else { None };
    let mut l_last = light.last().copied();
    let mut l_prev = if s >= 2 { Some(light[s - 2]) } else { None };
    match (&l_last, e_prev.as_mut()) {
        (Some(ll), e_prev) => {
            e_last.pdf_rev = pdf_area(scene, ll, l_prev.as_ref(), &e_last);
            if let Some(ep) = e_prev {
                ep.pdf_rev = pdf_area(scene, &e_last, Some(ll), ep);
            }
        }
        (None, Some(ep)) => {
            e_last.pdf_rev = pdf_light_origin(scene, &e_last);
            ep.pdf_rev = pdf_area(scene, &e_last, None, ep);
        }
        (None, None) => return 1.0,
    }
    if let Some(ll) = l_last.as_mut() {
        ll.pdf_rev = match &e_prev {
            Some(ep) => pdf_area(scene, &e_last, Some(ep), ll),
            None => to_area(camera.pdf_dir_to(ll.p), &e_last, ll),
        };
    }
    if let (Some(lp), Some(ll)) = (l_prev.as_mut(), l_last.as_ref()) {
        lp.pdf_rev = pdf_area(scene, ll, Some(&e_last), lp);
    }
    let eye_at = |i: usize| match (i, e_prev) {
        _ if i == t - 1 => e_last,
        (_, Some(ep)) if i + 2 == t => ep,
        _ => eye[i],
    };
    let light_at = |i: usize| match (l_last, l_prev) {
        (Some(ll), _) if i == s - 1 => ll,
        (_, Some(lp)) if i == s - 2 => lp,
        _ => light[i],
    };
    let mut sum = 0.0f32;
    let mut r = 1.0f32;
    for i in (1..t).rev() {
        r *= remap(eye_at(i).pdf_rev) / remap(eye_at(i).pdf_fwd);
        if !eye_at(i).delta && !eye_at(i - 1).delta {
            sum += r * r;
        }
    }
    r = 1.0;
    for i in (0..s).rev() {
        r *= remap(light_at(i).pdf_rev) / remap(light_at(i).pdf_fwd);
        let delta_before = if i > 0 { light_at(i - 1).delta } else { is_delta_light(scene, &light_at(0)) };
        if !light_at(i).delta && !delta_before {
            sum += r * r;
        }
    }
    1.0 / (1.0 + sum)
}

/// A scattering step from surface vertex `v`: the next ray, the BSDF weight for radiance
/// (eye subpaths) or importance (light subpaths), the solid-angle densities forward and reverse
/// (zero for specular lobes), and whether it was specular. `None` when the BSDF gives nothing.
pub fn scatter(scene: &Scene, v: &Vertex, transport: Transport, rng: &mut Rng) -> Option<(Ray, Rgb, f32, f32, bool)> {
    let m = material(scene, v)?;
    let bs = m.sample(v.normals(), v.wo, rng.next_2d(), rng.next_f32(), transport)?;
    let weight = bs.weight;
    let (pdf_fwd, pdf_rev) = if bs.specular { (0.0, 0.0) } else { (bs.pdf, m.pdf(v.n, bs.wi, v.wo)) };
    let side = if v.n.dot(bs.wi) >= 0.0 { v.n } else { -v.n };
    Some((Ray::new(offset_ray_origin(v.p, side), bs.wi), weight, pdf_fwd, pdf_rev, bs.specular))
}

/// The vertex where `ray` (leaving `prev` with solid-angle density `pdf_dir`) hits, carrying
/// `beta`; `None` if it leaves the scene.
pub fn hit_vertex(
    scene: &Scene,
    accel: &SceneAccel,
    ray: &Ray,
    hit: Option<crate::embree::Hit>,
    prev: &Vertex,
    beta: Rgb,
    pdf_dir: f32,
) -> Option<Vertex> {
    let (h, (surface, prim)) = hit.and_then(|h| Some((h, accel.resolve(&h)?)))?;
    let sp = scene.surface_point(surface, prim, h.u, h.v);
    let kind = match surface {
        SurfaceId::Object(o) => VertexKind::Surface(o),
        SurfaceId::Light(l) => VertexKind::Light(l),
    };
    let wo = -ray.dir.normalize();
    let mut v = Vertex { kind, p: sp.p, n: sp.n, ns: sp.ns, wo, beta, pdf_fwd: 0.0, pdf_rev: 0.0, delta: false };
    v.pdf_fwd = to_area(pdf_dir, prev, &v);
    Some(v)
}

/// Traces one light subpath of at most `max_vertices` vertices after the light's: a light by
/// power, a point and direction by its emission distribution, then BSDF sampling with Russian
/// roulette by the throughput since the light (scale-free: the light's units do not matter).
/// Lights absorb: a light subpath stops where it meets one. A light from outside (picked with
/// its share of the power) gives an empty subpath: its light reaches the image by the eye
/// subpath's (0, t) and (1, t) alone, weighed against each other in `lane.rs`. Returns the
/// vertices and the rays traced.
pub fn light_subpath(scene: &Scene, accel: &SceneAccel, max_vertices: usize, rng: &mut Rng) -> (Vec<Vertex>, u64) {
    let mut path = Vec::new();
    let Some(select) = &scene.light_selection else { return (path, 0) };
    let (l, pmf, _) = select.sample(rng.next_f32());
    let geometry = &scene.lights[l].geometry;
    if geometry.is_infinite() {
        // Lights from outside reach the image through the eye subpath's strategies alone.
        return (path, 0);
    }
    let Some((origin, dir, weight)) = geometry.sample_emission(rng.next_2d(), rng.next_2d()) else { return (path, 0) };
    let n = geometry.surface_normal();
    path.push(Vertex {
        kind: VertexKind::Light(l as u32),
        p: origin,
        n,
        ns: n,
        wo: Vec3::ZERO,
        beta: weight / pmf,
        pdf_fwd: pmf * geometry.pdf_position(),
        pdf_rev: 0.0,
        delta: false,
    });
    let mut ray = Ray::new(origin, dir);
    let mut beta = weight / pmf;
    let mut pdf_dir = geometry.pdf_emission_direction(n, dir);
    let mut scattered = Rgb::WHITE;
    let mut rays = 0;
    while path.len() <= max_vertices {
        rays += 1;
        let hit = accel.scene().intersect1(&ray);
        let prev = path[path.len() - 1];
        let Some(mut v) = hit_vertex(scene, accel, &ray, hit, &prev, beta, pdf_dir) else { break };
        if !matches!(v.kind, VertexKind::Surface(_)) {
            break;
        }
        let Some((next, weight, fwd, rev, specular)) = scatter(scene, &v, Transport::Importance, rng) else {
            path.push(v);
            break;
        };
        v.delta = specular;
        path.push(v);
        let k = path.len() - 1;
        path[k - 1].pdf_rev = to_area(rev, &path[k], &path[k - 1]);
        beta *= weight;
        scattered *= weight;
        // Roulette on the product of BSDF weights, not on β: β carries the light's flux in
        // scene units (about 7·10⁵ in the millimetre Cornell box), which would never roulette.
        let q = scattered.max_component().min(1.0);
        if k > 1 && q < 1.0 {
            if rng.next_f32() >= q {
                break;
            }
            beta = beta / q;
            scattered = scattered / q;
        }
        if beta.is_black() {
            break;
        }
        ray = next;
        pdf_dir = fwd;
    }
    (path, rays)
}
