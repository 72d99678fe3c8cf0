//! glTF 2.0 export and import on real files: the bundled scenes exported and read back (round
//! trip), the Cornell box as glTF against the JSON Cornell box, a .glb against a .gltf with an
//! external buffer, every technique on an exported mesh light, the bundled .glb files against
//! the exporter, Khronos's validator, and a file written by obj2gltf. Each feature the
//! importer reads, and bad files, are in `gltf_import.rs`.
mod common;
use base64::Engine;
use common::gltf_doc::{animated_doc, build, close, import, materials_doc, tempdir};
use glam::Vec3;
use relume::scene::animation::Animation;
use relume::scene::edits::apply;
use relume::scene::gltf::{export_glb, import_slice, ImportOptions, Imported};
use relume::scene::{LightGeometry, Material, Scene, ShapeDesc};
use relume::technique::TechniqueConfig;
use serde_json::{json, Value};

/// A bundled scene and its animation (if any), exported and imported back.
fn round_trip(name: &str) -> (Scene, Option<Animation>, Imported) {
    let root = common::scenes_dir();
    let scene = common::load(&format!("{name}.json"));
    let anim_path = root.join(format!("{name}.anim.json"));
    let anim = anim_path.is_file().then(|| Animation::load(&anim_path).expect("animation"));
    let anims: Vec<(String, Animation)> = anim.iter().map(|a| (name.to_string(), a.clone())).collect();
    let glb = export_glb(&scene, &anims).expect("export");
    let imported = import_slice(&glb, None, &ImportOptions::default()).expect("import of the export");
    (scene, anim, imported)
}

/// Every difference between two scenes beyond `tol` (a length in scene units), as text.
fn differences(a: &Scene, b: &Scene, tol: f32) -> Vec<String> {
    let mut out = Vec::new();
    if a.objects.len() != b.objects.len() || a.lights.len() != b.lights.len() {
        return vec![format!(
            "{} / {} objects, {} / {} lights",
            a.objects.len(),
            b.objects.len(),
            a.lights.len(),
            b.lights.len()
        )];
    }
    for (x, y) in a.objects.iter().zip(&b.objects) {
        if x.name != y.name || x.dynamic != y.dynamic || x.world_positions.len() != y.world_positions.len() {
            out.push(format!("object {} vs {}", x.name, y.name));
            continue;
        }
        if x.world_positions.iter().zip(&y.world_positions).any(|(p, q)| !close(*p, *q, tol)) {
            out.push(format!("object {}: vertices moved", x.name));
        }
        if a.materials[x.material as usize] != b.materials[y.material as usize] {
            out.push(format!("object {}: material", x.name));
        }
    }
    for (x, y) in a.lights.iter().zip(&b.lights) {
        if x.name != y.name || x.dynamic != y.dynamic {
            out.push(format!("light {} vs {}", x.name, y.name));
        }
        let rgb = |p: relume::core::Rgb, q: relume::core::Rgb| {
            (Vec3::from(p.to_array()) - Vec3::from(q.to_array())).length() <= 1e-5 * p.max_component().max(1.0)
        };
        let same = match (&x.geometry, &y.geometry) {
            (
                LightGeometry::Point { position: p, intensity: i },
                LightGeometry::Point { position: q, intensity: j },
            ) => close(*p, *q, tol) && rgb(*i, *j),
            (
                LightGeometry::Spot { position: p, axis: u, intensity: i, cos_falloff_start: s, cos_falloff_end: e },
                LightGeometry::Spot { position: q, axis: v, intensity: j, cos_falloff_start: s2, cos_falloff_end: e2 },
            ) => {
                close(*p, *q, tol)
                    && close(*u, *v, 1e-4)
                    && rgb(*i, *j)
                    && (s - s2).abs() < 1e-5
                    && (e - e2).abs() < 1e-5
            }
            (
                LightGeometry::Area { radiance: r, triangles: t, .. },
                LightGeometry::Area { radiance: r2, triangles: t2, .. },
            ) => {
                rgb(*r, *r2)
                    && t.len() == t2.len()
                    && t.iter().zip(t2).all(|(p, q)| (0..3).all(|k| close(p[k], q[k], tol)))
            }
            (
                LightGeometry::Directional { travel: u, irradiance: i, cos_max: c, .. },
                LightGeometry::Directional { travel: v, irradiance: j, cos_max: c2, .. },
            ) => close(*u, *v, 1e-4) && rgb(*i, *j) && (c - c2).abs() < 1e-6,
            (LightGeometry::Environment { radiance: r, .. }, LightGeometry::Environment { radiance: r2, .. }) => {
                rgb(*r, *r2)
            }
            _ => false,
        };
        if !same {
            out.push(format!("light {}: {:?} vs {:?}", x.name, x.geometry_kind(), y.geometry_kind()));
        }
    }
    let (c, d) = (&a.desc().camera, &b.desc().camera);
    let dir = |c: &relume::scene::CameraDesc| (Vec3::from(c.look_at) - Vec3::from(c.position)).normalize();
    if !close(c.position.into(), d.position.into(), tol)
        || !close(dir(c), dir(d), 1e-4)
        || (c.vfov_deg - d.vfov_deg).abs() > 1e-3
        || c.resolution != d.resolution
    {
        out.push(format!("camera {c:?} vs {d:?}"));
    }
    out
}

