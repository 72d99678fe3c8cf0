//! One camera sample of a pixel, shaded from the photon paths and kept (`pixels.rs`): camera
//! rays follow ideal mirror and glass chains to the first diffuse hit, where direct light comes
//! from next-event estimation and indirect light from a density estimate over the stored
//! photons.
//!
//! The density estimate uses photons from the second bounce on (the first hit of a path is
//! direct light, which NEE already counts; light reaching a diffuse surface through a specular
//! chain is counted by photons) with a uniform disc kernel of radius r:
//! L_o(x, ω_o) ≈ Σ_p f_r(ω_o, ω_p) Φ_p / (π r²) over photons within r whose surface faces the
//! same way as the query's side (normals within 60°), so thin walls and corners do not leak.
//! The sum is kept apart from its 1/(π r²) so that photons can later be splatted into it, one
//! term at a time: the estimate is linear in the photons.
//! The paper splats photons in screen space on a GPU; on the CPU a gather through a spatial
//! grid (`grid.rs`: cells r wide, so a query visits at most 27) is the natural
//! equivalent for a whole frame, and a splat into the kept pixels for a change.
use super::grid::PhotonGrid;
use crate::core::{Rgb, Rng};
use crate::scene::{Scene, SceneAccel};
use crate::technique::camera_chain::{self, DiffuseHit};
use glam::Vec2;

/// Ray counts of render work.
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

/// A pixel's kept camera sample: where it landed and what it has gathered there.
#[derive(Clone, Copy, Debug, Default)]
pub struct PixelSample {
    /// The point in the pixel, in [0, 1)².
    pub jitter: Vec2,
    /// Emission met along the camera chain.
    pub emitted: Rgb,
    pub hit: Option<DiffuseHit>,
    /// Distance from the camera to the diffuse hit (∞ if none was reached directly).
    pub first_t: f32,
    /// The camera ray met a specular surface first.
    pub chain: bool,
    /// Σ of the NEE estimates taken at `hit` (chain throughput included), and their number.
    pub direct: [f32; 3],
    pub direct_n: u32,
    /// Σ of the photon terms at `hit` (see the module doc), without the chain throughput.
    pub indirect: [f64; 3],
}

impl PixelSample {
    /// The pixel's estimate: emission + mean direct + throughput × Σ terms / (π r²).
    pub fn value(&self, kernel_area: f64) -> Rgb {
        let mut v = self.emitted;
        if let Some(hit) = &self.hit {
            let n = self.direct_n.max(1) as f32;
            let d = Rgb::new(self.direct[0] / n, self.direct[1] / n, self.direct[2] / n);
            let i = self.indirect;
            let indirect =
                Rgb::new((i[0] / kernel_area) as f32, (i[1] / kernel_area) as f32, (i[2] / kernel_area) as f32);
            v += d + hit.beta * indirect;
        }
        v
    }

    /// Adds one NEE estimate at the hit. Returns whether a shadow ray was traced.
    pub fn add_direct(&mut self, scene: &Scene, accel: &SceneAccel, rng: &mut Rng) -> bool {
        let Some(hit) = &self.hit else { return false };
        let (d, shadow) = camera_chain::direct_light(scene, accel, hit, rng);
        self.direct = [self.direct[0] + d.r, self.direct[1] + d.g, self.direct[2] + d.b];
        self.direct_n += 1;
        shadow.is_some()
    }

    /// Forgets the direct estimates (something may now shadow the hit, or light it).
    pub fn reset_direct(&mut self) {
        self.direct = [0.0; 3];
        self.direct_n = 0;
    }
}

/// Takes pixel `index`'s sample through `jitter`: the camera chain (drawing from `rng`), one
/// NEE estimate and a full gather.
pub fn sample_pixel(
    scene: &Scene,
    accel: &SceneAccel,
    grid: &PhotonGrid,
    index: usize,
    jitter: Vec2,
    rng: &mut Rng,
) -> (PixelSample, RenderRays) {
    let s = camera_chain::trace(scene, accel, index, jitter, rng);
    let mut rays = RenderRays { camera: 1, specular: s.specular_rays, shadow: 0 };
    let chain = s.specular_rays > 0;
    let first_t = match &s.hit {
        Some(h) if !chain => (h.p - scene.camera.position).length(),
        _ => f32::INFINITY,
    };
    let mut sample = PixelSample { jitter, emitted: s.emitted, hit: s.hit, first_t, chain, ..PixelSample::default() };
    if let Some(hit) = s.hit {
        sample.indirect = grid.gather_sum(hit.material(scene), hit.p, hit.n, hit.wo);
        rays.shadow += u64::from(sample.add_direct(scene, accel, rng));
    }
    (sample, rays)
}
