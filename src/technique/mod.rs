//! The `Technique` interface every light-transport method implements, its configuration
//! ([`TechniqueConfig`], serde-tagged by `id`), its typed statistics, and [`build`], the one
//! factory.
//!
//! A technique is driven by the engine once per tick: `update` sees what the edits changed
//! (verify, invalidate, retrace), then `render` adds samples to the film. The figures `update`
//! gathers travel to `render` as a value ([`UpdateStats`]): per-tick figures are not fields of
//! the state a technique keeps across ticks. Per-tick calls go through `Box<dyn Technique>`;
//! per-ray variety inside a technique is a closed `enum`.
//!
//! Adding a technique: its folder holds the code, its configuration and its registry
//! `DESCRIPTION` (id, summary, spec shorthands, main parameters, test configurations). Outside
//! it, three files change: this one (the `TechniqueConfig` and `TechniqueStats` variants and
//! the match arms), `registry.rs` (one line in `REGISTRY`), and `proto/openapi.yaml` (the
//! configuration's schema, which `tests/openapi.rs` checks against the registry). The spec
//! parser, `GET /v1/techniques`, the viewer's picker and the test matrix read the registry.
pub mod bdpt;
pub mod box_tree;
pub mod budget;
pub mod camera_chain;
pub mod instant_cache;
pub mod nee;
pub mod particle_gi;
pub mod path;
pub mod photon_reuse;
pub mod registry;
mod spec;

pub use budget::{MemoryEstimate, ResidentMemory};
pub use registry::TECHNIQUE_IDS;

use crate::film::Film;
use crate::scene::edits::SceneDelta;
use crate::scene::{Scene, SceneAccel};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Everything a technique may read during a tick.
pub struct RenderContext<'a> {
    pub scene: &'a Scene,
    pub accel: &'a SceneAccel,
    /// The session's seed; random streams derive from (seed, tick, pixel, sample).
    pub seed: u64,
    pub tick: u64,
}

#[derive(Debug, Error, Clone, PartialEq)]
pub enum TechniqueError {
    #[error("invalid technique configuration: {field}: {message}")]
    InvalidConfig { field: String, message: String },
    /// Valid, but more than the session may allocate (checked before allocating).
    #[error("{field}: {message}")]
    TooLarge { field: String, message: String },
    #[error("embree: {0}")]
    Embree(#[from] crate::embree::EmbreeError),
}

/// Rays traced, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RayCounts {
    /// Camera rays.
    pub primary: u64,
    /// Closest-hit rays after a scattering event.
    pub secondary: u64,
    /// Occlusion rays for next-event estimation.
    pub shadow: u64,
}

impl RayCounts {
    pub fn total(&self) -> u64 {
        self.primary + self.secondary + self.shadow
    }

    pub fn merge(self, o: RayCounts) -> RayCounts {
        RayCounts {
            primary: self.primary + o.primary,
            secondary: self.secondary + o.secondary,
            shadow: self.shadow + o.shadow,
        }
    }
}

/// What one `render` call did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderStats {
    pub rays: RayCounts,
    /// Technique-specific figures.
    pub detail: TechniqueStats,
}

/// Typed, technique-specific statistics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "id", rename_all = "snake_case")]
pub enum TechniqueStats {
    Path(path::PathStats),
    PhotonReuse(Box<photon_reuse::PhotonStats>),
    Bdpt(Box<bdpt::BdptStats>),
    InstantCache(Box<instant_cache::InstantCacheStats>),
    ParticleGi(Box<particle_gi::ParticleStats>),
}

impl TechniqueStats {
    /// What the technique keeps resident between ticks (its light-transport state; the film
    /// is the engine's). `path` and `bdpt` keep nothing.
    pub fn memory(&self) -> &ResidentMemory {
        match self {
            TechniqueStats::Path(s) => &s.memory,
            TechniqueStats::PhotonReuse(s) => &s.memory,
            TechniqueStats::Bdpt(s) => &s.memory,
            TechniqueStats::InstantCache(s) => &s.memory,
            TechniqueStats::ParticleGi(s) => &s.memory,
        }
    }
}