trait Kind {
    fn geometry_kind(&self) -> &'static str;
}

impl Kind for relume::scene::SceneLight {
    fn geometry_kind(&self) -> &'static str {
        match self.geometry {
            LightGeometry::Point { .. } => "point",
            LightGeometry::Spot { .. } => "spot",
            LightGeometry::Area { .. } => "area",
            LightGeometry::Directional { .. } => "directional",
            LightGeometry::Environment { .. } => "environment",
        }
    }
}

#[test]
fn a_sun_and_an_environment_survive_export_and_import() {
    // Property: a directional light keeps its direction, irradiance (lux = 683 × W/m²) and
    // angle, and the scene its environment, through a .glb. Control: the export of the same
    // scene with the sun turned by 1° differs from the first in the direction read back.
    let scene_with = |direction: [f32; 3]| {
        common::scene_from_json(json!({
            "camera": {"position": [0, 1, 4], "look_at": [0, 0, 0], "vfov_deg": 40, "resolution": [16, 16]},
            "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
            "objects": [{"name": "ball", "shape": {"type": "sphere"}, "material": "grey"}],
            "lights": [{"name": "sun", "emitter": {"type": "directional", "direction": direction,
                        "irradiance": [3, 2, 1], "angle_deg": 0.53}}],
            "environment": {"radiance": [0.1, 0.2, 0.3]}
        }))
    };
    let back = |scene: &Scene| {
        let glb = export_glb(scene, &[]).expect("export");
        import_slice(&glb, None, &ImportOptions::default()).expect("import of the export").desc
    };
    let travel = Vec3::new(0.3, -1.0, -0.2).normalize();
    let scene = scene_with(travel.to_array());
    let desc = back(&scene);
    assert_eq!(desc.environment, scene.desc().environment, "the environment");
    let relume::scene::EmitterDesc::Directional { direction, irradiance, angle_deg } = &desc.lights[0].emitter else {
        panic!("not a directional light: {:?}", desc.lights[0].emitter);
    };
    let read = Vec3::from(*direction);
    assert!(read.angle_between(travel) < 1e-3, "direction {read} vs {travel}");
    assert!(close(Vec3::from(irradiance.to_array()), Vec3::new(3.0, 2.0, 1.0), 1e-4), "irradiance {irradiance:?}");
    assert!((angle_deg - 0.53).abs() < 1e-6, "angle {angle_deg}");
    let turned = glam::Quat::from_rotation_y(1f32.to_radians()) * travel;
    let relume::scene::EmitterDesc::Directional { direction: other, .. } =
        &back(&scene_with(turned.to_array())).lights[0].emitter
    else {
        panic!("not a directional light");
    };
    assert!(Vec3::from(*other).angle_between(travel) >= 1e-3, "a 1° turn reads back as the same sun");
}

fn extent(scene: &Scene) -> f32 {
    scene.bounds().map(|(lo, hi)| (hi - lo).length()).unwrap_or(1.0)
}

