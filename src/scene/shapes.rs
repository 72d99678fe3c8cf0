//! Triangle meshes for every shape: tessellated primitives in their canonical object-space
//! extents (see `model.rs`) and OBJ files loaded with `tobj`.
//!
//! A mesh may carry unit vertex normals (OBJ `vn`, glTF `NORMAL`, inline `normals`), which
//! shade it smoothly (`Scene::surface_point`); primitives and meshes without them shade with
//! flat triangle normals.
//!
//! Invariant: triangles are wound so that `(p1-p0)×(p2-p0)` points outward (for closed shapes) or
//! towards +Z (for flat ones); glass and one-sided lights rely on it.
use super::edits::Aabb;
use glam::Vec3;
use std::f32::consts::PI;
use std::path::Path;

/// An indexed triangle mesh in object space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    /// One unit normal per position, or empty for flat shading. A zero normal (a file's
    /// degenerate `vn`) adds nothing where it is interpolated; where all three of a triangle's
    /// vanish, it shades flat.
    pub normals: Vec<Vec3>,
}

impl Mesh {
    /// The bounds of its vertices.
    pub fn bounds(&self) -> Aabb {
        Aabb::of_points(self.positions.iter().copied())
    }

    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[i];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// Removes triangles with zero or non-finite area; returns how many were dropped.
    pub fn drop_degenerate(&mut self) -> usize {
        let before = self.triangles.len();
        let positions = &self.positions;
        self.triangles.retain(|&[a, b, c]| {
            let (p0, p1, p2) = (positions[a as usize], positions[b as usize], positions[c as usize]);
            let area2 = (p1 - p0).cross(p2 - p0).length();
            area2.is_finite() && area2 > 0.0 && a != b && b != c && a != c
        });
        before - self.triangles.len()
    }

    /// A mesh from inline positions, index triples and optional vertex normals (one per
    /// position); errors name the first non-finite value or out-of-range index
    /// (`positions[3][1]`, `indices[7][2]`, `normals[2][0]`), or the `normals` count.
    pub fn from_inline(
        positions: &[[f32; 3]],
        indices: &[[u32; 3]],
        normals: Option<&[[f32; 3]]>,
    ) -> Result<Mesh, (String, String)> {
        check_finite("positions", positions)?;
        for (i, t) in indices.iter().enumerate() {
            if let Some(k) = t.iter().position(|&v| v as usize >= positions.len()) {
                return Err((
                    format!("indices[{i}][{k}]"),
                    format!("{} is out of range ({} positions)", t[k], positions.len()),
                ));
            }
        }
        let normals = match normals {
            Some(n) if n.len() != positions.len() => {
                return Err(("normals".into(), format!("{} normals for {} positions", n.len(), positions.len())))
            }
            Some(n) => {
                check_finite("normals", n)?;
                n.iter().map(|&v| Vec3::from(v).normalize_or_zero()).collect()
            }
            None => Vec::new(),
        };
        let positions = positions.iter().map(|&p| Vec3::from(p)).collect();
        Ok(Mesh { positions, triangles: indices.to_vec(), normals })
    }

