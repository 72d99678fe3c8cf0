//! Embree-3-specific query calls.
//!
//! Embree 3 passes an `RTCIntersectContext` (initialised by the inline `rtcInitIntersectContext`,
//! which bindgen cannot emit) to every query; Embree 4 replaced it with per-call argument
//! structs. Everything that depends on that difference is in this file.
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
    // SAFETY: `scene` is a committed scene kept alive by the caller's `CommittedScene`;
    // `ctx` and `rayhit` are valid, exclusively borrowed, 16-byte aligned (bindgen's repr).
    unsafe { sys::rtcIntersect1(scene, &mut ctx, rayhit) }
}

/// Occlusion for one ray: on return `ray.tfar` is `-inf` if anything was hit.
pub(crate) fn occluded1(scene: sys::RTCScene, ray: &mut sys::RTCRay) {
    let mut ctx = intersect_context(Coherence::Incoherent);
    // SAFETY: as in `intersect1`; `ray` is a valid, aligned, exclusively borrowed RTCRay.
    unsafe { sys::rtcOccluded1(scene, &mut ctx, ray) }
}

/// Closest hit for an 8-wide packet; lanes with `valid[i] == 0` are ignored.
pub(crate) fn intersect8(scene: sys::RTCScene, valid: &[i32; 8], rayhit: &mut sys::RTCRayHit8, coherence: Coherence) {
    let mut ctx = intersect_context(coherence);
    // SAFETY: `valid` holds 8 ints as Embree requires; `rayhit` is 32-byte aligned by its
    // bindgen repr(align(32)); the scene is committed and kept alive by the caller.
    unsafe { sys::rtcIntersect8(valid.as_ptr(), scene, &mut ctx, rayhit) }
}

/// Closest hit for a 16-wide packet.
pub(crate) fn intersect16(
    scene: sys::RTCScene,
    valid: &[i32; 16],
    rayhit: &mut sys::RTCRayHit16,
    coherence: Coherence,
) {
    let mut ctx = intersect_context(coherence);
    // SAFETY: `valid` holds 16 ints; `rayhit` is 64-byte aligned by its bindgen
    // repr(align(64)); the scene is committed and kept alive by the caller.
    unsafe { sys::rtcIntersect16(valid.as_ptr(), scene, &mut ctx, rayhit) }
}

/// Occlusion for an 8-wide packet.
pub(crate) fn occluded8(scene: sys::RTCScene, valid: &[i32; 8], ray: &mut sys::RTCRay8) {
    let mut ctx = intersect_context(Coherence::Incoherent);
    // SAFETY: as in `intersect8`, for the ray-only packet type.
    unsafe { sys::rtcOccluded8(valid.as_ptr(), scene, &mut ctx, ray) }
}

/// Occlusion for a 16-wide packet.
pub(crate) fn occluded16(scene: sys::RTCScene, valid: &[i32; 16], ray: &mut sys::RTCRay16) {
    let mut ctx = intersect_context(Coherence::Incoherent);
    // SAFETY: as in `intersect16`, for the ray-only packet type.
    unsafe { sys::rtcOccluded16(valid.as_ptr(), scene, &mut ctx, ray) }
}
