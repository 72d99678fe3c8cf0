//! Loading and validating scenes. Validation happens here, once: everything later trusts the
//! model. Every error names the offending field (`objects[2].transform.rotation`) or file and
//! line; nothing non-finite gets in, and nothing that f32 arithmetic on it would overflow: world
//! coordinates, scale factors and emission have bounds ([`MAX_COORDINATE`], [`SCALE_LIMITS`],
//! [`MAX_EMISSION`]), checked for scenes and edits alike.
use super::edits::Aabb;
use super::model::*;
use super::shapes::Mesh;
use glam::Vec3;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Quaternions must have unit length within this tolerance.
pub const QUATERNION_TOLERANCE: f32 = 1e-3;
/// Largest accepted image side, in pixels.
pub const MAX_RESOLUTION: u32 = 16384;
/// Largest accepted tessellation parameter.
pub const MAX_SEGMENTS: u32 = 4096;
/// The largest magnitude a world coordinate may have, in scene units: of an object's vertices
/// where its transform puts them, of a light's shape or position, of the camera's position and
/// target. Far beyond any scene (the hard cases move objects by 1e5), and small enough that the
/// areas, extents and cell counts techniques work out from positions stay finite in f32.
pub const MAX_COORDINATE: f32 = 1e8;
/// The largest component of a light's radiance (W/(sr·m²)) or intensity (W/sr): far above any
/// physical source in any unit of length (`tests/hard_cases.rs` shows images linear in it up to
/// here), and small enough that a light's power, radiance times an area of up to
/// (2·[`MAX_COORDINATE`])² times π, stays finite in f32 (about 1.3e37).
pub const MAX_EMISSION: f32 = 1e20;
/// The least and the largest magnitude of a scale factor.
pub const SCALE_LIMITS: [f32; 2] = [1e-6, 1e6];

#[derive(Debug, Error, Clone, PartialEq)]
pub enum SceneError {
    #[error("cannot read {path}: {message}")]
    Io { path: String, message: String },
    #[error("{field}: {message}")]
    Invalid { field: String, message: String },
    /// Over a [`SceneBudget`]: found before anything was built.
    #[error("{field}: {message}")]
    TooLarge { field: String, message: String },
}

/// What a scene may hold, checked from the description (shape parameters and OBJ face
/// counts) before any mesh is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneBudget {
    pub max_triangles: u64,
    pub max_objects: usize,
    /// At most 65 536: `photon_reuse` stores a path's light in 16 bits.
    pub max_lights: usize,
}

impl Default for SceneBudget {
    /// Bounds for local use (the CLI); the server passes its own, tighter limits.
    fn default() -> SceneBudget {
        SceneBudget { max_triangles: 64_000_000, max_objects: 100_000, max_lights: 4096 }
    }
}

/// Triangles the description's objects and light shapes will make, counted without making
/// them. Mesh paths are resolved (and confined to `root`) as the build will resolve them.
pub fn count_triangles(desc: &SceneDesc, scene_dir: &Path, root: &Path) -> Result<u64, SceneError> {
    let mut files: std::collections::HashMap<PathBuf, u64> = Default::default();
    let mut total = 0u64;
    for (i, o) in desc.objects.iter().enumerate() {
        total += match &o.shape {
            ShapeDesc::Mesh { path } => {
                let field = format!("objects[{i}].shape.path");
                let file = resolve_mesh_path(&field, path, scene_dir, root)?;
                match files.get(&file) {
                    Some(&n) => n,
                    None => {
                        let n = Mesh::count_obj_triangles(&file).map_err(|e| invalid(&field, e))?;
                        files.insert(file, n);
                        n
                    }
                }
            }
            ShapeDesc::Quad => 2,
            ShapeDesc::Box => 12,
            ShapeDesc::Sphere { segments } => Mesh::sphere_triangles(*segments),
            ShapeDesc::Disc { segments } => Mesh::disc_triangles(*segments),
            ShapeDesc::Cylinder { segments } => Mesh::cylinder_triangles(*segments),
            ShapeDesc::Triangles { indices, .. } => indices.len() as u64,
        };
    }
    for l in &desc.lights {
        total += match &l.emitter {
            EmitterDesc::Rect { .. } => 2,
            EmitterDesc::Disc { segments, .. } => Mesh::disc_triangles(*segments),
            EmitterDesc::Mesh { indices, .. } => indices.len() as u64,
            EmitterDesc::Point { .. } | EmitterDesc::Spot { .. } | EmitterDesc::Directional { .. } => 0,
        };
    }
    Ok(total)
}

