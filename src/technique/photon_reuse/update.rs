//! The resident paths' update on a later tick (steps 2–4 of Moreau et al. 2019, §3): light
//! edits (rescale, re-emit, move with distribution maps, §3.4), verification of the paths a
//! moved surface or an edited material may have changed (`verify.rs`, `error.rs`), pruning and
//! filling the maps, and the retrace of what failed. A tick with no change refines instead.
use super::distribution::{DistributionMap, EmissionFrame};
use super::lights::{self, MappedLight, Moved};
use super::store::PathStore;
use super::trace::Retrace;
use super::verify::{self, Changes, Standing, VerifyWork};
use super::{error, ms, PhotonReuse, ReuseMode, TickWork};
use crate::scene::edits::SceneDelta;
use crate::technique::box_tree::BOX_SLACK;
use crate::technique::RenderContext;
use glam::Affine3A;
use rayon::prelude::*;
use std::time::Instant;

/// This tick's light edits, sorted by [`PhotonReuse::light_edits`]: per light, re-emit its
/// paths, or where it moved from; and whether a rescale changed stored powers.
struct LightEdits {
    reemit: Vec<bool>,
    moved_from: Vec<Option<Affine3A>>,
    rescaled: bool,
}

impl PhotonReuse {
    /// Steps 2–4 of a later tick. Returns whether any stored photon changed, and adds every
    /// path it changed to `tick.touched` and its figures to `tick.stats`.
    pub(super) fn update_paths(
        &mut self,
        ctx: &RenderContext,
        store: &mut PathStore,
        delta: &SceneDelta,
        tick: &mut TickWork,
    ) -> bool {
        let edits = self.light_edits(ctx, store, delta, tick);
        let transport_changed = !delta.moved.is_empty() || !delta.lights.is_empty() || !delta.materials.is_empty();
        let settling = self.maps.iter().flatten().any(|m| !m.map.settled());
        if transport_changed || settling {
            self.restore_radius();
        } else {
            return self.refine(ctx, store, tick);
        }
        if self.config.reuse == ReuseMode::Off {
            if !transport_changed {
                return false;
            }
            let all: Vec<(usize, Retrace)> = (0..store.paths).map(|i| (i, Retrace::Emit)).collect();
            self.retrace(ctx, store, &all, tick);
            return true;
        }
        let mut plan: Vec<Option<Retrace>> = vec![None; store.paths];
        let mut standing = vec![Standing::Unchecked; store.paths];
        let mut changed = edits.rescaled;

        let t = Instant::now();
        let (valid_of_light, moved) = self.update_origins(ctx, store, &edits, (&mut plan, &mut standing), tick);
        changed |= moved;
        tick.stats.origins_ms = ms(t);

        // Dynamic occlusions against moved surfaces and edited materials.
        let t = Instant::now();
        if !delta.moved.is_empty() || !delta.materials.is_empty() {
            changed |= self.verify(ctx, store, delta, &mut plan, &standing, tick);
        }
        tick.stats.verify_ms = ms(t);

        let t = Instant::now();
        self.prune_and_fill(ctx, store, valid_of_light, &mut plan, tick);
        tick.stats.prune_ms = ms(t);

        let work: Vec<(usize, Retrace)> = plan.into_iter().enumerate().filter_map(|(i, r)| r.map(|r| (i, r))).collect();
        if !work.is_empty() {
            self.retrace(ctx, store, &work, tick);
            changed = true;
        }
        changed
    }

    /// Sorts this tick's light edits: a light whose emission only scaled has its paths' powers
    /// rescaled (when paths are reused), any other new emission re-emits its paths, and a
    /// moved light's old placement is kept for its origins.
    fn light_edits(
        &mut self,
        ctx: &RenderContext,
        store: &mut PathStore,
        delta: &SceneDelta,
        tick: &mut TickWork,
    ) -> LightEdits {
        let lights = ctx.scene.lights.len();
        let mut edits = LightEdits { reemit: vec![false; lights], moved_from: vec![None; lights], rescaled: false };
        let reuse = self.config.reuse != ReuseMode::Off;
        for change in &delta.lights {
            match (change.emission_changed, change.rescale) {
                (true, Some(factor)) if reuse => {
                    let paths = lights::rescale(store, change.light, factor);
                    tick.stats.rescaled += paths.len() as u64;
                    tick.touched.extend(paths);
                    edits.rescaled = true;
                }
                (true, _) => {
                    edits.reemit[change.light] = true;
                    self.maps[change.light] = None;
                    continue;
                }
                (false, _) => {}
            }
            if change.moved {
                edits.moved_from[change.light] = Some(change.old_world_from_object);
            }
        }
        edits
    }

    /// Lights: plans re-emission for those whose emission changed and updates the origins of
    /// those that moved. Returns, per light with a map to balance, which of its slots hold a
    /// valid path, and whether an origin moved.
    fn update_origins(
        &mut self,
        ctx: &RenderContext,
        store: &mut PathStore,
        edits: &LightEdits,
        (plan, standing): (&mut [Option<Retrace>], &mut [Standing]),
        tick: &mut TickWork,
    ) -> (Vec<Option<Vec<bool>>>, bool) {
        let mut changed = false;
        let mut valid_of_light: Vec<Option<Vec<bool>>> = vec![None; edits.reemit.len()];
        for (l, valid) in valid_of_light.iter_mut().enumerate() {
            if edits.reemit[l] {
                for i in store.paths_of(l) {
                    plan[i] = Some(Retrace::Emit);
                    standing[i] = Standing::Decided;
                }
                continue;
            }
            if let Some(old) = edits.moved_from[l] {
                *valid = self.move_light(ctx, store, l, old, plan, standing, tick);
                changed = true;
            } else if let Some(m) = self.maps[l].as_ref().filter(|m| !m.map.settled()) {
                *valid = Some(m.slots.clone().map(|s| !store.emit_power[s].is_black()).collect());
            }
        }
        (valid_of_light, changed)
    }

