//! Radiance particles and their estimation lists (Chang et al. §3.2).
//!
//! Every triangle of a diffuse object is split into m² subtriangles, m the least with edges
//! below the threshold; the radiance particles are the subtriangle vertices, never stored: a
//! particle is an id (per-triangle offset + the vertex's place in the triangle's grid) and its
//! position is recomputed from the triangle. A shading point interpolates the three vertices
//! of its subtriangle linearly. Each vertex has one particle per side, as area particles do.
//!
//! Estimation lists hold the area particles within radius R of a radiance particle whose
//! normals are within the cosine threshold, on the radiance particle's own object and side
//! (of the triangles' winding): the rule link ends follow, so light never crosses a contact
//! (a box standing on a lit floor keeps a dark inside and underside, though the floor's
//! particles lie within R of its bottom and face the same way as its inner side), nor a
//! closed object's wall thinner than R (its inner side's particles face the way the outer
//! side's do across the wall). Beyond the paper, they are built only for radiance
//! particles a camera sample actually needs, cached across ticks, and dropped when their own
//! object moves: a list depends on nothing else, so another object's move leaves it as a
//! rebuild would make it. A list that would be empty falls back to the nearest particle on
//! the same side of the same object, so every shading point gets an estimate.
use super::grid::ObjectGrids;
use super::particles::{pose, AreaParticles};
use crate::scene::{HitTriangle, Scene};
use glam::{Vec2, Vec3};

/// A radiance particle on one side: `object << OBJECT_SHIFT | id << 1 | side`, its id counted
/// within its object, so each object has its own key space and re-tessellating one object
/// leaves every other key alone.
pub type RadianceKey = u64;

/// Where a key's object starts: ids below 2³⁹ per object.
pub const OBJECT_SHIFT: u32 = 40;

/// A key's object and its place within the object's space (`id << 1 | side`).
pub fn key_parts(key: RadianceKey) -> (usize, usize) {
    ((key >> OBJECT_SHIFT) as usize, (key & ((1 << OBJECT_SHIFT) - 1)) as usize)
}

/// Where a radiance particle sits: its triangle and its vertex of the triangle's m-grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertex {
    pub object: u32,
    pub triangle: u32,
    pub i: u16,
    pub j: u16,
    pub m: u16,
    /// 0: the side of the triangle's winding normal; 1: the other.
    pub side: u8,
}

impl Vertex {
    /// World position and the unit normal of its side.
    pub fn pose(&self, scene: &Scene) -> (Vec3, Vec3) {
        let m = self.m as f32;
        let (p, n) = pose(scene, self.object, self.triangle, Vec2::new(self.i as f32 / m, self.j as f32 / m));
        (p, if self.side == 0 { n } else { -n })
    }
}

/// The implicit radiance particles of every diffuse triangle.
#[derive(Clone, Debug, Default)]
pub struct Tessellation {
    /// Per object and triangle: the first id (within the object) and m (none for objects
    /// without particles).
    first: Vec<Vec<u32>>,
    level: Vec<Vec<u16>>,
    /// Radiance particles per object (one side), and their sum.
    pub counts: Vec<u64>,
    pub total: u64,
}

/// Index of grid vertex (i, j), i + j ≤ m, in a triangle with m subdivisions (row i holds
/// m + 1 − i vertices).
fn local_index(i: u32, j: u32, m: u32) -> u32 {
    i * (m + 1) - i * (i.saturating_sub(1)) / 2 + j
}

impl Tessellation {
    /// Splits every triangle of the diffuse objects so subtriangle edges stay below `max_edge`.
    pub fn build(scene: &Scene, max_edge: f32) -> Tessellation {
        let n = scene.objects.len();
        let mut t =
            Tessellation { first: vec![Vec::new(); n], level: vec![Vec::new(); n], counts: vec![0; n], total: 0 };
        for object in 0..n {
            t.build_object(scene, object, max_edge);
        }
        t
    }

