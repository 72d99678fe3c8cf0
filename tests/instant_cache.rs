//! `instant_cache` (modes `igi`, `static` and `temporal`) against analytic answers and the `path`
//! reference.
mod common;
use common::*;
use relume::technique::instant_cache::{CacheMode, InstantCacheConfig};
use relume::technique::{TechniqueConfig, TechniqueStats};

/// How closely instant_cache must match `path` on the Cornell box, allowing the VPL bias
/// (1024 VPLs, clamped geometry term, interpolation); the negative control must fail it.
const CORNELL_TOLERANCE: Tolerance = Tolerance { channel: 0.04, block: 0.15, floor: 0.003 };

fn config(mode: CacheMode) -> InstantCacheConfig {
    InstantCacheConfig { mode, ..InstantCacheConfig::default() }
}

fn stats(frame: &relume::engine::Frame) -> relume::technique::instant_cache::InstantCacheStats {
    match &frame.stats.detail {
        TechniqueStats::InstantCache(s) => (**s).clone(),
        other => panic!("instant_cache stats expected, got {other:?}"),
    }
}

#[test]
fn furnace_is_within_one_percent_in_every_mode() {
    // Property: direct light by NEE plus indirect light from VPLs reproduce L = 1/π. The
    // irradiance is uniform, so interpolation adds no bias; c = 1e-4 makes the VPL paths'
    // truncation negligible and no clamp hides near VPLs. The VPLs are a scrambled Halton
    // set (fixed), so the figure is deterministic: a plain Halton set was 4.7% high here.
    let expected = furnace_radiance(None);
    for mode in [CacheMode::Igi, CacheMode::Static, CacheMode::Temporal] {
        let mut scene = load("furnace.json");
        scene.set_resolution(24, 24);
        let c =
            InstantCacheConfig { vpls: 1024, admitted_truncation: 1e-4, clamp_distance: 0.0, spp: 8, ..config(mode) };
        let img = render(scene, TechniqueConfig::InstantCache(c), 2, 1, 2).image;
        assert_finite_non_negative(&img);
        let mean = img.mean().g as f64;
        eprintln!("furnace {mode:?}: {mean:.5} (expected {expected:.5})");
        assert!((mean - expected).abs() < 0.01 * expected, "{mode:?}: {mean} vs {expected}");
    }
}

#[test]
fn cornell_box_matches_the_path_reference_within_the_vpl_bias() {
    // Property: both modes estimate the same image as `path`, up to the VPL method's bias
    // (1024 VPLs, clamped geometry term, interpolation): channel means within 4%, 4×4 block
    // means within 15%.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(32, 32);
    let reference = render(scene.clone(), TechniqueConfig::Path(path(256)), 3, 1, 2).image;
    for mode in [CacheMode::Igi, CacheMode::Static] {
        let c = InstantCacheConfig { spp: 64, vpls: 1024, ..config(mode) };
        let frame = render(scene.clone(), TechniqueConfig::InstantCache(c), 5, 1, 2);
        assert_matches_reference(&format!("{mode:?}"), &frame.image, &reference, CORNELL_TOLERANCE);
    }
    // Negative control: VPL paths cut after their first bounce (a truncation of 0.99) fail the
    // same bounds.
    let broken = InstantCacheConfig { spp: 64, vpls: 1024, admitted_truncation: 0.99, ..config(CacheMode::Static) };
    let frame = render(scene, TechniqueConfig::InstantCache(broken), 5, 1, 2);
    assert_rejected_by_reference("instant_cache, one bounce", &frame.image, &reference, CORNELL_TOLERANCE);
}

#[test]
fn the_cache_is_sparse_and_igi_gathers_a_subset_per_pixel() {
    // Properties: `static` makes far fewer records than pixels, each with one visibility ray
    // per VPL at most; `igi` traces about VPLs/n² visibility rays per pixel.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(64, 64);
    let pixels = 64 * 64;
    let s = stats(&render(scene.clone(), TechniqueConfig::InstantCache(config(CacheMode::Static)), 1, 1, 2));
    eprintln!("static: {s:?}");
    assert!(s.records > 10 && s.records < pixels / 4, "{} records for {pixels} pixels", s.records);
    assert_eq!(s.records, s.records_created);
    assert!(s.visibility_rays <= s.records * s.vpls && s.visibility_rays > s.records * s.vpls / 4);
    assert!(s.memory.part("cache") >= s.records * s.vpls * 4, "RGBE: 4 bytes per VPL per record");
    let i = stats(&render(scene, TechniqueConfig::InstantCache(config(CacheMode::Igi)), 1, 1, 2));
    let per_pixel = i.visibility_rays as f64 / pixels as f64;
    eprintln!("igi: {per_pixel:.1} visibility rays per pixel for {} VPLs", i.vpls);
    assert!(per_pixel <= i.vpls as f64 / 16.0 + 1.0, "{per_pixel}");
    assert_eq!(i.records, 0);
}

#[test]
fn bad_configurations_are_rejected_naming_the_field() {
    let scene = load("cornell-box.json");
    for (c, field) in [
        (InstantCacheConfig { vpls: 0, ..InstantCacheConfig::default() }, "vpls"),
        (InstantCacheConfig { interleave: 0, ..InstantCacheConfig::default() }, "interleave"),
        (InstantCacheConfig { caching_radius: f32::NAN, ..InstantCacheConfig::default() }, "caching_radius"),
        (InstantCacheConfig { clamp_distance: -1.0, ..InstantCacheConfig::default() }, "clamp_distance"),
        (InstantCacheConfig { max_age: 0, ..InstantCacheConfig::default() }, "max_age"),
    ] {
        match relume::technique::build(&TechniqueConfig::InstantCache(c), &scene) {
            Err(relume::technique::TechniqueError::InvalidConfig { field: f, .. }) => assert_eq!(f, field),
            Err(other) => panic!("{field}: {other}"),
            Ok(_) => panic!("{field} accepted"),
        }
    }
}
