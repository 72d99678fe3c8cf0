//! glTF documents built by hand for the glTF tests (`tests/gltf.rs`, `tests/gltf_import.rs`),
//! and the helpers both read them with.
use base64::Engine;
use glam::Vec3;
use relume::scene::gltf::{import_slice, ImportOptions, Imported};
use relume::scene::{Scene, SceneError};
use serde_json::{json, Value};

/// Are `a` and `b` within `tol` of each other?
pub fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
    (a - b).length() <= tol
}

/// The scene an import describes, built against the bundled scenes root.
pub fn build(imported: &Imported) -> Scene {
    Scene::from_desc(imported.desc.clone(), &super::scenes_dir(), &super::scenes_dir()).expect("imported scene builds")
}

/// A glTF document being built by hand, buffers as one `data:` URI.
#[derive(Default)]
pub struct Doc {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Doc {
    /// Appends `v` as a buffer view and an accessor of type `kind` (`SCALAR`, `VEC3` or
    /// `VEC4`, with bounds for the first two); returns the accessor's index.
    pub fn floats(&mut self, v: &[f32], kind: &str) -> usize {
        let offset = self.bin.len();
        self.bin.extend(v.iter().flat_map(|x| x.to_le_bytes()));
        self.views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": v.len() * 4}));
        let width = match kind {
            "SCALAR" => 1,
            "VEC3" => 3,
            _ => 4,
        };
        let mut a =
            json!({"bufferView": self.views.len() - 1, "componentType": 5126, "count": v.len() / width, "type": kind});
        if kind == "VEC3" || kind == "SCALAR" {
            let (mut lo, mut hi) = (vec![f32::MAX; width], vec![f32::MIN; width]);
            for c in v.chunks(width) {
                for k in 0..width {
                    lo[k] = lo[k].min(c[k]);
                    hi[k] = hi[k].max(c[k]);
                }
            }
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    /// A unit right triangle in XY facing +Z, as a mesh primitive with `material`.
    pub fn triangle(&mut self, material: Option<usize>) -> Value {
        let p = self.floats(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "VEC3");
        let mut prim = json!({"attributes": {"POSITION": p}});
        if let Some(m) = material {
            prim["material"] = json!(m);
        }
        json!({"primitives": [prim]})
    }

    /// The document `root` with the asset, the buffer and its views and accessors, as JSON.
    pub fn finish(self, mut root: Value) -> Vec<u8> {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        );
        root["asset"] = json!({"version": "2.0"});
        root["buffers"] = json!([{"byteLength": self.bin.len(), "uri": uri}]);
        root["bufferViews"] = json!(self.views);
        root["accessors"] = json!(self.accessors);
        serde_json::to_vec(&root).expect("json")
    }
}

/// Imports a document from memory with the default options.
pub fn import(bytes: &[u8]) -> Result<Imported, SceneError> {
    import_slice(bytes, None, &ImportOptions::default())
}

/// The world-space vertices of the imported object `name`.
pub fn world_vertices(imported: &Imported, name: &str) -> Vec<Vec3> {
    let scene = build(imported);
    let i = scene.object_index(name).unwrap_or_else(|| panic!("no object {name}"));
    scene.objects[i].world_positions.clone()
}

/// Six triangles, one per material mapping the importer reads.
pub fn materials_doc() -> Vec<u8> {
    let mut doc = Doc::default();
    let meshes: Vec<Value> = (0..6).map(|m| doc.triangle(Some(m))).collect();
    let nodes: Vec<Value> = (0..6)
        .map(|m| json!({"name": format!("n{m}"), "mesh": m, "translation": [m as f32 * 2.0, 0.0, 0.0]}))
        .collect();
    doc.finish(json!({
        "scene": 0, "scenes": [{"nodes": [0, 1, 2, 3, 4, 5]}], "meshes": meshes, "nodes": nodes,
        "extensionsUsed": ["KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_emissive_strength"],
        "textures": [{"source": 0}], "images": [{"uri": "brick.png"}],
        "materials": [
            {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 0.125, 1.0], "metallicFactor": 0.0}},
            {"name": "chrome", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.8, 0.7, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.0}},
            {"name": "glass", "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.33}}},
            {"name": "brushed", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.6, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.5}},
            {"name": "brick", "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.3, 0.2, 1.0], "metallicFactor": 0.0, "baseColorTexture": {"index": 0}}},
            {"name": "lamp", "emissiveFactor": [1.0, 0.5, 0.25], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 8.0}}},
        ],
    }))
}

/// An animation on node 0 (a parent) and node 1 (its child with the mesh), one channel per
/// interpolation mode.
pub fn animated_doc() -> Vec<u8> {
    animated_doc_with(true)
}

/// [`animated_doc`], or (`cubic: false`, a negative control) with the scale channel a LINEAR
/// line between the same two key values.
pub fn animated_doc_with(cubic: bool) -> Vec<u8> {
    let mut doc = Doc::default();
    let mesh = doc.triangle(None);
    let t_lin = doc.floats(&[0.0, 2.0], "SCALAR");
    let v_lin = doc.floats(&[0.0, 0.0, 0.0, 4.0, 0.0, 0.0], "VEC3");
    let t_step = doc.floats(&[0.0, 1.0], "SCALAR");
    let v_step = doc.floats(&[0.0, 0.0, 0.0, 0.0, 5.0, 0.0], "VEC3");
    let t_cub = doc.floats(&[0.0, 2.0], "SCALAR");
    // (in-tangent, value, out-tangent) per key: a scale from 1 to 3 with zero tangents.
    let v_cub = if cubic {
        doc.floats(&[0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.0, 3.0, 3.0, 0.0, 0.0, 0.0], "VEC3")
    } else {
        doc.floats(&[1.0, 1.0, 1.0, 3.0, 3.0, 3.0], "VEC3")
    };
    let cubic_mode = if cubic { "CUBICSPLINE" } else { "LINEAR" };
    doc.finish(json!({
        "scene": 0, "scenes": [{"nodes": [0]}], "meshes": [mesh],
        "nodes": [{"name": "rig", "children": [1]}, {"name": "body", "mesh": 0}],
        "animations": [{"name": "walk",
            "samplers": [
                {"input": t_lin, "output": v_lin, "interpolation": "LINEAR"},
                {"input": t_step, "output": v_step, "interpolation": "STEP"},
                {"input": t_cub, "output": v_cub, "interpolation": cubic_mode},
            ],
            "channels": [
                {"sampler": 0, "target": {"node": 0, "path": "translation"}},
                {"sampler": 1, "target": {"node": 1, "path": "translation"}},
                {"sampler": 2, "target": {"node": 1, "path": "scale"}},
            ]}],
    }))
}

/// A fresh directory under the system temp dir for test `tag`.
pub fn tempdir(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("relume-gltf-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}
