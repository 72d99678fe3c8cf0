//! glTF 2.0 import on hand-built files: each feature the importer reads (node hierarchies,
//! materials, punctual lights and the camera, animations), and bad or mangled files, each
//! refused with an error naming the part and never a panic.
mod common;
use common::gltf_doc::{animated_doc, animated_doc_with, build, close, import, materials_doc, world_vertices, Doc};
use glam::{Mat4, Quat, Vec3};
use relume::scene::edits::Edit;
use relume::scene::gltf::export_glb;
use relume::scene::{LightGeometry, Material};
use serde_json::{json, Value};

#[test]
fn nested_node_transforms_compose_into_world_positions() {
    let mut doc = Doc::default();
    let mesh = doc.triangle(None);
    let (q, t, s) = (Quat::from_rotation_z(0.5), Vec3::new(1.0, 2.0, 3.0), 2.0);
    let bytes = doc.finish(json!({
        "scene": 0, "scenes": [{"nodes": [0]}], "meshes": [mesh],
        "nodes": [
            {"name": "parent", "translation": t.to_array(), "rotation": q.to_array(), "children": [1]},
            {"name": "child", "scale": [s, s, s], "children": [2]},
            {"name": "leaf", "mesh": 0, "matrix": Mat4::from_translation(Vec3::X).to_cols_array()},
        ],
    }));
    let imported = import(&bytes).expect("import");
    let expected =
        Mat4::from_rotation_translation(q, t) * Mat4::from_scale(Vec3::splat(s)) * Mat4::from_translation(Vec3::X);
    let got = world_vertices(&imported, "leaf");
    for (p, local) in got.iter().zip([Vec3::ZERO, Vec3::X, Vec3::Y]) {
        assert!(close(*p, expected.transform_point3(local), 1e-5), "{p} vs {}", expected.transform_point3(local));
    }
    // The warnings name the missing material and the missing camera.
    assert!(imported.warnings.iter().any(|w| w.contains("without a material")), "{:?}", imported.warnings);
    assert!(imported.warnings.iter().any(|w| w.contains("no perspective camera")), "{:?}", imported.warnings);
}

#[test]
fn vertex_normals_turn_with_their_node_and_survive_export() {
    // Property: NORMAL is read; the shading normal is the file's normal under the inverse
    // transpose of the node's world matrix, whether that stays a transform (a non-uniform
    // scale) or is baked into the vertices (a rotation under a non-uniform scale, which has
    // shear); export writes NORMAL back, and its import gives the same shading normals.
    // Negative control: the world matrix itself (no inverse transpose) turns the normal
    // elsewhere for both nodes.
    let mut doc = Doc::default();
    let n = Vec3::new(0.6, 0.0, 0.8);
    let p = doc.floats(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "VEC3");
    let normals = doc.floats(&[n.to_array(); 3].concat(), "VEC3");
    let mesh = json!({"primitives": [{"attributes": {"POSITION": p, "NORMAL": normals}}]});
    let scale = Vec3::new(3.0, 1.0, 0.5);
    let turn = Quat::from_rotation_y(0.7);
    let bytes = doc.finish(json!({
        "scene": 0, "scenes": [{"nodes": [0, 1]}], "meshes": [mesh],
        "nodes": [
            {"name": "scaled", "mesh": 0, "scale": scale.to_array()},
            {"name": "skewed", "scale": scale.to_array(), "children": [2]},
            {"name": "turned", "mesh": 0, "rotation": turn.to_array()},
        ],
    }));
    let imported = import(&bytes).expect("import");
    assert!(!imported.warnings.iter().any(|w| w.contains("normal")), "{:?}", imported.warnings);
    let worlds = [("scaled", Mat4::from_scale(scale)), ("turned", Mat4::from_scale(scale) * Mat4::from_quat(turn))];
    let check = |scene: &relume::scene::Scene, what: &str| {
        for (name, world) in worlds {
            let i = scene.object_index(name).unwrap_or_else(|| panic!("no object {name}"));
            let sp = scene.surface_point(relume::scene::SurfaceId::Object(i as u32), 0, 0.2, 0.3);
            let m = glam::Mat3::from_mat4(world);
            let side = |v: Vec3| if v.dot(sp.n) < 0.0 { -v } else { v };
            let expected = side((m.inverse().transpose() * n).normalize());
            assert!(close(sp.ns, expected, 1e-5), "{what} {name}: {} vs {expected}", sp.ns);
            assert!(!close(sp.ns, side((m * n).normalize()), 1e-2), "{what} {name}: negative control");
        }
    };
    let scene = build(&imported);
    check(&scene, "imported");
    let again = import(&export_glb(&scene, &[]).expect("export")).expect("re-import");
    check(&build(&again), "exported and imported again");
}