    /// Prunes and fills the maps of lights that moved or have not settled, adding the paths to
    /// retrace to `plan`.
    fn prune_and_fill(
        &mut self,
        ctx: &RenderContext,
        store: &PathStore,
        valid_of_light: Vec<Option<Vec<bool>>>,
        plan: &mut [Option<Retrace>],
        tick: &mut TickWork,
    ) {
        for (l, valid) in valid_of_light.into_iter().enumerate() {
            let (Some(valid), Some(m)) = (valid, self.maps[l].as_mut()) else { continue };
            let b = lights::balance(m, store, &valid, ctx.seed, ctx.tick, l);
            tick.stats.pruned += b.pruned;
            tick.stats.filled += b.filled;
            for (slot, how) in b.work {
                plan[slot] = Some(how);
            }
        }
    }

    /// Updates the origins of light `l`'s paths after it moved from `old`, making its map the
    /// first time. Returns which of its slots still hold a valid path.
    fn move_light(
        &mut self,
        ctx: &RenderContext,
        store: &mut PathStore,
        l: usize,
        old: Affine3A,
        plan: &mut [Option<Retrace>],
        standing: &mut [Standing],
        tick: &mut TickWork,
    ) -> Option<Vec<bool>> {
        let frame = EmissionFrame::of(ctx.scene, l, self.config.distribution_map)?;
        let mapped = match self.maps[l].take() {
            Some(m) => MappedLight { frame, ..m },
            None => {
                let slots = store.paths_of(l);
                let map = DistributionMap::new(frame.targets(slots.len() as u32));
                MappedLight { frame, map, slots }
            }
        };
        let paths_of_light = self.paths_per_light[l];
        let moved: Vec<(Moved, u64)> = mapped
            .slots
            .clone()
            .into_par_iter()
            .map(|s| lights::update_origin(ctx.scene, ctx.accel, store, s, &mapped.frame, old, paths_of_light))
            .collect();
        let mut valid = Vec::with_capacity(moved.len());
        for (slot, (outcome, rays)) in mapped.slots.clone().zip(moved) {
            tick.stats.origin_rays += rays;
            match outcome {
                Moved::Kept { origin, dir, scale, cell, retrace } => {
                    if lights::apply_moved(store, slot, origin, dir, scale, cell) {
                        tick.touched.push(slot);
                    }
                    valid.push(true);
                    plan[slot] = retrace;
                    standing[slot] = if retrace.is_some() { Standing::Decided } else { Standing::FirstVerified };
                }
                Moved::Invalid => {
                    valid.push(false);
                    standing[slot] = Standing::Decided;
                }
            }
        }
        self.maps[l] = Some(mapped);
        Some(valid)
    }

    /// Dynamic occlusions for every path not yet decided. Returns whether a photon moved.
    fn verify(
        &mut self,
        ctx: &RenderContext,
        store: &mut PathStore,
        delta: &SceneDelta,
        plan: &mut [Option<Retrace>],
        standing: &[Standing],
        tick: &mut TickWork,
    ) -> bool {
        let scene = ctx.scene;
        let diagonal = ctx.accel.scene().bounds().map_or(1.0, |(lo, hi)| (hi - lo).length());
        let changes = Changes::new(scene, delta, BOX_SLACK * diagonal);
        // A segment in a moved box is tested against the moved surfaces alone before it is
        // retraced (naive) or re-intersected with the full scene (error): on the walker that
        // took about 8% off error mode's verify stage (`docs/benchmarks.md`, stop 48).
        let changes = changes.with_geometry(ctx.accel, delta);
        let t = Instant::now();
        let (screened, screen_tests) = verify::screen(scene, store, &changes, standing);
        tick.stats.screen_ms = ms(t);
        tick.stats.screened = screened.len() as u64;
        tick.stats.verify_box_tests += screen_tests;
        if self.config.reuse == ReuseMode::Naive {
            let (work, failed) = check_all(&screened, |i, mask| {
                let (retrace, work) = verify::check_path(scene, store, i, &changes, mask);
                (work, retrace)
            });
            tick.stats.count_verification(work);
            for (i, r) in failed {
                plan[i] = Some(r);
            }
            return false;
        }
        let threshold = self.config.threshold;
        let (work, decided) = check_all(&screened, |i, mask| {
            let c = error::check_path(scene, ctx.accel, store, i, &changes, threshold, mask);
            let decided = c.outcome != error::Outcome::Valid || !c.moved.is_empty();
            (c.work, decided.then_some(c))
        });
        tick.stats.count_verification(work);
        let moved_photons = !decided.is_empty();
        for (i, c) in decided {
            plan[i] = error::apply(store, i, c);
            tick.touched.push(i);
        }
        moved_photons
    }
}

/// Runs `check` on every screened (path, mask) in parallel: the sum of what the checks cost,
/// and the results they return, with their paths. Results are moved, never cloned.
fn check_all<T: Send>(
    screened: &[(u32, u16)],
    check: impl Fn(usize, u16) -> (VerifyWork, Option<T>) + Sync,
) -> (VerifyWork, Vec<(usize, T)>) {
    screened
        .par_iter()
        .fold(
            || (VerifyWork::default(), Vec::new()),
            |(work, mut out), &(i, mask)| {
                let (w, result) = check(i as usize, mask);
                out.extend(result.map(|x| (i as usize, x)));
                (work + w, out)
            },
        )
        .reduce(
            || (VerifyWork::default(), Vec::new()),
            |(work, mut out), (more, rest)| {
                out.extend(rest);
                (work + more, out)
            },
        )
}
