//! Embree-3-specific query calls.
//!
//! Embree 3 passes an `RTCIntersectContext` (initialised by the inline `rtcInitIntersectContext`,
//! which bindgen cannot emit) to every query; Embree 4 replaced it with per-call argument
//! structs. Everything that depends on that difference is in this file.
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

/// Mirrors `rtcInitIntersectContext` from `rtcore_common.h` (Embree 3.13, one instance level).
pub(crate) fn intersect_context(coherence: Coherence) -> sys::RTCIntersectContext {
    sys::RTCIntersectContext {
        flags: match coherence {
            Coherence::Coherent => sys::RTC_INTERSECT_CONTEXT_FLAG_COHERENT,
            Coherence::Incoherent => sys::RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT,
        },
        filter: None,
        instID: [sys::RTC_INVALID_GEOMETRY_ID; 1],
    }
}

/// Closest hit for one ray. The caller passes a committed scene handle.
pub(crate) fn intersect1(scene: sys::RTCScene, rayhit: &mut sys::RTCRayHit) {
    let mut ctx = intersect_context(Coherence::Incoherent);
    // SAFETY: rtcIntersect1(3): `scene` is a committed scene kept alive by the caller's
    // `&CommittedScene`; `ctx` is initialised as `rtcInitIntersectContext` would; `rayhit` is
    // live, exclusively borrowed and 16-byte aligned by bindgen's RTC_ALIGN(16) (layout.rs).
    unsafe { sys::rtcIntersect1(scene, &mut ctx, rayhit) }
}

/// Occlusion for one ray: on return `ray.tfar` is `-inf` if anything was hit.
pub(crate) fn occluded1(scene: sys::RTCScene, ray: &mut sys::RTCRay) {
    let mut ctx = intersect_context(Coherence::Incoherent);
    // SAFETY: rtcOccluded1(3): as in `intersect1`; `ray` is a live, exclusively borrowed RTCRay,
    // 16-byte aligned by RTC_ALIGN(16).
    unsafe { sys::rtcOccluded1(scene, &mut ctx, ray) }
}

/// Closest hit for an 8-wide packet; lanes with `valid[i] == 0` are ignored.
pub(crate) fn intersect8(scene: sys::RTCScene, valid: &ValidMask8, rayhit: &mut sys::RTCRayHit8, coherence: Coherence) {
    let mut ctx = intersect_context(coherence);
    // SAFETY: rtcIntersect8(3): `valid` is 8 ints and `rayhit` one packet, both 32-byte aligned
    // by their types (`ValidMask8`'s repr(align(32)), bindgen's RTC_ALIGN(32); asserted in
    // layout.rs); both are live, exclusively borrowed for the call; the scene is committed and
    // kept alive by the caller's `&CommittedScene`.
    unsafe { sys::rtcIntersect8(valid.0.as_ptr(), scene, &mut ctx, rayhit) }
}

/// Closest hit for a 16-wide packet.
pub(crate) fn intersect16(
    scene: sys::RTCScene,
    valid: &ValidMask16,
    rayhit: &mut sys::RTCRayHit16,
    coherence: Coherence,
) {
    let mut ctx = intersect_context(coherence);
    // SAFETY: rtcIntersect16(3): as `intersect8`, with 16 lanes and 64-byte alignment, which
    // `ValidMask16` and bindgen's RTC_ALIGN(64) give by type (asserted in layout.rs).
    unsafe { sys::rtcIntersect16(valid.0.as_ptr(), scene, &mut ctx, rayhit) }
}

/// Occlusion for an 8-wide packet.
pub(crate) fn occluded8(scene: sys::RTCScene, valid: &ValidMask8, ray: &mut sys::RTCRay8) {
    let mut ctx = intersect_context(Coherence::Incoherent);
    // SAFETY: rtcOccluded8(3): as in `intersect8`, for the ray-only packet type (RTC_ALIGN(32)).
    unsafe { sys::rtcOccluded8(valid.0.as_ptr(), scene, &mut ctx, ray) }
}

/// Occlusion for a 16-wide packet.
pub(crate) fn occluded16(scene: sys::RTCScene, valid: &ValidMask16, ray: &mut sys::RTCRay16) {
    let mut ctx = intersect_context(Coherence::Incoherent);
    // SAFETY: rtcOccluded16(3): as in `intersect16`, for the ray-only packet type (RTC_ALIGN(64)).
    unsafe { sys::rtcOccluded16(valid.0.as_ptr(), scene, &mut ctx, ray) }
}
