//! Tracing photon paths with Embree: whole paths, kept segments re-intersected, and fresh tails.
//!
//! Every path draws its random numbers from its own stream keyed by (seed, path, generation), so
//! results do not depend on scheduling. Paths end by Russian roulette (continue with probability
//! max(f·cos/pdf), capped at 1), at B photons, on a light (lights absorb), or by leaving the
//! scene. Photons are stored at every surface hit, specular ones included, so that every segment
//! is a straight line between consecutive rows.
use super::store::PathStore;
use crate::core::{offset_ray_origin, Rgb, Rng};
use crate::embree::Ray;
use crate::scene::{Scene, SceneAccel, SurfaceId};
use glam::Vec3;

/// Separates photon random streams from camera streams keyed by the same numbers.
const PHOTON_STREAM: u64 = 0x5048_4f54_4f4e; // "PHOTON"

/// One stored photon.
#[derive(Clone, Copy, Debug)]
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
    /// with a fresh tail (the vertex it leaves did not change).
    KeepSegment(u32),
    /// Sample a fresh direction at photon `k − 1` and trace a fresh tail from there.
    FreshFrom(u32),
}

/// The new tail of a path, computed in parallel and written back afterwards.
#[derive(Clone, Debug)]
pub struct TracedTail {
    pub path: usize,
    /// First row written.
    pub from: u32,
    pub photons: Vec<Photon>,
    pub escape: Vec3,
    /// New segment 0 (origin, direction, flux) when re-emitted.
    pub emission: Option<(Vec3, Vec3, Rgb)>,
    pub rays: u64,
}

fn photon_at(store: &PathStore, path: usize, row: usize) -> Photon {
    let r = &store.rows[row];
    Photon {
        position: r.position[path],
        incoming: r.incoming[path],
        object: r.object[path],
        prim: r.prim[path],
        power: r.power[path],
    }
}

/// The start of segment 0 of a path.
pub fn path_origin(scene: &Scene, store: &PathStore, path: usize) -> Vec3 {
    match &store.origin {
        Some(o) => o[path],
        None => scene.desc().lights[store.light[path] as usize].transform.translation(),
    }
}

/// Traces path `path` as `how` says, reading the store and returning the new tail.
/// `paths_of_light` is how many paths the path's light owns: each carries `1/paths_of_light` of
/// the light's estimated power, so their sum estimates it.
pub fn trace(
    scene: &Scene,
    accel: &SceneAccel,
    store: &PathStore,
    path: usize,
    how: Retrace,
    paths_of_light: u32,
    seed: u64,
) -> TracedTail {
    let generation = store.generation[path].wrapping_add(1);
    let mut rng = Rng::for_sample(seed, generation as u64, path as u64, PHOTON_STREAM);
    let max = store.max_photons as u32;
    let mut tail = TracedTail { path, from: 0, photons: Vec::new(), escape: Vec3::ZERO, emission: None, rays: 0 };

    // Where the traced segment starts, where it goes, with what flux; and whether the vertex it
    // leaves from needs a fresh BSDF sample first.
    let (mut origin, mut dir, mut power, from) = match how {
        Retrace::Emit => {
            let light = &scene.lights[store.light[path] as usize].geometry;
            let Some((o, d, flux_over_pdf)) = light.sample_emission(rng.next_2d(), rng.next_2d()) else {
                tail.emission = Some((path_origin(scene, store, path), Vec3::Z, Rgb::BLACK));
                return tail;
            };
            // Each path carries its light's power divided among that light's paths.
            let power = flux_over_pdf / paths_of_light.max(1) as f32;
            tail.emission = Some((o, d, power));
            (o, d, power, 0)
        }
        Retrace::KeepSegment(0) => (path_origin(scene, store, path), store.emit_dir[path], store.emit_power[path], 0),
        Retrace::KeepSegment(k) => {
            let prev = photon_at(store, path, k as usize - 1);
            let next = photon_at(store, path, k as usize);
            let n = surface_normal(scene, &prev);
            let side = if n.dot(next.incoming) >= 0.0 { n } else { -n };
            (offset_ray_origin(prev.position, side), next.incoming, next.power, k)
        }
        Retrace::FreshFrom(k) => {
            let prev = photon_at(store, path, k as usize - 1);
            match scatter(scene, &prev, &mut rng) {
                Some((o, d, p)) => (o, d, p, k),
                None => {
                    tail.from = k;
                    return tail;
                }
            }
        }
    };
    tail.from = from;

    // Follow the path until roulette, a light, the photon limit, or the scene's end.
    let mut row = from;
    while row < max {
        tail.rays += 1;
        let Some(hit) = accel.scene().intersect1(&Ray::new(origin, dir)) else {
            tail.escape = dir;
            break;
        };
        let Some((SurfaceId::Object(object), prim)) = accel.resolve(&hit) else { break };
        let sp = scene.surface_point(SurfaceId::Object(object), prim, hit.u, hit.v);
        let photon = Photon { position: sp.p, incoming: dir, object, prim, power };
        tail.photons.push(photon);
        row += 1;
        if row >= max {
            break;
        }
        match scatter(scene, &photon, &mut rng) {
            Some((o, d, p)) => {
                origin = o;
                dir = d;
                power = p;
            }
            None => break,
        }
    }
    tail
}

/// Unit geometric normal of the triangle a photon lies on.
fn surface_normal(scene: &Scene, p: &Photon) -> Vec3 {
    let [a, b, c] = scene.triangle(SurfaceId::Object(p.object), p.prim);
    (b - a).cross(c - a).normalize_or_zero()
}

/// Samples the BSDF at a photon with Russian roulette; returns the next ray and flux.
fn scatter(scene: &Scene, p: &Photon, rng: &mut Rng) -> Option<(Vec3, Vec3, Rgb)> {
    let material = &scene.materials[scene.objects[p.object as usize].material as usize];
    let n = surface_normal(scene, p);
    let bs = material.sample(n, -p.incoming, rng.next_2d(), rng.next_f32())?;
    let q = bs.weight.max_component().min(1.0);
    if q <= 0.0 || rng.next_f32() >= q {
        return None;
    }
    let side = if n.dot(bs.wi) >= 0.0 { n } else { -n };
    Some((offset_ray_origin(p.position, side), bs.wi, p.power * bs.weight / q))
}

/// Writes traced tails back into the store.
pub fn write_back(store: &mut PathStore, tails: Vec<TracedTail>) {
    for t in tails {
        let i = t.path;
        if let Some((o, d, p)) = t.emission {
            if let Some(origins) = &mut store.origin {
                origins[i] = o;
            }
            store.emit_dir[i] = d;
            store.emit_power[i] = p;
        }
        for (k, ph) in t.photons.iter().enumerate() {
            let r = &mut store.rows[t.from as usize + k];
            r.position[i] = ph.position;
            r.incoming[i] = ph.incoming;
            r.object[i] = ph.object;
            r.prim[i] = ph.prim;
            r.power[i] = ph.power;
        }
        store.word[i] = store.word[i].cleared().with_photons(t.from + t.photons.len() as u32);
        store.escape[i] = t.escape;
        store.generation[i] = store.generation[i].wrapping_add(1);
    }
}
