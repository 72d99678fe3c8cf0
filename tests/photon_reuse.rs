//! photon_reuse against analytic answers and the `path` reference, and its reuse behaviour.
mod common;
use common::*;
use relume::embree::Device;
use relume::engine::Session;
use relume::scene::edits::Edit;
use relume::scene::Trs;
use relume::technique::photon_reuse::{PhotonReuseConfig, ReuseMode};
use relume::technique::TechniqueConfig;

/// How closely photon_reuse must match `path` on the Cornell box, allowing the disc kernel's
/// blur at corners and B = 7 truncation; the negative control must fail it.
const CORNELL_TOLERANCE: Tolerance = Tolerance { channel: 0.03, block: 0.10, floor: 0.002 };

fn config(paths: u32, reuse: ReuseMode) -> PhotonReuseConfig {
    PhotonReuseConfig { paths, reuse, ..PhotonReuseConfig::default() }
}

#[test]
fn furnace_matches_the_analytic_radiance_within_one_percent() {
    // Property: NEE plus the photon density estimate reproduce L = ρI/(πR²(1−ρ)) = 1/π. In a
    // sphere the irradiance is uniform, so the kernel adds no bias; B = 15 makes the truncation
    // (ρ^15 ≈ 3e-5) negligible. The bound includes the 99.9% Student-t interval over independent seeds.
    for reuse in [ReuseMode::Off, ReuseMode::Naive, ReuseMode::Error] {
        let c = TechniqueConfig::PhotonReuse(PhotonReuseConfig { max_photons: 15, ..config(300_000, reuse) });
        assert_within_one_percent(
            &format!("furnace {reuse:?}"),
            &furnace_batches(&c, 8, Some(24), 2),
            furnace_radiance(None),
        );
    }
}

#[test]
fn cornell_box_matches_the_path_reference() {
    // Property: the photon estimate converges to the path tracer's image. Compared: the mean of
    // each channel (tolerance 3%: the disc kernel's blur at corners and B = 7 truncation cost
    // about 1.5% here) and 4×4 block means (10%), at a photon count the test can afford.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(48, 48);
    let reference = render(
        scene.clone(),
        TechniqueConfig::Path(relume::technique::path::PathConfig { admitted_truncation: 1e-3, ..path(96) }),
        3,
        1,
        2,
    )
    .image;
    let photons =
        render(scene.clone(), TechniqueConfig::PhotonReuse(config(300_000, ReuseMode::Naive)), 3, 24, 2).image;
    assert_matches_reference("cornell", &photons, &reference, CORNELL_TOLERANCE);
    // Negative control: photon paths of one photon (B = 1, no multiple bounces) fail the same
    // bounds.
    let broken = PhotonReuseConfig { max_photons: 1, ..config(300_000, ReuseMode::Naive) };
    let photons = render(scene, TechniqueConfig::PhotonReuse(broken), 3, 8, 2).image;
    assert_rejected_by_reference("cornell, B = 1", &photons, &reference, CORNELL_TOLERANCE);
}

#[test]
fn a_static_scene_retraces_nothing_after_the_first_tick_and_accumulates() {
    // With refinement off, a still scene keeps every path; with it on (the default), a still
    // tick emits exactly its share afresh and keeps the rest. Either way the film accumulates.
    let mut scene = load("bunnies-1.json");
    scene.set_resolution(16, 16);
    let device = Device::new(1).unwrap();
    for refine in [0.0, 0.125] {
        let c = PhotonReuseConfig { refine, ..config(20_000, ReuseMode::Naive) };
        let mut s = Session::new(scene.clone(), &TechniqueConfig::PhotonReuse(c), 1, &device).unwrap();
        let first = s.tick().unwrap();
        assert_eq!(photon_stats(&first).fully_retraced, 20_000);
        let share = (refine * 20_000.0) as u64;
        for _ in 0..3 {
            let f = s.tick().unwrap();
            let st = photon_stats(&f);
            assert_eq!((st.untouched, st.partly_retraced, st.fully_retraced), (20_000 - share, 0, share));
            assert_eq!(st.refined, share);
            assert_eq!(st.retrace_rays > 0, share > 0, "refine {refine}");
            assert_eq!(f.accumulation_id, first.accumulation_id);
        }
        assert_eq!(s.film().passes, 4);
        // A camera edit restarts the film but retraces no path for it: photons do not depend
        // on the view.
        s.queue_edits(vec![camera_dolly()]).unwrap();
        let f = s.tick().unwrap();
        assert_eq!(photon_stats(&f).untouched, 20_000 - share);
        assert_ne!(f.accumulation_id, first.accumulation_id);
    }
}