#[test]
fn every_material_mapping_reads_as_documented() {
    let imported = import(&materials_doc()).expect("import");
    let m = &imported.desc.materials;
    let rgb = relume::core::Rgb::new;
    assert_eq!(m["paint"], Material::Diffuse { reflectance: rgb(0.5, 0.25, 0.125) });
    assert_eq!(m["chrome"], Material::Mirror { reflectance: rgb(0.9, 0.8, 0.7) });
    assert_eq!(m["glass"], Material::Glass { ior: 1.33 });
    assert_eq!(m["brushed"], Material::Diffuse { reflectance: rgb(0.6, 0.6, 0.6) });
    assert_eq!(m["brick"], Material::Diffuse { reflectance: rgb(0.7, 0.3, 0.2) });
    assert!(!m.contains_key("lamp"), "an emissive material makes a light, not an object");
    let lamp = imported.desc.lights.iter().find(|l| l.name == "n5").expect("the emissive primitive is a light");
    let relume::scene::EmitterDesc::Mesh { radiance, .. } = &lamp.emitter else { panic!("a mesh emitter expected") };
    assert_eq!(*radiance, rgb(8.0, 4.0, 2.0));
    let w = imported.warnings.join("\n");
    assert!(w.contains("metallic") && w.contains("'brushed'"), "{w}");
    assert!(w.contains("base colour textures") && w.contains("'brick'"), "{w}");
}

#[test]
fn punctual_lights_and_the_camera_read_in_relume_units() {
    let mut doc = Doc::default();
    let mesh = doc.triangle(None);
    let down = Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2);
    let bytes = doc.finish(json!({
        "scene": 0, "scenes": [{"nodes": [0, 1, 2, 3]}], "meshes": [mesh],
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "color": [1.0, 0.5, 0.25], "intensity": 683.0},
            {"type": "spot", "intensity": 1366.0, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
        ]}},
        "cameras": [{"name": "main", "type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 2.0, "znear": 0.01}}],
        "nodes": [
            {"name": "floor", "mesh": 0},
            {"name": "bulb", "translation": [0.0, 3.0, 0.0], "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "spot", "translation": [0.0, 4.0, 0.0], "rotation": down.to_array(), "extensions": {"KHR_lights_punctual": {"light": 1}}},
            {"name": "eye", "translation": [0.0, 1.0, 5.0], "camera": 0},
        ],
    }));
    let imported = import(&bytes).expect("import");
    let scene = build(&imported);
    let bulb = &scene.lights[scene.light_index("bulb").expect("bulb")];
    let LightGeometry::Point { position, intensity } = bulb.geometry else { panic!("point") };
    assert_eq!(position, Vec3::new(0.0, 3.0, 0.0));
    assert_eq!(intensity, relume::core::Rgb::new(1.0, 0.5, 0.25), "683 cd is 1 W/sr");
    let spot = &scene.lights[scene.light_index("spot").expect("spot")];
    let LightGeometry::Spot { axis, intensity, cos_falloff_start, cos_falloff_end, .. } = spot.geometry else {
        panic!("spot")
    };
    // glTF's −Z turned down by the node: the spot shines along (−Z rotated) = −Y.
    assert!(close(axis, down * Vec3::NEG_Z, 1e-5), "axis {axis}");
    assert!((intensity.g - 2.0).abs() < 1e-5);
    assert!((cos_falloff_start - 0.2f32.cos()).abs() < 1e-5 && (cos_falloff_end - 0.5f32.cos()).abs() < 1e-5);
    let cam = &imported.desc.camera;
    assert_eq!(cam.position, [0.0, 1.0, 5.0]);
    assert!((cam.vfov_deg - 0.8f32.to_degrees()).abs() < 1e-4);
    assert_eq!(cam.resolution, [512, 256], "aspect 2 at the default 256 rows");
    let forward = (Vec3::from(cam.look_at) - Vec3::from(cam.position)).normalize();
    assert!(close(forward, Vec3::NEG_Z, 1e-5), "glTF cameras look along −Z: {forward}");
}

