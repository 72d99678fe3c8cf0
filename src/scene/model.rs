//! The scene file format: plain serde data, exactly what `scenes/*.json` holds and
//! `proto/scene.schema.json` documents. Validation happens once, in `load.rs`.
//!
//! Conventions: meters, radians except fields named `*_deg`; right-handed, +Y up; transforms are
//! glTF-style TRS (`world_from_object = T·R·S`, rotation a unit quaternion `[x, y, z, w]`).
//! Primitive shapes follow Mitsuba's canonical extents: `quad` spans [-1,1]² in the XY plane
//! facing +Z, `box` is [-1,1]³, `sphere` has radius 1, `disc` radius 1 in XY facing +Z, and
//! `cylinder` radius 1 from z=0 to z=1 with both caps. Area lights emit towards their local +Z;
//! spot lights point along their local +Z.
use crate::core::Rgb;
use glam::{Affine3A, Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Object-space vertex positions of an inline triangle list (what a glTF primitive becomes).
/// Shared, so cloning a description does not copy its meshes.
pub type Positions = Arc<[[f32; 3]]>;
/// Counter-clockwise vertex-index triples into [`Positions`]; the front face is the side
/// `(p1-p0)×(p2-p0)` points to.
pub type Indices = Arc<[[u32; 3]]>;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneDesc {
    pub camera: CameraDesc,
    /// Materials by name; objects refer to them by that name.
    pub materials: BTreeMap<String, Material>,
    pub objects: Vec<ObjectDesc>,
    #[serde(default)]
    pub lights: Vec<LightDesc>,
    /// Light arriving from outside the scene along every ray that leaves it. Absent: none
    /// (black), unless the scene has no light at all (see `load::light_the_lightless`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment: Option<EnvironmentDesc>,
}

/// The environment around a scene: `{"radiance": [r, g, b]}`, uniform radiance in
/// W/(sr·m²) from every direction.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentDesc {
    pub radiance: Rgb,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    pub position: [f32; 3],
    pub look_at: [f32; 3],
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    /// Full vertical field of view, degrees.
    pub vfov_deg: f32,
    /// `[width, height]` in pixels.
    pub resolution: [u32; 2],
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Material {
    /// Lambertian; `reflectance` in [0,1] per channel.
    Diffuse { reflectance: Rgb },
    /// Ideal specular reflector tinted by `reflectance`.
    Mirror {
        #[serde(default = "white")]
        reflectance: Rgb,
    },
    /// Ideal smooth dielectric with index of refraction `ior` (outside is vacuum).
    Glass { ior: f32 },
}

fn white() -> Rgb {
    Rgb::WHITE
}

/// A TRS transform; `world_from_object = T·R·S`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Trs {
    #[serde(default)]
    pub translation: [f32; 3],
    /// Unit quaternion `[x, y, z, w]`.
    #[serde(default = "identity_rotation")]
    pub rotation: [f32; 4],
    #[serde(default = "unit_scale")]
    pub scale: [f32; 3],
}

fn identity_rotation() -> [f32; 4] {
    [0.0, 0.0, 0.0, 1.0]
}

fn unit_scale() -> [f32; 3] {
    [1.0, 1.0, 1.0]
}

impl Default for Trs {
    fn default() -> Trs {
        Trs { translation: [0.0; 3], rotation: identity_rotation(), scale: unit_scale() }
    }
}

impl Trs {
    pub fn world_from_object(&self) -> Affine3A {
        Affine3A::from_scale_rotation_translation(
            Vec3::from(self.scale),
            Quat::from_array(self.rotation).normalize(),
            Vec3::from(self.translation),
        )
    }

    pub fn translation(&self) -> Vec3 {
        Vec3::from(self.translation)
    }

    pub fn rotation(&self) -> Quat {
        Quat::from_array(self.rotation).normalize()
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectDesc {
    pub name: String,
    pub shape: ShapeDesc,
    /// Name of an entry in `materials`.
    pub material: String,
    #[serde(default)]
    pub transform: Trs,
    /// Dynamic objects get their own Embree instance and may be moved by edits; static ones are
    /// merged into one bottom-level scene that is never rebuilt.
    #[serde(default)]
    pub dynamic: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeDesc {
    /// A Wavefront OBJ file, relative to the scene file and inside the scenes root.
    Mesh {
        path: String,
    },
    Quad,
    Box,
    Sphere {
        #[serde(default = "default_segments")]
        segments: u32,
    },
    Disc {
        #[serde(default = "default_segments")]
        segments: u32,
    },
    Cylinder {
        #[serde(default = "default_segments")]
        segments: u32,
    },
    /// Triangles given inline (what glTF import makes of a mesh primitive), with optional unit
    /// vertex normals (one per position) that shade them smoothly.
    Triangles {
        positions: Positions,
        indices: Indices,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        normals: Option<Positions>,
    },
}

pub fn default_segments() -> u32 {
    32
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightDesc {
    pub name: String,
    /// What the light emits and from what shape (`{"type": "rect", "radiance": [..]}`, ...).
    pub emitter: EmitterDesc,
    #[serde(default)]
    pub transform: Trs,
    #[serde(default)]
    pub dynamic: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum EmitterDesc {
    /// Isotropic point light; `intensity` in W/sr.
    Point { intensity: Rgb },
    /// Spot light along local +Z; `intensity` in W/sr on the axis, smoothly falling to zero
    /// between `falloff_start_deg` and `cone_deg` (half-angles).
    Spot {
        intensity: Rgb,
        #[serde(default = "default_cone")]
        cone_deg: f32,
        /// Absent (never `null`) when not given: the schema's number has no null.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        falloff_start_deg: Option<f32>,
    },
    /// One-sided rectangle ([-1,1]² in XY, emitting to +Z); `radiance` in W/(sr·m²).
    Rect { radiance: Rgb },
    /// One-sided disc (radius 1 in XY, emitting to +Z), tessellated into `segments` triangles.
    Disc {
        radiance: Rgb,
        #[serde(default = "default_segments")]
        segments: u32,
    },
    /// One-sided triangle mesh, emitting towards each triangle's front face and sampled by
    /// area (what glTF import makes of an emissive primitive); `radiance` in W/(sr·m²).
    Mesh { radiance: Rgb, positions: Positions, indices: Indices },
    /// A distant light such as the sun: light travelling along `direction` (from the light into
    /// the scene), `irradiance` in W/m² on a surface facing it, from a disc of angular diameter
    /// `angle_deg` (0, the default, is a delta light whose shadows are sharp). It has no
    /// placement: its transform must be the identity.
    Directional {
        direction: [f32; 3],
        irradiance: Rgb,
        #[serde(default)]
        angle_deg: f32,
    },
}

fn default_cone() -> f32 {
    30.0
}
