//! The kept pixels: a render that follows the change while the camera is still.
//!
//! Every full pass keeps each pixel's camera sample ([`PixelSample`]: its hit, its direct
//! light estimates and its photon sum). When only objects moved, a tick does not render the
//! frame again; for each pixel it decides what the move can have changed:
//! - **Resampled**: the camera ray went through a specular chain, ended on a moved object, or
//!   may now be crossed by a moved object (its segment against the old and new boxes, widened
//!   by the pixel's footprint). The sample is taken again through the same jitter.
//! - **Direct light stale**: a moved box (widened by the pixel's footprint) meets the convex
//!   hull of the hit and a light's bounds ([`meets_hull`], exact), so some shadow ray may now
//!   be blocked or freed. Its NEE estimates are forgotten.
//! - **Indirect light changed**: a photon the grid took out or put in lies within r (plus the
//!   footprint) of the hit. Its photon sum is updated by splatting exactly those photons, with
//!   the same term a gather uses, so it equals a fresh gather up to rounding (the sums are
//!   f64).
//!
//! Only those pixels restart their accumulation (with one NEE estimate more); every other
//! pixel keeps accumulating, untouched, at no cost. A camera move, a light or material edit, or
//! a rebuilt grid falls back to a full pass (`mod.rs` decides).
//!
//! The footprint, reach = t · pixel angle / max(|cos θ|, ¼), bounds how far another sample of
//! the same pixel may land from the kept one on the same surface; a pixel straddling a depth
//! edge may keep, from earlier passes, a little of the far surface's old indirect light until
//! its next restart. Memory: one [`PixelSample`] and its footprint per pixel.
use super::gather::{self, PixelSample, RenderRays};
use super::grid::{ChangedPhotons, PhotonGrid};
use super::near::NearPhotons;
use crate::core::Rng;
use crate::film::Film;
use crate::scene::edits::Aabb;
use crate::scene::{Scene, SceneAccel};
use crate::technique::box_tree::{meets_hull, segment_hits_box, widened, BoxTree};
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// What a move did to one kept pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fate {
    Kept,
    Resampled,
    DirectStale,
}

/// What one followed tick did to the pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FollowCounts {
    pub resampled: u64,
    pub direct_stale: u64,
    /// Pixels whose photon sum a splat changed.
    pub splatted: u64,
    /// Photon terms added to or taken from kept pixels.
    pub splat_terms: u64,
    pub restarted: u64,
}

/// What moved this tick, as the pixels need it.
pub struct Moves<'a> {
    /// Old and new world bounds of every moved surface.
    pub boxes: &'a [Aabb],
    /// `moved[object]`.
    pub moved: &'a [bool],
    /// World bounds of each light.
    pub lights: &'a [Aabb],
    /// The boxes' widening against rounding (scene units).
    pub slack: f32,
}

/// Bytes kept per pixel: its sample and its footprint, as `memory_bytes` counts them.
pub const BYTES_PER_PIXEL: u64 = (std::mem::size_of::<PixelSample>() + 4) as u64;

/// The kept camera samples of the current camera, one per pixel.
#[derive(Clone, Debug, Default)]
pub struct PixelCache {
    samples: Vec<PixelSample>,
    /// Each sample's footprint (see the module doc).
    reach: Vec<f32>,
    /// The gather radius the photon sums were taken with.
    radius: f32,
}

impl PixelCache {
    /// The gather radius of the kept photon sums, if there are samples of the current camera
    /// (a full pass has run since it moved).
    pub fn gathered_at(&self) -> Option<f32> {
        (!self.samples.is_empty()).then_some(self.radius)
    }

    /// Forgets every sample (the camera moved).
    pub fn clear(&mut self) {
        self.samples.clear();
        self.reach.clear();
    }

    pub fn memory_bytes(&self) -> u64 {
        (self.samples.capacity() * std::mem::size_of::<PixelSample>() + self.reach.capacity() * 4) as u64
    }

