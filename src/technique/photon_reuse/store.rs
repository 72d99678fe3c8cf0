//! The path store: N photon paths of up to B photons each, as structure-of-arrays, bounce-major
//! (Moreau et al. 2019, §4): row i holds the i-th photon of every path, so a pass over "bounce i
//! of all paths" reads contiguous memory.
//!
//! Segment k of a path runs from its start (the light point for k = 0, photon k−1 otherwise) to
//! photon k. A path whose last segment left the scene keeps that segment's direction
//! (`escape`), so an object moving into it is still noticed. Units: positions in meters, power
//! in watts (flux per photon), directions unit length.
//!
//! Layout (the paper's Table 1 budget): a photon is 32 bytes (position 12, octahedral incoming
//! direction 4, surface id 4, flux 12); a path's reuse data is 24 bytes (path word 4, octahedral
//! segment-0 and escape directions 4 + 4, segment-0 flux 12), plus a 12-byte origin only when
//! some light has a shape. Each light's paths are contiguous, so no path stores its light. Stored
//! directions are within [`PackedDir::MAX_ANGLE_ERROR`] of the traced ones.
use crate::core::{PackedDir, Rgb};
use crate::scene::Scene;
use glam::Vec3;

/// Row i of the store: photon i of every path, 32 bytes per photon as in the paper's Table 1.
#[derive(Clone, Debug, Default)]
pub struct PhotonRow {
    pub position: Vec<Vec3>,
    /// Direction of travel arriving at the photon (pointing into the surface), packed.
    pub incoming: Vec<PackedDir>,
    /// The object and triangle the photon lies on, as one id ([`SurfaceIds`]); the triangle
    /// gives the surface normal when a ray leaves the photon.
    pub surface: Vec<u32>,
    /// Flux arriving with the photon.
    pub power: Vec<Rgb>,
}

impl PhotonRow {
    /// Stores `p` as this row's photon of `path`.
    pub fn put(&mut self, path: usize, p: StoredPhoton) {
        self.position[path] = p.position;
        self.incoming[path] = p.incoming;
        self.surface[path] = p.surface;
        self.power[path] = p.power;
    }

    /// Bytes per photon: position, packed incoming direction, surface id and power.
    pub const BYTES_PER_PHOTON: u64 = (std::mem::size_of::<Vec3>()
        + std::mem::size_of::<PackedDir>()
        + std::mem::size_of::<u32>()
        + std::mem::size_of::<Rgb>()) as u64;

    fn with_len(n: usize) -> PhotonRow {
        PhotonRow {
            position: vec![Vec3::ZERO; n],
            incoming: vec![PackedDir::NONE; n],
            surface: vec![0; n],
            power: vec![Rgb::BLACK; n],
        }
    }

    /// Heap bytes the row holds. The paper's photon is 32 bytes too (a radius where this one
    /// has its surface id; the radius is global here): the surface id buys robust ray offsets
    /// when a path is retraced from a stored photon.
    fn heap_bytes(&self) -> u64 {
        heap_bytes(&self.position) + heap_bytes(&self.incoming) + heap_bytes(&self.surface) + heap_bytes(&self.power)
    }
}

/// A photon as a row keeps it (packed where tracing runs in parallel, copied in afterwards).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StoredPhoton {
    pub position: Vec3,
    pub incoming: PackedDir,
    pub surface: u32,
    pub power: Rgb,
}

/// One 32-bit id per (object, triangle), decoded in O(1). Ids come in blocks of 2^`shift`;
/// each object starts on a block boundary, so one table lookup by `id >> shift` names the
/// object. `shift` is the smallest that keeps the table within [`SurfaceIds::MAX_BLOCKS`] (or
/// two per object), so it stays in cache. Objects keep their meshes for a session's life (edits
/// move them, never reshape them), so the ids made at the first tick stay valid.
#[derive(Clone, Debug, Default)]
pub struct SurfaceIds {
    shift: u32,
    /// `first[o]`: the id of object o's triangle 0.
    first: Vec<u32>,
    /// The object each block of ids belongs to.
    object_of_block: Vec<u32>,
}

impl SurfaceIds {
    /// Largest table of blocks, unless the scene has more objects than half of it.
    pub const MAX_BLOCKS: u64 = 4096;

