//! Area particles (Chang et al. §3.1): points spread uniformly over the diffuse surfaces, each
//! standing for an area ΔA around it.
//!
//! Sampling is in object space: a particle is (object, triangle, barycentrics), fixed by the
//! seed and the object's index, and its world position is recomputed from the object's current
//! placement, so a rigidly moving object carries its particles and a full rebuild places them
//! bit for bit where the carried ones are. Each sampled point carries two particles, one per
//! side (normals n and −n): surfaces may be lit and seen from either side, and a particle on
//! the side that never receives light costs links but adds no error.
//!
//! ΔA_i is each point's share of its object's area: the part of the surface nearer to it than
//! to any other point (its Voronoi cell), estimated with [`AREA_SAMPLES`] stratified samples
//! per point (add-one smoothed). A link hit goes to the nearest particle, so a particle catches
//! flux in proportion to its cell; dividing by one mean ΔA instead made L = ρ/π·φ/ΔA track the
//! cell size, and the gather, which also lands in large cells more often, came out high (+6%
//! of the furnace's indirect light, where E[c²]/E[c]² = 1.17). Sampling and cells are computed
//! in object space, so a moved object's particles and areas are the same wherever it is
//! (exact for uniform scale; a non-uniformly scaled object gets object-space cells).
//! Units: metres, m².
use super::grid::ParticleGrid;
use crate::core::{Rgb, Rng};
use crate::scene::{Normals, Scene, SceneObject, SurfaceId};
use glam::{Vec2, Vec3};

/// Area particles, structure of arrays; particles 2k and 2k + 1 share point k.
#[derive(Clone, Debug, Default)]
pub struct AreaParticles {
    pub object: Vec<u32>,
    pub triangle: Vec<u32>,
    pub barycentric: Vec<Vec2>,
    pub position: Vec<Vec3>,
    /// Unit geometric normal of the particle's side.
    pub normal: Vec<Vec3>,
    /// Unit shading normal of the particle's side, where some object is smooth-shaded (empty
    /// otherwise, so flat scenes pay nothing for it).
    pub shading: Vec<Vec3>,
    /// ΔA_i (m²) per particle, and its share of its object's area (ΔA_i over the area).
    pub areas: Vec<f32>,
    cell: Vec<f64>,
    /// The mean ΔA (m²): the diffuse area over the points.
    pub area: f32,
}

/// The diffuse objects, which carry particles.
fn diffuse_objects(scene: &Scene) -> Vec<usize> {
    (0..scene.objects.len()).filter(|&i| !scene.materials[scene.objects[i].material as usize].is_specular()).collect()
}

/// Whole points per object from their areas: the largest-remainder rule, so the counts add up
/// to `wanted`, then at least one point (two particles, one per side) for every object with
/// area, so a small object never goes black (PG-1): links that hit it find particles there.
fn points_per_object(areas: &[f64], wanted: f64) -> Vec<u64> {
    let total: f64 = areas.iter().sum();
    let shares: Vec<f64> = areas.iter().map(|a| wanted * a / total).collect();
    let mut points = largest_remainder(&shares);
    for (p, &a) in points.iter_mut().zip(areas) {
        if a > 0.0 {
            *p = (*p).max(1);
        }
    }
    points
}

/// Rounds `shares` to whole numbers that sum to their (whole) total: floors, then one more for
/// the largest remainders.
fn largest_remainder(shares: &[f64]) -> Vec<u64> {
    let mut out: Vec<u64> = shares.iter().map(|s| s.floor() as u64).collect();
    let mut order: Vec<usize> = (0..shares.len()).collect();
    order.sort_by(|&a, &b| (shares[b] - shares[b].floor()).total_cmp(&(shares[a] - shares[a].floor())).then(a.cmp(&b)));
    let missing = (shares.iter().sum::<f64>().round() as u64).saturating_sub(out.iter().sum());
    for &k in order.iter().take(missing as usize) {
        out[k] += 1;
    }
    out
}

