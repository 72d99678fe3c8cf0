//! The scene: the validated model plus the world-space data rendering needs, and the mapping of
//! every Embree hit back to an (object or light, triangle).
//!
//! Units: meters (the Cornell box keeps its published millimetre numbers as scene units: radiance
//! is scale-invariant), radians, linear Rec.709. Invariants: everything in a `Scene` passed
//! `load::validate_*`; each object's `world_positions` equal its mesh under `world_from_object`,
//! its `hit_triangles` are those positions gathered per triangle with the winding's normal, and
//! its `shading_normals` are its mesh's vertex normals under the inverse transpose (empty when
//! the mesh has none). A surface point's shading normal lies on its geometric normal's side.
pub mod accel;
pub mod animation;
pub mod camera;
pub mod edits;
pub mod gltf;
pub mod light;
pub mod load;
pub mod material;
pub mod model;
pub mod shapes;

pub use accel::SceneAccel;
pub use camera::Camera;
pub use light::{IncidentSample, LightGeometry, Outside};
pub use load::{SceneBudget, SceneError};
pub use material::{Normals, Transport};
pub use model::{CameraDesc, EmitterDesc, EnvironmentDesc, LightDesc, Material, ObjectDesc, SceneDesc, ShapeDesc, Trs};
pub use shapes::Mesh;

use crate::core::sampling::DiscreteDistribution;
use glam::{Affine3A, Vec3};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A scene file as loaded: the scene, what loading it left out (the load report), and the
/// animations a glTF file holds, by name.
pub struct LoadedScene {
    pub scene: Scene,
    pub warnings: Vec<String>,
    pub animations: Vec<(String, animation::Animation)>,
}

/// Which surface a hit landed on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SurfaceId {
    Object(u32),
    Light(u32),
}

/// A scene object in world space.
#[derive(Clone, Debug)]
pub struct SceneObject {
    pub name: String,
    pub mesh: Arc<Mesh>,
    pub material: u32,
    pub world_from_object: Affine3A,
    pub dynamic: bool,
    pub world_positions: Vec<Vec3>,
    /// Per triangle, what resolving a hit reads, in one cache line.
    pub hit_triangles: Vec<HitTriangle>,
    /// Per triangle, its three world-space unit vertex normals; empty for a flat-shaded mesh,
    /// so a scene without vertex normals pays nothing for them.
    pub shading_normals: Vec<[Vec3; 3]>,
    /// World-space surface area (m²).
    pub area: f32,
    /// The bounds of `mesh` in object space: where a new transform would put it.
    pub local_bounds: edits::Aabb,
}

/// A light in world space; `mesh` is its object-space shape, if it has one.
#[derive(Clone, Debug)]
pub struct SceneLight {
    pub name: String,
    pub mesh: Option<Arc<Mesh>>,
    pub geometry: LightGeometry,
    pub dynamic: bool,
}

/// A loaded, validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    desc: SceneDesc,
    pub camera: Camera,
    /// Materials in `desc.materials` name order.
    pub materials: Vec<Material>,
    pub material_names: Vec<String>,
    pub objects: Vec<SceneObject>,
    /// The description's lights in its order, then the environment (if the scene has one).
    pub lights: Vec<SceneLight>,
    /// Indices into `lights` of the lights from outside (directional lights, the environment),
    /// which rays leaving the scene see.
    pub infinite_lights: Vec<usize>,
    /// The scene's bounding sphere at load, which lights from outside emit into.
    pub outside: Outside,
    /// Light selection proportional to emitted power (luminance); `None` when nothing emits.
    pub light_selection: Option<DiscreteDistribution>,
    /// Degenerate triangles dropped at load, per object name.
    pub dropped_degenerate: Vec<(String, usize)>,
}

/// A resolved surface point.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    pub p: Vec3,
    /// Unit geometric normal from the triangle's winding, in world space.
    pub n: Vec3,
    /// Unit shading normal, interpolated from the vertex normals and on the side of `n`; equal
    /// to `n` on flat-shaded meshes and lights.
    pub ns: Vec3,
    /// The mesh has vertex normals (else `ns` is `n`).
    pub smooth: bool,
    pub surface: SurfaceId,
    pub prim: u32,
}

