//! The Embree layer: the only module with `unsafe` code.
//!
//! Purpose: a small safe wrapper over the system Embree 3 library (Debian `libembree-dev`).
//! - [`Device`]: one per process, ref-counted, with an error callback routed to `tracing`.
//! - [`Scene`] (mutable, being built) → [`Scene::commit`] → [`CommittedScene`] (immutable,
//!   `Send + Sync`, shared by every tracing thread). [`CommittedScene::edit`] turns it back into a
//!   `Scene` only when no one else holds it, so nothing can trace while Embree commits.
//! - Geometry: triangle meshes (vertex buffers padded by [`padded_vertex_floats`]) and instances
//!   of committed scenes with an updatable `world_from_object` transform.
//! - Queries: single rays and 8/16-wide packets, closest hit and occlusion.
//!
//! Units: whatever the scene uses (meters by convention); `t` is in units of the ray direction's
//! length. Directions need not be normalised. Invariants: every raw handle is released exactly
//! once (in `Drop`), and buffers shared with Embree outlive every scene that references them.
//!
//! Version-specific calls (Embree 3's `RTCIntersectContext` and its inline initialiser) live in
//! `version.rs` alone, so Embree 4 can be supported by changing that file.
mod device;
mod error;
mod flush;
mod query;
mod scene;
mod sys;
mod version;

pub use device::Device;
pub use error::EmbreeError;
pub use flush::flush_denormals_to_zero;
pub use query::{Hit, Ray, PACKET16, PACKET8};
pub use scene::{padded_vertex_floats, CommittedScene, GeometryId, Scene, SceneQuality};
