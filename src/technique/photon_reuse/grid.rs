//! The photon grid: the photons a gather reads, bucketed by cell, kept across ticks and updated
//! in place for the paths that changed.
//!
//! It holds every stored photon from the second bounce on (row ≥ 1) that lies on a diffuse
//! surface (the first hit of a path is direct light, which NEE counts). Cells are cubes of side
//! 2r, so a gather of radius r visits at most 2×2×2 of them; only occupied cells exist (a hash
//! map from cell coordinates), so memory follows the photons, not the scene's extent.
//!
//! Invariants, which make an updated grid equal to one built from scratch, photon for photon
//! and bit for bit in what it returns:
//! - a cell's photons are sorted by key (`path · B + row`), whatever order they arrived in;
//! - a cell's power is summed in that order, and the grid's power over cells in coordinate
//!   order, in f64;
//! - `home[key]` names the cell holding photon `key`, or [`NONE`].
//!
//! Units: positions in meters, power in watts.
use super::store::PathStore;
use crate::core::Rgb;
use crate::scene::{Material, Scene, SurfaceId};
use glam::{IVec3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Least cosine between a photon's surface normal and the query's for the photon to count.
const FACING_COSINE: f32 = 0.5;
/// `home` of a photon that is not in the grid.
const NONE: u32 = u32::MAX;

#[derive(Clone, Copy, Debug, PartialEq)]
struct GridPhoton {
    position: Vec3,
    /// The unit geometric normal of the photon's surface, on the side the photon arrived from.
    /// Gathering needs only this: the Lambertian BRDF is constant on a side, and a query only
    /// accepts photons whose surface faces the way its own does (see [`PhotonGrid::radiance`]).
    facing: Vec3,
    power: Rgb,
    /// `path · B + row`.
    key: u32,
}

#[derive(Clone, Debug, Default, PartialEq)]
struct Cell {
    coord: [i32; 3],
    photons: Vec<GridPhoton>,
    power: [f64; 3],
}

impl Cell {
    fn sum_power(&mut self) {
        self.power = self.photons.iter().fold([0.0; 3], |s, p| add(s, p.power));
    }
}

fn add(s: [f64; 3], p: Rgb) -> [f64; 3] {
    [s[0] + p.r as f64, s[1] + p.g as f64, s[2] + p.b as f64]
}

/// A cheap hash for cell coordinates (the gather looks up eight per query).
#[derive(Default)]
struct CellHasher(u64);

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

type CellMap = HashMap<[i32; 3], u32, BuildHasherDefault<CellHasher>>;

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
    inv_cell: f32,
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
    if row_index >= store.word[path].photons() as usize {
        return None;
    }
    let row = &store.rows[row_index];
    if !diffuse[row.object[path] as usize] {
        return None;
    }
    let [a, b, c] = scene.triangle(SurfaceId::Object(row.object[path]), row.prim[path]);
    let n = (b - a).cross(c - a).normalize_or_zero();
    let incoming = row.incoming[path];
    let photon = GridPhoton {
        position: row.position[path],
        facing: if n.dot(incoming) < 0.0 { n } else { -n },
        power: row.power[path],
        key: (path * store.max_photons + row_index) as u32,
    };
    Some((cell_of(photon.position, inv_cell), photon))
}

/// A photon's cell, clamped to the ±2²⁰ cells a side that [`pack`] orders exactly.
fn cell_of(p: Vec3, inv_cell: f32) -> [i32; 3] {
    (p * inv_cell).floor().clamp(Vec3::splat(-CELL_LIMIT), Vec3::splat(CELL_LIMIT - 1.0)).as_ivec3().to_array()
}

const CELL_LIMIT: f32 = (1 << 20) as f32;

/// Cell coordinates as one integer with the same (x, y, z) lexicographic order.
fn pack(c: [i32; 3]) -> u64 {
    let field = |v: i32| (v + (1 << 20)) as u64 & ((1 << 21) - 1);
    (field(c[0]) << 42) | (field(c[1]) << 21) | field(c[2])
}

fn diffuse_objects(scene: &Scene) -> Vec<bool> {
    scene.objects.iter().map(|o| !scene.materials[o.material as usize].is_specular()).collect()
}

