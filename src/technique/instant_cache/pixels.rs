//! Each camera sample's interpolation (eq. 4): the records with w_k(x) > 1 at its first
//! diffuse hit x and their weights, which `temporal` keeps from tick to tick.
//!
//! A sample looks the cache up (one grid query, once a pass, after the pass's new records are
//! placed) only when it must: its hit changed or one of its records went (`Cache::retain`
//! reports the renumbering). Otherwise it keeps its list. If a record made this pass may reach
//! it (a cell grid of the pass's new records says so; cells are at least the records' reach
//! wide, so the 27 cells around a new record hold every point it reaches), it asks the new
//! records alone and appends those with w > 1: they have the highest indices, so the list stays
//! in index order. Only the weighted sum is redone, since re-evaluation may have changed the
//! records' irradiance. On a still tick (nothing in the scene changed) even the sum is kept.
//!
//! Lists are in record-index order and sums run in that order. Records that stay keep their
//! relative order when others go, so a kept list sums to the same bits a fresh lookup would.
//!
//! Invariant (audited with `audit: true`, stat `audit_samples_mismatched`): every sample's list
//! equals, bit for bit, what a fresh lookup of the cache gives at its hit.
use super::cache::{Cache, Record, GONE};
use super::grid::{Cells, RecordGrid};
use crate::core::Rgb;
use crate::technique::camera_chain::CameraSample;
use glam::{Vec3, Vec3A};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// A sample's first diffuse hit as kept: position, facing shading normal, object.
pub type HitKey = (Vec3, Vec3, u32);

pub fn hit_key(sample: &CameraSample) -> Option<HitKey> {
    sample.hit.as_ref().map(|h| (h.p, h.shading_facing(), h.object))
}

/// One camera sample's interpolation, kept for the next tick.
#[derive(Clone, Debug, Default)]
pub struct SampleState {
    pub hit: Option<HitKey>,
    /// The records with w > 1 at the hit and their weights, by record index.
    pub weights: Vec<(u32, f32)>,
    /// The irradiance interpolated from them.
    pub indirect: Option<Rgb>,
}

/// One pass's sample states and the bytes they hold, counted by the pass that last changed them
/// ([`interpolate_all`]), so a tick that changes no list (a still or idle one) counts nothing.
#[derive(Clone, Debug, Default)]
pub struct PassStates {
    pub states: Vec<SampleState>,
    pub bytes: u64,
}

/// Bytes a sample's state holds besides its weights.
pub const STATE_BYTES: u64 = std::mem::size_of::<SampleState>() as u64;
/// Bytes per weight entry.
pub const WEIGHT_BYTES: u64 = std::mem::size_of::<(u32, f32)>() as u64;

/// The records with w > 1 at `hit`, by index.
fn look_up_at(cache: &Cache, hit: HitKey, weights: &mut Vec<(u32, f32)>) {
    weights.clear();
    cache.near(hit.0, hit.1, |i, w| weights.push((i, w)));
    weights.sort_unstable_by_key(|e| e.0);
}

/// Follows `renumbering` in place; false if one of the records went. An index that stays is
/// not written: records mostly go from the end (this tick's records on moved objects), so most
/// lists keep their indices, and their memory is then only read. A list whose last (highest)
/// index is below `first_moved`, the first index the renumbering changes, is not read further
/// (0 reads every list).
fn renumber(weights: &mut [(u32, f32)], renumbering: &[u32], first_moved: usize) -> bool {
    if weights.last().is_some_and(|&(i, _)| (i as usize) < first_moved) {
        return true;
    }
    weights.iter_mut().all(|(i, _)| {
        let now = renumbering.get(*i as usize).copied().unwrap_or(GONE);
        if now != *i {
            *i = now;
        }
        now != GONE
    })
}

/// The first index a renumbering changes (its length if none): a list of lower indices, in
/// index order, keeps them all.
fn first_moved(renumbering: &[u32]) -> usize {
    renumbering.iter().enumerate().position(|(i, &now)| now != i as u32).unwrap_or(renumbering.len())
}

