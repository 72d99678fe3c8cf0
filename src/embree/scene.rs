//! Scenes and their geometry: build a [`Scene`], `commit()` it into a shareable
//! [`CommittedScene`], and `edit()` it again when nothing else holds it.
use super::device::Device;
use super::error::EmbreeError;
use super::sys;
use glam::{Affine3A, Vec3};
use std::collections::HashMap;
use std::sync::Arc;

/// Embree's id of a geometry within one scene (`geomID`, or `instID` for instances).
pub type GeometryId = u32;

/// How a scene is built: a static scene favours trace speed (`RTC_BUILD_QUALITY_HIGH`), a
/// dynamic one rebuild speed (`RTC_SCENE_FLAG_DYNAMIC`, `RTC_BUILD_QUALITY_LOW`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneQuality {
    Static,
    Dynamic,
}

/// Which triangle test Embree compiles in. `Robust` (`RTC_SCENE_FLAG_ROBUST`) is watertight
/// along shared edges and avoids optimisations that reduce arithmetic accuracy. `Fast` is
/// Embree's default kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Intersector {
    Robust,
    Fast,
}

/// Bytes a shared Embree buffer needs for `count` elements of `stride` bytes: Embree reads the
/// last element with a 16-byte SSE load, so the buffer must reach 16 bytes past its start.
pub fn required_buffer_bytes(stride: usize, count: usize) -> usize {
    if count == 0 {
        return 0;
    }
    stride * (count - 1) + stride.max(16)
}

/// Packs positions as `FLOAT3` (12-byte stride) followed by the padding Embree's 16-byte read of
/// the last vertex needs ([`required_buffer_bytes`]).
pub fn padded_vertex_floats(positions: &[Vec3]) -> Vec<f32> {
    let floats = required_buffer_bytes(12, positions.len()).div_ceil(4);
    let mut out = Vec::with_capacity(floats);
    for p in positions {
        out.extend_from_slice(&[p.x, p.y, p.z]);
    }
    out.resize(floats, 0.0);
    out
}

/// What a geometry keeps alive: buffers Embree reads, or the scene an instance points at.
enum Attached {
    Triangles { _vertices: Vec<f32>, _indices: Vec<u32> },
    Instance { _child: Arc<CommittedScene> },
}

struct GeometrySlot {
    raw: sys::RTCGeometry,
    _keep: Attached,
}

/// Raw scene state shared by [`Scene`] and [`CommittedScene`].
struct SceneHandle {
    device: Device,
    raw: sys::RTCScene,
    geometries: HashMap<GeometryId, GeometrySlot>,
    /// Buffers of geometries detached since the last commit. The scene's previous build may
    /// still point into them until `rtcCommitScene` rebuilds it, so they are freed only then.
    retired: Vec<Attached>,
}

// SAFETY: Embree scene and geometry handles may be used from any thread; mutation only happens
// through `&mut Scene`, and committed scenes only answer queries, which Embree allows
// concurrently. Buffers referenced by Embree are owned here and never reallocated.
unsafe impl Send for SceneHandle {}
// SAFETY: see `Send`: shared access (`&CommittedScene`) only runs thread-safe queries.
unsafe impl Sync for SceneHandle {}

impl Drop for SceneHandle {
    fn drop(&mut self) {
        for slot in self.geometries.values() {
            // SAFETY: each geometry handle was created by us and is released exactly once here.
            unsafe { sys::rtcReleaseGeometry(slot.raw) };
        }
        // SAFETY: the scene handle was created by `rtcNewScene` and is released once, before
        // the buffers and child scenes it references are dropped (fields drop after this).
        unsafe { sys::rtcReleaseScene(self.raw) };
    }
}

/// A scene being built or edited. Not traceable until [`Scene::commit`].
pub struct Scene {
    handle: SceneHandle,
}

/// A committed, immutable scene: `Send + Sync`, queried from any number of threads.
pub struct CommittedScene {
    handle: SceneHandle,
}

impl Scene {
    /// A robust scene of the given quality.
    pub fn new(device: &Device, quality: SceneQuality) -> Result<Scene, EmbreeError> {
        Scene::with_intersector(device, quality, Intersector::Robust)
    }

