//! glTF materials as relume materials, and emission as area-light radiance.
//!
//! | glTF | relume |
//! |---|---|
//! | `KHR_materials_transmission` (factor > 0), `KHR_materials_ior` (default 1.5) | `glass` |
//! | `metallicFactor` 1 and `roughnessFactor` ≤ 0.05 | `mirror`, reflectance = `baseColorFactor` |
//! | anything else | `diffuse`, reflectance = `baseColorFactor` |
//! | `emissiveFactor` × `KHR_materials_emissive_strength` > 0 | the primitive is a `mesh` light |
//!
//! Emission maps one to one: radiance in W/(sr·m²) = `emissiveFactor` × strength. What the
//! table cannot express (textures, partial metalness, alpha, partial transmission) is read as
//! its factor with a warning.
use super::warnings::Warnings;
use crate::core::Rgb;
use crate::scene::model::Material;

/// At or below this roughness a fully metallic material is read as an ideal mirror.
pub const MIRROR_ROUGHNESS: f32 = 0.05;
/// The glTF default index of refraction.
const DEFAULT_IOR: f32 = 1.5;
/// What a primitive without a material reflects (glTF's default is a white rough metal,
/// which relume cannot render; a mid grey is the conventional stand-in).
pub const DEFAULT_REFLECTANCE: f32 = 0.8;

/// `materials[2] ('brick')`.
pub fn material_label(m: &gltf::Material) -> String {
    match (m.index(), m.name()) {
        (Some(i), Some(name)) => format!("materials[{i}] ('{name}')"),
        (Some(i), None) => format!("materials[{i}]"),
        (None, _) => "the default material".into(),
    }
}

/// A glTF material as relume's, warning about whatever it leaves out.
pub fn convert(m: &gltf::Material, warnings: &mut Warnings) -> Material {
    let label = material_label(m);
    if m.index().is_none() {
        warnings
            .add(format!("primitives without a material are diffuse with reflectance {DEFAULT_REFLECTANCE}"), &label);
        return Material::Diffuse { reflectance: Rgb::splat(DEFAULT_REFLECTANCE) };
    }
    warn_unsupported(m, &label, warnings);
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, _] = pbr.base_color_factor();
    let base = Rgb::new(r.clamp(0.0, 1.0), g.clamp(0.0, 1.0), b.clamp(0.0, 1.0));
    if let Some(t) = m.transmission().filter(|t| t.transmission_factor() > 0.0) {
        if t.transmission_factor() < 1.0 {
            warnings.add("partial transmission is read as full transmission (glass)", &label);
        }
        return Material::Glass { ior: m.ior().unwrap_or(DEFAULT_IOR) };
    }
    let (metallic, roughness) = (pbr.metallic_factor(), pbr.roughness_factor());
    if metallic >= 1.0 && roughness <= MIRROR_ROUGHNESS {
        return Material::Mirror { reflectance: base };
    }
    if metallic > 0.0 {
        warnings.add(
            format!("metallic materials rougher than {MIRROR_ROUGHNESS}, or partly metallic, are read as diffuse"),
            &label,
        );
    }
    Material::Diffuse { reflectance: base }
}

/// Radiance in W/(sr·m²) when the material emits (`emissiveFactor` × emissive strength).
pub fn emission(m: &gltf::Material) -> Option<Rgb> {
    let [r, g, b] = m.emissive_factor();
    let e = Rgb::new(r, g, b) * m.emissive_strength().unwrap_or(1.0);
    (e.to_array().iter().all(|v| v.is_finite() && *v >= 0.0) && e.max_component() > 0.0).then_some(e)
}

fn warn_unsupported(m: &gltf::Material, label: &str, warnings: &mut Warnings) {
    let pbr = m.pbr_metallic_roughness();
    if pbr.base_color_texture().is_some() {
        warnings.add("base colour textures are not read; baseColorFactor is used", label);
    }
    let other_textures = [
        pbr.metallic_roughness_texture().is_some(),
        m.normal_texture().is_some(),
        m.occlusion_texture().is_some(),
        m.emissive_texture().is_some(),
    ];
    if other_textures.iter().any(|&t| t) {
        warnings.add("metallic-roughness, normal, occlusion and emissive textures are not read", label);
    }
    if m.alpha_mode() != gltf::material::AlphaMode::Opaque {
        warnings.add("alpha modes MASK and BLEND are read as OPAQUE", label);
    }
    let [r, g, b, _] = pbr.base_color_factor();
    if [r, g, b].iter().any(|c| !(0.0..=1.0).contains(c)) {
        warnings.add("baseColorFactor components outside [0, 1] are clamped", label);
    }
}
