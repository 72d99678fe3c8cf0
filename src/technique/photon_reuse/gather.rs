//! Rendering a frame from the photon paths: camera rays follow ideal mirror and glass chains to
//! the first diffuse hit, where direct light comes from next-event estimation and indirect light
//! from a density estimate over the stored photons.
//!
//! The density estimate uses photons from the second bounce on (the first hit of a path is
//! direct light, which NEE already counts; light reaching a diffuse surface through a specular
//! chain is counted by photons) with a uniform disc kernel of radius r:
//! L_o(x, ω_o) ≈ Σ_p f_r(ω_o, ω_p) Φ_p / (π r²) over photons within r whose surface faces the
//! same way as the query's side (normals within 60°), so thin walls and corners do not leak.
//! The paper splats photons in screen space on a GPU; on the CPU a gather through a spatial
//! grid (`grid.rs`: cell size 2r, so a query visits at most 8 cells) is the natural
//! equivalent, and it costs work per pixel rather than per photon.
use super::grid::PhotonGrid;
use crate::core::Rng;
use crate::film::PixelAccum;
use crate::scene::{Scene, SceneAccel};
use crate::technique::camera_chain;

/// Ray counts of one render pass.
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderRays {
    pub camera: u64,
    pub specular: u64,
    pub shadow: u64,
}

impl RenderRays {
    pub fn merge(self, o: RenderRays) -> RenderRays {
        RenderRays {
            camera: self.camera + o.camera,
            specular: self.specular + o.specular,
            shadow: self.shadow + o.shadow,
        }
    }
}

/// One sample for each pixel of `chunk` (pixels `first..`), added to the film.
pub fn render_chunk(
    scene: &Scene,
    accel: &SceneAccel,
    grid: &PhotonGrid,
    stream: (u64, u64, u64),
    first: usize,
    chunk: &mut [PixelAccum],
) -> RenderRays {
    let (seed, tick, pass) = stream;
    let mut rays = RenderRays::default();
    for (offset, pixel) in chunk.iter_mut().enumerate() {
        let index = first + offset;
        let mut rng = Rng::for_sample(seed, tick, index as u64, pass);
        let jitter = rng.next_2d();
        let sample = camera_chain::trace(scene, accel, index, jitter, &mut rng);
        rays.camera += 1;
        rays.specular += sample.specular_rays;
        let mut radiance = sample.emitted;
        if let Some(hit) = sample.hit {
            // Diffuse: direct light by NEE, indirect light from the photons.
            let (direct, traced) = camera_chain::direct_light(scene, accel, &hit, &mut rng);
            rays.shadow += u64::from(traced);
            radiance += direct + hit.beta * grid.radiance(hit.material(scene), hit.p, hit.n, hit.wo);
        }
        pixel.add(radiance);
        pixel.count += 1.0;
    }
    rays
}
