//! Cell coordinates of the photon grid (`grid.rs`) and of the changed photons' index
//! (`near.rs`): a point's cell for a given cell side, a total order on cells, and a cheap hash
//! for maps keyed by them. Cells are cubes; coordinates are clamped to ±2²⁰ a side.
use glam::Vec3;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// A cheap hash for cell coordinates (the gather looks up to 27 per query).
#[derive(Default)]
pub struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        crate::core::rng::mix64(self.0)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x100_0000_01B3);
        }
    }
    fn write_i32(&mut self, v: i32) {
        self.0 = (self.0 ^ v as u32 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

/// A map keyed by cell coordinates, with the cheap hash.
pub type CellMap = HashMap<[i32; 3], u32, BuildHasherDefault<CellHasher>>;

/// A photon's cell, clamped to the ±2²⁰ cells a side that [`pack`] orders exactly.
pub fn cell_of(p: Vec3, inv_cell: f32) -> [i32; 3] {
    (p * inv_cell).floor().clamp(Vec3::splat(-CELL_LIMIT), Vec3::splat(CELL_LIMIT - 1.0)).as_ivec3().to_array()
}

const CELL_LIMIT: f32 = (1 << 20) as f32;

/// Cell coordinates as one integer with the same (x, y, z) lexicographic order.
pub fn pack(c: [i32; 3]) -> u64 {
    let field = |v: i32| (v + (1 << 20)) as u64 & ((1 << 21) - 1);
    (field(c[0]) << 42) | (field(c[1]) << 21) | field(c[2])
}