    /// One full pass: a fresh sample per pixel (stream `(seed, tick, pixel, pass)`) is added to
    /// the film and kept.
    pub fn full_pass(
        &mut self,
        scene: &Scene,
        accel: &SceneAccel,
        grid: &PhotonGrid,
        stream: (u64, u64, u64),
        film: &mut Film,
    ) -> RenderRays {
        let (seed, tick, pass) = stream;
        let pixels = (scene.camera.width * scene.camera.height) as usize;
        let taken: Vec<(PixelSample, RenderRays)> = (0..pixels)
            .into_par_iter()
            .map(|index| {
                let mut rng = Rng::for_sample(seed, tick, index as u64, pass);
                let jitter = rng.next_2d();
                gather::sample_pixel(scene, accel, grid, index, jitter, &mut rng)
            })
            .collect();
        let rays = taken.iter().fold(RenderRays::default(), |a, (_, r)| a.merge(*r));
        self.samples = taken.into_iter().map(|(s, _)| s).collect();
        self.reach = self.samples.iter().map(|s| footprint(scene, s)).collect();
        self.radius = grid.radius;
        let (samples, k) = (&self.samples, grid.kernel_area() as f64);
        let width = scene.camera.width as usize;
        film.accumulate_chunks(
            width,
            |first, chunk| {
                for (offset, pixel) in chunk.iter_mut().enumerate() {
                    pixel.add(samples[first + offset].value(k));
                    pixel.count += 1.0;
                }
            },
            |_, _| (),
        );
        film.passes += 1;
        rays
    }

    /// A tick where only objects moved and the grid was updated in place with `changed`:
    /// resample, forget direct light and splat only where the move reaches, and restart those
    /// pixels in the film.
    #[allow(clippy::too_many_arguments)]
    pub fn follow(
        &mut self,
        scene: &Scene,
        accel: &SceneAccel,
        grid: &PhotonGrid,
        changed: &ChangedPhotons,
        moves: &Moves,
        stream: (u64, u64),
        film: &mut Film,
    ) -> (FollowCounts, RenderRays) {
        let (seed, tick) = stream;
        let fates = self.fates(scene, moves);
        let mut counts = FollowCounts::default();
        let touched = self.splat(scene, grid, changed, &fates, &mut counts);
        let k = grid.kernel_area() as f64;
        // The pixels to redo lie where the moves are, often in one band of rows: listed first,
        // they split evenly between the workers (a filter over all pixels would hand one band,
        // and one worker, most of them).
        let redo: Vec<usize> =
            (0..self.samples.len()).into_par_iter().filter(|&i| fates[i] != Fate::Kept || touched[i]).collect();
        let restarts: Vec<(usize, PixelSample, RenderRays)> = redo
            .into_par_iter()
            .map(|i| {
                // Streams apart from any full pass's (those use small pass numbers).
                let mut rng = Rng::for_sample(seed, tick, i as u64, u64::MAX);
                let mut s = self.samples[i];
                let mut rays = RenderRays::default();
                match fates[i] {
                    Fate::Resampled => (s, rays) = gather::sample_pixel(scene, accel, grid, i, s.jitter, &mut rng),
                    Fate::DirectStale | Fate::Kept => {
                        if fates[i] == Fate::DirectStale {
                            s.reset_direct();
                        }
                        rays.shadow += u64::from(s.add_direct(scene, accel, &mut rng));
                    }
                }
                (i, s, rays)
            })
            .collect();
        let mut rays = RenderRays::default();
        let mut values = Vec::with_capacity(restarts.len());
        for (i, s, r) in restarts {
            rays = rays.merge(r);
            match fates[i] {
                Fate::Resampled => {
                    counts.resampled += 1;
                    self.reach[i] = footprint(scene, &s);
                }
                Fate::DirectStale => counts.direct_stale += 1,
                Fate::Kept => {}
            }
            self.samples[i] = s;
            values.push((i as u32, s.value(k)));
        }
        counts.restarted = values.len() as u64;
        film.restart_pixels(&values);
        (counts, rays)
    }

