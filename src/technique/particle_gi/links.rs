//! Particle links (Chang et al. §3.1): per area particle, n_s × n_s stratified cosine-weighted
//! directions, each traced once and tied to the particle nearest its hit.
//!
//! Link k of particle i has the fixed direction of stratum k jittered by a stream seeded by
//! (seed, set, i), in the frame of the particle's normal, so a link can be re-derived at any
//! time and a retrace gives what a full rebuild would. A hit on a light, a miss, or a hit with
//! no particle nearby ends nowhere ([`NOWHERE`]); a hit on a specular surface ends at
//! [`NON_DIFFUSE`] (this method carries diffuse transport only). The end particle is the
//! nearest one of the hit object on the side the hit triangle turns towards the ray (that
//! side's grid, and a normal facing the ray), never one on another object, so moving one
//! object cannot change where a link to a static surface ends. Each link also keeps its exact
//! hit distance (infinite: none), for the incremental update: its box tests, and the bounded
//! retrace that confirms a link whose segment only nears a moved surface.
//!
//! Beyond the paper, a set can be built lazily: a particle's links are traced the first time
//! they are asked for ([`LinkSet::ensure`]) and stored in the order asked, behind a slot per
//! particle. The gathering set is built so (only particles in a needed estimation list are ever
//! gathered, so sides never seen cost nothing), and so is the scattering set, for the particles
//! the lighting stage's walks can reach from the directly lit ones
//! ([`LinkSet::ensure_reached`]): sides that can never be lit, such as the inside of a closed
//! object or the outside of a closed room, cost nothing. The links themselves do not depend on
//! when they are traced, so a lazy set holds what a full one would for every particle it has.
//! When an object moves, the gathering set forgets its particles' links ([`LinkSet::forget`])
//! rather than retracing them, and only those gathered again are traced again; the scattering
//! set retraces its own, which the next walks need.
use super::grid::ObjectGrids;
use super::particles::AreaParticles;
use super::strata::{StratumCones, MAX_STRATA};
use crate::core::frame::ShadingFrame;
use crate::core::sampling::cosine_hemisphere;
use crate::core::{offset_ray_origin, Rng};
use crate::embree::Ray;
use crate::scene::edits::Aabb;
use crate::scene::{Scene, SceneAccel, SurfaceId};
use crate::technique::box_tree::{BoxTree, SphereCone};
use crate::technique::RenderContext;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// The link ends at no particle.
pub const NOWHERE: u32 = u32::MAX;
/// The link ends on a specular surface.
pub const NON_DIFFUSE: u32 = u32::MAX - 1;
/// Shells of grid cells searched for a hit's nearest particle.
const NEAREST_RINGS: i32 = 2;

/// Bytes a link holds: its end and its hit distance.
pub const BYTES_PER_LINK: u64 = 8;
/// Bytes per link while a batch of links is traced.
pub const TRACING_BYTES_PER_LINK: u64 = std::mem::size_of::<Traced>() as u64;

/// The least strata a set must have for the update to cull by stratum cones: a 4 × 4 set's
/// cones are some 30° wide, so marking them cost more than it saved (merry-go-round's
/// scattering check, 1.0 → 1.7 ms), where a 16 × 16 set's culled three links in four.
const CULLED_STRATA: usize = 64;

/// A particle whose links are not built.
const UNBUILT: u32 = u32::MAX;

/// One set of links (scattering or gathering), for every particle or those asked for so far.
#[derive(Clone, Debug)]
pub struct LinkSet {
    /// n_s: the set has n_s² links per particle.
    pub n: u32,
    /// Salt of the direction streams, different per set.
    salt: u64,
    /// Per particle, its slot in `ends` ([`UNBUILT`] if none); per slot, its particle
    /// ([`UNBUILT`] if free), and the free slots, which [`LinkSet::ensure`] fills first.
    slot: Vec<u32>,
    owner: Vec<u32>,
    free: Vec<u32>,
    /// End particle of link k of the particle in slot s at `s · n² + k`.
    ends: Vec<u32>,
    /// Hit distance of each link (infinite: it hit nothing).
    distance: Vec<f32>,
    /// Cones bounding each stratum's directions, for the update's culling.
    cones: &'static StratumCones,
}

/// What tracing a link found.
struct Traced {
    end: u32,
    distance: f32,
}

/// A link that hit nothing.
const MISSED: Traced = Traced { end: NOWHERE, distance: f32::INFINITY };