#[test]
fn a_still_scene_converges_to_the_reference() {
    // Property (progressive refinement): over 64 still ticks of the Cornell box, fresh photon
    // paths and a shrinking radius drive the error down: the relMSE against a 1024-spp path
    // reference falls to at most 1/10 of the first tick's, and the mean ends within 1.5%. At
    // 20 000 paths the photon map's noise is a large part of the first tick's error (measured
    // here: 1/12 refined, 1/8 frozen; the rest is camera noise, which falls as 1/ticks).
    // Negative control: with refinement off the photon map is frozen, so its noise and the
    // kernel's bias stay, and the same bound on the relMSE fails.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(24, 24);
    let reference = render(scene.clone(), TechniqueConfig::Path(path(1024)), 7, 1, 2).image;
    let device = Device::new(2).unwrap();
    let pool = relume::engine::thread_pool(2).unwrap();
    let run = |refine: f32| {
        pool.install(|| {
            let c = PhotonReuseConfig { refine, ..config(20_000, ReuseMode::Error) };
            let mut s = Session::new(scene.clone(), &TechniqueConfig::PhotonReuse(c), 9, &device).unwrap();
            let first = rel_mse(&s.tick().unwrap().image, &reference);
            let last = (1..64).map(|_| s.tick().unwrap()).last().unwrap().image;
            (first, rel_mse(&last, &reference), last.mean())
        })
    };
    let (first, last, mean) = run(0.125);
    let r = reference.mean();
    eprintln!("refined: relMSE {first:.5} after tick 1, {last:.5} after 64; mean {mean:?} vs {r:?}");
    assert!(last <= first / 10.0, "relMSE {last} after 64 still ticks, {first} after one");
    for (x, y) in mean.to_array().iter().zip(r.to_array()) {
        assert!((x - y).abs() <= 0.015 * y, "mean {mean:?} vs the reference {r:?}");
    }
    let (first, last, _) = run(0.0);
    eprintln!("frozen (negative control): relMSE {first:.5} after tick 1, {last:.5} after 64");
    assert!(last > first / 10.0, "a frozen photon map converged as fast: {last} vs {first}");
}

#[test]
fn naive_mode_retraces_only_what_a_move_touches_and_matches_the_baseline() {
    // Property: after a bunny moves, naive mode retraces a fraction of the paths (off retraces
    // all), and both images estimate the same radiance.
    let run = |reuse: ReuseMode| {
        let mut scene = load("bunnies-1.json");
        scene.set_resolution(32, 32);
        let device = Device::new(2).unwrap();
        let pool = relume::engine::thread_pool(2).unwrap();
        pool.install(|| {
            let mut s = Session::new(scene, &TechniqueConfig::PhotonReuse(config(150_000, reuse)), 9, &device).unwrap();
            s.tick().unwrap();
            let moved =
                Trs { translation: [350.0, 0.0, 250.0], rotation: [0.0, 0.0, 0.0, 1.0], scale: [150.0, 150.0, 150.0] };
            s.queue_edits(vec![Edit::Object { name: "bunny-1".into(), transform: moved }]).unwrap();
            let after = s.tick().unwrap();
            let st = photon_stats(&after);
            let mut last = after;
            for _ in 0..15 {
                last = s.tick().unwrap();
            }
            (st, last.image.mean())
        })
    };
    let (naive, naive_mean) = run(ReuseMode::Naive);
    let (off, off_mean) = run(ReuseMode::Off);
    eprintln!("naive: {naive:?}\noff: {off:?}");
    assert_eq!(off.fully_retraced, 150_000);
    let touched = naive.partly_retraced + naive.fully_retraced;
    assert!(touched > 0 && touched < 150_000 / 2, "naive retraced {touched} of 150000");
    assert!(
        naive.retrace_rays < off.retrace_rays / 2,
        "naive traced {} rays, off {}",
        naive.retrace_rays,
        off.retrace_rays
    );
    assert!(naive.verify_box_tests > 0);
    for (x, y) in naive_mean.to_array().iter().zip(off_mean.to_array()) {
        assert!((x - y).abs() < 0.04 * y, "naive {naive_mean:?} vs off {off_mean:?}");
    }
}

