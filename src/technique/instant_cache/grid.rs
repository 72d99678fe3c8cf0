//! A uniform grid over cache records for "which records lie within r of x" (the flat
//! grid in place of Ward et al.'s octree). Every record reaches the same distance r (a·D), so
//! every record within r of x lies in the cells the cube [x − r, x + r] overlaps: with cells at
//! least r wide, at most 3 × 3 × 3 of them (2 × 2 × 2 only if they were 2r wide, which would
//! read more records per query on average: the cube overlaps 2r/w + 1 cells per axis). A query
//! reads those cells' records and nothing else. `bench icache` measured cells r/2 and r/3
//! wide slower (more cells to visit), and 1.5r and 2r within noise of r.
//!
//! The grid spans the scene's first bounds, at most [`MAX_CELLS`] cells per axis; a point
//! outside falls into the nearest border cell. Clamping is monotone, so a record within r of x
//! still lies in a cell the query's (clamped) range covers. The same cells ([`Cells`]) mark
//! where a tick's new records reach (`pixels.rs`). Units: scene units.
use glam::Vec3;

/// Most cells per axis: a tiny radius gives wider cells, never a huge grid.
pub const MAX_CELLS: f32 = 32.0;
/// Bytes of the empty grid at most (one vector header per cell).
pub const MAX_EMPTY_BYTES: u64 = (MAX_CELLS * MAX_CELLS * MAX_CELLS) as u64 * std::mem::size_of::<Vec<u8>>() as u64;

/// A uniform division of a box into cells at least a given width (at most [`MAX_CELLS`] per
/// axis), with points outside clamped into the border cells.
#[derive(Clone, Debug)]
pub struct Cells {
    lo: Vec3,
    cell: Vec3,
    pub dims: [i32; 3],
}

impl Cells {
    /// Cells over the box `(lo, hi)`, each at least `width` wide (one cell on an axis shorter).
    pub fn new(lo: Vec3, hi: Vec3, width: f32) -> Cells {
        let size = (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
        // Rounded down, so cells are at least `width` wide.
        let dims = (size / width.max(f32::MIN_POSITIVE)).floor().clamp(Vec3::ONE, Vec3::splat(MAX_CELLS));
        Cells { lo, cell: size / dims, dims: [dims.x as i32, dims.y as i32, dims.z as i32] }
    }

    pub fn len(&self) -> usize {
        (self.dims[0] * self.dims[1] * self.dims[2]) as usize
    }

    /// The cell of `p`, clamped into the grid (monotone in each coordinate). Clamping before
    /// the cast makes truncation a floor (the baseline x86-64 has no rounding instruction, and
    /// `floor` costs a libm call); NaN falls into cell 0.
    pub fn cell_of(&self, p: Vec3) -> [i32; 3] {
        let c = (p - self.lo) / self.cell;
        let clamp = |v: f32, n: i32| v.max(0.0).min((n - 1) as f32) as i32;
        [clamp(c.x, self.dims[0]), clamp(c.y, self.dims[1]), clamp(c.z, self.dims[2])]
    }

    pub fn index(&self, c: [i32; 3]) -> usize {
        ((c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]) as usize
    }
}

/// Items of type `T` (kept inline, so a query reads them without chasing indices) by position.
#[derive(Clone, Debug)]
pub struct RecordGrid<T> {
    cells: Cells,
    items: Vec<Vec<T>>,
}

impl<T: Copy> RecordGrid<T> {
    /// An empty grid over the box `(lo, hi)` for query radius `r`.
    pub fn new(lo: Vec3, hi: Vec3, r: f32) -> RecordGrid<T> {
        let cells = Cells::new(lo, hi, r);
        RecordGrid { items: vec![Vec::new(); cells.len()], cells }
    }

    pub fn clear(&mut self) {
        self.items.iter_mut().for_each(Vec::clear);
    }

    /// Inserts `item` at `p`.
    pub fn insert(&mut self, item: T, p: Vec3) {
        let i = self.cells.index(self.cells.cell_of(p));
        self.items[i].push(item);
    }

    /// Calls `f` with every item whose position may lie within `r` of `p` (a superset; the
    /// caller tests the distance) until `f` returns false. Returns false if it was stopped.
    pub fn query(&self, p: Vec3, r: f32, mut f: impl FnMut(&T) -> bool) -> bool {
        let (lo, hi) = (self.cells.cell_of(p - Vec3::splat(r)), self.cells.cell_of(p + Vec3::splat(r)));
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    if !self.items[self.cells.index([x, y, z])].iter().all(&mut f) {
                        return false;
                    }
                }
            }
        }
        true
    }

    pub fn memory_bytes(&self) -> u64 {
        let items: usize = self.items.iter().map(|c| c.capacity() * std::mem::size_of::<T>()).sum();
        (self.items.len() * std::mem::size_of::<Vec<T>>() + items) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Queries return a superset of the brute-force answer, also for records and queries
    /// outside the grid's bounds (clamped into its border cells).
    #[test]
    fn queries_agree_with_brute_force_on_random_records() {
        let mut rng = crate::core::Rng::new(7, 8);
        let mut v = || rng.next_f32() * 20.0 - 10.0;
        let r = 0.7;
        let points: Vec<Vec3> = (0..3000).map(|_| Vec3::new(v(), v(), v())).collect();
        let mut grid = RecordGrid::new(Vec3::splat(-8.0), Vec3::splat(8.0), r);
        for (i, p) in points.iter().enumerate() {
            grid.insert(i as u32, *p);
        }
        let mut all = 0;
        grid.query(Vec3::ZERO, 1e9, |_: &u32| {
            all += 1;
            true
        });
        assert_eq!(all, points.len(), "every record is reachable");
        let mut outside = 0;
        for _ in 0..500 {
            let q = Vec3::new(v(), v(), v());
            outside += usize::from(q.abs().max_element() > 8.0);
            let mut found: Vec<u32> = Vec::new();
            grid.query(q, r, |&i| {
                if (points[i as usize] - q).length() <= r {
                    found.push(i)
                }
                true
            });
            found.sort_unstable();
            let brute: Vec<u32> =
                (0..points.len() as u32).filter(|&i| (points[i as usize] - q).length() <= r).collect();
            assert_eq!(found, brute, "query at {q:?}");
        }
        assert!(outside > 50, "too few queries outside the grid: {outside}");
    }
}
