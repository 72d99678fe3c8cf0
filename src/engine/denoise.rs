//! The engine's denoise stage (docs/architecture.md, tick step 7): after resolve, the accumulated
//! image goes through OIDN ([`Denoiser`]), guided by auxiliary images the stage traces itself.
//! It belongs to no technique, so every technique gets it, and their raw images are untouched.
//!
//! The auxiliary pass follows each pixel's camera ray through mirror and glass chains to the
//! first diffuse surface (the same chain the cached techniques shade,
//! [`camera_chain::trace`]) and records that surface's reflectance times the chain's tint, and
//! its camera-facing normal; a light seen directly records white. One jittered sample per pixel
//! is added per tick until [`AuxFilm::TARGET_PASSES`], then the stage traces nothing more until
//! the camera, an object or a material changes: in a still scene it costs only the filter.
use crate::core::rng::mix64;
use crate::core::{Rgb, Rng};
use crate::film::{AuxFilm, AuxSample, DenoiseError, DenoiseSettings, Denoiser, FilmVersion, LinearImage};
use crate::scene::edits::SceneDelta;
use crate::scene::{Scene, SceneAccel};
use crate::technique::camera_chain;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Keys the auxiliary pass's random streams apart from every technique's.
const AUX_STREAM: u64 = 0xA0C5_11A2_D1E5_0153;

/// The denoiser, its auxiliary images, and what the stage did this tick.
pub struct DenoiseStage {
    denoiser: Denoiser,
    aux: AuxFilm,
    /// The denoiser holds the current auxiliary images (none added or reset since it got them).
    aux_sent: bool,
    /// The last tick's output and the version of the film it came from.
    last: Option<(FilmVersion, Arc<LinearImage>)>,
}

/// What one tick's denoise stage did.
#[derive(Clone, Copy, Debug, Default)]
pub struct AuxWork {
    /// Camera and specular-chain rays of the auxiliary pass (0 once the images are converged).
    pub rays: u64,
    /// Nothing was traced or denoised: the film and the auxiliary images were as they were at
    /// the last tick, so its output stands.
    pub reused: bool,
}

impl DenoiseStage {
    pub fn new(settings: DenoiseSettings, width: u32, height: u32) -> Result<DenoiseStage, DenoiseError> {
        Ok(DenoiseStage {
            denoiser: Denoiser::new(settings, width, height)?,
            aux: AuxFilm::new(width, height),
            aux_sent: false,
            last: None,
        })
    }

    pub fn settings(&self) -> DenoiseSettings {
        self.denoiser.settings()
    }

    pub fn aux(&self) -> &AuxFilm {
        &self.aux
    }

    /// Restarts the auxiliary images when what they show changed: the camera, an object's or
    /// light shape's placement, or a material. A light's emission does not change them.
    pub fn update(&mut self, delta: &SceneDelta) {
        if delta.camera || !delta.moved.is_empty() || !delta.materials.is_empty() {
            self.aux.reset();
            self.aux_sent = false;
        }
    }

    /// Refines the auxiliary images by up to `passes` samples per pixel (if asked for and not
    /// yet converged) and denoises `image`. A tick passes 1; a still rendered once passes
    /// [`AuxFilm::TARGET_PASSES`], as no later tick would refine them.
    pub fn run(
        &mut self,
        scene: &Scene,
        accel: &SceneAccel,
        seed: u64,
        image: &LinearImage,
        passes: u32,
    ) -> Result<(LinearImage, AuxWork), DenoiseError> {
        let mut work = AuxWork::default();
        for _ in 0..passes {
            if !self.settings().aux || self.aux.converged() {
                break;
            }
            work.rays += self.trace_pass(scene, accel, seed);
        }
        // Resolve and send the auxiliary images only when they changed.
        let aux = (self.settings().aux && !self.aux_sent).then(|| self.aux.resolve());
        let denoised = self.denoiser.denoise(image, aux)?;
        self.aux_sent = true;
        Ok((denoised, work))
    }

    /// A tick's denoise: [`DenoiseStage::run`] with one pass, unless the film is at the last
    /// tick's `version` and the auxiliary images are done and sent; then that tick's output.
    pub fn tick(
        &mut self,
        scene: &Scene,
        accel: &SceneAccel,
        seed: u64,
        image: &LinearImage,
        version: FilmVersion,
    ) -> Result<(Arc<LinearImage>, AuxWork), DenoiseError> {
        let aux_done = self.aux_sent && (!self.settings().aux || self.aux.converged());
        if let Some((_, output)) = self.last.as_ref().filter(|(v, _)| aux_done && *v == version) {
            return Ok((Arc::clone(output), AuxWork { rays: 0, reused: true }));
        }
        let (output, work) = self.run(scene, accel, seed, image, 1)?;
        let output = Arc::new(output);
        self.last = Some((version, Arc::clone(&output)));
        Ok((output, work))
    }

    /// One jittered auxiliary sample per pixel; returns the rays traced.
    fn trace_pass(&mut self, scene: &Scene, accel: &SceneAccel, seed: u64) -> u64 {
        let pass = self.aux.passes as u64;
        let pixels = (self.aux.width * self.aux.height) as usize;
        let traced: Vec<(AuxSample, u64)> = (0..pixels)
            .into_par_iter()
            .map(|i| {
                let mut rng = Rng::for_sample(mix64(seed ^ AUX_STREAM), 0, i as u64, pass);
                let jitter = rng.next_2d();
                let s = camera_chain::trace(scene, accel, i, jitter, &mut rng);
                let sample = match &s.hit {
                    Some(hit) => AuxSample {
                        albedo: hit.beta * hit.material(scene).diffuse_reflectance(),
                        normal: hit.shading_facing(),
                    },
                    None if s.emitted != Rgb::BLACK => AuxSample { albedo: Rgb::WHITE, normal: Vec3::ZERO },
                    None => AuxSample::default(),
                };
                (sample, 1 + s.specular_rays)
            })
            .collect();
        let rays = traced.iter().map(|t| t.1).sum();
        let samples: Vec<AuxSample> = traced.into_iter().map(|t| t.0).collect();
        self.aux.add_pass(&samples);
        self.aux_sent = false;
        rays
    }
}
