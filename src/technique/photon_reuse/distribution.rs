//! Distribution maps (Moreau et al. 2019, §3.1): a partition of a light's emitted rays into
//! cells, with the number of paths each cell should hold (DM_T) and the number it holds
//! (DM_C). Keeping DM_C at DM_T while a light moves keeps its photons spread as its emission
//! distribution says, although every kept path keeps its first photon.
//!
//! # Parametrisations
//! Directions are taken in the light's emission frame ([`ShadingFrame`] around its axis or
//! normal), so a cell means the same rays whatever the light's placement:
//! - point: (cos θ, φ) over the sphere, cos θ in [−1, 1];
//! - spot: (cos θ, φ) inside the cone, cos θ in [cos θ_max, 1];
//! - rect and disc: (u, v, sin²θ, φ): the object-space point on the shape ([−1, 1]² split into
//!   `position` cells) and a cosine-weighted direction (sin²θ is uniform under cosine sampling).
//!
//! Every light samples uniformly in these coordinates (the emission weight carries falloff), so
//! DM_T is uniform over directions and, for area lights, proportional to the shape's area inside
//! each position cell (exact, by clipping its triangles). Cell indices fit the path word's 22
//! bits: at most 2²² cells.
use crate::core::{offset_ray_origin, Rng, ShadingFrame};
use crate::scene::light::LightGeometry;
use crate::scene::Scene;
use glam::{Affine3A, Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;

/// Cells per distribution map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapResolution {
    /// Cells across an area light's surface, (u, v). Unused for point and spot lights.
    pub position: [u32; 2],
    /// Cells over directions, (θ, φ).
    pub direction: [u32; 2],
}

impl Default for MapResolution {
    /// The paper's 8×8×64×64 for area lights; point and spot lights use the 64×64 directions.
    fn default() -> MapResolution {
        MapResolution { position: [8, 8], direction: [64, 64] }
    }
}

/// Largest cell count a path word can address.
pub const MAX_CELLS: u64 = 1 << 22;

impl MapResolution {
    /// Cells of an area light's map (the largest of the three kinds).
    pub fn area_cells(&self) -> u64 {
        self.position.iter().chain(&self.direction).map(|&n| n as u64).product()
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.position.iter().chain(&self.direction).any(|&n| n == 0) {
            return Err("every resolution must be at least 1".into());
        }
        if self.area_cells() > MAX_CELLS {
            return Err(format!("{} cells exceed the path word's {MAX_CELLS}", self.area_cells()));
        }
        Ok(())
    }
}

#[derive(Clone, Debug)]
enum Kind {
    Sphere,
    Cone {
        cos_max: f32,
    },
    /// Object-space triangles of the shape (z = 0) and the world-space normal.
    Area {
        triangles: Vec<[Vec2; 3]>,
        normal: Vec3,
    },
}

/// A light's current placement, as the map's coordinates need it.
#[derive(Clone, Debug)]
pub struct EmissionFrame {
    kind: Kind,
    frame: ShadingFrame,
    world_from_object: Affine3A,
    object_from_world: Affine3A,
    resolution: MapResolution,
}

impl EmissionFrame {
    /// The frame of light `light` as the scene holds it now; `None` for an area light without
    /// triangles (it emits nothing) and for lights from outside, which never move (an edit of
    /// their emission re-emits their paths).
    pub fn of(scene: &Scene, light: usize, resolution: MapResolution) -> Option<EmissionFrame> {
        let desc = scene.desc().lights.get(light)?;
        let world_from_object = desc.transform.world_from_object();
        let (kind, axis) = match &scene.lights[light].geometry {
            LightGeometry::Point { .. } => (Kind::Sphere, (desc.transform.rotation() * Vec3::Z).normalize()),
            LightGeometry::Spot { axis, cos_falloff_end, .. } => (Kind::Cone { cos_max: *cos_falloff_end }, *axis),
            LightGeometry::Area { triangles, .. } => {
                let [a, b, c] = *triangles.first()?;
                let normal = (b - a).cross(c - a).normalize();
                let mesh = scene.lights[light].mesh.as_ref()?;
                let flat = (0..mesh.triangles.len()).map(|i| mesh.triangle(i).map(|p| p.truncate())).collect();
                (Kind::Area { triangles: flat, normal }, normal)
            }
            LightGeometry::Directional { .. } | LightGeometry::Environment { .. } => return None,
        };
        Some(EmissionFrame {
            kind,
            frame: ShadingFrame::from_normal(axis),
            world_from_object,
            object_from_world: world_from_object.inverse(),
            resolution,
        })
    }

    pub fn world_from_object(&self) -> Affine3A {
        self.world_from_object
    }

    pub fn is_area(&self) -> bool {
        matches!(self.kind, Kind::Area { .. })
    }

