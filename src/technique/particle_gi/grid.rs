//! Nearest-particle lookups: a hash grid over a set of area particles, and one such grid per
//! object and side ([`ObjectGrids`]).
//!
//! A link's end and an estimation list only ever take particles of one object and side (the
//! hit's object and the side the hit faces, or the radiance particle's own), so each
//! (object, side) gets its own grid: a query looks at no particle it must reject, and a moved
//! or rescaled object rebuilds only its own two grids. Side 0 holds the particles with the
//! winding normal (even indices), side 1 the others. Grids are in world space, built from the
//! particles' current positions, so a rebuild and an incremental update hold the same grids.
//! Units: metres.
use super::particles::AreaParticles;
use glam::Vec3;

/// Bytes per particle a grid holds at most: its index, and up to four hash slots.
pub const BYTES_PER_PARTICLE: u64 = 4 + 4 * 4;
/// Bytes of an empty grid (one slot and the end of the starts).
pub const BYTES_PER_GRID: u64 = 8;

/// A hash grid over some particles' positions for nearest-particle queries.
#[derive(Clone, Debug, Default)]
pub struct ParticleGrid {
    cell: f32,
    /// Particle indices sorted by cell slot, and where each slot's run starts.
    starts: Vec<u32>,
    indices: Vec<u32>,
    /// The least and greatest cell holding a particle: cells beyond are empty, though their
    /// slots may not be.
    lo: [i32; 3],
    hi: [i32; 3],
}

fn cell_of(p: Vec3, cell: f32) -> [i32; 3] {
    let c = (p / cell).floor();
    [c.x as i32, c.y as i32, c.z as i32]
}

impl ParticleGrid {
    /// A grid of cells `cell` metres wide over the particles `members` (indices into
    /// `particles`, in the order their runs keep).
    pub fn build(particles: &AreaParticles, members: &[u32], cell: f32) -> ParticleGrid {
        let slots = (members.len().max(1) * 2).next_power_of_two();
        let slot_of = |i: u32| slot(cell_of(particles.position[i as usize], cell), slots);
        let (mut lo, mut hi) = ([i32::MAX; 3], [i32::MIN; 3]);
        let mut starts = vec![0u32; slots + 1];
        for &i in members {
            let c = cell_of(particles.position[i as usize], cell);
            for a in 0..3 {
                (lo[a], hi[a]) = (lo[a].min(c[a]), hi[a].max(c[a]));
            }
            starts[slot_of(i) + 1] += 1;
        }
        for s in 0..slots {
            starts[s + 1] += starts[s];
        }
        let mut fill = starts.clone();
        let mut indices = vec![0u32; members.len()];
        for &i in members {
            let s = slot_of(i);
            indices[fill[s] as usize] = i;
            fill[s] += 1;
        }
        ParticleGrid { cell, starts, indices, lo, hi }
    }

    /// The particle nearest `p` among those with `accept(i)`, searched in growing shells of
    /// cells up to `max_rings` (or until the shells cover every occupied cell); ties go to the
    /// lower index, so the answer depends only on the accepted particles' positions.
    pub fn nearest(
        &self,
        particles: &AreaParticles,
        p: Vec3,
        max_rings: i32,
        accept: impl Fn(usize) -> bool,
    ) -> Option<u32> {
        if self.indices.is_empty() {
            return None;
        }
        let c = cell_of(p, self.cell);
        let mut best: Option<(f32, u32)> = None;
        for ring in 0..=max_rings {
            self.shell(c, ring, |cell| {
                // Skip cells farther than the best so far.
                let lo = Vec3::new(cell[0] as f32, cell[1] as f32, cell[2] as f32) * self.cell;
                let gap = (lo - p).max(p - lo - Vec3::splat(self.cell)).max(Vec3::ZERO).length_squared();
                if best.is_some_and(|(d, _)| gap > d) {
                    return;
                }
                for &i in self.run(cell) {
                    if !accept(i as usize) {
                        continue;
                    }
                    let d = (particles.position[i as usize] - p).length_squared();
                    if best.is_none_or(|(bd, bi)| d < bd || (d == bd && i < bi)) {
                        best = Some((d, i));
                    }
                }
            });
            // Everything closer to p than the searched block's nearest face has been seen, and
            // a block covering every occupied cell has seen everything.
            let lo = (Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) - Vec3::splat(ring as f32)) * self.cell;
            let hi = lo + Vec3::splat((2 * ring + 1) as f32 * self.cell);
            let seen = (p - lo).min(hi - p).min_element();
            let covered = (0..3).all(|a| c[a] - ring <= self.lo[a] && c[a] + ring >= self.hi[a]);
            if covered || best.is_some_and(|(d, _)| d <= seen * seen) {
                break;
            }
        }
        best.map(|(_, i)| i)
    }

    /// Calls `f` with each occupied-range cell at Chebyshev distance `ring` from cell `c`.
    fn shell(&self, c: [i32; 3], ring: i32, mut f: impl FnMut([i32; 3])) {
        let lo: [i32; 3] = std::array::from_fn(|a| (c[a] - ring).max(self.lo[a]));
        let hi: [i32; 3] = std::array::from_fn(|a| (c[a] + ring).min(self.hi[a]));
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                if (x - c[0]).abs() < ring && (y - c[1]).abs() < ring {
                    // Inside the shell in x and y: only its two z faces.
                    for z in [c[2] - ring, c[2] + ring] {
                        if (lo[2]..=hi[2]).contains(&z) {
                            f([x, y, z]);
                        }
                    }
                } else {
                    (lo[2]..=hi[2]).for_each(|z| f([x, y, z]));
                }
            }
        }
    }

    /// The particles in `cell`'s hash slot (a superset of the cell's).
    fn run(&self, cell: [i32; 3]) -> &[u32] {
        let s = slot(cell, self.starts.len() - 1);
        &self.indices[self.starts[s] as usize..self.starts[s + 1] as usize]
    }

    /// Calls `f` with every particle within `r` of `p` (a superset: the caller tests).
    pub fn within(&self, p: Vec3, r: f32, mut f: impl FnMut(u32)) {
        if self.indices.is_empty() {
            return;
        }
        let (lo, hi) = (cell_of(p - Vec3::splat(r), self.cell), cell_of(p + Vec3::splat(r), self.cell));
        let lo: [i32; 3] = std::array::from_fn(|a| lo[a].max(self.lo[a]));
        let hi: [i32; 3] = std::array::from_fn(|a| hi[a].min(self.hi[a]));
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    self.run([x, y, z]).iter().for_each(|&i| f(i));
                }
            }
        }
    }

    pub fn memory_bytes(&self) -> u64 {
        ((self.starts.len() + self.indices.len()) * 4) as u64
    }
}