/// A still tick's shortcut: if every camera sample was kept (`kept`), so each found last
/// tick's hit, their kept irradiance (no record changed, and none is needed); else `None`.
pub fn all_kept(states: &[SampleState], kept: &[bool]) -> Option<Vec<Option<Rgb>>> {
    let same = states.len() == kept.len() && kept.par_iter().all(|&k| k);
    same.then(|| states.par_iter().map(|s| s.indirect).collect())
}

/// Step 1 of a pass: each sample keeps its list (`keep`, its camera sample `kept` so its hit is
/// the one its state holds, a list that is not empty, no record of it gone) or clears it, to
/// look the cache up in step 3 after the new records are placed. Only the hits of samples
/// that do not keep their list are asked for (`hit`, by sample index). Returns per sample
/// whether it cleared its list and has a hit: step 2 tests those samples' coverage, and step
/// 3 looks them up.
pub fn keep_lists(
    states: &mut [SampleState],
    (hit, kept): (impl Fn(usize) -> Option<HitKey> + Sync, &[bool]),
    renumbering: Option<&[u32]>,
    keep: bool,
) -> Vec<bool> {
    let first_moved = renumbering.map_or(0, first_moved);
    states
        .par_iter_mut()
        .zip(kept)
        .enumerate()
        .map(|(i, (state, &kept))| {
            let stays = keep && kept && !state.weights.is_empty();
            if stays && renumbering.is_none_or(|map| renumber(&mut state.weights, map, first_moved)) {
                return false;
            }
            state.hit = hit(i);
            state.weights.clear();
            state.hit.is_some()
        })
        .collect()
}

/// The cells a tick's new records may reach: [`Cells`] over the scene's first extent, at least
/// the records' reach wide; points outside it fall into the border cells, which keeps the test
/// conservative. The marked cells answer "may a new record reach this sample?" with one read,
/// for every sample; the grid of the new records answers "which?" for the few that may.
pub struct NewRecords {
    cells: Cells,
    marked: Vec<bool>,
    /// The new records' indices by position.
    records: RecordGrid<u32>,
    reach: f32,
    /// A box around every new record and twice its reach (a margin that rounding cannot eat):
    /// a point outside it needs no cell lookup.
    bounds: (Vec3A, Vec3A),
    pub count: u64,
}

impl NewRecords {
    pub fn new(lo: Vec3, hi: Vec3, reach: f32) -> NewRecords {
        let cells = Cells::new(lo, hi, reach);
        let records = RecordGrid::new(lo, hi, reach);
        let bounds = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        NewRecords { marked: vec![false; cells.len()], cells, records, reach, bounds, count: 0 }
    }

    /// Marks the cells the record `index` at `p` may reach.
    fn mark(&mut self, index: u32, p: Vec3) {
        self.records.insert(index, p);
        self.count += 1;
        let (a, reach) = (Vec3A::from(p), Vec3A::splat(2.0 * self.reach));
        self.bounds = (self.bounds.0.min(a - reach), self.bounds.1.max(a + reach));
        let c = self.cells.cell_of(p);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let n = [c[0] + dx, c[1] + dy, c[2] + dz];
                    if n.iter().zip(&self.cells.dims).all(|(&v, &d)| (0..d).contains(&v)) {
                        let i = self.cells.index(n);
                        self.marked[i] = true;
                    }
                }
            }
        }
    }

    /// May a record made this tick reach `p`?
    pub fn near(&self, p: Vec3) -> bool {
        // Written so that a NaN coordinate passes the box and meets the cells, as a fresh lookup
        // does (it clamps NaN into cell 0).
        let a = Vec3A::from(p);
        !a.cmplt(self.bounds.0).any()
            && !a.cmpgt(self.bounds.1).any()
            && self.marked[self.cells.index(self.cells.cell_of(p))]
    }

    /// Appends to `weights` the new records with w > 1 at `hit`, by index. A kept list holds
    /// only older records (lower indices), so the list stays in index order and equals a
    /// fresh lookup. Returns whether any was appended.
    fn append_to(&self, cache: &Cache, hit: HitKey, weights: &mut Vec<(u32, f32)>) -> bool {
        let start = weights.len();
        self.records.query(hit.0, self.reach, |&i| {
            let r = &cache.records[i as usize];
            if let Some(w) = cache.weight(hit.0, hit.1, r.position, r.normal) {
                weights.push((i, w));
            }
            true
        });
        weights[start..].sort_unstable_by_key(|e| e.0);
        weights.len() > start
    }
}

