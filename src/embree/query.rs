//! Ray queries on a [`CommittedScene`]: single rays and 8/16-wide packets, closest hit and
//! occlusion. All are `&self` and safe to call from many threads at once.
use super::layout::{ValidMask16, ValidMask8};
use super::scene::CommittedScene;
use super::sys;
use super::version::{self, Coherence};
use glam::Vec3;

pub const PACKET8: usize = 8;
pub const PACKET16: usize = 16;

/// A ray segment `origin + t·dir` for `t` in `[tnear, tfar]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tnear: f32,
    pub tfar: f32,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray { origin, dir, tnear: 0.0, tfar: f32::INFINITY }
    }

    pub fn segment(origin: Vec3, dir: Vec3, tfar: f32) -> Ray {
        Ray { origin, dir, tnear: 0.0, tfar }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// The closest hit of a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray, in units of `|dir|`.
    pub t: f32,
    /// Barycentrics: the hit is `(1-u-v)·v0 + u·v1 + v·v2`.
    pub u: f32,
    pub v: f32,
    /// Unnormalised geometric normal `(v1-v0)×(v2-v0)` as Embree reports it (`RTCHit(3)`): in the object
    /// space of the instance for instanced geometry (not world space).
    pub ng: Vec3,
    /// `instID`: the top-level instance hit, or `None` for geometry hit directly.
    pub inst_id: Option<u32>,
    /// `geomID` within the scene that holds the triangles.
    pub geom_id: u32,
    pub prim_id: u32,
}

fn inst(id: u32) -> Option<u32> {
    (id != sys::RTC_INVALID_GEOMETRY_ID).then_some(id)
}