/// Points (each two particles, one per side) for `count` particles or one per `area` m², over
/// `total` m² of diffuse surface.
fn planned_points(count: u32, area: Option<f32>, total: f64) -> f64 {
    match area {
        Some(a) => (total / a as f64).round(),
        None => (count / 2) as f64,
    }
    .max(1.0)
}

/// How many points each object gets, and the mean ΔA (m²) they were planned for. It outlives
/// rebuilds while it [`holds`](Layout::holds), so an object's change of scale keeps every
/// object's count and particle indices (the rescaled object's particles are re-placed and
/// their areas rescaled, `AreaParticles::rescale_object`), and a full rebuild makes the same
/// particles an incremental update has.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// Points per object (0 for specular objects).
    pub points: Vec<u64>,
    pub area: f32,
}

impl Layout {
    /// Spreads about `count` particles (or one per `area` m²) over the diffuse objects by area.
    pub fn plan(scene: &Scene, count: u32, area: Option<f32>) -> Layout {
        let diffuse = diffuse_objects(scene);
        let areas: Vec<f64> = diffuse.iter().map(|&i| scaled_area(scene, i)).collect();
        let total: f64 = areas.iter().sum();
        let mut points = vec![0; scene.objects.len()];
        if total <= 0.0 {
            return Layout { points, area: 0.0 };
        }
        for (&object, n) in diffuse.iter().zip(points_per_object(&areas, planned_points(count, area, total))) {
            points[object] = n;
        }
        let placed: u64 = points.iter().sum();
        Layout { points, area: (total / placed.max(1) as f64) as f32 }
    }

    /// Whether every diffuse object's count is still within a factor 2 of its area over the
    /// planned ΔA (hysteresis: scales that come and go within it resample nothing), for the
    /// same objects and materials.
    pub fn holds(&self, scene: &Scene) -> bool {
        let diffuse = diffuse_objects(scene);
        let planned: Vec<usize> = (0..self.points.len()).filter(|&i| self.points[i] > 0).collect();
        self.area > 0.0
            && self.points.len() == scene.objects.len()
            && diffuse == planned
            && diffuse.iter().all(|&i| {
                let ideal = scaled_area(scene, i) / self.area as f64;
                let n = self.points[i] as f64;
                n >= (0.5 * ideal).floor() && n <= (2.0 * ideal).ceil().max(1.0)
            })
    }
}

/// Particles [`AreaParticles::sample`] will make on `scene`, without making them.
pub fn planned_particles(scene: &Scene, count: u32, area: Option<f32>) -> f64 {
    let total: f64 = diffuse_objects(scene).iter().map(|&i| scaled_area(scene, i)).sum();
    if total <= 0.0 {
        return 0.0;
    }
    2.0 * planned_points(count, area, total)
}

/// Bytes per particle as `memory_bytes` counts them, and the temporary bytes per point while
/// its area is estimated (`AREA_SAMPLES` stratified samples of a triangle and a barycentric).
pub const BYTES_PER_PARTICLE: u64 = 4 + 4 + 8 + 12 + 12 + 4 + 8;
pub const SAMPLING_BYTES_PER_POINT: u64 = AREA_SAMPLES * 12;

/// Samples per point for estimating its cell's area.
pub const AREA_SAMPLES: u64 = 64;

/// Uniform points on a triangle's barycentric domain.
fn triangle_point(u: Vec2) -> Vec2 {
    crate::core::sampling::uniform_triangle(u)
}

impl AreaParticles {
    /// The particles of `layout`, grouped by object in object order.
    pub fn sample(scene: &Scene, layout: &Layout, seed: u64) -> AreaParticles {
        let mut out = AreaParticles { area: layout.area, ..AreaParticles::default() };
        for (object, &n) in layout.points.iter().enumerate().filter(|(_, &n)| n > 0) {
            out.sample_object(scene, object, n, scaled_area(scene, object), seed);
        }
        out
    }

