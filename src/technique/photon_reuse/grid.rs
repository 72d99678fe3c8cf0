//! The photon grid: the photons a gather reads, bucketed by cell, kept across ticks and updated
//! in place for the paths that changed.
//!
//! It holds every stored photon from the second bounce on (row ≥ 1) that lies on a diffuse
//! surface (the first hit of a path is direct light, which NEE counts). Cells are cubes of side
//! r (the radius the grid is built with), so a gather of radius r visits at most 3×3×3 of them
//! and reads the photons of about (3r)² of a surface for the π r² it keeps, against (4r)² with
//! cells 2r wide and 2×2×2 visits: `bench reuse` measured a full render 24% faster with side r
//! than 2r, and slower with 1.5r or 0.7r (docs/benchmarks.md, stop 57). Only occupied cells
//! exist (a hash map from cell coordinates), so memory follows the photons, not the scene's
//! extent.
//!
//! Invariants, which make an updated grid equal to one built from scratch, photon for photon
//! and bit for bit in what it returns:
//! - a cell's photons are sorted by key (`path · B + row`), whatever order they arrived in;
//! - a cell's power is summed in that order, and the grid's power over cells in coordinate
//!   order, in f64;
//! - `home[key]` names the cell holding photon `key`, or [`NONE`].
//!
//! Units: positions in meters, power in watts.
use super::cells::{cell_of, pack, CellMap};
use super::store::PathStore;
use crate::core::Rgb;
use crate::scene::{Material, Normals, Scene, Transport};
use glam::{IVec3, Vec3};
use rayon::prelude::*;

/// Least cosine between a photon's surface normal and the query's for the photon to count.
const FACING_COSINE: f32 = 0.5;
/// `home` of a photon that is not in the grid.
const NONE: u32 = u32::MAX;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridPhoton {
    pub position: Vec3,
    /// The unit geometric normal of the photon's surface, on the side the photon arrived from.
    /// Gathering needs only this: the Lambertian BRDF is constant on a side, and a query only
    /// accepts photons whose surface faces the way its own does (see [`PhotonGrid::radiance`]).
    pub facing: Vec3,
    /// The photon's flux times its surface's shading factor for the direction it arrived from
    /// (`Normals::diffuse_factor`, 1 on flat-shaded meshes), which is all that shading normals
    /// change in a Lambertian density estimate.
    pub power: Rgb,
    /// `path · B + row`.
    pub(super) key: u32,
}

impl GridPhoton {
    /// This photon's term of the density estimate at `p` (unit normal `n`, on the side
    /// `n_side` facing `wo`): f_r·Φ if it lies within √`r2` on a surface facing the same way,
    /// else nothing. The estimate is Σ terms / (π r²); a gather and a splat share this.
    pub fn term(&self, material: &Material, p: Vec3, n: Vec3, wo: Vec3, n_side: Vec3, r2: f32) -> Option<Rgb> {
        self.counts(p, n_side, r2).then(|| self.value(material, n, wo))
    }

    /// Whether this photon has a term at `p` (see [`GridPhoton::term`]); without a branch.
    #[inline]
    fn counts(&self, p: Vec3, n_side: Vec3, r2: f32) -> bool {
        ((self.position - p).length_squared() <= r2) & (self.facing.dot(n_side) > FACING_COSINE)
    }

    /// The term of a photon that [`GridPhoton::counts`].
    #[inline]
    fn value(&self, material: &Material, n: Vec3, wo: Vec3) -> Rgb {
        material.eval(Normals::flat(n), wo, self.facing, Transport::Radiance) * self.power
    }
}

/// The photons one update took out of the grid and put in, for renders that splat them.
#[derive(Clone, Debug, Default)]
pub struct ChangedPhotons {
    pub removed: Vec<GridPhoton>,
    pub added: Vec<GridPhoton>,
}

/// Bytes the grid holds per photon (the photon, its place in `order` and `home`) and per
/// occupied cell (the cell and its index entry), as `memory_bytes` counts them.
pub const BYTES_PER_PHOTON: u64 = (std::mem::size_of::<GridPhoton>() + 8) as u64;
pub const BYTES_PER_CELL: u64 = (std::mem::size_of::<Cell>() + std::mem::size_of::<[i32; 3]>() + 4) as u64;

