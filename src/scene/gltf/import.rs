//! A glTF document as a relume scene description: mesh primitives become objects with inline
//! triangles (or `mesh` lights, when their material emits), punctual lights become point and
//! spot lights, and one camera becomes the scene's camera.
//!
//! Units: glTF's metres are kept, times the scene-level `scale`. glTF gives punctual lights in
//! candela (lm/sr); relume's intensity is radiometric, W/sr = cd / 683 (the luminous efficacy
//! that defines the candela). Emission maps one to one (see `materials.rs`).
use super::materials;
use super::nodes::{check_world, decompose, node_label, relume_extras, NodeInfo};
use super::warnings::Warnings;
use super::Target;
use crate::core::Rgb;
use crate::scene::load::{invalid, SceneBudget, SceneError, MAX_COORDINATE};
use crate::scene::model::*;
use glam::{Mat4, Quat, Vec3};
use std::collections::{BTreeMap, HashMap, HashSet};

/// Lumens per watt at 555 nm: candela = 683 × W/sr.
pub const LUMENS_PER_WATT: f32 = 683.0;
/// Rows of the image when the file does not say (its camera's aspect ratio sets the width).
pub const DEFAULT_ROWS: u32 = 256;
/// Vertical field of view of the camera made for a file without one, degrees.
const FRAMING_VFOV_DEG: f32 = 40.0;

/// The rotation taking a punctual light's glTF axis (local −Z) to relume's (local +Z).
pub fn light_axis_flip() -> Quat {
    Quat::from_rotation_y(std::f32::consts::PI)
}

/// Camera position, look-at and up from a camera node's world matrix (glTF cameras look
/// along local −Z with +Y up); `focus` is the look-at distance.
pub fn camera_pose(world: &Mat4, focus: f32) -> ([f32; 3], [f32; 3], [f32; 3]) {
    let position = world.transform_point3(Vec3::ZERO);
    let forward = world.transform_vector3(Vec3::NEG_Z).normalize_or(Vec3::NEG_Z);
    let up = world.transform_vector3(Vec3::Y).normalize_or(Vec3::Y);
    (position.to_array(), (position + forward * focus).to_array(), up.to_array())
}

/// A primitive's positions, triangles and vertex normals (`NORMAL`), if it has them.
type Primitive = (Positions, Indices, Option<Positions>);

pub struct Importer<'a> {
    buffers: &'a [Vec<u8>],
    budget: SceneBudget,
    pub warnings: Warnings,
    pub objects: Vec<ObjectDesc>,
    pub lights: Vec<LightDesc>,
    pub materials: BTreeMap<String, Material>,
    /// glTF material index (`None`: the default material) → relume material name.
    material_names: HashMap<Option<usize>, String>,
    names: HashSet<String>,
    light_names: HashSet<String>,
    primitives: HashMap<(usize, usize, bool), Primitive>,
    triangles: u64,
    bounds: Option<(Vec3, Vec3)>,
    /// What each animated node drives, for the animation import.
    pub targets: Vec<(usize, Target)>,
}