    /// After `object`'s scale changed (its layout holding): the same points, re-placed, with
    /// their areas rescaled to its new area, as a rebuild would make them.
    pub fn rescale_object(&mut self, scene: &Scene, object: usize) {
        let range = self.range_of(object);
        let world_area = scaled_area(scene, object);
        for i in range.clone() {
            self.areas[i] = (self.cell[i] * world_area) as f32;
        }
        self.place(scene, range);
    }

    /// The indices of `object`'s particles (they are grouped by object, in object order).
    pub fn range_of(&self, object: usize) -> std::ops::Range<usize> {
        self.object.partition_point(|&o| (o as usize) < object)..self.object.partition_point(|&o| o as usize <= object)
    }

    /// `n` stratified points on `object`, picked by area along its triangles, with their cell
    /// areas.
    fn sample_object(&mut self, scene: &Scene, object: usize, n: u64, world_area: f64, seed: u64) {
        let o = &scene.objects[object];
        let mut rng = Rng::new(seed ^ 0x5041_5254, object as u64); // "PART"
        let points = stratified_points(o, n, &mut rng);
        if points.is_empty() {
            return;
        }
        // Cells: the nearest point of many stratified samples, in object space.
        let local = AreaParticles {
            position: points.iter().map(|&(t, b)| object_point(o, t, b)).collect(),
            ..AreaParticles::default()
        };
        let object_area: f32 = object_triangle_areas(o).iter().sum::<f64>() as f32;
        let members: Vec<u32> = (0..points.len() as u32).collect();
        let grid = ParticleGrid::build(&local, &members, 2.0 * (object_area / n as f32).sqrt().max(f32::MIN_POSITIVE));
        let mut caught = vec![1u64; points.len()];
        let samples = stratified_points(o, n * AREA_SAMPLES, &mut rng);
        for &(t, b) in &samples {
            if let Some(i) = grid.nearest(&local, object_point(o, t, b), 8, |_| true) {
                caught[i as usize] += 1;
            }
        }
        let total: u64 = caught.iter().sum();
        for (&(triangle, b), &c) in points.iter().zip(&caught) {
            let cell = c as f64 / total as f64;
            for _side in 0..2 {
                self.object.push(object as u32);
                self.triangle.push(triangle);
                self.barycentric.push(b);
                self.areas.push((cell * world_area) as f32);
                self.cell.push(cell);
            }
        }
        let first = self.position.len();
        self.position.resize(self.object.len(), Vec3::ZERO);
        self.normal.resize(self.object.len(), Vec3::ZERO);
        if scene.objects.iter().any(|o| !o.shading_normals.is_empty()) {
            self.shading.resize(self.object.len(), Vec3::ZERO);
        }
        self.place(scene, first..self.object.len());
    }

    /// Recomputes the world position and normal of particles `range` from their objects'
    /// current placement.
    pub fn place(&mut self, scene: &Scene, range: std::ops::Range<usize>) {
        for i in range {
            let b = self.barycentric[i];
            let sp = scene.surface_point(SurfaceId::Object(self.object[i]), self.triangle[i], b.x, b.y);
            let side = if i % 2 == 0 { 1.0 } else { -1.0 };
            self.position[i] = sp.p;
            self.normal[i] = sp.n * side;
            if let Some(s) = self.shading.get_mut(i) {
                *s = sp.ns * side;
            }
        }
    }

    /// Particle `i`'s normals (both flat unless some object is smooth-shaded).
    pub fn normals(&self, i: usize) -> Normals {
        let geometric = self.normal[i];
        Normals::new(geometric, self.shading.get(i).copied().unwrap_or(geometric))
    }

    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// The diffuse reflectance of particle `i`'s surface.
    pub fn reflectance(&self, scene: &Scene, i: usize) -> Rgb {
        scene.materials[scene.objects[self.object[i] as usize].material as usize].diffuse_reflectance()
    }

    pub fn memory_bytes(&self) -> u64 {
        self.len() as u64 * BYTES_PER_PARTICLE
    }
}

/// An object's scale with the low 8 mantissa bits cleared: animations that interpolate a
/// constant scale as a·(1 − t) + b·t wobble in the last bits, which would otherwise make a
/// moved object's areas and tessellation differ from a rebuild's.
pub fn stable_scale(scene: &Scene, object: usize) -> Vec3 {
    let s = scene.desc().objects[object].transform.scale;
    Vec3::from(s.map(|x| f32::from_bits(x.to_bits() & !0xFF)))
}

