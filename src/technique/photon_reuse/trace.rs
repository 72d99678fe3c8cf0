//! Tracing photon paths with Embree: whole paths, kept segments re-intersected, and fresh tails.
//!
//! Every path draws its random numbers from its own stream keyed by (seed, retrace pass, path),
//! so results do not depend on scheduling. Paths end by Russian roulette (continue with probability
//! max(f·cos/pdf), capped at 1), at B photons, on a light (lights absorb), or by leaving the
//! scene. Photons are stored at every surface hit, specular ones included, so that every segment
//! is a straight line between consecutive rows.
use super::distribution::EmissionFrame;
use super::store::{PathStore, StoredPhoton};
use crate::core::{offset_ray_origin, PackedDir, Rgb, Rng};
use crate::embree::Ray;
use crate::scene::{Normals, Scene, SceneAccel, SurfaceId, Transport};
use glam::Vec3;
use rayon::prelude::*;

/// Separates photon random streams from camera streams keyed by the same numbers.
const PHOTON_STREAM: u64 = 0x5048_4f54_4f4e; // "PHOTON"

/// One stored photon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Photon {
    pub position: Vec3,
    pub incoming: Vec3,
    pub object: u32,
    pub prim: u32,
    pub power: Rgb,
}

/// How a path is (re)traced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Retrace {
    /// Emit anew from the path's light: new origin, direction and tail.
    Emit,
    /// Re-intersect segment `k` along its stored direction with its stored flux, then continue
    /// with a fresh tail (the vertex it leaves did not change). For the escape segment (`k` =
    /// the path's photon count) the flux is recomputed from photon `k − 1` and its BSDF.
    KeepSegment(u32),
    /// Sample a fresh direction at photon `k − 1` and trace a fresh tail from there.
    FreshFrom(u32),
    /// Sample a fresh direction at photon `k − 1` whose Russian roulette already let the path
    /// go on (its vertex did not change, only what lies beyond): the roulette is not drawn
    /// again, which would continue the path with probability q² instead of q.
    Redirect(u32),
    /// Emit anew inside distribution-map cell `c` of the path's light (§3.1, "fill").
    Fill(u32),
}

impl Retrace {
    /// The first segment this retrace rewrites (the path word's "retrace from" field).
    pub fn first_segment(self) -> u32 {
        match self {
            Retrace::Emit | Retrace::Fill(_) => 0,
            Retrace::KeepSegment(k) | Retrace::FreshFrom(k) | Retrace::Redirect(k) => k,
        }
    }
}

/// The new tail of a path, computed in parallel and written back afterwards.
#[derive(Clone, Debug)]
pub struct TracedTail {
    pub path: usize,
    /// First row written.
    pub from: u32,
    pub photons: Vec<StoredPhoton>,
    pub escape: PackedDir,
    /// New segment 0 (origin, direction, flux) when re-emitted.
    pub emission: Option<(Vec3, PackedDir, Rgb)>,
    /// The distribution-map cell of a re-emitted path whose light has a map.
    pub cell: Option<u32>,
    pub rays: u64,
}

pub fn photon_at(store: &PathStore, path: usize, row: usize) -> Photon {
    let r = &store.rows[row];
    let (object, prim) = store.surfaces.object_and_prim(r.surface[path]);
    Photon { position: r.position[path], incoming: r.incoming[path].get(), object, prim, power: r.power[path] }
}

/// The start of segment 0 of a path.
pub fn path_origin(scene: &Scene, store: &PathStore, path: usize) -> Vec3 {
    match &store.origin {
        Some(o) => o[path],
        None => scene.light_position(store.light_of(path)),
    }
}

/// What tracing reads besides the store: the scene, its Embree scenes, the seed, how many paths
/// each light owns (each carries `1/paths_of_light` of its light's power, so their sum
/// estimates it) and the emission frames of lights with a distribution map.
pub struct Tracer<'a> {
    pub scene: &'a Scene,
    pub accel: &'a SceneAccel,
    pub seed: u64,
    pub paths_per_light: &'a [u32],
    pub frames: &'a [Option<&'a EmissionFrame>],
    /// Which retrace pass this is: a path is traced at most once per pass, so (seed, epoch,
    /// path) keys a fresh random stream for every new tail without a per-path counter.
    pub epoch: u64,
}

