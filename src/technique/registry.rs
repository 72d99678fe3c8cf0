//! One description per technique, kept in its folder and listed once in [`REGISTRY`]: its id,
//! a one-line summary, its CLI spec shorthands and the parameters a user reaches for first,
//! with their ranges. The spec parser, `GET /v1/techniques` (and through it the viewer's
//! technique picker), the OpenAPI test and the test matrix all read it.
//!
//! Defaults are not restated here: they are what the technique's configuration deserializes
//! to from `{"id": ID}` ([`default_config`]).
use serde::Serialize;

/// How a parameter is entered.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ParameterKind {
    Integer { min: u64, max: u64 },
    Number { min: f64, max: f64 },
    Choice { choices: &'static [&'static str] },
    Boolean,
}

/// One of a technique's main parameters (a field of its JSON configuration).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Parameter {
    pub name: &'static str,
    #[serde(flatten)]
    pub kind: ParameterKind,
    pub help: &'static str,
}

/// What the rest of relume knows of a technique besides its code.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TechniqueDescription {
    pub id: &'static str,
    pub summary: &'static str,
    /// The fields a CLI spec's `VARIANT` and `@VALUE` set (`photon_reuse:error@0.001`).
    #[serde(skip)]
    pub shorthand: Option<(&'static str, &'static str)>,
    /// The parameters the viewer offers; the full set is the configuration's schema.
    pub parameters: &'static [Parameter],
    /// Small configurations (CLI specs) the test matrix runs: the hard cases, the Embree ISA
    /// renders, the mesh-light twins.
    #[serde(skip)]
    pub test_specs: &'static [&'static str],
}

/// Camera samples per pixel per tick: a main parameter of every technique that has it.
pub const SPP: Parameter = Parameter {
    name: "spp",
    kind: ParameterKind::Integer { min: 1, max: 64 },
    help: "camera samples per pixel per tick",
};

/// Every technique, in the order the viewer lists them.
pub const REGISTRY: &[&TechniqueDescription] = &[
    &super::path::DESCRIPTION,
    &super::photon_reuse::DESCRIPTION,
    &super::bdpt::DESCRIPTION,
    &super::instant_cache::DESCRIPTION,
    &super::particle_gi::DESCRIPTION,
];

/// The technique ids, from [`REGISTRY`].
pub const TECHNIQUE_IDS: [&str; REGISTRY.len()] = {
    let mut ids = [""; REGISTRY.len()];
    let mut i = 0;
    while i < REGISTRY.len() {
        ids[i] = REGISTRY[i].id;
        i += 1;
    }
    ids
};

pub fn describe(id: &str) -> Option<&'static TechniqueDescription> {
    REGISTRY.iter().copied().find(|d| d.id == id)
}

/// A technique's configuration at its defaults.
pub fn default_config(id: &str) -> Option<super::TechniqueConfig> {
    serde_json::from_value(serde_json::json!({ "id": id })).ok()
}
