//! BSDFs of the three materials, evaluated and sampled in world space around the geometric
//! normal. Directions `wo` and `wi` point away from the surface.
//!
//! Diffuse and mirror are two-sided (the normal is flipped to the side of `wo`); glass uses the
//! normal's side to tell entering from leaving, so glass meshes must wind outward. Refraction
//! scales radiance by 1/η² (Veach 1997, §5.2; pbrt-v4 `DielectricBxDF`).
use super::model::Material;
use crate::core::{sampling, Rgb, ShadingFrame};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// A sampled incident direction with its weight `f·|cos θi| / pdf`.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub wi: Vec3,
    pub weight: Rgb,
    /// Solid-angle density; meaningless (set to 0) for specular samples.
    pub pdf: f32,
    pub specular: bool,
    /// Relative index of refraction crossed (1 for reflection), for Russian roulette.
    pub eta: f32,
}

/// Unpolarised Fresnel reflectance of a smooth dielectric; `eta` = η_transmitted / η_incident.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    2.0 * wo.dot(n) * n - wo
}

impl Material {
    /// True for materials with only delta lobes, which next-event estimation cannot connect to.
    pub fn is_specular(&self) -> bool {
        !matches!(self, Material::Diffuse { .. })
    }

    /// Mean hemispherical reflectance, used for the scene's ρ_S (glass counts as 1: it loses no energy).
    pub fn mean_reflectance(&self) -> f32 {
        match self {
            Material::Diffuse { reflectance } | Material::Mirror { reflectance } => reflectance.mean(),
            Material::Glass { .. } => 1.0,
        }
    }

    /// Diffuse reflectance, or black for specular materials.
    pub fn diffuse_reflectance(&self) -> Rgb {
        match self {
            Material::Diffuse { reflectance } => *reflectance,
            _ => Rgb::BLACK,
        }
    }

    /// BSDF value `f(wo, wi)` (without the cosine) for the non-delta part.
    pub fn eval(&self, n: Vec3, wo: Vec3, wi: Vec3) -> Rgb {
        match self {
            Material::Diffuse { reflectance } if n.dot(wo) * n.dot(wi) > 0.0 => *reflectance * FRAC_1_PI,
            _ => Rgb::BLACK,
        }
    }

    /// Solid-angle density with which [`Material::sample`] picks `wi` (0 for delta lobes).
    pub fn pdf(&self, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Material::Diffuse { .. } if n.dot(wo) * n.dot(wi) > 0.0 => sampling::cosine_hemisphere_pdf(n.dot(wi).abs()),
            _ => 0.0,
        }
    }

    /// The weight `f·|cos|/pdf` with which [`Material::sample`] returns `wi` (for specular
    /// lobes, the lobe's weight with the lobe choice cancelled): the reflectance for diffuse and
    /// mirror, 1 for glass reflection and 1/η² for glass transmission. Black if `wi` lies on a
    /// side the material cannot send light to.
    pub fn sampled_weight(&self, n: Vec3, wo: Vec3, wi: Vec3) -> Rgb {
        let same_side = n.dot(wo) * n.dot(wi) > 0.0;
        match self {
            Material::Diffuse { reflectance } | Material::Mirror { reflectance } if same_side => *reflectance,
            Material::Glass { .. } if same_side => Rgb::WHITE,
            Material::Glass { ior } => {
                let eta = if n.dot(wo) > 0.0 { *ior } else { 1.0 / *ior };
                Rgb::splat(1.0 / (eta * eta))
            }
            _ => Rgb::BLACK,
        }
    }

    /// Samples an incident direction. `u` drives the direction, `uc` the lobe choice.
    pub fn sample(&self, n: Vec3, wo: Vec3, u: Vec2, uc: f32) -> Option<BsdfSample> {
        let cos_o = n.dot(wo);
        if cos_o == 0.0 {
            return None;
        }
        let nf = if cos_o > 0.0 { n } else { -n };
        match self {
            Material::Diffuse { reflectance } => {
                let local = sampling::cosine_hemisphere(u);
                if local.z <= 0.0 {
                    return None;
                }
                let wi = ShadingFrame::from_normal(nf).to_world(local);
                Some(BsdfSample {
                    wi,
                    weight: *reflectance,
                    pdf: sampling::cosine_hemisphere_pdf(local.z),
                    specular: false,
                    eta: 1.0,
                })
            }
            Material::Mirror { reflectance } => {
                Some(BsdfSample { wi: reflect(wo, nf), weight: *reflectance, pdf: 0.0, specular: true, eta: 1.0 })
            }
            Material::Glass { ior } => {
                // Entering when wo is on the outside (the side the outward normal points to).
                let eta = if cos_o > 0.0 { *ior } else { 1.0 / *ior };
                let cos_i = cos_o.abs();
                let f = fresnel_dielectric(cos_i, eta);
                if uc < f {
                    return Some(BsdfSample {
                        wi: reflect(wo, nf),
                        weight: Rgb::WHITE,
                        pdf: 0.0,
                        specular: true,
                        eta: 1.0,
                    });
                }
                let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
                let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
                let wi = (-wo / eta + (cos_i / eta - cos_t) * nf).normalize();
                Some(BsdfSample { wi, weight: Rgb::splat(1.0 / (eta * eta)), pdf: 0.0, specular: true, eta })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_limits() {
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-3);
        assert_eq!(fresnel_dielectric(0.1, 1.0 / 1.5), 1.0);
        assert!((fresnel_dielectric(0.0, 1.5) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn glass_refraction_obeys_snell() {
        let glass = Material::Glass { ior: 1.5 };
        let n = Vec3::Z;
        let wo = Vec3::new(0.6, 0.0, 0.8);
        // uc = 0.999 forces the transmission lobe (F ≈ 0.04 here).
        let s = glass.sample(n, wo, Vec2::ZERO, 0.999).unwrap();
        let sin_o = 0.6f32;
        let sin_t = (s.wi.x * s.wi.x + s.wi.y * s.wi.y).sqrt();
        assert!(s.wi.z < 0.0);
        assert!((sin_o - 1.5 * sin_t).abs() < 1e-5);
        assert!((s.weight.r - 1.0 / 2.25).abs() < 1e-6);
    }

    #[test]
    fn diffuse_eval_and_pdf_agree_with_sampling() {
        let m = Material::Diffuse { reflectance: Rgb::splat(0.5) };
        let n = Vec3::new(0.0, 1.0, 0.0);
        let wo = Vec3::new(0.3, -0.9, 0.1).normalize();
        let s = m.sample(n, wo, Vec2::new(0.3, 0.7), 0.0).unwrap();
        assert!(s.wi.dot(n) < 0.0, "sampled on the side of wo");
        let f = m.eval(n, wo, s.wi);
        let expect = f * s.wi.dot(n).abs() / m.pdf(n, wo, s.wi);
        assert!((expect.r - s.weight.r).abs() < 1e-5);
    }
}
