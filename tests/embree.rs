//! The Embree layer against analytic answers, on the real library. The query tests run under
//! every Embree kernel family this CPU has (`for_each_isa`).
mod common;
use common::for_each_isa;
use glam::{Affine3A, Quat, Vec3};
use relume::embree::{CommittedScene, Device, EmbreeError, Ray, Scene, SceneQuality};
use std::sync::Arc;

/// A unit square in the z = 0 plane, spanning [-1, 1]².
fn square(device: &Device) -> Scene {
    let mut s = Scene::new(device, SceneQuality::Static).unwrap();
    let p =
        [Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(-1.0, 1.0, 0.0)];
    s.attach_triangles(&p, &[[0, 1, 2], [0, 2, 3]]).unwrap();
    s
}

#[test]
fn under_every_isa_hits_and_misses_match_the_plane_equation() {
    for_each_isa(|_, device| hits_and_misses_match_the_plane_equation(device));
}

fn hits_and_misses_match_the_plane_equation(device: &Device) {
    let scene = square(device).commit().unwrap();
    // Ray from z=5 straight down at (0.3, -0.2): hits at t = 5 with barycentrics that give the point back.
    let ray = Ray::new(Vec3::new(0.3, -0.2, 5.0), Vec3::new(0.0, 0.0, -1.0));
    let hit = scene.intersect1(&ray).expect("must hit the square");
    assert!((hit.t - 5.0).abs() < 1e-5, "t = {}", hit.t);
    assert_eq!(hit.inst_id, None);
    assert_eq!(hit.geom_id, 0);
    let n = hit.ng.normalize();
    assert!((n.z.abs() - 1.0).abs() < 1e-6);
    // Oblique ray: t scales with the direction's length.
    let ray = Ray::new(Vec3::new(0.0, 0.0, 2.0), Vec3::new(0.25, 0.0, -0.5));
    let hit = scene.intersect1(&ray).unwrap();
    assert!((hit.t - 4.0).abs() < 1e-5);
    // Misses: outside the square, pointing away, and stopped short by tfar.
    assert!(scene.intersect1(&Ray::new(Vec3::new(1.5, 0.0, 5.0), Vec3::NEG_Z)).is_none());
    assert!(scene.intersect1(&Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::Z)).is_none());
    assert!(scene.intersect1(&Ray::segment(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 4.99)).is_none());
    assert!(scene.occluded1(&Ray::segment(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 5.01)));
    assert!(!scene.occluded1(&Ray::segment(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 4.99)));
    assert_eq!(scene.bounds(), Some((Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0))));
}

#[test]
fn under_every_isa_packets_agree_with_single_rays() {
    for_each_isa(|_, device| packets_agree_with_single_rays(device));
}

fn packets_agree_with_single_rays(device: &Device) {
    let scene = square(device).commit().unwrap();
    let rays8: [Ray; 8] = std::array::from_fn(|i| Ray::new(Vec3::new(-1.4 + 0.4 * i as f32, 0.1, 3.0), Vec3::NEG_Z));
    let mut active = [true; 8];
    active[3] = false;
    let mut hits = [None; 8];
    scene.intersect8(&rays8, &active, true, &mut hits);
    let mut occ = [false; 8];
    scene.occluded8(&rays8, &active, &mut occ);
    for i in 0..8 {
        let single = if active[i] { scene.intersect1(&rays8[i]) } else { None };
        assert_eq!(hits[i], single, "lane {i}");
        assert_eq!(occ[i], single.is_some(), "lane {i}");
    }
    assert!(hits.iter().filter(|h| h.is_some()).count() >= 4);
    let rays16: [Ray; 16] =
        std::array::from_fn(|i| Ray::new(Vec3::new(-1.6 + 0.2 * i as f32, -0.5, 3.0), Vec3::new(0.0, 0.05, -1.0)));
    let active = [true; 16];
    let mut hits = [None; 16];
    let mut occ = [false; 16];
    scene.intersect16(&rays16, &active, false, &mut hits);
    scene.occluded16(&rays16, &active, &mut occ);
    for i in 0..16 {
        assert_eq!(hits[i], scene.intersect1(&rays16[i]), "lane {i}");
        assert_eq!(occ[i], hits[i].is_some());
    }
}

#[test]
fn under_every_isa_an_empty_scene_is_missed_by_every_query() {
    // Embree commits a scene with no geometry; every query must miss it, directly and through
    // an instance, and its bounds are empty.
    for_each_isa(|isa, device| {
        let empty = Arc::new(Scene::new(device, SceneQuality::Static).unwrap().commit().unwrap());
        let mut top = Scene::new(device, SceneQuality::Dynamic).unwrap();
        top.attach_instance(empty.clone(), Affine3A::IDENTITY).unwrap();
        let top = top.commit().unwrap();
        for scene in [&*empty, &top] {
            assert_eq!(scene.bounds(), None, "{isa}");
            let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
            assert_eq!(scene.intersect1(&ray), None, "{isa}");
            assert!(!scene.occluded1(&ray), "{isa}");
            let (mut hits, mut occ) = ([None; 16], [false; 16]);
            scene.intersect16(&[ray; 16], &[true; 16], true, &mut hits);
            scene.occluded16(&[ray; 16], &[true; 16], &mut occ);
            assert!(hits.iter().all(Option::is_none) && occ.iter().all(|o| !o), "{isa}");
            let (mut hits, mut occ) = ([None; 8], [false; 8]);
            scene.intersect8(&[ray; 8], &[true; 8], false, &mut hits);
            scene.occluded8(&[ray; 8], &[true; 8], &mut occ);
            assert!(hits.iter().all(Option::is_none) && occ.iter().all(|o| !o), "{isa}");
        }
    });
}

