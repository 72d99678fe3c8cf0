//! Core types shared by every module: colour, deterministic random numbers, sampling warps,
//! shading frames and robust ray offsets.
//!
//! Units: meters, radians. Colours are linear Rec.709 ([`Rgb`]). Random streams are keyed by
//! (seed, tick, pixel, sample) so results never depend on thread scheduling.
pub mod frame;
pub mod octahedral;
pub mod offset;
pub mod rgb;
pub mod rng;
pub mod sampling;

pub use frame::ShadingFrame;
pub use octahedral::PackedDir;
pub use offset::offset_ray_origin;
pub use rgb::Rgb;
pub use rng::Rng;