    pub fn with_intersector(
        device: &Device,
        quality: SceneQuality,
        intersector: Intersector,
    ) -> Result<Scene, EmbreeError> {
        // SAFETY: the device handle is live for as long as `device` exists.
        let raw = unsafe { sys::rtcNewScene(device.raw()) };
        device.check(|| "rtcNewScene".into())?;
        let robust = match intersector {
            Intersector::Robust => sys::RTC_SCENE_FLAG_ROBUST,
            Intersector::Fast => sys::RTC_SCENE_FLAG_NONE,
        };
        let (flags, build) = match quality {
            SceneQuality::Static => (robust, sys::RTC_BUILD_QUALITY_HIGH),
            SceneQuality::Dynamic => (robust | sys::RTC_SCENE_FLAG_DYNAMIC, sys::RTC_BUILD_QUALITY_LOW),
        };
        // SAFETY: `raw` is a live scene handle we own.
        unsafe {
            sys::rtcSetSceneFlags(raw, flags);
            sys::rtcSetSceneBuildQuality(raw, build);
        }
        let handle = SceneHandle { device: device.clone(), raw, geometries: HashMap::new(), retired: Vec::new() };
        device.check(|| "rtcSetSceneFlags".into())?;
        Ok(Scene { handle })
    }

    /// Attaches a triangle mesh; returns its `geomID`. Indices must address `positions`, and all
    /// coordinates must be finite.
    pub fn attach_triangles(&mut self, positions: &[Vec3], triangles: &[[u32; 3]]) -> Result<GeometryId, EmbreeError> {
        if positions.is_empty() || triangles.is_empty() {
            return Err(EmbreeError::InvalidGeometry("a triangle mesh needs vertices and triangles".into()));
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(EmbreeError::InvalidGeometry(format!("vertex {i} is not finite")));
        }
        let n = positions.len() as u32;
        if let Some(t) = triangles.iter().position(|tri| tri.iter().any(|&i| i >= n)) {
            return Err(EmbreeError::InvalidGeometry(format!("triangle {t} indexes past the {n} vertices")));
        }
        let vertices = padded_vertex_floats(positions);
        let indices: Vec<u32> = triangles.iter().flatten().copied().collect();
        let device = self.handle.device.clone();
        // SAFETY: the device is live; the new geometry is owned by the slot stored below.
        let geom = unsafe { sys::rtcNewGeometry(device.raw(), sys::RTC_GEOMETRY_TYPE_TRIANGLE) };
        device.check(|| "rtcNewGeometry(TRIANGLE)".into())?;
        // SAFETY: the buffers are heap allocations moved into the slot below, never reallocated
        // and freed only after the geometry is released; the vertex buffer carries the padding
        // Embree's 16-byte loads need (`padded_vertex_floats`), strides match the formats.
        let id = unsafe {
            sys::rtcSetSharedGeometryBuffer(
                geom,
                sys::RTC_BUFFER_TYPE_VERTEX,
                0,
                sys::RTC_FORMAT_FLOAT3,
                vertices.as_ptr().cast(),
                0,
                12,
                positions.len(),
            );
            sys::rtcSetSharedGeometryBuffer(
                geom,
                sys::RTC_BUFFER_TYPE_INDEX,
                0,
                sys::RTC_FORMAT_UINT3,
                indices.as_ptr().cast(),
                0,
                12,
                triangles.len(),
            );
            sys::rtcCommitGeometry(geom);
            sys::rtcAttachGeometry(self.handle.raw, geom)
        };
        let slot = GeometrySlot { raw: geom, _keep: Attached::Triangles { _vertices: vertices, _indices: indices } };
        self.handle.geometries.insert(id, slot);
        device.check(|| "attach triangle geometry".into())?;
        Ok(id)
    }

    /// Attaches an instance of `child` placed by `world_from_object`; returns its `instID`.
    pub fn attach_instance(
        &mut self,
        child: Arc<CommittedScene>,
        world_from_object: Affine3A,
    ) -> Result<GeometryId, EmbreeError> {
        let device = self.handle.device.clone();
        // SAFETY: the device is live; the geometry is owned by the slot stored below.
        let geom = unsafe { sys::rtcNewGeometry(device.raw(), sys::RTC_GEOMETRY_TYPE_INSTANCE) };
        device.check(|| "rtcNewGeometry(INSTANCE)".into())?;
        let cols = world_from_object.to_cols_array();
        // SAFETY: `child.raw` is a committed scene kept alive by the `Arc` stored in the slot;
        // `cols` holds the 12 floats FLOAT3X4_COLUMN_MAJOR reads and outlives the call (Embree
        // copies transforms).
        let id = unsafe {
            sys::rtcSetGeometryInstancedScene(geom, child.handle.raw);
            sys::rtcSetGeometryTimeStepCount(geom, 1);
            sys::rtcSetGeometryTransform(geom, 0, sys::RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, cols.as_ptr().cast());
            sys::rtcCommitGeometry(geom);
            sys::rtcAttachGeometry(self.handle.raw, geom)
        };
        self.handle.geometries.insert(id, GeometrySlot { raw: geom, _keep: Attached::Instance { _child: child } });
        device.check(|| "attach instance".into())?;
        Ok(id)
    }