/// Hash slot of a cell (Teschner et al.'s spatial hash).
fn slot(c: [i32; 3], slots: usize) -> usize {
    let h = (c[0] as u32).wrapping_mul(73_856_093)
        ^ (c[1] as u32).wrapping_mul(19_349_663)
        ^ (c[2] as u32).wrapping_mul(83_492_791);
    h as usize & (slots - 1)
}

/// One [`ParticleGrid`] per object and side, all with the same cell width.
#[derive(Clone, Debug, Default)]
pub struct ObjectGrids {
    cell: f32,
    grids: Vec<[ParticleGrid; 2]>,
}

impl ObjectGrids {
    /// Grids of cells `cell` metres wide for each of `objects` objects' particles.
    pub fn build(particles: &AreaParticles, objects: usize, cell: f32) -> ObjectGrids {
        let mut grids = ObjectGrids { cell, grids: vec![Default::default(); objects] };
        for object in 0..objects {
            grids.rebuild(particles, object);
        }
        grids
    }

    /// Rebuilds `object`'s two grids from its particles' current positions.
    pub fn rebuild(&mut self, particles: &AreaParticles, object: usize) {
        let range = particles.range_of(object);
        let side = |s: usize| -> Vec<u32> { range.clone().filter(|i| i % 2 == s).map(|i| i as u32).collect() };
        self.grids[object] = [0, 1].map(|s| ParticleGrid::build(particles, &side(s), self.cell));
    }

    /// The grid of `object`'s particles on `side` (0: the winding normal's).
    pub fn side(&self, object: usize, side: usize) -> &ParticleGrid {
        &self.grids[object][side]
    }

    pub fn memory_bytes(&self) -> u64 {
        self.grids.iter().flatten().map(ParticleGrid::memory_bytes).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::Rng;

    /// Two clusters far apart (one of three particles, like a small object's), and queries
    /// near them, between them and far outside.
    #[test]
    fn nearest_and_within_match_brute_force() {
        let mut rng = Rng::new(7, 0);
        let mut particles = AreaParticles::default();
        for k in 0..403 {
            let centre = if k < 400 { Vec3::ZERO } else { Vec3::new(9.0, 1.0, -4.0) };
            particles.position.push(centre + (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * 3.0);
        }
        let members: Vec<u32> = (0..particles.len() as u32).collect();
        let grid = ParticleGrid::build(&particles, &members, 0.25);
        let accept = |i: usize| i % 3 != 0;
        let mut far = 0;
        for _ in 0..2000 {
            let p = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.3) * 16.0;
            let brute = (0..particles.len() as u32).filter(|&i| accept(i as usize)).min_by(|&a, &b| {
                let (da, db) = (
                    (particles.position[a as usize] - p).length_squared(),
                    (particles.position[b as usize] - p).length_squared(),
                );
                da.total_cmp(&db).then(a.cmp(&b))
            });
            assert_eq!(grid.nearest(&particles, p, 1 << 12, accept), brute, "query {p}");
            far += usize::from(cell_of(p, 0.25).iter().zip(&grid.hi).any(|(c, h)| c > h));
            let r = 0.6;
            let mut found = Vec::new();
            grid.within(p, r, |i| found.push(i));
            let near = (0..particles.len() as u32).filter(|&i| (particles.position[i as usize] - p).length() <= r);
            assert!(near.into_iter().all(|i| found.contains(&i)), "within misses a particle near {p}");
        }
        assert!(far > 100, "too few queries outside the occupied cells: {far}");
    }
}
