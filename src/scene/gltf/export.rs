//! A relume scene, and its animations, written as one binary glTF 2.0 file (`.glb`), so any
//! glTF viewer shows what relume renders and import reads it back.
//!
//! Every object becomes a node with its TRS and a mesh of its triangles (primitives are
//! tessellated, OBJ meshes copied; objects with equal shape and material share one mesh).
//! Materials map back as `materials.rs` reads them. Area lights become emissive meshes
//! (`emissiveFactor` × `KHR_materials_emissive_strength` = radiance, black base colour),
//! point and spot lights `KHR_lights_punctual` lights (candela = 683 × W/sr, axis turned to
//! −Z), directional lights directional ones (lux = 683 × W/m², −Z along the direction, a
//! non-zero `angle_deg` in the node's `extras.relume`). The camera keeps its resolution and
//! look-at distance in `extras.relume`, dynamic objects and lights say so there too, and the
//! scene its environment. Animation tracks become LINEAR channels.
use super::import::{light_axis_flip, LUMENS_PER_WATT};
use crate::scene::animation::{Animation, Track};
use crate::scene::load::{invalid, SceneError};
use crate::scene::model::{CameraDesc, EmitterDesc, Material, Trs};
use crate::scene::{Mesh, Scene};
use glam::{Mat3, Quat, Vec3};
use serde_json::{json, Value};
use std::collections::HashMap;

const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// Key times closer than this are spread apart: glTF inputs must strictly increase.
const MIN_KEY_GAP_S: f32 = 1e-4;

/// The binary chunk with its buffer views and accessors.
#[derive(Default)]
struct Bin {
    data: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Bin {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        let offset = self.data.len();
        self.data.extend_from_slice(bytes);
        self.data.resize(self.data.len().next_multiple_of(4), 0);
        let mut v = json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.views.push(v);
        self.views.len() - 1
    }

    fn floats(&mut self, values: &[f32], width: usize, kind: &str, target: Option<u32>) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let (mut lo, mut hi) = (vec![f32::INFINITY; width], vec![f32::NEG_INFINITY; width]);
        for chunk in values.chunks_exact(width) {
            for (k, v) in chunk.iter().enumerate() {
                lo[k] = lo[k].min(*v);
                hi[k] = hi[k].max(*v);
            }
        }
        self.accessors.push(json!({
            "bufferView": view, "componentType": FLOAT, "count": values.len() / width,
            "type": kind, "min": lo, "max": hi,
        }));
        self.accessors.len() - 1
    }

    fn indices(&mut self, triangles: &[[u32; 3]]) -> usize {
        let bytes: Vec<u8> = triangles.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(json!({
            "bufferView": view, "componentType": UNSIGNED_INT, "count": triangles.len() * 3, "type": "SCALAR",
        }));
        self.accessors.len() - 1
    }

    fn mesh(&mut self, mesh: &Mesh, material: usize) -> Value {
        let positions: Vec<f32> = mesh.positions.iter().flat_map(|p| p.to_array()).collect();
        let position = self.floats(&positions, 3, "VEC3", Some(ARRAY_BUFFER));
        let indices = self.indices(&mesh.triangles);
        let mut attributes = json!({"POSITION": position});
        // glTF requires unit normals: a mesh with a zero one (a degenerate `vn`) is written flat.
        if !mesh.normals.is_empty() && mesh.normals.iter().all(|n| *n != glam::Vec3::ZERO) {
            let normals: Vec<f32> = mesh.normals.iter().flat_map(|n| n.to_array()).collect();
            attributes["NORMAL"] = json!(self.floats(&normals, 3, "VEC3", Some(ARRAY_BUFFER)));
        }
        json!({"primitives": [{"attributes": attributes, "indices": indices, "material": material}]})
    }
}

/// The document being written.
#[derive(Default)]
struct Writer {
    bin: Bin,
    nodes: Vec<Value>,
    meshes: Vec<Value>,
    materials: Vec<Value>,
    punctual: Vec<Value>,
    extensions: std::collections::BTreeSet<&'static str>,
    /// Node index by object or light name, for animation channels.
    object_nodes: HashMap<String, usize>,
    light_nodes: HashMap<String, (usize, bool)>,
    camera_node: usize,
}