/// What links are traced against: the scene, its accel, the particles and their grids.
#[derive(Clone, Copy)]
pub struct Target<'a> {
    pub scene: &'a Scene,
    pub accel: &'a SceneAccel,
    pub particles: &'a AreaParticles,
    pub grids: &'a ObjectGrids,
}

impl<'a> Target<'a> {
    pub fn new(ctx: &RenderContext<'a>, particles: &'a AreaParticles, grids: &'a ObjectGrids) -> Target<'a> {
        Target { scene: ctx.scene, accel: ctx.accel, particles, grids }
    }
}

/// The surfaces that moved this tick, for [`LinkSet::update`].
pub struct Moves<'a> {
    /// Per object: did it move (or change scale)?
    pub moved: &'a [bool],
    /// Per moved surface, the union of its old and new bounds, widened.
    pub spans: Vec<Aabb>,
    /// The old bounds alone, and the new bounds alone.
    pub old: BoxTree,
    pub new: BoxTree,
}

impl LinkSet {
    pub fn per_particle(&self) -> usize {
        (self.n * self.n) as usize
    }

    /// Links built and held.
    pub fn len(&self) -> usize {
        (self.owner.len() - self.free.len()) * self.per_particle()
    }

    /// A set with no links built yet, for `particles` particles.
    pub fn empty(n: u32, salt: u64, particles: usize) -> LinkSet {
        let slot = vec![UNBUILT; particles];
        let (owner, free, ends, distance) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        LinkSet { n, salt, slot, owner, free, ends, distance, cones: StratumCones::of(n) }
    }

    /// The end particles of particle `i`'s links (empty if they are not built).
    pub fn ends_of(&self, i: usize) -> &[u32] {
        match self.slot[i] {
            UNBUILT => &[],
            s => {
                let per = self.per_particle();
                &self.ends[s as usize * per..(s as usize + 1) * per]
            }
        }
    }

    /// Builds the links of the particles of `wanted` that have none, in that order. Returns
    /// the rays traced.
    pub fn ensure(&mut self, target: Target, wanted: impl Iterator<Item = u32>) -> u64 {
        let new: Vec<u32> = wanted.filter(|&i| self.slot[i as usize] == UNBUILT).collect();
        let per = self.per_particle();
        let this = &*self;
        let traced: Vec<Traced> =
            (0..new.len() * per).into_par_iter().map(|l| this.trace(target, new[l / per] as usize, l % per)).collect();
        for (&i, traced) in new.iter().zip(traced.chunks_exact(per)) {
            let s = match self.free.pop() {
                Some(s) => s,
                None => {
                    self.ends.resize(self.ends.len() + per, NOWHERE);
                    self.distance.resize(self.distance.len() + per, f32::INFINITY);
                    self.owner.push(UNBUILT);
                    (self.owner.len() - 1) as u32
                }
            };
            (self.slot[i as usize], self.owner[s as usize]) = (s, i);
            let links = s as usize * per..(s as usize + 1) * per;
            self.ends[links.clone()].iter_mut().zip(traced).for_each(|(e, t)| *e = t.end);
            self.distance[links].iter_mut().zip(traced).for_each(|(d, t)| *d = t.distance);
        }
        traced.len() as u64
    }

    /// Builds the links of every particle reachable from `from` through the set's links (the
    /// particles a walk from them may visit), round by round. Returns the rays traced.
    pub fn ensure_reached(&mut self, target: Target, from: &[u32]) -> u64 {
        let mut seen = vec![false; self.slot.len()];
        let mut frontier: Vec<u32> =
            from.iter().copied().filter(|&i| !std::mem::replace(&mut seen[i as usize], true)).collect();
        let mut traced = 0;
        while !frontier.is_empty() {
            traced += self.ensure(target, frontier.iter().copied());
            let ends = frontier.iter().flat_map(|&i| self.ends_of(i as usize).iter().copied());
            frontier = ends.filter(|&e| e < NON_DIFFUSE && !std::mem::replace(&mut seen[e as usize], true)).collect();
        }
        traced
    }

    /// Forgets the links of the particles with `drop(i)` (their slots are reused), so they are
    /// traced again only if asked for.
    pub fn forget(&mut self, drop: impl Fn(u32) -> bool) {
        for s in 0..self.owner.len() {
            let i = self.owner[s];
            if i != UNBUILT && drop(i) {
                (self.slot[i as usize], self.owner[s]) = (UNBUILT, UNBUILT);
                self.free.push(s as u32);
            }
        }
    }

