//! Lights in world space: emitted power, next-event sampling of incident radiance, and the
//! solid-angle density of that sampling (for MIS).
//!
//! Units follow pbrt-v4: point and spot intensity in W/sr, area radiance in W/(sr·m²), power in W.
//! Area lights emit from the side their triangles' winding normal faces, and are sampled
//! uniformly by area over their (tessellated) triangles, so the sampled shape is exactly the
//! intersectable one. An area light of two triangles forming a parallelogram (a rect light, or a
//! mesh light such as a glTF export of one) is sampled directly over its two edges, with no
//! choice of triangle: the same density, for 1.01–1.17× `path`'s samples/s on the Cornell box
//! (`docs/benchmarks.md`).
//!
//! Lights from outside (pbrt-v4's infinite lights): a directional light (the sun: irradiance E in
//! W/m² on a surface facing it, from a cone of half-angle θ_max, or a delta direction when
//! θ_max = 0) and a uniform environment (radiance L from every direction). They have no surface:
//! next-event estimation samples their directions (the sun's cone uniformly, the environment
//! cosine-weighted about the receiver's normal), rays that leave the scene see them
//! ([`LightGeometry::escaped`]), and emitted rays start on a disc of the scene's bounding
//! sphere's radius r facing the sampled direction, outside the sphere, so their power is E·πr²
//! (sun) and L·4π·πr² (environment).
//! The sun's cone carries radiance E / (π sin²θ_max), which gives exactly E on a facing surface.
//! The sphere is taken at load: an object moved out of it gets no photons from outside.
use super::model::{EmitterDesc, LightDesc};
use super::shapes::Mesh;
use crate::core::sampling::{self, DiscreteDistribution};
use crate::core::Rgb;
use glam::{Affine3A, Vec2, Vec3};
use std::f32::consts::PI;

/// A light's world-space emission geometry.
#[derive(Clone, Debug)]
pub enum LightGeometry {
    Point {
        position: Vec3,
        intensity: Rgb,
    },
    Spot {
        position: Vec3,
        axis: Vec3,
        intensity: Rgb,
        cos_falloff_start: f32,
        cos_falloff_end: f32,
    },
    /// `normals[i]` is triangle i's unit normal (its emitting side), kept so sampling a point
    /// costs no cross product. `parallelogram` is a corner and two edges when the triangles are
    /// two halves of one, so a point is sampled over it directly.
    Area {
        radiance: Rgb,
        triangles: Vec<[Vec3; 3]>,
        normals: Vec<Vec3>,
        area: f32,
        by_area: DiscreteDistribution,
        parallelogram: Option<[Vec3; 3]>,
    },
    /// A distant light travelling along unit `travel`; `cos_max` is 1 for a delta direction.
    Directional {
        travel: Vec3,
        irradiance: Rgb,
        cos_max: f32,
        outside: Outside,
    },
    /// Uniform radiance from every direction.
    Environment {
        radiance: Rgb,
        outside: Outside,
    },
}

/// The scene's bounding sphere as lights from outside see it: their emitted rays start on a
/// disc of radius `radius` just outside it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outside {
    pub center: Vec3,
    pub radius: f32,
}

impl Outside {
    /// The sphere around `points` (the box's circumscribed one, at least 1 mm across).
    pub fn around(points: impl IntoIterator<Item = Vec3>) -> Outside {
        let b = super::edits::Aabb::of_points(points);
        if b.is_empty() {
            return Outside { center: Vec3::ZERO, radius: 1.0 };
        }
        Outside { center: 0.5 * (b.min + b.max), radius: (0.5 * (b.max - b.min).length()).max(1e-3) }
    }

    /// A distance from `p` along any direction that lies beyond the sphere: where a shadow ray
    /// towards a light from outside may stop.
    fn beyond(&self, p: Vec3) -> f32 {
        2.0 * ((p - self.center).length() + self.radius)
    }

    fn disc_area(&self) -> f32 {
        PI * self.radius * self.radius
    }

    /// A ray travelling along `toward` from a point uniform on the disc facing it outside the
    /// sphere.
    fn ray_in(&self, toward: Vec3, u: Vec2) -> Vec3 {
        let d = sampling::concentric_disc(u) * self.radius;
        let frame = crate::core::ShadingFrame::from_normal(toward);
        self.center - toward * self.radius + frame.to_world(Vec3::new(d.x, d.y, 0.0))
    }
}