impl Tracer<'_> {
    /// A new segment 0 for `path`: anywhere on its light, or inside `cell` of its map.
    fn emit(&self, store: &PathStore, path: usize, cell: Option<u32>, rng: &mut Rng) -> Option<(Vec3, Vec3, Rgb)> {
        let light = store.light_of(path);
        let geometry = &self.scene.lights[light].geometry;
        let frame = self.frames.get(light).copied().flatten();
        // A point or spot light emits from where it is now; the path's stored origin is where
        // it was when the path was traced (an area light's cell brings its own origin).
        let here = self.scene.light_position(light);
        let in_cell = match (cell, frame) {
            (Some(c), Some(f)) => f.sample_in_cell(c, here, rng),
            _ => None,
        };
        let (origin, dir, weight) = match in_cell {
            Some((o, d)) => (o, d, geometry.emission_weight(d)),
            None => geometry.sample_emission(rng.next_2d(), rng.next_2d())?,
        };
        let paths_of_light = self.paths_per_light.get(light).copied().unwrap_or(1).max(1);
        (!weight.is_black()).then(|| (origin, dir, weight / paths_of_light as f32))
    }

    /// Traces path `path` as `how` says, reading the store and returning the new tail.
    pub fn trace(&self, store: &PathStore, path: usize, how: Retrace) -> TracedTail {
        let mut rng = Rng::for_sample(self.seed, self.epoch, path as u64, PHOTON_STREAM);
        let mut tail = TracedTail {
            path,
            from: 0,
            photons: Vec::new(),
            escape: PackedDir::NONE,
            emission: None,
            cell: None,
            rays: 0,
        };
        if let Some(start) = self.segment_start(store, path, how, &mut rng, &mut tail) {
            self.follow(store, &mut tail, start, &mut rng);
        }
        tail
    }

    /// Where the traced segment of `path` starts, where it goes and with what flux; sets
    /// `tail.from`, its first row. `None` when there is nothing to trace: `tail` is then complete
    /// (an emission that failed, or a path that roulette or a black weight ends at `tail.from`).
    fn segment_start(
        &self,
        store: &PathStore,
        path: usize,
        how: Retrace,
        rng: &mut Rng,
        tail: &mut TracedTail,
    ) -> Option<(Vec3, Vec3, Rgb)> {
        let scene = self.scene;
        let (origin, dir, power, from) = match how {
            Retrace::Emit | Retrace::Fill(_) => {
                let cell = if let Retrace::Fill(c) = how { Some(c) } else { None };
                let Some((o, d, power)) = self.emit(store, path, cell, rng) else {
                    tail.emission = Some((path_origin(scene, store, path), PackedDir::new(Vec3::Z), Rgb::BLACK));
                    return None;
                };
                tail.emission = Some((o, PackedDir::new(d), power));
                let frame = self.frames.get(store.light_of(path)).copied().flatten();
                tail.cell = frame.and_then(|f| f.cell_of(o, d));
                (o, d, power, 0)
            }
            Retrace::KeepSegment(0) => {
                (path_origin(scene, store, path), store.emit_dir[path].get(), store.emit_power[path], 0)
            }
            Retrace::KeepSegment(k) if k < store.word[path].photons() => {
                let prev = photon_at(store, path, k as usize - 1);
                let next = photon_at(store, path, k as usize);
                (leaving(scene, &prev, next.incoming), next.incoming, next.power, k)
            }
            Retrace::KeepSegment(k) => {
                // The path's escape segment: its flux is what leaves photon k − 1 along it.
                let prev = photon_at(store, path, k as usize - 1);
                let escape = store.escape[path].get();
                let material = &scene.materials[scene.objects[prev.object as usize].material as usize];
                let w = material.sampled_weight(
                    photon_normals(scene, &prev),
                    -prev.incoming,
                    escape,
                    Transport::Importance,
                );
                let q = w.max_component().min(1.0);
                if q <= 0.0 {
                    tail.from = k;
                    return None;
                }
                (leaving(scene, &prev, escape), escape, prev.power * w / q, k)
            }
            Retrace::FreshFrom(k) | Retrace::Redirect(k) => {
                let prev = photon_at(store, path, k as usize - 1);
                let roulette = matches!(how, Retrace::FreshFrom(_));
                match scatter(scene, &prev, rng, roulette) {
                    Some((o, d, p)) => (o, d, p, k),
                    None => {
                        tail.from = k;
                        return None;
                    }
                }
            }
        };
        tail.from = from;
        Some((origin, dir, power))
    }

    /// Follows a segment until roulette, a light, the photon limit, or the scene's end, adding
    /// a photon to `tail` at every object hit.
    fn follow(
        &self,
        store: &PathStore,
        tail: &mut TracedTail,
        (mut origin, mut dir, mut power): (Vec3, Vec3, Rgb),
        rng: &mut Rng,
    ) {
        let (scene, accel) = (self.scene, self.accel);
        let max = store.max_photons as u32;
        let mut row = tail.from;
        while row < max {
            tail.rays += 1;
            let Some(hit) = accel.scene().intersect1(&Ray::new(origin, dir)) else {
                tail.escape = PackedDir::new(dir);
                break;
            };
            let Some((SurfaceId::Object(object), prim)) = accel.resolve(&hit) else {
                // A light absorbs the path; its last segment is kept like an escape, so an
                // object moving into it is noticed.
                tail.escape = PackedDir::new(dir);
                break;
            };
            let sp = scene.surface_point(SurfaceId::Object(object), prim, hit.u, hit.v);
            let photon = Photon { position: sp.p, incoming: dir, object, prim, power };
            tail.photons.push(pack(store, &photon));
            row += 1;
            if row >= max {
                break;
            }
            match scatter(scene, &photon, rng, true) {
                Some((o, d, p)) => {
                    origin = o;
                    dir = d;
                    power = p;
                }
                None => break,
            }
        }
    }
}

