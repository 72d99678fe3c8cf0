//! Per-tick figures of `photon_reuse`: paths by fate, rays by kind, time by stage, memory by
//! structure. Times in milliseconds, memory in bytes.
use super::pixels::FollowCounts;
use super::store::StoreMemory;
use super::verify::VerifyWork;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhotonStats {
    // Paths.
    pub paths: u64,
    pub untouched: u64,
    pub partly_retraced: u64,
    pub fully_retraced: u64,
    /// Dropped from over-full distribution-map cells (eq. 1).
    pub pruned: u64,
    /// Emitted into cells below target.
    pub filled: u64,
    /// Emitted afresh by this still tick's progressive refinement.
    pub refined: u64,
    /// Paths whose fluxes an intensity or colour edit scaled, with no rays.
    pub rescaled: u64,
    /// Every path was assigned to the lights and emitted afresh this tick: a light that owned
    /// no paths (it was dark at the first tick) was switched on.
    pub reassigned: bool,
    // Rays by kind.
    /// Occlusion rays checking the new primary segments of moved lights.
    pub origin_rays: u64,
    /// Closest-hit rays against the full scene of `error` mode's verification.
    pub verify_rays: u64,
    /// Occlusion rays of verification against the moved surfaces alone (the exact crossing
    /// test of a segment in a moved box, both modes).
    pub crossing_rays: u64,
    /// Rays of retraced segments.
    pub retrace_rays: u64,
    /// Rays of paths filled into distribution-map cells.
    pub fill_rays: u64,
    pub camera_rays: u64,
    pub specular_rays: u64,
    pub shadow_rays: u64,
    /// Segment-against-box tests made by verification (the screen's cover tests included).
    pub verify_box_tests: u64,
    /// Paths the bounce-row screen passed on to the per-path checks (the rest are valid).
    pub screened: u64,
    // Time by stage.
    /// Update origins of moved lights, with their primary-segment rays, and count DM_C.
    pub origins_ms: f64,
    /// Dynamic occlusions: verification against moved surfaces and edited materials.
    pub verify_ms: f64,
    /// The bounce-row screen, part of `verify_ms`.
    pub screen_ms: f64,
    pub prune_ms: f64,
    /// Tracing the filled paths.
    pub fill_ms: f64,
    /// Tracing the other retraced paths.
    pub trace_ms: f64,
    pub grid_ms: f64,
    pub render_ms: f64,
    // Gather and distribution maps.
    pub radius: f32,
    pub grid_photons: u64,
    /// Photons the grid update took out and put in (a rebuild counts every photon as put in).
    pub grid_removed: u64,
    pub grid_added: u64,
    /// Grid cells those photons left or entered.
    pub grid_cells_touched: u64,
    /// The grid was built from scratch this tick (the first tick, `off` mode, or more than a
    /// quarter of the paths changed) rather than updated in place.
    pub grid_rebuilt: bool,
    /// Total flux of the gathered photons (W per channel): the indirect light in the map.
    pub grid_power: [f64; 3],
    /// Largest χ² of DM_C against DM_T over the lights with a map, after this tick's fill.
    pub distribution_chi2: f64,
    /// Cells of the map with that χ² (its degrees of freedom + 1).
    pub distribution_cells: u64,
    // The kept pixels.
    /// This tick's render followed the change in the kept pixels instead of a full pass.
    pub followed: bool,
    /// What following did to the pixels (all zero after a full pass).
    pub pixels: FollowCounts,
    /// The path store's structures.
    pub store: StoreMemory,
    /// Everything resident: the store's parts, the photon grid (`grid`) and the kept camera
    /// samples with their hit index (`pixels`).
    pub memory: crate::technique::ResidentMemory,
}

impl PhotonStats {
    /// Rays traced for photon paths this tick: verification, retraced and filled segments.
    pub fn photon_rays(&self) -> u64 {
        self.origin_rays + self.crossing_rays + self.verify_rays + self.retrace_rays + self.fill_rays
    }

    /// Adds what verification cost.
    pub fn count_verification(&mut self, work: VerifyWork) {
        self.verify_box_tests += work.tests;
        self.crossing_rays += work.crossing_rays;
        self.verify_rays += work.scene_rays;
    }
}