#[derive(Clone, Debug, Default, PartialEq)]
struct Cell {
    coord: [i32; 3],
    photons: Vec<GridPhoton>,
    power: [f64; 3],
}

impl Cell {
    /// Takes the photons with keys `out` (sorted) out and puts `ins` (sorted by key, none of
    /// them here) in, in place: the photons stay in key order. Returns the photons taken out.
    fn merge(&mut self, out: &[(u32, u32)], ins: &[(u32, GridPhoton)]) -> Vec<GridPhoton> {
        let mut removed = Vec::with_capacity(out.len());
        if !out.is_empty() {
            let mut gone = out.iter().map(|x| x.1).peekable();
            self.photons.retain(|p| {
                while gone.next_if(|&k| k < p.key).is_some() {}
                let goes = gone.next_if_eq(&p.key).is_some();
                if goes {
                    removed.push(*p);
                }
                !goes
            });
        }
        if let Some(&(_, first)) = ins.first() {
            // Merge from the back into the grown vector, so nothing moves twice.
            let kept = self.photons.len();
            // Exactly: the grid's memory follows its photons (a cell that lost as many as it
            // gains reuses the room).
            self.photons.reserve_exact(ins.len());
            self.photons.resize(kept + ins.len(), first);
            let (mut i, mut j) = (kept, ins.len());
            for w in (0..kept + ins.len()).rev() {
                if j == 0 {
                    break;
                }
                if i > 0 && self.photons[i - 1].key > ins[j - 1].1.key {
                    i -= 1;
                    self.photons[w] = self.photons[i];
                } else {
                    j -= 1;
                    self.photons[w] = ins[j].1;
                }
            }
        }
        self.sum_power();
        removed
    }

    fn sum_power(&mut self) {
        self.power = self.photons.iter().fold([0.0; 3], |s, p| add(s, p.power));
    }
}

fn add(s: [f64; 3], p: Rgb) -> [f64; 3] {
    [s[0] + p.r as f64, s[1] + p.g as f64, s[2] + p.b as f64]
}

/// `items` grouped by slot (all below `slots`), keeping their order within a slot: a counting
/// sort, linear in the items and the slots.
fn by_slot<T: Copy>(items: &[(u32, T)], slots: usize) -> Vec<(u32, T)> {
    let mut start = vec![0usize; slots + 1];
    for &(slot, _) in items {
        start[slot as usize + 1] += 1;
    }
    for s in 0..slots {
        start[s + 1] += start[s];
    }
    let mut out = items.to_vec();
    for &item in items {
        out[start[item.0 as usize]] = item;
        start[item.0 as usize] += 1;
    }
    out
}

/// One cell's share of an update: its slot, the keys leaving it and the photons entering it.
type CellChange<'a> = (u32, &'a [(u32, u32)], &'a [(u32, GridPhoton)]);

/// What one update touched: photons taken out and put in, and the cells they live in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GridUpdate {
    pub removed: u64,
    pub added: u64,
    pub cells_touched: u64,
}

/// Photons bucketed by cell; see the module doc.
#[derive(Clone, Debug, Default)]
pub struct PhotonGrid {
    pub radius: f32,
    /// 1 / the cell side (the radius the grid was built with).
    pub inv_cell: f32,
    /// B: photons per path, the stride of keys.
    rows: u32,
    index: CellMap,
    cells: Vec<Cell>,
    /// Cells in coordinate order, for the total power.
    order: Vec<u32>,
    home: Vec<u32>,
    /// Total flux of the gathered photons (W).
    pub power: [f64; 3],
    len: usize,
}

/// Photon `row` of `path` as the grid holds it, with its cell; `None` if the path has no such
/// photon or it lies on a specular surface.
fn photon_at(
    scene: &Scene,
    store: &PathStore,
    diffuse: &[bool],
    inv_cell: f32,
    path: usize,
    row_index: usize,
) -> Option<([i32; 3], GridPhoton)> {
    if !gathered(store, diffuse, path, row_index) {
        return None;
    }
    let row = &store.rows[row_index];
    let (object, prim) = store.surfaces.object_and_prim(row.surface[path]);
    let position = row.position[path];
    let normals = scene.normals_at(object, prim, position);
    let n = normals.geometric;
    let incoming = row.incoming[path].get();
    let photon = GridPhoton {
        position,
        facing: if n.dot(incoming) < 0.0 { n } else { -n },
        power: row.power[path] * normals.diffuse_factor(-incoming),
        key: (path * store.max_photons + row_index) as u32,
    };
    Some((cell_of(photon.position, inv_cell), photon))
}