impl PhotonGrid {
    /// Builds the grid from every path of the store: photons are made row by row (each row's
    /// arrays are read in order), sorted by (cell, key) and moved into their cells, all in
    /// parallel; the result does not depend on the thread count.
    pub fn build(scene: &Scene, store: &PathStore, radius: f32) -> PhotonGrid {
        let diffuse = diffuse_objects(scene);
        let inv_cell = 1.0 / (2.0 * radius);
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
    /// now. Costs time in proportion to those photons and the cells they touch, not to the grid.
    pub fn update(&mut self, scene: &Scene, store: &PathStore, paths: &[usize]) -> GridUpdate {
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
        // What leaves each cell (keys) and what enters it (photons), by cell slot.
        let mut leaving: Vec<(u32, u32)> = Vec::new();
        for &path in paths {
            for key in (path * self.rows as usize)..((path + 1) * self.rows as usize) {
                let slot = std::mem::replace(&mut self.home[key], NONE);
                if slot != NONE {
                    leaving.push((slot, key as u32));
                }
            }
        }
        let mut entering: Vec<(u32, GridPhoton)> = Vec::with_capacity(fresh.len());
        let mut new_cells = false;
        for (coord, photon) in fresh {
            let next = self.cells.len() as u32;
            let slot = *self.index.entry(coord).or_insert(next);
            if slot == next {
                self.cells.push(Cell { coord, ..Cell::default() });
                new_cells = true;
            }
            self.home[photon.key as usize] = slot;
            entering.push((slot, photon));
        }
        let stats = GridUpdate { removed: leaving.len() as u64, added: entering.len() as u64, cells_touched: 0 };
        self.len = self.len + entering.len() - leaving.len();
        // Both lists are in key order within a slot once sorted by slot (stably).
        leaving.par_sort_by_key(|&(slot, _)| slot);
        entering.par_sort_by_key(|&(slot, _)| slot);
        let touched = self.merge_changes(&leaving, &entering);
        if new_cells {
            self.sort_order();
        }
        self.sum_power();
        GridUpdate { cells_touched: touched, ..stats }
    }

    /// Applies sorted removals and insertions cell by cell, in parallel: each touched cell is
    /// merged in one pass, keeping key order. Returns how many cells it touched.
    fn merge_changes(&mut self, leaving: &[(u32, u32)], entering: &[(u32, GridPhoton)]) -> u64 {
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
        self.cells.par_iter_mut().enumerate().filter(|(s, _)| of_slot[*s] != u32::MAX).for_each(|(s, cell)| {
            let (_, out, ins) = work[of_slot[s] as usize];
            let mut gone = out.iter().map(|x| x.1).peekable();
            let mut coming = ins.iter().map(|x| x.1).peekable();
            let mut merged = Vec::with_capacity(cell.photons.len() + ins.len());
            for p in cell.photons.drain(..) {
                while gone.next_if(|&k| k < p.key).is_some() {}
                if gone.next_if_eq(&p.key).is_some() {
                    continue;
                }
                while let Some(c) = coming.next_if(|c| c.key < p.key) {
                    merged.push(c);
                }
                merged.push(p);
            }
            merged.extend(coming);
            cell.photons = merged;
            cell.sum_power();
        });
        work.len() as u64
    }

    fn sort_order(&mut self) {
        let cells = &self.cells;
        self.order = (0..cells.len() as u32).collect();
        self.order.par_sort_unstable_by_key(|&s| pack(cells[s as usize].coord));
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

    /// Reflected radiance at `p` (unit normal `n`) towards `wo` from photons within the radius.
    pub fn radiance(&self, material: &Material, p: Vec3, n: Vec3, wo: Vec3) -> Rgb {
        if self.len == 0 {
            return Rgb::BLACK;
        }
        let r2 = self.radius * self.radius;
        let lo = IVec3::from(cell_of(p - Vec3::splat(self.radius), self.inv_cell));
        let hi = IVec3::from(cell_of(p + Vec3::splat(self.radius), self.inv_cell));
        // Only photons on a surface facing the same way as this side of the query's: not the
        // other side of a thin wall, nor the inside face of a corner (a box seen from outside
        // would otherwise glow along its edges with the light inside it).
        let n_side = if n.dot(wo) >= 0.0 { n } else { -n };
        let mut sum = Rgb::BLACK;
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let Some(&slot) = self.index.get(&[x, y, z]) else { continue };
                    for ph in &self.cells[slot as usize].photons {
                        if (ph.position - p).length_squared() <= r2 && ph.facing.dot(n_side) > FACING_COSINE {
                            sum += material.eval(n, wo, ph.facing) * ph.power;
                        }
                    }
                }
            }
        }
        sum / (std::f32::consts::PI * r2)
    }
}