impl<'a> Importer<'a> {
    pub fn new(buffers: &'a [Vec<u8>], budget: SceneBudget) -> Importer<'a> {
        Importer {
            buffers,
            budget,
            warnings: Warnings::default(),
            objects: Vec::new(),
            lights: Vec::new(),
            materials: BTreeMap::new(),
            material_names: HashMap::new(),
            names: HashSet::new(),
            light_names: HashSet::new(),
            primitives: HashMap::new(),
            triangles: 0,
            bounds: None,
            targets: Vec::new(),
        }
    }

    /// Adds what one node holds: its mesh's primitives and its punctual light.
    pub fn add_node(&mut self, node: &gltf::Node, info: &NodeInfo) -> Result<(), SceneError> {
        let label = node_label(node);
        if node.skin().is_some() {
            self.warnings.add("skins are not read; the mesh renders in its bind pose", &label);
        }
        if node.mesh().is_some() || node.light().is_some() {
            check_world(&label, &info.world)?;
        }
        if let Some(mesh) = node.mesh() {
            let primitives = mesh.primitives().len();
            for prim in mesh.primitives() {
                let base = node.name().map(str::to_string).unwrap_or_else(|| format!("node{}", node.index()));
                let name = if primitives > 1 { format!("{base}/{}", prim.index()) } else { base };
                self.add_primitive(&label, &mesh, &prim, info, name)?;
            }
        }
        if let Some(light) = node.light() {
            self.add_punctual(&label, &light, node, info)?;
        }
        Ok(())
    }

    fn add_primitive(
        &mut self,
        label: &str,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        info: &NodeInfo,
        name: String,
    ) -> Result<(), SceneError> {
        let world = info.world;
        let mirrored = world.determinant() < 0.0;
        let (positions, indices, normals) = self.primitive(mesh, prim, mirrored)?;
        self.count(indices.len() as u64)?;
        self.grow_bounds(label, &world, &positions)?;
        let (transform, positions, normals) = match decompose(&world) {
            Some(trs) => (trs, positions, normals),
            None if info.dynamic => return Err(invalid(
                label,
                "its world matrix has shear (a non-uniform scale under a rotation), which a moving object cannot have",
            )),
            None => {
                let normal_matrix = glam::Mat3::from_mat4(world).inverse().transpose();
                let normals = normals.map(|n| n.iter().map(|v| (normal_matrix * Vec3::from(*v)).to_array()).collect());
                let positions = positions.iter().map(|p| world.transform_point3((*p).into()).to_array()).collect();
                (Trs::default(), positions, normals)
            }
        };
        let material = prim.material();
        if let Some(radiance) = materials::emission(&material) {
            let name = unique(&mut self.light_names, name);
            self.lights.push(LightDesc {
                name: name.clone(),
                emitter: EmitterDesc::Mesh { radiance, positions, indices },
                transform,
                dynamic: info.dynamic,
            });
            self.targets.push((info.index, Target::Light { name, punctual: false }));
            return Ok(());
        }
        let material = self.material(&material);
        let name = unique(&mut self.names, name);
        self.objects.push(ObjectDesc {
            name: name.clone(),
            shape: ShapeDesc::Triangles { positions, indices, normals },
            material,
            transform,
            dynamic: info.dynamic,
        });
        self.targets.push((info.index, Target::Object(name)));
        Ok(())
    }

    /// A primitive's triangles, read once per (mesh, primitive, mirrored): a node whose world
    /// matrix mirrors (negative determinant) flips the winding, as glTF's front faces do.
    fn primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        mirrored: bool,
    ) -> Result<Primitive, SceneError> {
        let key = (mesh.index(), prim.index(), mirrored);
        if let Some(p) = self.primitives.get(&key) {
            return Ok(p.clone());
        }
        let field = match mesh.name() {
            Some(n) => format!("meshes[{}] ('{n}').primitives[{}]", mesh.index(), prim.index()),
            None => format!("meshes[{}].primitives[{}]", mesh.index(), prim.index()),
        };
        if prim.mode() != gltf::mesh::Mode::Triangles {
            return Err(invalid(format!("{field}.mode"), format!("{:?} is not read; only TRIANGLES", prim.mode())));
        }
        self.warn_attributes(&field, prim);
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let positions: Vec<[f32; 3]> =
            reader.read_positions().ok_or_else(|| invalid(format!("{field}.attributes"), "has no POSITION"))?.collect();
        let flat: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        if flat.len() % 3 != 0 {
            return Err(invalid(
                format!("{field}.indices"),
                format!("{} indices do not make whole triangles", flat.len()),
            ));
        }
        let mut triangles: Vec<[u32; 3]> = flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        if mirrored {
            triangles.iter_mut().for_each(|t| t.swap(1, 2));
        }
        let normals: Option<Vec<[f32; 3]>> = reader.read_normals().map(Iterator::collect);
        crate::scene::load::inline_mesh(&field, &positions, &triangles, normals.as_deref())?;
        let p: Primitive = (positions.into(), triangles.into(), normals.map(Into::into));
        self.primitives.insert(key, p.clone());
        Ok(p)
    }

    fn warn_attributes(&mut self, field: &str, prim: &gltf::Primitive) {
        use gltf::Semantic;
        for (semantic, _) in prim.attributes() {
            let message = match semantic {
                Semantic::Colors(_) => "vertex colours are not read",
                Semantic::Joints(_) | Semantic::Weights(_) => "skinning attributes are not read",
                _ => continue,
            };
            self.warnings.add(message, field);
        }
        if prim.morph_targets().len() > 0 {
            self.warnings.add("morph targets are not read", field);
        }
    }

