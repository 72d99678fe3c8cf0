//! Virtual point lights (Keller 1997, instant radiosity; Debattista et al. §3.1): photons shot
//! from the lights with a Halton sequence at fixed indices, leaving a VPL at every diffuse hit.
//!
//! Path i draws dimension d of its Halton point i + 1: 0 picks the light (by power), 1–2 the
//! point, 3–4 the direction, then 4 per bounce (2 for the BSDF direction, 1 for the lobe,
//! 1 for Russian roulette) for the first [`HALTON_BOUNCES`] bounces; later bounces draw from a
//! generator keyed by (path, bounce). Paths end by Russian roulette only, which is unbiased;
//! [`MAX_VPL_BOUNCES`] is a guard that drops at most ρ^64 of a path's light (6·10⁻⁷ at
//! ρ = 0.8), unless the configuration asks for shorter paths. When nothing changes the VPLs are
//! the same every tick. A VPL's `key`
//! (path, bounce) stays the same until what it depends on changes, so visibility rays are
//! matched across ticks by key. A VPL's `intensity` is Φ·ρ/π, the radiant intensity per unit
//! cosine of the flux Φ it reflects diffusely; Φ is the light's power over the paths shot. On a
//! smooth-shaded mesh it is also times the shading factor of the direction Φ arrived from
//! (`Normals::diffuse_factor`), and its `normal` stays the geometric one, whose cosine the
//! emission takes. Receivers take theirs about their shading normal.
use crate::core::{offset_ray_origin, Rgb};
use crate::embree::Ray;
use crate::scene::{Scene, SceneAccel, SurfaceId, Transport};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

const PRIMES: [u32; 48] = [
    2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71, 73, 79, 83, 89, 97, 101, 103, 107, 109,
    113, 127, 131, 137, 139, 149, 151, 157, 163, 167, 173, 179, 181, 191, 193, 197, 199, 211, 223,
];

/// Bounces whose samples come from the Halton sequence: its dimensions run out after them.
pub const HALTON_BOUNCES: usize = (PRIMES.len() - 5) / 4;

/// The longest VPL path (a guard: roulette ends paths long before), and the stride of keys.
pub const MAX_VPL_BOUNCES: u32 = 64;

/// The four samples of bounce `bounce` of path `index`: BSDF direction (2), lobe, roulette.
fn bounce_samples(index: u64, bounce: usize) -> [f32; 4] {
    if bounce < HALTON_BOUNCES {
        let d = 5 + 4 * bounce;
        [halton(index, d), halton(index, d + 1), halton(index, d + 2), halton(index, d + 3)]
    } else {
        let mut rng = crate::core::Rng::new(index, bounce as u64);
        [rng.next_f32(), rng.next_f32(), rng.next_f32(), rng.next_f32()]
    }
}

/// A digit permutation per Halton dimension, fixed (seeded) and keeping 0 in place so the
/// infinitely many leading zero digits add nothing.
fn digit_permutation(dim: usize) -> Vec<u32> {
    let base = PRIMES[dim % PRIMES.len()];
    let mut perm: Vec<u32> = (0..base).collect();
    let mut rng = crate::core::Rng::new(0x4841_4c54_4f4e, dim as u64); // "HALTON"
    for i in (2..base as usize).rev() {
        let j = 1 + (rng.next_u32() as usize) % i;
        perm.swap(i, j);
    }
    perm
}

/// Dimension `dim` of Halton point `index`: the radical inverse of `index` in the `dim`-th
/// prime, its digits scrambled by a fixed permutation. Plain Halton's high dimensions move in
/// step over the first points (bases 19 and 23 both start 1/b, 2/b, ...), which made the
/// roulette of successive bounces agree and biased a 256-VPL furnace 4.7% high; the scrambling
/// (Faure's remedy, here with seeded permutations) brings it within 0.2%.
pub fn halton(index: u64, dim: usize) -> f32 {
    thread_local! {
        static PERMUTATIONS: Vec<Vec<u32>> = (0..PRIMES.len()).map(digit_permutation).collect();
    }
    let base = PRIMES[dim % PRIMES.len()] as u64;
    PERMUTATIONS.with(|perms| {
        let perm = &perms[dim % PRIMES.len()];
        let (mut n, mut inv, mut result) = (index, 1.0f64 / base as f64, 0.0f64);
        let step = inv;
        while n > 0 {
            result += perm[(n % base) as usize] as f64 * inv;
            n /= base;
            inv *= step;
        }
        (result as f32).min(1.0 - f32::EPSILON)
    })
}