    pub fn cells(&self) -> usize {
        let [nt, np] = self.resolution.direction;
        let [nu, nv] = if self.is_area() { self.resolution.position } else { [1, 1] };
        (nu * nv * nt * np) as usize
    }

    /// The world-space emitting normal of an area light.
    pub fn normal(&self) -> Option<Vec3> {
        match &self.kind {
            Kind::Area { normal, .. } => Some(*normal),
            _ => None,
        }
    }

    /// Where the line through `through` along `-dir` meets an area light's plane now, if it does
    /// in front of `through` and `dir` leaves the emitting side (§3.1, "update path origins").
    pub fn origin_on_plane(&self, through: Vec3, dir: Vec3) -> Option<Vec3> {
        let normal = self.normal()?;
        let centre = self.world_from_object.transform_point3(Vec3::ZERO);
        let cos = dir.dot(normal);
        if cos <= 0.0 {
            return None;
        }
        let t = (through - centre).dot(normal) / cos;
        (t > 0.0).then(|| offset_ray_origin(through - dir * t, normal))
    }

    /// The cell of a ray leaving `origin` along unit `dir`, or `None` if this light cannot emit
    /// it (outside the cone, behind the area light, off its shape).
    pub fn cell_of(&self, origin: Vec3, dir: Vec3) -> Option<u32> {
        let [nt, np] = self.resolution.direction;
        let local = self.frame.to_local(dir);
        let phi = local.y.atan2(local.x).rem_euclid(2.0 * PI);
        let phi_bin = bin(phi / (2.0 * PI), np);
        let theta_bin = match &self.kind {
            Kind::Sphere => bin((1.0 - local.z) * 0.5, nt),
            Kind::Cone { cos_max } => {
                if local.z < *cos_max {
                    return None;
                }
                bin((1.0 - local.z) / (1.0 - cos_max).max(f32::MIN_POSITIVE), nt)
            }
            Kind::Area { .. } => {
                if local.z <= 0.0 {
                    return None;
                }
                bin(1.0 - local.z * local.z, nt)
            }
        };
        let direction = theta_bin * np + phi_bin;
        match &self.kind {
            Kind::Area { triangles, .. } => {
                let p = self.object_from_world.transform_point3(origin).truncate();
                if !triangles.iter().any(|t| inside_triangle(p, t)) {
                    return None;
                }
                let [nu, nv] = self.resolution.position;
                let position = bin((p.x + 1.0) * 0.5, nu) * nv + bin((p.y + 1.0) * 0.5, nv);
                Some(position * nt * np + direction)
            }
            _ => Some(direction),
        }
    }

    /// Samples a ray inside `cell` uniformly in the map's coordinates: (origin, unit direction).
    /// `None` when an area cell's sliver of the shape was not found in a few tries.
    pub fn sample_in_cell(&self, cell: u32, origin: Vec3, rng: &mut Rng) -> Option<(Vec3, Vec3)> {
        let [nt, np] = self.resolution.direction;
        let direction = cell % (nt * np);
        let (theta_bin, phi_bin) = (direction / np, direction % np);
        let u = rng.next_2d();
        let phi = 2.0 * PI * (phi_bin as f32 + u.y) / np as f32;
        let s = (theta_bin as f32 + u.x) / nt as f32;
        let cos_theta = match &self.kind {
            Kind::Sphere => 1.0 - 2.0 * s,
            Kind::Cone { cos_max } => 1.0 - s * (1.0 - cos_max),
            Kind::Area { .. } => (1.0 - s).max(0.0).sqrt(),
        };
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let dir = self.frame.to_world(Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta)).normalize();
        match &self.kind {
            Kind::Area { triangles, normal } => {
                let [nu, nv] = self.resolution.position;
                let position = cell / (nt * np);
                let lo =
                    Vec2::new((position / nv) as f32 / nu as f32, (position % nv) as f32 / nv as f32) * 2.0 - Vec2::ONE;
                let size = Vec2::new(2.0 / nu as f32, 2.0 / nv as f32);
                for _ in 0..64 {
                    let p = lo + size * rng.next_2d();
                    if triangles.iter().any(|t| inside_triangle(p, t)) {
                        let on_light = self.world_from_object.transform_point3(p.extend(0.0));
                        return Some((offset_ray_origin(on_light, *normal), dir));
                    }
                }
                None
            }
            _ => Some((origin, dir)),
        }
    }

    /// DM_T: `paths` spread over the cells in proportion to the sampling density (uniform over
    /// directions; the shape's area for area-light positions), rounded by largest remainder so
    /// the targets sum to `paths`.
    pub fn targets(&self, paths: u32) -> Vec<u32> {
        let [nt, np] = self.resolution.direction;
        let directions = (nt * np) as usize;
        let position_weights: Vec<f64> = match &self.kind {
            Kind::Area { triangles, .. } => {
                let [nu, nv] = self.resolution.position;
                let size = Vec2::new(2.0 / nu as f32, 2.0 / nv as f32);
                (0..nu * nv)
                    .map(|c| {
                        let lo = Vec2::new((c / nv) as f32, (c % nv) as f32) * size - Vec2::ONE;
                        triangles.iter().map(|t| clipped_area(t, lo, lo + size) as f64).sum()
                    })
                    .collect()
            }
            _ => vec![1.0],
        };
        let total: f64 = position_weights.iter().sum::<f64>() * directions as f64;
        let mut exact: Vec<(usize, f64)> = Vec::with_capacity(self.cells());
        for (p, w) in position_weights.iter().enumerate() {
            for d in 0..directions {
                exact.push((p * directions + d, paths as f64 * w / total.max(f64::MIN_POSITIVE)));
            }
        }
        let mut targets: Vec<u32> = exact.iter().map(|(_, x)| x.floor() as u32).collect();
        let short = paths.saturating_sub(targets.iter().sum::<u32>()) as usize;
        exact.sort_by(|a, b| (b.1 - b.1.floor()).total_cmp(&(a.1 - a.1.floor())).then(a.0.cmp(&b.0)));
        for (cell, _) in exact.iter().take(short) {
            targets[*cell] += 1;
        }
        targets
    }
}

