//! Scene validation: every error names the field (or file) at fault, and nothing invalid loads.
use relume::scene::{Scene, SceneError};
use std::path::PathBuf;

/// A scenes root in a fresh temp folder, with a small valid OBJ and a degenerate one.
fn root(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("relume-validation-{}-{tag}", std::process::id()));
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::write(dir.join("meshes/tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(
        dir.join("meshes/degenerate.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 2\n",
    )
    .unwrap();
    std::fs::write(dir.join("meshes/flat.obj"), "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").unwrap();
    std::fs::write(dir.join("meshes/nan.obj"), "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(
        dir.join("meshes/nan-normal.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 0 nan 1\nf 1//1 2//2 3//1\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.parent().unwrap().join("outside-relume")).ok();
    dir
}

const BASE: &str = r#"{
  "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "vfov_deg": 40, "resolution": [32, 32]},
  "materials": {"m": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
  "objects": [{"name": "o", "shape": {"type": "mesh", "path": "meshes/tri.obj"}, "material": "m"}],
  "lights": [{"name": "l", "emitter": {"type": "point", "intensity": [1, 1, 1]}, "transform": {"translation": [0, 2, 2]}}]
}"#;

fn load_with(tag: &str, edit: impl FnOnce(&mut serde_json::Value)) -> Result<Scene, SceneError> {
    let root = root(tag);
    let mut v: serde_json::Value = serde_json::from_str(BASE).unwrap();
    edit(&mut v);
    let path = root.join("scene.json");
    // serde_json cannot write NaN; tests that need out-of-range numbers patch the text.
    std::fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
    Scene::load(&path, &root)
}

fn load_text(tag: &str, text: &str) -> Result<Scene, SceneError> {
    let root = root(tag);
    let path = root.join("scene.json");
    std::fs::write(&path, text).unwrap();
    Scene::load(&path, &root)
}

fn expect_error(result: Result<Scene, SceneError>, field: &str, words: &str) {
    match result {
        Err(SceneError::Invalid { field: f, message }) => {
            assert_eq!(f, field, "wrong field (message: {message})");
            assert!(message.contains(words), "message '{message}' lacks '{words}'");
        }
        Err(other) => panic!("expected an error on {field}, got {other}"),
        Ok(_) => panic!("expected an error on {field}, but the scene loaded"),
    }
}

#[test]
fn the_base_scene_is_valid() {
    let s = load_with("base", |_| {}).unwrap();
    assert_eq!(s.objects.len(), 1);
    assert!(s.dropped_degenerate.is_empty());
}

#[test]
fn infinite_numbers_are_rejected_by_field() {
    // 1e39 overflows f32 to infinity.
    let text = BASE.replace(r#""translation": [0, 2, 2]"#, r#""translation": [0, 1e39, 2]"#);
    expect_error(load_text("inf", &text), "lights[0].transform.translation[1]", "not a finite number");
    let text = BASE.replace(r#""vfov_deg": 40"#, r#""vfov_deg": -1e39"#);
    expect_error(load_text("inf2", &text), "camera.vfov_deg[0]", "not a finite number");
}

#[test]
fn nan_in_an_obj_names_the_vertex() {
    let r = load_with("nan", |v| v["objects"][0]["shape"]["path"] = "meshes/nan.obj".into());
    expect_error(r, "objects[0].shape.path", "vertex 2");
}

#[test]
fn bad_vertex_normals_name_the_vertex_or_the_field() {
    let r = load_with("nan-normal", |v| v["objects"][0]["shape"]["path"] = "meshes/nan-normal.obj".into());
    expect_error(r, "objects[0].shape.path", "normal of vertex 2");
    let triangles = |normals: serde_json::Value| {
        move |v: &mut serde_json::Value| {
            v["objects"][0]["shape"] = serde_json::json!({
                "type": "triangles", "positions": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "indices": [[0, 1, 2]],
                "normals": normals,
            })
        }
    };
    let r = load_with("normal-count", triangles(serde_json::json!([[0, 0, 1], [0, 0, 1]])));
    expect_error(r, "objects[0].shape.normals", "2 normals for 3 positions");
    let text = serde_json::to_string(&{
        let mut v: serde_json::Value = serde_json::from_str(BASE).unwrap();
        triangles(serde_json::json!([[0, 0, 1], [0, 0, 1], [0, 7, 1]]))(&mut v);
        v
    })
    .unwrap()
    .replace("[0,7,1]", "[0,1e39,1]");
    expect_error(load_text("normal-inf", &text), "objects[0].shape.normals[2][1]", "not a finite number");
    // A zero normal loads (a file's degenerate `vn`): it adds nothing where it is interpolated.
    assert!(load_with("normal-zero", triangles(serde_json::json!([[0, 0, 0], [0, 0, 1], [0, 0, 1]]))).is_ok());
}

#[test]
fn zero_length_vectors_are_rejected() {
    expect_error(load_with("up", |v| v["camera"]["up"] = serde_json::json!([0, 0, 0])), "camera.up", "zero-length");
    expect_error(
        load_with("look", |v| v["camera"]["look_at"] = serde_json::json!([0, 0, 5])),
        "camera.look_at",
        "zero length",
    );
    expect_error(
        load_with("scale", |v| v["objects"][0]["transform"] = serde_json::json!({"scale": [1, 0, 1]})),
        "objects[0].transform.scale[1]",
        "zero",
    );
}

#[test]
fn non_unit_quaternions_are_rejected() {
    let r = load_with("quat", |v| v["objects"][0]["transform"] = serde_json::json!({"rotation": [0, 0, 0.5, 0.5]}));
    expect_error(r, "objects[0].transform.rotation", "length 0.70");
    // Within tolerance is accepted (and normalised).
    assert!(load_with("quat-ok", |v| v["objects"][0]["transform"] =
        serde_json::json!({"rotation": [0, 0, 0, 1.0004]}))
    .is_ok());
}

#[test]
fn degenerate_triangles_are_dropped_and_counted() {
    let s = load_with("degen", |v| v["objects"][0]["shape"]["path"] = "meshes/degenerate.obj".into()).unwrap();
    assert_eq!(s.dropped_degenerate, vec![("o".to_string(), 2)]);
    assert_eq!(s.objects[0].mesh.triangles.len(), 1);
}

#[test]
fn empty_meshes_are_rejected() {
    let r = load_with("flat", |v| v["objects"][0]["shape"]["path"] = "meshes/flat.obj".into());
    expect_error(r, "objects[0].shape", "mesh is empty");
}

#[test]
fn missing_files_are_rejected() {
    let r = load_with("missing", |v| v["objects"][0]["shape"]["path"] = "meshes/nope.obj".into());
    expect_error(r, "objects[0].shape.path", "not found");
    match Scene::load(&root("nofile").join("absent.json"), &root("nofile")) {
        Err(SceneError::Io { path, .. }) => assert!(path.ends_with("absent.json")),
        other => panic!("expected an I/O error, got {other:?}"),
    }
}

#[test]
fn paths_escaping_the_scenes_root_are_rejected() {
    let r = load_with("escape", |v| v["objects"][0]["shape"]["path"] = "../../../../../../etc/hostname".into());
    expect_error(r, "objects[0].shape.path", "escapes the scenes root");
    // A target that does not exist is still named as escaping, whatever the checkout's depth.
    let r = load_with("escape-missing", |v| v["objects"][0]["shape"]["path"] = "../no-such-dir/x.obj".into());
    expect_error(r, "objects[0].shape.path", "escapes the scenes root");
    let r = load_with("absolute", |v| v["objects"][0]["shape"]["path"] = "/etc/hostname".into());
    expect_error(r, "objects[0].shape.path", "absolute");
}

#[test]
fn unknown_fields_and_types_name_their_path() {
    expect_error(
        load_with("unknown", |v| v["objects"][0]["colour"] = "red".into()),
        "objects[0].colour",
        "unknown field",
    );
    expect_error(load_with("badtype", |v| v["camera"]["vfov_deg"] = "wide".into()), "camera.vfov_deg", "invalid type");
    expect_error(
        load_with("badshape", |v| v["objects"][0]["shape"] = serde_json::json!({"type": "teapot"})),
        "objects[0].shape.type",
        "unknown variant",
    );
}

#[test]
fn references_and_names_are_checked() {
    expect_error(
        load_with("mat", |v| v["objects"][0]["material"] = "gold".into()),
        "objects[0].material",
        "unknown material 'gold'",
    );
    let r = load_with("dup", |v| {
        let o = v["objects"][0].clone();
        v["objects"].as_array_mut().unwrap().push(o);
    });
    expect_error(r, "objects[1].name", "duplicate object name");
}

#[test]
fn physical_ranges_are_enforced() {
    let r = load_with("rho", |v| v["materials"]["m"]["reflectance"] = serde_json::json!([0.5, 1.2, 0.5]));
    expect_error(r, "materials.m.reflectance", "energy conservation");
    let r = load_with("neg", |v| v["lights"][0]["emitter"]["intensity"] = serde_json::json!([1, -1, 1]));
    expect_error(r, "lights[0].emitter.intensity", "negative");
    let r = load_with("res", |v| v["camera"]["resolution"] = serde_json::json!([0, 10]));
    expect_error(r, "camera.resolution[0]", "outside");
    let r = load_with("fov", |v| v["camera"]["vfov_deg"] = serde_json::json!(180));
    expect_error(r, "camera.vfov_deg", "outside (0, 180)");
}

#[test]
fn world_coordinates_scales_and_emission_are_bounded() {
    // Beyond these, areas and light power overflow f32 (the hazard is in
    // `tests/hostile_clients.rs`). The mesh is a unit triangle.
    let r = load_with("far", |v| v["objects"][0]["transform"] = serde_json::json!({"translation": [0, 2e8, 0]}));
    expect_error(r, "objects[0].transform.translation[1]", "largest world coordinate");
    let r = load_with("huge", |v| v["objects"][0]["transform"] = serde_json::json!({"scale": [1, 1, 1e7]}));
    expect_error(r, "objects[0].transform.scale[2]", "magnitude");
    let r = load_with("tiny", |v| v["objects"][0]["transform"] = serde_json::json!({"scale": [-1e-7, 1, 1]}));
    expect_error(r, "objects[0].transform.scale[0]", "magnitude");
    let r = load_with("reach", |v| {
        v["objects"][0]["transform"] = serde_json::json!({"translation": [9.95e7, 0, 0], "scale": [1e6, 1, 1]})
    });
    expect_error(r, "objects[0].transform", "largest world coordinate");
    let r = load_with("eye", |v| v["camera"]["position"] = serde_json::json!([0, 0, 1e9]));
    expect_error(r, "camera.position[2]", "largest world coordinate");
    let r = load_with("sun", |v| v["lights"][0]["emitter"]["intensity"] = serde_json::json!([1e21, 1, 1]));
    expect_error(r, "lights[0].emitter.intensity", "largest emission");
    // At the bounds, and mirrored, the scene loads.
    let r = load_with("edge", |v| {
        v["objects"][0]["transform"] = serde_json::json!({"translation": [9.8e7, -1e8, 0], "scale": [-1e6, 1e-6, 1]});
        v["lights"][0]["emitter"]["intensity"] = serde_json::json!([1e20, 0, 0]);
    });
    assert!(r.is_ok(), "{:?}", r.err());
}

#[test]
fn animation_keyframes_keep_shapes_within_the_world_coordinates() {
    // An edit that moves a shape beyond the largest world coordinate is refused; so is an
    // animation whose keyframe would make that edit, when it is loaded, not when it plays.
    let scene = load_with("anim-reach", |v| {
        v["objects"][0]["dynamic"] = serde_json::json!(true);
        v["objects"][0]["transform"] = serde_json::json!({"scale": [10, 10, 10]});
    })
    .expect("scene");
    let track = |x: f64| {
        let keys = serde_json::json!([
            {"time": 0, "transform": {"translation": [0, 0, 0], "scale": [1e6, 1e6, 1e6]}},
            {"time": 1, "transform": {"translation": [x, 0, 0], "scale": [1e6, 1e6, 1e6]}},
        ]);
        let anim = serde_json::json!({"duration": 1, "tracks": [{"target": "object", "name": "o", "keyframes": keys}]});
        serde_json::from_value::<relume::scene::animation::Animation>(anim).expect("animation json")
    };
    // The unit triangle scaled 1e6 reaches 1e6 past its translation.
    match track(9.95e7).validate(&scene) {
        Err(SceneError::Invalid { field, message }) => {
            assert_eq!(field, "tracks[0].keyframes[1].transform", "{message}");
            assert!(message.contains("largest world coordinate"), "{message}");
        }
        other => panic!("a keyframe beyond the world's coordinates was not refused: {other:?}"),
    }
    track(9.8e7).validate(&scene).expect("a keyframe within the world's coordinates");
}
