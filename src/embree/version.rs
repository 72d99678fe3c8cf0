//! Embree 4's query calls and the inline initialisers bindgen cannot emit.
//!
//! Embree 4 passes each query an optional `RTCIntersectArguments` / `RTCOccludedArguments`
//! (`rtcInitIntersectArguments(3)`, `rtcInitOccludedArguments(3)`): flags (the coherence hint),
//! a feature mask, an optional `RTCRayQueryContext` (the instance stack, which filter callbacks
//! read), and an optional filter function. Those initialisers are `RTC_FORCEINLINE` in
//! `rtcore_scene.h`, so they are mirrored here, field for field, and every query builds its
//! arguments through them.
use super::layout::{ValidMask16, ValidMask8};
use super::sys;

/// How rays in one query relate, as a hint to Embree's traversal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coherence {
    /// Camera rays of neighbouring pixels.
    Coherent,
    /// Bounce and shadow rays.
    Incoherent,
}

impl Coherence {
    fn flags(self) -> sys::RTCRayQueryFlags {
        match self {
            Coherence::Coherent => sys::RTC_RAY_QUERY_FLAG_COHERENT,
            Coherence::Incoherent => sys::RTC_RAY_QUERY_FLAG_INCOHERENT,
        }
    }
}

/// Mirrors `rtcInitRayQueryContext` (`rtcore_common.h`): an empty instance stack.
fn query_context() -> sys::RTCRayQueryContext {
    const LEVELS: usize = sys::RTC_MAX_INSTANCE_LEVEL_COUNT as usize;
    sys::RTCRayQueryContext {
        instID: [sys::RTC_INVALID_GEOMETRY_ID; LEVELS],
        instPrimID: [sys::RTC_INVALID_GEOMETRY_ID; LEVELS],
    }
}

/// Mirrors `rtcInitIntersectArguments`, with the coherence hint and the caller's context.
fn intersect_arguments(coherence: Coherence, ctx: &mut sys::RTCRayQueryContext) -> sys::RTCIntersectArguments {
    sys::RTCIntersectArguments {
        flags: coherence.flags(),
        feature_mask: sys::RTC_FEATURE_FLAG_ALL,
        context: ctx,
        filter: None,
        intersect: None,
    }
}

/// Mirrors `rtcInitOccludedArguments`, with the coherence hint and the caller's context.
fn occluded_arguments(coherence: Coherence, ctx: &mut sys::RTCRayQueryContext) -> sys::RTCOccludedArguments {
    sys::RTCOccludedArguments {
        flags: coherence.flags(),
        feature_mask: sys::RTC_FEATURE_FLAG_ALL,
        context: ctx,
        filter: None,
        occluded: None,
    }
}

/// Closest hit for one ray. The caller passes a committed scene handle.
pub(crate) fn intersect1(scene: sys::RTCScene, rayhit: &mut sys::RTCRayHit) {
    let mut ctx = query_context();
    let mut args = intersect_arguments(Coherence::Incoherent, &mut ctx);
    // SAFETY: rtcIntersect1(3): `scene` is a committed scene kept alive by the caller's
    // `&CommittedScene`; `args` is initialised as `rtcInitIntersectArguments` would and points
    // at `ctx`, both live for the call; `rayhit` is live, exclusively borrowed and 16-byte
    // aligned by bindgen's RTC_ALIGN(16) (layout.rs).
    unsafe { sys::rtcIntersect1(scene, rayhit, &mut args) }
}

/// Occlusion for one ray: on return `ray.tfar` is `-inf` if anything was hit.
pub(crate) fn occluded1(scene: sys::RTCScene, ray: &mut sys::RTCRay) {
    let mut ctx = query_context();
    let mut args = occluded_arguments(Coherence::Incoherent, &mut ctx);
    // SAFETY: rtcOccluded1(3): as in `intersect1`; `ray` is a live, exclusively borrowed RTCRay,
    // 16-byte aligned by RTC_ALIGN(16).
    unsafe { sys::rtcOccluded1(scene, ray, &mut args) }
}

/// Closest hit for an 8-wide packet; lanes with `valid[i] == 0` are ignored.
pub(crate) fn intersect8(scene: sys::RTCScene, valid: &ValidMask8, rayhit: &mut sys::RTCRayHit8, coherence: Coherence) {
    let mut ctx = query_context();
    let mut args = intersect_arguments(coherence, &mut ctx);
    // SAFETY: rtcIntersect8(3): `valid` is 8 ints and `rayhit` one packet, both 32-byte aligned
    // by their types (`ValidMask8`'s repr(align(32)), bindgen's RTC_ALIGN(32); asserted in
    // layout.rs); both are live, exclusively borrowed for the call, as are `args` and `ctx`;
    // the scene is committed and kept alive by the caller's `&CommittedScene`.
    unsafe { sys::rtcIntersect8(valid.0.as_ptr(), scene, rayhit, &mut args) }
}

/// Closest hit for a 16-wide packet.
pub(crate) fn intersect16(
    scene: sys::RTCScene,
    valid: &ValidMask16,
    rayhit: &mut sys::RTCRayHit16,
    coherence: Coherence,
) {
    let mut ctx = query_context();
    let mut args = intersect_arguments(coherence, &mut ctx);
    // SAFETY: rtcIntersect16(3): as `intersect8`, with 16 lanes and 64-byte alignment, which
    // `ValidMask16` and bindgen's RTC_ALIGN(64) give by type (asserted in layout.rs).
    unsafe { sys::rtcIntersect16(valid.0.as_ptr(), scene, rayhit, &mut args) }
}

/// Occlusion for an 8-wide packet.
pub(crate) fn occluded8(scene: sys::RTCScene, valid: &ValidMask8, ray: &mut sys::RTCRay8) {
    let mut ctx = query_context();
    let mut args = occluded_arguments(Coherence::Incoherent, &mut ctx);
    // SAFETY: rtcOccluded8(3): as in `intersect8`, for the ray-only packet type (RTC_ALIGN(32)).
    unsafe { sys::rtcOccluded8(valid.0.as_ptr(), scene, ray, &mut args) }
}

/// Occlusion for a 16-wide packet.
pub(crate) fn occluded16(scene: sys::RTCScene, valid: &ValidMask16, ray: &mut sys::RTCRay16) {
    let mut ctx = query_context();
    let mut args = occluded_arguments(Coherence::Incoherent, &mut ctx);
    // SAFETY: rtcOccluded16(3): as in `intersect16`, for the ray-only packet type (RTC_ALIGN(64)).
    unsafe { sys::rtcOccluded16(valid.0.as_ptr(), scene, ray, &mut args) }
}