    /// The ids of `scene`'s triangles, or `None` when they do not fit in 32 bits (the scene's
    /// triangle limit keeps them far below).
    pub fn of(scene: &Scene) -> Option<SurfaceIds> {
        let triangles: Vec<u64> = scene.objects.iter().map(|o| o.mesh.triangles.len() as u64).collect();
        Self::for_counts(&triangles)
    }

    /// The ids of objects with these triangle counts.
    fn for_counts(triangles: &[u64]) -> Option<SurfaceIds> {
        let blocks = |shift: u32| triangles.iter().map(|&t| t.div_ceil(1 << shift)).sum::<u64>();
        let limit = Self::MAX_BLOCKS.max(2 * triangles.len() as u64);
        let shift = (0..32).find(|&s| blocks(s) <= limit)?;
        if blocks(shift) << shift > u64::from(u32::MAX) {
            return None;
        }
        let mut ids = SurfaceIds { shift, first: Vec::with_capacity(triangles.len()), object_of_block: Vec::new() };
        for (object, &t) in triangles.iter().enumerate() {
            ids.first.push((ids.object_of_block.len() as u32) << shift);
            ids.object_of_block.extend(std::iter::repeat_n(object as u32, t.div_ceil(1 << shift) as usize));
        }
        Some(ids)
    }

    pub fn id(&self, object: u32, prim: u32) -> u32 {
        self.first[object as usize] + prim
    }

    pub fn object(&self, id: u32) -> u32 {
        self.object_of_block[(id >> self.shift) as usize]
    }

    /// `per_object`, looked up per block of ids, with the shift that finds an id's block: one
    /// load per id instead of two.
    pub fn per_block(&self, per_object: &[bool]) -> (Vec<bool>, u32) {
        (self.object_of_block.iter().map(|&o| per_object[o as usize]).collect(), self.shift)
    }

    pub fn object_and_prim(&self, id: u32) -> (u32, u32) {
        let object = self.object(id);
        (object, id - self.first[object as usize])
    }
}

/// Bytes a vector's allocation holds (its capacity, not its length).
fn heap_bytes<T>(v: &Vec<T>) -> u64 {
    (v.capacity() * std::mem::size_of::<T>()) as u64
}

/// The 32-bit path word of the paper's §4: distribution-map cell (22 bits), segment count (4),
/// segment to retrace from (4), replace flag (1), reuse-light flag (1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PathWord(pub u32);

impl PathWord {
    const CELL_BITS: u32 = 22;
    const COUNT_SHIFT: u32 = 22;
    const FROM_SHIFT: u32 = 26;
    const REPLACE_BIT: u32 = 1 << 30;
    const REUSE_LIGHT_BIT: u32 = 1 << 31;
    /// Largest photon count a path word can hold.
    pub const MAX_PHOTONS: u32 = 15;

    pub fn cell(self) -> u32 {
        self.0 & ((1 << Self::CELL_BITS) - 1)
    }
    /// Photons on the path (0..=15).
    pub fn photons(self) -> u32 {
        (self.0 >> Self::COUNT_SHIFT) & 0xF
    }
    /// The segment retracing starts from (meaningful when `replace` is set).
    pub fn retrace_from(self) -> u32 {
        (self.0 >> Self::FROM_SHIFT) & 0xF
    }
    pub fn replace(self) -> bool {
        self.0 & Self::REPLACE_BIT != 0
    }
    pub fn reuse_light(self) -> bool {
        self.0 & Self::REUSE_LIGHT_BIT != 0
    }

    /// Sets the distribution-map cell (`c` below 2²²).
    pub fn with_cell(self, c: u32) -> PathWord {
        PathWord((self.0 & !((1 << Self::CELL_BITS) - 1)) | (c & ((1 << Self::CELL_BITS) - 1)))
    }
    pub fn with_photons(self, n: u32) -> PathWord {
        PathWord((self.0 & !(0xF << Self::COUNT_SHIFT)) | ((n.min(Self::MAX_PHOTONS)) << Self::COUNT_SHIFT))
    }
    /// Marks the path for retracing from `segment`.
    pub fn retrace(self, segment: u32) -> PathWord {
        PathWord((self.0 & !(0xF << Self::FROM_SHIFT)) | ((segment & 0xF) << Self::FROM_SHIFT) | Self::REPLACE_BIT)
    }
    pub fn cleared(self) -> PathWord {
        PathWord(self.0 & !Self::REPLACE_BIT)
    }
    /// Sets or clears the reuse-light flag: the path kept its light sample (origin and
    /// direction) when its light moved.
    pub fn with_reused_light(self, reused: bool) -> PathWord {
        PathWord((self.0 & !Self::REUSE_LIGHT_BIT) | if reused { Self::REUSE_LIGHT_BIT } else { 0 })
    }
}