#[test]
fn a_cpu_without_a_family_refuses_it_by_name() {
    use relume::embree::Isa;
    for isa in Isa::ALL.into_iter().filter(|i| !i.supported_by_cpu()) {
        let e = Device::with_isa(1, Some(isa)).expect_err("an unsupported family must be refused");
        assert!(e.to_string().contains(isa.name()), "{e}");
    }
    // The cap is what the device reports; without one, the widest family this CPU has.
    let widest = *Isa::supported().last().unwrap();
    assert_eq!(Device::new(1).unwrap().isa(), widest);
    assert_eq!(Device::with_isa(1, Some(Isa::Sse2)).unwrap().isa(), Isa::Sse2);
}

#[test]
fn moving_an_instance_then_recommitting_changes_what_is_hit() {
    let device = Device::new(1).unwrap();
    let blas = Arc::new(square(&device).commit().unwrap());
    let mut top = Scene::new(&device, SceneQuality::Dynamic).unwrap();
    let id = top.attach_instance(blas, Affine3A::IDENTITY).unwrap();
    let top = Arc::new(top.commit().unwrap());
    let probe = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
    let hit = top.intersect1(&probe).unwrap();
    assert_eq!(hit.inst_id, Some(id));
    assert!((hit.t - 5.0).abs() < 1e-5);

    // Lift the square by 2 and turn it 90° about X: the probe now misses, a ray along z=... hits.
    let mut top = CommittedScene::edit_shared(top).map_err(|(_, e)| e).unwrap();
    let moved = Affine3A::from_rotation_translation(
        Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
        Vec3::new(0.0, 0.0, 2.0),
    );
    top.set_instance_transform(id, moved).unwrap();
    let top = top.commit().unwrap();
    assert!(top.intersect1(&probe).is_none_or(|h| (h.t - 5.0).abs() > 0.5), "old position still hit");
    // The square now lies in the y=0 plane, spanning z in [1, 3].
    let side = Ray::new(Vec3::new(0.2, 4.0, 2.5), Vec3::NEG_Y);
    let hit = top.intersect1(&side).expect("moved square must be hit from above");
    assert!((hit.t - 4.0).abs() < 1e-4, "t = {}", hit.t);
}

#[test]
fn a_shared_scene_cannot_be_edited() {
    let device = Device::new(1).unwrap();
    let shared = Arc::new(square(&device).commit().unwrap());
    let other = Arc::clone(&shared);
    let (back, err) = CommittedScene::edit_shared(shared).err().expect("must refuse while shared");
    assert_eq!(err, EmbreeError::SceneShared(1));
    drop(other);
    assert!(CommittedScene::edit_shared(back).is_ok());
}

#[test]
fn detaching_really_detaches() {
    let device = Device::new(1).unwrap();
    let mut s = square(&device);
    let far = [Vec3::new(-1.0, -1.0, -3.0), Vec3::new(1.0, -1.0, -3.0), Vec3::new(0.0, 1.0, -3.0)];
    let far_id = s.attach_triangles(&far, &[[0, 1, 2]]).unwrap();
    let s = s.commit().unwrap();
    let probe = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
    assert_eq!(s.intersect1(&probe).unwrap().geom_id, 0);
    let mut s = s.edit();
    s.detach(0).unwrap();
    assert_eq!(s.geometry_count(), 1);
    let s = s.commit().unwrap();
    let hit = s.intersect1(&probe).expect("the far triangle remains");
    assert_eq!(hit.geom_id, far_id);
    assert!((hit.t - 8.0).abs() < 1e-5);
    let mut s = s.edit();
    assert_eq!(s.detach(0), Err(EmbreeError::UnknownGeometry(0)));
    s.detach(far_id).unwrap();
    let s = s.commit().unwrap();
    assert!(s.intersect1(&probe).is_none());
    assert!(s.bounds().is_none());
}