    /// Re-splits one object's triangles (after a change of scale).
    pub fn build_object(&mut self, scene: &Scene, object: usize, max_edge: f32) {
        let o = &scene.objects[object];
        let diffuse = !scene.materials[o.material as usize].is_specular();
        let (mut first, mut level, mut next) = (Vec::new(), Vec::new(), 0u64);
        for &HitTriangle { vertices: [a, b, c], .. } in o.hit_triangles.iter().filter(|_| diffuse) {
            let edge = (b - a).length().max((c - b).length()).max((a - c).length());
            let m = ((edge / max_edge).ceil() as u32).clamp(1, u16::MAX as u32 / 2);
            first.push(next.min(u32::MAX as u64) as u32);
            level.push(m as u16);
            next += ((m + 1) * (m + 2) / 2) as u64;
        }
        self.total = self.total - self.counts[object] + next;
        (self.first[object], self.level[object], self.counts[object]) = (first, level, next);
    }

    /// The three radiance particles around barycentrics `uv` of a triangle, on `side`, with
    /// their interpolation weights. `None` for triangles without radiance particles.
    pub fn corners(&self, object: u32, triangle: u32, uv: Vec2, side: u8) -> Option<[(RadianceKey, Vertex, f32); 3]> {
        let first = *self.first.get(object as usize)?.get(triangle as usize)?;
        let m = self.level[object as usize][triangle as usize] as u32;
        let (su, sv) = (uv.x.clamp(0.0, 1.0) * m as f32, uv.y.clamp(0.0, 1.0) * m as f32);
        let (mut i, mut j) = (su.floor() as u32, sv.floor() as u32);
        if i + j >= m {
            // On the far edge: step back into the last cell.
            (i, j) = (i.min(m.saturating_sub(1)), j.min(m.saturating_sub(1 + i.min(m.saturating_sub(1)))));
        }
        let (fu, fv) = (su - i as f32, sv - j as f32);
        let vertex = |i: u32, j: u32| {
            let id = first as u64 + local_index(i, j, m) as u64;
            let v = Vertex { object, triangle, i: i as u16, j: j as u16, m: m as u16, side };
            ((object as u64) << OBJECT_SHIFT | id << 1 | side as u64, v)
        };
        let with = |(k, v): (RadianceKey, Vertex), w: f32| (k, v, w.max(0.0));
        Some(if fu + fv <= 1.0 || i + j + 2 > m {
            [with(vertex(i, j), 1.0 - fu - fv), with(vertex(i + 1, j), fu), with(vertex(i, j + 1), fv)]
        } else {
            [
                with(vertex(i + 1, j + 1), fu + fv - 1.0),
                with(vertex(i, j + 1), 1.0 - fu),
                with(vertex(i + 1, j), 1.0 - fv),
            ]
        })
    }

    pub fn memory_bytes(&self) -> u64 {
        self.first.iter().map(|f| f.len() as u64 * 6).sum()
    }
}

/// A cached estimation list.
#[derive(Clone, Debug, Default)]
pub struct EstimationList {
    pub particles: Vec<u32>,
}

/// Whether area particle `k`, of the radiance particle's object and side, belongs in the list
/// of a radiance particle at `q` with normal `n`.
fn admitted(particles: &AreaParticles, k: usize, q: Vec3, n: Vec3, radius: f32, min_cosine: f32) -> bool {
    (particles.position[k] - q).length_squared() <= radius * radius && particles.normal[k].dot(n) >= min_cosine
}

/// Estimation lists of the radiance particles needed so far, indexed directly by key: per
/// object, per key within it (`id << 1 | side`), the slot of its list ([`NO_LIST`]: none).
#[derive(Clone, Debug, Default)]
pub struct EstimationLists {
    slots: Vec<Vec<u32>>,
    lists: Vec<EstimationList>,
    /// Slots of `lists` whose list was dropped, reused first.
    free: Vec<u32>,
}