/// A virtual point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vpl {
    pub position: Vec3,
    /// Unit normal on the side the photon arrived from (the side the VPL lights).
    pub normal: Vec3,
    /// Φ·ρ/π (W/sr per unit cosine).
    pub intensity: Rgb,
    /// Where visibility rays to the VPL end: its position offset off its lit side.
    pub anchor: Vec3,
    pub object: u32,
    /// Stable identity: (path index − 1) · [`MAX_VPL_BOUNCES`] + bounce. Ticks compare VPLs by
    /// key, so a path that gains or loses a bounce does not renumber the VPLs of later paths.
    pub key: u32,
}

/// What [`shoot`] made.
#[derive(Debug, Default)]
pub struct Shot {
    pub vpls: Vec<Vpl>,
    pub rays: u64,
    /// The paths the VPLs come from, and the light is divided among.
    pub paths: u64,
    /// The VPL cap stopped shooting before every path asked for was shot.
    pub capped: bool,
}

/// Shoots `paths` photon paths (Halton points first + 1..=first + paths) of at most
/// `max_bounces` bounces and returns their VPLs. Successive generations of a still view take
/// successive runs of points (`first` = generation × paths), so G generations together are the
/// first G × paths points: one VPL set G times larger. The path count, not the VPL count, is
/// fixed: stopping when a VPL budget is reached would divide by a random path count, and the
/// estimate would be biased upwards (measured: +110% at 64 VPLs in the furnace). `max_vpls` is
/// only a memory guard, far above the expected count: if it is reached, the path in flight is
/// dropped and the light is divided among the paths completed before it (a shorter Halton
/// prefix), never among paths not shot.
pub fn shoot(scene: &Scene, accel: &SceneAccel, first: u64, paths: u64, max_vpls: usize, max_bounces: u32) -> Shot {
    let mut shot = Shot { paths, ..Shot::default() };
    let Some(select) = &scene.light_selection else { return shot };
    let max_bounces = max_bounces.min(MAX_VPL_BOUNCES) as usize;
    // One whole path always fits.
    let max_vpls = max_vpls.max(max_bounces);
    for index in first + 1..=first + paths {
        let kept = shot.vpls.len();
        shoot_path(scene, accel, select, index, max_bounces, &mut shot);
        if shot.vpls.len() > max_vpls {
            shot.vpls.truncate(kept);
            shot.paths = index - 1 - first;
            shot.capped = true;
            break;
        }
    }
    let scale = 1.0 / shot.paths.max(1) as f32;
    for v in &mut shot.vpls {
        v.intensity *= scale;
    }
    shot
}

/// Follows path `index`, leaving a VPL at every diffuse hit.
fn shoot_path(
    scene: &Scene,
    accel: &SceneAccel,
    select: &crate::core::sampling::DiscreteDistribution,
    index: u64,
    max_bounces: usize,
    shot: &mut Shot,
) {
    let u = |d: usize| halton(index, d);
    let (light, pmf, _) = select.sample(u(0));
    let Some((origin, dir, weight)) =
        scene.lights[light].geometry.sample_emission(Vec2::new(u(1), u(2)), Vec2::new(u(3), u(4)))
    else {
        return;
    };
    let mut power = weight / pmf;
    let mut ray = Ray::new(origin, dir);
    for bounce in 0..max_bounces {
        shot.rays += 1;
        let Some(hit) = accel.scene().intersect1(&ray) else { break };
        let Some((SurfaceId::Object(object), prim)) = accel.resolve(&hit) else { break };
        let sp = scene.surface_point(SurfaceId::Object(object), prim, hit.u, hit.v);
        let material = &scene.materials[scene.objects[object as usize].material as usize];
        let wo = -ray.dir;
        if !material.is_specular() {
            let facing = if sp.n.dot(wo) >= 0.0 { sp.n } else { -sp.n };
            let intensity = power * material.diffuse_reflectance() * (FRAC_1_PI * sp.normals().diffuse_factor(wo));
            let key = (index - 1) as u32 * MAX_VPL_BOUNCES + bounce as u32;
            shot.vpls.push(Vpl {
                position: sp.p,
                normal: facing,
                intensity,
                anchor: offset_ray_origin(sp.p, facing),
                object,
                key,
            });
        }
        let [d0, d1, lobe, roulette] = bounce_samples(index, bounce);
        let Some(bs) = material.sample(sp.normals(), wo, Vec2::new(d0, d1), lobe, Transport::Importance) else { break };
        let q = bs.weight.max_component().min(1.0);
        if q <= 0.0 || roulette >= q {
            break;
        }
        power = power * bs.weight / q;
        let side = if sp.n.dot(bs.wi) >= 0.0 { sp.n } else { -sp.n };
        ray = Ray::new(offset_ray_origin(sp.p, side), bs.wi);
    }
}

