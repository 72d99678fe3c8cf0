//! The t = 1 strategies: every non-specular vertex of a light subpath connected to the pinhole
//! and splatted onto the pixel it projects to (Veach 1997, §10.2, "light tracing"; pbrt-v4's
//! `ConnectBDPT` with t = 1).
//!
//! # The estimate
//! With N_L light subpaths in a pass and a box pixel filter, the importance of pixel j is
//! W_j(ω) = 1 / (A_pixel · cos⁴θ) on the directions through it (A_pixel on the plane one unit in
//! front of the pinhole), so a light vertex x with throughput β adds to pixel j
//!
//!   β · f(x, wo, ω) · |cos_x| · W_j · cosθ / (d² · N_L) = β · f · |cos_x| · p_c(ω) / d²,
//!
//! where p_c is the camera's image-wide direction density 1 / (A_image · cos³θ) divided by N_L /
//! pixels, exactly the density the MIS weights use (`vertex.rs::CameraDensity`). A pass's
//! splats are that pass's estimate, so the film averages them over passes.
//!
//! # Light tracing alone
//! With `light_tracing_only`, every splat has weight 1 and the light's own vertex (s = 1) is
//! splatted too (an area light seen directly, Le · |cos| · p_c / (d² · p_origin)), so the splats
//! alone estimate the whole image: an independent check on `bdpt`'s caustics.
use super::vertex::{material, mis_weight, CameraDensity, Vertex, VertexKind};
use crate::core::{offset_ray_origin, Rgb};
use crate::embree::Ray;
use crate::scene::{Scene, SceneAccel, Transport};
use crate::technique::nee::shadow_segment;

/// Occlusion rays per Embree call (its 8-wide packet kernel).
const PACKET: usize = 8;

/// A splat waiting for its visibility ray.
struct Candidate {
    pixel: u32,
    value: Rgb,
    ray: Ray,
}

/// What splatting one queue's light subpaths gave: (pixel index, value) for the film, and the
/// visibility rays traced.
#[derive(Default)]
pub struct Splats {
    pub splats: Vec<(u32, Rgb)>,
    pub rays: u64,
}

/// Connects every vertex of `batch` that can be connected to the camera, traces the
/// visibility rays in packets, and returns the visible splats. `weighted`: MIS weights against
/// the other strategies (full `bdpt`); otherwise light tracing alone, light vertices included.
pub fn splat_light_subpaths(
    scene: &Scene,
    accel: &SceneAccel,
    camera: &CameraDensity,
    batch: &[Vec<Vertex>],
    weighted: bool,
) -> Splats {
    let eye = [camera.vertex()];
    let mut candidates = Vec::new();
    for path in batch {
        let first = if weighted { 2 } else { 1 };
        for s in first..=path.len() {
            let weight = if weighted { mis_weight(scene, camera, &eye, &path[..s]) } else { 1.0 };
            if let Some(c) = connect(scene, camera, &path[..s]) {
                candidates.push(Candidate { value: c.value * weight, ..c });
            }
        }
    }
    trace_visibility(accel, candidates)
}

/// The unweighted splat of the last vertex of `subpath` towards the camera, with the ray that
/// must be clear for it to count; `None` if it cannot reach the image.
fn connect(scene: &Scene, camera: &CameraDensity, subpath: &[Vertex]) -> Option<Candidate> {
    let v = subpath.last()?;
    if v.delta {
        return None;
    }
    let (x, y, _) = camera.camera.raster(v.p)?;
    let to_camera = camera.camera.position - v.p;
    let dist2 = to_camera.length_squared();
    let dir = to_camera / dist2.sqrt();
    let cos = v.n.dot(dir).abs();
    let through = match v.kind {
        VertexKind::Surface(_) => v.beta * material(scene, v)?.eval(v.normals(), v.wo, dir, Transport::Importance),
        VertexKind::Light(l) => {
            let geometry = &scene.lights[l as usize].geometry;
            if geometry.is_delta() || v.pdf_fwd <= 0.0 {
                return None;
            }
            geometry.emitted(v.n, dir) / v.pdf_fwd
        }
        VertexKind::Camera => return None,
    };
    let value = through * (cos * camera.pdf_dir(-dir) / dist2);
    if value.is_black() || !value.is_finite() {
        return None;
    }
    let from = offset_ray_origin(v.p, if v.n.dot(dir) >= 0.0 { v.n } else { -v.n });
    let ray = shadow_segment(from, camera.camera.position)?;
    let pixel = y as u32 * camera.camera.width + x as u32;
    Some(Candidate { pixel, value, ray })
}

/// Traces the candidates' visibility rays, `PACKET` at a time, and keeps the visible ones.
fn trace_visibility(accel: &SceneAccel, candidates: Vec<Candidate>) -> Splats {
    let mut out = Splats { splats: Vec::with_capacity(candidates.len()), rays: candidates.len() as u64 };
    let mut occluded = [false; PACKET];
    for group in candidates.chunks(PACKET) {
        let n = group.len();
        let mut rays = [group[0].ray; PACKET];
        for (r, c) in rays.iter_mut().zip(group) {
            *r = c.ray;
        }
        accel.scene().occluded_lanes(&rays[..n], &[true; PACKET][..n], &mut occluded[..n]);
        out.splats.extend(group.iter().zip(&occluded).filter(|(_, &o)| !o).map(|(c, _)| (c.pixel, c.value)));
    }
    out
}