/// `scene` (as edited) and `animations` as GLB bytes.
pub fn export_glb(scene: &Scene, animations: &[(String, Animation)]) -> Result<Vec<u8>, SceneError> {
    let mut w = Writer::default();
    w.materials(scene);
    w.objects(scene);
    w.lights(scene)?;
    w.camera(&scene.desc().camera);
    let animations: Vec<Value> = animations.iter().map(|(name, a)| w.animation(name, a, scene)).collect();
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": concat!("relume ", env!("CARGO_PKG_VERSION"))},
        "scene": 0,
        "scenes": [scene_json(scene, w.nodes.len())],
        "nodes": w.nodes, "meshes": w.meshes, "materials": w.materials,
        "cameras": [camera_json(&scene.desc().camera)],
        "buffers": [{"byteLength": w.bin.data.len()}],
        "bufferViews": w.bin.views, "accessors": w.bin.accessors,
    });
    if !animations.is_empty() {
        doc["animations"] = json!(animations);
    }
    if !w.punctual.is_empty() {
        doc["extensions"] = json!({"KHR_lights_punctual": {"lights": w.punctual}});
    }
    if !w.extensions.is_empty() {
        doc["extensionsUsed"] = json!(w.extensions);
    }
    let json = serde_json::to_vec(&doc).map_err(|e| invalid("gltf", e.to_string()))?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
        json: json.into(),
        bin: Some(w.bin.data.into()),
    };
    glb.to_vec().map_err(|e| invalid("gltf", e.to_string()))
}

fn trs_json(t: &Trs) -> Value {
    json!({"translation": t.translation, "rotation": t.rotation, "scale": t.scale})
}

/// The glTF scene of `nodes` root nodes, with the environment in its `extras.relume`.
fn scene_json(scene: &Scene, nodes: usize) -> Value {
    let mut out = json!({"nodes": (0..nodes).collect::<Vec<_>>()});
    if let Some(env) = &scene.desc().environment {
        out["extras"] = json!({"relume": {"environment": env}});
    }
    out
}

fn dynamic_extras(dynamic: bool) -> Value {
    if dynamic {
        json!({"relume": {"dynamic": true}})
    } else {
        json!({})
    }
}

/// A colour as a factor of at most 1 in each channel and the strength multiplying it.
fn factor_and_strength(c: crate::core::Rgb) -> ([f32; 3], f32) {
    let strength = c.max_component();
    if strength <= 1.0 {
        (c.to_array(), 1.0)
    } else {
        ((c * (1.0 / strength)).to_array(), strength)
    }
}

fn camera_rotation(c: &CameraDesc) -> Quat {
    let forward = (Vec3::from(c.look_at) - Vec3::from(c.position)).normalize();
    let right = forward.cross(Vec3::from(c.up)).normalize();
    let up = right.cross(forward);
    Quat::from_mat3(&Mat3::from_cols(right, up, -forward)).normalize()
}

fn camera_json(c: &CameraDesc) -> Value {
    let aspect = c.resolution[0] as f32 / c.resolution[1] as f32;
    let distance = (Vec3::from(c.look_at) - Vec3::from(c.position)).length();
    json!({"type": "perspective", "perspective": {
        "yfov": c.vfov_deg.to_radians(), "aspectRatio": aspect, "znear": (1e-3 * distance).max(1e-6),
    }})
}

impl Writer {
    fn materials(&mut self, scene: &Scene) {
        for m in scene.desc().materials.values() {
            let pbr = |c: crate::core::Rgb, metallic: f32, roughness: f32| json!({"baseColorFactor": [c.r, c.g, c.b, 1.0], "metallicFactor": metallic, "roughnessFactor": roughness});
            let v = match m {
                Material::Diffuse { reflectance } => json!({"pbrMetallicRoughness": pbr(*reflectance, 0.0, 1.0)}),
                Material::Mirror { reflectance } => json!({"pbrMetallicRoughness": pbr(*reflectance, 1.0, 0.0)}),
                Material::Glass { ior } => {
                    self.extensions.extend(["KHR_materials_transmission", "KHR_materials_ior"]);
                    json!({"pbrMetallicRoughness": pbr(crate::core::Rgb::WHITE, 0.0, 0.0), "extensions": {
                        "KHR_materials_transmission": {"transmissionFactor": 1.0},
                        "KHR_materials_ior": {"ior": ior},
                    }})
                }
            };
            self.materials.push(v);
        }
        for (v, name) in self.materials.iter_mut().zip(scene.desc().materials.keys()) {
            v["name"] = json!(name);
        }
    }

