//! The JSON Schemas in proto/ and the loader agree: every bundled document validates against its
//! schema, the schemas' own examples load, and documents the loader rejects for their shape are
//! rejected by the schema too.
mod common;
use common::scenes_dir;
use jsonschema::{Resource, Validator};
use relume::scene::animation::Animation;
use relume::scene::Scene;
use serde_json::Value;
use std::path::Path;

fn read(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn proto(name: &str) -> Value {
    read(&Path::new(env!("CARGO_MANIFEST_DIR")).join("proto").join(name))
}

fn validator(name: &str) -> Validator {
    let scene = proto("scene.schema.json");
    jsonschema::options()
        .with_resource("https://relume.invalid/proto/scene.schema.json", Resource::from_contents(scene).unwrap())
        .build(&proto(name))
        .unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn errors(v: &Validator, doc: &Value) -> Vec<String> {
    v.iter_errors(doc).map(|e| format!("{} at {}", e, e.instance_path)).collect()
}

#[test]
fn bundled_scenes_and_animations_match_their_schemas() {
    let scene_schema = validator("scene.schema.json");
    let anim_schema = validator("animation.schema.json");
    let mut checked = 0;
    for entry in std::fs::read_dir(scenes_dir()).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if !name.ends_with(".json") {
            continue;
        }
        let doc = read(&path);
        let v = if name.ends_with(".anim.json") { &anim_schema } else { &scene_schema };
        let errs = errors(v, &doc);
        assert!(errs.is_empty(), "{name}: {errs:?}");
        checked += 1;
    }
    assert!(checked >= 18, "only {checked} documents found");
}

/// Every bundled scene, as the server sends it back (`GET /v1/sessions/{id}/scene` and the
/// snapshot's scene are the loaded scene's description), still matches the scene schema: an
/// optional field the loader filled in must be left out, never sent as `null`.
#[test]
fn loaded_scenes_serialize_back_to_their_schema() {
    let scene_schema = validator("scene.schema.json");
    let mut spots = 0;
    let mut names: Vec<String> = std::fs::read_dir(scenes_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".json") && !n.ends_with(".anim.json"))
        .collect();
    names.sort();
    assert!(names.len() >= 10, "{names:?}");
    for name in &names {
        let scene = common::load(name);
        let doc = serde_json::to_value(scene.desc()).unwrap();
        spots += doc["lights"].as_array().map_or(0, |l| l.iter().filter(|l| l["emitter"]["type"] == "spot").count());
        let errs = errors(&scene_schema, &doc);
        assert!(errs.is_empty(), "{name} as served back: {errs:?}");
    }
    assert!(spots > 0, "no bundled scene has a spot light, so the null case is not exercised");
    // Negative control: the schema refuses a spot light's `falloff_start_deg: null`.
    let mut doc = serde_json::to_value(common::load("maze.json").desc()).unwrap();
    let spot = doc["lights"].as_array_mut().unwrap().iter_mut().find(|l| l["emitter"]["type"] == "spot").unwrap();
    spot["emitter"]["falloff_start_deg"] = Value::Null;
    assert!(!errors(&scene_schema, &doc).is_empty(), "a null falloff_start_deg passed the schema");
}

#[test]
fn websocket_examples_match_the_ws_schema() {
    let ws = validator("ws.schema.json");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/examples");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.file_name().unwrap().to_string_lossy().starts_with("ws-") {
            let errs = errors(&ws, &read(&path));
            assert!(errs.is_empty(), "{}: {errs:?}", path.display());
            n += 1;
        }
    }
    assert_eq!(n, 10);
    // Edits inside the HTTP example follow the same edit schema.
    let edits = read(&dir.join("edits.request.json"));
    let msg = serde_json::json!({"type": "edits", "edits": edits["edits"]});
    assert!(errors(&ws, &msg).is_empty(), "{:?}", errors(&ws, &msg));
    assert!(!errors(&ws, &serde_json::json!({"type": "subscribe", "every": 0})).is_empty());
    assert!(!errors(&ws, &serde_json::json!({"type": "update"})).is_empty(), "an update must change something");
}

#[test]
fn schema_examples_validate_and_load() {
    let scene_schema = validator("scene.schema.json");
    for example in proto("scene.schema.json")["examples"].as_array().unwrap() {
        assert!(errors(&scene_schema, example).is_empty());
        let desc = serde_json::from_value(example.clone()).unwrap();
        let dir = scenes_dir();
        let scene = Scene::from_desc(desc, &dir, &dir).expect("the schema's example scene loads");
        let anim_schema = validator("animation.schema.json");
        for anim in proto("animation.schema.json")["examples"].as_array().unwrap() {
            assert!(errors(&anim_schema, anim).is_empty());
            let anim: Animation = serde_json::from_value(anim.clone()).unwrap();
            anim.validate(&scene).expect("the schema's example animation drives the example scene");
        }
    }
}

#[test]
fn shape_errors_are_caught_by_schema_and_loader_alike() {
    let schema = validator("scene.schema.json");
    let base = read(&scenes_dir().join("cornell-box.json"));
    type Mutation = Box<dyn Fn(&mut Value)>;
    let mutations: Vec<(&str, Mutation)> = vec![
        ("unknown field", Box::new(|v| v["objects"][0]["colour"] = "red".into())),
        ("unknown shape", Box::new(|v| v["objects"][0]["shape"] = serde_json::json!({"type": "teapot"}))),
        (
            "missing camera field",
            Box::new(|v| v["camera"].as_object_mut().unwrap().remove("vfov_deg").map(|_| ()).unwrap_or(())),
        ),
        ("wrong type", Box::new(|v| v["camera"]["resolution"] = serde_json::json!(["256", 256]))),
        (
            "reflectance above one",
            Box::new(|v| v["materials"]["white"]["reflectance"] = serde_json::json!([1.5, 0.5, 0.5])),
        ),
        ("negative radiance", Box::new(|v| v["lights"][0]["emitter"]["radiance"] = serde_json::json!([-1, 0, 0]))),
    ];
    for (what, mutate) in mutations {
        let mut doc = base.clone();
        mutate(&mut doc);
        assert!(!errors(&schema, &doc).is_empty(), "schema accepted: {what}");
        let dir = scenes_dir();
        let loaded = serde_json::from_value::<relume::scene::SceneDesc>(doc)
            .map_err(|e| e.to_string())
            .and_then(|d| Scene::from_desc(d, &dir, &dir).map_err(|e| e.to_string()));
        assert!(loaded.is_err(), "loader accepted: {what}");
    }
}