/// Whether the grid holds photon `row` of `path`: the path has it, and it lies on a diffuse
/// surface (row 0, direct light, is left out by the callers, which start at row 1).
fn gathered(store: &PathStore, diffuse: &[bool], path: usize, row: usize) -> bool {
    row < store.word[path].photons() as usize && diffuse[store.surfaces.object(store.rows[row].surface[path]) as usize]
}

fn diffuse_objects(scene: &Scene) -> Vec<bool> {
    scene.objects.iter().map(|o| !scene.materials[o.material as usize].is_specular()).collect()
}

impl PhotonGrid {
    /// How many photons a grid built from the store holds, without building one: the gather
    /// radius is chosen from this count before the first build.
    pub fn count(scene: &Scene, store: &PathStore) -> usize {
        let diffuse = diffuse_objects(scene);
        (0..store.paths)
            .into_par_iter()
            .map(|path| (1..store.rows.len()).filter(|&row| gathered(store, &diffuse, path, row)).count())
            .sum()
    }

    /// Builds the grid from every path of the store: photons are made row by row (each row's
    /// arrays are read in order), sorted by (cell, key) and moved into their cells, all in
    /// parallel; the result does not depend on the thread count.
    pub fn build(scene: &Scene, store: &PathStore, radius: f32) -> PhotonGrid {
        let diffuse = diffuse_objects(scene);
        let inv_cell = 1.0 / radius;
        let mut all: Vec<GridPhoton> = Vec::new();
        for row in 1..store.rows.len() {
            all.par_extend(
                (0..store.paths)
                    .into_par_iter()
                    .filter_map(|path| photon_at(scene, store, &diffuse, inv_cell, path, row).map(|(_, p)| p)),
            );
        }
        // Sort by (cell, key): cell coordinates packed into one u64 in lexicographic order
        // (21 bits each, which any scene of fewer than a million cells a side fits), the key
        // next to it.
        let mut sorted: Vec<(u64, u32, u32)> =
            all.par_iter().enumerate().map(|(i, p)| (pack(cell_of(p.position, inv_cell)), p.key, i as u32)).collect();
        sorted.par_sort_unstable();
        // Runs of one cell each, then each cell's photons gathered in key order.
        let starts: Vec<usize> = (0..sorted.len())
            .into_par_iter()
            .filter(|&i| i == 0 || sorted[i].0 != sorted[i - 1].0)
            .chain(rayon::iter::once(sorted.len()))
            .collect();
        let cells: Vec<Cell> = starts
            .par_windows(2)
            .map(|w| {
                let run = &sorted[w[0]..w[1]];
                let mut cell = Cell {
                    coord: cell_of(all[run[0].2 as usize].position, inv_cell),
                    photons: run.iter().map(|&(_, _, i)| all[i as usize]).collect(),
                    power: [0.0; 3],
                };
                cell.sum_power();
                cell
            })
            .collect();
        let mut home = vec![NONE; store.paths * store.max_photons];
        for (slot, cell) in cells.iter().enumerate() {
            for p in &cell.photons {
                home[p.key as usize] = slot as u32;
            }
        }
        let index = cells.iter().enumerate().map(|(s, c)| (c.coord, s as u32)).collect();
        let mut grid = PhotonGrid {
            radius,
            inv_cell,
            rows: store.max_photons as u32,
            index,
            order: (0..cells.len() as u32).collect(),
            cells,
            home,
            len: all.len(),
            power: [0.0; 3],
        };
        grid.sum_power();
        grid
    }