#[test]
fn every_bundled_scene_survives_export_and_import() {
    let mut names: Vec<String> = std::fs::read_dir(common::scenes_dir())
        .expect("scenes")
        .flatten()
        .filter_map(|e| {
            e.file_name().to_str()?.strip_suffix(".json").filter(|n| !n.ends_with(".anim")).map(str::to_string)
        })
        .collect();
    names.sort();
    assert!(names.len() >= 8, "bundled scenes: {names:?}");
    for name in &names {
        let (scene, anim, imported) = round_trip(name);
        let back = build(&imported);
        let tol = 1e-5 * extent(&scene);
        let diff = differences(&scene, &back, tol);
        assert!(diff.is_empty(), "{name}: {diff:?}");
        // Negative control: the comparison sees a 0.1% move of the first object.
        let mut moved = scene.clone();
        let mut t = moved.desc().objects[0].transform;
        t.translation[0] += 1e-3 * extent(&scene);
        moved.set_object_transform(0, t);
        assert!(!differences(&moved, &back, tol).is_empty(), "{name}: the comparison misses a moved object");
        let Some(anim) = anim else { continue };
        let (anim_name, back_anim) = &imported.animations[0];
        assert_eq!(anim_name, name);
        back_anim.validate(&back).unwrap_or_else(|e| panic!("{name}: imported animation: {e}"));
        for k in 0..=8 {
            let t = anim.duration * k as f32 / 8.0;
            let (mut a, mut b) = (scene.clone(), back.clone());
            apply(&mut a, anim.edits_at(t)).expect("original edits");
            apply(&mut b, back_anim.edits_at(t)).expect("imported edits");
            let diff = differences(&a, &b, 1e-4 * extent(&scene));
            assert!(diff.is_empty(), "{name} at {t} s: {diff:?}");
        }
    }
}

#[test]
fn the_cornell_box_as_gltf_renders_as_the_json_cornell_box() {
    let (scene, _, imported) = round_trip("cornell-box");
    assert!(imported.desc.objects.iter().all(|o| matches!(o.shape, ShapeDesc::Triangles { .. })));
    let config = || TechniqueConfig::Path(common::path(4));
    let json = common::render(scene.clone(), config(), 7, 4, 2).image;
    let gltf = common::render(build(&imported), config(), 7, 4, 2).image;
    // Same triangles, materials, light and seed: the same image up to float rounding.
    let tolerance = 1e-6;
    let err = common::rel_mse(&gltf, &json);
    assert!(err < tolerance, "relMSE {err} between the glTF and JSON Cornell boxes");
    // Negative control: one wall 2% darker is seen.
    let mut darker = scene;
    let wall = darker.material_names.iter().position(|n| n != "light").expect("a material");
    let Material::Diffuse { reflectance } = darker.materials[wall].clone() else { panic!("diffuse wall expected") };
    darker.set_material(wall, Material::Diffuse { reflectance: reflectance * 0.98 });
    let control = common::render(darker, config(), 7, 4, 2).image;
    assert!(common::rel_mse(&control, &json) > tolerance, "a 2% darker wall went unseen");
}

#[test]
fn a_glb_and_a_gltf_with_an_external_bin_read_the_same() {
    let dir = tempdir("external-bin");
    let bytes = animated_doc();
    let mut root: Value = serde_json::from_slice(&bytes).expect("json");
    let uri = root["buffers"][0]["uri"].as_str().expect("uri").to_string();
    let payload =
        base64::engine::general_purpose::STANDARD.decode(uri.split_once(',').expect("data uri").1).expect("b64");
    std::fs::write(dir.join("walk data.bin"), &payload).expect("bin");
    root["buffers"][0]["uri"] = json!("walk%20data.bin");
    std::fs::write(dir.join("walk.gltf"), serde_json::to_vec(&root).expect("json")).expect("gltf");
    let loaded = Scene::load_file(&dir.join("walk.gltf"), &dir, &ImportOptions::default()).expect("external .bin");
    // The same document as GLB, through the exporter.
    let glb = export_glb(&loaded.scene, &loaded.animations).expect("export");
    std::fs::write(dir.join("walk.glb"), &glb).expect("glb");
    let from_glb = Scene::load_file(&dir.join("walk.glb"), &dir, &ImportOptions::default()).expect("glb");
    assert!(differences(&loaded.scene, &from_glb.scene, 1e-5).is_empty());
    assert_eq!(from_glb.animations[0].0, "walk");
    // An external buffer outside the scenes root is refused, naming the buffer.
    root["buffers"][0]["uri"] = json!("../outside.bin");
    std::fs::write(dir.join("escape.gltf"), serde_json::to_vec(&root).expect("json")).expect("gltf");
    let err = Scene::load_file(&dir.join("escape.gltf"), &dir, &ImportOptions::default()).err().expect("refused");
    assert!(err.to_string().contains("buffers[0].uri") && err.to_string().contains("escapes"), "{err}");
}