    pub fn quad() -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            normals: Vec::new(),
        }
    }

    /// The cube [-1,1]³ as 6 outward-facing quads.
    pub fn cube() -> Mesh {
        let mut m = Mesh::default();
        // (normal, u axis, v axis) with u × v = normal, so each face winds outward.
        let faces = [
            (Vec3::X, Vec3::Y, Vec3::Z),
            (Vec3::NEG_X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::Z, Vec3::X),
            (Vec3::NEG_Y, Vec3::X, Vec3::Z),
            (Vec3::Z, Vec3::X, Vec3::Y),
            (Vec3::NEG_Z, Vec3::Y, Vec3::X),
        ];
        for (n, u, v) in faces {
            let base = m.positions.len() as u32;
            for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                m.positions.push(n + u * su + v * sv);
            }
            m.triangles.push([base, base + 1, base + 2]);
            m.triangles.push([base, base + 2, base + 3]);
        }
        m
    }

    /// Unit sphere: `segments` around the equator, `segments / 2` rings.
    pub fn sphere(segments: u32) -> Mesh {
        let segs = segments.max(3);
        let rings = (segs / 2).max(2);
        let mut m = Mesh::default();
        for j in 0..=rings {
            let theta = PI * j as f32 / rings as f32;
            for i in 0..=segs {
                let phi = 2.0 * PI * i as f32 / segs as f32;
                m.positions.push(Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()));
            }
        }
        let idx = |j: u32, i: u32| j * (segs + 1) + i;
        for j in 0..rings {
            for i in 0..segs {
                let (a, b, c, d) = (idx(j, i), idx(j + 1, i), idx(j + 1, i + 1), idx(j, i + 1));
                if j + 1 < rings {
                    m.triangles.push([a, b, c]);
                }
                if j > 0 {
                    m.triangles.push([a, c, d]);
                }
            }
        }
        m
    }

    /// Unit disc in the XY plane facing +Z, as a fan of `segments` triangles.
    pub fn disc(segments: u32) -> Mesh {
        let segs = segments.max(3);
        let mut m = Mesh { positions: vec![Vec3::ZERO], ..Mesh::default() };
        for i in 0..segs {
            let phi = 2.0 * PI * i as f32 / segs as f32;
            m.positions.push(Vec3::new(phi.cos(), phi.sin(), 0.0));
        }
        for i in 0..segs {
            m.triangles.push([0, 1 + i, 1 + (i + 1) % segs]);
        }
        m
    }

    /// Capped cylinder of radius 1 from z=0 to z=1.
    pub fn cylinder(segments: u32) -> Mesh {
        let segs = segments.max(3);
        let mut m = Mesh::default();
        for i in 0..segs {
            let phi = 2.0 * PI * i as f32 / segs as f32;
            let (x, y) = (phi.cos(), phi.sin());
            m.positions.push(Vec3::new(x, y, 0.0));
            m.positions.push(Vec3::new(x, y, 1.0));
        }
        let bottom_c = m.positions.len() as u32;
        m.positions.push(Vec3::ZERO);
        let top_c = bottom_c + 1;
        m.positions.push(Vec3::Z);
        for i in 0..segs {
            let j = (i + 1) % segs;
            let (b0, t0, b1, t1) = (2 * i, 2 * i + 1, 2 * j, 2 * j + 1);
            m.triangles.push([b0, b1, t1]);
            m.triangles.push([b0, t1, t0]);
            m.triangles.push([bottom_c, b1, b0]);
            m.triangles.push([top_c, t0, t1]);
        }
        m
    }

    /// Triangles [`Mesh::sphere`] makes for `segments`, without making them.
    pub fn sphere_triangles(segments: u32) -> u64 {
        let segs = u64::from(segments.max(3));
        let rings = (segs / 2).max(2);
        2 * segs * (rings - 1)
    }

    /// Triangles [`Mesh::disc`] makes for `segments`.
    pub fn disc_triangles(segments: u32) -> u64 {
        u64::from(segments.max(3))
    }

    /// Triangles [`Mesh::cylinder`] makes for `segments`.
    pub fn cylinder_triangles(segments: u32) -> u64 {
        4 * u64::from(segments.max(3))
    }

    /// Triangles an OBJ file's faces make once triangulated (a face of n corners makes n − 2),
    /// from its `f` lines alone: nothing is parsed or allocated per vertex.
    pub fn count_obj_triangles(path: &Path) -> Result<u64, String> {
        use std::io::BufRead;
        let file = std::fs::File::open(path).map_err(|e| format!("cannot read OBJ {}: {e}", path.display()))?;
        let mut triangles = 0u64;
        let mut line = String::new();
        let mut reader = std::io::BufReader::new(file);
        loop {
            line.clear();
            match reader.read_line(&mut line) {
                Ok(0) => return Ok(triangles),
                Ok(_) => {}
                Err(e) => return Err(format!("cannot read OBJ {}: {e}", path.display())),
            }
            if let Some(face) = line.strip_prefix("f ").or_else(|| line.strip_prefix("f\t")) {
                triangles += (face.split_whitespace().count() as u64).saturating_sub(2);
            }
        }
    }

    /// Loads every object of an OBJ file into one mesh (triangulated), with its vertex normals
    /// when every object has them (`vn`; a file that gives some objects none shades flat).
    pub fn load_obj(path: &Path) -> Result<Mesh, String> {
        let options =
            tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
        let (models, _) =
            tobj::load_obj(path, &options).map_err(|e| format!("cannot read OBJ {}: {e}", path.display()))?;
        let mut mesh = Mesh::default();
        let smooth = models.iter().all(|m| m.mesh.normals.len() == m.mesh.positions.len());
        if !smooth && models.iter().any(|m| !m.mesh.normals.is_empty()) {
            tracing::warn!("{}: some objects have no vertex normals, so the whole mesh shades flat", path.display());
        }
        for model in models {
            let base = mesh.positions.len() as u32;
            for (i, n) in model.mesh.normals.chunks_exact(3).enumerate().filter(|_| smooth) {
                let n = Vec3::new(n[0], n[1], n[2]);
                if !n.is_finite() {
                    let name = &model.name;
                    return Err(format!(
                        "{}: normal of vertex {} of object '{name}' is not finite",
                        path.display(),
                        i + 1
                    ));
                }
                mesh.normals.push(n.normalize_or_zero());
            }
            let p = &model.mesh.positions;
            for (i, v) in p.chunks_exact(3).enumerate() {
                let v = Vec3::new(v[0], v[1], v[2]);
                if !v.is_finite() {
                    return Err(format!(
                        "{}: vertex {} of object '{}' is not finite",
                        path.display(),
                        i + 1,
                        model.name
                    ));
                }
                mesh.positions.push(v);
            }
            for t in model.mesh.indices.chunks_exact(3) {
                mesh.triangles.push([base + t[0], base + t[1], base + t[2]]);
            }
        }
        Ok(mesh)
    }
}