/// Step 2, in sample order (so the image does not depend on the thread count): a sample that
/// cleared its list (`cleared`) and that no record covers gets a new one (without
/// contributions yet), unless one made earlier in this loop covers it. Samples that kept their
/// list are covered by it. Returns the cells the new records reach and the coverage tests made.
pub fn place_records(
    cache: &mut Cache,
    states: &[SampleState],
    cleared: &[bool],
    tick: u64,
    mut new: NewRecords,
) -> (NewRecords, u64) {
    let mut tests = 0;
    for (state, _) in states.iter().zip(cleared).filter(|(_, &c)| c) {
        let Some((p, n, object)) = state.hit else { continue };
        tests += 1;
        if !cache.covers(p, n) {
            let index = cache.insert(Record::new(p, n, object, Vec::new(), tick));
            new.mark(index, p);
        }
    }
    (new, tests)
}

/// Step 3: samples that must (`needs`, from step 1) look the cache up; samples that kept their
/// list and that a new record may reach add the new records that reach them (a query of the
/// new records alone). Returns per sample whether its list changed or was looked up.
pub fn look_up(cache: &Cache, states: &mut [SampleState], needs: &[bool], new: &NewRecords) -> Vec<bool> {
    states
        .par_iter_mut()
        .zip(needs)
        .map(|(state, &needs)| match state.hit {
            Some(h) if needs => {
                look_up_at(cache, h, &mut state.weights);
                true
            }
            Some(h) if new.near(h.0) => new.append_to(cache, h, &mut state.weights),
            _ => false,
        })
        .collect()
}

/// Eq. 4: the weighted mean of the records' irradiance (`irradiance`, by record index), summed
/// in index order; sets each record's flag in `used` on the way.
fn interpolate(irradiance: &[Rgb], weights: &[(u32, f32)], used: &AtomicFlags) -> Rgb {
    let (mut sum, mut total) = (Rgb::BLACK, 0.0f32);
    for &(i, w) in weights {
        used.set(i);
        sum += irradiance[i as usize] * w;
        total += w;
    }
    if total > 0.0 {
        sum / total
    } else {
        Rgb::BLACK
    }
}

/// What [`interpolate_all`] gives: each sample's indirect irradiance, how many samples have a
/// hit and how many kept last tick's value, and the records some sample's list holds (flags by
/// index, gathered in the same pass over the lists).
pub struct Interpolated {
    pub indirect: Vec<Option<Rgb>>,
    pub hits: u64,
    pub kept: u64,
    pub used: Vec<bool>,
    /// Bytes the states hold, with their weight lists.
    pub bytes: u64,
}

/// Each sample's irradiance: kept when `still` (no record's irradiance changed) and the sample
/// did not look up (`looked`), else interpolated. The records' irradiance is gathered first
/// into one dense array (12 bytes a record against the record's 80), so the samples' lookups
/// into it stay in the L1 cache.
pub fn interpolate_all(records: &[Record], states: &mut [SampleState], looked: &[bool], still: bool) -> Interpolated {
    let used = AtomicFlags::new(records.len());
    let irradiance: Vec<Rgb> = records.iter().map(|r| r.irradiance).collect();
    let (indirect, kept): (Vec<Option<Rgb>>, Vec<(bool, u64)>) = states
        .par_iter_mut()
        .zip(looked)
        .map(|(state, &looked)| {
            let bytes = STATE_BYTES + state.weights.capacity() as u64 * WEIGHT_BYTES;
            if state.hit.is_none() {
                return (None, (false, bytes));
            }
            let keep = still && !looked && state.indirect.is_some();
            if keep {
                state.weights.iter().for_each(|&(i, _)| used.set(i));
            } else {
                state.indirect = Some(interpolate(&irradiance, &state.weights, &used));
            }
            (state.indirect, (keep, bytes))
        })
        .unzip();
    let hits = indirect.par_iter().filter(|e| e.is_some()).count() as u64;
    let (kept, bytes) =
        kept.par_iter().map(|&(k, b)| (u64::from(k), b)).reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    Interpolated { indirect, hits, kept, used: used.into_vec(), bytes }
}