#[test]
fn bad_configurations_are_rejected_naming_the_field() {
    let scene = load("cornell-box.json");
    for (c, field) in [
        (PhotonReuseConfig { paths: 0, ..PhotonReuseConfig::default() }, "paths"),
        (PhotonReuseConfig { max_photons: 16, ..PhotonReuseConfig::default() }, "max_photons"),
        (PhotonReuseConfig { radius: Some(f32::NAN), ..PhotonReuseConfig::default() }, "radius"),
        (PhotonReuseConfig { spp: 0, ..PhotonReuseConfig::default() }, "spp"),
    ] {
        match relume::technique::build(&TechniqueConfig::PhotonReuse(c), &scene) {
            Err(relume::technique::TechniqueError::InvalidConfig { field: f, .. }) => assert_eq!(f, field),
            Err(other) => panic!("{field}: {other}"),
            Ok(_) => panic!("{field} accepted"),
        }
    }
    let parsed: Result<TechniqueConfig, _> = serde_json::from_str(r#"{"id": "photon_reuse", "reuse": "sometimes"}"#);
    assert!(parsed.is_err());
    // A field of the wrong type is named, though the technique is chosen by its `id` (serde's
    // tagged enums lose the field's name).
    for (json, field) in [
        (r#"{"id": "photon_reuse", "paths": -3}"#, "paths"),
        (r#"{"id": "photon_reuse", "distribution_map": {"position": [8, "x"]}}"#, "distribution_map.position[1]"),
        (r#"{"id": "path", "spp": 1.5}"#, "spp"),
    ] {
        let error = serde_json::from_str::<TechniqueConfig>(json).expect_err(json).to_string();
        assert!(error.starts_with(&format!("{field}: ")), "{json}: {error}");
    }
}

#[test]
fn only_what_the_scene_uses_is_allocated() {
    // Property: the store models only what the scene needs. With only point lights (the
    // furnace) no emission origins are stored; an area light (the Cornell box) needs them.
    let memory = |name: &str, paths: u32| {
        let mut scene = load(name);
        scene.set_resolution(8, 8);
        photon_stats(&render(scene, TechniqueConfig::PhotonReuse(config(paths, ReuseMode::Naive)), 1, 1, 1)).store
    };
    let point = memory("furnace.json", 1000);
    let area = memory("cornell-box.json", 1000);
    assert_eq!(point.origins, 0);
    assert!(area.origins > 0);
    assert_eq!(memory("cornell-box.json", 2000).origins, 2 * area.origins, "one origin per path");
    assert_eq!(point.photon_map, area.photon_map);
    assert_eq!(area.distribution_maps, 0, "no light moved: no maps");

    // A moving point light gets a 2-D (θ, φ) map, never the 4-D area-light one, and still no
    // origins. A scene with no dynamic object verifies nothing when only the camera moves.
    let device = Device::new(1).unwrap();
    let mut desc = load("furnace.json").desc().clone();
    desc.lights[0].dynamic = true;
    desc.camera.resolution = [8, 8];
    let scene = relume::scene::Scene::from_desc(desc, &scenes_dir(), &scenes_dir()).unwrap();
    let mut s = Session::new(scene, &TechniqueConfig::PhotonReuse(config(4000, ReuseMode::Error)), 1, &device).unwrap();
    s.tick().unwrap();
    s.queue_edits(vec![camera_dolly()]).unwrap();
    let still = photon_stats(&s.tick().unwrap());
    assert_eq!((still.verify_box_tests, still.verify_rays, still.origin_rays), (0, 0, 0));
    assert_eq!(still.store.distribution_maps, 0);
    let moved = Trs { translation: [0.1, 0.0, 0.0], rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0, 1.0, 1.0] };
    s.queue_edits(vec![Edit::Light { name: "centre".into(), transform: Some(moved), emitter: None }]).unwrap();
    let m = photon_stats(&s.tick().unwrap());
    let cells = relume::technique::photon_reuse::MapResolution::default().direction.iter().product::<u32>() as u64;
    assert_eq!(m.distribution_cells, cells, "a point light's map is 2-D");
    assert!(m.store.distribution_maps > 0);
    assert_eq!(m.store.origins, 0);
}