/// Refuses a description over `budget`, naming the field, before anything is built.
pub fn check_budget(desc: &SceneDesc, scene_dir: &Path, root: &Path, budget: &SceneBudget) -> Result<(), SceneError> {
    let too_large = |field: &str, message: String| SceneError::TooLarge { field: field.into(), message };
    if desc.objects.len() > budget.max_objects {
        return Err(too_large(
            "objects",
            format!("{} objects exceed the limit of {}", desc.objects.len(), budget.max_objects),
        ));
    }
    if desc.lights.len() > budget.max_lights {
        return Err(too_large(
            "lights",
            format!("{} lights exceed the limit of {}", desc.lights.len(), budget.max_lights),
        ));
    }
    let triangles = count_triangles(desc, scene_dir, root)?;
    if triangles > budget.max_triangles {
        return Err(too_large(
            "objects",
            format!(
                "{triangles} triangles (from the shapes' segments and the OBJ files' faces) exceed the limit of {}",
                budget.max_triangles
            ),
        ));
    }
    Ok(())
}

pub(crate) fn invalid(field: impl Into<String>, message: impl Into<String>) -> SceneError {
    SceneError::Invalid { field: field.into(), message: message.into() }
}

/// Parses scene JSON; errors carry the JSON path of the field and serde's line/column.
pub fn parse_scene_json(text: &str) -> Result<SceneDesc, SceneError> {
    parse_json(text)
}

/// Parses any of the model's JSON documents with the field path in errors.
pub fn parse_json<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, SceneError> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let field = if path.is_empty() || path == "." { "(document)".to_string() } else { path };
        invalid(field, e.into_inner().to_string())
    })
}

fn check_finite(field: &str, values: &[f32]) -> Result<(), SceneError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(invalid(format!("{field}[{i}]"), format!("{} is not a finite number", values[i]))),
        None => Ok(()),
    }
}

/// Refuses a colour with a negative or non-finite component, or one above `max` (`why` says
/// what the bound is for).
fn check_rgb(field: &str, c: crate::core::Rgb, max: f32, why: &str) -> Result<(), SceneError> {
    check_finite(field, &c.to_array())?;
    if c.min_component() < 0.0 {
        return Err(invalid(field, "components must not be negative"));
    }
    if c.max_component() > max {
        let max = if max < 1e6 { max.to_string() } else { format!("{max:e}") };
        return Err(invalid(field, format!("components must lie in [0, {max}] ({why})")));
    }
    Ok(())
}

/// Checks an emitter's radiance or intensity: at most [`MAX_EMISSION`].
fn check_emission(field: &str, c: crate::core::Rgb) -> Result<(), SceneError> {
    check_rgb(field, c, MAX_EMISSION, "the largest emission: a light's power must stay finite in f32")
}

pub fn validate_trs(field: &str, t: &Trs) -> Result<(), SceneError> {
    check_finite(&format!("{field}.translation"), &t.translation)?;
    check_finite(&format!("{field}.rotation"), &t.rotation)?;
    check_finite(&format!("{field}.scale"), &t.scale)?;
    let len = t.rotation.iter().map(|v| v * v).sum::<f32>().sqrt();
    if (len - 1.0).abs() > QUATERNION_TOLERANCE {
        return Err(invalid(
            format!("{field}.rotation"),
            format!("quaternion [x, y, z, w] has length {len}, expected 1 (±{QUATERNION_TOLERANCE})"),
        ));
    }
    check_coordinates(&format!("{field}.translation"), &t.translation)?;
    let [least, largest] = SCALE_LIMITS;
    if let Some(i) = t.scale.iter().position(|s| !(least..=largest).contains(&s.abs())) {
        return Err(invalid(
            format!("{field}.scale[{i}]"),
            format!(
                "{:e}: a scale's magnitude must lie in [{least:e}, {largest:e}] (zero flattens an axis)",
                t.scale[i]
            ),
        ));
    }
    Ok(())
}

/// Refuses a coordinate beyond ±[`MAX_COORDINATE`].
fn check_coordinates(field: &str, values: &[f32]) -> Result<(), SceneError> {
    match values.iter().position(|v| v.abs() > MAX_COORDINATE) {
        Some(i) => Err(invalid(
            format!("{field}[{i}]"),
            format!("{:e} is beyond ±{MAX_COORDINATE:e}, the largest world coordinate", values[i]),
        )),
        None => Ok(()),
    }
}