fn rtc_ray(r: &Ray) -> sys::RTCRay {
    sys::RTCRay {
        org_x: r.origin.x,
        org_y: r.origin.y,
        org_z: r.origin.z,
        tnear: r.tnear,
        dir_x: r.dir.x,
        dir_y: r.dir.y,
        dir_z: r.dir.z,
        time: 0.0,
        tfar: r.tfar,
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}

impl CommittedScene {
    /// Closest hit of one ray.
    pub fn intersect1(&self, ray: &Ray) -> Option<Hit> {
        let mut rh = sys::RTCRayHit { ray: rtc_ray(ray), hit: sys::RTCHit::default() };
        rh.hit.geomID = sys::RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID = [sys::RTC_INVALID_GEOMETRY_ID];
        version::intersect1(self.raw(), &mut rh);
        (rh.hit.geomID != sys::RTC_INVALID_GEOMETRY_ID).then(|| Hit {
            t: rh.ray.tfar,
            u: rh.hit.u,
            v: rh.hit.v,
            ng: Vec3::new(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z),
            inst_id: inst(rh.hit.instID[0]),
            geom_id: rh.hit.geomID,
            prim_id: rh.hit.primID,
        })
    }

    /// True if anything lies on the ray between `tnear` and `tfar`.
    pub fn occluded1(&self, ray: &Ray) -> bool {
        let mut r = rtc_ray(ray);
        version::occluded1(self.raw(), &mut r);
        r.tfar == f32::NEG_INFINITY
    }
}

/// Generates the packet queries for one width; the two widths differ only in types and calls.
macro_rules! packet_queries {
    ($width:literal, $mask:ident, $rayhit:ident, $ray:ident, $intersect:ident, $occluded:ident, $v_intersect:path, $v_occluded:path) => {
        impl CommittedScene {
            #[doc = concat!("Closest hits of a ", stringify!($width), "-wide packet; inactive lanes are left `None`.")]
            pub fn $intersect(
                &self,
                rays: &[Ray; $width],
                active: &[bool; $width],
                coherent: bool,
                hits: &mut [Option<Hit>; $width],
            ) {
                let valid = $mask::from_active(active);
                let mut p = sys::$rayhit::default();
                for i in 0..$width {
                    let r = &rays[i];
                    p.ray.org_x[i] = r.origin.x;
                    p.ray.org_y[i] = r.origin.y;
                    p.ray.org_z[i] = r.origin.z;
                    p.ray.tnear[i] = r.tnear;
                    p.ray.dir_x[i] = r.dir.x;
                    p.ray.dir_y[i] = r.dir.y;
                    p.ray.dir_z[i] = r.dir.z;
                    p.ray.tfar[i] = r.tfar;
                    p.ray.mask[i] = u32::MAX;
                    p.hit.geomID[i] = sys::RTC_INVALID_GEOMETRY_ID;
                    p.hit.instID[0][i] = sys::RTC_INVALID_GEOMETRY_ID;
                }
                let coherence = if coherent { Coherence::Coherent } else { Coherence::Incoherent };
                $v_intersect(self.raw(), &valid, &mut p, coherence);
                for i in 0..$width {
                    hits[i] = (active[i] && p.hit.geomID[i] != sys::RTC_INVALID_GEOMETRY_ID).then(|| Hit {
                        t: p.ray.tfar[i],
                        u: p.hit.u[i],
                        v: p.hit.v[i],
                        ng: Vec3::new(p.hit.Ng_x[i], p.hit.Ng_y[i], p.hit.Ng_z[i]),
                        inst_id: inst(p.hit.instID[0][i]),
                        geom_id: p.hit.geomID[i],
                        prim_id: p.hit.primID[i],
                    });
                }
            }

            #[doc = concat!("Occlusion of a ", stringify!($width), "-wide packet; inactive lanes report `false`.")]
            pub fn $occluded(&self, rays: &[Ray; $width], active: &[bool; $width], occluded: &mut [bool; $width]) {
                let valid = $mask::from_active(active);
                let mut p = sys::$ray::default();
                for i in 0..$width {
                    let r = &rays[i];
                    p.org_x[i] = r.origin.x;
                    p.org_y[i] = r.origin.y;
                    p.org_z[i] = r.origin.z;
                    p.tnear[i] = r.tnear;
                    p.dir_x[i] = r.dir.x;
                    p.dir_y[i] = r.dir.y;
                    p.dir_z[i] = r.dir.z;
                    p.tfar[i] = r.tfar;
                    p.mask[i] = u32::MAX;
                }
                $v_occluded(self.raw(), &valid, &mut p);
                for i in 0..$width {
                    occluded[i] = active[i] && p.tfar[i] == f32::NEG_INFINITY;
                }
            }
        }
    };
}

packet_queries!(8, ValidMask8, RTCRayHit8, RTCRay8, intersect8, occluded8, version::intersect8, version::occluded8);
packet_queries!(
    16,
    ValidMask16,
    RTCRayHit16,
    RTCRay16,
    intersect16,
    occluded16,
    version::intersect16,
    version::occluded16
);

impl CommittedScene {
    /// Closest hits for any number of lanes: 16 and 8 lanes go to Embree's packet kernels, any
    /// other count is traced ray by ray. Inactive lanes are left `None`.
    pub fn intersect_lanes(&self, rays: &[Ray], active: &[bool], coherent: bool, hits: &mut [Option<Hit>]) {
        if let (Ok(r), Ok(a), Ok(h)) =
            (rays.try_into(), active.try_into(), <&mut [Option<Hit>; 16]>::try_from(&mut *hits))
        {
            return self.intersect16(r, a, coherent, h);
        }
        if let (Ok(r), Ok(a), Ok(h)) =
            (rays.try_into(), active.try_into(), <&mut [Option<Hit>; 8]>::try_from(&mut *hits))
        {
            return self.intersect8(r, a, coherent, h);
        }
        for ((r, a), h) in rays.iter().zip(active).zip(hits.iter_mut()) {
            *h = if *a { self.intersect1(r) } else { None };
        }
    }

    /// Occlusion for any number of lanes, dispatched like [`CommittedScene::intersect_lanes`].
    pub fn occluded_lanes(&self, rays: &[Ray], active: &[bool], occluded: &mut [bool]) {
        if let (Ok(r), Ok(a), Ok(o)) = (rays.try_into(), active.try_into(), <&mut [bool; 16]>::try_from(&mut *occluded))
        {
            return self.occluded16(r, a, o);
        }
        if let (Ok(r), Ok(a), Ok(o)) = (rays.try_into(), active.try_into(), <&mut [bool; 8]>::try_from(&mut *occluded))
        {
            return self.occluded8(r, a, o);
        }
        for ((r, a), o) in rays.iter().zip(active).zip(occluded.iter_mut()) {
            *o = *a && self.occluded1(r);
        }
    }
}