/// Which technique to run, with its parameters. JSON: `{"id": "path", "spp": 4, ...}`.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "id", rename_all = "snake_case")]
pub enum TechniqueConfig {
    Path(path::PathConfig),
    PhotonReuse(photon_reuse::PhotonReuseConfig),
    Bdpt(bdpt::BdptConfig),
    InstantCache(instant_cache::InstantCacheConfig),
    ParticleGi(particle_gi::ParticleGiConfig),
}

impl<'de> Deserialize<'de> for TechniqueConfig {
    /// As `#[serde(tag = "id")]` would, except that an error in a technique's fields names the
    /// field (`paths: invalid value ...`): serde's tagged enums buffer the fields and lose the
    /// path to the one at fault.
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let mut fields = serde_json::Map::<String, serde_json::Value>::deserialize(deserializer)?;
        let id = match fields.remove("id") {
            Some(serde_json::Value::String(id)) => id,
            Some(other) => return Err(D::Error::custom(format!("id: {other} is not a technique id"))),
            None => return Err(D::Error::missing_field("id")),
        };
        fn fields_of<T: serde::de::DeserializeOwned, E: serde::de::Error>(
            fields: serde_json::Map<String, serde_json::Value>,
        ) -> Result<T, E> {
            serde_path_to_error::deserialize(serde_json::Value::Object(fields)).map_err(|e| {
                let path = e.path().to_string();
                match path.as_str() {
                    "" | "." => E::custom(e.into_inner()),
                    _ => E::custom(format!("{path}: {}", e.into_inner())),
                }
            })
        }
        match id.as_str() {
            "path" => fields_of(fields).map(TechniqueConfig::Path),
            "photon_reuse" => fields_of(fields).map(TechniqueConfig::PhotonReuse),
            "bdpt" => fields_of(fields).map(TechniqueConfig::Bdpt),
            "instant_cache" => fields_of(fields).map(TechniqueConfig::InstantCache),
            "particle_gi" => fields_of(fields).map(TechniqueConfig::ParticleGi),
            other => Err(D::Error::unknown_variant(other, &TECHNIQUE_IDS)),
        }
    }
}

impl TechniqueConfig {
    pub fn id(&self) -> &'static str {
        match self {
            TechniqueConfig::Path(_) => "path",
            TechniqueConfig::PhotonReuse(_) => "photon_reuse",
            TechniqueConfig::Bdpt(_) => "bdpt",
            TechniqueConfig::InstantCache(_) => "instant_cache",
            TechniqueConfig::ParticleGi(_) => "particle_gi",
        }
    }

    /// Camera samples per pixel each tick renders.
    pub fn spp_per_tick(&self) -> u32 {
        match self {
            TechniqueConfig::Path(c) => c.spp,
            TechniqueConfig::PhotonReuse(c) => c.spp,
            TechniqueConfig::Bdpt(c) => c.spp,
            TechniqueConfig::InstantCache(c) => c.spp,
            TechniqueConfig::ParticleGi(_) => 1,
        }
    }

    /// Sets the camera samples per pixel each tick renders (`particle_gi` renders one, plus
    /// its adaptive supersampling, and ignores this).
    pub fn set_spp_per_tick(&mut self, spp: u32) {
        match self {
            TechniqueConfig::Path(c) => c.spp = spp,
            TechniqueConfig::PhotonReuse(c) => c.spp = spp,
            TechniqueConfig::Bdpt(c) => c.spp = spp,
            TechniqueConfig::InstantCache(c) => c.spp = spp,
            TechniqueConfig::ParticleGi(_) => {}
        }
    }

    /// Checks every parameter, naming the first one at fault.
    pub fn validate(&self) -> Result<(), TechniqueError> {
        match self {
            TechniqueConfig::Path(c) => c.validate(),
            TechniqueConfig::PhotonReuse(c) => c.validate(),
            TechniqueConfig::Bdpt(c) => c.validate(),
            TechniqueConfig::InstantCache(c) => c.validate(),
            TechniqueConfig::ParticleGi(c) => c.validate(),
        }
    }

    /// Resident memory the technique will hold on `scene` at `pixels` pixels, before anything
    /// is allocated (see `budget.rs`). The film, which every technique has, is not included;
    /// `bdpt`'s splat buffer, which only it adds to the film, is.
    pub fn resident_estimate(
        &self,
        scene: &crate::scene::Scene,
        pixels: u64,
    ) -> Result<MemoryEstimate, TechniqueError> {
        match self {
            TechniqueConfig::Path(_) => Ok(MemoryEstimate { bytes: 0, field: "id" }),
            TechniqueConfig::Bdpt(_) => Ok(MemoryEstimate {
                bytes: pixels.saturating_mul(crate::film::Film::SPLAT_BYTES_PER_PIXEL),
                field: "id",
            }),
            TechniqueConfig::PhotonReuse(c) => c.resident_estimate(scene, pixels),
            TechniqueConfig::InstantCache(c) => c.resident_estimate(pixels),
            TechniqueConfig::ParticleGi(c) => c.resident_estimate(scene),
        }
    }

    /// Resident photon paths the technique keeps (0 for techniques without any).
    pub fn photon_paths(&self) -> u32 {
        match self {
            TechniqueConfig::Path(_)
            | TechniqueConfig::Bdpt(_)
            | TechniqueConfig::InstantCache(_)
            | TechniqueConfig::ParticleGi(_) => 0,
            TechniqueConfig::PhotonReuse(c) => c.paths,
        }
    }
}

