//! relume: dynamic global illumination with resident light transport.
//!
//! # Module map (dependencies point down)
//! - [`tools`]: command-line tools (serve, render, bench); binaries' code, uses `anyhow`.
//! - [`server`]: axum HTTP + WebSocket over the engine; never touches Embree.
//! - [`engine`]: [`engine::Session`] owns a scene, its Embree scenes, a technique and a film, and
//!   runs the tick pipeline drain → apply → commit → update → render → resolve.
//! - [`technique`]: the [`technique::Technique`] trait, [`technique::TechniqueConfig`] and the
//!   techniques (`path`, ...).
//! - [`film`]: accumulation, resolve, encoding.
//! - [`scene`]: the scene model, loading and validation, animations, edits, and the two-level
//!   Embree acceleration structure.
//! - [`embree`]: a safe wrapper over Intel Embree 4, and the only module with FFI code.
//! - [`core`]: colour, random numbers, sampling, frames, robust ray offsets.
//!
//! # Conventions
//! - Units: meters, seconds, radians; degrees only in fields named `*_deg`. (The Cornell box
//!   keeps its published millimetre numbers as scene units; radiance is scale-invariant.)
//! - Right-handed, +Y up; the camera looks down −Z. Transforms are `world_from_object`, TRS with a
//!   unit quaternion `[x, y, z, w]`. Directions `wi`, `wo` point away from the surface.
//! - Colour: [`core::Rgb`], linear Rec.709, scene-referred. sRGB only when encoding 8-bit images.
//! - Radiometry as pbrt-v4: point/spot intensity in W/sr, area radiance in W/(sr·m²), power in W.
pub mod core;
pub mod embree;
pub mod engine;
pub mod film;
pub mod scene;
pub mod server;
pub mod technique;
pub mod tools;
