//! Auxiliary images for the denoiser: per pixel, the running mean of the first non-specular
//! hit's albedo (times the tint of the mirror or glass chain in front of it) and of its normal.
//!
//! Units: albedo is a reflectance in [0, 1]; normals are world-space, facing the camera ray,
//! averaged over a pixel's samples (so shorter than 1 on edges), and zero where nothing was hit.
//!
//! These images depend on the camera, the geometry and the materials, never on the lights, so
//! they are kept across ticks and refined until [`AuxFilm::TARGET_PASSES`] samples per pixel;
//! the engine restarts them only when the camera, an object or a material changes.
use crate::core::Rgb;
use glam::Vec3;

/// Per-pixel sums of albedo and normal samples.
#[derive(Clone, Debug)]
pub struct AuxFilm {
    pub width: u32,
    pub height: u32,
    albedo: Vec<[f32; 3]>,
    normal: Vec<[f32; 3]>,
    /// Samples accumulated in every pixel since the last reset.
    pub passes: u32,
}

/// The resolved auxiliary images, planar RGB f32 (three floats per pixel, row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct AuxImages {
    pub albedo: Vec<f32>,
    pub normal: Vec<f32>,
}

/// One sample of one pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AuxSample {
    pub albedo: Rgb,
    pub normal: Vec3,
}

impl AuxFilm {
    /// Samples per pixel after which the images are left as they are: enough to average the
    /// pixel footprint's edges; more would spend rays on images that no longer change.
    pub const TARGET_PASSES: u32 = 16;

    pub fn new(width: u32, height: u32) -> AuxFilm {
        let n = (width * height) as usize;
        AuxFilm { width, height, albedo: vec![[0.0; 3]; n], normal: vec![[0.0; 3]; n], passes: 0 }
    }

    pub fn reset(&mut self) {
        self.albedo.iter_mut().for_each(|a| *a = [0.0; 3]);
        self.normal.iter_mut().for_each(|n| *n = [0.0; 3]);
        self.passes = 0;
    }

    pub fn converged(&self) -> bool {
        self.passes >= Self::TARGET_PASSES
    }

    /// Adds one pass: `samples[i]` is pixel i's sample.
    pub fn add_pass(&mut self, samples: &[AuxSample]) {
        for ((a, n), s) in self.albedo.iter_mut().zip(self.normal.iter_mut()).zip(samples) {
            for (sum, v) in a.iter_mut().zip(s.albedo.to_array()) {
                *sum += v;
            }
            for (sum, v) in n.iter_mut().zip(s.normal.to_array()) {
                *sum += v;
            }
        }
        self.passes += 1;
    }

    /// The mean images (zero before the first pass).
    pub fn resolve(&self) -> AuxImages {
        let inv = if self.passes > 0 { 1.0 / self.passes as f32 } else { 0.0 };
        let mean = |v: &[[f32; 3]]| v.iter().flat_map(|p| p.map(|c| c * inv)).collect();
        AuxImages { albedo: mean(&self.albedo), normal: mean(&self.normal) }
    }

    /// The mean albedo and normal of pixel (x, y).
    pub fn pixel(&self, x: u32, y: u32) -> AuxSample {
        let i = (y * self.width + x) as usize;
        let inv = if self.passes > 0 { 1.0 / self.passes as f32 } else { 0.0 };
        let [r, g, b] = self.albedo[i].map(|c| c * inv);
        AuxSample { albedo: Rgb::new(r, g, b), normal: Vec3::from(self.normal[i]) * inv }
    }
}
