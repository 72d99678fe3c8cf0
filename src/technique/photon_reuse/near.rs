//! The photons one followed tick took out of the grid or put in, by cell, for the kept pixels'
//! splat (`pixels.rs`): a dense block of cells over their bounds, each cell's photons stored
//! together in the order given and their positions apart, so a pixel finds the cells around
//! its hit by index rather than by hashing, and its distance tests stream 12 bytes a photon.
//! On walker (1M paths, about 60k photons changed a tick) this took the splat from about 20 to
//! 14 ms a tick (`docs/benchmarks.md`).
//!
//! The splat asks for cells 2r wide: a pixel's query reaches r plus its footprint, about 2r
//! there, so it reads at most 3 × 3 × 3 cells; cells r wide measured no faster. A block that
//! would exceed [`MAX_CELLS`] (photons scattered far apart) doubles its cell width until it
//! fits, so its memory stays bounded; the answers do not depend on the width. Units: scene
//! units; signs are −1 for a photon taken out and +1 for one put in.
use super::cells::cell_of;
use super::grid::GridPhoton;
use glam::Vec3;

/// Most cells in the block (4 bytes each).
const MAX_CELLS: i64 = 1 << 21;

/// Signed photons by cell; see the module doc.
pub struct NearPhotons {
    inv_cell: f32,
    lo: [i32; 3],
    dims: [i32; 3],
    /// `starts[c]..starts[c + 1]`: the photons of cell c.
    starts: Vec<u32>,
    /// The photons' positions apart, so the distance tests stream 12 bytes a photon.
    positions: Vec<Vec3>,
    photons: Vec<(GridPhoton, f64)>,
}

impl NearPhotons {
    /// The index of `signed` in cells `width` wide (or wider, see the module doc); `None` when
    /// it is empty.
    pub fn new(signed: Vec<(GridPhoton, f64)>, width: f32) -> Option<NearPhotons> {
        if signed.is_empty() {
            return None;
        }
        let mut inv_cell = if width > 0.0 && width.is_finite() { 1.0 / width } else { 0.0 };
        loop {
            let cells: Vec<[i32; 3]> = signed.iter().map(|(p, _)| cell_of(p.position, inv_cell)).collect();
            let lo = cells.iter().fold([i32::MAX; 3], |a, c| std::array::from_fn(|k| a[k].min(c[k])));
            let hi = cells.iter().fold([i32::MIN; 3], |a, c| std::array::from_fn(|k| a[k].max(c[k])));
            let dims: [i32; 3] = std::array::from_fn(|k| hi[k] - lo[k] + 1);
            if dims.iter().map(|&d| i64::from(d)).product::<i64>() > MAX_CELLS {
                inv_cell *= 0.5;
                continue;
            }
            let mut near =
                NearPhotons { inv_cell, lo, dims, starts: Vec::new(), positions: Vec::new(), photons: Vec::new() };
            near.fill(signed, &cells);
            return Some(near);
        }
    }

    /// Orders the photons by cell (stably, so a cell keeps the given order) and marks where
    /// each cell's run starts.
    fn fill(&mut self, signed: Vec<(GridPhoton, f64)>, cells: &[[i32; 3]]) {
        let index: Vec<usize> = cells.iter().map(|&c| self.index(c)).collect();
        let mut starts = vec![0u32; (self.dims[0] * self.dims[1] * self.dims[2]) as usize + 1];
        for &i in &index {
            starts[i + 1] += 1;
        }
        for c in 1..starts.len() {
            starts[c] += starts[c - 1];
        }
        let mut order: Vec<usize> = (0..signed.len()).collect();
        order.sort_by_key(|&j| index[j]);
        self.photons = order.iter().map(|&j| signed[j]).collect();
        self.positions = self.photons.iter().map(|(p, _)| p.position).collect();
        self.starts = starts;
    }

    /// The cell at block coordinates `c` (within the block).
    fn index(&self, c: [i32; 3]) -> usize {
        let [x, y, z] = std::array::from_fn(|k| c[k] - self.lo[k]);
        ((z * self.dims[1] + y) * self.dims[0] + x) as usize
    }

    /// Calls `f` with the positions and photons of each cell the cube of half-side `reach`
    /// around `p` overlaps (a superset of the photons within `reach`; the caller tests the
    /// distance), cell by cell in z, y, x order.
    pub fn around(&self, p: Vec3, reach: f32, mut f: impl FnMut(&[Vec3], &[(GridPhoton, f64)])) {
        let (a, b) = (cell_of(p - Vec3::splat(reach), self.inv_cell), cell_of(p + Vec3::splat(reach), self.inv_cell));
        let lo: [i32; 3] = std::array::from_fn(|k| a[k].max(self.lo[k]));
        let hi: [i32; 3] = std::array::from_fn(|k| b[k].min(self.lo[k] + self.dims[k] - 1));
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let c = self.index([x, y, z]);
                    let run = self.starts[c] as usize..self.starts[c + 1] as usize;
                    if !run.is_empty() {
                        f(&self.positions[run.clone()], &self.photons[run]);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{Rgb, Rng};

    /// `n` photons spread over a cube `spread` wide, each photon's red power its index.
    fn scattered(n: usize, spread: f32, rng: &mut Rng) -> Vec<(GridPhoton, f64)> {
        (0..n)
            .map(|i| {
                let position = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * spread;
                let power = Rgb::new(i as f32, 0.0, 0.0);
                let photon = GridPhoton { position, facing: Vec3::Z, power, key: i as u32 };
                (photon, if i % 2 == 0 { 1.0 } else { -1.0 })
            })
            .collect()
    }

    #[test]
    fn around_hands_over_every_photon_within_reach() {
        // Property: the photons `around` hands over include every one within `reach` of the
        // query, checked by brute force, in a block of cells as wide as asked and in one so
        // spread out that its cells widen. Negative control (by hand): a block that starts one
        // cell late (`a[k].max(self.lo[k]) + 1`) misses photons.
        let mut rng = Rng::new(3, 4);
        for (spread, width) in [(10.0f32, 0.5f32), (1e4, 1e-2)] {
            let photons = scattered(400, spread, &mut rng);
            let near = NearPhotons::new(photons.clone(), width).expect("photons");
            assert_eq!(near.inv_cell < 1.0 / width, spread > 1e3, "cells widen only for the spread block");
            let mut found_any = 0;
            for k in 0..300 {
                let (q, reach) = if k % 2 == 0 {
                    (photons[k].0.position + Vec3::splat(0.3 * width), width * 2.0 * rng.next_f32())
                } else {
                    (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * spread, spread * 0.05)
                };
                let mut handed = Vec::new();
                near.around(q, reach, |_, ps| handed.extend(ps.iter().map(|(p, _)| p.key)));
                let within: Vec<u32> =
                    photons.iter().filter(|(p, _)| (p.position - q).length() <= reach).map(|(p, _)| p.key).collect();
                found_any += within.len();
                for key in &within {
                    assert!(handed.contains(key), "photon {key} within {reach} of {q:?} not handed over");
                }
            }
            assert!(found_any > 50, "too few photons near the queries to test: {found_any}");
        }
    }
}