/// Refuses a transform (`field`) that puts a shape with object-space bounds `local` beyond
/// ±[`MAX_COORDINATE`] on some axis: the bounds' corners are where its vertices reach furthest.
pub fn check_placement(field: &str, local: &Aabb, trs: &Trs) -> Result<(), SceneError> {
    let xf = trs.world_from_object();
    let reach = (0..8)
        .map(|c: u32| {
            let pick = |bit: u32, lo: f32, hi: f32| if c & bit == 0 { lo } else { hi };
            let (lo, hi) = (local.min, local.max);
            let corner = Vec3::new(pick(1, lo.x, hi.x), pick(2, lo.y, hi.y), pick(4, lo.z, hi.z));
            let p = xf.transform_point3(corner);
            if p.is_finite() {
                p.abs().max_element()
            } else {
                f32::INFINITY
            }
        })
        .fold(0.0, f32::max);
    if reach > MAX_COORDINATE {
        return Err(invalid(
            field,
            format!(
                "puts the shape {reach:e} from the origin, beyond ±{MAX_COORDINATE:e}, the largest world coordinate"
            ),
        ));
    }
    Ok(())
}

pub fn validate_camera(c: &CameraDesc) -> Result<(), SceneError> {
    check_finite("camera.position", &c.position)?;
    check_finite("camera.look_at", &c.look_at)?;
    check_finite("camera.up", &c.up)?;
    check_finite("camera.vfov_deg", &[c.vfov_deg])?;
    check_coordinates("camera.position", &c.position)?;
    check_coordinates("camera.look_at", &c.look_at)?;
    let forward = glam::Vec3::from(c.look_at) - glam::Vec3::from(c.position);
    if forward.length_squared() == 0.0 {
        return Err(invalid("camera.look_at", "equals camera.position: the view direction has zero length"));
    }
    let up = glam::Vec3::from(c.up);
    if up.length_squared() == 0.0 {
        return Err(invalid("camera.up", "zero-length vector"));
    }
    if forward.normalize().cross(up.normalize()).length() < 1e-4 {
        return Err(invalid("camera.up", "parallel to the view direction"));
    }
    if !(c.vfov_deg > 0.0 && c.vfov_deg < 180.0) {
        return Err(invalid("camera.vfov_deg", format!("{} is outside (0, 180)", c.vfov_deg)));
    }
    for (i, r) in c.resolution.iter().enumerate() {
        if *r == 0 || *r > MAX_RESOLUTION {
            return Err(invalid(format!("camera.resolution[{i}]"), format!("{r} is outside 1..={MAX_RESOLUTION}")));
        }
    }
    Ok(())
}

pub fn validate_material(field: &str, m: &Material) -> Result<(), SceneError> {
    match m {
        Material::Diffuse { reflectance } | Material::Mirror { reflectance } => {
            check_rgb(&format!("{field}.reflectance"), *reflectance, 1.0, "energy conservation")
        }
        Material::Glass { ior } => {
            check_finite(&format!("{field}.ior"), &[*ior])?;
            if *ior <= 0.0 {
                return Err(invalid(format!("{field}.ior"), "index of refraction must be positive"));
            }
            Ok(())
        }
    }
}

pub fn validate_emitter(field: &str, e: &EmitterDesc) -> Result<(), SceneError> {
    match e {
        EmitterDesc::Point { intensity } => check_emission(&format!("{field}.intensity"), *intensity),
        EmitterDesc::Spot { intensity, cone_deg, falloff_start_deg } => {
            check_emission(&format!("{field}.intensity"), *intensity)?;
            check_finite(&format!("{field}.cone_deg"), &[*cone_deg])?;
            if !(*cone_deg > 0.0 && *cone_deg < 180.0) {
                return Err(invalid(format!("{field}.cone_deg"), "half-angle must lie in (0, 180)"));
            }
            if let Some(start) = falloff_start_deg {
                check_finite(&format!("{field}.falloff_start_deg"), &[*start])?;
                if !(*start >= 0.0 && start <= cone_deg) {
                    return Err(invalid(format!("{field}.falloff_start_deg"), "must lie in [0, cone_deg]"));
                }
            }
            Ok(())
        }
        EmitterDesc::Rect { radiance } => check_emission(&format!("{field}.radiance"), *radiance),
        EmitterDesc::Disc { radiance, segments } => {
            check_emission(&format!("{field}.radiance"), *radiance)?;
            check_segments(&format!("{field}.segments"), *segments)
        }
        EmitterDesc::Mesh { radiance, positions, indices } => {
            check_emission(&format!("{field}.radiance"), *radiance)?;
            let mut mesh = inline_mesh(field, positions, indices, None)?;
            mesh.drop_degenerate();
            if mesh.triangles.is_empty() {
                return Err(invalid(format!("{field}.indices"), "no non-degenerate triangles"));
            }
            Ok(())
        }
        EmitterDesc::Directional { direction, irradiance, angle_deg } => {
            check_emission(&format!("{field}.irradiance"), *irradiance)?;
            check_finite(&format!("{field}.direction"), direction)?;
            if Vec3::from(*direction).length() < 1e-6 {
                return Err(invalid(format!("{field}.direction"), "must not be zero: it is the way the light travels"));
            }
            check_finite(&format!("{field}.angle_deg"), &[*angle_deg])?;
            if !(0.0..=MAX_SUN_ANGLE_DEG).contains(angle_deg) {
                return Err(invalid(
                    format!("{field}.angle_deg"),
                    format!("the angular diameter must lie in [0, {MAX_SUN_ANGLE_DEG}] (the sun's is 0.53)"),
                ));
            }
            Ok(())
        }
    }
}