/// Where visibility rays from `x` (unit normal `n` on the side it looks from) start.
pub fn ray_origin(x: Vec3, n: Vec3) -> Vec3 {
    offset_ray_origin(x, n)
}

/// The visibility ray from `from` ([`ray_origin`] of a point) to `vpl`: both ends leave their
/// surface on their lit side, so a ray between the two sides of one thin wall crosses it and
/// is occluded.
pub fn visibility_ray(from: Vec3, vpl: &Vpl) -> Ray {
    // A VPL at the record itself: an empty segment, which nothing occludes.
    crate::technique::nee::shadow_segment(from, vpl.anchor).unwrap_or(Ray::segment(from, Vec3::Z, 0.0))
}

/// The smoothstep clamp of the bounded geometry term (eq. 3): 0 below `a`, 1 above `b`.
pub fn clamp_factor(a: f32, b: f32, x: f32) -> f32 {
    if x > b {
        1.0
    } else if x < a {
        0.0
    } else {
        let t = (x - a) / (b - a);
        3.0 * t * t - 2.0 * t * t * t
    }
}

/// Irradiance at `x` (unit normal `n`, on the side the query looks from) from `vpl`, without
/// visibility: the bounded geometry term G′ (eq. 2) times the VPL's intensity. Returns the
/// value and the unit direction towards the VPL, or `None` if it cannot contribute.
pub fn irradiance_from(vpl: &Vpl, x: Vec3, n: Vec3, min_distance: f32) -> Option<(Rgb, Vec3, f32)> {
    let d = vpl.position - x;
    let dist2 = d.length_squared();
    if dist2 <= 0.0 {
        return None;
    }
    let dist = dist2.sqrt();
    let w = d / dist;
    let (cos_x, cos_y) = (n.dot(w), -vpl.normal.dot(w));
    if cos_x <= 0.0 || cos_y <= 0.0 {
        return None;
    }
    let g = cos_x * cos_y / dist2 * clamp_factor(0.8 * min_distance, 1.2 * min_distance, dist);
    (g > 0.0).then(|| (vpl.intensity * g, w, dist))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halton_points_are_stratified_and_their_dimensions_uncorrelated() {
        // Base 2 has a single non-zero digit to permute: the plain radical inverse.
        assert_eq!((halton(1, 0), halton(2, 0), halton(3, 0)), (0.5, 0.25, 0.75));
        // Stratified: 1000 points of any dimension fill 10 bins evenly.
        for dim in [2, 8, 20] {
            let mut bins = [0; 10];
            for i in 1..=1000 {
                bins[(halton(i, dim) * 10.0) as usize] += 1;
            }
            assert!(bins.iter().all(|&b| (90..=110).contains(&b)), "dim {dim}: {bins:?}");
        }
        // The first points of two high dimensions are not in step (plain Halton's base 19 and
        // 23 both start 1/b, 2/b, ...); the furnace test in tests/instant_cache.rs guards the
        // bias that caused.
        assert!((1..=8u64).any(|i| (halton(i, 7) < halton(i + 1, 7)) != (halton(i, 8) < halton(i + 1, 8))));
    }

    #[test]
    fn the_clamp_is_smooth_and_bounded() {
        assert_eq!(clamp_factor(1.0, 2.0, 0.5), 0.0);
        assert_eq!(clamp_factor(1.0, 2.0, 2.5), 1.0);
        assert!((clamp_factor(1.0, 2.0, 1.5) - 0.5).abs() < 1e-6);
    }
}
