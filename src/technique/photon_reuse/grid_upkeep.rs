//! Keeping the photon grid and the gather radius up to date between ticks: rebuild or update
//! in place, progressive refinement on still ticks (with the radius schedule), and the render
//! plan that follows from what changed. Radii in meters.
use super::grid::{ChangedPhotons, PhotonGrid};
use super::store::PathStore;
use super::trace::Retrace;
use super::{ms, PhotonReuse, PhotonStats, Plan, TickWork, REFINE_ALPHA};
use crate::scene::edits::SceneDelta;
use crate::scene::{Scene, SurfaceId};
use crate::technique::RenderContext;
use rayon::prelude::*;
use std::time::Instant;

impl PhotonReuse {
    /// Progressive refinement on a still tick (in the manner of Knaus and Zwicker's
    /// probabilistic progressive photon mapping): the next `refine` share of the paths of lights
    /// that never moved is emitted afresh, and the radius shrinks to r_k with
    /// r_k² = r₀² · Π_{i ≤ k} (i + α)/(i + 1), α = 2/3. Returns whether photons changed.
    pub(super) fn refine(&mut self, ctx: &RenderContext, store: &mut PathStore, tick: &mut TickWork) -> bool {
        let count = (self.config.refine as f64 * store.paths as f64).ceil() as usize;
        if count == 0 || self.base_radius <= 0.0 {
            return false;
        }
        let unmapped = |i: usize| self.maps.get(store.light_of(i)).is_none_or(|m| m.is_none());
        let work: Vec<(usize, Retrace)> = (0..count.min(store.paths))
            .map(|k| (self.refine_cursor + k) % store.paths)
            .filter(|&i| unmapped(i))
            .map(|i| (i, Retrace::Emit))
            .collect();
        self.refine_cursor = (self.refine_cursor + count) % store.paths;
        self.refined += 1;
        let k = self.refined as f32;
        self.shrink *= ((k + REFINE_ALPHA) / (k + 1.0)).sqrt();
        self.grid.radius = self.base_radius * self.shrink;
        tick.stats.refined = work.len() as u64;
        self.retrace(ctx, store, &work, tick);
        true
    }

    /// A change ends the refinement: the radius goes back to r₀.
    pub(super) fn restore_radius(&mut self) {
        self.refined = 0;
        self.shrink = 1.0;
        if self.base_radius > 0.0 {
            self.grid.radius = self.base_radius;
        }
    }

    /// Picks the gather radius (r₀, fixed after the first tick) and rebuilds the photon grid.
    /// The first pick needs only the number of photons the grid will hold, which is counted
    /// without building a grid (a throwaway grid of unit cells took as long as the real one:
    /// `docs/benchmarks.md`, stop 58).
    pub(super) fn rebuild_grid(&mut self, scene: &Scene, store: &PathStore, stats: &mut PhotonStats) {
        let t = Instant::now();
        let radius = match self.config.radius {
            Some(r) => r,
            None if self.base_radius > 0.0 => self.base_radius,
            None => {
                let area: f32 = scene
                    .objects
                    .iter()
                    .filter(|o| !scene.materials[o.material as usize].is_specular())
                    .map(|o| o.area)
                    .sum();
                let photons = PhotonGrid::count(scene, store);
                (self.config.gather_photons as f32 * area / (std::f32::consts::PI * photons.max(1) as f32)).sqrt()
            }
        };
        self.grid = PhotonGrid::build(scene, store, radius);
        self.base_radius = radius;
        self.grid.radius = radius * self.shrink;
        stats.grid_ms = ms(t);
        stats.grid_rebuilt = true;
        stats.grid_added = self.grid.len() as u64;
    }

    /// Brings the grid up to date with the paths this tick changed: in place, unless so many
    /// changed that a rebuild is cheaper (`bench reuse` measures both; at a quarter of the paths
    /// the update's per-photon inserts cost about what a parallel rebuild does). Returns the
    /// photons an in-place update took out and put in, or `None` after a rebuild.
    pub(super) fn refresh_grid(
        &mut self,
        scene: &Scene,
        store: &PathStore,
        mut touched: Vec<usize>,
        stats: &mut PhotonStats,
    ) -> Option<ChangedPhotons> {
        if self.grid.radius <= 0.0 || touched.len() * 4 > store.paths {
            self.rebuild_grid(scene, store, stats);
            return None;
        }
        let t = Instant::now();
        touched.par_sort_unstable();
        touched.dedup();
        let (u, changed) = self.grid.update(scene, store, &touched);
        stats.grid_removed = u.removed;
        stats.grid_added = u.added;
        stats.grid_cells_touched = u.cells_touched;
        stats.grid_ms = ms(t);
        Some(changed)
    }

    /// The render plan for a later tick: the kept pixels follow the change when the camera
    /// stood still, no light or material changed, and the grid was updated in place
    /// (`changed`; `None` after a rebuild).
    pub(super) fn plan(&mut self, scene: &Scene, delta: &SceneDelta, changed: Option<ChangedPhotons>) -> Plan {
        if delta.camera {
            self.pixels.clear();
        }
        // A refined still tick renders in full and keeps accumulating: its new photons are
        // fresh samples of the same light, not a change.
        let still = delta.is_empty()
            && (self.refined > 0 || changed.as_ref().is_none_or(|c| c.removed.is_empty() && c.added.is_empty()));
        let followable = self.pixels.gathered_at() == Some(self.grid.radius)
            && delta.lights.is_empty()
            && delta.materials.is_empty();
        match changed {
            Some(changed) if !still && followable => {
                let mut moved = vec![false; scene.objects.len()];
                let mut boxes = Vec::with_capacity(2 * delta.moved.len());
                for m in &delta.moved {
                    boxes.extend([m.old_bounds, m.new_bounds]);
                    if let SurfaceId::Object(o) = m.surface {
                        moved[o as usize] = true;
                    }
                }
                Plan::Follow { changed, boxes, moved }
            }
            _ => Plan::Full,
        }
    }
}
