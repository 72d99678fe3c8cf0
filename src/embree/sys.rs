//! Raw bindgen output for Embree 4 (`rtc*` functions, `RTC*` types and constants).
//! Nothing outside `src/embree/` uses these directly.
#![allow(non_upper_case_globals, non_camel_case_types, non_snake_case, dead_code, clippy::all)]
include!(concat!(env!("OUT_DIR"), "/embree_bindings.rs"));

/// `RTC_INVALID_GEOMETRY_ID` is `((unsigned int)-1)` in `rtcore_common.h`, a cast bindgen skips.
pub const RTC_INVALID_GEOMETRY_ID: u32 = u32::MAX;