/// The records some sample's list holds, as flags by index.
pub fn used(records: usize, states: &[SampleState]) -> Vec<bool> {
    let flags = AtomicFlags::new(records);
    states.par_iter().for_each(|s| s.weights.iter().for_each(|&(i, _)| flags.set(i)));
    flags.into_vec()
}

/// Bytes the passes' states hold, as their passes last counted them.
pub fn samples_bytes(passes: &[PassStates]) -> u64 {
    passes.iter().map(|p| p.bytes).sum()
}

/// Marks the records the samples use (`used`, flags by index) as used at `tick` and returns
/// how many of those before `first_new` (kept from earlier ticks) there are. `None` when every
/// sample kept its list: the records used are then those used last tick.
pub fn mark_used(cache: &mut Cache, used: Option<&[bool]>, first_new: usize, tick: u64) -> u64 {
    let used: std::borrow::Cow<[bool]> = match used {
        Some(used) => used.into(),
        None => cache.records.iter().map(|r| r.last_used + 1 >= tick).collect(),
    };
    for (r, _) in cache.records.iter_mut().zip(used.iter()).filter(|(_, &u)| u) {
        r.last_used = tick;
    }
    used[..first_new].iter().filter(|&&u| u).count() as u64
}

/// What [`audit`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SampleAudit {
    /// Samples whose hit or list differs from a fresh lookup at the camera sample's hit (the
    /// invariant above).
    pub mismatched: u64,
    /// Samples that had to look up: their hit or their records differ from last tick's
    /// (`previous`, followed through `renumbering`).
    pub needed: u64,
}

/// Checks every sample's hit against its camera sample's (`hit`, by index) and its list
/// against a fresh lookup there, and counts the samples whose list had to change since
/// `previous` (for `audit`).
pub fn audit(
    cache: &Cache,
    states: &[SampleState],
    hit: impl Fn(usize) -> Option<HitKey> + Sync,
    previous: &[SampleState],
    renumbering: Option<&[u32]>,
) -> SampleAudit {
    let bits = |w: &[(u32, f32)]| w.iter().map(|&(i, w)| (i, w.to_bits())).collect::<Vec<_>>();
    states
        .par_iter()
        .enumerate()
        .map(|(k, s)| {
            let mut fresh = Vec::new();
            if let Some(h) = hit(k) {
                look_up_at(cache, h, &mut fresh);
            }
            let needed = previous.get(k).is_none_or(|p| {
                let mut old = p.weights.clone();
                let stayed = renumbering.is_none_or(|map| renumber(&mut old, map, 0));
                p.hit != s.hit || !stayed || bits(&old) != bits(&fresh)
            });
            let mismatched = hit(k) != s.hit || bits(&fresh) != bits(&s.weights);
            SampleAudit { mismatched: u64::from(mismatched), needed: u64::from(needed) }
        })
        .reduce(SampleAudit::default, |a, b| SampleAudit {
            mismatched: a.mismatched + b.mismatched,
            needed: a.needed + b.needed,
        })
}

/// One flag per record, set from many threads.
struct AtomicFlags(Vec<AtomicBool>);

impl AtomicFlags {
    fn new(len: usize) -> AtomicFlags {
        AtomicFlags((0..len).map(|_| AtomicBool::new(false)).collect())
    }

    /// Sets flag `i`. A flag already set is only read: the samples of both workers' rows
    /// share records, and a store to a line the other core holds would take it from there.
    fn set(&self, i: u32) {
        if let Some(flag) = self.0.get(i as usize) {
            if !flag.load(Ordering::Relaxed) {
                flag.store(true, Ordering::Relaxed);
            }
        }
    }