/// All resident paths.
#[derive(Clone, Debug)]
pub struct PathStore {
    pub paths: usize,
    pub max_photons: usize,
    /// `rows[i]` holds photon i of every path.
    pub rows: Vec<PhotonRow>,
    pub word: Vec<PathWord>,
    /// Each light's paths are contiguous: light l owns `light_end[l − 1]..light_end[l]`
    /// (fixed when the paths are assigned), so no path stores its light.
    light_end: Vec<u32>,
    /// Emission point: stored only when some light has a shape (area lights); point and spot
    /// paths start at their light's position.
    pub origin: Option<Vec<Vec3>>,
    /// Direction (packed) and flux of segment 0.
    pub emit_dir: Vec<PackedDir>,
    pub emit_power: Vec<Rgb>,
    /// Direction of the last segment if it left the scene or ended on a light; NONE if the
    /// path ended at its last photon (roulette or B).
    pub escape: Vec<PackedDir>,
    /// How the rows' surface ids map to objects and triangles.
    pub surfaces: SurfaceIds,
}

/// Bytes per structure, reported in the stats.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct StoreMemory {
    pub photon_map: u64,
    pub path_words: u64,
    pub origins: u64,
    pub segment0_and_escape: u64,
    /// DM_T and DM_C of lights that have moved (none for lights that never moved).
    pub distribution_maps: u64,
}

impl StoreMemory {
    /// The store's parts as the technique reports them (`PhotonStats::memory`).
    pub fn resident(&self) -> crate::technique::ResidentMemory {
        let mut m = crate::technique::ResidentMemory::default();
        for (part, bytes) in [
            ("photon_map", self.photon_map),
            ("path_words", self.path_words),
            ("origins", self.origins),
            ("segment0_and_escape", self.segment0_and_escape),
            ("distribution_maps", self.distribution_maps),
        ] {
            m.set(part, bytes);
        }
        m
    }

    pub fn total(&self) -> u64 {
        self.resident().total_bytes
    }
}

/// Whether paths must keep their origins: a point or spot light's paths all start where it
/// stands, but an area light's and a light from outside's each start somewhere else.
pub fn keeps_origins(scene: &Scene) -> bool {
    scene.lights.iter().any(|l| l.mesh.is_some() || l.geometry.is_infinite())
}

impl PathStore {
    pub fn new(paths: usize, max_photons: usize, with_origins: bool, surfaces: SurfaceIds) -> PathStore {
        PathStore {
            paths,
            max_photons,
            rows: (0..max_photons).map(|_| PhotonRow::with_len(paths)).collect(),
            word: vec![PathWord::default(); paths],
            light_end: Vec::new(),
            origin: with_origins.then(|| vec![Vec3::ZERO; paths]),
            emit_dir: vec![PackedDir::NONE; paths],
            emit_power: vec![Rgb::BLACK; paths],
            escape: vec![PackedDir::NONE; paths],
            surfaces,
        }
    }

    /// Writes photon `p` into row `row` of path `path`.
    pub fn put(&mut self, row: usize, path: usize, p: StoredPhoton) {
        self.rows[row].put(path, p);
    }

    /// Gives light l the next `counts[l]` paths, in light order. Paths beyond the counts' sum
    /// (none when some light emits) belong to the last light.
    pub fn assign(&mut self, counts: &[u32]) {
        let mut end = 0u32;
        self.light_end = counts
            .iter()
            .map(|&c| {
                end = end.saturating_add(c);
                end
            })
            .collect();
    }

    /// The light that owns `path`.
    pub fn light_of(&self, path: usize) -> usize {
        let l = self.light_end.partition_point(|&end| end as usize <= path);
        l.min(self.light_end.len().saturating_sub(1))
    }

    /// The paths light `l` owns.
    pub fn paths_of(&self, l: usize) -> std::ops::Range<usize> {
        let start = if l == 0 { 0 } else { self.light_end.get(l - 1).map_or(self.paths, |&e| e as usize) };
        let end = if l + 1 >= self.light_end.len() { self.paths } else { self.light_end[l] as usize };
        start.min(self.paths)..end.max(start).min(self.paths)
    }