/// An object's area with its (stable) scale applied but not its rotation or translation: its
/// world area, computed so that it is bit for bit the same wherever the object has moved.
fn scaled_area(scene: &Scene, object: usize) -> f64 {
    let o = &scene.objects[object];
    let scale = stable_scale(scene, object);
    o.mesh
        .triangles
        .iter()
        .map(|&[a, b, c]| {
            let (a, b, c) = (
                o.mesh.positions[a as usize] * scale,
                o.mesh.positions[b as usize] * scale,
                o.mesh.positions[c as usize] * scale,
            );
            0.5 * (b - a).cross(c - a).length() as f64
        })
        .sum()
}

/// Object-space triangle areas (independent of where the object is).
fn object_triangle_areas(o: &SceneObject) -> Vec<f64> {
    o.mesh
        .triangles
        .iter()
        .map(|&[a, b, c]| {
            let (a, b, c) = (o.mesh.positions[a as usize], o.mesh.positions[b as usize], o.mesh.positions[c as usize]);
            0.5 * (b - a).cross(c - a).length() as f64
        })
        .collect()
}

/// The object-space point at barycentrics `b` of triangle `t`.
fn object_point(o: &SceneObject, t: u32, b: Vec2) -> Vec3 {
    let [i, j, k] = o.mesh.triangles[t as usize];
    let (p0, p1, p2) = (o.mesh.positions[i as usize], o.mesh.positions[j as usize], o.mesh.positions[k as usize]);
    p0 * (1.0 - b.x - b.y) + p1 * b.x + p2 * b.y
}

/// `n` points (triangle, barycentrics) stratified along the object's cumulative area: point k
/// falls in stratum k of n, uniformly within its triangle.
fn stratified_points(o: &SceneObject, n: u64, rng: &mut Rng) -> Vec<(u32, Vec2)> {
    let areas = object_triangle_areas(o);
    let total: f64 = areas.iter().sum();
    if total <= 0.0 || n == 0 {
        return Vec::new();
    }
    let (mut triangle, mut below) = (0usize, 0.0f64);
    (0..n)
        .map(|k| {
            let target = (k as f64 + rng.next_f32() as f64) / n as f64 * total;
            while triangle + 1 < areas.len() && below + areas[triangle] <= target {
                below += areas[triangle];
                triangle += 1;
            }
            (triangle as u32, triangle_point(rng.next_2d()))
        })
        .collect()
}

/// World position and unit geometric normal at barycentrics `b` of an object's triangle.
pub fn pose(scene: &Scene, object: u32, triangle: u32, b: Vec2) -> (Vec3, Vec3) {
    let sp = scene.surface_point(SurfaceId::Object(object), triangle, b.x, b.y);
    (sp.p, sp.n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_object_with_area_gets_a_point_however_small() {
        // PG-1: 20 points over a room of 64 m² and a box of 0.5 m² (0.8% of the area): its share
        // is 0.16 points, and the rounding alone gives it none (checked here, so the case is a
        // real one), which left every link that hits it without light.
        let areas = [32.0, 16.0, 16.0, 0.5];
        let wanted = 20.0;
        let total: f64 = areas.iter().sum();
        let shares: Vec<f64> = areas.iter().map(|a| wanted * a / total).collect();
        let rounded = largest_remainder(&shares);
        assert_eq!(rounded.iter().sum::<u64>(), 20);
        assert_eq!(rounded[3], 0, "the rounding alone must starve the small box: {rounded:?}");
        let points = points_per_object(&areas, wanted);
        assert!(points.iter().all(|&p| p >= 1), "{points:?}");
        assert_eq!(&points[..3], &rounded[..3], "the large objects keep their rounded counts");
        assert_eq!(points_per_object(&[1.0, 0.0], 4.0), vec![4, 0], "an object without area gets none");
    }
}