    /// Moves an instance. Takes effect at the next [`Scene::commit`].
    pub fn set_instance_transform(&mut self, id: GeometryId, world_from_object: Affine3A) -> Result<(), EmbreeError> {
        let slot = self.handle.geometries.get(&id).ok_or(EmbreeError::UnknownGeometry(id))?;
        let cols = world_from_object.to_cols_array();
        // SAFETY: `slot.raw` is a live geometry of this scene; `cols` holds 12 floats and Embree
        // copies them. A non-instance geometry makes Embree report an error, checked below.
        unsafe {
            sys::rtcSetGeometryTransform(slot.raw, 0, sys::RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, cols.as_ptr().cast());
            sys::rtcCommitGeometry(slot.raw);
        }
        self.handle.device.check(|| format!("set transform of geometry {id}"))
    }

    /// Removes a geometry from the scene and frees what it kept alive.
    pub fn detach(&mut self, id: GeometryId) -> Result<(), EmbreeError> {
        let slot = self.handle.geometries.remove(&id).ok_or(EmbreeError::UnknownGeometry(id))?;
        // SAFETY: rtcDetachGeometry(3)/rtcReleaseGeometry(3): `id` is attached to this scene and
        // our handle to it is released exactly once, here. The buffers it shares are kept in
        // `retired` until the next commit has rebuilt the scene without them.
        unsafe {
            sys::rtcDetachGeometry(self.handle.raw, id);
            sys::rtcReleaseGeometry(slot.raw);
        }
        self.handle.retired.push(slot._keep);
        self.handle.device.check(|| format!("detach geometry {id}"))
    }

    /// Builds the acceleration structure. The result can be shared and queried concurrently.
    pub fn commit(mut self) -> Result<CommittedScene, EmbreeError> {
        // SAFETY: rtcCommitScene(3) must not run while the scene is traced: we own it exclusively
        // (`self` by value; a `CommittedScene` becomes a `Scene` only as the last holder), and
        // every instanced child is an immutable `CommittedScene`. A scene with no geometry
        // commits to an empty scene that every ray misses.
        unsafe { sys::rtcCommitScene(self.handle.raw) };
        self.handle.device.check(|| "rtcCommitScene".into())?;
        self.handle.retired.clear();
        Ok(CommittedScene { handle: self.handle })
    }

    pub fn geometry_count(&self) -> usize {
        self.handle.geometries.len()
    }
}

impl CommittedScene {
    /// Reopens the scene for editing. Take it out of its `Arc` first (`Arc::try_unwrap`), which
    /// proves no other thread can be tracing it.
    pub fn edit(self) -> Scene {
        Scene { handle: self.handle }
    }

    /// Reopens a shared scene if this is its last holder; otherwise hands it back.
    pub fn edit_shared(shared: Arc<CommittedScene>) -> Result<Scene, (Arc<CommittedScene>, EmbreeError)> {
        Arc::try_unwrap(shared).map(CommittedScene::edit).map_err(|arc| {
            let others = Arc::strong_count(&arc) - 1;
            (arc, EmbreeError::SceneShared(others))
        })
    }

    pub(crate) fn raw(&self) -> sys::RTCScene {
        self.handle.raw
    }

    /// The device this scene was made on.
    pub fn device(&self) -> &Device {
        &self.handle.device
    }

    /// World-space bounds of everything in the scene, `None` when empty.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut b = sys::RTCBounds::default();
        // SAFETY: the scene is committed; `b` is a valid, aligned RTCBounds.
        unsafe { sys::rtcGetSceneBounds(self.handle.raw, &mut b) };
        let lo = Vec3::new(b.lower_x, b.lower_y, b.lower_z);
        let hi = Vec3::new(b.upper_x, b.upper_y, b.upper_z);
        (lo.cmple(hi).all()).then_some((lo, hi))
    }

    pub fn geometry_count(&self) -> usize {
        self.handle.geometries.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padding_reaches_sixteen_bytes_past_last_vertex() {
        for n in 1..6 {
            let pts: Vec<Vec3> = (0..n).map(|i| Vec3::splat(i as f32)).collect();
            let buf = padded_vertex_floats(&pts);
            // The last vertex starts at float 3(n-1) and Embree reads 4 floats from there.
            assert!(buf.len() >= 3 * (n - 1) + 4, "n={n}: {} floats", buf.len());
            assert_eq!(buf.len(), 3 * n + 1);
            assert_eq!(&buf[3 * (n - 1)..3 * n], &[(n - 1) as f32; 3]);
        }
        assert_eq!(required_buffer_bytes(12, 0), 0);
        assert_eq!(required_buffer_bytes(16, 10), 160);
        assert_eq!(required_buffer_bytes(12, 1), 16);
    }
}
