//! `instant_cache`'s configuration (validated as the service receives it) and its per-tick
//! figures. Distances are fractions of the scene's bounding diagonal; times in milliseconds;
//! memory in bytes.
use super::cache::Record;
use super::vpl::Vpl;
use crate::technique::budget::{product_sum, size, MemoryEstimate};
use crate::technique::registry::{Parameter, ParameterKind, TechniqueDescription, SPP};
use crate::technique::TechniqueError;
use serde::{Deserialize, Serialize};

/// How indirect light is gathered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CacheMode {
    /// Instant global illumination: interleaved VPL subsets and a discontinuity buffer.
    Igi,
    /// The instant cache, rebuilt every tick.
    Static,
    /// The instant cache kept across ticks; only what edits invalidated is re-evaluated.
    Temporal,
}

/// When `temporal` re-evaluates what a tick invalidated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reevaluation {
    /// Every record at the start of the tick (Algorithm 1).
    #[default]
    Immediate,
    /// Records are flagged and re-evaluated when first interpolated; flagged records no pixel
    /// used are dropped at the next tick.
    OnDemand,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InstantCacheConfig {
    pub mode: CacheMode,
    pub vpls: u32,
    pub interleave: u32,
    pub caching_radius: f32,
    /// θ: how far (degrees) a normal may turn from a record's before it stops using it.
    pub normal_tolerance: f32,
    pub clamp_distance: f32,
    /// Bounces a VPL path may take; `None`: until Russian roulette ends it (unbiased). A cap
    /// drops the light of longer paths (about ρ_S^n of the indirect light).
    pub max_bounces: Option<u32>,
    pub spp: u32,
    pub reevaluation: Reevaluation,
    /// `temporal`: records no pixel used for this many ticks are dropped.
    pub max_age: u32,
    /// Still ticks (no change at all) that refine the view, each rendering the next VPL
    /// generation with new sub-pixel points into the accumulated image; after them a still
    /// tick adds nothing. 0: a still tick renders the resident generation again.
    pub refine_ticks: u32,
    /// After each pass, recompute every record from scratch and report the records that differ
    /// (`audit_*` stats). Costs a static cache's work per pass; for tests and benchmarks.
    pub audit: bool,
}

impl Default for InstantCacheConfig {
    fn default() -> InstantCacheConfig {
        InstantCacheConfig {
            mode: CacheMode::Temporal,
            vpls: 256,
            interleave: 4,
            caching_radius: 0.05,
            normal_tolerance: DEFAULT_NORMAL_TOLERANCE,
            clamp_distance: 0.01,
            max_bounces: None,
            spp: 1,
            reevaluation: Reevaluation::Immediate,
            max_age: 16,
            refine_ticks: DEFAULT_REFINE_TICKS,
            audit: false,
        }
    }
}

/// θ's default, in degrees, chosen by `relume bench error` (relMSE against 1024-spp `path`,
/// docs/benchmarks.md, stop 52). With 256 VPLs the error is mostly the VPL set's, and a record
/// that serves a wider cone of normals averages more of it away: from 20° to 40°, bunnies-1 at
/// 256² 0.0177 → 0.0137 (records made a frame 154 → 76), merry-go-round 0.0615 → 0.0586, a
/// diffuse sphere 0.0220 → 0.0213, walker, maze and the Cornell box unchanged. Once a still
/// view has refined for 64 ticks the interpolation's own blur shows: the sphere 0.00527 →
/// 0.00542 (60°: 0.00554), the Cornell box unchanged.
pub const DEFAULT_NORMAL_TOLERANCE: f32 = 40.0;

/// Records a sample's interpolation holds, for the memory estimate (about 10 on the bundled
/// scenes at the default caching radius).
const WEIGHTS_PER_SAMPLE: u64 = 16;

/// `refine_ticks`' default: see `bench error`'s still-view rows in docs/benchmarks.md.
pub const DEFAULT_REFINE_TICKS: u32 = 64;

/// Most refinement generations (VPL keys of every generation must fit in a u32).
pub const MAX_REFINE_TICKS: u32 = 256;

/// Most VPLs a tick may shoot.
pub const MAX_VPLS: u32 = 65_536;