/// A key without a list.
const NO_LIST: u32 = u32::MAX;

/// Bytes per radiance particle and side the index holds.
pub const INDEX_BYTES_PER_KEY: u64 = 4;

impl EstimationLists {
    /// Builds the list of radiance particle `v`: area particles of `v`'s object and side within
    /// `radius` whose normal has a cosine of at least `min_cosine` with `v`'s, in index order.
    pub fn build(
        scene: &Scene,
        particles: &AreaParticles,
        grids: &ObjectGrids,
        v: &Vertex,
        radius: f32,
        min_cosine: f32,
    ) -> EstimationList {
        let (q, n) = v.pose(scene);
        let grid = grids.side(v.object as usize, v.side as usize);
        let mut found = Vec::new();
        grid.within(q, radius, |i| {
            if admitted(particles, i as usize, q, n, radius, min_cosine) {
                found.push(i);
            }
        });
        found.sort_unstable();
        found.dedup();
        if found.is_empty() {
            found.extend(grid.nearest(particles, q, 8, |k| particles.normal[k].dot(n) > 0.0));
        }
        EstimationList { particles: found }
    }

    /// No lists, for the radiance particles of `tessellation` (both sides each).
    pub fn new(tessellation: &Tessellation) -> EstimationLists {
        let slots = tessellation.counts.iter().map(|&c| vec![NO_LIST; 2 * c as usize]).collect();
        EstimationLists { slots, lists: Vec::new(), free: Vec::new() }
    }

    fn slot(&self, key: RadianceKey) -> Option<usize> {
        let (object, local) = key_parts(key);
        let slot = *self.slots.get(object)?.get(local)?;
        (slot != NO_LIST).then_some(slot as usize)
    }

    pub fn get(&self, key: RadianceKey) -> Option<&EstimationList> {
        self.slot(key).map(|s| &self.lists[s])
    }

    pub fn contains(&self, key: RadianceKey) -> bool {
        self.slot(key).is_some()
    }

    /// Holds `list` as `key`'s (a key of the tessellation the index was made or reset for).
    pub fn insert(&mut self, key: RadianceKey, list: EstimationList) {
        let (object, local) = key_parts(key);
        let at = &mut self.slots[object][local];
        if *at != NO_LIST {
            self.lists[*at as usize] = list;
        } else if let Some(s) = self.free.pop() {
            (*at, self.lists[s as usize]) = (s, list);
        } else {
            *at = self.lists.len() as u32;
            self.lists.push(list);
        }
    }

    /// Lists held.
    pub fn len(&self) -> usize {
        self.lists.len() - self.free.len()
    }

    /// Drops the lists of radiance particles on a moved object (`moved[object]`): they are
    /// made of their own object's particles only.
    pub fn invalidate(&mut self, moved: &[bool]) {
        for object in 0..self.slots.len() {
            if moved.get(object).copied().unwrap_or(true) {
                self.drop_object(object);
            }
        }
    }

    /// Drops `object`'s lists and makes room for its `count` radiance particles per side (it
    /// was tessellated again).
    pub fn reset_object(&mut self, object: usize, count: u64) {
        self.drop_object(object);
        self.slots[object] = vec![NO_LIST; 2 * count as usize];
    }

    fn drop_object(&mut self, object: usize) {
        for at in self.slots[object].iter_mut().filter(|at| **at != NO_LIST) {
            self.lists[*at as usize] = EstimationList::default();
            self.free.push(std::mem::replace(at, NO_LIST));
        }
    }

    pub fn memory_bytes(&self) -> u64 {
        let index = self.slots.iter().map(|s| s.len() as u64 * INDEX_BYTES_PER_KEY).sum::<u64>();
        let lists = self.lists.iter().map(|l| (std::mem::size_of::<EstimationList>() + l.particles.len() * 4) as u64);
        index + lists.sum::<u64>()
    }
}

#[cfg(test)]
mod tests {
    use super::super::particles::Layout;
    use super::*;

