//! `particle_gi`'s configuration (validated as the service receives it) and its per-tick
//! figures, laid out like Chang et al.'s Tables 1 and 2. Lengths are fractions of the particle
//! spacing √ΔA unless stated; times in milliseconds; memory in bytes.
use super::{grid, lighting, links, particles, radiance};
use crate::scene::Scene;
use crate::technique::budget::{product_sum, MemoryEstimate};
use crate::technique::registry::{Parameter, ParameterKind, TechniqueDescription};
use crate::technique::TechniqueError;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ParticleGiConfig {
    /// Area particles over all diffuse surfaces (both sides counted), unless `particle_area`;
    /// `None`: [`PARTICLES_PER_PIXEL`] per pixel of the camera, at least [`MIN_PARTICLES`].
    pub particles: Option<u32>,
    /// ΔA in m² per particle instead of a count (the count follows from the diffuse area).
    pub particle_area: Option<f32>,
    /// n_s of the scattering links (n_s × n_s per particle).
    pub scatter_links: u32,
    /// n_s of the gathering links.
    pub gather_links: u32,
    /// n_b, the single-link bounces after the first; `None` picks it from the scene's mean
    /// reflectance ρ_S: the smallest n_b with ρ_S^(n_b + 2) below `admitted_truncation`.
    pub bounces: Option<u32>,
    pub admitted_truncation: f32,
    /// Radius of the estimation lists, in particle spacings.
    pub estimation_radius: f32,
    /// Least cosine between an estimation list's particles and its radiance particle.
    pub estimation_cosine: f32,
    /// Longest subtriangle edge of the radiance-particle tessellation, in particle spacings.
    pub subtriangle_edge: f32,
    /// Samples per area light per particle in the emission step.
    pub emission_samples: u32,
    /// Update links incrementally when objects move (`false`: rebuild every link).
    pub incremental: bool,
    /// Adaptive supersampling: extra samples for pixels whose luminance differs from a
    /// neighbour's by more than `supersample_contrast` (relative); 0 turns it off.
    pub supersample: u32,
    pub supersample_contrast: f32,
    /// Seed of the particles, link directions and scattering walks (fixed across ticks).
    pub seed: u64,
}

impl Default for ParticleGiConfig {
    fn default() -> ParticleGiConfig {
        ParticleGiConfig {
            particles: None,
            particle_area: None,
            scatter_links: 4,
            gather_links: 16,
            bounces: None,
            admitted_truncation: 0.01,
            estimation_radius: 2.0,
            estimation_cosine: 0.9,
            subtriangle_edge: 1.5,
            emission_samples: 4,
            incremental: true,
            supersample: 0,
            supersample_contrast: 0.1,
            seed: 1,
        }
    }
}

const RGB_BYTES: u64 = std::mem::size_of::<crate::core::Rgb>() as u64;

/// The default particle density: 0.15 particles per pixel (9 830 at 256²). Measured on the
/// Cornell box at 256² over 16 still ticks (`relume bench error`): relMSE 0.0048 at 5 000,
/// 0.0046 at 10 000, 0.0045 at 20 000 and at 50 000, so 10 000 is within 5% of 50 000; the
/// paper used 0.05–0.2 per pixel.
pub const PARTICLES_PER_PIXEL: f64 = 0.15;
/// The default's floor, for small images.
pub const MIN_PARTICLES: u32 = 2_000;

/// Most area particles a scene may hold.
pub const MAX_PARTICLES: u32 = 4_000_000;

impl ParticleGiConfig {
    /// The particle count on `scene`: `particles`, or the per-pixel default.
    pub fn particle_count(&self, scene: &Scene) -> u32 {
        self.particles.unwrap_or_else(|| {
            let pixels = f64::from(scene.camera.width) * f64::from(scene.camera.height);
            ((PARTICLES_PER_PIXEL * pixels).round() as u32).clamp(MIN_PARTICLES, MAX_PARTICLES)
        })
    }

    /// Resident memory on `scene` (`budget.rs`): the particles `particles` or `particle_area` gives
    /// there with their grids (two per object), their area estimation's temporary samples, both link
    /// sets (an end and a distance per link, plus what tracing them holds while building), the field's
    /// direct flux and radiance per lighting share, and the estimate cache (about one radiance particle
    /// per area particle at the default subtriangle edge, both sides, one estimate per share, two flags
    /// and a list-index entry each). Refuses more than [`MAX_PARTICLES`] particles, which
    /// `particle_area` alone cannot bound.
    pub fn resident_estimate(&self, scene: &Scene) -> Result<MemoryEstimate, TechniqueError> {
        let field = if self.particle_area.is_some() { "particle_area" } else { "particles" };
        let planned = particles::planned_particles(scene, self.particle_count(scene), self.particle_area);
        if planned > f64::from(MAX_PARTICLES) {
            return Err(TechniqueError::TooLarge {
                field: field.into(),
                message: format!("gives {planned:.0} particles on this scene, above the limit of {MAX_PARTICLES}"),
            });
        }
        let particles = planned as u64;
        let links_each = u64::from(self.scatter_links.pow(2) + self.gather_links.pow(2));
        let shares = lighting::share_count(scene.lights.len()) as u64;
        product_sum(
            field,
            &[
                (particles, particles::BYTES_PER_PARTICLE + grid::BYTES_PER_PARTICLE),
                (2 * scene.objects.len() as u64, grid::BYTES_PER_GRID),
                (particles / 2, particles::SAMPLING_BYTES_PER_POINT),
                (particles * links_each, links::BYTES_PER_LINK + links::TRACING_BYTES_PER_LINK),
                (particles * shares, 2 * RGB_BYTES),
                (2 * particles, shares * RGB_BYTES + 2 + radiance::INDEX_BYTES_PER_KEY),
            ],
        )
    }