#[test]
fn animations_read_linear_step_and_cubic_channels_through_the_hierarchy() {
    let imported = import(&animated_doc()).expect("import");
    assert!(imported.desc.objects[0].dynamic, "an animated node's mesh is dynamic");
    let anim = imported.animation("walk").expect("named as the file names it");
    let scene = build(&imported);
    anim.validate(&scene).expect("valid against its scene");
    let pose = |t: f32| {
        let edits = anim.edits_at(t);
        let Some(Edit::Object { transform, .. }) = edits.first() else { panic!("an object edit") };
        *transform
    };
    // glTF's own definitions, evaluated by hand: LINEAR x = 2t, STEP y = 5 from t = 1,
    // CUBICSPLINE scale 1 + 2(3s² − 2s³) with s = t/2 and zero tangents.
    let cubic_scale = |t: f32| {
        let s = t / 2.0;
        1.0 + 2.0 * (3.0 * s * s - 2.0 * s * s * s)
    };
    let times = [0.25f32, 0.5, 0.99, 1.01, 1.5, 1.95];
    // Negative control for the cubic tolerance: the same keys joined by a straight line miss
    // the Hermite curve by more than it.
    let line = import(&animated_doc_with(false)).expect("import");
    let line_anim = line.animation("walk").expect("walk");
    let worst_line = times
        .iter()
        .map(|&t| {
            let edits = line_anim.edits_at(t);
            let Some(Edit::Object { transform, .. }) = edits.first() else { panic!("an object edit") };
            (transform.scale[0] - cubic_scale(t)).abs()
        })
        .fold(0.0f32, f32::max);
    assert!(worst_line > 0.02, "a LINEAR scale channel passes the cubic tolerance ({worst_line})");
    for t in times {
        let got = pose(t);
        let scale = cubic_scale(t);
        let y = if t < 1.0 { 0.0 } else { 5.0 };
        assert!((got.translation[0] - 2.0 * t).abs() < 1e-4, "t {t}: x {}", got.translation[0]);
        assert!((got.translation[1] - y).abs() < 1e-4, "t {t}: y {}", got.translation[1]);
        // Cubic segments are sampled at 8 points: between them the error is that of a chord.
        assert!((got.scale[0] - scale).abs() < 0.02, "t {t}: scale {} vs {scale}", got.scale[0]);
    }
    assert!(imported.warnings.iter().any(|w| w.contains("CUBICSPLINE")), "{:?}", imported.warnings);
}