    /// Replaces the photons of `paths` (ascending, no repeats) by what the store holds for them
    /// now, returning what it took out and put in. Costs time in proportion to those photons
    /// and the cells they touch, not to the grid.
    pub fn update(&mut self, scene: &Scene, store: &PathStore, paths: &[usize]) -> (GridUpdate, ChangedPhotons) {
        let diffuse = diffuse_objects(scene);
        let diffuse = diffuse.as_slice();
        let inv_cell = self.inv_cell;
        let rows = store.rows.len();
        let fresh: Vec<([i32; 3], GridPhoton)> = paths
            .par_iter()
            .flat_map_iter(|&path| {
                (1..rows).filter_map(move |row| photon_at(scene, store, diffuse, inv_cell, path, row))
            })
            .collect();
        // What leaves each cell (keys) and what enters it (photons), by cell slot: found in
        // parallel (reads of `home` and the cell index); only new cells are made in order.
        let keys = |path: usize| (path * self.rows as usize)..((path + 1) * self.rows as usize);
        let home = &self.home;
        let leaving: Vec<(u32, u32)> = paths
            .par_iter()
            .flat_map_iter(|&path| keys(path).filter(|&k| home[k] != NONE).map(|k| (home[k], k as u32)))
            .collect();
        let index = &self.index;
        let known: Vec<Option<u32>> = fresh.par_iter().map(|(coord, _)| index.get(coord).copied()).collect();
        for &path in paths {
            self.home[keys(path)].fill(NONE);
        }
        let mut entering: Vec<(u32, GridPhoton)> = Vec::with_capacity(fresh.len());
        let first_new_cell = self.cells.len();
        for ((coord, photon), known) in fresh.into_iter().zip(known) {
            let slot = known.unwrap_or_else(|| {
                let next = self.cells.len() as u32;
                let slot = *self.index.entry(coord).or_insert(next);
                if slot == next {
                    self.cells.push(Cell { coord, ..Cell::default() });
                }
                slot
            });
            self.home[photon.key as usize] = slot;
            entering.push((slot, photon));
        }
        let stats = GridUpdate { removed: leaving.len() as u64, added: entering.len() as u64, cells_touched: 0 };
        self.len = self.len + entering.len() - leaving.len();
        // Both lists arrive in key order (`paths` is sorted), so grouping them by slot stably
        // leaves each slot's share in key order.
        let (leaving, entering) = (by_slot(&leaving, self.cells.len()), by_slot(&entering, self.cells.len()));
        let (touched, removed) = self.merge_changes(&leaving, &entering);
        self.order_new_cells(first_new_cell);
        self.sum_power();
        let added = entering.into_iter().map(|(_, p)| p).collect();
        (GridUpdate { cells_touched: touched, ..stats }, ChangedPhotons { removed, added })
    }

    /// Applies sorted removals and insertions cell by cell, in parallel: each touched cell is
    /// merged in place ([`Cell::merge`]), keeping key order. Returns how many cells it touched and the
    /// photons it took out.
    fn merge_changes(&mut self, leaving: &[(u32, u32)], entering: &[(u32, GridPhoton)]) -> (u64, Vec<GridPhoton>) {
        let mut work: Vec<CellChange> = Vec::new();
        let (mut l, mut e) = (leaving, entering);
        while !l.is_empty() || !e.is_empty() {
            let slot = match (l.first(), e.first()) {
                (Some(a), Some(b)) => a.0.min(b.0),
                (Some(a), None) => a.0,
                (None, Some(b)) => b.0,
                (None, None) => break,
            };
            let nl = l.iter().take_while(|x| x.0 == slot).count();
            let ne = e.iter().take_while(|x| x.0 == slot).count();
            work.push((slot, &l[..nl], &e[..ne]));
            (l, e) = (&l[nl..], &e[ne..]);
        }
        let mut of_slot = vec![u32::MAX; self.cells.len()];
        for (w, (slot, _, _)) in work.iter().enumerate() {
            of_slot[*slot as usize] = w as u32;
        }
        let removed = self
            .cells
            .par_iter_mut()
            .enumerate()
            .filter(|(s, _)| of_slot[*s] != u32::MAX)
            .flat_map_iter(|(s, cell)| {
                let (_, out, ins) = work[of_slot[s] as usize];
                cell.merge(out, ins)
            })
            .collect();
        (work.len() as u64, removed)
    }

    /// Puts the cells from `first_new` on into `order`: they are sorted among themselves and
    /// appended, and the stable sort merges the two sorted runs in one pass (it finds runs), so
    /// the cost follows the new cells and one pass over `order`, not a sort of every cell.
    /// Coordinates are unique, so the order is the one a full sort gives.
    fn order_new_cells(&mut self, first_new: usize) {
        if first_new >= self.cells.len() {
            return;
        }
        let cells = &self.cells;
        let key = |s: &u32| pack(cells[*s as usize].coord);
        let mut new: Vec<u32> = (first_new as u32..cells.len() as u32).collect();
        new.sort_unstable_by_key(key);
        self.order.extend(new);
        self.order.sort_by_key(key);
    }