/// A ray origin leaving photon `p` along `dir`, offset to the side `dir` leaves from.
pub fn leaving(scene: &Scene, p: &Photon, dir: Vec3) -> Vec3 {
    offset_towards(p.position, surface_normal(scene, p), dir)
}

/// `position` offset off its surface (normal `n`) to the side `dir` points to.
fn offset_towards(position: Vec3, n: Vec3, dir: Vec3) -> Vec3 {
    offset_ray_origin(position, if n.dot(dir) >= 0.0 { n } else { -n })
}

/// Unit geometric normal of the triangle a photon lies on.
pub fn surface_normal(scene: &Scene, p: &Photon) -> Vec3 {
    scene.normal(SurfaceId::Object(p.object), p.prim)
}

/// Both normals where a photon lies.
pub fn photon_normals(scene: &Scene, p: &Photon) -> Normals {
    scene.normals_at(p.object, p.prim, p.position)
}

/// Samples the BSDF at a photon; returns the next ray and flux, divided by the continuation
/// probability q = min(1, max weight). With `roulette` the path ends with probability 1 − q;
/// without, the caller knows the path already survived q at this photon.
fn scatter(scene: &Scene, p: &Photon, rng: &mut Rng, roulette: bool) -> Option<(Vec3, Vec3, Rgb)> {
    let material = &scene.materials[scene.objects[p.object as usize].material as usize];
    let normals = photon_normals(scene, p);
    let n = normals.geometric;
    let bs = material.sample(normals, -p.incoming, rng.next_2d(), rng.next_f32(), Transport::Importance)?;
    let q = bs.weight.max_component().min(1.0);
    if q <= 0.0 || (roulette && rng.next_f32() >= q) {
        return None;
    }
    Some((offset_towards(p.position, n, bs.wi), bs.wi, p.power * bs.weight / q))
}

/// Photon `p` packed as the store keeps it.
fn pack(store: &PathStore, p: &Photon) -> StoredPhoton {
    let surface = store.surfaces.id(p.object, p.prim);
    StoredPhoton { position: p.position, incoming: PackedDir::new(p.incoming), surface, power: p.power }
}

/// Writes photon `p` into row `row` of path `path`.
pub fn put_photon(store: &mut PathStore, row: usize, path: usize, p: &Photon) {
    store.put(row, path, pack(store, p));
}

/// Writes traced tails back into the store: each photon row on a worker of its own, beside the
/// paths' own fields. The retrace ran in parallel, and writing its tails on one thread took 70–177
/// ms of walker's 460–750 ms full retrace (`docs/benchmarks.md`, stop 58).
pub fn write_back(store: &mut PathStore, tails: Vec<TracedTail>) {
    let PathStore { rows, word, origin, emit_dir, emit_power, escape, .. } = store;
    let tails = &tails;
    rayon::join(
        || {
            rows.par_iter_mut().enumerate().for_each(|(k, row)| {
                for t in tails {
                    if let Some(&p) = (k as u32).checked_sub(t.from).and_then(|j| t.photons.get(j as usize)) {
                        row.put(t.path, p);
                    }
                }
            })
        },
        || {
            for t in tails {
                let i = t.path;
                if let Some(c) = t.cell {
                    word[i] = word[i].with_cell(c);
                }
                debug_assert!(word[i].replace(), "path {i} traced without being marked");
                if let Some((o, d, p)) = t.emission {
                    word[i] = word[i].with_reused_light(false);
                    if let Some(origins) = origin {
                        origins[i] = o;
                    }
                    emit_dir[i] = d;
                    emit_power[i] = p;
                }
                word[i] = word[i].cleared().with_photons(t.from + t.photons.len() as u32);
                escape[i] = t.escape;
            }
        },
    );
}