    fn into_vec(self) -> Vec<bool> {
        self.0.into_iter().map(AtomicBool::into_inner).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cache over the unit cube (a = 0.05 of its diagonal) with records on a plane (normal +z).
    fn plane_cache(points: &[Vec3]) -> Cache {
        let mut cache = Cache::new(Vec3::ZERO, Vec3::ONE, 0.05, 10.0);
        for (i, &p) in points.iter().enumerate() {
            let mut r = Record::new(p, Vec3::Z, 0, Vec::new(), 0);
            r.irradiance = Rgb::new(i as f32 + 1.0, 1.0, 1.0);
            cache.insert(r);
        }
        cache
    }

    fn states_on_grid(n: usize) -> (Vec<SampleState>, Vec<Option<HitKey>>) {
        let hits: Vec<Option<HitKey>> = (0..n * n)
            .map(|i| Some((Vec3::new((i % n) as f32 / n as f32, (i / n) as f32 / n as f32, 0.5), Vec3::Z, 0)))
            .collect();
        (vec![SampleState::default(); hits.len()], hits)
    }

    #[test]
    fn kept_lists_match_fresh_lookups_after_records_go_and_come() {
        // Property: after records are removed (renumbered) and new ones placed, kept lists and
        // re-looked-up lists together equal fresh lookups everywhere. Negative control: the
        // same steps without the new-record cells leave samples near the new records with
        // lists that miss them, and the audit counts them.
        let points: Vec<Vec3> = (0..40).map(|i| Vec3::new((i % 8) as f32 / 8.0, (i / 8) as f32 / 5.0, 0.5)).collect();
        let (mut states, hits) = states_on_grid(32);
        let run = |use_cells: bool, states: &mut Vec<SampleState>| {
            let mut cache = plane_cache(&points);
            let reach = cache.reach();
            let no_cells = || NewRecords::new(Vec3::ZERO, Vec3::ONE, reach);
            let hit = |i: usize| hits[i];
            // The first pass traces every camera sample; the second keeps them all.
            let needs = keep_lists(states, (hit, &vec![false; hits.len()]), None, true);
            look_up(&cache, states, &needs, &no_cells());
            cache.retain(|r| r.position.x < 0.5);
            let map = cache.take_renumbering().expect("records went");
            let needs = keep_lists(states, (hit, &vec![true; hits.len()]), Some(&map), true);
            assert!(needs.iter().any(|&l| l) && needs.iter().any(|&l| !l), "some kept, some look up");
            let (new, _) = place_records(&mut cache, states, &needs, 1, no_cells());
            assert!(new.count > 0, "the removed area gets new records");
            look_up(&cache, states, &needs, &if use_cells { new } else { no_cells() });
            audit(&cache, states, hit, &[], None).mismatched
        };
        assert_eq!(run(true, &mut states), 0, "kept lists differ from fresh lookups");
        let (mut control, _) = states_on_grid(32);
        assert!(run(false, &mut control) > 0, "the audit cannot see a list missing a new record");
    }

    #[test]
    fn a_cell_grid_holds_every_point_a_record_reaches() {
        // Property: a point within the reach of a new record lies in a marked cell, also
        // outside the grid's extent (border cells). Checked against distances on random points.
        let mut rng = crate::core::Rng::new(3, 4);
        // A reach that does not divide the extent: rounding the cell count up would make cells
        // narrower than the reach (0.25 for 0.3 on the unit axis), and this check fails then.
        let reach = 0.3;
        let mut u = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let mut reached = 0;
        for _ in 0..200 {
            // One record, mostly inside the grid, and points around it out to its reach.
            let mut new = NewRecords::new(Vec3::ZERO, Vec3::new(1.0, 0.7, 2.0), reach);
            let record = u() * Vec3::new(1.2, 0.9, 2.2) - 0.1;
            new.mark(0, record);
            for _ in 0..200 {
                let p = record + (u() * 2.0 - Vec3::ONE) * reach;
                if (record - p).length() <= reach {
                    reached += 1;
                    assert!(new.near(p), "{p:?} is within reach of {record:?} but not marked");
                }
            }
        }
        assert!(reached > 10, "the check saw too few reached points ({reached})");
    }
}