/// The first non-finite component of `values`, named `{name}[i][k]`.
fn check_finite(name: &str, values: &[[f32; 3]]) -> Result<(), (String, String)> {
    for (i, p) in values.iter().enumerate() {
        if let Some(k) = p.iter().position(|v| !v.is_finite()) {
            return Err((format!("{name}[{i}][{k}]"), format!("{} is not a finite number", p[k])));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_counts_are_known_before_the_meshes_are_made() {
        for segments in [0, 3, 4, 5, 32, 101] {
            assert_eq!(Mesh::sphere_triangles(segments), Mesh::sphere(segments).triangles.len() as u64, "{segments}");
            assert_eq!(Mesh::disc_triangles(segments), Mesh::disc(segments).triangles.len() as u64, "{segments}");
            assert_eq!(Mesh::cylinder_triangles(segments), Mesh::cylinder(segments).triangles.len() as u64);
        }
        let meshes = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/meshes");
        let mut files = 0;
        for entry in std::fs::read_dir(&meshes).expect("bundled meshes").flatten() {
            let path = entry.path();
            if path.extension().is_some_and(|e| e == "obj") {
                let built = Mesh::load_obj(&path).expect("bundled OBJ").triangles.len() as u64;
                assert_eq!(Mesh::count_obj_triangles(&path), Ok(built), "{}", path.display());
                files += 1;
            }
        }
        assert!(files > 0, "no bundled OBJ files to compare");
        // A quad face and a pentagon fan into 2 and 3 triangles.
        let dir = std::env::temp_dir().join(format!("relume-obj-count-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let file = dir.join("faces.obj");
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 2 0\nf 1 2 3 4\nf\t1 2 3 4 5\n";
        std::fs::write(&file, text).expect("write");
        assert_eq!(Mesh::count_obj_triangles(&file), Ok(5));
        assert_eq!(Mesh::load_obj(&file).expect("parse").triangles.len(), 5);
    }

    fn area_and_centroid_winding(m: &Mesh) -> (f32, f32) {
        // Sum of area and of (outward normal · centroid) for closed shapes centred at the origin.
        let mut area = 0.0;
        let mut outward = 0.0;
        for i in 0..m.triangles.len() {
            let [a, b, c] = m.triangle(i);
            let n = (b - a).cross(c - a);
            area += 0.5 * n.length();
            outward += n.dot((a + b + c) / 3.0);
        }
        (area, outward)
    }

    #[test]
    fn closed_primitives_wind_outward_with_the_right_area() {
        let (a, o) = area_and_centroid_winding(&Mesh::cube());
        assert!((a - 24.0).abs() < 1e-4 && o > 0.0);
        let mut s = Mesh::sphere(64);
        assert_eq!(s.drop_degenerate(), 0);
        let (a, o) = area_and_centroid_winding(&s);
        assert!((a - 4.0 * PI).abs() / (4.0 * PI) < 0.01, "sphere area {a}");
        assert!(o > 0.0);
        let mut c = Mesh::cylinder(64);
        for p in &mut c.positions {
            p.z -= 0.5;
        }
        let (a, o) = area_and_centroid_winding(&c);
        assert!((a - 4.0 * PI).abs() / (4.0 * PI) < 0.01, "cylinder area {a}");
        assert!(o > 0.0);
    }

    #[test]
    fn flat_primitives_face_plus_z() {
        for m in [Mesh::quad(), Mesh::disc(16)] {
            for i in 0..m.triangles.len() {
                let [a, b, c] = m.triangle(i);
                assert!((b - a).cross(c - a).z > 0.0);
            }
        }
    }

    #[test]
    fn degenerate_triangles_are_dropped_and_counted() {
        let mut m = Mesh::quad();
        m.triangles.push([0, 0, 1]);
        m.positions.push(Vec3::new(2.0, 2.0, 0.0));
        m.positions.push(Vec3::new(3.0, 3.0, 0.0));
        m.triangles.push([0, 4, 5]);
        assert_eq!(m.drop_degenerate(), 2);
        assert_eq!(m.triangles.len(), 2);
    }
}