/// The radiance of a sun of irradiance `e` and cone `cos_max` < 1: E / (π sin²θ_max), with
/// sin² as (1 − cos)(1 + cos): 1 − cos is exact in f32, where 1 − cos² loses the sun's 0.53°.
fn sun_radiance(e: Rgb, cos_max: f32) -> Rgb {
    e / (PI * (1.0 - cos_max) * (1.0 + cos_max))
}

/// An incident-radiance sample towards a light.
#[derive(Clone, Copy, Debug)]
pub struct IncidentSample {
    /// Unit direction from the receiving point to the light.
    pub wi: Vec3,
    /// Distance to the sampled light point.
    pub dist: f32,
    /// Radiance arriving along `wi` (for delta lights, intensity / dist²).
    pub li: Rgb,
    /// Solid-angle density; 1 for delta lights.
    pub pdf: f32,
    pub delta: bool,
    /// Unit normal at the sampled light point (zero for point and spot lights).
    pub normal: Vec3,
}

/// When `new` differs from `old` only in its intensity or radiance, and every channel of the
/// old one is positive: the per-channel factor new/old. Every flux the old emitter sent out is
/// linear in that parameter, so this factor turns it into the new emitter's exactly (up to
/// rounding), with no new samples.
pub fn emission_rescale(old: &EmitterDesc, new: &EmitterDesc) -> Option<Rgb> {
    let (a, b) = match (old, new) {
        (EmitterDesc::Point { intensity: a }, EmitterDesc::Point { intensity: b }) => (a, b),
        (
            EmitterDesc::Spot { intensity: a, cone_deg: c, falloff_start_deg: f },
            EmitterDesc::Spot { intensity: b, cone_deg: c2, falloff_start_deg: f2 },
        ) if c == c2 && f == f2 => (a, b),
        (EmitterDesc::Rect { radiance: a }, EmitterDesc::Rect { radiance: b }) => (a, b),
        (EmitterDesc::Disc { radiance: a, segments: s }, EmitterDesc::Disc { radiance: b, segments: s2 })
            if s == s2 =>
        {
            (a, b)
        }
        (
            EmitterDesc::Mesh { radiance: a, positions: p, indices: i },
            EmitterDesc::Mesh { radiance: b, positions: p2, indices: i2 },
        ) if p == p2 && i == i2 => (a, b),
        (
            EmitterDesc::Directional { irradiance: a, direction: d, angle_deg: g },
            EmitterDesc::Directional { irradiance: b, direction: d2, angle_deg: g2 },
        ) if d == d2 && g == g2 => (a, b),
        _ => return None,
    };
    channel_ratio(*a, *b)
}

/// The per-channel factor `new/old`, when every channel of `old` is positive.
pub fn channel_ratio(old: Rgb, new: Rgb) -> Option<Rgb> {
    (old.min_component() > 0.0).then(|| Rgb::new(new.r / old.r, new.g / old.g, new.b / old.b))
}

/// The object-space mesh of a validated light with a shape (`None` for point and spot
/// lights); a mesh emitter's degenerate triangles are left out, as they emit nothing.
pub fn emitter_mesh(emitter: &EmitterDesc) -> Option<Mesh> {
    match emitter {
        EmitterDesc::Rect { .. } => Some(Mesh::quad()),
        EmitterDesc::Disc { segments, .. } => Some(Mesh::disc(*segments)),
        EmitterDesc::Mesh { positions, indices, .. } => {
            let mut mesh = Mesh::from_inline(positions, indices, None).ok()?;
            mesh.drop_degenerate();
            Some(mesh)
        }
        EmitterDesc::Point { .. } | EmitterDesc::Spot { .. } | EmitterDesc::Directional { .. } => None,
    }
}

/// The corner and two edges of the parallelogram two triangles make, when they share a
/// diagonal, face the same way, and their far corners sum to the diagonal's ends (to 1e-5 of the
/// longest edge, so a transformed rectangle still counts). The corner is the first triangle's
/// vertex off the diagonal, and the edges run from it to the next two vertices of that triangle.
fn parallelogram(triangles: &[[Vec3; 3]], normals: &[Vec3]) -> Option<[Vec3; 3]> {
    let ([first, second], [n0, n1]) = (triangles, normals) else { return None };
    let i = first.iter().position(|v| !second.contains(v))?;
    let far = *second.iter().find(|v| !first.contains(v))?;
    let (corner, s0, s1) = (first[i], first[(i + 1) % 3], first[(i + 2) % 3]);
    let shares_diagonal = second.contains(&s0) && second.contains(&s1);
    let closes = (corner + far - s0 - s1).length() <= 1e-5 * (s0 - corner).length().max((s1 - corner).length());
    (shares_diagonal && closes && n0.dot(*n1) > 0.999_99).then(|| [corner, s0 - corner, s1 - corner])
}