#[cfg(test)]
mod tests {
    use super::PhotonGrid;
    use crate::embree::Device;
    use crate::scene::edits::{self, Edit, SceneDelta};
    use crate::scene::{Scene, SceneAccel, Trs};
    use crate::technique::photon_reuse::{PhotonReuse, PhotonReuseConfig, ReuseMode};
    use crate::technique::{RenderContext, Technique};
    use std::path::Path;

    /// The Cornell box at 16² with its short block and its light dynamic.
    fn cornell() -> Scene {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        let text = std::fs::read_to_string(root.join("cornell-box.json")).expect("bundled scene");
        let mut desc: crate::scene::SceneDesc = serde_json::from_str(&text).expect("scene JSON");
        for o in desc.objects.iter_mut().filter(|o| o.name == "short-block") {
            o.dynamic = true;
        }
        for l in &mut desc.lights {
            l.dynamic = true;
        }
        desc.camera.resolution = [16, 16];
        Scene::from_desc(desc, &root, &root).expect("valid scene")
    }

    /// Tick `tick`'s edit: the block slides; every third tick the light moves and tilts too (a
    /// tilt rescales the flux of the paths it keeps).
    fn edits_at(scene: &Scene, tick: u32) -> Vec<Edit> {
        let block = &scene.desc().objects[scene.object_index("short-block").expect("block")];
        let mut edits = vec![Edit::Object {
            name: "short-block".into(),
            transform: Trs { translation: [-12.0 * tick as f32, 0.0, 8.0 * tick as f32], ..block.transform },
        }];
        if tick % 3 == 0 {
            let light = &scene.desc().lights[0];
            let t = light.transform.translation;
            let tilt = glam::Quat::from_rotation_x(0.15) * glam::Quat::from_array(light.transform.rotation);
            edits.push(Edit::Light {
                name: light.name.clone(),
                transform: Some(Trs {
                    translation: [t[0] + 5.0, t[1], t[2] - 5.0],
                    rotation: tilt.to_array(),
                    ..light.transform
                }),
                emitter: None,
            });
        }
        edits
    }

    #[test]
    fn an_updated_grid_equals_a_rebuilt_one() {
        // Property: after every tick of an animation that moves an object and an area light,
        // the grid updated in place holds the same photons in the same cells, in the same
        // order, with the same total power bit for bit, as one built from scratch from the
        // store; and the update touched far fewer photons than the grid holds.
        let device = Device::new(2).expect("device");
        for reuse in [ReuseMode::Naive, ReuseMode::Error] {
            let mut scene = cornell();
            let mut accel = SceneAccel::build(&device, &scene).expect("accel");
            let config = PhotonReuseConfig { paths: 20_000, reuse, ..PhotonReuseConfig::default() };
            let mut technique = PhotonReuse::new(config, &scene).expect("technique");
            let mut updated = 0;
            for tick in 0..8u32 {
                let delta = if tick == 0 {
                    SceneDelta::default()
                } else {
                    let batch = edits_at(&scene, tick);
                    edits::apply(&mut scene, batch).expect("valid edits")
                };
                let moved: Vec<_> = delta.moved.iter().map(|m| m.surface).collect();
                accel.update_instances(&scene, &moved).expect("commit");
                let ctx = RenderContext { scene: &scene, accel: &accel, seed: 3, tick: tick as u64 };
                technique.update(&ctx, &delta).expect("update");
                let store = technique.store.as_ref().expect("store");
                let grid = &technique.grid;
                let rebuilt = PhotonGrid::build(&scene, store, grid.radius);
                assert_eq!(grid.len(), rebuilt.len(), "{reuse:?} tick {tick}");
                assert!(grid.cell_keys() == rebuilt.cell_keys(), "{reuse:?} tick {tick}: cells differ");
                assert_eq!(grid.power, rebuilt.power, "{reuse:?} tick {tick}");
                let p = &technique.pending;
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