    fn sum_power(&mut self) {
        self.power = self.order.iter().fold([0.0; 3], |s, &c| {
            let p = self.cells[c as usize].power;
            [s[0] + p[0], s[1] + p[1], s[2] + p[2]]
        });
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Bytes held: the photons, the cells, the cell index and `home`.
    pub fn memory_bytes(&self) -> u64 {
        let photons: usize = self.cells.iter().map(|c| c.photons.capacity()).sum();
        (photons * std::mem::size_of::<GridPhoton>()
            + self.cells.capacity() * std::mem::size_of::<Cell>()
            + self.index.capacity() * (std::mem::size_of::<[i32; 3]>() + 4)
            + self.order.capacity() * 4
            + self.home.capacity() * 4) as u64
    }

    /// Each occupied cell's coordinates and photon keys, in coordinate order (for tests that
    /// compare an updated grid with a rebuilt one).
    pub fn cell_keys(&self) -> Vec<([i32; 3], Vec<u32>)> {
        self.order
            .iter()
            .map(|&s| &self.cells[s as usize])
            .filter(|c| !c.photons.is_empty())
            .map(|c| (c.coord, c.photons.iter().map(|p| p.key).collect()))
            .collect()
    }

    /// The kernel's normalisation: the estimate is Σ terms / (π r²).
    pub fn kernel_area(&self) -> f32 {
        std::f32::consts::PI * self.radius * self.radius
    }

    /// Σ of [`GridPhoton::term`] over the photons near `p` (unit normal `n`), seen from `wo`, in
    /// f64 so that splats added and taken away later stay within rounding of a fresh gather.
    pub fn gather_sum(&self, material: &Material, p: Vec3, n: Vec3, wo: Vec3) -> [f64; 3] {
        if self.len == 0 {
            return [0.0; 3];
        }
        let r2 = self.radius * self.radius;
        let lo = IVec3::from(cell_of(p - Vec3::splat(self.radius), self.inv_cell));
        let hi = IVec3::from(cell_of(p + Vec3::splat(self.radius), self.inv_cell));
        // Only photons on a surface facing the same way as this side of the query's: not the
        // other side of a thin wall, nor the inside face of a corner (a box seen from outside
        // would otherwise glow along its edges with the light inside it).
        let n_side = if n.dot(wo) >= 0.0 { n } else { -n };
        let mut sum = [0.0; 3];
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let Some(&slot) = self.index.get(&[x, y, z]) else { continue };
                    // Which photons count, 32 at a time without a branch (a branch per photon
                    // mispredicts), then their terms in order.
                    for photons in self.cells[slot as usize].photons.chunks(32) {
                        let mut counted = 0u32;
                        for (j, ph) in photons.iter().enumerate() {
                            counted |= u32::from(ph.counts(p, n_side, r2)) << j;
                        }
                        while counted != 0 {
                            sum = add(sum, photons[counted.trailing_zeros() as usize].value(material, n, wo));
                            counted &= counted - 1;
                        }
                    }
                }
            }
        }
        sum
    }

    /// Reflected radiance at `p` (unit normal `n`) towards `wo` from photons within the radius.
    pub fn radiance(&self, material: &Material, p: Vec3, n: Vec3, wo: Vec3) -> Rgb {
        let s = self.gather_sum(material, p, n, wo);
        let k = self.kernel_area() as f64;
        Rgb::new((s[0] / k) as f32, (s[1] / k) as f32, (s[2] / k) as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::{add, PhotonGrid};
    use crate::core::Rng;
    use crate::embree::Device;
    use crate::technique::photon_reuse::test_scenes::CornellRun;
    use crate::technique::photon_reuse::ReuseMode;
    use glam::Vec3;

    #[test]
    fn a_gather_sums_every_photon_within_its_radius() {
        // Property: a gather equals the sum of `GridPhoton::term` over every photon in the grid
        // (the same f32 terms in another order, summed in f64: equal up to rounding), at
        // queries on and beside the photons' surfaces, seen from either side. Negative control,
        // by hand: visiting one cell fewer per axis (`hi - 1` in `gather_sum`) fails it.
        let device = Device::new(2).expect("device");
        let mut run = CornellRun::new(&device, ReuseMode::Naive);
        run.update(0, 3);
        let (grid, scene) = (&run.technique.grid, &run.scene);
        let photons: Vec<_> = grid.cells.iter().flat_map(|c| &c.photons).collect();
        let material = scene.materials.iter().find(|m| !m.is_specular()).expect("a diffuse material");
        let r2 = grid.radius * grid.radius;
        let mut rng = Rng::new(11, 12);
        let mut lit = 0;
        for k in 0..300 {
            let at = photons[(rng.next_f32() * photons.len() as f32) as usize % photons.len()];
            let mut u = || rng.next_f32() - 0.5;
            let p = at.position + Vec3::new(u(), u(), u()) * (2.5 * grid.radius);
            let n = at.facing;
            let wo = ((if k % 3 == 0 { -n } else { n }) + Vec3::new(u(), u(), u())).normalize();
            let n_side = if n.dot(wo) >= 0.0 { n } else { -n };
            let brute = photons.iter().filter_map(|q| q.term(material, p, n, wo, n_side, r2)).fold([0.0; 3], add);
            let gathered = grid.gather_sum(material, p, n, wo);
            for c in 0..3 {
                let close = (gathered[c] - brute[c]).abs() <= 1e-9 * brute[c].abs().max(1e-6);
                assert!(close, "query {k} at {p:?}: gathered {gathered:?}, every photon {brute:?}");
            }
            lit += usize::from(brute[0] > 0.0);
        }
        assert!(lit > 100, "too few queries with photons near them: {lit} of 300");
    }

    #[test]
    fn the_count_that_picks_the_radius_is_the_photons_a_grid_holds() {
        // Property: `PhotonGrid::count`, which picks the first radius without building a grid,
        // equals the number of photons the built grid holds: after the first tick, and after
        // three ticks that move the block (and, at the third, the light), with paths of every
        // length. Negative control, by hand: counting from row 0 (direct light) fails it.
        let device = Device::new(2).expect("device");
        let mut run = CornellRun::new(&device, ReuseMode::Error);
        for tick in 0..4 {
            run.update(tick, 3);
            let store = run.technique.store.as_ref().expect("a store");
            let built = PhotonGrid::build(&run.scene, store, run.technique.grid.radius);
            assert!(built.len() > 1000, "too few photons to tell: {}", built.len());
            assert_eq!(PhotonGrid::count(&run.scene, store), built.len(), "after tick {tick}");
        }
    }

    #[test]
    fn an_updated_grid_equals_a_rebuilt_one() {
        // Property: after every tick of an animation that moves an object and an area light,
        // the grid updated in place holds the same photons in the same cells, in the same
        // order, with the same total power bit for bit, as one built from scratch from the
        // store; and the update touched far fewer photons than the grid holds.
        let device = Device::new(2).expect("device");
        for reuse in [ReuseMode::Naive, ReuseMode::Error] {
            let mut run = CornellRun::new(&device, reuse);
            let mut updated = 0;
            for tick in 0..8u32 {
                let p: crate::technique::photon_reuse::PhotonStats = run.update(tick, 3).take();
                let technique = &run.technique;
                let store = technique.store.as_ref().expect("store");
                let grid = &technique.grid;
                let rebuilt = PhotonGrid::build(&run.scene, store, grid.radius);
                assert_eq!(grid.len(), rebuilt.len(), "{reuse:?} tick {tick}");
                assert!(grid.cell_keys() == rebuilt.cell_keys(), "{reuse:?} tick {tick}: cells differ");
                assert_eq!(grid.power, rebuilt.power, "{reuse:?} tick {tick}");
                if tick > 0 && !p.grid_rebuilt {
                    updated += 1;
                    assert!(p.grid_added + p.grid_removed < grid.len() as u64, "{reuse:?} tick {tick}: {p:?}");
                    assert!(p.grid_cells_touched > 0, "an update that changed photons touched no cell: {p:?}");
                }
            }
            assert!(updated >= 4, "{reuse:?}: the grid was rebuilt instead of updated ({updated} updates)");
        }
    }
}
