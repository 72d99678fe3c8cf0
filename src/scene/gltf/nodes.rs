//! The node hierarchy of a glTF scene: each reachable node's world matrix, name and whether it
//! is dynamic, and the decomposition of matrices into relume's TRS.
//!
//! A node is dynamic when an animation channel targets it or any ancestor, or when its own or
//! an ancestor's `extras` say `{"relume": {"dynamic": true}}`. World matrices are
//! `root · … · parent · local`, where `root` is the scene-level uniform scale.
use super::super::load::{invalid, SceneError, MAX_COORDINATE, SCALE_LIMITS};
use super::super::model::Trs;
use glam::{DMat4, Mat4, Quat, Vec3};
use std::collections::HashSet;

/// Relative tolerance for a matrix to count as T·R·S: recomposing the decomposition must
/// give every column back within this fraction of the largest column length.
const SHEAR_TOLERANCE: f32 = 1e-4;

/// A node reached from the scene's roots.
pub struct NodeInfo {
    pub index: usize,
    pub parent: Option<usize>,
    pub world: Mat4,
    pub dynamic: bool,
}

/// `nodes[3] ('arm')`, the way every error and warning names a node.
pub fn node_label(node: &gltf::Node) -> String {
    match node.name() {
        Some(name) => format!("nodes[{}] ('{name}')", node.index()),
        None => format!("nodes[{}]", node.index()),
    }
}

/// The node's own transform as a matrix; a `matrix` must be T·R·S (no shear).
pub fn local_matrix(node: &gltf::Node) -> Result<Mat4, SceneError> {
    let label = node_label(node);
    match node.transform() {
        gltf::scene::Transform::Matrix { matrix } => {
            let m = Mat4::from_cols_array_2d(&matrix);
            if !m.is_finite() {
                return Err(invalid(format!("{label}.matrix"), "holds a value that is not a finite number"));
            }
            if decompose(&m).is_none() {
                return Err(invalid(
                    format!("{label}.matrix"),
                    "has shear or a zero axis; only translation · rotation · scale matrices are read",
                ));
            }
            Ok(m)
        }
        gltf::scene::Transform::Decomposed { translation, rotation, scale } => {
            let (t, r, s) = (Vec3::from(translation), Quat::from_array(rotation), Vec3::from(scale));
            if !(t.is_finite() && r.is_finite() && s.is_finite()) {
                return Err(invalid(label, "translation, rotation or scale is not finite"));
            }
            if r.length() < 1e-6 {
                return Err(invalid(format!("{label}.rotation"), "is a zero quaternion"));
            }
            Ok(Mat4::from_scale_rotation_translation(s, r.normalize(), t))
        }
    }
}

/// The matrix as TRS, or `None` when it has shear, a zero axis or non-finite entries. The
/// decomposition runs in f64, where an axis's squared length cannot overflow, so a huge but
/// finite scale decomposes (and is then refused by its size, not mistaken for shear).
pub fn decompose(m: &Mat4) -> Option<Trs> {
    let d = m.as_dmat4();
    let (s, r, t) = d.to_scale_rotation_translation();
    if !(s.is_finite() && r.is_finite() && t.is_finite()) || s.min_element().abs() == 0.0 {
        return None;
    }
    let back = DMat4::from_scale_rotation_translation(s, r.normalize(), t);
    let size = d.x_axis.length().max(d.y_axis.length()).max(d.z_axis.length()).max(1e-300);
    let worst = (0..3).map(|c| (back.col(c) - d.col(c)).length()).fold(0.0f64, f64::max);
    let trs = Trs {
        translation: t.as_vec3().to_array(),
        rotation: r.as_quat().normalize().to_array(),
        scale: s.as_vec3().to_array(),
    };
    (worst <= f64::from(SHEAR_TOLERANCE) * size && trs.scale.iter().all(|v| v.is_finite() && *v != 0.0)).then_some(trs)
}

/// Refuses a node holding a mesh or a light whose world transform scales by a factor outside
/// [`SCALE_LIMITS`] or translates beyond ±[`MAX_COORDINATE`], the bounds scene validation puts
/// on every transform, so that the error names the node and not the object, light or framing
/// camera it would become.
pub fn check_world(label: &str, world: &Mat4) -> Result<(), SceneError> {
    if !world.is_finite() {
        return Err(invalid(label, "its world transform overflows f32 (the product of its ancestors' transforms)"));
    }
    // In f64, where an axis's squared length cannot overflow; reported in f32, as stored.
    let d = world.as_dmat4();
    let [least, largest] = SCALE_LIMITS;
    let scales = [d.x_axis, d.y_axis, d.z_axis].map(|axis| axis.truncate().length() as f32);
    if let Some(s) = scales.iter().find(|s| !(least..=largest).contains(*s)) {
        return Err(invalid(
            label,
            format!(
                "its world transform scales by {s:e}, outside [{least:e}, {largest:e}], the scale factors relume takes"
            ),
        ));
    }
    let reach = world.w_axis.truncate().abs().max_element();
    if reach > MAX_COORDINATE {
        return Err(invalid(
            label,
            format!(
                "its world translation reaches {reach:e}, beyond ±{MAX_COORDINATE:e}, the largest world coordinate"
            ),
        ));
    }
    Ok(())
}

/// Whether the node's `extras` hold `{"relume": {"dynamic": true}}`.
fn marked_dynamic(node: &gltf::Node) -> bool {
    relume_extras(node.extras()).and_then(|r| r.get("dynamic").and_then(|d| d.as_bool())).unwrap_or(false)
}

/// The `relume` object of some `extras`, if there is one.
pub fn relume_extras(extras: &gltf::json::Extras) -> Option<serde_json::Value> {
    let raw = extras.as_ref()?;
    let value: serde_json::Value = serde_json::from_str(raw.get()).ok()?;
    value.get("relume").cloned()
}

/// Every node reachable from `scene`'s roots, parents before children. A node reached twice
/// (two parents, or a cycle) is an error naming it.
pub fn walk(scene: &gltf::Scene, root: Mat4, animated: &HashSet<usize>) -> Result<Vec<NodeInfo>, SceneError> {
    let mut out = Vec::new();
    let mut seen = HashSet::new();
    let mut stack: Vec<(gltf::Node, Option<usize>, Mat4, bool)> =
        scene.nodes().map(|n| (n, None, root, false)).collect();
    stack.reverse();
    while let Some((node, parent, parent_world, parent_dynamic)) = stack.pop() {
        if !seen.insert(node.index()) {
            return Err(invalid(node_label(&node), "is reached twice: a node may have one parent and no cycle"));
        }
        let world = parent_world * local_matrix(&node)?;
        let dynamic = parent_dynamic || animated.contains(&node.index()) || marked_dynamic(&node);
        let index = node.index();
        let children: Vec<_> = node.children().collect();
        for child in children.into_iter().rev() {
            stack.push((child, Some(index), world, dynamic));
        }
        out.push(NodeInfo { index, parent, world, dynamic });
    }
    Ok(out)
}
