pub mod core;
pub mod embree;
pub mod engine;
pub mod film;
pub mod scene;
pub mod technique;
pub mod tools;
