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

    /// The spec that parses back to this configuration, `from_spec(&c.label()) == c` (for labels
    /// and file names): the technique's usual head (`path:spp=1`, `photon_reuse:error@0.001`,
    /// `instant_cache:temporal@256`), then `:KEY=VALUE` for every other field that differs from
    /// the technique's defaults, in key order. Two configurations share a label only if equal.
    /// (A nested object, `path`'s `preview_filter`, is written as JSON: no spec can set one.)
    pub fn label(&self) -> String {
        let (mut label, written) = self.label_head();
        let fields = serde_json::to_value(self).ok();
        let defaults = super::registry::default_config(self.id()).and_then(|d| serde_json::to_value(d).ok());
        let (Some(Value::Object(fields)), Some(Value::Object(defaults))) = (fields, defaults) else { return label };
        for (key, value) in &fields {
            if key != "id" && !written.contains(&key.as_str()) && defaults.get(key) != Some(value) {
                label.push_str(&format!(":{key}={}", spec_value(value)));
            }
        }
        label
    }

    /// The head of [`TechniqueConfig::label`] and the fields it states.
    fn label_head(&self) -> (String, &'static [&'static str]) {
        match self {
            TechniqueConfig::Path(c) => (format!("path:spp={}", c.spp), &["spp"]),
            TechniqueConfig::InstantCache(c) => {
                (format!("instant_cache:{}@{}", variant_name(c.mode), c.vpls), &["mode", "vpls"])
            }
            TechniqueConfig::ParticleGi(_) => ("particle_gi".into(), &[]),
            TechniqueConfig::Bdpt(c) => (format!("bdpt:spp={}", c.spp), &["spp"]),
            TechniqueConfig::PhotonReuse(c) => {
                let mode = variant_name(c.reuse);
                if c.reuse == super::photon_reuse::ReuseMode::Error {
                    (format!("photon_reuse:{mode}@{}", c.threshold), &["reuse", "threshold"])
                } else {
                    (format!("photon_reuse:{mode}"), &["reuse"])
                }
            }
        }
    }
}

/// A unit enum variant's name as its JSON has it (`temporal`, `error`).
fn variant_name(variant: impl serde::Serialize) -> String {
    serde_json::to_value(variant).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default()
}

/// A field's value as a spec writes it: strings bare, numbers that are `f32`s in their
/// shortest form (`0.07`, not the `f64` widening's `0.07000000029802322`), the rest as JSON.
fn spec_value(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        Value::Number(n) if n.is_f64() => {
            let wide = n.as_f64().unwrap_or(f64::NAN);
            let narrow = wide as f32;
            if f64::from(narrow) == wide {
                narrow.to_string()
            } else {
                wide.to_string()
            }
        }
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::technique::photon_reuse::ReuseMode;
    use crate::technique::registry::{Parameter, ParameterKind};

    #[test]
    fn specs_parse_into_the_service_configuration() {
        let c = TechniqueConfig::from_spec("photon_reuse:error@0.01:paths=2000").unwrap();
        let TechniqueConfig::PhotonReuse(p) = &c else { panic!("{c:?}") };
        assert_eq!((p.reuse, p.threshold, p.paths), (ReuseMode::Error, 0.01, 2000));
        assert_eq!(c.label(), "photon_reuse:error@0.01:paths=2000");
        let c = TechniqueConfig::from_spec("path:spp=4").unwrap();
        assert_eq!(c, serde_json::from_str(r#"{"id": "path", "spp": 4}"#).unwrap());
        assert_eq!(TechniqueConfig::from_spec("photon_reuse:naive").unwrap().label(), "photon_reuse:naive");
    }

    /// Specs of a configuration with `parameter` set to a value other than its default.
    fn specs_off_default(id: &str, parameter: &Parameter, default: &Value) -> Vec<String> {
        let name = parameter.name;
        match parameter.kind {
            ParameterKind::Integer { min, max } => {
                let v = if default.as_u64() == Some(max) { min } else { max };
                vec![format!("{id}:{name}={v}")]
            }
            ParameterKind::Number { min, max } => {
                let quarter = min + 0.25 * (max - min);
                let v = if default.as_f64() == Some(quarter) { min + 0.75 * (max - min) } else { quarter };
                vec![format!("{id}:{name}={v}")]
            }
            ParameterKind::Choice { choices } => choices.iter().map(|c| format!("{id}:{name}={c}")).collect(),
            ParameterKind::Boolean => vec![format!("{id}:{name}={}", !default.as_bool().unwrap_or(false))],
        }
    }

    #[test]
    fn labels_parse_back_to_their_configuration() {
        // Property: a configuration's label is a spec that parses back to it, so configurations
        // that differ in any field have different labels (`bench error` groups its results and
        // names its files by label). Configurations: each technique's defaults, its test specs,
        // and each of its registry parameters set off its default, alone and all together.
        // Negative control, by hand: labels of the head alone (without the `:KEY=VALUE` of the
        // other fields) fail, first on `path:regeneration=false`.
        let mut labels = std::collections::HashMap::new();
        for d in crate::technique::registry::REGISTRY {
            let defaults = serde_json::to_value(crate::technique::registry::default_config(d.id).unwrap()).unwrap();
            let mut specs: Vec<String> = vec![d.id.to_string()];
            specs.extend(d.test_specs.iter().map(|s| s.to_string()));
            for p in d.parameters {
                specs.extend(specs_off_default(d.id, p, &defaults[p.name]));
            }
            let all_off: Vec<String> =
                d.parameters.iter().filter_map(|p| specs_off_default(d.id, p, &defaults[p.name]).pop()).collect();
            specs.push(
                std::iter::once(d.id.to_string())
                    .chain(all_off.iter().map(|s| s.split_once(':').unwrap().1.to_string()))
                    .collect::<Vec<_>>()
                    .join(":"),
            );
            for spec in specs {
                let config = TechniqueConfig::from_spec(&spec).unwrap_or_else(|e| panic!("{spec}: {e}"));
                let label = config.label();
                let back = TechniqueConfig::from_spec(&label).unwrap_or_else(|e| panic!("{spec} -> {label}: {e}"));
                assert_eq!(back, config, "{spec}: its label {label} parses to another configuration");
                if let Some(other) = labels.insert(label.clone(), config.clone()) {
                    assert_eq!(other, config, "{label} labels two configurations");
                }
            }
        }
        assert!(labels.len() > 20, "only {} distinct configurations were checked", labels.len());
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
