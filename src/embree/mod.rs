//! The Embree layer: the only module with `unsafe` code.
//!
//! Purpose: a small safe wrapper over Intel Embree 4 (4.3 or later; 4.4 on the development
//! machines).
//! - [`Device`]: one per process, ref-counted, with an error callback routed to `tracing`, an
//!   optional cap on the kernel family ([`Isa`], `max_isa=`), and the library's [`Version`].
//! - [`Scene`] (mutable, being built) → [`Scene::commit`] → [`CommittedScene`] (immutable,
//!   `Send + Sync`, shared by every tracing thread). [`CommittedScene::edit`] turns it back into a
//!   `Scene` only when no one else holds it, so nothing can trace while Embree commits.
//! - Geometry: triangle meshes (vertex buffers padded by [`padded_vertex_floats`]) and instances
//!   of committed scenes with an updatable `world_from_object` transform.
//! - Queries: single rays and 8/16-wide packets, closest hit and occlusion.
//!
//! Units: whatever the scene uses (meters by convention); `t` is in units of the ray direction's
//! length. Directions need not be normalised.
//!
//! ## Where the library comes from
//! `build.rs` binds the headers with bindgen and links `libembree4`, found in this order:
//! `$EMBREE_DIR`, the system (Debian trixie's `libembree-dev` 4.3), then `.deps/embree`, which
//! `scripts/embree.sh` fills on Debian bookworm (which has no Embree 4): Intel's `libembree4`
//! 4.4.0 and its oneTBB 2021.12 from the PyPI wheel `embreex`, and Debian's 4.4 headers. The
//! binary finds a library outside the system's search path by rpath. [`Device`] refuses a library
//! older than the headers (minor version) or of another major version.
//!
//! ## TBB
//! Embree builds BVHs on Intel's TBB, as Open Image Denoise runs its network on it. On bookworm
//! the two wheels each bring their own TBB under distinct names (`libtbb-<hash>.so.12` and
//! `libtbb.so.12`), so a process that commits scenes and denoises holds two TBB pools of one
//! worker per spare core. They are kept apart, measured: see `docs/embree.md` ("One TBB or
//! two"). In the trixie image both libraries need `libtbb.so.12`, so the loader maps one TBB.
//!
//! ## The FFI contracts, and what guarantees each
//! Checked against Embree 4's API pages (`rtcIntersect1/4/8/16(3)`, `rtcOccluded*(3)`,
//! `rtcInitIntersectArguments(3)`, `rtcInitOccludedArguments(3)`, `rtcInitRayQueryContext(3)`,
//! `rtcSetGeometryMask(3)`, `rtcSetSceneFlags(3)`, `rtcSetGeometryEnableFilterFunctionFromArguments(3)`,
//! `rtcForwardIntersect1(3)`, `rtcSetSharedGeometryBuffer(3)`, `RTC_GEOMETRY_TYPE_TRIANGLE(3)`,
//! `RTC_GEOMETRY_TYPE_INSTANCE(3)`, `rtcCommitScene(3)`, `rtcSetDeviceErrorFunction(3)`,
//! `rtcGetDeviceError(3)`, `rtcGetDeviceProperty(3)`, `rtcGetSceneBounds(3)`).
//! - **Query arguments.** Embree 4 replaced Embree 3's `RTCIntersectContext` with per-call
//!   `RTCIntersectArguments` / `RTCOccludedArguments`, each pointing at an `RTCRayQueryContext`
//!   (the instance stack). Their initialisers are inline in the headers; `version.rs` mirrors
//!   them field for field and passes the coherence hint as `RTC_RAY_QUERY_FLAG_COHERENT` or
//!   `_INCOHERENT`. Both structs and the context live on the caller's stack for the one call.
//! - **Masks.** Embree 4 always tests ray masks, and a new geometry's mask is 1 (Embree 3's was
//!   all ones, and masks were compiled out). Every ray here carries the mask `u32::MAX`, so it
//!   meets every geometry whatever its mask; no geometry sets one.
//! - **Instances.** Single-level instancing (`RTC_MAX_INSTANCE_LEVEL_COUNT` 1, asserted in
//!   `layout.rs`): Embree traverses instances itself, so `rtcForwardIntersect*`, which only
//!   user-geometry callbacks call, is not used. The hit's `Ng` is in the instance's object space
//!   (`RTCHit(3)`); `instID[0]` names the instance.
//! - **Robust mode.** Scenes are built with `RTC_SCENE_FLAG_ROBUST` unless [`Intersector::Fast`]
//!   is asked for: watertight along shared edges, without the optimisations that reduce
//!   arithmetic accuracy.
//! - **Filter functions.** None is installed yet. A filter passed in the query arguments runs
//!   only on a scene with `RTC_SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS` and for geometries that
//!   enable it with `rtcSetGeometryEnableFilterFunctionFromArguments` (or every geometry, with
//!   `RTC_RAY_QUERY_FLAG_INVOKE_ARGUMENT_FILTER`); it may be called from any tracing thread, must
//!   not unwind, and rejects a candidate hit by zeroing its lane of the valid mask.
//! - **Alignment.** Valid masks and packets: 32 bytes for 8 lanes, 64 for 16; single rays and
//!   hits and `RTCBounds`: 16. Guaranteed by type: `layout.rs` defines `repr(align)` mask types,
//!   the query calls in `version.rs` accept only them, and `const` assertions check bindgen's
//!   `RTC_ALIGN` structs. (Until this was so, masks were `[i32; W]` locals, 4-byte aligned, and a
//!   release build crashed in `rtcIntersect8` under the AVX-512 kernels.)
//! - **Buffer padding.** Embree reads the last vertex with a 16-byte load, so a `FLOAT3` vertex
//!   buffer needs 4 bytes past its last element: [`padded_vertex_floats`], tested in
//!   `scene.rs`. Shared buffers must be 4-byte aligned: they are `Vec<f32>`/`Vec<u32>`.
//! - **Shared-buffer lifetimes.** Shared buffers must outlive every use by Embree. Each
//!   geometry's buffers (or the child scene an instance points at, as an `Arc`) are owned by
//!   its slot in the scene; a `Vec`'s heap block does not move when the `Vec` does. A detached
//!   geometry's buffers are kept until the next commit has rebuilt the scene without them, and
//!   `Drop` releases the scene before its buffers.
//! - **Commit versus trace.** A scene must not be traced while it commits, nor a child scene
//!   changed while a parent that instances it is in use. Only `Scene` (owned, not `Sync`) can be
//!   changed or committed; `CommittedScene` answers queries only, and `edit_shared` reopens it
//!   only as the last `Arc` holder. Children are held as `Arc<CommittedScene>`, so a child
//!   cannot be reopened while a parent holds it.
//! - **Thread safety.** Queries on a committed scene and calls on one device may come from any
//!   thread (`Send + Sync` on the handles). Every tracing thread sets FTZ/DAZ
//!   ([`flush_denormals_to_zero`], in the rayon pool's start handler).
//! - **Errors.** The error callback may be called from any thread during any call: it only
//!   formats the message and logs it through `tracing` (thread-safe, no unwinding across the
//!   `extern "C"` boundary, which would abort). `rtcGetDeviceError` reports the calling
//!   thread's last error, so `Device::check` runs on the thread that made the call, right after
//!   it.
//! - **Empty scenes.** A scene with no geometry commits; every ray misses it and
//!   `rtcGetSceneBounds` returns inverted bounds, reported as `None` (tested in
//!   `tests/embree.rs`).
//! - **Kernel families.** The same calls run on every ISA Embree was built with; the tests run
//!   the queries and a render of every technique under each family this CPU has
//!   (`tests/embree_isa.rs`).
//!
//! Version-specific calls (the query arguments and their inline initialisers) live in
//! `version.rs` alone.
mod device;
mod error;
mod flush;
mod isa;
mod layout;
mod query;
mod scene;
mod sys;
mod version;

pub use device::{Device, Version, HEADER_VERSION};
pub use error::EmbreeError;
pub use flush::flush_denormals_to_zero;
pub use isa::{Isa, UnknownIsa};
pub use query::{Hit, Ray, PACKET16, PACKET8};
pub use scene::{padded_vertex_floats, CommittedScene, GeometryId, Intersector, Scene, SceneQuality};