/// A point uniformly distributed by area over an area light's triangles, with its unit normal:
/// over a parallelogram (a corner and two edges) directly, else by choosing a triangle by area.
/// `by_area` must not be empty.
fn sample_area_point(
    triangles: &[[Vec3; 3]],
    normals: &[Vec3],
    by_area: &DiscreteDistribution,
    parallelogram: Option<&[Vec3; 3]>,
    u: Vec2,
) -> (Vec3, Vec3) {
    if let Some([corner, edge_a, edge_b]) = parallelogram {
        return (*corner + *edge_a * u.x + *edge_b * u.y, normals[0]);
    }
    let (i, _, u0) = by_area.sample(u.x);
    let [a, b, c] = triangles[i];
    let bary = sampling::uniform_triangle(Vec2::new(u0, u.y));
    (a * (1.0 - bary.x - bary.y) + b * bary.x + c * bary.y, normals[i])
}

/// Smoothstep from `lo` to `hi`, as pbrt-v4's spot falloff uses.
fn smoothstep(x: f32, lo: f32, hi: f32) -> f32 {
    if lo == hi {
        return if x < lo { 0.0 } else { 1.0 };
    }
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl LightGeometry {
    /// World-space geometry of a validated light description; `outside` is the scene's sphere.
    pub fn new(desc: &LightDesc, mesh: Option<&Mesh>, outside: Outside) -> LightGeometry {
        let xf: Affine3A = desc.transform.world_from_object();
        let position = desc.transform.translation();
        match (&desc.emitter, mesh) {
            (EmitterDesc::Point { intensity }, _) => LightGeometry::Point { position, intensity: *intensity },
            (EmitterDesc::Directional { direction, irradiance, angle_deg }, _) => LightGeometry::Directional {
                travel: Vec3::from(*direction).normalize_or(Vec3::NEG_Y),
                irradiance: *irradiance,
                cos_max: if *angle_deg > 0.0 { (0.5 * angle_deg).to_radians().cos().min(1.0 - 1e-7) } else { 1.0 },
                outside,
            },
            (EmitterDesc::Spot { intensity, cone_deg, falloff_start_deg }, _) => LightGeometry::Spot {
                position,
                axis: (desc.transform.rotation() * Vec3::Z).normalize(),
                intensity: *intensity,
                cos_falloff_start: falloff_start_deg.unwrap_or((cone_deg - 5.0).max(0.0)).to_radians().cos(),
                cos_falloff_end: cone_deg.to_radians().cos(),
            },
            (
                EmitterDesc::Rect { radiance }
                | EmitterDesc::Disc { radiance, .. }
                | EmitterDesc::Mesh { radiance, .. },
                Some(mesh),
            ) => {
                let triangles: Vec<[Vec3; 3]> =
                    (0..mesh.triangles.len()).map(|i| mesh.triangle(i).map(|p| xf.transform_point3(p))).collect();
                let areas: Vec<f32> =
                    triangles.iter().map(|[a, b, c]| 0.5 * (*b - *a).cross(*c - *a).length()).collect();
                let area = areas.iter().sum();
                let by_area = DiscreteDistribution::new(&areas).unwrap_or_default();
                let normals: Vec<Vec3> =
                    triangles.iter().map(|[a, b, c]| (*b - *a).cross(*c - *a).normalize_or_zero()).collect();
                let parallelogram = parallelogram(&triangles, &normals);
                LightGeometry::Area { radiance: *radiance, triangles, normals, area, by_area, parallelogram }
            }
            (
                EmitterDesc::Rect { radiance }
                | EmitterDesc::Disc { radiance, .. }
                | EmitterDesc::Mesh { radiance, .. },
                None,
            ) => LightGeometry::Area {
                radiance: *radiance,
                triangles: Vec::new(),
                normals: Vec::new(),
                area: 0.0,
                by_area: DiscreteDistribution::default(),
                parallelogram: None,
            },
        }
    }

    /// Total emitted power (W per channel).
    pub fn power(&self) -> Rgb {
        match self {
            LightGeometry::Point { intensity, .. } => *intensity * (4.0 * PI),
            LightGeometry::Spot { intensity, cos_falloff_start, cos_falloff_end, .. } => {
                *intensity * (2.0 * PI * (1.0 - 0.5 * (cos_falloff_start + cos_falloff_end)))
            }
            LightGeometry::Area { radiance, area, .. } => *radiance * (PI * area),
            LightGeometry::Directional { .. } | LightGeometry::Environment { .. } => self.emission_weight(Vec3::Z),
        }
    }

    /// The environment as a light: uniform `radiance` around `outside`.
    pub fn environment(radiance: Rgb, outside: Outside) -> LightGeometry {
        LightGeometry::Environment { radiance, outside }
    }

    /// A light from outside the scene (no surface, seen by rays that leave it).
    pub fn is_infinite(&self) -> bool {
        matches!(self, LightGeometry::Directional { .. } | LightGeometry::Environment { .. })
    }

    /// Radiance arriving along a ray that leaves the scene in unit direction `dir` (black for
    /// lights with a surface and for a delta sun).
    pub fn escaped(&self, dir: Vec3) -> Rgb {
        match self {
            LightGeometry::Environment { radiance, .. } => *radiance,
            LightGeometry::Directional { travel, irradiance, cos_max, .. }
                if *cos_max < 1.0 && -dir.dot(*travel) >= *cos_max =>
            {
                sun_radiance(*irradiance, *cos_max)
            }
            _ => Rgb::BLACK,
        }
    }

    /// Solid-angle density with which [`LightGeometry::sample_incident`] picks unit direction
    /// `wi` of a light from outside for a receiver whose side is `side` (0 for the rest and for
    /// a delta sun).
    pub fn pdf_direction(&self, wi: Vec3, side: Vec3) -> f32 {
        match self {
            LightGeometry::Environment { .. } if side == Vec3::ZERO => sampling::UNIFORM_SPHERE_PDF,
            LightGeometry::Environment { .. } => sampling::cosine_hemisphere_pdf(wi.dot(side).max(0.0)),
            LightGeometry::Directional { travel, cos_max, .. } if *cos_max < 1.0 && -wi.dot(*travel) >= *cos_max => {
                sampling::uniform_cone_pdf(*cos_max)
            }
            _ => 0.0,
        }
    }

    /// The emitting side's unit normal of a (planar) area light; zero for point and spot lights.
    pub fn surface_normal(&self) -> Vec3 {
        match self {
            LightGeometry::Area { triangles, .. } => {
                triangles.first().map_or(Vec3::ZERO, |[a, b, c]| (*b - *a).cross(*c - *a).normalize_or_zero())
            }
            _ => Vec3::ZERO,
        }
    }

    /// The light's next-event samples are deltas (a point, a spot, a sun of angle 0): BSDF
    /// sampling never finds them.
    pub fn is_delta(&self) -> bool {
        match self {
            LightGeometry::Area { .. } | LightGeometry::Environment { .. } => false,
            LightGeometry::Directional { cos_max, .. } => *cos_max >= 1.0,
            LightGeometry::Point { .. } | LightGeometry::Spot { .. } => true,
        }
    }

    /// Samples radiance arriving at `p`, a point on a surface whose unit normal on the receiving
    /// side is `side` (zero when unknown). `None` when nothing can arrive (back side, zero
    /// area). The environment is sampled cosine-weighted about `side` (uniformly over the sphere
    /// without one), which makes a diffuse receiver's estimate exact where nothing occludes it.
    pub fn sample_incident(&self, p: Vec3, side: Vec3, u: Vec2) -> Option<IncidentSample> {
        match self {
            LightGeometry::Point { position, intensity } => {
                let d = *position - p;
                let dist2 = d.length_squared();
                (dist2 > 0.0).then(|| {
                    let dist = dist2.sqrt();
                    IncidentSample {
                        wi: d / dist,
                        dist,
                        li: *intensity / dist2,
                        pdf: 1.0,
                        delta: true,
                        normal: Vec3::ZERO,
                    }
                })
            }
            LightGeometry::Spot { position, axis, intensity, cos_falloff_start, cos_falloff_end } => {
                let d = *position - p;
                let dist2 = d.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let falloff = smoothstep(-wi.dot(*axis), *cos_falloff_end, *cos_falloff_start);
                (falloff > 0.0).then(|| IncidentSample {
                    wi,
                    dist,
                    li: *intensity * (falloff / dist2),
                    pdf: 1.0,
                    delta: true,
                    normal: Vec3::ZERO,
                })
            }
            LightGeometry::Directional { travel, irradiance, cos_max, outside } => {
                let (wi, li, pdf) = if *cos_max >= 1.0 {
                    (-*travel, *irradiance, 1.0)
                } else {
                    let local = sampling::uniform_cone(u, *cos_max);
                    let wi = crate::core::ShadingFrame::from_normal(-*travel).to_world(local);
                    (wi, sun_radiance(*irradiance, *cos_max), sampling::uniform_cone_pdf(*cos_max))
                };
                let delta = *cos_max >= 1.0;
                Some(IncidentSample { wi, dist: outside.beyond(p), li, pdf, delta, normal: Vec3::ZERO })
            }
            LightGeometry::Environment { radiance, outside } => {
                let wi = if side == Vec3::ZERO {
                    sampling::uniform_sphere(u)
                } else {
                    crate::core::ShadingFrame::from_normal(side).to_world(sampling::cosine_hemisphere(u))
                };
                let pdf = self.pdf_direction(wi, side);
                (pdf > 0.0).then(|| IncidentSample {
                    wi,
                    dist: outside.beyond(p),
                    li: *radiance,
                    pdf,
                    delta: false,
                    normal: Vec3::ZERO,
                })
            }
            LightGeometry::Area { radiance, triangles, normals, area, by_area, parallelogram } => {
                if by_area.is_empty() {
                    return None;
                }
                let (q, n) = sample_area_point(triangles, normals, by_area, parallelogram.as_ref(), u);
                let d = q - p;
                let dist2 = d.length_squared();
                let dist = dist2.sqrt();
                let wi = d / dist;
                let cos_l = -n.dot(wi);
                (cos_l > 0.0 && dist > 0.0).then(|| IncidentSample {
                    wi,
                    dist,
                    li: *radiance,
                    pdf: dist2 / (cos_l * area),
                    delta: false,
                    normal: n,
                })
            }
        }
    }

    /// Solid-angle density with which [`LightGeometry::sample_incident`] would pick the point `q`
    /// (unit normal `n_light`) seen from `p`.
    pub fn pdf_incident(&self, p: Vec3, q: Vec3, n_light: Vec3) -> f32 {
        match self {
            LightGeometry::Area { area, .. } if *area > 0.0 => {
                let d = q - p;
                let dist2 = d.length_squared();
                let cos_l = n_light.dot(-d / dist2.sqrt());
                if cos_l > 0.0 {
                    dist2 / (cos_l * area)
                } else {
                    0.0
                }
            }
            _ => 0.0,
        }
    }

    /// Samples an emitted ray for photon tracing: (origin, unit direction, flux / pdf) with the
    /// origin offset off an area light's surface (robustly, as every spawned ray), and the
    /// pdf over positions and directions together, so `E[flux/pdf] = power()`. `u_pos` picks
    /// the point on an area light, `u_dir` the direction (uniform sphere for point lights,
    /// uniform cone for spots, cosine-weighted for area lights).
    pub fn sample_emission(&self, u_pos: Vec2, u_dir: Vec2) -> Option<(Vec3, Vec3, Rgb)> {
        let (origin, dir) = match self {
            LightGeometry::Point { position, .. } => (*position, sampling::uniform_sphere(u_dir)),
            LightGeometry::Spot { position, axis, cos_falloff_end, .. } => {
                let local = sampling::uniform_cone(u_dir, *cos_falloff_end);
                (*position, crate::core::ShadingFrame::from_normal(*axis).to_world(local))
            }
            LightGeometry::Area { triangles, normals, by_area, parallelogram, .. } => {
                if by_area.is_empty() {
                    return None;
                }
                let (on_light, n) = sample_area_point(triangles, normals, by_area, parallelogram.as_ref(), u_pos);
                let dir = crate::core::ShadingFrame::from_normal(n).to_world(sampling::cosine_hemisphere(u_dir));
                // Off the light's surface, so the ray cannot hit its own light.
                (crate::core::offset_ray_origin(on_light, n), dir)
            }
            LightGeometry::Directional { travel, cos_max, outside, .. } => {
                let dir = if *cos_max >= 1.0 {
                    *travel
                } else {
                    let local = sampling::uniform_cone(u_dir, *cos_max);
                    crate::core::ShadingFrame::from_normal(*travel).to_world(local)
                };
                (outside.ray_in(dir, u_pos), dir)
            }
            LightGeometry::Environment { outside, .. } => {
                let dir = -sampling::uniform_sphere(u_dir);
                (outside.ray_in(dir, u_pos), dir)
            }
        };
        let weight = self.emission_weight(dir);
        (!weight.is_black()).then_some((origin, dir, weight))
    }

    /// `flux / pdf` of a ray [`LightGeometry::sample_emission`] emits along `dir`: uniform
    /// sphere `I·4π` for points; `I·falloff / pdf_cone` for spots; `L cosθ / (pdf_A · pdf_ω) =
    /// L cosθ / ((1/A) · cosθ/π) = L π A` for area lights (`dir` on the emitting side);
    /// `E·πr²` for a delta sun, `L·πr²/pdf_cone` for a sun of angle θ_max, `L·πr²·4π` for the
    /// environment (each ray crosses its disc of area πr² square on).
    pub fn emission_weight(&self, dir: Vec3) -> Rgb {
        match self {
            LightGeometry::Point { intensity, .. } => *intensity / sampling::UNIFORM_SPHERE_PDF,
            LightGeometry::Spot { axis, intensity, cos_falloff_start, cos_falloff_end, .. } => {
                let falloff = smoothstep(axis.dot(dir), *cos_falloff_end, *cos_falloff_start);
                *intensity * (falloff / sampling::uniform_cone_pdf(*cos_falloff_end))
            }
            LightGeometry::Area { radiance, area, .. } => *radiance * (PI * area),
            LightGeometry::Directional { irradiance, cos_max, outside, .. } if *cos_max >= 1.0 => {
                *irradiance * outside.disc_area()
            }
            LightGeometry::Directional { irradiance, cos_max, outside, .. } => {
                sun_radiance(*irradiance, *cos_max) * (outside.disc_area() / sampling::uniform_cone_pdf(*cos_max))
            }
            LightGeometry::Environment { radiance, outside } => {
                *radiance * (outside.disc_area() / sampling::UNIFORM_SPHERE_PDF)
            }
        }
    }

    /// Density over area with which [`LightGeometry::sample_emission`] and
    /// [`LightGeometry::sample_incident`] pick an emission point: 1/A for area lights, 1 for
    /// point and spot lights (a delta in position).
    pub fn pdf_position(&self) -> f32 {
        match self {
            LightGeometry::Area { area, .. } if *area > 0.0 => 1.0 / area,
            LightGeometry::Area { .. } => 0.0,
            LightGeometry::Directional { outside, .. } | LightGeometry::Environment { outside, .. } => {
                1.0 / outside.disc_area()
            }
            _ => 1.0,
        }
    }

    /// Solid-angle density with which [`LightGeometry::sample_emission`] picks `dir` leaving a
    /// point with unit normal `n` (ignored for point and spot lights).
    pub fn pdf_emission_direction(&self, n: Vec3, dir: Vec3) -> f32 {
        match self {
            LightGeometry::Point { .. } => sampling::UNIFORM_SPHERE_PDF,
            LightGeometry::Spot { axis, cos_falloff_end, .. } => {
                if axis.dot(dir) >= *cos_falloff_end {
                    sampling::uniform_cone_pdf(*cos_falloff_end)
                } else {
                    0.0
                }
            }
            LightGeometry::Area { .. } => sampling::cosine_hemisphere_pdf(n.dot(dir)),
            LightGeometry::Directional { .. } | LightGeometry::Environment { .. } => {
                self.pdf_direction(-dir, Vec3::ZERO)
            }
        }
    }

    /// Radiance leaving an area light's surface with normal `n` towards `w`.
    pub fn emitted(&self, n: Vec3, w: Vec3) -> Rgb {
        match self {
            LightGeometry::Area { radiance, .. } if n.dot(w) > 0.0 => *radiance,
            _ => Rgb::BLACK,
        }
    }
}