    fn objects(&mut self, scene: &Scene) {
        let desc = scene.desc();
        let mut written: Vec<(usize, usize)> = Vec::new();
        for (i, (o, built)) in desc.objects.iter().zip(&scene.objects).enumerate() {
            let same = written.iter().find(|(j, _)| {
                let other = &desc.objects[*j];
                other.shape == o.shape && other.material == o.material
            });
            let mesh = match same {
                Some(&(_, mesh)) => mesh,
                None => {
                    let value = self.bin.mesh(&built.mesh, built.material as usize);
                    self.meshes.push(value);
                    self.meshes.len() - 1
                }
            };
            written.push((i, mesh));
            let mut node = trs_json(&o.transform);
            node["name"] = json!(o.name);
            node["mesh"] = json!(mesh);
            node["extras"] = dynamic_extras(o.dynamic);
            self.object_nodes.insert(o.name.clone(), self.nodes.len());
            self.nodes.push(node);
        }
    }

    fn lights(&mut self, scene: &Scene) -> Result<(), SceneError> {
        for (i, (l, built)) in scene.desc().lights.iter().zip(&scene.lights).enumerate() {
            let mut node = json!({"name": l.name, "extras": dynamic_extras(l.dynamic)});
            let punctual = match &l.emitter {
                EmitterDesc::Point { intensity } => Some(self.punctual_light(*intensity, json!({"type": "point"}))),
                EmitterDesc::Spot { intensity, cone_deg, falloff_start_deg } => {
                    if *cone_deg > 90.0 {
                        return Err(invalid(
                            format!("lights[{i}].emitter.cone_deg"),
                            "glTF spot lights open at most 90°",
                        ));
                    }
                    let outer = cone_deg.to_radians();
                    let inner = falloff_start_deg.unwrap_or((cone_deg - 5.0).max(0.0)).to_radians().min(outer * 0.9999);
                    Some(self.punctual_light(
                        *intensity,
                        json!({"type": "spot", "spot": {"innerConeAngle": inner, "outerConeAngle": outer}}),
                    ))
                }
                EmitterDesc::Directional { direction, irradiance, angle_deg } => {
                    if *angle_deg > 0.0 {
                        node["extras"]["relume"]["angle_deg"] = json!(angle_deg);
                    }
                    let index = self.punctual_light(*irradiance, json!({"type": "directional"}));
                    let rotation = Quat::from_rotation_arc(Vec3::NEG_Z, Vec3::from(*direction).normalize());
                    node["rotation"] = json!(rotation.to_array());
                    node["extensions"] = json!({"KHR_lights_punctual": {"light": index}});
                    self.light_nodes.insert(l.name.clone(), (self.nodes.len(), true));
                    self.nodes.push(node);
                    continue;
                }
                EmitterDesc::Rect { radiance }
                | EmitterDesc::Disc { radiance, .. }
                | EmitterDesc::Mesh { radiance, .. } => {
                    let mesh = built.mesh.as_deref().ok_or_else(|| invalid(format!("lights[{i}]"), "has no mesh"))?;
                    let material = self.emissive_material(&l.name, *radiance);
                    let value = self.bin.mesh(mesh, material);
                    self.meshes.push(value);
                    node["mesh"] = json!(self.meshes.len() - 1);
                    None
                }
            };
            let mut trs = l.transform;
            if let Some(index) = punctual {
                trs.rotation = (Quat::from_array(trs.rotation).normalize() * light_axis_flip()).normalize().to_array();
                trs.scale = [1.0; 3];
                node["extensions"] = json!({"KHR_lights_punctual": {"light": index}});
            }
            for (k, v) in trs_json(&trs).as_object().into_iter().flatten() {
                node[k] = v.clone();
            }
            self.light_nodes.insert(l.name.clone(), (self.nodes.len(), punctual.is_some()));
            self.nodes.push(node);
        }
        Ok(())
    }