#[test]
fn bad_files_are_refused_naming_the_part() {
    let base: Value = serde_json::from_slice(&materials_doc()).expect("json");
    type Mutation = Box<dyn Fn(&mut Value)>;
    let cases: Vec<(&str, Mutation, &str)> = vec![
        (
            "lines",
            Box::new(|d: &mut Value| d["meshes"][0]["primitives"][0]["mode"] = json!(1)),
            "meshes[0].primitives[0].mode",
        ),
        (
            "shear",
            Box::new(
                |d: &mut Value| d["nodes"][0] = json!({"name": "n0", "mesh": 0, "matrix": [1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]}),
            ),
            "nodes[0] ('n0').matrix",
        ),
        (
            "sun wider than a sun",
            Box::new(|d: &mut Value| {
                d["extensions"] = json!({"KHR_lights_punctual": {"lights": [{"type": "directional"}]}});
                d["nodes"][0]["extensions"] = json!({"KHR_lights_punctual": {"light": 0}});
                d["nodes"][0]["extras"] = json!({"relume": {"angle_deg": 45}});
            }),
            "angle_deg",
        ),
        ("cycle", Box::new(|d: &mut Value| d["nodes"][1]["children"] = json!([1])), "nodes[1]"),
        ("short buffer", Box::new(|d: &mut Value| d["buffers"][0]["byteLength"] = json!(1 << 20)), "buffers[0]"),
        ("file buffer inline", Box::new(|d: &mut Value| d["buffers"][0]["uri"] = json!("mesh.bin")), "buffers[0].uri"),
        // gltf-json's own validation indexes this accessor before checking it (it panics).
        (
            "accessor out of range",
            Box::new(|d: &mut Value| d["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99)),
            "gltf",
        ),
        // A node beyond the bounds scene validation puts on transforms is refused by name, not
        // as the object it becomes (an empty mesh, its triangles overflowed or collapsed) or the
        // camera framed around it (NaN). A 1e30 matrix decomposes; it is not taken for shear.
        (
            "huge scale",
            Box::new(|d: &mut Value| d["nodes"][0]["scale"] = json!([1e30, 1e30, 1e30])),
            "nodes[0] ('n0'): its world transform scales by 1e30",
        ),
        (
            "tiny scale",
            Box::new(|d: &mut Value| d["nodes"][0]["scale"] = json!([1.0, 1e-30, 1.0])),
            "nodes[0] ('n0'): its world transform scales by 1e-30",
        ),
        (
            "huge matrix",
            Box::new(
                |d: &mut Value| d["nodes"][0] = json!({"name": "n0", "mesh": 0, "matrix": [1e30, 0.0, 0.0, 0.0, 0.0, 1e30, 0.0, 0.0, 0.0, 0.0, 1e30, 0.0, 0.0, 0.0, 0.0, 1.0]}),
            ),
            "nodes[0] ('n0'): its world transform scales by 1e30",
        ),
        (
            "far",
            Box::new(|d: &mut Value| d["nodes"][0]["translation"] = json!([0.0, -3e38, 0.0])),
            "nodes[0] ('n0'): its world translation reaches 3e38",
        ),
        (
            "no scene",
            Box::new(|d: &mut Value| {
                d.as_object_mut().expect("object").remove("scene");
                d["scenes"] = json!([]);
            }),
            "scenes",
        ),
    ];
    for (what, mutate, part) in cases {
        let mut doc = base.clone();
        mutate(&mut doc);
        let err = import(&serde_json::to_vec(&doc).expect("json")).err().unwrap_or_else(|| panic!("{what}: accepted"));
        assert!(err.to_string().contains(part), "{what}: '{err}' does not name {part}");
    }
}

#[test]
fn bad_buffer_data_is_refused_naming_the_place() {
    // Non-finite data and vertices beyond the largest world coordinate live in the buffers:
    // build them so, under an identity node.
    let cases = [(f32::NAN, "positions[1][0]"), (1e30, "nodes[0]: puts its mesh 1e30 from the origin")];
    for (x, part) in cases {
        let mut doc = Doc::default();
        let p = doc.floats(&[0.0, 0.0, 0.0, x, 0.0, 0.0, 0.0, 1.0, 0.0], "VEC3");
        let bytes = doc.finish(json!({"scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}], "meshes": [{"primitives": [{"attributes": {"POSITION": p}}]}]}));
        let err = import(&bytes).err().unwrap_or_else(|| panic!("a vertex at {x} was accepted"));
        assert!(err.to_string().contains(part), "{err}");
    }
}

#[test]
fn the_largest_accepted_node_transforms_import_and_build() {
    // Scale 1e6 and 1e-6 (the limits), the unit triangle's far corner at 9.9e7 < 1e8.
    for (scale, x) in [(1e6f32, 9.8e7f32), (1e-6, -9.9e7)] {
        let mut doc = Doc::default();
        let mesh = doc.triangle(None);
        let bytes = doc.finish(json!({
            "scene": 0, "scenes": [{"nodes": [0]}], "meshes": [mesh],
            "nodes": [{"name": "far", "mesh": 0, "scale": [scale, scale, scale], "translation": [x, 0.0, 0.0]}],
        }));
        let imported = import(&bytes).unwrap_or_else(|e| panic!("scale {scale} at {x}: {e}"));
        let got = world_vertices(&imported, "far");
        assert!(close(got[1], Vec3::new(x + scale, 0.0, 0.0), 1.0), "scale {scale} at {x}: {got:?}");
    }
}

#[test]
fn mangled_glb_bytes_are_refused_or_read_never_a_panic() {
    let glb = export_glb(&common::load("walker.json"), &[]).expect("export");
    use proptest::prelude::*;
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig { cases: 400, ..ProptestConfig::default() });
    let len = glb.len();
    runner
        .run(&proptest::collection::vec((0..len, any::<u8>()), 1..8), |flips| {
            let mut bytes = glb.clone();
            for (at, v) in flips {
                bytes[at] = v;
            }
            let _ = import(&bytes);
            Ok(())
        })
        .expect("no panic");
}
