//! `photon_reuse` parameters, their defaults and their validation.
use super::distribution::MapResolution;
use super::store::{PathStore, PathWord, PhotonRow};
use super::{grid, pixels};
use crate::scene::Scene;
use crate::technique::budget::{product_sum, MemoryEstimate};
use crate::technique::registry::{Parameter, ParameterKind, TechniqueDescription, SPP};
use crate::technique::TechniqueError;
use serde::{Deserialize, Serialize};

/// How paths are reused from tick to tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReuseMode {
    /// Baseline: retrace every path whenever the scene changed.
    Off,
    /// Retrace from the first segment a moved surface's bounds may cross (§3.2).
    Naive,
    /// Re-trace crossed segments and keep the path while reflected energy stays within
    /// `threshold` (§3.3, Algorithm 1).
    Error,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PhotonReuseConfig {
    pub paths: u32,
    pub max_photons: u32,
    pub reuse: ReuseMode,
    /// T of `error` mode: relative energy change a kept vertex may have.
    pub threshold: f32,
    pub distribution_map: MapResolution,
    pub gather_photons: u32,
    pub radius: Option<f32>,
    pub spp: u32,
    /// Share of the paths emitted afresh each still tick, while the gather radius shrinks
    /// (progressive refinement; 0 turns it off).
    pub refine: f32,
}

impl Default for PhotonReuseConfig {
    fn default() -> PhotonReuseConfig {
        PhotonReuseConfig {
            paths: 1_000_000,
            max_photons: 7,
            reuse: ReuseMode::Error,
            threshold: 0.001,
            distribution_map: MapResolution::default(),
            gather_photons: 64,
            radius: None,
            spp: 1,
            refine: 0.125,
        }
    }
}

/// Largest share of the paths a still tick re-emits: more would rebuild the grid every tick.
pub const MAX_REFINE: f32 = 0.25;

/// Largest accepted path count.
pub const MAX_PATHS: u32 = 16_000_000;

/// Largest `gather_photons`: a gather visits about this many photons per pixel.
pub const MAX_GATHER_PHOTONS: u32 = 4096;

/// Largest `radius`, as a share of the scene's bounding diagonal: a wider kernel makes every
/// gather visit a large part of the map.
pub const MAX_RADIUS_SHARE: f32 = 0.1;

impl PhotonReuseConfig {
    /// Resident memory on `scene` at `pixels` pixels (`budget.rs`): the path store, the photon
    /// grid (every photon in it, and one cell per `gather_photons / 4` photons: cells are r
    /// wide, so a surface crossing one holds about r² of the πr² that holds `gather_photons`)
    /// and the kept pixels. Also refuses a `radius` wider than [`MAX_RADIUS_SHARE`] of the
    /// scene's diagonal.
    pub fn resident_estimate(&self, scene: &Scene, pixels: u64) -> Result<MemoryEstimate, TechniqueError> {
        if let Some(r) = self.radius {
            let diagonal = scene.bounds().map_or(0.0, |(lo, hi)| (hi - lo).length());
            if r > MAX_RADIUS_SHARE * diagonal {
                return Err(TechniqueError::TooLarge {
                    field: "radius".into(),
                    message: format!(
                        "{r} m exceeds {MAX_RADIUS_SHARE} of the scene's diagonal ({diagonal} m): every gather would visit much of the map"
                    ),
                });
            }
        }
        let paths = u64::from(self.paths);
        let photons = paths * u64::from(self.max_photons);
        let cells = photons / u64::from((self.gather_photons / 4).max(1));
        let with_origins = super::store::keeps_origins(scene);
        product_sum(
            "paths",
            &[
                (photons, PhotonRow::BYTES_PER_PHOTON + grid::BYTES_PER_PHOTON),
                (paths, PathStore::bytes_per_path(with_origins)),
                (cells, grid::BYTES_PER_CELL),
                (pixels, pixels::BYTES_PER_PIXEL),
            ],
        )
    }

    pub fn validate(&self) -> Result<(), TechniqueError> {
        let bad = |field: &str, message: String| Err(TechniqueError::InvalidConfig { field: field.into(), message });
        if self.paths == 0 || self.paths > MAX_PATHS {
            return bad("paths", format!("must lie in 1..={MAX_PATHS}"));
        }
        if self.max_photons == 0 || self.max_photons > PathWord::MAX_PHOTONS {
            return bad("max_photons", format!("must lie in 1..={}", PathWord::MAX_PHOTONS));
        }
        if !(self.threshold.is_finite() && (0.0..=1.0).contains(&self.threshold)) {
            return bad("threshold", "must lie in 0..=1 (a relative energy change)".into());
        }
        if let Err(message) = self.distribution_map.validate() {
            return bad("distribution_map", message);
        }
        if self.gather_photons == 0 || self.gather_photons > MAX_GATHER_PHOTONS {
            return bad("gather_photons", format!("must lie in 1..={MAX_GATHER_PHOTONS}"));
        }
        if let Some(r) = self.radius {
            if !(r.is_finite() && r > 0.0) {
                return bad("radius", "must be a positive number of meters".into());
            }
        }
        if !(self.refine.is_finite() && (0.0..=MAX_REFINE).contains(&self.refine)) {
            return bad("refine", format!("must lie in 0..={MAX_REFINE} (a share of the paths)"));
        }
        if self.spp == 0 || self.spp > crate::technique::path::MAX_SPP {
            return bad("spp", format!("must lie in 1..={}", crate::technique::path::MAX_SPP));
        }
        Ok(())
    }
}

/// The registry's description (`technique/registry.rs`).
pub const DESCRIPTION: TechniqueDescription = TechniqueDescription {
    id: "photon_reuse",
    summary:
        "Resident photon paths verified every tick; only the paths an edit invalidated are retraced (Moreau et al.)",
    shorthand: Some(("reuse", "threshold")),
    parameters: &[
        Parameter {
            name: "paths",
            kind: ParameterKind::Integer { min: 1000, max: 4_000_000 },
            help: "resident photon paths",
        },
        Parameter {
            name: "reuse",
            kind: ParameterKind::Choice { choices: &["off", "naive", "error"] },
            help:
                "off retraces everything; naive keeps unhit paths; error also keeps paths whose energy barely changed",
        },
        Parameter {
            name: "threshold",
            kind: ParameterKind::Number { min: 0.0, max: 1.0 },
            help: "error mode's relative energy change T",
        },
        SPP,
    ],
    test_specs: &["photon_reuse:paths=20000"],
};
