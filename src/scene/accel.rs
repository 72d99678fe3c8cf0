//! The scene as Embree scenes, and the map from Embree ids back to surfaces.
//!
//! Layout ([`AccelLayout`]): every static object and static light shape is one triangle
//! geometry in world space, built once. Each dynamic object or dynamic light shape is its own
//! bottom-level scene (object-space vertices) under an instance whose transform edits update.
//! The static geometries sit either directly in the top-level scene ([`StaticLayout::Flat`]:
//! no instance transform, and with nothing dynamic one traversal of one BVH) or in one
//! bottom-level scene under an identity instance ([`StaticLayout::Nested`]). Only the top level
//! is recommitted when something moves. The default, [`StaticLayout::FlatWhenStill`], is flat
//! for a scene with nothing dynamic and nested otherwise: in a dynamic top level, Embree builds
//! each static geometry its own low-quality BVH, and `relume bench rays` on walker measured that
//! slower than nesting (`docs/benchmarks.md`).
use super::{Scene, SurfaceId};
use crate::embree::{
    CommittedScene, Device, EmbreeError, GeometryId, Hit, Intersector, Scene as EmbreeScene, SceneQuality,
};
use glam::{Affine3A, Vec3};
use std::borrow::Cow;
use std::collections::HashMap;
use std::sync::Arc;

/// Where static geometry goes: see the module doc.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StaticLayout {
    Flat,
    Nested,
    FlatWhenStill,
}

/// How [`SceneAccel`] lays the scene out in Embree. The default was chosen with
/// `relume bench rays`, which measures the alternatives in one run (`docs/benchmarks.md`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct AccelLayout {
    pub statics: StaticLayout,
    /// The triangle test of every level: robust, because the fast one leaks through shared
    /// edges (`tests/embree.rs`).
    pub intersector: Intersector,
}

impl Default for AccelLayout {
    fn default() -> AccelLayout {
        AccelLayout { statics: StaticLayout::FlatWhenStill, intersector: Intersector::Robust }
    }
}

/// What a top-level geometry or instance stands for.
#[derive(Clone, Debug)]
enum Slot {
    /// A static triangle geometry of the top level, or a dynamic surface's instance.
    Surface(SurfaceId),
    /// The identity instance of the nested static scene; its `geomID` indexes this table.
    StaticInstance(Vec<SurfaceId>),
}

/// One surface's triangles in the space they are stored in, borrowed from the scene where it
/// holds them that way.
struct Part<'a> {
    id: SurfaceId,
    positions: Cow<'a, [Vec3]>,
    triangles: Cow<'a, [[u32; 3]]>,
    world_from_object: Affine3A,
}

pub struct SceneAccel {
    top: Arc<CommittedScene>,
    slots: Vec<Option<Slot>>,
    /// Each dynamic surface's instance in `top` and its bottom-level scene.
    instance_of: HashMap<SurfaceId, (GeometryId, Arc<CommittedScene>)>,
    layout: AccelLayout,
}

impl SceneAccel {
    pub fn build(device: &Device, scene: &Scene) -> Result<SceneAccel, EmbreeError> {
        SceneAccel::build_with(device, scene, AccelLayout::default())
    }

