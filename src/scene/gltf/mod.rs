//! glTF 2.0 scenes (`.gltf` with its buffers, or `.glb`): import into a relume scene
//! description with its animations and a load report, and export of a relume scene back.
//!
//! What import reads, warns about, or refuses:
//! - **Read:** the default scene's node hierarchy (TRS or T·R·S `matrix`), TRIANGLES
//!   primitives (positions, indices, normals), materials (see `materials.rs`), emissive primitives as
//!   `mesh` lights, `KHR_lights_punctual` point and spot lights (candela → W/sr by 1/683), the
//!   first perspective camera or the one named, TRS animation channels in all three
//!   interpolations (see `animation.rs`), `extras.relume` (`dynamic`, and a camera's
//!   `resolution` and `focus_distance`), buffers from the GLB chunk, `data:` URIs and files
//!   inside the scenes root.
//! - **Warned (read in part):** textures (their factors are used), partial metalness, alpha
//!   modes, partial transmission, out-of-range colours, vertex colours, skins,
//!   morph targets, light `range`, CUBICSPLINE sampling, a missing camera or material.
//! - **Refused (an error naming the part):** other primitive modes, matrices with shear, moving
//!   nodes whose world transform gets shear, directional lights, orthographic cameras chosen by
//!   name, buffers outside the scenes root or over the limits, non-finite data, bad indices.
//!
//! Units: metres as in the file, times `scale`. Objects animated by the file (or whose node
//! or an ancestor's `extras` say `{"relume": {"dynamic": true}}`) are dynamic.
mod animation;
mod buffers;
mod export;
mod import;
mod materials;
mod nodes;
mod warnings;

pub use buffers::FileContext;
pub use export::export_glb;

use super::animation::Animation;
use super::load::{invalid, SceneBudget, SceneError};
use super::model::SceneDesc;
use glam::Mat4;
use std::path::Path;

/// What one animated node drives.
#[derive(Clone, Debug)]
pub enum Target {
    Object(String),
    /// `punctual`: a point or spot light (its axis is flipped from glTF's −Z).
    Light {
        name: String,
        punctual: bool,
    },
    /// The scene's camera, with its look-at distance.
    Camera {
        focus: f32,
    },
}

/// How to read a glTF file.
#[derive(Clone, Debug)]
pub struct ImportOptions {
    /// The camera to use, by camera or node name; the first perspective camera otherwise.
    pub camera: Option<String>,
    /// Uniform scale applied to the whole scene (glTF is in metres).
    pub scale: f32,
    pub budget: SceneBudget,
    /// Bytes the buffers may hold in all.
    pub max_buffer_bytes: u64,
    /// The environment to light the scene with, over the file's own.
    pub environment: Option<crate::scene::EnvironmentDesc>,
}

impl Default for ImportOptions {
    fn default() -> ImportOptions {
        ImportOptions {
            camera: None,
            scale: 1.0,
            budget: SceneBudget::default(),
            max_buffer_bytes: 1 << 31,
            environment: None,
        }
    }
}

/// A glTF file as relume reads it.
#[derive(Clone, Debug)]
pub struct Imported {
    pub desc: SceneDesc,
    /// The file's animations, by their names in the file (`animation3` when unnamed).
    pub animations: Vec<(String, Animation)>,
    /// What was read only in part (the load report).
    pub warnings: Vec<String>,
}

impl Imported {
    pub fn animation(&self, name: &str) -> Option<&Animation> {
        self.animations.iter().find(|(n, _)| n == name).map(|(_, a)| a)
    }
}

/// Whether a path names a glTF file (`.gltf` or `.glb`).
pub fn is_gltf_path(path: &Path) -> bool {
    matches!(path.extension().and_then(|e| e.to_str()), Some("gltf" | "glb"))
}

/// Reads a `.gltf` or `.glb` file; external buffers resolve next to it, inside `root`.
pub fn import_file(path: &Path, root: &Path, options: &ImportOptions) -> Result<Imported, SceneError> {
    let bytes =
        std::fs::read(path).map_err(|e| SceneError::Io { path: path.display().to_string(), message: e.to_string() })?;
    let dir = path.parent().unwrap_or(Path::new("."));
    import_slice(&bytes, Some(&FileContext { dir, root }), options)
}