impl InstantCacheConfig {
    /// Resident memory at `pixels` pixels (`budget.rs`): the VPLs and the cache records, at
    /// most one per camera sample of a tick, each holding 4 bytes per VPL and its grid entry,
    /// and the empty grid; `audit` holds a second cache while it recomputes; the caches keep
    /// each sample's hit, result and weights, and `temporal` its camera sample. Refinement
    /// keeps a second generation's VPLs, and in `temporal` its own cache and samples beside the
    /// resident ones.
    pub fn resident_estimate(&self, pixels: u64) -> Result<MemoryEstimate, TechniqueError> {
        let generations = 1 + u64::from(self.refine_ticks > 0);
        let cache_layers = if self.mode == CacheMode::Temporal { generations } else { 1 };
        let vpls = u64::from(self.vpls);
        let samples = pixels.saturating_mul(u64::from(self.spp));
        let records = samples * (cache_layers + u64::from(self.audit));
        // The caches keep each sample's hit, irradiance and record weights (`pixels.rs`),
        // estimated at `WEIGHTS_PER_SAMPLE` each.
        let kept = if self.mode == CacheMode::Igi { 0 } else { samples * cache_layers };
        let per_sample = super::pixels::STATE_BYTES + WEIGHTS_PER_SAMPLE * super::pixels::WEIGHT_BYTES;
        let record = size::<Record>() + 4 * vpls + super::cache::KEY_BYTES;
        let grid = if self.mode == CacheMode::Igi { 0 } else { cache_layers + u64::from(self.audit) };
        // `temporal` keeps each sample's camera sample for the next tick (`cameras.rs`).
        let cameras = if self.mode == CacheMode::Temporal { samples } else { 0 };
        product_sum(
            "vpls",
            &[
                (vpls * generations, size::<Vpl>()),
                (records, record),
                (kept, per_sample),
                (grid, super::grid::MAX_EMPTY_BYTES),
                (cameras, super::cameras::SHADED_BYTES),
            ],
        )
    }

    pub fn validate(&self) -> Result<(), TechniqueError> {
        let bad = |field: &str, message: &str| {
            Err(TechniqueError::InvalidConfig { field: field.into(), message: message.into() })
        };
        if self.vpls == 0 || self.vpls > MAX_VPLS {
            return bad("vpls", &format!("must lie in 1..={MAX_VPLS}"));
        }
        if self.interleave == 0 || self.interleave > 16 {
            return bad("interleave", "must lie in 1..=16");
        }
        if !(self.caching_radius > 0.0 && self.caching_radius <= 1.0) {
            return bad("caching_radius", "must lie in (0, 1] (a fraction of the scene's diagonal)");
        }
        if !(self.normal_tolerance > 0.0 && self.normal_tolerance <= 90.0) {
            return bad("normal_tolerance", "must lie in (0, 90] degrees");
        }
        if !(self.clamp_distance >= 0.0 && self.clamp_distance <= 1.0) {
            return bad("clamp_distance", "must lie in [0, 1] (a fraction of the scene's diagonal)");
        }
        if self.max_bounces.is_some_and(|n| n == 0 || n > super::vpl::MAX_VPL_BOUNCES) {
            return bad("max_bounces", &format!("must lie in 1..={} (or be absent)", super::vpl::MAX_VPL_BOUNCES));
        }
        if self.spp == 0 || self.spp > crate::technique::path::MAX_SPP {
            return bad("spp", &format!("must lie in 1..={}", crate::technique::path::MAX_SPP));
        }
        if self.refine_ticks > MAX_REFINE_TICKS {
            return bad("refine_ticks", &format!("must lie in 0..={MAX_REFINE_TICKS}"));
        }
        if self.max_age == 0 {
            return bad("max_age", "must be at least 1 tick");
        }
        Ok(())
    }
}