    /// Bytes per path besides its photons: word, origin (only `with_origins`), packed
    /// segment-0 direction, its flux, and packed escape direction.
    pub fn bytes_per_path(with_origins: bool) -> u64 {
        let origin = if with_origins { std::mem::size_of::<Vec3>() } else { 0 };
        (std::mem::size_of::<PathWord>() + 2 * std::mem::size_of::<PackedDir>() + std::mem::size_of::<Rgb>() + origin)
            as u64
    }

    /// What the store's allocations hold, measured from the vectors themselves.
    pub fn memory(&self) -> StoreMemory {
        StoreMemory {
            photon_map: self.rows.iter().map(PhotonRow::heap_bytes).sum(),
            path_words: heap_bytes(&self.word) + heap_bytes(&self.light_end),
            origins: self.origin.as_ref().map_or(0, heap_bytes),
            segment0_and_escape: heap_bytes(&self.emit_dir) + heap_bytes(&self.emit_power) + heap_bytes(&self.escape),
            distribution_maps: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_word_fields_are_independent() {
        let w = PathWord(0x1234).with_photons(7).retrace(3);
        assert_eq!(
            (w.cell(), w.photons(), w.retrace_from(), w.replace(), w.reuse_light()),
            (0x1234, 7, 3, true, false)
        );
        let w = w.cleared().with_photons(15);
        assert_eq!((w.cell(), w.photons(), w.replace()), (0x1234, 15, false));
        let w = w.with_cell((1 << 22) - 1);
        assert_eq!((w.cell(), w.photons(), w.retrace_from()), ((1 << 22) - 1, 15, 3));
        assert_eq!(PathWord(0).with_photons(99).photons(), 15);
        let w = w.with_reused_light(true);
        assert!(w.reuse_light() && w.with_reused_light(false).0 == w.0 & !(1 << 31));
    }

    #[test]
    fn surface_ids_round_trip_and_keep_their_table_small() {
        // Property: every (object, triangle) decodes to itself, objects without triangles
        // included, and the block table stays within its bound. The counts make the first
        // shift that fits the bound something other than 0. Negative control: ids that do
        // not fit 32 bits are refused.
        let counts = [5u64, 0, 70_000, 1, 0, 3, 200_000, 9];
        let ids = SurfaceIds::for_counts(&counts).expect("fits");
        assert!(ids.shift > 0 && ids.object_of_block.len() as u64 <= SurfaceIds::MAX_BLOCKS);
        for (object, &n) in counts.iter().enumerate() {
            for prim in [0, 1, n / 2, n.saturating_sub(1)].into_iter().filter(|&p| p < n) {
                let id = ids.id(object as u32, prim as u32);
                assert_eq!(ids.object_and_prim(id), (object as u32, prim as u32));
            }
        }
        assert!(SurfaceIds::for_counts(&[u64::from(u32::MAX), 2]).is_none());
    }

    #[test]
    fn each_light_owns_the_paths_it_was_assigned() {
        // Property: light_of and paths_of agree with the counts, lights with no paths
        // included, and paths beyond the counts belong to the last light.
        let mut store = PathStore::new(10, 1, false, SurfaceIds::default());
        store.assign(&[3, 0, 5, 1]);
        let owners: Vec<usize> = (0..10).map(|p| store.light_of(p)).collect();
        assert_eq!(owners, [0, 0, 0, 2, 2, 2, 2, 2, 3, 3]);
        let ranges: Vec<_> = (0..4).map(|l| store.paths_of(l)).collect();
        assert_eq!(ranges, [0..3, 3..3, 3..8, 8..10]);
        for (l, r) in ranges.into_iter().enumerate() {
            assert!(r.clone().all(|p| store.light_of(p) == l));
        }
    }

    #[test]
    fn memory_grows_with_paths_and_bounces_and_origins_only_when_asked() {
        let base = PathStore::new(1000, 7, false, SurfaceIds::default()).memory();
        assert_eq!(PathStore::new(2000, 7, false, SurfaceIds::default()).memory().photon_map, 2 * base.photon_map);
        assert_eq!(PathStore::new(1000, 14, false, SurfaceIds::default()).memory().photon_map, 2 * base.photon_map);
        assert_eq!(PathStore::new(1000, 14, false, SurfaceIds::default()).memory().path_words, base.path_words);
        assert_eq!(base.origins, 0);
        let with = PathStore::new(1000, 7, true, SurfaceIds::default()).memory();
        assert!(with.origins > 0 && with.total() == base.total() + with.origins);
    }
}