    fn punctual_light(&mut self, intensity: crate::core::Rgb, mut kind: Value) -> usize {
        self.extensions.insert("KHR_lights_punctual");
        let (color, strength) = match intensity.max_component() {
            m if m > 0.0 => ((intensity * (1.0 / m)).to_array(), m),
            _ => ([1.0; 3], 0.0),
        };
        kind["color"] = json!(color);
        kind["intensity"] = json!(strength * LUMENS_PER_WATT);
        self.punctual.push(kind);
        self.punctual.len() - 1
    }

    fn emissive_material(&mut self, light: &str, radiance: crate::core::Rgb) -> usize {
        let (factor, strength) = factor_and_strength(radiance);
        let mut m = json!({
            "name": format!("emission:{light}"),
            "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
            "emissiveFactor": factor,
        });
        if strength != 1.0 {
            self.extensions.insert("KHR_materials_emissive_strength");
            m["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": strength}});
        }
        self.materials.push(m);
        self.materials.len() - 1
    }

    fn camera(&mut self, c: &CameraDesc) {
        let distance = (Vec3::from(c.look_at) - Vec3::from(c.position)).length();
        self.camera_node = self.nodes.len();
        self.nodes.push(json!({
            "name": "camera", "camera": 0, "translation": c.position,
            "rotation": camera_rotation(c).to_array(),
            "extras": {"relume": {"resolution": c.resolution, "focus_distance": distance}},
        }));
    }

    fn animation(&mut self, name: &str, anim: &Animation, scene: &Scene) -> Value {
        let (mut samplers, mut channels) = (Vec::new(), Vec::new());
        let mut channel = |bin: &mut Bin, node: usize, path: &str, input: usize, values: Vec<f32>, width: usize| {
            let kind = if width == 4 { "VEC4" } else { "VEC3" };
            let output = bin.floats(&values, width, kind, None);
            samplers.push(json!({"input": input, "output": output, "interpolation": "LINEAR"}));
            channels.push(json!({"sampler": samplers.len() - 1, "target": {"node": node, "path": path}}));
        };
        for track in &anim.tracks {
            let (node, flip, keys) = match track {
                Track::Object { name, keyframes } => (self.object_nodes.get(name).copied(), false, keyframes),
                Track::Light { name, keyframes } => match self.light_nodes.get(name) {
                    Some(&(node, punctual)) => (Some(node), punctual, keyframes),
                    None => (None, false, keyframes),
                },
                Track::Camera { keyframes } => {
                    let times = increasing(keyframes.iter().map(|k| k.time));
                    let input = self.bin.floats(&times, 1, "SCALAR", None);
                    let cams: Vec<CameraDesc> = keyframes
                        .iter()
                        .map(|k| CameraDesc { position: k.position, look_at: k.look_at, ..scene.desc().camera.clone() })
                        .collect();
                    let node = self.camera_node;
                    channel(
                        &mut self.bin,
                        node,
                        "translation",
                        input,
                        cams.iter().flat_map(|c| c.position).collect(),
                        3,
                    );
                    let rotations = cams.iter().flat_map(|c| camera_rotation(c).to_array()).collect();
                    channel(&mut self.bin, node, "rotation", input, rotations, 4);
                    continue;
                }
            };
            let Some(node) = node else { continue };
            let times = increasing(keys.iter().map(|k| k.time));
            let input = self.bin.floats(&times, 1, "SCALAR", None);
            let turn = if flip { light_axis_flip() } else { Quat::IDENTITY };
            channel(
                &mut self.bin,
                node,
                "translation",
                input,
                keys.iter().flat_map(|k| k.transform.translation).collect(),
                3,
            );
            let rotations = keys
                .iter()
                .flat_map(|k| (Quat::from_array(k.transform.rotation).normalize() * turn).to_array())
                .collect();
            channel(&mut self.bin, node, "rotation", input, rotations, 4);
            if !flip {
                channel(&mut self.bin, node, "scale", input, keys.iter().flat_map(|k| k.transform.scale).collect(), 3);
            }
        }
        json!({"name": name, "samplers": samplers, "channels": channels})
    }
}

/// Key times made strictly increasing (equal times spread by [`MIN_KEY_GAP_S`]).
fn increasing(times: impl Iterator<Item = f32>) -> Vec<f32> {
    let mut out: Vec<f32> = Vec::new();
    for t in times {
        let t = match out.last() {
            Some(&prev) if t < prev + MIN_KEY_GAP_S => prev + MIN_KEY_GAP_S,
            _ => t,
        };
        out.push(t);
    }
    out
}
