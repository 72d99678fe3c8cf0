//! Camera samples through ideal mirror and glass chains to the first diffuse surface, shared by
//! the techniques that shade diffuse surfaces from a cache (`photon_reuse`, `instant_cache`).
//! Lights seen directly or through the chain, and the lights outside the scene along a ray that
//! leaves it, add their emission (next-event estimation cannot reach them there); the chain
//! gives up after [`MAX_SPECULAR_CHAIN`] specular bounces.
use crate::core::{offset_ray_origin, Rgb, Rng};
use crate::embree::Ray;
use crate::scene::{Material, Normals, Scene, SceneAccel, SurfaceId, Transport};
use crate::technique::nee::{escaped_radiance, sample_next_event};
use glam::{Vec2, Vec3};

/// Longest specular chain a camera ray follows before it gives up.
pub const MAX_SPECULAR_CHAIN: u32 = 16;

/// The first diffuse surface a camera sample reaches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffuseHit {
    pub p: Vec3,
    /// Unit geometric normal.
    pub n: Vec3,
    /// Unit shading normal (on the side of `n`; equal to it on flat-shaded meshes).
    pub ns: Vec3,
    /// Unit direction back along the arriving ray.
    pub wo: Vec3,
    pub object: u32,
    /// The triangle hit and the barycentrics (u, v) of the hit on it.
    pub triangle: u32,
    pub uv: Vec2,
    /// Throughput of the specular chain (white when the camera sees the surface directly).
    pub beta: Rgb,
}

impl DiffuseHit {
    pub fn material<'a>(&self, scene: &'a Scene) -> &'a Material {
        &scene.materials[scene.objects[self.object as usize].material as usize]
    }

    pub fn normals(&self) -> Normals {
        Normals::new(self.n, self.ns)
    }

    /// The geometric normal on the side the sample arrives from.
    pub fn facing(&self) -> Vec3 {
        self.turned_to_viewer(self.n)
    }

    /// The shading normal on the side the sample arrives from (the geometric normal's side).
    pub fn shading_facing(&self) -> Vec3 {
        self.turned_to_viewer(self.ns)
    }

    /// `v`, negated if the sample arrives from the geometric normal's back side.
    fn turned_to_viewer(&self, v: Vec3) -> Vec3 {
        if self.n.dot(self.wo) >= 0.0 {
            v
        } else {
            -v
        }
    }
}

/// What one camera sample found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraSample {
    /// Emission of lights met along the chain, weighted by its throughput.
    pub emitted: Rgb,
    pub hit: Option<DiffuseHit>,
    /// Rays traced after the camera ray.
    pub specular_rays: u64,
}

/// The camera ray through point `jitter` ∈ [0, 1)² of pixel `index` (row-major).
pub fn camera_ray(scene: &Scene, index: usize, jitter: Vec2) -> Ray {
    let width = scene.camera.width as usize;
    scene.camera.ray((index % width) as f32 + jitter.x, (index / width) as f32 + jitter.y)
}

/// Traces the camera ray through point `jitter` ∈ [0, 1)² of pixel `index` (row-major) and
/// its specular chain, which draws from `rng`.
pub fn trace(scene: &Scene, accel: &SceneAccel, index: usize, jitter: Vec2, rng: &mut Rng) -> CameraSample {
    let mut ray = camera_ray(scene, index, jitter);
    let mut out = CameraSample::default();
    let mut beta = Rgb::WHITE;
    for depth in 0..MAX_SPECULAR_CHAIN {
        if depth > 0 {
            out.specular_rays += 1;
        }
        let Some(hit) = accel.scene().intersect1(&ray) else {
            out.emitted += beta * escaped_radiance(scene, ray.dir, None);
            break;
        };
        let Some((surface, prim)) = accel.resolve(&hit) else { break };
        let sp = scene.surface_point(surface, prim, hit.u, hit.v);
        let wo = -ray.dir;
        let SurfaceId::Object(object) = surface else {
            if let SurfaceId::Light(l) = surface {
                out.emitted += beta * scene.lights[l as usize].geometry.emitted(sp.n, wo);
            }
            break;
        };
        let material = &scene.materials[scene.objects[object as usize].material as usize];
        if !material.is_specular() {
            let uv = Vec2::new(hit.u, hit.v);
            out.hit = Some(DiffuseHit { p: sp.p, n: sp.n, ns: sp.ns, wo, object, triangle: prim, uv, beta });
            break;
        }
        let Some(bs) = material.sample(sp.normals(), wo, rng.next_2d(), rng.next_f32(), Transport::Radiance) else {
            break;
        };
        beta *= bs.weight;
        let side = if sp.n.dot(bs.wi) >= 0.0 { sp.n } else { -sp.n };
        ray = Ray::new(offset_ray_origin(sp.p, side), bs.wi);
    }
    out
}

/// Direct light at a diffuse hit by next-event estimation (one light by power, one shadow
/// ray), times the chain's throughput. Returns the radiance and the shadow ray, if one was
/// traced.
pub fn direct_light(scene: &Scene, accel: &SceneAccel, hit: &DiffuseHit, rng: &mut Rng) -> (Rgb, Option<Ray>) {
    let material = hit.material(scene);
    match sample_next_event(scene, material, hit.p, hit.normals(), hit.wo, rng, false) {
        Some(ne) if !accel.scene().occluded1(&ne.shadow) => (hit.beta * ne.contribution, Some(ne.shadow)),
        Some(ne) => (Rgb::BLACK, Some(ne.shadow)),
        None => (Rgb::BLACK, None),
    }
}