#[test]
fn every_technique_renders_the_exported_mesh_light_as_the_rect_light() {
    let (scene, _, imported) = round_trip("cornell-box");
    let back = build(&imported);
    assert!(imported.desc.lights.iter().all(|l| matches!(l.emitter, relume::scene::EmitterDesc::Mesh { .. })));
    let tolerance = 1e-6;
    let mut dimmer = scene.clone();
    let desc = dimmer.desc().lights[0].clone();
    let relume::scene::EmitterDesc::Rect { radiance } = desc.emitter else { panic!("a rect light expected") };
    dimmer.set_light(0, desc.transform, relume::scene::EmitterDesc::Rect { radiance: radiance * 0.98 });
    for config in common::small_techniques() {
        let label = format!("{config:?}");
        let json = common::render(scene.clone(), config.clone(), 3, 2, 2).image;
        let gltf = common::render(back.clone(), config.clone(), 3, 2, 2).image;
        let err = common::rel_mse(&gltf, &json);
        assert!(err < tolerance, "{label}: relMSE {err} between the mesh light and the rect light");
        // Negative control: a light 2% dimmer is seen.
        let control = common::render(dimmer.clone(), config, 3, 2, 2).image;
        assert!(common::rel_mse(&control, &json) > tolerance, "{label}: a 2% dimmer light went unseen");
    }
}

#[test]
fn the_bundled_glb_files_are_what_the_exporter_writes() {
    let root = common::scenes_dir();
    let mut checked = 0;
    for entry in std::fs::read_dir(&root).expect("scenes").flatten() {
        let path = entry.path();
        if path.extension().and_then(|e| e.to_str()) != Some("glb") {
            continue;
        }
        let stem = path.file_stem().and_then(|s| s.to_str()).expect("name").to_string();
        let scene = common::load(&format!("{stem}.json"));
        let anim_path = root.join(format!("{stem}.anim.json"));
        let anims: Vec<(String, Animation)> = if anim_path.is_file() {
            vec![(stem.clone(), Animation::load(&anim_path).expect("animation"))]
        } else {
            Vec::new()
        };
        let fresh = export_glb(&scene, &anims).expect("export");
        let shipped = std::fs::read(&path).expect("glb");
        assert!(fresh == shipped, "scenes/{stem}.glb is stale: run scripts/export-scenes.sh");
        checked += 1;
    }
    let json_scenes = std::fs::read_dir(&root)
        .expect("scenes")
        .flatten()
        .filter(|e| e.file_name().to_str().is_some_and(|n| n.ends_with(".json") && !n.ends_with(".anim.json")))
        .count();
    assert_eq!(checked, json_scenes, "every bundled JSON scene ships as .glb");
}

/// Runs the Khronos glTF validator (scripts/nodetools.sh installs it; scripts/test.sh does) on
/// `files`: the number of errors per file.
fn khronos_errors(files: &[std::path::PathBuf]) -> Vec<u64> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    assert!(
        root.join(".deps/nodetools/node_modules/gltf-validator").is_dir(),
        "the Khronos glTF validator is missing: run scripts/nodetools.sh (scripts/test.sh does)"
    );
    let out = std::process::Command::new("node")
        .arg(root.join("scripts/gltf-validate.js"))
        .args(files)
        .output()
        .expect("node");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| {
            let v: Value = serde_json::from_str(l).unwrap_or_else(|e| panic!("validator output '{l}': {e}"));
            assert!(v["errors"].as_u64() == Some(0) || !v["messages"].as_array().expect("messages").is_empty());
            v["errors"].as_u64().expect("errors")
        })
        .collect()
}