/// The widest directional light, in degrees of angular diameter: wider than this it is an
/// environment, not a sun.
pub const MAX_SUN_ANGLE_DEG: f32 = 30.0;

/// Refuses an environment with a negative or non-finite radiance.
pub fn validate_environment(field: &str, env: &EnvironmentDesc) -> Result<(), SceneError> {
    check_emission(&format!("{field}.radiance"), env.radiance)
}

/// The radiance that lights a scene with no light at all.
pub const LIGHTLESS_ENVIRONMENT: f32 = 1.0;

/// A scene with no light and no environment gets a uniform white environment (as a glTF viewer
/// lights a model), with a warning that says so and how to change it; any other scene is left as
/// it is.
pub fn light_the_lightless(desc: &mut SceneDesc) -> Option<String> {
    if !desc.lights.is_empty() || desc.environment.is_some() {
        return None;
    }
    desc.environment = Some(EnvironmentDesc { radiance: crate::core::Rgb::splat(LIGHTLESS_ENVIRONMENT) });
    Some(format!(
        "the scene has no light: it is lit by a uniform environment of radiance {LIGHTLESS_ENVIRONMENT} \
         (give it lights, or an \"environment\" such as {{\"radiance\": [0.5, 0.5, 0.5]}}, to change this)"
    ))
}

/// An inline triangle list as a mesh; errors name the field under `field`.
pub fn inline_mesh(
    field: &str,
    positions: &[[f32; 3]],
    indices: &[[u32; 3]],
    normals: Option<&[[f32; 3]]>,
) -> Result<Mesh, SceneError> {
    Mesh::from_inline(positions, indices, normals).map_err(|(at, message)| invalid(format!("{field}.{at}"), message))
}

fn check_segments(field: &str, s: u32) -> Result<(), SceneError> {
    if (3..=MAX_SEGMENTS).contains(&s) {
        Ok(())
    } else {
        Err(invalid(field, format!("{s} is outside 3..={MAX_SEGMENTS}")))
    }
}

/// Resolves a mesh path against the scene's folder and refuses anything outside `root`.
///
/// The check runs twice: lexically first, so a path that climbs out of the root is named as
/// such whether or not its target exists, then on the canonical path, so a symlink inside the
/// root cannot point outside it.
pub fn resolve_mesh_path(field: &str, path: &str, scene_dir: &Path, root: &Path) -> Result<PathBuf, SceneError> {
    if Path::new(path).is_absolute() {
        return Err(invalid(field, format!("'{path}' is absolute; mesh paths are relative to the scene file")));
    }
    let root =
        root.canonicalize().map_err(|e| SceneError::Io { path: root.display().to_string(), message: e.to_string() })?;
    let escapes = || invalid(field, format!("'{path}' escapes the scenes root {}", root.display()));
    let scene_dir = scene_dir.canonicalize().unwrap_or_else(|_| scene_dir.to_path_buf());
    if !lexically_normal(&scene_dir.join(path)).starts_with(&root) {
        return Err(escapes());
    }
    let joined = scene_dir.join(path);
    let canonical = joined
        .canonicalize()
        .map_err(|e| invalid(field, format!("mesh file '{}' not found: {e}", joined.display())))?;
    if !canonical.starts_with(&root) {
        return Err(escapes());
    }
    Ok(canonical)
}