/// Per-tick figures of `instant_cache`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct InstantCacheStats {
    /// The VPL generation this tick rendered: 0 is the resident one, which follows changes;
    /// 1..=`refine_ticks` are a still view's refinements (`idle` once they are done).
    pub generation: u32,
    /// A still view whose refinement is done: the tick rendered nothing.
    pub idle: bool,
    pub vpls: u64,
    /// Photon paths the VPLs come from (their light is divided among these).
    pub vpl_paths: u64,
    /// The VPL cap (4 × `vpls`) stopped the shooting early; the light was divided among the
    /// paths completed before it.
    pub vpl_cap_reached: bool,
    pub vpl_rays: u64,
    /// `temporal`: this tick's VPLs against last tick's, by key (cases 1–2).
    pub vpls_reused: u64,
    pub vpls_reweighted: u64,
    pub vpls_invalidated: u64,
    /// Records in the resident cache after this tick; records made this tick (in a refinement
    /// generation's cache on a refining tick), and kept from earlier ticks and interpolated.
    pub records: u64,
    pub records_created: u64,
    pub records_reused: u64,
    /// Camera samples whose irradiance was interpolated (eq. 4) this tick.
    pub samples_interpolated: u64,
    /// `temporal`: camera samples that kept their last tick's irradiance (a still tick: same
    /// hit and records, no change in the scene), without a lookup or a sum.
    pub samples_reused: u64,
    /// Camera samples that looked the cache up (the rest kept their records: `pixels.rs`).
    pub samples_looked_up: u64,
    /// Grid queries: samples' lookups and the coverage tests of samples with no record.
    pub cache_lookups: u64,
    /// `temporal`: records re-evaluated, and by case those with a ray retraced or a
    /// contribution changed (`vpl`: cases 1–2, a VPL moved, appeared or changed intensity).
    pub records_refreshed: u64,
    pub records_invalidated_vpl: u64,
    pub records_invalidated_occluded: u64,
    pub records_invalidated_deoccluded: u64,
    /// Case 5: removed because they lay on an object that moved.
    pub records_removed_moved: u64,
    pub records_aged_out: u64,
    /// On-demand: flagged records no pixel used, dropped.
    pub records_dropped_stale: u64,
    /// Every ray from a record or pixel towards a VPL; the kinds below add up to it.
    pub visibility_rays: u64,
    /// Rays of records made this tick (and of `igi`'s gather).
    pub visibility_rays_new: u64,
    /// Case 1–2 rays (changed VPLs) against the full scene.
    pub visibility_rays_vpl: u64,
    /// Case 3 rays against the moved surfaces only, and the box tests that selected them.
    pub visibility_rays_occlusion: u64,
    pub occlusion_box_tests: u64,
    /// Case 4 rays against the full scene, and the old-bounds tests that selected them.
    pub visibility_rays_deocclusion: u64,
    pub deocclusion_box_tests: u64,
    /// Camera rays traced (`temporal` keeps the samples a change cannot have reached: `cameras.rs`).
    pub camera_rays: u64,
    /// `temporal`: camera samples kept from last tick instead of traced.
    #[serde(default)]
    pub camera_samples_kept: u64,
    /// `temporal`: kept camera samples that also kept their direct light (no shadow ray).
    #[serde(default)]
    pub direct_samples_kept: u64,
    /// `temporal`: runs of `cameras::RUN` pixels whose samples were kept, direct light too,
    /// on their run's summary alone, without reading them.
    #[serde(default)]
    pub camera_runs_settled: u64,
    pub specular_rays: u64,
    pub shadow_rays: u64,
    pub vpl_ms: f64,
    /// `temporal`: ageing, case 5 and (immediate) re-evaluation at the start of the tick.
    pub invalidate_ms: f64,
    /// The indirect component: record creation, on-demand re-evaluation and interpolation, or
    /// the IGI gather and filter.
    pub indirect_ms: f64,
    /// The part of `indirect_ms` spent computing new records and re-evaluating flagged ones.
    #[serde(default)]
    pub records_ms: f64,
    /// Camera samples and their direct light (traced, or kept by `temporal`); not indirect.
    #[serde(default)]
    pub camera_ms: f64,
    pub render_ms: f64,
    /// `vpls` and `cache` (records, their contributions and the grid).
    pub memory: crate::technique::ResidentMemory,
    /// With `audit`: records checked, those differing from a fresh computation, and those no
    /// longer on any surface.
    pub audit_records: u64,
    pub audit_mismatched: u64,
    pub audit_off_surface: u64,
    /// With `audit`: samples whose kept records differ from a fresh lookup, and samples whose
    /// hit or records changed since last tick (those that had to look up).
    pub audit_samples_mismatched: u64,
    pub audit_samples_needed: u64,
    /// With `audit`: kept camera samples that differ from a fresh trace.
    #[serde(default)]
    pub audit_cameras_mismatched: u64,
    /// A hash of the audited records (positions, normals, contributions): equal caches, equal
    /// digests.
    pub audit_digest: u64,
}

/// The registry's description (`technique/registry.rs`).
pub const DESCRIPTION: TechniqueDescription = TechniqueDescription {
    id: "instant_cache",
    summary: "Virtual point lights and an irradiance cache invalidated over time (instant radiosity with caching)",
    shorthand: Some(("mode", "vpls")),
    parameters: &[
        Parameter {
            name: "mode",
            kind: ParameterKind::Choice { choices: &["igi", "static", "temporal"] },
            help: "igi: no cache; static: rebuilt each tick; temporal: invalidated by change",
        },
        Parameter { name: "vpls", kind: ParameterKind::Integer { min: 1, max: 65536 }, help: "virtual point lights" },
        SPP,
    ],
    test_specs: &["instant_cache:igi", "instant_cache:static", "instant_cache:temporal"],
};
