//! Technique specs for the command line: `ID[:VARIANT][@VALUE][:KEY=VALUE]...`, e.g.
//! `photon_reuse:error@0.001`, `photon_reuse:naive:paths=200000`, `path:spp=4`.
//!
//! A spec is turned into the JSON object the service accepts (`{"id": ..., key: value}`) and
//! parsed by the same serde code and validation, so the CLI and the server share one parser.
//! `VARIANT` and `@VALUE` are shorthands for a technique's mode field and its parameter:
//! `reuse` and `threshold` for `photon_reuse`. Values parse as JSON when they can (numbers,
//! booleans, arrays) and as strings otherwise.
use super::{TechniqueConfig, TechniqueError};
use serde_json::{Map, Value};

/// The fields a technique's `VARIANT` and `@VALUE` shorthands set (from the registry).
fn shorthand_fields(id: &str) -> Option<(&'static str, &'static str)> {
    super::registry::describe(id).and_then(|d| d.shorthand)
}

fn bad(message: String) -> TechniqueError {
    TechniqueError::InvalidConfig { field: "spec".into(), message }
}

fn value_of(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|_| Value::String(text.to_string()))
}

impl TechniqueConfig {
    /// Parses and validates a spec (see the module doc).
    pub fn from_spec(spec: &str) -> Result<TechniqueConfig, TechniqueError> {
        let mut parts = spec.split(':');
        let id = parts.next().unwrap_or_default().trim();
        if id.is_empty() {
            return Err(bad(format!("'{spec}' names no technique")));
        }
        if !super::TECHNIQUE_IDS.contains(&id) {
            return Err(bad(format!("unknown technique '{id}' (available: {})", super::TECHNIQUE_IDS.join(", "))));
        }
        let mut object = Map::new();
        object.insert("id".into(), Value::String(id.into()));
        for (i, part) in parts.enumerate() {
            if let Some((key, value)) = part.split_once('=') {
                object.insert(key.trim().into(), value_of(value.trim()));
                continue;
            }
            let Some((variant_key, value_key)) = shorthand_fields(id).filter(|_| i == 0) else {
                return Err(bad(format!("'{part}' in '{spec}' is not KEY=VALUE")));
            };
            let (variant, value) = match part.split_once('@') {
                Some((v, x)) => (v, Some(x)),
                None => (part, None),
            };
            object.insert(variant_key.into(), Value::String(variant.trim().into()));
            if let Some(x) = value {
                object.insert(value_key.into(), value_of(x.trim()));
            }
        }
        let config: TechniqueConfig =
            serde_json::from_value(Value::Object(object)).map_err(|e| bad(format!("'{spec}': {e}")))?;
        config.validate()?;
        Ok(config)
    }

    /// The spec that parses back to this configuration's id and mode (for labels and file names).
    pub fn label(&self) -> String {
        match self {
            TechniqueConfig::Path(c) => format!("path:spp={}", c.spp),
            TechniqueConfig::InstantCache(c) => {
                let mode = serde_json::to_value(c.mode).ok().and_then(|v| v.as_str().map(str::to_string));
                let on_demand = c.reevaluation == super::instant_cache::Reevaluation::OnDemand;
                let theta = c.normal_tolerance;
                let refine = c.refine_ticks;
                format!(
                    "instant_cache:{}@{}{}{}{}",
                    mode.unwrap_or_default(),
                    c.vpls,
                    if on_demand { ":reevaluation=on_demand" } else { "" },
                    if theta == super::instant_cache::DEFAULT_NORMAL_TOLERANCE {
                        String::new()
                    } else {
                        format!(":normal_tolerance={theta}")
                    },
                    if refine == super::instant_cache::DEFAULT_REFINE_TICKS {
                        String::new()
                    } else {
                        format!(":refine_ticks={refine}")
                    }
                )
            }
            TechniqueConfig::ParticleGi(c) => match c.particles {
                Some(n) => format!("particle_gi:particles={n}"),
                None => "particle_gi".into(),
            },
            TechniqueConfig::Bdpt(c) => format!(
                "bdpt:spp={}{}{}{}",
                c.spp,
                if c.light_per_eye_path { ":light_per_eye_path=true" } else { "" },
                if c.permute { "" } else { ":permute=false" },
                if c.light_tracing_only { ":light_tracing_only=true" } else { "" }
            ),
            TechniqueConfig::PhotonReuse(c) => {
                let mode = serde_json::to_value(c.reuse).ok().and_then(|v| v.as_str().map(str::to_string));
                let mode = mode.unwrap_or_default();
                if c.reuse == super::photon_reuse::ReuseMode::Error {
                    format!("photon_reuse:{mode}@{}", c.threshold)
                } else {
                    format!("photon_reuse:{mode}")
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::technique::photon_reuse::ReuseMode;

    #[test]
    fn specs_parse_into_the_service_configuration() {
        let c = TechniqueConfig::from_spec("photon_reuse:error@0.01:paths=2000").unwrap();
        let TechniqueConfig::PhotonReuse(p) = &c else { panic!("{c:?}") };
        assert_eq!((p.reuse, p.threshold, p.paths), (ReuseMode::Error, 0.01, 2000));
        assert_eq!(c.label(), "photon_reuse:error@0.01");
        let c = TechniqueConfig::from_spec("path:spp=4").unwrap();
        assert_eq!(c, serde_json::from_str(r#"{"id": "path", "spp": 4}"#).unwrap());
        assert_eq!(TechniqueConfig::from_spec("photon_reuse:naive").unwrap().label(), "photon_reuse:naive");
    }

    #[test]
    fn bad_specs_say_what_is_wrong() {
        for (spec, words) in [
            ("", "names no technique"),
            ("warp", "unknown technique 'warp'"),
            ("path:fast", "not KEY=VALUE"),
            ("photon_reuse:sometimes", "unknown variant"),
            ("photon_reuse:error@2", "threshold"),
            ("path:spp=0", "spp"),
            ("path:nonsense=1", "unknown field"),
        ] {
            let e = TechniqueConfig::from_spec(spec).unwrap_err().to_string();
            assert!(e.contains(words), "{spec}: {e}");
        }
    }
}