#[test]
fn embree_errors_come_back_as_err() {
    // A bad device configuration is refused by rtcNewDevice.
    match Device::with_config("threads=lots") {
        Err(EmbreeError::Device { code, .. }) => assert_ne!(code, "RTC_ERROR_NONE"),
        other => panic!("expected a device error, got {other:?}"),
    }
    let device = Device::new(1).unwrap();
    let mut s = square(&device);
    // Setting an instance transform on a triangle mesh is an Embree INVALID_OPERATION.
    match s.set_instance_transform(0, Affine3A::IDENTITY) {
        Err(EmbreeError::Device { code, .. }) => assert_eq!(code, "RTC_ERROR_INVALID_OPERATION"),
        other => panic!("expected an Embree error, got {other:?}"),
    }
    // Argument checks in front of Embree: out-of-range indices, NaN, empty meshes.
    let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
    assert!(matches!(s.attach_triangles(&p, &[[0, 1, 3]]), Err(EmbreeError::InvalidGeometry(_))));
    assert!(matches!(
        s.attach_triangles(&[Vec3::NAN, Vec3::X, Vec3::Y], &[[0, 1, 2]]),
        Err(EmbreeError::InvalidGeometry(_))
    ));
    assert!(matches!(s.attach_triangles(&[], &[]), Err(EmbreeError::InvalidGeometry(_))));
    assert_eq!(s.set_instance_transform(42, Affine3A::IDENTITY), Err(EmbreeError::UnknownGeometry(42)));
    // The device is still usable afterwards.
    let s = s.commit().unwrap();
    assert!(s.intersect1(&Ray::new(Vec3::new(0.0, 0.0, 1.0), Vec3::NEG_Z)).is_some());
}

#[test]
fn instance_normals_are_reported_in_object_space() {
    // Pins down what Embree reports as Ng for instanced geometry (`RTCHit(3)`): the scene layer transforms it.
    let device = Device::new(1).unwrap();
    let blas = Arc::new(square(&device).commit().unwrap());
    let mut top = Scene::new(&device, SceneQuality::Dynamic).unwrap();
    let rot = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
    top.attach_instance(blas, Affine3A::from_quat(rot)).unwrap();
    let top = top.commit().unwrap();
    let hit = top.intersect1(&Ray::new(Vec3::new(0.1, 3.0, 0.2), Vec3::NEG_Y)).unwrap();
    let n = hit.ng.normalize();
    // World normal would be ±Y; the square's object-space normal is +Z.
    assert!((n - Vec3::Z).length() < 1e-6, "Ng = {n}");
}

/// A fan of `n` triangles around `center` in the plane z = `center.z`, radius `r`: every spoke is
/// an edge shared by two triangles.
fn fan(device: &Device, intersector: relume::embree::Intersector, center: Vec3, r: f32, n: u32) -> CommittedScene {
    let mut s = Scene::with_intersector(device, SceneQuality::Static, intersector).unwrap();
    let mut p = vec![center];
    for i in 0..n {
        let a = std::f32::consts::TAU * i as f32 / n as f32;
        p.push(center + r * Vec3::new(a.cos(), a.sin(), 0.0));
    }
    let tris: Vec<[u32; 3]> = (0..n).map(|i| [0, 1 + i, 1 + (i + 1) % n]).collect();
    s.attach_triangles(&p, &tris).unwrap();
    s.commit().unwrap()
}

/// Rays aimed at points on the shared spokes of a fan far from the origin that miss it.
fn edge_misses(device: &Device, intersector: relume::embree::Intersector) -> (u32, u32) {
    let center = Vec3::new(4096.3, -1024.7, 3.1);
    let n = 97;
    let scene = fan(device, intersector, center, 5.0, n);
    let mut rng = relume::core::Rng::new(5, 5);
    let (mut misses, mut rays) = (0, 0);
    for i in 0..n {
        let a = std::f32::consts::TAU * i as f32 / n as f32;
        let spoke = center + 5.0 * Vec3::new(a.cos(), a.sin(), 0.0);
        for _ in 0..400 {
            let target = center.lerp(spoke, 0.05 + 0.9 * rng.next_f32());
            let u = rng.next_2d();
            let origin = target + Vec3::new(40.0 * u.x - 20.0, 40.0 * u.y - 20.0, 7.0 + 30.0 * rng.next_f32());
            rays += 1;
            if scene.intersect1(&Ray::new(origin, (target - origin).normalize())).is_none() {
                misses += 1;
            }
        }
    }
    (misses, rays)
}

#[test]
fn robust_triangles_are_watertight_along_shared_edges() {
    // Property: why every level of `SceneAccel` is robust although Embree's fast kernel traces
    // as fast on the bundled scenes (`relume bench rays`): rays aimed at edges shared by two
    // triangles, 4 km from the origin, all hit. The fast kernel, the negative control, lets
    // some through the cracks.
    for_each_isa(|isa, device| {
        let (misses, rays) = edge_misses(device, relume::embree::Intersector::Robust);
        let (fast_misses, _) = edge_misses(device, relume::embree::Intersector::Fast);
        eprintln!("{isa:?}: {rays} rays at shared edges: robust {misses} misses, fast {fast_misses}");
        assert_eq!(misses, 0, "{isa:?}");
        assert!(fast_misses > 0, "{isa:?}: the fast kernel found no crack, so the test cannot fail");
    });
}