    /// Decides each pixel's [`Fate`] from what moved.
    fn fates(&self, scene: &Scene, moves: &Moves) -> Vec<Fate> {
        let widest = self.reach.iter().copied().filter(|r| r.is_finite()).fold(0.0f32, f32::max);
        let exact = BoxTree::new(moves.boxes.iter().map(|b| widened(b, moves.slack)).collect());
        let wide = BoxTree::new(moves.boxes.iter().map(|b| widened(b, moves.slack + widest)).collect());
        let camera = &scene.camera;
        let width = camera.width as usize;
        self.samples
            .par_iter()
            .zip(&self.reach)
            .enumerate()
            .map(|(i, (s, &reach))| {
                let ray = camera.ray((i % width) as f32 + s.jitter.x, (i / width) as f32 + s.jitter.y);
                let on_moved = s.hit.is_some_and(|h| moves.moved[h.object as usize]);
                // The camera segment against the boxes widened by this pixel's footprint (the
                // tree widened by the largest footprint culls first).
                let crossed = || {
                    wide.hits(ray.origin, ray.dir, s.first_t).0
                        && moves
                            .boxes
                            .iter()
                            .any(|b| segment_hits_box(ray.origin, ray.dir, s.first_t, &widened(b, moves.slack + reach)))
                };
                if s.chain || on_moved || crossed() {
                    return Fate::Resampled;
                }
                let Some(hit) = &s.hit else { return Fate::Kept };
                // A shadow ray of any sample of this pixel runs from within `reach` of the hit to
                // a light: inside the hull of the hit and the light, widened by `reach`. The
                // boxes' union culls first.
                let around = Aabb { min: hit.p - Vec3::splat(reach), max: hit.p + Vec3::splat(reach) };
                let point = Aabb { min: hit.p, max: hit.p };
                let in_a_shadow_ray = |l: &Aabb| {
                    exact.overlaps(&around.union(l))
                        && moves.boxes.iter().any(|b| meets_hull(&point, l, &widened(b, moves.slack + reach)))
                };
                if moves.lights.iter().any(in_a_shadow_ray) {
                    Fate::DirectStale
                } else {
                    Fate::Kept
                }
            })
            .collect()
    }

    /// Splats the removed (−) and added (+) photons into the photon sums of every pixel not
    /// being resampled, pixel by pixel through an index of only the changed photons
    /// ([`NearPhotons`], so the work is a few cells per pixel plus the terms near it). Returns
    /// which pixels a photon reached (within r plus the pixel's footprint).
    fn splat(
        &mut self,
        scene: &Scene,
        grid: &PhotonGrid,
        changed: &ChangedPhotons,
        fates: &[Fate],
        counts: &mut FollowCounts,
    ) -> Vec<bool> {
        let signed = changed.removed.iter().map(|p| (*p, -1.0)).chain(changed.added.iter().map(|p| (*p, 1.0)));
        let Some(near) = NearPhotons::new(signed.collect(), 2.0 * grid.radius) else {
            return vec![false; self.samples.len()];
        };
        let r2 = grid.radius * grid.radius;
        let found: Vec<(bool, u64)> = self
            .samples
            .par_iter_mut()
            .zip(&self.reach)
            .zip(fates)
            .map(|((s, &reach), &fate)| {
                let Some(hit) = s.hit.filter(|_| fate != Fate::Resampled) else { return (false, 0) };
                let within = grid.radius + reach;
                let (material, side) = (hit.material(scene), hit.facing());
                let (mut touched, mut terms) = (false, 0);
                near.around(hit.p, within, |positions, photons| {
                    // Distances first, for 32 photons at a time without a branch (about a third
                    // are within reach: a branch per photon mispredicts), then the terms of the
                    // photons within r, in order.
                    for (qs, ps) in positions.chunks(32).zip(photons.chunks(32)) {
                        let (mut reached, mut in_r) = (0u32, 0u32);
                        for (j, q) in qs.iter().enumerate() {
                            let d2 = (*q - hit.p).length_squared();
                            reached |= u32::from(d2 <= within * within) << j;
                            in_r |= u32::from(d2 <= r2) << j;
                        }
                        touched |= reached != 0;
                        while in_r != 0 {
                            let (photon, sign) = &ps[in_r.trailing_zeros() as usize];
                            in_r &= in_r - 1;
                            if let Some(t) = photon.term(material, hit.p, hit.n, hit.wo, side, r2) {
                                let i = &mut s.indirect;
                                *i = [i[0] + t.r as f64 * sign, i[1] + t.g as f64 * sign, i[2] + t.b as f64 * sign];
                                terms += 1;
                            }
                        }
                    }
                });
                (touched, terms)
            })
            .collect();
        counts.splat_terms = found.iter().map(|f| f.1).sum();
        counts.splatted = found.iter().filter(|f| f.1 > 0).count() as u64;
        found.into_iter().map(|f| f.0).collect()
    }

