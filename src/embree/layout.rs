//! Types whose memory layout Embree's API dictates, with compile-time proofs.
//!
//! Embree's packet kernels load the valid mask and the ray/hit packet with aligned SIMD
//! instructions: `rtcIntersect8`/`rtcOccluded8` need 32-byte alignment and the 16-wide calls
//! 64-byte alignment (`rtcIntersect4/8/16(3)`, "the ray packet must be aligned to …"; Embree's
//! kernels read the valid mask the same way). A plain `[i32; W]` is only 4-byte aligned, so
//! whether it happens to land on a 32- or 64-byte boundary depends on the optimiser's stack
//! layout; that is how a release build once crashed in `rtcIntersect8` while every test passed.
//! Here alignment is a property of the type: the mask types below are `repr(align)`, the query
//! functions in `version.rs` take only these types, and the `const` assertions fail the build if
//! bindgen's packet structs ever lose their `RTC_ALIGN`.
use super::sys;
use std::mem::{align_of, size_of};

/// The valid mask of an 8-wide packet: `-1` for an active lane, `0` for an inactive one.
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct ValidMask8(pub [i32; 8]);

/// The valid mask of a 16-wide packet.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct ValidMask16(pub [i32; 16]);

impl ValidMask8 {
    pub(crate) fn from_active(active: &[bool; 8]) -> ValidMask8 {
        ValidMask8(active.map(lane))
    }
}

impl ValidMask16 {
    pub(crate) fn from_active(active: &[bool; 16]) -> ValidMask16 {
        ValidMask16(active.map(lane))
    }
}

fn lane(active: bool) -> i32 {
    if active {
        -1
    } else {
        0
    }
}

// Valid masks: aligned to the packet size, and exactly one i32 per lane.
const _: () = assert!(align_of::<ValidMask8>() >= 32 && size_of::<ValidMask8>() == 32);
const _: () = assert!(align_of::<ValidMask16>() >= 64 && size_of::<ValidMask16>() == 64);
// Packets: `RTC_ALIGN(32)` / `RTC_ALIGN(64)` in rtcore_ray.h.
const _: () = assert!(align_of::<sys::RTCRay8>() >= 32 && align_of::<sys::RTCRayHit8>() >= 32);
const _: () = assert!(align_of::<sys::RTCRay16>() >= 64 && align_of::<sys::RTCRayHit16>() >= 64);
// Single rays and hits: `RTC_ALIGN(16)` (`rtcIntersect1(3)`: "the ray must be aligned to 16 bytes").
const _: () = assert!(align_of::<sys::RTCRay>() >= 16 && align_of::<sys::RTCRayHit>() >= 16);
// `rtcGetSceneBounds(3)`: "the provided destination pointer must be aligned to 16 bytes".
const _: () = assert!(align_of::<sys::RTCBounds>() >= 16);
// The query arguments and context have no stated alignment beyond their fields' (they hold pointers).
const _: () = assert!(align_of::<sys::RTCIntersectArguments>() >= align_of::<usize>());
// One instance level: `Hit` reads `instID[0]`, and `query_context` in version.rs fills the stack.
const _: () = assert!(sys::RTC_MAX_INSTANCE_LEVEL_COUNT == 1);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_mark_active_lanes() {
        let mut active = [false; 16];
        active[3] = true;
        active[15] = true;
        let m = ValidMask16::from_active(&active);
        assert_eq!(m.0.iter().filter(|&&v| v == -1).count(), 2);
        assert_eq!((m.0[3], m.0[4], m.0[15]), (-1, 0, -1));
    }
}
