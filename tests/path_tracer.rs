//! The reference path tracer against analytic answers and against itself.
mod common;
use common::*;
use relume::technique::TechniqueConfig;

#[test]
fn furnace_matches_the_analytic_radiance_within_one_percent() {
    // Property: the estimator is unbiased up to the l_m truncation, which c = 1e-4 makes
    // negligible (ρ^l_m ≈ 6e-5). The bound includes the 99.9% two-sided Student-t interval.
    let config = TechniqueConfig::Path(relume::technique::path::PathConfig { admitted_truncation: 1e-4, ..path(2) });
    assert_within_one_percent("furnace", &furnace_batches(&config, 12, None, 1), furnace_radiance(None));
}

#[test]
fn furnace_truncated_paths_match_the_truncated_series() {
    // Property: bounce k adds exactly ρ^k of the light: energy is conserved bounce by bounce, and
    // `max_path_length` cuts exactly where it says.
    for k in [1u32, 2, 4] {
        let config = TechniqueConfig::Path(relume::technique::path::PathConfig { max_path_length: Some(k), ..path(2) });
        assert_within_one_percent(
            &format!("furnace k={k}"),
            &furnace_batches(&config, 6, None, 1),
            furnace_radiance(Some(k)),
        );
    }
}

#[test]
fn cornell_box_radiance_grows_with_bounces_and_converges() {
    // Property: each extra bounce adds non-negative energy, and the additions shrink
    // geometrically (ρ_S < 1), so the mean converges.
    let means: Vec<f64> = [1u32, 2, 3, 6, 12]
        .iter()
        .map(|&k| {
            let mut scene = load("cornell-box.json");
            scene.set_resolution(48, 48);
            let config = relume::technique::path::PathConfig { max_path_length: Some(k), ..path(8) };
            let frame = render(scene, TechniqueConfig::Path(config), 7, 1, 2);
            assert_finite_non_negative(&frame.image);
            frame.image.mean().luminance() as f64
        })
        .collect();
    eprintln!("cornell mean luminance by max path length 1,2,3,6,12: {means:?}");
    for w in means.windows(2) {
        assert!(w[1] > w[0] * 0.995, "mean fell with more bounces: {means:?}");
    }
    let first_gain = means[1] - means[0];
    let last_gain = means[4] - means[3];
    assert!(first_gain > 0.05 * means[0], "indirect light missing: {means:?}");
    assert!(last_gain < 0.25 * first_gain, "not converging: {means:?}");
}

#[test]
fn same_seed_gives_the_same_image_with_one_and_two_threads() {
    for width in [1u32, 8, 16] {
        let config = relume::technique::path::PathConfig { packet_width: Some(width), ..path(2) };
        let mut scene = load("cornell-box.json");
        scene.set_resolution(40, 30);
        let one = render(scene.clone(), TechniqueConfig::Path(config.clone()), 42, 2, 1);
        let two = render(scene, TechniqueConfig::Path(config), 42, 2, 2);
        assert_eq!(one.image, two.image, "packet width {width}");
        assert_eq!(one.stats.rays, two.stats.rays);
    }
}

#[test]
fn regeneration_and_packet_widths_change_the_order_not_the_image() {
    // Property: every path has its own random stream and each pixel a fixed number of paths, so
    // how lanes are filled cannot change the estimate (this is what makes regeneration unbiased).
    let image = |regeneration: bool, packet_width: u32| {
        let mut scene = load("cornell-box.json");
        scene.set_resolution(24, 20);
        let config = relume::technique::path::PathConfig { regeneration, packet_width: Some(packet_width), ..path(2) };
        render(scene, TechniqueConfig::Path(config), 9, 1, 2).image
    };
    let reference = image(true, 16);
    for (regeneration, width) in [(false, 16), (true, 8), (false, 8), (true, 1), (false, 1)] {
        let other = image(regeneration, width);
        let worst = reference
            .pixels
            .iter()
            .zip(&other.pixels)
            .map(|(a, b)| (*a - *b).max_component().abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "regeneration {regeneration}, width {width}: max pixel difference {worst}");
    }
}

#[test]
fn regeneration_keeps_lanes_busier() {
    let stats = |regeneration: bool| {
        let mut scene = load("cornell-box.json");
        scene.set_resolution(32, 32);
        let config = relume::technique::path::PathConfig { regeneration, packet_width: Some(16), ..path(1) };
        match render(scene, TechniqueConfig::Path(config), 3, 1, 1).stats.detail {
            relume::technique::TechniqueStats::Path(p) => p,
            other => panic!("path stats expected, got {other:?}"),
        }
    };
    let on = stats(true);
    let off = stats(false);
    eprintln!("utilisation: regeneration {:.3}, none {:.3}", on.lane_utilisation(), off.lane_utilisation());
    assert!(on.lane_utilisation() > off.lane_utilisation());
    assert!(on.lane_utilisation() > 0.7);
}

#[test]
fn progressive_accumulation_resets_on_change() {
    use relume::embree::Device;
    use relume::engine::Session;
    let device = Device::new(1).unwrap();
    let mut scene = load("cornell-box.json");
    scene.set_resolution(16, 16);
    let mut s = Session::new(scene, &TechniqueConfig::Path(path(1)), 1, &device).unwrap();
    let f1 = s.tick().unwrap();
    let f2 = s.tick().unwrap();
    assert_eq!(f1.accumulation_id, f2.accumulation_id);
    assert_eq!((f1.spp, f2.spp), (1, 2));
    s.queue_edits(vec![camera_dolly()]).unwrap();
    let f3 = s.tick().unwrap();
    assert_ne!(f3.accumulation_id, f2.accumulation_id);
    assert_eq!(f3.spp, 1);
    assert_eq!(f3.stats.edits_received, 1);
}

#[test]
fn the_fraction_of_paths_cut_at_l_m_is_the_analytic_one_and_within_c() {
    // Property: in the furnace (ρ = 0.5, closed, no escape) a path survives roulette with
    // probability ρ² at its second vertex and ρ at each later one, so the fraction cut short at
    // l_m is exactly ρ^l_m, and l_m = ⌈log_ρ c⌉ keeps it below c (Novák et al. §3.3).
    let mut scene = load("furnace.json");
    scene.set_resolution(64, 64);
    let frame = render(scene, TechniqueConfig::Path(path(16)), 7, 1, 2);
    let relume::technique::TechniqueStats::Path(p) = &frame.stats.detail else { panic!("path stats expected") };
    let n = p.paths as f64;
    let observed = p.truncated_paths as f64 / n;
    let expected = 0.5f64.powi(p.max_path_length as i32);
    let sigma = (expected * (1.0 - expected) / n).sqrt();
    eprintln!(
        "l_m {}: {} of {} paths cut, {observed:.5} (analytic {expected:.5} ± {sigma:.5})",
        p.max_path_length, p.truncated_paths, p.paths
    );
    assert!((observed - expected).abs() < 4.0 * sigma, "{observed} vs {expected}");
    let c = relume::technique::path::PathConfig::default().admitted_truncation as f64;
    assert!(observed < c, "{observed} of paths cut, c = {c}");
    // Negative control: one vertex more (ρ^(l_m+1)) is outside the same 4σ.
    let one_more = 0.5f64.powi(p.max_path_length as i32 + 1);
    assert!((observed - one_more).abs() > 4.0 * sigma, "{observed} vs {one_more}");
}