fn bin(x: f32, n: u32) -> u32 {
    ((x * n as f32) as u32).min(n - 1)
}

fn inside_triangle(p: Vec2, [a, b, c]: &[Vec2; 3]) -> bool {
    let edge = |u: Vec2, v: Vec2| (v - u).perp_dot(p - u);
    let (e0, e1, e2) = (edge(*a, *b), edge(*b, *c), edge(*c, *a));
    (e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0) || (e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0)
}

/// Area of a triangle inside the box [lo, hi] (Sutherland–Hodgman clipping, then the shoelace
/// formula).
fn clipped_area(triangle: &[Vec2; 3], lo: Vec2, hi: Vec2) -> f32 {
    let mut poly: Vec<Vec2> = triangle.to_vec();
    for (axis, bound, keep_below) in [(0, lo.x, false), (0, hi.x, true), (1, lo.y, false), (1, hi.y, true)] {
        let inside = |p: Vec2| if keep_below { p[axis] <= bound } else { p[axis] >= bound };
        let mut out = Vec::with_capacity(poly.len() + 2);
        for i in 0..poly.len() {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            if inside(a) {
                out.push(a);
            }
            if inside(a) != inside(b) {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                out.push(a + (b - a) * t);
            }
        }
        poly = out;
        if poly.is_empty() {
            return 0.0;
        }
    }
    let twice: f32 = (0..poly.len()).map(|i| poly[i].perp_dot(poly[(i + 1) % poly.len()])).sum();
    0.5 * twice.abs()
}

/// A light's map: the target and current path counts per cell.
#[derive(Clone, Debug)]
pub struct DistributionMap {
    pub target: Vec<u32>,
    pub current: Vec<u32>,
}

impl DistributionMap {
    pub fn new(target: Vec<u32>) -> DistributionMap {
        let current = vec![0; target.len()];
        DistributionMap { target, current }
    }

    /// Pearson's χ² of the current counts against the targets, over cells with a target (a
    /// path in a cell without one counts as if its target were 1).
    pub fn chi2(&self) -> f64 {
        self.target
            .iter()
            .zip(&self.current)
            .map(|(&t, &c)| {
                let d = c as f64 - t as f64;
                d * d / (t.max(1) as f64)
            })
            .sum()
    }

    /// Does every cell hold exactly its target?
    pub fn settled(&self) -> bool {
        self.target == self.current
    }

    pub fn memory_bytes(&self) -> u64 {
        (self.target.len() + self.current.len()) as u64 * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_recovers_analytic_areas() {
        let t = [Vec2::new(-1.0, -1.0), Vec2::new(1.0, -1.0), Vec2::new(1.0, 1.0)];
        assert!((clipped_area(&t, Vec2::splat(-2.0), Vec2::splat(2.0)) - 2.0).abs() < 1e-6);
        assert!((clipped_area(&t, Vec2::new(0.0, -1.0), Vec2::new(1.0, 0.0)) - 1.0).abs() < 1e-6);
        assert!((clipped_area(&t, Vec2::new(-1.0, 0.0), Vec2::new(0.0, 1.0))).abs() < 1e-6);
        assert!((clipped_area(&t, Vec2::new(0.0, 0.0), Vec2::new(1.0, 1.0)) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn bins_cover_their_range() {
        assert_eq!(bin(0.0, 8), 0);
        assert_eq!(bin(0.999_99, 8), 7);
        assert_eq!(bin(1.0, 8), 7);
        assert!(MapResolution { position: [64, 64], direction: [64, 64] }.validate().is_err());
        assert!(MapResolution::default().validate().is_ok());
    }
}