impl SurfacePoint {
    #[inline]
    pub fn normals(&self) -> Normals {
        Normals::known(self.n, self.ns, self.smooth)
    }
}

/// One triangle as a hit reads it: its world vertices and unit geometric normal, 64 bytes
/// aligned to a cache line. Resolving a hit through it is one load after the object, where the
/// indexed mesh needs four dependent ones (the triangle, then each vertex) and a normalize:
/// 3–20% (median 11%) more `path` samples/s on the Cornell box, one thread (`docs/benchmarks.md`). It costs
/// 64 bytes per object triangle.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct HitTriangle {
    pub vertices: [Vec3; 3],
    pub normal: Vec3,
    /// Whether its object has vertex normals: read from this cache line, a flat-shaded hit
    /// never touches `shading_normals` (5% of `path`'s time on the Cornell box when it did).
    pub smooth: bool,
}

fn hit_triangles(positions: &[Vec3], mesh: &Mesh) -> Vec<HitTriangle> {
    let triangle = |&[a, b, c]: &[u32; 3]| {
        let (a, b, c) = (positions[a as usize], positions[b as usize], positions[c as usize]);
        HitTriangle { vertices: [a, b, c], normal: unit_normal([a, b, c]), smooth: !mesh.normals.is_empty() }
    };
    mesh.triangles.iter().map(triangle).collect()
}

/// Unit normal of a triangle from its winding; zero for a degenerate one.
fn unit_normal([a, b, c]: [Vec3; 3]) -> Vec3 {
    (b - a).cross(c - a).normalize_or_zero()
}

/// Each triangle's vertex normals in world space (the inverse transpose of `xf`), or none for a
/// mesh without vertex normals.
fn shading_normals(mesh: &Mesh, xf: &Affine3A) -> Vec<[Vec3; 3]> {
    if mesh.normals.is_empty() {
        return Vec::new();
    }
    let m = xf.matrix3.inverse().transpose();
    let world: Vec<Vec3> = mesh.normals.iter().map(|n| (m * *n).normalize_or_zero()).collect();
    mesh.triangles.iter().map(|t| t.map(|i| world[i as usize])).collect()
}

/// The shading normal at barycentrics (`u`, `v`) from vertex normals `ns`, turned to the side of
/// the geometric normal `n`; `n` itself where the interpolation vanishes.
fn interpolate_shading_normal(ns: &[Vec3; 3], n: Vec3, u: f32, v: f32) -> Vec3 {
    let s = (ns[0] * (1.0 - u - v) + ns[1] * u + ns[2] * v).normalize_or_zero();
    match s.dot(n) {
        d if d > 0.0 => s,
        d if d < 0.0 => -s,
        _ => n,
    }
}

/// The shading normal of an object's triangle `prim` at barycentrics (`u`, `v`): its vertex
/// normals interpolated, or its geometric normal if the object has none.
fn shading_normal_of(o: &SceneObject, prim: u32, u: f32, v: f32) -> Vec3 {
    let n = o.hit_triangles[prim as usize].normal;
    o.shading_normals.get(prim as usize).map_or(n, |vertex_normals| interpolate_shading_normal(vertex_normals, n, u, v))
}

