//! The scene as a two-level Embree scene, and the map from Embree ids back to surfaces.
//!
//! Layout: every static object and static light shape is one geometry (world-space vertices) of
//! a single bottom-level scene, which is built once and never rebuilt. Each dynamic object or
//! dynamic light shape is its own bottom-level scene (object-space vertices) under an instance
//! whose transform edits update. The top-level scene holds the static instance (identity) and
//! the dynamic instances; only it is recommitted when something moves.
use super::{Scene, SurfaceId};
use crate::embree::{CommittedScene, Device, EmbreeError, GeometryId, Hit, Scene as EmbreeScene, SceneQuality};
use glam::Affine3A;
use std::collections::HashMap;
use std::sync::Arc;

/// What an instance of the top-level scene stands for.
#[derive(Clone, Debug)]
enum InstanceContent {
    /// The static bottom-level scene; `geomID` indexes this table.
    Static(Vec<SurfaceId>),
    Dynamic(SurfaceId),
}

pub struct SceneAccel {
    top: Arc<CommittedScene>,
    instances: Vec<Option<InstanceContent>>,
    /// Each dynamic surface's instance in `top` and its bottom-level scene.
    instance_of: HashMap<SurfaceId, (GeometryId, Arc<CommittedScene>)>,
}

impl SceneAccel {
    pub fn build(device: &Device, scene: &Scene) -> Result<SceneAccel, EmbreeError> {
        // Gather every intersectable surface with its vertices in the space it is stored in.
        let mut static_scene = EmbreeScene::new(device, SceneQuality::Static)?;
        let mut static_map = Vec::new();
        let mut dynamic = Vec::new();
        for (i, o) in scene.objects.iter().enumerate() {
            let id = SurfaceId::Object(i as u32);
            if o.dynamic {
                dynamic.push((id, o.mesh.positions.clone(), o.mesh.triangles.clone(), o.world_from_object));
            } else {
                let g = static_scene.attach_triangles(&o.world_positions, &o.mesh.triangles)?;
                set_slot(&mut static_map, g, id);
            }
        }
        for (i, l) in scene.lights.iter().enumerate() {
            let Some(mesh) = &l.mesh else { continue };
            let id = SurfaceId::Light(i as u32);
            let desc = &scene.desc().lights[i];
            if l.dynamic {
                dynamic.push((id, mesh.positions.clone(), mesh.triangles.clone(), desc.transform.world_from_object()));
            } else {
                let tris: Vec<[u32; 3]> =
                    (0..mesh.triangles.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
                let verts: Vec<_> = (0..mesh.triangles.len()).flat_map(|t| scene.triangle(id, t as u32)).collect();
                let g = static_scene.attach_triangles(&verts, &tris)?;
                set_slot(&mut static_map, g, id);
            }
        }

        // The top level: one instance for all static geometry, one per dynamic surface.
        let mut top = EmbreeScene::new(device, SceneQuality::Dynamic)?;
        let mut instances = Vec::new();
        let mut instance_of = HashMap::new();
        if static_scene.geometry_count() > 0 {
            let inst = top.attach_instance(Arc::new(static_scene.commit()?), Affine3A::IDENTITY)?;
            set_slot(
                &mut instances,
                inst,
                InstanceContent::Static(static_map.into_iter().map(|s| s.unwrap_or(SurfaceId::Object(0))).collect()),
            );
        }
        for (id, positions, triangles, xf) in dynamic {
            let mut blas = EmbreeScene::new(device, SceneQuality::Static)?;
            blas.attach_triangles(&positions, &triangles)?;
            let blas = Arc::new(blas.commit()?);
            let inst = top.attach_instance(blas.clone(), xf)?;
            set_slot(&mut instances, inst, InstanceContent::Dynamic(id));
            instance_of.insert(id, (inst, blas));
        }
        Ok(SceneAccel { top: Arc::new(top.commit()?), instances, instance_of })
    }

    /// The committed top-level scene, for queries.
    pub fn scene(&self) -> &CommittedScene {
        &self.top
    }

    /// Maps a hit to the surface and triangle it landed on.
    pub fn resolve(&self, hit: &Hit) -> Option<(SurfaceId, u32)> {
        let inst = hit.inst_id? as usize;
        match self.instances.get(inst)?.as_ref()? {
            InstanceContent::Static(map) => map.get(hit.geom_id as usize).map(|s| (*s, hit.prim_id)),
            InstanceContent::Dynamic(s) => Some((*s, hit.prim_id)),
        }
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
        let mut subset = EmbreeScene::new(self.top.device(), SceneQuality::Dynamic)?;
        for (id, transform) in placed {
            let (_, blas) = self.instance_of.get(id).ok_or(EmbreeError::UnknownGeometry(u32::MAX))?;
            subset.attach_instance(blas.clone(), *transform)?;
        }
        subset.commit()
    }
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
