//! Per-tick statistics, forwarded unchanged by the server.
use crate::technique::{RayCounts, TechniqueStats};
use serde::{Deserialize, Serialize};

/// Wall time of each tick phase, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhaseTimes {
    pub drain_ms: f64,
    pub apply_ms: f64,
    pub commit_ms: f64,
    pub update_ms: f64,
    pub render_ms: f64,
    pub resolve_ms: f64,
    /// The denoise stage (auxiliary pass and OIDN), 0 when the session does not denoise.
    #[serde(default)]
    pub denoise_ms: f64,
    pub total_ms: f64,
}

/// What one tick did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TickStats {
    pub tick: u64,
    pub technique: String,
    pub times: PhaseTimes,
    pub rays: RayCounts,
    /// Edits drained this tick, and how many of them a later edit to the same target replaced.
    pub edits_received: usize,
    pub edits_coalesced: usize,
    /// Edits (after coalescing) whose result equalled the current value, so changed nothing.
    pub edits_unchanged: usize,
    /// Every edit batch with a sequence number up to this one is applied (or coalesced into a
    /// later edit of the same target that is); 0 before any batch.
    pub edits_applied_through: u64,
    /// Objects and light shapes whose Embree instance was updated.
    pub moved_surfaces: usize,
    /// Render passes accumulated since the last reset.
    pub spp: u32,
    /// Mean number of estimates (paths) per pixel since the last reset.
    pub paths_per_pixel: f64,
    pub accumulation_id: u64,
    /// Rays the denoise stage's auxiliary pass traced (0 once its images are converged, and
    /// when the session does not denoise).
    #[serde(default)]
    pub aux_rays: u64,
    /// True when the denoise stage returned the last tick's output: nothing in the film (nor in
    /// the auxiliary images) changed since. Absent otherwise.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub denoise_reused: bool,
    /// True when the film was as the last tick left it, so its image was not resolved again:
    /// the frame shares the last tick's image. Absent otherwise.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub resolve_reused: bool,
    /// True on the first tick after a restore from a snapshot: the technique rebuilt (retraced)
    /// its state. Absent otherwise.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub restored: bool,
    pub detail: TechniqueStats,
}