/// The figures a tick's `update` gathered, in the technique's own stats type, on their way to
/// the same tick's `render`. Empty for a technique whose `update` measures nothing.
#[derive(Default)]
pub struct UpdateStats(Option<Box<dyn std::any::Any + Send>>);

impl UpdateStats {
    pub fn new<T: std::any::Any + Send>(stats: T) -> UpdateStats {
        UpdateStats(Some(Box::new(stats)))
    }

    /// The figures as a `T`, or `T`'s default if there are none of that type.
    pub fn take<T: std::any::Any + Default>(self) -> T {
        self.0.and_then(|b| b.downcast::<T>().ok()).map_or_else(T::default, |b| *b)
    }
}

/// A light-transport method driven by the engine, one tick at a time.
pub trait Technique: Send {
    fn id(&self) -> &'static str;

    /// Reacts to what changed since the last tick (an empty delta on the first tick). Returns
    /// the figures it gathered, which the engine hands to this tick's `render`.
    fn update(&mut self, ctx: &RenderContext, delta: &SceneDelta) -> Result<UpdateStats, TechniqueError>;

    /// Asked after `update`: should the engine restart the whole film for this delta? The
    /// default is any change. A technique that restarts only the pixels a change touched
    /// answers no and does that itself in `render` ([`Film::restart_pixels`]).
    fn restarts_whole_film(&self, delta: &SceneDelta) -> bool {
        !delta.is_empty()
    }

    /// Adds this tick's samples to `film`; `update` holds what this tick's `update` returned,
    /// which the technique completes into its [`RenderStats`].
    fn render(
        &mut self,
        ctx: &RenderContext,
        film: &mut Film,
        update: UpdateStats,
    ) -> Result<RenderStats, TechniqueError>;

    /// An edge-preserving filter the engine applies to the resolved image (previews only).
    fn preview_filter(&self) -> Option<path::PreviewFilter> {
        None
    }
}

/// The one factory: validates the configuration and builds the technique for `scene`.
pub fn build(config: &TechniqueConfig, scene: &Scene) -> Result<Box<dyn Technique>, TechniqueError> {
    match config {
        TechniqueConfig::Path(c) => Ok(Box::new(path::PathTracer::new(c.clone(), scene)?)),
        TechniqueConfig::PhotonReuse(c) => Ok(Box::new(photon_reuse::PhotonReuse::new(c.clone(), scene)?)),
        TechniqueConfig::Bdpt(c) => Ok(Box::new(bdpt::Bdpt::new(c.clone(), scene)?)),
        TechniqueConfig::InstantCache(c) => Ok(Box::new(instant_cache::InstantCache::new(c.clone(), scene)?)),
        TechniqueConfig::ParticleGi(c) => Ok(Box::new(particle_gi::ParticleGi::new(c.clone(), scene)?)),
    }
}