    #[test]
    fn grid_vertices_are_numbered_densely() {
        for m in 1..6u32 {
            let mut seen = Vec::new();
            for i in 0..=m {
                for j in 0..=(m - i) {
                    seen.push(local_index(i, j, m));
                }
            }
            let count = ((m + 1) * (m + 2) / 2) as usize;
            seen.sort_unstable();
            assert_eq!(seen, (0..count as u32).collect::<Vec<_>>(), "m = {m}");
        }
    }

    use crate::scene::SceneDesc;

    /// A floor with a small box standing on it (normals of every orientation near the floor).
    fn scene() -> Scene {
        let desc: SceneDesc = serde_json::from_value(serde_json::json!({
            "camera": {"position": [0, 2, -3], "look_at": [0, 0, 0], "vfov_deg": 50, "resolution": [8, 8]},
            "materials": {"white": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
            "objects": [
                {"name": "floor", "shape": {"type": "quad"}, "material": "white",
                 "transform": {"rotation": [-0.70710677, 0.0, 0.0, 0.70710677], "scale": [2, 2, 1]}},
                {"name": "box", "shape": {"type": "box"}, "material": "white",
                 "transform": {"translation": [0, 0.3, 0], "scale": [0.3, 0.3, 0.3]}}
            ],
            "lights": [{"name": "lamp", "emitter": {"type": "point", "intensity": [1, 1, 1]},
                        "transform": {"translation": [0, 2, 0]}}]
        }))
        .expect("scene JSON");
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        Scene::from_desc(desc, &dir, &dir).expect("scene")
    }

    /// The scene's particles (6 000), grids and tessellation, with the default radius and cosine.
    struct Fixture {
        scene: Scene,
        particles: AreaParticles,
        grids: ObjectGrids,
        tessellation: Tessellation,
        radius: f32,
        cosine: f32,
    }

    fn fixture() -> Fixture {
        let scene = scene();
        let particles = AreaParticles::sample(&scene, &Layout::plan(&scene, 6000, None), 3);
        let spacing = particles.area.sqrt();
        let grids = ObjectGrids::build(&particles, scene.objects.len(), spacing);
        let tessellation = Tessellation::build(&scene, 1.5 * spacing);
        Fixture { scene, particles, grids, tessellation, radius: 2.0 * spacing, cosine: 0.9 }
    }

    #[test]
    fn estimation_lists_hold_exactly_the_near_particles_with_similar_normals() {
        let Fixture { scene, particles, grids, tessellation, radius, cosine } = fixture();
        let mut checked = 0;
        for object in 0..2u32 {
            for triangle in 0..2u32 {
                for (u, v) in [(0.1, 0.1), (0.5, 0.3), (0.2, 0.7)] {
                    for side in 0..2u8 {
                        let corners = tessellation.corners(object, triangle, Vec2::new(u, v), side).expect("corners");
                        for (_, vertex, _) in corners {
                            let list = EstimationLists::build(&scene, &particles, &grids, &vertex, radius, cosine);
                            let (q, n) = vertex.pose(&scene);
                            let brute: Vec<u32> = (0..particles.len() as u32)
                                .filter(|&i| {
                                    let k = i as usize;
                                    particles.object[k] == object
                                        && k % 2 == side as usize
                                        && (particles.position[k] - q).length_squared() <= radius * radius
                                        && particles.normal[k].dot(n) >= cosine
                                })
                                .collect();
                            if brute.is_empty() {
                                // The fallback: one particle, on the same side of the same object.
                                assert_eq!(list.particles.len(), 1);
                                let k = list.particles[0] as usize;
                                assert!(particles.object[k] == object && k % 2 == side as usize);
                                assert!(particles.normal[k].dot(n) > 0.0);
                            } else {
                                assert_eq!(list.particles, brute, "object {object} triangle {triangle} side {side}");
                                checked += 1;
                            }
                        }
                    }
                }
            }
        }
        assert!(checked > 20, "too few lists checked: {checked}");
    }

    #[test]
    fn another_objects_move_keeps_a_list_as_a_rebuild_makes_it() {
        // Property: a list holds only its own object's particles, so when the box's particles
        // move, `invalidate` keeps the floor's lists, even those within R of the box, and each
        // equals the list built afresh after the move; the box's go. Negative control: the
        // box's own lists, built again after the move, differ from before it.
        let Fixture { scene, mut particles, mut grids, tessellation, radius, cosine } = fixture();
        let mut lists = EstimationLists::new(&tessellation);
        let mut vertices = Vec::new();
        // The box is 0.6 wide, centred 0.3 above the floor's centre.
        let near_box = |q: Vec3| (q - Vec3::new(0.0, 0.3, 0.0)).length() < 0.52 + radius;
        for object in 0..2u32 {
            for triangle in 0..2u32 {
                let grid = (1..20).flat_map(|a| (1..20 - a).map(move |b| (a as f32 / 20.0, b as f32 / 20.0)));
                for (u, v) in grid {
                    let corners = tessellation.corners(object, triangle, Vec2::new(u, v), 0).expect("corners");
                    for (key, vertex, _) in corners {
                        lists.insert(key, EstimationLists::build(&scene, &particles, &grids, &vertex, radius, cosine));
                        vertices.push((key, vertex));
                    }
                }
            }
        }
        let floor_near = vertices.iter().filter(|(_, v)| v.object == 0 && near_box(v.pose(&scene).0)).count();
        assert!(floor_near > 4, "too few floor lists near the box: {floor_near}");
        let before = lists.clone();
        for k in particles.range_of(1) {
            particles.position[k] += Vec3::new(0.05, 0.0, 0.1);
        }
        grids.rebuild(&particles, 1);
        lists.invalidate(&[false, true]);
        let mut changed = 0;
        for (key, vertex) in &vertices {
            let fresh = EstimationLists::build(&scene, &particles, &grids, vertex, radius, cosine);
            match vertex.object {
                0 => assert_eq!(lists.get(*key).map(|l| &l.particles), Some(&fresh.particles), "floor {key}"),
                _ => {
                    assert!(!lists.contains(*key), "a list of the moved box was kept");
                    changed += usize::from(before.get(*key).expect("held before").particles != fresh.particles);
                }
            }
        }
        assert!(changed > 0, "the move changed no list of the box: the control shows nothing");
    }

    #[test]
    fn the_floor_lies_within_the_lists_reach_of_the_box_bottom() {
        // The negative control of `no_light_crosses_a_contact` (tests/particle_gi.rs): the
        // box's bottom rests on the floor, so radiance particles on its inner side (facing up)
        // have floor particles, facing up too, within R. Without the object rule they would
        // join the list; with it none does.
        let Fixture { scene, particles, grids, tessellation, radius, cosine } = fixture();
        let (mut bottoms, mut reachable) = (0, 0);
        for triangle in 0..scene.objects[1].mesh.triangles.len() as u32 {
            for side in 0..2u8 {
                let corners = tessellation.corners(1, triangle, Vec2::new(0.3, 0.3), side).expect("corners");
                for (_, vertex, _) in corners {
                    let (q, n) = vertex.pose(&scene);
                    if q.y.abs() > 1e-4 || n.y < 0.99 {
                        continue;
                    }
                    bottoms += 1;
                    let floor = particles.range_of(0);
                    reachable += floor.filter(|&k| admitted(&particles, k, q, n, radius, cosine)).count();
                    let list = EstimationLists::build(&scene, &particles, &grids, &vertex, radius, cosine);
                    assert!(list.particles.iter().all(|&k| particles.object[k as usize] == 1), "{:?}", list.particles);
                }
            }
        }
        assert!(bottoms > 0 && reachable > 0, "no contact to test: {bottoms} radiance particles, {reachable} near");
    }
}