#[test]
fn exports_pass_the_khronos_validator_with_no_errors() {
    let dir = tempdir("khronos");
    let mut files = Vec::new();
    for (name, bytes) in [("animated", animated_doc()), ("materials", materials_doc())] {
        let loaded = import(&bytes).expect("import");
        let scene = build(&loaded);
        let path = dir.join(format!("{name}.glb"));
        std::fs::write(&path, export_glb(&scene, &loaded.animations).expect("export")).expect("write");
        files.push(path);
    }
    for entry in std::fs::read_dir(common::scenes_dir()).expect("scenes").flatten() {
        if entry.path().extension().and_then(|e| e.to_str()) == Some("glb") {
            files.push(entry.path());
        }
    }
    let errors = khronos_errors(&files);
    assert_eq!(errors.len(), files.len());
    for (file, n) in files.iter().zip(&errors) {
        assert_eq!(*n, 0, "{}: {n} validation errors", file.display());
    }
    // Negative control: the same validator finds an accessor whose declared bounds are wrong.
    let glb = std::fs::read(common::scenes_dir().join("cornell-box.glb")).expect("glb");
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("header")) as usize;
    let mut doc: Value = serde_json::from_slice(&glb[20..20 + json_len]).expect("json chunk");
    std::fs::write(dir.join("broken.bin"), &glb[28 + json_len..]).expect("bin");
    doc["buffers"][0]["uri"] = json!("broken.bin");
    doc["accessors"][0]["max"] = json!([0.0, 0.0, 0.0]);
    let broken = dir.join("broken.gltf");
    std::fs::write(&broken, serde_json::to_vec(&doc).expect("json")).expect("gltf");
    assert!(khronos_errors(&[broken])[0] > 0, "the validator missed a wrong accessor bound");
}

/// A floor and a small square lamp above it, as OBJ with an emissive MTL material.
const ROOM_OBJ: &str = "mtllib room.mtl\no floor\nv -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nusemtl grey\nf 1 4 3 2\n\
o lamp\nv -0.3 1 -0.3\nv 0.3 1 -0.3\nv 0.3 1 0.3\nv -0.3 1 0.3\nusemtl glow\nf 5 6 7 8\n";
const ROOM_MTL: &str = "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl glow\nKd 0 0 0\nKe 4 4 4\n";

#[test]
fn a_file_written_by_obj2gltf_reads_as_the_scene_it_describes() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let tool = root.join(".deps/nodetools/node_modules/.bin/obj2gltf");
    assert!(tool.is_file(), "obj2gltf is missing: run scripts/nodetools.sh (scripts/test.sh does)");
    let dir = tempdir("obj2gltf");
    std::fs::write(dir.join("room.obj"), ROOM_OBJ).expect("obj");
    std::fs::write(dir.join("room.mtl"), ROOM_MTL).expect("mtl");
    let out = dir.join("room.glb");
    let status = std::process::Command::new(&tool)
        .arg("-i")
        .arg(dir.join("room.obj"))
        .arg("-o")
        .arg(&out)
        .output()
        .expect("obj2gltf");
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    let loaded = Scene::load_file(&out, &dir, &ImportOptions::default()).expect("obj2gltf's file loads");
    assert_eq!((loaded.scene.objects.len(), loaded.scene.lights.len()), (1, 1), "a floor and the emissive lamp");
    // The twin: the scene the OBJ describes, written by hand in relume's JSON, seen through
    // the camera the import framed.
    let twin = |lamp: f32| {
        common::scene_from_json(json!({
            "camera": serde_json::to_value(&loaded.scene.desc().camera).expect("camera"),
            "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
            "objects": [{"name": "floor", "material": "grey", "shape": {"type": "triangles",
                "positions": [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], "indices": [[0, 3, 2], [0, 2, 1]]}}],
            "lights": [{"name": "lamp", "emitter": {"type": "mesh", "radiance": [lamp, lamp, lamp],
                "positions": [[-0.3, 1, -0.3], [0.3, 1, -0.3], [0.3, 1, 0.3], [-0.3, 1, 0.3]], "indices": [[0, 1, 2], [0, 2, 3]]}}],
        }))
    };
    let config = || TechniqueConfig::Path(common::path(4));
    let from_tool = common::render(loaded.scene.clone(), config(), 5, 4, 2).image;
    let by_hand = common::render(twin(4.0), config(), 5, 4, 2).image;
    // Same seed and the same triangles (up to their order): the 4×4 block means agree within
    // 5%, far inside what a 20% dimmer lamp moves them.
    let (a, b) = (common::block_means(&from_tool), common::block_means(&by_hand));
    let rel =
        |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| (p - q).abs() / q.abs().max(1e-3)).fold(0.0, f64::max);
    let tolerance = 0.05;
    assert!(rel(&a, &b) < tolerance, "obj2gltf's room differs from the hand-written one by {}", rel(&a, &b));
    // Negative control: the twin with a 20% dimmer lamp is told apart.
    let dimmer = common::block_means(&common::render(twin(3.2), config(), 5, 4, 2).image);
    assert!(rel(&dimmer, &b) > tolerance, "a 20% dimmer lamp went unseen");
}