/// Reads glTF JSON or GLB bytes. Without `files` (a document sent inline) only the GLB chunk
/// and `data:` URIs can hold buffers.
pub fn import_slice(
    bytes: &[u8],
    files: Option<&FileContext>,
    options: &ImportOptions,
) -> Result<Imported, SceneError> {
    if !(options.scale.is_finite() && options.scale > 0.0) {
        return Err(invalid("scale", format!("{} is not a positive finite number", options.scale)));
    }
    // gltf-json 1.4.1's validation indexes some arrays before checking the index (a POSITION
    // accessor out of range panics), and hostile documents must cost nothing: a panic in the
    // parser or in reading its data is a refusal of the document.
    let read = std::panic::AssertUnwindSafe(|| -> Result<Imported, SceneError> {
        let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| invalid("gltf", e.to_string()))?;
        let gltf::Gltf { document, blob } = gltf;
        let buffers = buffers::load(&document, blob, files, options.max_buffer_bytes)?;
        convert(&document, &buffers, options)
    });
    std::panic::catch_unwind(read).unwrap_or_else(|_| {
        Err(invalid("gltf", "malformed document: an index points outside its array (the glTF parser failed on it)"))
    })
}

fn convert(doc: &gltf::Document, buffers: &[Vec<u8>], options: &ImportOptions) -> Result<Imported, SceneError> {
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| invalid("scenes", "the file has no scene"))?;
    let animated = doc.animations().flat_map(|a| a.channels().map(|c| c.target().node().index()).collect::<Vec<_>>());
    let root = Mat4::from_scale(glam::Vec3::splat(options.scale));
    let nodes = nodes::walk(&scene, root, &animated.collect())?;
    let mut importer = import::Importer::new(buffers, options.budget);
    for info in &nodes {
        if let Some(node) = doc.nodes().nth(info.index) {
            importer.add_node(&node, info)?;
        }
    }
    let camera = choose_camera(doc, &nodes, options.camera.as_deref())?;
    let desc_camera = match &camera {
        Some((node, info)) => importer.camera(node, info)?,
        None => importer.framing_camera(),
    };
    if let Some((node, info)) = &camera {
        if info.dynamic {
            let focus = (glam::Vec3::from(desc_camera.look_at) - glam::Vec3::from(desc_camera.position)).length();
            importer.targets.push((node.index(), Target::Camera { focus }));
        }
    }
    let animations = animation::convert(doc, buffers, &nodes, &importer.targets, root, &mut importer.warnings)?;
    let desc = SceneDesc {
        camera: desc_camera,
        materials: importer.materials,
        objects: importer.objects,
        lights: importer.lights,
        environment: scene_environment(&scene)?,
    };
    Ok(Imported { desc, animations, warnings: importer.warnings.into_lines() })
}

/// The scene's `extras.relume.environment`, if it has one (validated).
fn scene_environment(scene: &gltf::Scene) -> Result<Option<crate::scene::EnvironmentDesc>, SceneError> {
    let Some(value) = nodes::relume_extras(scene.extras()).and_then(|e| e.get("environment").cloned()) else {
        return Ok(None);
    };
    let field = "scenes.extras.relume.environment";
    let env: crate::scene::EnvironmentDesc =
        serde_json::from_value(value).map_err(|e| invalid(field, e.to_string()))?;
    crate::scene::load::validate_environment(field, &env)?;
    Ok(Some(env))
}

/// The camera node to use: the one whose camera or node is called `name`, or the first
/// perspective camera reached.
fn choose_camera<'a>(
    doc: &'a gltf::Document,
    nodes: &'a [nodes::NodeInfo],
    name: Option<&str>,
) -> Result<Option<(gltf::Node<'a>, &'a nodes::NodeInfo)>, SceneError> {
    let with_camera = nodes.iter().filter_map(|info| {
        let node = doc.nodes().nth(info.index)?;
        node.camera().is_some().then_some((node, info))
    });
    let Some(name) = name else {
        return Ok(with_camera.into_iter().find(|(n, _)| {
            n.camera().is_some_and(|c| matches!(c.projection(), gltf::camera::Projection::Perspective(_)))
        }));
    };
    let mut with_camera = with_camera;
    with_camera
        .find(|(n, _)| {
            n.name() == Some(name) || n.camera().and_then(|c| c.name().map(str::to_string)).as_deref() == Some(name)
        })
        .map(Some)
        .ok_or_else(|| invalid("camera", format!("no camera or camera node named '{name}' in the scene")))
}