    /// The kept samples (tests compare their photon sums with fresh gathers).
    #[cfg(test)]
    pub fn samples(&self) -> &[PixelSample] {
        &self.samples
    }
}

/// How far another sample of the same pixel may land from `s`'s hit on its surface.
fn footprint(scene: &Scene, s: &PixelSample) -> f32 {
    let Some(hit) = &s.hit else { return 0.0 };
    if !s.first_t.is_finite() {
        return 0.0;
    }
    let camera = &scene.camera;
    let pixel_angle = 2.0 * camera.tan_half_vfov / camera.height as f32 * std::f32::consts::SQRT_2;
    s.first_t * pixel_angle / hit.n.dot(hit.wo).abs().max(0.25)
}

#[cfg(test)]
mod tests {
    use crate::embree::Device;
    use crate::film::Film;
    use crate::technique::photon_reuse::test_scenes::CornellRun;
    use crate::technique::photon_reuse::{PhotonReuse, ReuseMode};
    use crate::technique::{Technique, TechniqueStats};

    /// The first pixel whose photon sum differs from a fresh gather at its hit by more than
    /// rounding (f64 sums of the same f32 terms in another order), if any.
    fn first_mismatch(technique: &PhotonReuse, scene: &crate::scene::Scene) -> Option<(usize, [f64; 3], [f64; 3])> {
        let grid = &technique.grid;
        technique.pixels.samples().iter().enumerate().find_map(|(i, s)| {
            let hit = s.hit?;
            let fresh = grid.gather_sum(hit.material(scene), hit.p, hit.n, hit.wo);
            let close = (0..3).all(|c| (s.indirect[c] - fresh[c]).abs() <= 1e-9 * fresh[c].abs().max(1e-6));
            (!close).then_some((i, s.indirect, fresh))
        })
    }

    #[test]
    fn splatted_pixels_equal_a_full_gather() {
        // Property: after every tick of an animation that moves the block (and, every third
        // tick, the light: those ticks render in full), each kept pixel's photon sum equals a
        // fresh gather at its hit up to rounding. Negative control: the sums as they were
        // before a followed tick's splat fail the same comparison.
        let device = Device::new(2).expect("device");
        for reuse in [ReuseMode::Naive, ReuseMode::Error] {
            let mut run = CornellRun::new(&device, reuse);
            let mut film = Film::new(run.scene.camera.width, run.scene.camera.height);
            let (mut followed, mut stale_caught) = (0, 0);
            for tick in 0..10u32 {
                let update = run.update(tick, 5);
                let before = run.technique.pixels.clone();
                let ctx = crate::technique::RenderContext {
                    scene: &run.scene,
                    accel: &run.accel,
                    seed: 5,
                    tick: tick as u64,
                };
                let stats = run.technique.render(&ctx, &mut film, update).expect("render");
                let TechniqueStats::PhotonReuse(s) = stats.detail else { panic!("photon_reuse stats") };
                let (technique, scene) = (&mut run.technique, &run.scene);
                assert_eq!(first_mismatch(technique, scene), None, "{reuse:?} tick {tick}");
                if s.followed {
                    followed += 1;
                    assert!(
                        s.pixels.splat_terms > 0,
                        "{reuse:?} tick {tick}: a move that splatted nothing: {:?}",
                        s.pixels
                    );
                    let after = std::mem::replace(&mut technique.pixels, before);
                    stale_caught += usize::from(first_mismatch(technique, scene).is_some());
                    technique.pixels = after;
                }
            }
            assert!(followed >= 5, "{reuse:?}: only {followed} ticks followed the change");
            assert_eq!(stale_caught, followed, "{reuse:?}: unsplatted sums passed the comparison");
        }
    }
}