    fn count(&mut self, indices: u64) -> Result<(), SceneError> {
        self.triangles += indices / 3;
        if self.triangles > self.budget.max_triangles {
            return Err(SceneError::TooLarge {
                field: "meshes".into(),
                message: format!("more than {} triangles", self.budget.max_triangles),
            });
        }
        if self.objects.len() >= self.budget.max_objects || self.lights.len() >= self.budget.max_lights {
            return Err(SceneError::TooLarge {
                field: "nodes".into(),
                message: format!("more than {} objects or {} lights", self.budget.max_objects, self.budget.max_lights),
            });
        }
        Ok(())
    }

    /// Grows the scene's bounds by the node's world-space vertices, refusing the node when a
    /// vertex lands beyond ±[`MAX_COORDINATE`] (scene validation's bound, named here by node).
    fn grow_bounds(&mut self, label: &str, world: &Mat4, positions: &[[f32; 3]]) -> Result<(), SceneError> {
        for p in positions {
            let w = world.transform_point3((*p).into());
            let reach = w.abs().max_element();
            if reach.is_nan() || reach > MAX_COORDINATE {
                return Err(invalid(
                    label,
                    format!("puts its mesh {reach:e} from the origin, beyond ±{MAX_COORDINATE:e}, the largest world coordinate"),
                ));
            }
            self.bounds = Some(match self.bounds {
                Some((lo, hi)) => (lo.min(w), hi.max(w)),
                None => (w, w),
            });
        }
        Ok(())
    }

    /// The relume name of a glTF material, converting it on first use.
    fn material(&mut self, m: &gltf::Material) -> String {
        if let Some(name) = self.material_names.get(&m.index()) {
            return name.clone();
        }
        let converted = materials::convert(m, &mut self.warnings);
        let base = match (m.index(), m.name()) {
            (_, Some(n)) if !n.is_empty() => n.to_string(),
            (Some(i), _) => format!("material{i}"),
            (None, _) => "default".to_string(),
        };
        let mut name = base.clone();
        let mut n = 2;
        while self.materials.contains_key(&name) {
            name = format!("{base}#{n}");
            n += 1;
        }
        self.materials.insert(name.clone(), converted);
        self.material_names.insert(m.index(), name.clone());
        name
    }

    fn add_punctual(
        &mut self,
        label: &str,
        light: &gltf::khr_lights_punctual::Light,
        node: &gltf::Node,
        info: &NodeInfo,
    ) -> Result<(), SceneError> {
        use gltf::khr_lights_punctual::Kind;
        let field = format!("{label}.extensions.KHR_lights_punctual");
        let [r, g, b] = light.color();
        let intensity = Rgb::new(r, g, b) * (light.intensity() / LUMENS_PER_WATT);
        if light.range().is_some() {
            self.warnings.add("light range is not read; relume lights fall off with the inverse square", label);
        }
        let emitter = match light.kind() {
            Kind::Point => EmitterDesc::Point { intensity },
            Kind::Spot { inner_cone_angle, outer_cone_angle } => EmitterDesc::Spot {
                intensity,
                cone_deg: outer_cone_angle.to_degrees(),
                falloff_start_deg: Some(inner_cone_angle.to_degrees()),
            },
            Kind::Directional => {
                let direction = info.world.transform_vector3(Vec3::NEG_Z);
                if !(direction.is_finite() && direction.length() > 1e-6) {
                    return Err(invalid(format!("{label}.rotation"), "the light's −Z axis has no direction"));
                }
                if info.dynamic {
                    self.warnings
                        .add("animation of a directional light is not read; it keeps its first direction", label);
                }
                let angle_deg =
                    relume_extras(node.extras()).and_then(|e| e.get("angle_deg")?.as_f64()).map_or(0.0, |a| a as f32);
                let emitter = EmitterDesc::Directional {
                    direction: direction.normalize().to_array(),
                    irradiance: intensity,
                    angle_deg,
                };
                crate::scene::load::validate_emitter(&field, &emitter)?;
                self.count(0)?;
                let name = node.name().map(str::to_string).or(light.name().map(str::to_string));
                let name = unique(&mut self.light_names, name.unwrap_or_else(|| format!("light{}", node.index())));
                self.lights.push(LightDesc { name, emitter, transform: Trs::default(), dynamic: false });
                return Ok(());
            }
        };
        let name = node.name().map(str::to_string).or(light.name().map(str::to_string));
        self.count(0)?;
        let name = unique(&mut self.light_names, name.unwrap_or_else(|| format!("light{}", node.index())));
        self.lights.push(LightDesc {
            name: name.clone(),
            emitter,
            transform: punctual_trs(&info.world),
            dynamic: info.dynamic,
        });
        self.targets.push((info.index, Target::Light { name, punctual: true }));
        Ok(())
    }