    /// Unit world direction of link `k` of particle `i`, whose normal's frame is `frame`.
    fn direction(&self, frame: &ShadingFrame, i: usize, k: usize) -> Vec3 {
        let n = self.n as usize;
        let mut rng = Rng::new(self.salt ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15), k as u64);
        let j = rng.next_2d();
        let u = Vec2::new(((k % n) as f32 + j.x) / n as f32, ((k / n) as f32 + j.y) / n as f32);
        frame.to_world(cosine_hemisphere(u))
    }

    /// The shading factor at particle `i` of light arriving back along its link `k` (1 unless
    /// some object is smooth-shaded): what a gather through the link weighs its radiance by.
    pub fn receive_factor(&self, particles: &AreaParticles, i: usize, k: usize) -> f32 {
        if particles.shading.is_empty() {
            return 1.0;
        }
        particles.normals(i).diffuse_factor(self.link_direction(particles, i, k))
    }

    /// The shading factor at `end` of flux arriving along link `k` of particle `i` (1 unless
    /// some object is smooth-shaded): what a scattering deposit there is weighted by.
    pub fn deposit_factor(&self, particles: &AreaParticles, i: usize, k: usize, end: usize) -> f32 {
        if particles.shading.is_empty() {
            return 1.0;
        }
        particles.normals(end).diffuse_factor(-self.link_direction(particles, i, k))
    }

    /// Unit world direction of link `k` of particle `i`, in the frame of its geometric normal.
    fn link_direction(&self, particles: &AreaParticles, i: usize, k: usize) -> Vec3 {
        self.direction(&ShadingFrame::from_normal(particles.normal[i]), i, k)
    }

    fn ray(&self, particles: &AreaParticles, i: usize, k: usize) -> Ray {
        Ray::new(offset_ray_origin(particles.position[i], particles.normal[i]), self.link_direction(particles, i, k))
    }

    fn trace(&self, target: Target, i: usize, k: usize) -> Traced {
        self.trace_before(target, i, k, f32::INFINITY).unwrap_or(MISSED)
    }

    /// Traces link `k` of particle `i` for hits closer than `before` (`None`: there are none).
    fn trace_before(&self, target: Target, i: usize, k: usize, before: f32) -> Option<Traced> {
        let Target { scene, accel, particles, grids } = target;
        let mut ray = self.ray(particles, i, k);
        if before.is_finite() {
            if before <= 0.0 {
                return None;
            }
            // The greatest float below `before` (a positive, finite float's bits are ordered).
            ray.tfar = f32::from_bits(before.to_bits() - 1);
        }
        let hit = accel.scene().intersect1(&ray)?;
        let end = match accel.resolve(&hit) {
            Some((SurfaceId::Object(object), triangle)) => {
                if scene.materials[scene.objects[object as usize].material as usize].is_specular() {
                    NON_DIFFUSE
                } else {
                    // The side hit: the triangle's normal turned towards the ray's origin.
                    let n = scene.surface_point(SurfaceId::Object(object), triangle, hit.u, hit.v).n;
                    let (side, facing) = if n.dot(ray.dir) < 0.0 { (0, n) } else { (1, -n) };
                    grids
                        .side(object as usize, side)
                        .nearest(particles, ray.at(hit.t), NEAREST_RINGS, |j| particles.normal[j].dot(facing) > 0.0)
                        .unwrap_or(NOWHERE)
                }
            }
            _ => NOWHERE,
        };
        Some(Traced { end, distance: hit.t })
    }

    /// Retraces the links that may have changed after surfaces moved. A link of a particle on a
    /// moved object, one ending on a moved object, and one whose hit lies in a moved surface's
    /// old bounds (it may have hit that surface) are traced again in full. Any other link hit
    /// no moved surface, so it changes only if a moved surface now lies in front of its hit:
    /// if its segment touches a new bound, it is traced again up to its old hit, and kept when
    /// nothing is found before. Either way it ends as a full rebuild's would. A particle with
    /// every box behind its tangent plane is skipped whole (its links leave into its
    /// hemisphere), and a link shorter than the way to the nearest box is skipped untested.
    /// Returns the links retraced and box tests.
    pub fn update(&mut self, target: Target, moves: &Moves) -> (u64, u64) {
        let per = self.per_particle();
        let this = &*self;
        let checked: Vec<(Vec<(usize, f32)>, u64)> =
            (0..this.owner.len()).into_par_iter().map(|s| this.stale_links(target.particles, moves, s)).collect();
        let tests: u64 = checked.iter().map(|c| c.1).sum();
        let stale: Vec<(usize, f32)> = checked.into_iter().flat_map(|c| c.0).collect();
        let retraced: Vec<(usize, Traced)> = stale
            .par_iter()
            .filter_map(|&(l, before)| {
                let i = this.owner[l / per] as usize;
                let traced = this.trace_before(target, i, l % per, before);
                match (traced, before.is_finite()) {
                    (Some(t), _) => Some((l, t)),
                    (None, true) => None,
                    (None, false) => Some((l, MISSED)),
                }
            })
            .collect();
        for (l, t) in &retraced {
            self.ends[*l] = t.end;
            self.distance[*l] = t.distance;
        }
        (stale.len() as u64, tests)
    }

    /// The links of the particle in slot `s` to trace again, each with the distance before
    /// which to look (infinite: a full retrace); and the box tests made.
    fn stale_links(&self, particles: &AreaParticles, moves: &Moves, s: usize) -> (Vec<(usize, f32)>, u64) {
        let per = self.per_particle();
        let on_moved = |i: u32| moves.moved[particles.object[i as usize] as usize];
        let i = self.owner[s] as usize;
        let links = s * per..(s + 1) * per;
        if i == UNBUILT as usize {
            return (Vec::new(), 0);
        }
        if on_moved(i as u32) {
            return (links.map(|l| (l, f32::INFINITY)).collect(), 0);
        }
        let (p, n) = (particles.position[i], particles.normal[i]);
        let origin = offset_ray_origin(p, n);
        let in_front = |b: &Aabb| {
            let (centre, half) = ((b.min + b.max) * 0.5, (b.max - b.min) * 0.5);
            n.dot(centre - p) + n.abs().dot(half) >= 0.0
        };
        if !moves.spans.iter().any(in_front) {
            return (Vec::new(), moves.spans.len() as u64);
        }
        let frame = ShadingFrame::from_normal(n);
        let strata = self.reachable_strata(&frame, origin, &moves.spans);
        let reachable = |k: usize| strata.as_ref().is_none_or(|s| s[k] != 0);
        // A link shorter than the way to the nearest box cannot touch one.
        let reach = moves.spans.iter().map(|b| (b.min - origin).max(origin - b.max).max(Vec3::ZERO).length());
        let reach = reach.fold(f32::INFINITY, f32::min);
        let (mut stale, mut tests) = (Vec::new(), 0u64);
        for l in links {
            let (end, t) = (self.ends[l], self.distance[l]);
            if end < NON_DIFFUSE && on_moved(end) {
                stale.push((l, f32::INFINITY));
                continue;
            }
            if t < reach || !reachable(l % per) {
                continue;
            }
            let dir = self.direction(&frame, i, l % per);
            if t.is_finite() {
                let (was_on, count) = moves.old.hits(origin + dir * t, dir, 0.0);
                tests += count;
                if was_on {
                    stale.push((l, f32::INFINITY));
                    continue;
                }
            }
            let (touches, count) = moves.new.hits(origin, dir, t);
            tests += count;
            if touches {
                stale.push((l, t));
            }
        }
        (stale, tests)
    }

    /// The strata whose directions may reach a moved surface from `origin`, whose normal's
    /// frame is `frame`: those whose cones meet the cone around some span's bounding sphere
    /// (`None`: all of them, or a set too coarse for its strata to cull; see [`CULLED_STRATA`]).
    fn reachable_strata(&self, frame: &ShadingFrame, origin: Vec3, spans: &[Aabb]) -> Option<[u8; MAX_STRATA]> {
        if self.per_particle() < CULLED_STRATA {
            return None;
        }
        let mut mask = [0u8; MAX_STRATA];
        for b in spans {
            let cone = SphereCone::new(origin, b)?;
            let axis = frame.to_local(cone.axis);
            // A sphere wholly below the tangent plane is out of every link's reach.
            if axis.z >= -cone.sin {
                self.cones.mark(axis, cone.cos, cone.sin, &mut mask);
            }
        }
        Some(mask)
    }

    pub fn memory_bytes(&self) -> u64 {
        self.ends.len() as u64 * BYTES_PER_LINK + ((self.slot.len() + self.owner.len() + self.free.len()) * 4) as u64
    }
}