    pub fn build_with(device: &Device, scene: &Scene, layout: AccelLayout) -> Result<SceneAccel, EmbreeError> {
        let (statics, dynamics) = parts(scene);
        let quality = if dynamics.is_empty() { SceneQuality::Static } else { SceneQuality::Dynamic };
        let mut top = EmbreeScene::with_intersector(device, quality, layout.intersector)?;
        let mut slots = Vec::new();
        let flat = match layout.statics {
            StaticLayout::Flat => true,
            StaticLayout::Nested => false,
            StaticLayout::FlatWhenStill => dynamics.is_empty(),
        };
        if flat {
            for part in &statics {
                let g = top.attach_triangles(&part.positions, &part.triangles)?;
                set_slot(&mut slots, g, Slot::Surface(part.id));
            }
        } else if !statics.is_empty() {
            let mut nested = EmbreeScene::with_intersector(device, SceneQuality::Static, layout.intersector)?;
            let mut map = Vec::new();
            for part in &statics {
                let g = nested.attach_triangles(&part.positions, &part.triangles)?;
                set_slot(&mut map, g, part.id);
            }
            let inst = top.attach_instance(Arc::new(nested.commit()?), Affine3A::IDENTITY)?;
            let map = map.into_iter().map(|s| s.unwrap_or(SurfaceId::Object(0))).collect();
            set_slot(&mut slots, inst, Slot::StaticInstance(map));
        }
        let mut instance_of = HashMap::new();
        for part in dynamics {
            let mut blas = EmbreeScene::with_intersector(device, SceneQuality::Static, layout.intersector)?;
            blas.attach_triangles(&part.positions, &part.triangles)?;
            let blas = Arc::new(blas.commit()?);
            let inst = top.attach_instance(blas.clone(), part.world_from_object)?;
            set_slot(&mut slots, inst, Slot::Surface(part.id));
            instance_of.insert(part.id, (inst, blas));
        }
        Ok(SceneAccel { top: Arc::new(top.commit()?), slots, instance_of, layout })
    }

    /// The layout this accel was built with.
    pub fn layout(&self) -> AccelLayout {
        self.layout
    }

    /// The committed top-level scene, for queries.
    pub fn scene(&self) -> &CommittedScene {
        &self.top
    }

    /// Maps a hit to the surface and triangle it landed on.
    pub fn resolve(&self, hit: &Hit) -> Option<(SurfaceId, u32)> {
        let slot = self.slots.get(hit.inst_id.unwrap_or(hit.geom_id) as usize)?.as_ref()?;
        let surface = match (slot, hit.inst_id) {
            (Slot::Surface(s), _) => *s,
            (Slot::StaticInstance(map), Some(_)) => *map.get(hit.geom_id as usize)?,
            (Slot::StaticInstance(_), None) => return None,
        };
        Some((surface, hit.prim_id))
    }

    /// Updates the instances of `moved` surfaces to their current transforms and recommits the
    /// top-level scene. Static geometry is untouched. Fails if a moved surface is not dynamic.
    pub fn update_instances(&mut self, scene: &Scene, moved: &[SurfaceId]) -> Result<(), EmbreeError> {
        if moved.is_empty() {
            return Ok(());
        }
        let stand_in = Arc::new(placeholder(&self.top)?);
        let shared = std::mem::replace(&mut self.top, stand_in);
        let mut top = CommittedScene::edit_shared(shared).map_err(|(back, e)| {
            self.top = back;
            e
        })?;
        let edited = moved.iter().try_for_each(|id| {
            let (inst, _) = self.instance_of.get(id).ok_or(EmbreeError::UnknownGeometry(u32::MAX))?;
            top.set_instance_transform(*inst, current_transform(scene, *id))
        });
        // Recommit even after a failed edit, so the accel stays traceable.
        self.top = Arc::new(top.commit()?);
        edited
    }

    /// A separate scene holding only the dynamic `surfaces`, at their current transforms: the
    /// same bottom-level scenes under the same transforms as in [`SceneAccel::scene`], so a ray
    /// meets them exactly as it would there. Queries against it cost a few instances, not the
    /// scene. Fails if a surface is not dynamic.
    pub fn subset(&self, scene: &Scene, surfaces: &[SurfaceId]) -> Result<CommittedScene, EmbreeError> {
        let placed: Vec<_> = surfaces.iter().map(|&id| (id, current_transform(scene, id))).collect();
        self.subset_at(&placed)
    }