/// Removes `.` and resolves `..` against the preceding component, without touching the disk.
fn lexically_normal(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// A name must be non-empty and unique among its kind.
fn check_name<'a>(
    field: &str,
    kind: &str,
    name: &'a str,
    seen: &mut std::collections::HashSet<&'a str>,
) -> Result<(), SceneError> {
    if name.is_empty() {
        return Err(invalid(format!("{field}.name"), "must not be empty"));
    }
    if !seen.insert(name) {
        return Err(invalid(format!("{field}.name"), format!("duplicate {kind} name '{name}'")));
    }
    Ok(())
}

/// Degenerate triangles dropped at load: (object name, count).
pub type DroppedTriangles = Vec<(String, usize)>;

/// Validates the description against `budget` and builds each object's mesh with its
/// object-space bounds; `meshes[i]` belongs to `desc.objects[i]`. Degenerate triangles are
/// dropped and counted.
pub fn validate_and_build_meshes(
    desc: &SceneDesc,
    scene_dir: &Path,
    root: &Path,
    budget: &SceneBudget,
) -> Result<(Vec<(Mesh, Aabb)>, DroppedTriangles), SceneError> {
    validate_camera(&desc.camera)?;
    check_budget(desc, scene_dir, root, budget)?;
    for (name, m) in &desc.materials {
        validate_material(&format!("materials.{name}"), m)?;
    }
    let mut names = std::collections::HashSet::new();
    let mut meshes = Vec::with_capacity(desc.objects.len());
    let mut dropped = Vec::new();
    let mut cache: std::collections::HashMap<PathBuf, Mesh> = Default::default();
    for (i, o) in desc.objects.iter().enumerate() {
        let field = format!("objects[{i}]");
        check_name(&field, "object", &o.name, &mut names)?;
        if !desc.materials.contains_key(&o.material) {
            return Err(invalid(format!("{field}.material"), format!("unknown material '{}'", o.material)));
        }
        validate_trs(&format!("{field}.transform"), &o.transform)?;
        let shape_field = format!("{field}.shape");
        let mut mesh = match &o.shape {
            ShapeDesc::Mesh { path } => {
                let file = resolve_mesh_path(&format!("{shape_field}.path"), path, scene_dir, root)?;
                match cache.get(&file) {
                    Some(m) => m.clone(),
                    None => {
                        let m = Mesh::load_obj(&file).map_err(|e| invalid(format!("{shape_field}.path"), e))?;
                        cache.insert(file, m.clone());
                        m
                    }
                }
            }
            ShapeDesc::Quad => Mesh::quad(),
            ShapeDesc::Box => Mesh::cube(),
            ShapeDesc::Sphere { segments } => {
                check_segments(&format!("{shape_field}.segments"), *segments)?;
                Mesh::sphere(*segments)
            }
            ShapeDesc::Disc { segments } => {
                check_segments(&format!("{shape_field}.segments"), *segments)?;
                Mesh::disc(*segments)
            }
            ShapeDesc::Cylinder { segments } => {
                check_segments(&format!("{shape_field}.segments"), *segments)?;
                Mesh::cylinder(*segments)
            }
            ShapeDesc::Triangles { positions, indices, normals } => {
                inline_mesh(&shape_field, positions, indices, normals.as_deref())?
            }
        };
        let n = mesh.drop_degenerate();
        if n > 0 {
            tracing::warn!("{field} '{}': dropped {n} degenerate triangle(s)", o.name);
            dropped.push((o.name.clone(), n));
        }
        if mesh.triangles.is_empty() {
            return Err(invalid(shape_field, "mesh is empty (no non-degenerate triangles)"));
        }
        let bounds = mesh.bounds();
        check_placement(&format!("{field}.transform"), &bounds, &o.transform)?;
        meshes.push((mesh, bounds));
    }
    if let Some(env) = &desc.environment {
        validate_environment("environment", env)?;
    }
    let mut light_names = std::collections::HashSet::new();
    for (i, l) in desc.lights.iter().enumerate() {
        let field = format!("lights[{i}]");
        check_name(&field, "light", &l.name, &mut light_names)?;
        validate_emitter(&format!("{field}.emitter"), &l.emitter)?;
        validate_trs(&format!("{field}.transform"), &l.transform)?;
        if matches!(l.emitter, EmitterDesc::Directional { .. }) && l.transform != Trs::default() {
            return Err(invalid(
                format!("{field}.transform"),
                "a directional light has no placement: give its emitter's direction instead",
            ));
        }
        if let Some(mesh) = super::light::emitter_mesh(&l.emitter) {
            check_placement(&format!("{field}.transform"), &mesh.bounds(), &l.transform)?;
        }
    }
    Ok((meshes, dropped))
}