/// The barycentrics (u, v) of `p` projected onto triangle `[a, b, c]` (weights of `b` and `c`).
fn barycentrics([a, b, c]: &[Vec3; 3], p: Vec3) -> (f32, f32) {
    let (e1, e2, d) = (*b - *a, *c - *a, p - *a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det <= 0.0 {
        return (0.0, 0.0);
    }
    ((d22 * d1 - d12 * d2) / det, (d11 * d2 - d12 * d1) / det)
}

/// The name the environment goes by among the scene's lights (in stats and light lists).
pub const ENVIRONMENT: &str = "environment";

/// The sphere around the objects and the shaped lights, which lights from outside emit into.
fn outside_of(objects: &[SceneObject], lights: &[LightDesc], meshes: &[Option<Arc<Mesh>>]) -> Outside {
    let shaped = lights.iter().zip(meshes).filter_map(|(l, m)| Some((l.transform.world_from_object(), m.as_ref()?)));
    let light_points = shaped.flat_map(|(xf, m)| m.positions.iter().map(move |p| xf.transform_point3(*p)));
    Outside::around(objects.iter().flat_map(|o| o.world_positions.iter().copied()).chain(light_points))
}

fn world_positions(mesh: &Mesh, xf: &Affine3A) -> Vec<Vec3> {
    mesh.positions.iter().map(|p| xf.transform_point3(*p)).collect()
}

fn mesh_area(positions: &[Vec3], mesh: &Mesh) -> f32 {
    mesh.triangles
        .iter()
        .map(|&[a, b, c]| {
            let (a, b, c) = (positions[a as usize], positions[b as usize], positions[c as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .sum()
}

impl Scene {
    /// Loads a scene file; meshes must lie inside `root` (the scenes folder).
    pub fn load(path: &Path, root: &Path) -> Result<Scene, SceneError> {
        Scene::load_within(path, root, &SceneBudget::default())
    }

    /// [`Scene::load`] refusing, before building anything, a scene over `budget`.
    pub fn load_within(path: &Path, root: &Path, budget: &SceneBudget) -> Result<Scene, SceneError> {
        let options = gltf::ImportOptions { budget: *budget, ..Default::default() };
        Scene::load_file(path, root, &options).map(|loaded| loaded.scene)
    }

    /// Loads a scene file, relume JSON or glTF (`.gltf`, `.glb`, read with `options`), with
    /// its load report and, for glTF, the animations it holds.
    pub fn load_file(path: &Path, root: &Path, options: &gltf::ImportOptions) -> Result<LoadedScene, SceneError> {
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
        let (desc, warnings, animations) = if gltf::is_gltf_path(path) {
            let imported = gltf::import_file(path, root, options)?;
            (imported.desc, imported.warnings, imported.animations)
        } else {
            let text = std::fs::read_to_string(path)
                .map_err(|e| SceneError::Io { path: path.display().to_string(), message: e.to_string() })?;
            (load::parse_scene_json(&text)?, Vec::new(), Vec::new())
        };
        Scene::from_loaded_desc(desc, (&dir, root), options, warnings, animations)
    }

    /// Builds a loaded description: `options.environment` replaces the file's, a scene with no
    /// light at all gets the default environment (and a warning, added to `warnings`).
    pub fn from_loaded_desc(
        mut desc: SceneDesc,
        (dir, root): (&Path, &Path),
        options: &gltf::ImportOptions,
        mut warnings: Vec<String>,
        animations: Vec<(String, animation::Animation)>,
    ) -> Result<LoadedScene, SceneError> {
        if let Some(env) = options.environment {
            desc.environment = Some(env);
        }
        warnings.extend(load::light_the_lightless(&mut desc));
        let scene = Scene::from_desc_within(desc, dir, root, &options.budget)?;
        Ok(LoadedScene { scene, warnings, animations })
    }

    /// Builds a scene from a description whose relative mesh paths resolve against `dir`.
    pub fn from_desc(desc: SceneDesc, dir: &Path, root: &Path) -> Result<Scene, SceneError> {
        Scene::from_desc_within(desc, dir, root, &SceneBudget::default())
    }

    /// [`Scene::from_desc`] refusing, before building anything, a scene over `budget`.
    pub fn from_desc_within(
        desc: SceneDesc,
        dir: &Path,
        root: &Path,
        budget: &SceneBudget,
    ) -> Result<Scene, SceneError> {
        let (meshes, dropped_degenerate) = load::validate_and_build_meshes(&desc, dir, root, budget)?;
        let material_names: Vec<String> = desc.materials.keys().cloned().collect();
        let materials: Vec<Material> = desc.materials.values().cloned().collect();
        let objects: Vec<SceneObject> = desc
            .objects
            .iter()
            .zip(meshes)
            .map(|(o, (mesh, local_bounds))| {
                let xf = o.transform.world_from_object();
                let world = world_positions(&mesh, &xf);
                let area = mesh_area(&world, &mesh);
                let hit_triangles = hit_triangles(&world, &mesh);
                let shading_normals = shading_normals(&mesh, &xf);
                let material = material_names.iter().position(|n| *n == o.material).unwrap_or(0) as u32;
                SceneObject {
                    name: o.name.clone(),
                    local_bounds,
                    mesh: Arc::new(mesh),
                    material,
                    world_from_object: xf,
                    dynamic: o.dynamic,
                    world_positions: world,
                    hit_triangles,
                    shading_normals,
                    area,
                }
            })
            .collect();
        let meshes: Vec<Option<Arc<Mesh>>> =
            desc.lights.iter().map(|l| light::emitter_mesh(&l.emitter).map(Arc::new)).collect();
        let outside = outside_of(&objects, &desc.lights, &meshes);
        let mut lights: Vec<SceneLight> = desc
            .lights
            .iter()
            .zip(meshes)
            .map(|(l, mesh)| SceneLight {
                name: l.name.clone(),
                geometry: LightGeometry::new(l, mesh.as_deref(), outside),
                mesh,
                dynamic: l.dynamic,
            })
            .collect();
        if let Some(env) = &desc.environment {
            lights.push(SceneLight {
                name: ENVIRONMENT.into(),
                mesh: None,
                geometry: LightGeometry::environment(env.radiance, outside),
                dynamic: false,
            });
        }
        let infinite_lights = (0..lights.len()).filter(|&i| lights[i].geometry.is_infinite()).collect();
        let mut scene = Scene {
            camera: Camera::from_desc(&desc.camera),
            desc,
            materials,
            material_names,
            objects,
            lights,
            infinite_lights,
            outside,
            light_selection: None,
            dropped_degenerate,
        };
        scene.update_light_selection();
        Ok(scene)
    }

    /// The current scene description (edits are reflected in it).
    pub fn desc(&self) -> &SceneDesc {
        &self.desc
    }

    /// Index into `lights` of the environment, if the scene has one.
    pub fn environment_light(&self) -> Option<usize> {
        self.desc.environment.map(|_| self.desc.lights.len())
    }

    /// The world position of light `l`'s transform (the origin for the environment).
    pub fn light_position(&self, l: usize) -> Vec3 {
        self.desc.lights.get(l).map_or(Vec3::ZERO, |d| d.transform.translation())
    }

    /// Replaces the environment's radiance (the scene has one; validated by the caller).
    pub fn set_environment(&mut self, env: EnvironmentDesc) {
        if let Some(i) = self.environment_light() {
            self.desc.environment = Some(env);
            self.lights[i].geometry = LightGeometry::environment(env.radiance, self.outside);
            self.update_light_selection();
        }
    }

    fn update_light_selection(&mut self) {
        let weights: Vec<f32> = self.lights.iter().map(|l| l.geometry.power().luminance()).collect();
        self.light_selection = DiscreteDistribution::new(&weights);
    }

    /// World-space vertices of triangle `prim` of a surface.
    pub fn triangle(&self, surface: SurfaceId, prim: u32) -> [Vec3; 3] {
        match surface {
            SurfaceId::Object(i) => self.objects[i as usize].hit_triangles[prim as usize].vertices,
            SurfaceId::Light(i) => match &self.lights[i as usize].geometry {
                LightGeometry::Area { triangles, .. } => triangles[prim as usize],
                _ => [Vec3::ZERO; 3],
            },
        }
    }

    /// The world-space point and normal at barycentrics (`u`, `v`) of a triangle. Interpolating
    /// world vertices keeps the point's error bounded, as the robust ray offset assumes.
    pub fn surface_point(&self, surface: SurfaceId, prim: u32, u: f32, v: f32) -> SurfacePoint {
        let ([a, b, c], n, ns, smooth) = match surface {
            SurfaceId::Object(i) => {
                let o = &self.objects[i as usize];
                let t = &o.hit_triangles[prim as usize];
                let ns = if t.smooth { shading_normal_of(o, prim, u, v) } else { t.normal };
                (t.vertices, t.normal, ns, t.smooth)
            }
            SurfaceId::Light(_) => {
                let t = self.triangle(surface, prim);
                let n = unit_normal(t);
                (t, n, n, false)
            }
        };
        let p = a * (1.0 - u - v) + b * u + c * v;
        SurfacePoint { p, n, ns, smooth, surface, prim }
    }

    /// Both normals at point `p` of an object's triangle (for what keeps positions but not
    /// barycentrics, such as photons): flat ones unless the mesh has vertex normals.
    pub fn normals_at(&self, object: u32, prim: u32, p: Vec3) -> Normals {
        let o = &self.objects[object as usize];
        let t = &o.hit_triangles[prim as usize];
        if !t.smooth {
            return Normals::flat(t.normal);
        }
        let (u, v) = barycentrics(&t.vertices, p);
        Normals::new(t.normal, shading_normal_of(o, prim, u, v))
    }

    /// Unit geometric normal of a triangle, from its winding (zero for a light without one).
    pub fn normal(&self, surface: SurfaceId, prim: u32) -> Vec3 {
        match surface {
            SurfaceId::Object(i) => self.objects[i as usize].hit_triangles[prim as usize].normal,
            SurfaceId::Light(_) => unit_normal(self.triangle(surface, prim)),
        }
    }

    /// Area-weighted mean reflectance ρ_S of the scene's objects (Novák et al. 2010, §3.3).
    pub fn mean_reflectance(&self) -> f32 {
        let (weighted, area) = self.objects.iter().fold((0.0f64, 0.0f64), |(w, a), o| {
            let rho = self.materials[o.material as usize].mean_reflectance() as f64;
            (w + rho * o.area as f64, a + o.area as f64)
        });
        if area > 0.0 {
            (weighted / area) as f32
        } else {
            0.0
        }
    }

    /// The same scene with every diffuse and mirror reflectance multiplied by `factor`, clamped to 1
    /// (the dark and bright variants of the paper's Table 1).
    pub fn with_reflectance_scaled(&self, factor: f32) -> Scene {
        let mut s = self.clone();
        for m in s.materials.iter_mut().chain(s.desc.materials.values_mut()) {
            if let Material::Diffuse { reflectance } | Material::Mirror { reflectance } = m {
                let c = *reflectance * factor;
                *reflectance = crate::core::Rgb::new(c.r.min(1.0), c.g.min(1.0), c.b.min(1.0));
            }
        }
        s
    }

    /// Renders at another resolution than the file's camera.
    pub fn set_resolution(&mut self, width: u32, height: u32) {
        self.desc.camera.resolution = [width, height];
        self.camera = self.camera.clone().with_resolution(width, height);
    }

    pub fn object_index(&self, name: &str) -> Option<usize> {
        self.objects.iter().position(|o| o.name == name)
    }

    /// The index of the described light `name` (never the environment, which edits reach as
    /// their own target).
    pub fn light_index(&self, name: &str) -> Option<usize> {
        self.desc.lights.iter().position(|l| l.name == name)
    }

    /// Moves an object; the caller has validated `trs` and that the object is dynamic.
    pub fn set_object_transform(&mut self, index: usize, trs: Trs) {
        self.desc.objects[index].transform = trs;
        let o = &mut self.objects[index];
        o.world_from_object = trs.world_from_object();
        o.world_positions = world_positions(&o.mesh, &o.world_from_object);
        o.area = mesh_area(&o.world_positions, &o.mesh);
        o.hit_triangles = hit_triangles(&o.world_positions, &o.mesh);
        o.shading_normals = shading_normals(&o.mesh, &o.world_from_object);
    }

    /// Replaces a light's transform and emitter (validated by the caller).
    pub fn set_light(&mut self, index: usize, trs: Trs, emitter: EmitterDesc) {
        let desc = &mut self.desc.lights[index];
        desc.transform = trs;
        desc.emitter = emitter;
        let l = &mut self.lights[index];
        l.geometry = LightGeometry::new(desc, l.mesh.as_deref(), self.outside);
        self.update_light_selection();
    }

    /// The world bounds of every object (`None` for a scene without objects).
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut points = self.objects.iter().flat_map(|o| o.world_positions.iter().copied());
        let first = points.next()?;
        Some(points.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p))))
    }

    /// Replaces the camera (validated by the caller), keeping the render resolution.
    pub fn set_camera(&mut self, mut camera: CameraDesc) {
        camera.resolution = self.desc.camera.resolution;
        self.camera = Camera::from_desc(&camera);
        self.desc.camera = camera;
    }

    /// Replaces a material's parameters (validated by the caller).
    pub fn set_material(&mut self, index: usize, material: Material) {
        let name = self.material_names[index].clone();
        self.desc.materials.insert(name, material.clone());
        self.materials[index] = material;
    }
}