    /// Like [`SceneAccel::subset`], with each dynamic surface under the given transform (where
    /// it was before a move, say).
    pub fn subset_at(&self, placed: &[(SurfaceId, Affine3A)]) -> Result<CommittedScene, EmbreeError> {
        let mut subset =
            EmbreeScene::with_intersector(self.top.device(), SceneQuality::Dynamic, self.layout.intersector)?;
        for (id, transform) in placed {
            let (_, blas) = self.instance_of.get(id).ok_or(EmbreeError::UnknownGeometry(u32::MAX))?;
            subset.attach_instance(blas.clone(), *transform)?;
        }
        subset.commit()
    }
}

/// Every intersectable surface, static ones in world space and dynamic ones in object space
/// with their current transforms: (static, dynamic).
fn parts(scene: &Scene) -> (Vec<Part<'_>>, Vec<Part<'_>>) {
    let (mut statics, mut dynamics) = (Vec::new(), Vec::new());
    for (i, o) in scene.objects.iter().enumerate() {
        let id = SurfaceId::Object(i as u32);
        if o.dynamic {
            let (positions, triangles) = (Cow::from(&o.mesh.positions[..]), Cow::from(&o.mesh.triangles[..]));
            dynamics.push(Part { id, positions, triangles, world_from_object: o.world_from_object });
        } else {
            let (positions, triangles) = (Cow::from(&o.world_positions[..]), Cow::from(&o.mesh.triangles[..]));
            statics.push(Part { id, positions, triangles, world_from_object: Affine3A::IDENTITY });
        }
    }
    for (i, l) in scene.lights.iter().enumerate() {
        let Some(mesh) = &l.mesh else { continue };
        let id = SurfaceId::Light(i as u32);
        if l.dynamic {
            let world_from_object = scene.desc().lights[i].transform.world_from_object();
            let (positions, triangles) = (Cow::from(&mesh.positions[..]), Cow::from(&mesh.triangles[..]));
            dynamics.push(Part { id, positions, triangles, world_from_object });
        } else {
            let triangles =
                Cow::Owned((0..mesh.triangles.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect());
            let positions = Cow::Owned((0..mesh.triangles.len()).flat_map(|t| scene.triangle(id, t as u32)).collect());
            statics.push(Part { id, positions, triangles, world_from_object: Affine3A::IDENTITY });
        }
    }
    (statics, dynamics)
}

/// Where a dynamic surface is now.
fn current_transform(scene: &Scene, id: SurfaceId) -> Affine3A {
    match id {
        SurfaceId::Object(i) => scene.objects[i as usize].world_from_object,
        SurfaceId::Light(i) => scene.desc().lights[i as usize].transform.world_from_object(),
    }
}

/// An empty committed scene that stands in while the real top level is being edited.
fn placeholder(like: &CommittedScene) -> Result<CommittedScene, EmbreeError> {
    EmbreeScene::new(like.device(), SceneQuality::Dynamic)?.commit()
}

fn set_slot<T>(table: &mut Vec<Option<T>>, id: GeometryId, value: T) {
    let i = id as usize;
    if table.len() <= i {
        table.resize_with(i + 1, || None);
    }
    table[i] = Some(value);
}

/// What lies under a film position: the surface, its name, whether edits may move it, and the
/// world point hit.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Picked {
    /// `object` or `light`.
    pub target: &'static str,
    pub name: String,
    pub dynamic: bool,
    pub position: [f32; 3],
}

/// The surface the camera sees at film position (`x`, `y`) in pixels, as of the last commit.
pub fn pick(scene: &Scene, accel: &SceneAccel, x: f32, y: f32) -> Option<Picked> {
    let ray = scene.camera.ray(x, y);
    let hit = accel.scene().intersect1(&ray)?;
    let (surface, _) = accel.resolve(&hit)?;
    let position = (ray.origin + ray.dir * hit.t).to_array();
    Some(match surface {
        SurfaceId::Object(i) => {
            let o = scene.objects.get(i as usize)?;
            Picked { target: "object", name: o.name.clone(), dynamic: o.dynamic, position }
        }
        SurfaceId::Light(i) => {
            let l = scene.lights.get(i as usize)?;
            Picked { target: "light", name: l.name.clone(), dynamic: l.dynamic, position }
        }
    })
}