    pub fn validate(&self) -> Result<(), TechniqueError> {
        let bad = |field: &str, message: &str| {
            Err(TechniqueError::InvalidConfig { field: field.into(), message: message.into() })
        };
        if self.particles.is_some_and(|p| !(2..=MAX_PARTICLES).contains(&p)) {
            return bad("particles", &format!("must lie in 2..={MAX_PARTICLES}"));
        }
        if let Some(a) = self.particle_area {
            if !(a.is_finite() && a > 0.0) {
                return bad("particle_area", "must be a positive area in m²");
            }
        }
        if !(1..=8).contains(&self.scatter_links) {
            return bad("scatter_links", "must lie in 1..=8");
        }
        if !(1..=32).contains(&self.gather_links) {
            return bad("gather_links", "must lie in 1..=32");
        }
        if self.bounces.is_some_and(|b| b > 64) {
            return bad("bounces", "must be at most 64");
        }
        if !(self.admitted_truncation > 0.0 && self.admitted_truncation < 1.0) {
            return bad("admitted_truncation", "must lie in (0, 1)");
        }
        if !(self.estimation_radius.is_finite() && self.estimation_radius > 0.0 && self.estimation_radius <= 64.0) {
            return bad("estimation_radius", "must lie in (0, 64] particle spacings");
        }
        if !(self.estimation_cosine >= -1.0 && self.estimation_cosine <= 1.0) {
            return bad("estimation_cosine", "must lie in [-1, 1]");
        }
        if !(self.subtriangle_edge.is_finite() && self.subtriangle_edge >= 0.1 && self.subtriangle_edge <= 1000.0) {
            return bad("subtriangle_edge", "must lie in [0.1, 1000] particle spacings");
        }
        if !(1..=64).contains(&self.emission_samples) {
            return bad("emission_samples", "must lie in 1..=64");
        }
        if self.supersample > 64 {
            return bad("supersample", "must be at most 64");
        }
        if !(self.supersample_contrast.is_finite() && self.supersample_contrast > 0.0) {
            return bad("supersample_contrast", "must be positive");
        }
        Ok(())
    }
}

/// Per-tick figures of `particle_gi`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleStats {
    pub area_particles: u64,
    /// ΔA (m²) and the particle spacing √ΔA (m).
    pub particle_area: f64,
    pub radiance_particles: u64,
    /// n_b used this tick.
    pub bounces: u32,
    /// Links in both sets, and those traced this tick (all of them when built, the ones that
    /// may have changed when updated incrementally), with the box tests that chose them.
    pub links_total: u64,
    /// Of `links_total`, the scattering links (built for the particles the walks reach).
    pub scattering_links: u64,
    pub links_traced: u64,
    /// Of `links_traced`, the links built lazily (`links.rs`): gathering links of particles
    /// gathered for the first time, scattering links of particles walks reach for the first time.
    pub links_built_lazily: u64,
    pub link_box_tests: u64,
    /// Radiance particles estimated this tick (those a camera sample needed with no cached
    /// estimate), estimation lists built this tick, and lists and estimates cached.
    pub radiance_particles_estimated: u64,
    pub lists_built: u64,
    pub lists_cached: u64,
    pub estimates_cached: u64,
    /// Area particles gathered (those in the needed lists).
    pub area_particles_gathered: u64,
    /// Particles lit directly by the lights whose share was recomputed this tick, and their
    /// scattering deposits (0 when the lighting stage did not run).
    pub particles_lit: u64,
    pub scatter_deposits: u64,
    /// Objects whose change of scale rescaled their particles in place (the layout held).
    pub objects_rescaled: u64,
    /// Lights whose intensity edit was applied as a scale of their share (no rays, no walks).
    pub lights_rescaled: u64,
    pub supersampled_pixels: u64,
    pub camera_rays: u64,
    pub specular_rays: u64,
    pub shadow_rays: u64,
    /// Visibility rays of the emission step.
    pub emission_rays: u64,
    pub geometry_ms: f64,
    /// Camera rays, specular chains and direct light: a Whitted frame's work.
    pub trace_ms: f64,
    pub emission_ms: f64,
    pub scattering_ms: f64,
    pub preliminary_ms: f64,
    pub gathering_ms: f64,
    pub estimation_ms: f64,
    pub final_ms: f64,
    /// `particles` (with the tessellation), `scatter_links`, `gather_links`, `lists`, `grid`,
    /// `estimates`, `field`.
    pub memory: crate::technique::ResidentMemory,
}

impl ParticleStats {
    /// Adds a lighting stage's work.
    pub(super) fn record(&mut self, work: lighting::LightingWork) {
        self.emission_rays += work.emission_rays;
        self.particles_lit += work.lit;
        self.scatter_deposits += work.deposits;
        self.emission_ms += work.emission_ms;
        self.scattering_ms += work.scattering_ms;
    }
}

/// The registry's description (`technique/registry.rs`).
pub const DESCRIPTION: TechniqueDescription = TechniqueDescription {
    id: "particle_gi",
    summary: "Area particles, scattering and gathering links, and radiance particles (Chang et al.)",
    shorthand: None,
    parameters: &[
        Parameter {
            name: "particles",
            kind: ParameterKind::Integer { min: 100, max: 1_000_000 },
            help: "area particles over the diffuse surfaces",
        },
        Parameter {
            name: "gather_links",
            kind: ParameterKind::Integer { min: 1, max: 32 },
            help: "n_s of the gathering links",
        },
    ],
    test_specs: &["particle_gi:particles=4000:gather_links=8"],
};
