//! Next-event estimation shared by the techniques: pick one light by power, sample a point on
//! it, and return the contribution that counts if the shadow ray towards it is unoccluded; and
//! the light a ray finds when it leaves the scene, weighted against next-event estimation.
use crate::core::sampling::power_heuristic;
use crate::core::{offset_ray_origin, Rgb, Rng};
use crate::embree::Ray;
use crate::scene::{Material, Normals, Scene, Transport};
use glam::Vec3;

/// Relative shortening of shadow rays so they stop just before the sampled light point.
pub const SHADOW_EPSILON: f32 = 1e-4;

/// The occlusion ray from `from` to just short of `to` (unit direction, shortened by
/// [`SHADOW_EPSILON`] of the distance); `None` where the two coincide.
pub fn shadow_segment(from: Vec3, to: Vec3) -> Option<Ray> {
    let span = to - from;
    let length = span.length();
    (length > 0.0).then(|| Ray { origin: from, dir: span / length, tnear: 0.0, tfar: length * (1.0 - SHADOW_EPSILON) })
}

/// A light sample waiting for its shadow ray.
#[derive(Clone, Copy, Debug)]
pub struct NextEvent {
    pub shadow: Ray,
    /// `f · L_i · |cos θ_i| / pdf`, times the MIS weight; per unit path throughput.
    pub contribution: Rgb,
    /// The light chosen, its selection probability, and the sampled point and its normal (zero
    /// for point and spot lights), for callers that weigh strategies themselves (`bdpt`).
    pub light: usize,
    pub light_pmf: f32,
    pub light_point: Vec3,
    pub light_normal: Vec3,
}

/// Samples direct light at `p` (with `normals`, outgoing `wo`) on a non-specular
/// material. With `mis_with_bsdf`, area-light samples carry the power-heuristic weight against
/// BSDF sampling (the caller must then also count BSDF-sampled emission hits with the matching
/// weight); without it the estimate stands alone. Consumes three random numbers.
pub fn sample_next_event(
    scene: &Scene,
    material: &Material,
    p: Vec3,
    normals: Normals,
    wo: Vec3,
    rng: &mut Rng,
    mis_with_bsdf: bool,
) -> Option<NextEvent> {
    let n = normals.geometric;
    let select = scene.light_selection.as_ref()?;
    let (li, pmf, _) = select.sample(rng.next_f32());
    let u = rng.next_2d();
    let side = if n.dot(wo) >= 0.0 { n } else { -n };
    let origin = offset_ray_origin(p, side);
    let s = scene.lights[li].geometry.sample_incident(origin, side, u)?;
    let f = material.eval(normals, wo, s.wi, Transport::Radiance);
    if f.is_black() || s.pdf <= 0.0 {
        return None;
    }
    let light_pdf = s.pdf * pmf;
    let weight = if s.delta || !mis_with_bsdf { 1.0 } else { power_heuristic(light_pdf, material.pdf(n, wo, s.wi)) };
    Some(NextEvent {
        shadow: Ray { origin, dir: s.wi, tnear: 0.0, tfar: s.dist * (1.0 - SHADOW_EPSILON) },
        contribution: f * s.li * (s.wi.dot(n).abs() * weight / light_pdf),
        light: li,
        light_pmf: pmf,
        light_point: origin + s.wi * s.dist,
        light_normal: s.normal,
    })
}

/// Radiance from the lights outside the scene along a ray that leaves it in unit direction
/// `dir`. `bsdf` is the solid-angle density with which the BSDF sampled `dir` and the
/// geometric normal on the side of `wo` at the vertex it left, when next-event estimation
/// (with MIS, as [`sample_next_event`] weighs it) also reached these lights; `None` for camera
/// rays and specular bounces, which count the whole radiance.
pub fn escaped_radiance(scene: &Scene, dir: Vec3, bsdf: Option<(f32, Vec3)>) -> Rgb {
    let mut sum = Rgb::BLACK;
    for &l in &scene.infinite_lights {
        let geometry = &scene.lights[l].geometry;
        let le = geometry.escaped(dir);
        if le.is_black() {
            continue;
        }
        let weight = match bsdf {
            None => 1.0,
            Some((pdf, side)) => {
                let pmf = scene.light_selection.as_ref().map_or(0.0, |d| d.pmf(l));
                power_heuristic(pdf, pmf * geometry.pdf_direction(dir, side))
            }
        };
        sum += le * weight;
    }
    sum
}