    /// The camera on `node` (a perspective one), its look-at distance taken from the node's
    /// `extras.relume.focus_distance` or the scene's bounds.
    pub fn camera(&self, node: &gltf::Node, info: &NodeInfo) -> Result<CameraDesc, SceneError> {
        let label = node_label(node);
        let camera = node.camera().ok_or_else(|| invalid(&label, "has no camera"))?;
        let gltf::camera::Projection::Perspective(p) = camera.projection() else {
            return Err(invalid(format!("{label}.camera"), "is orthographic; only perspective cameras are read"));
        };
        let extras = relume_extras(node.extras());
        let focus = extras.as_ref().and_then(|e| e.get("focus_distance")?.as_f64()).map(|f| f as f32);
        let position = info.world.transform_point3(Vec3::ZERO);
        let focus = focus.filter(|f| f.is_finite() && *f > 0.0).unwrap_or_else(|| match self.bounds {
            Some((lo, hi)) => (0.5 * (lo + hi) - position).length().max(1e-3),
            None => 1.0,
        });
        let (position, look_at, up) = camera_pose(&info.world, focus);
        let resolution = extras
            .as_ref()
            .and_then(|e| serde_json::from_value::<[u32; 2]>(e.get("resolution")?.clone()).ok())
            .unwrap_or_else(|| {
                let aspect = p.aspect_ratio().filter(|a| a.is_finite() && *a > 0.0).unwrap_or(1.0);
                [((DEFAULT_ROWS as f32 * aspect).round() as u32).max(1), DEFAULT_ROWS]
            });
        Ok(CameraDesc { position, look_at, up, vfov_deg: p.yfov().to_degrees(), resolution })
    }

    /// A camera looking at the scene's bounds along −Z, for a file without one.
    pub fn framing_camera(&mut self) -> CameraDesc {
        self.warnings.add("the file has no perspective camera; one framing the scene's bounds is used", "cameras");
        let (lo, hi) = self.bounds.unwrap_or((Vec3::splat(-1.0), Vec3::splat(1.0)));
        let (center, radius) = (0.5 * (lo + hi), (0.5 * (hi - lo)).length().max(1e-3));
        let distance = 1.1 * radius / (0.5 * FRAMING_VFOV_DEG.to_radians()).sin();
        CameraDesc {
            position: (center + Vec3::Z * distance).to_array(),
            look_at: center.to_array(),
            up: [0.0, 1.0, 0.0],
            vfov_deg: FRAMING_VFOV_DEG,
            resolution: [DEFAULT_ROWS, DEFAULT_ROWS],
        }
    }
}

/// A punctual light's relume transform: its node's position and rotation (axis flipped from
/// −Z to +Z), unit scale.
pub fn punctual_trs(world: &Mat4) -> Trs {
    let (_, r, t) = world.to_scale_rotation_translation();
    let r = if r.is_finite() { r.normalize() } else { Quat::IDENTITY };
    Trs { translation: t.to_array(), rotation: (r * light_axis_flip()).normalize().to_array(), scale: [1.0; 3] }
}

/// `name`, or `name#2`, `name#3`, … if taken.
fn unique(taken: &mut HashSet<String>, name: String) -> String {
    let name = if name.is_empty() { "unnamed".to_string() } else { name };
    let mut candidate = name.clone();
    let mut n = 2;
    while !taken.insert(candidate.clone()) {
        candidate = format!("{name}#{n}");
        n += 1;
    }
    candidate
}
