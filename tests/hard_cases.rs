//! Numerically hard cases. Each test states the property it protects.
mod common;
use common::*;
use relume::film::LinearImage;
use relume::scene::{Scene, SceneDesc};
use relume::technique::{TechniqueConfig, TechniqueStats};
use serde_json::json;

/// The Cornell box with every position mapped by x ↦ s·x + offset (objects, lights, camera).
fn transformed_cornell(scale: f32, offset: [f32; 3]) -> Scene {
    let dir = scenes_dir();
    let mut desc: SceneDesc =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cornell-box.json")).unwrap()).unwrap();
    let map = |p: [f32; 3]| [p[0] * scale + offset[0], p[1] * scale + offset[1], p[2] * scale + offset[2]];
    for o in &mut desc.objects {
        o.transform.translation = map(o.transform.translation);
        o.transform.scale = o.transform.scale.map(|v| v * scale);
    }
    for l in &mut desc.lights {
        l.transform.translation = map(l.transform.translation);
        l.transform.scale = l.transform.scale.map(|v| v * scale);
    }
    desc.camera.position = map(desc.camera.position);
    desc.camera.look_at = map(desc.camera.look_at);
    desc.camera.resolution = [32, 32];
    Scene::from_desc(desc, &dir, &dir).unwrap()
}

fn render_path(scene: Scene) -> LinearImage {
    std::sync::Arc::unwrap_or_clone(render(scene, TechniqueConfig::Path(path(64)), 11, 1, 2).image)
}

#[test]
fn far_from_the_origin_and_at_any_scale_the_cornell_box_renders_the_same() {
    // Property: ray origins are offset by the hit point's floating-point error bound
    // (Wächter & Binder), not by a fixed epsilon, so neither self-intersection (dark speckles,
    // lost energy) nor light leaking appears when coordinates are huge or tiny. Radiance does not
    // depend on scale, so every variant must match the original within noise.
    let reference = render_path(transformed_cornell(1.0, [0.0; 3]));
    let reference_blocks = block_means(&reference);
    for (name, scale, offset) in [
        ("translated by 1e5", 1.0, [1e5, 1e5, 1e5]),
        ("scaled by 1e-3", 1e-3, [0.0; 3]),
        ("scaled by 1e3", 1e3, [0.0; 3]),
    ] {
        let img = render_path(transformed_cornell(scale, offset));
        assert_finite_non_negative(&img);
        let (a, b) = (img.mean().luminance() as f64, reference.mean().luminance() as f64);
        eprintln!("{name}: mean luminance {a:.5} vs {b:.5}");
        assert!((a - b).abs() < 0.02 * b, "{name}: mean {a} vs {b}");
        for (i, (x, y)) in block_means(&img).iter().zip(&reference_blocks).enumerate() {
            assert!((x - y).abs() < 0.08 * y + 0.002, "{name}: block {i}: {x} vs {y}");
        }
    }
}

/// A 4 m diffuse floor, a camera and a point light of `intensity` placed by the caller.
fn floor_scene(camera: [f32; 3], light: [f32; 3], intensity: f32) -> Scene {
    scene_from_json(json!({
        "camera": {"position": camera, "look_at": [0, 0, 0], "vfov_deg": 40, "resolution": [16, 16]},
        "materials": {"white": {"type": "diffuse", "reflectance": [0.8, 0.8, 0.8]}},
        "objects": [{"name": "floor", "shape": {"type": "quad"}, "material": "white",
                     "transform": {"rotation": FACE_UP, "scale": [2, 2, 1]}}],
        "lights": [{"name": "bulb", "emitter": {"type": "point", "intensity": [intensity, intensity, intensity]},
                    "transform": {"translation": light}}]
    }))
}

#[test]
fn grazing_camera_and_light_give_finite_non_negative_images() {
    // Property: at 89.9° from the normal, cosines near zero and long footprints produce no NaN,
    // Inf or negative radiance in any technique.
    let h = 5.0 * 0.1f32.to_radians().tan();
    for config in small_techniques() {
        let img = render(floor_scene([0.0, h, -5.0], [5.0, h, 0.0], 10.0), config.clone(), 3, 2, 2).image;
        assert_finite_non_negative(&img);
        assert!(img.mean().max_component() > 0.0, "{}: the grazing light should still light the floor", config.id());
    }
}

#[test]
fn a_closed_box_leaks_no_light_to_its_outside() {
    // Property: a light inside a closed box lights nothing outside it. The box's faces have no
    // thickness: a shadow ray from the outside must be stopped by the face it leaves, and the
    // photon gather must not pick up photons from the face's inner side.
    let scene = scene_from_json(json!({
        "camera": {"position": [0.5, 1.5, 4], "look_at": [0, 0, 0], "vfov_deg": 45, "resolution": [24, 24]},
        "materials": {"white": {"type": "diffuse", "reflectance": [0.8, 0.8, 0.8]}},
        "objects": [{"name": "box", "shape": {"type": "box"}, "material": "white"}],
        "lights": [{"name": "bulb", "emitter": {"type": "point", "intensity": [20, 20, 20]}}]
    }));
    for config in small_techniques() {
        let img = render(scene.clone(), config.clone(), 5, 2, 2).image;
        assert_finite_non_negative(&img);
        assert_eq!(img.mean().max_component(), 0.0, "{}: light leaked out of the box", config.id());
    }
}

#[test]
fn degenerate_triangles_are_dropped_with_a_count_and_needles_render_finite() {
    // Property: zero-area triangles (repeated vertices, collinear ones) are dropped at load and
    // counted; a needle triangle (area 1e-8 of its neighbours) stays and traces to finite values.
    let dir = std::env::temp_dir().join(format!("relume-hard-degenerate-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("scenes")).unwrap();
    std::fs::write(
        dir.join("scenes/bad.obj"),
        "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv 0 0 0\nv 0.5 0 0.5\nv 0 1e-8 2\n\
         f 1 2 3\nf 1 3 4\nf 1 1 2\nf 1 5 6\nf 2 7 4\n",
    )
    .unwrap();
    let desc = json!({
        "camera": {"position": [0, 2, -3], "look_at": [0, 0, 0], "vfov_deg": 50, "resolution": [16, 16]},
        "materials": {"white": {"type": "diffuse", "reflectance": [0.7, 0.7, 0.7]}},
        "objects": [{"name": "mesh", "shape": {"type": "mesh", "path": "bad.obj"}, "material": "white"}],
        "lights": [{"name": "bulb", "emitter": {"type": "point", "intensity": [5, 5, 5]},
                    "transform": {"translation": [0, 2, 0]}}]
    });
    let desc: relume::scene::SceneDesc = serde_json::from_value(desc).unwrap();
    let root = dir.join("scenes");
    let scene = Scene::from_desc(desc, &root, &root).unwrap();
    assert_eq!(scene.dropped_degenerate, vec![("mesh".to_string(), 2)]);
    for config in small_techniques() {
        let img = render(scene.clone(), config, 2, 2, 2).image;
        assert_finite_non_negative(&img);
        assert!(img.mean().max_component() > 0.0);
    }
}

#[test]
fn coincident_surfaces_render_deterministically_and_finite() {
    // Property: two coplanar quads of different colours (z-fighting) give whichever hit Embree
    // reports, the same one every time: the same seed gives the same, finite image.
    let scene = scene_from_json(json!({
        "camera": {"position": [0, 3, -3], "look_at": [0, 0, 0], "vfov_deg": 50, "resolution": [16, 16]},
        "materials": {"red": {"type": "diffuse", "reflectance": [0.8, 0.1, 0.1]},
                      "green": {"type": "diffuse", "reflectance": [0.1, 0.8, 0.1]}},
        "objects": [
            {"name": "a", "shape": {"type": "quad"}, "material": "red", "transform": {"rotation": FACE_UP}},
            {"name": "b", "shape": {"type": "quad"}, "material": "green", "transform": {"rotation": FACE_UP}}
        ],
        "lights": [{"name": "bulb", "emitter": {"type": "point", "intensity": [5, 5, 5]},
                    "transform": {"translation": [0, 2, 0]}}]
    }));
    for config in small_techniques() {
        let a = render(scene.clone(), config.clone(), 9, 2, 2).image;
        let b = render(scene.clone(), config.clone(), 9, 2, 2).image;
        assert_finite_non_negative(&a);
        assert_eq!(a, b, "{}", config.id());
    }
}

#[test]
fn extreme_light_placement_and_power_stay_finite_and_linear() {
    // Properties: a point light 1e-6 m above a surface gives a finite image (its 1/d² peak is
    // about 1e12 and is carried in f32 and summed in f64); a zero-intensity light gives exact
    // black; radiance is linear in intensity from 1e-20 to 1e20 (no underflow to zero, no
    // overflow to Inf): with the same seed, mean(I)/I is the same for every I.
    for config in small_techniques() {
        let id = config.id();
        let near = render(floor_scene([0.0, 2.0, -3.0], [0.0, 1e-6, 0.0], 1.0), config.clone(), 4, 2, 2).image;
        assert_finite_non_negative(&near);
        assert!(near.pixels.iter().all(|p| p.max_component() < 1e14), "{id}: unbounded");
        let dark = render(floor_scene([0.0, 2.0, -3.0], [0.0, 1.0, 0.0], 0.0), config.clone(), 4, 2, 2).image;
        assert!(dark.pixels.iter().all(|p| p.max_component() == 0.0), "{id}: a black light lit something");
        let unit = render(floor_scene([0.0, 2.0, -3.0], [0.0, 1.0, 0.0], 1.0), config.clone(), 4, 2, 2).image;
        let base = unit.mean().luminance() as f64;
        assert!(base > 0.0);
        for intensity in [1e-20f32, 1e20] {
            let img = render(floor_scene([0.0, 2.0, -3.0], [0.0, 1.0, 0.0], intensity), config.clone(), 4, 2, 2).image;
            assert_finite_non_negative(&img);
            let ratio = img.mean().luminance() as f64 / intensity as f64 / base;
            assert!((ratio - 1.0).abs() < 1e-3, "{id}: intensity {intensity:e} scales radiance by {ratio}");
        }
    }
}

#[test]
fn a_million_samples_of_one_pixel_stay_accurate() {
    // Property: the film sums in f64, so 10^6 samples keep their mean to about 1e-12 relative,
    // where a plain f32 running sum is off by far more than the noise of the mean (which is 0
    // here: the samples are a fixed sequence with a known mean).
    let samples = (0..1_000_000u32).map(|i| 0.1 + 0.05 * ((i % 7) as f32 - 3.0));
    let exact: f64 = samples.clone().map(|x| x as f64).sum::<f64>() / 1e6;
    let mut accum = relume::film::PixelAccum::default();
    let mut naive = 0.0f32;
    for x in samples {
        accum.add(relume::core::Rgb::splat(x));
        accum.count += 1.0;
        naive += x;
    }
    let shipped = accum.mean().r as f64;
    let naive = naive as f64 / 1e6;
    eprintln!("exact {exact}, f64 film {shipped}, f32 running sum {naive}");
    assert!((shipped - exact).abs() < 1e-7 * exact, "the film lost precision: {shipped} vs {exact}");
    assert!((naive - exact).abs() > 100.0 * (shipped - exact).abs(), "the f32 comparison should show its drift");
}

/// A unit sphere of reflectance `rho` around a point light, seen from inside.
fn furnace(rho: f32) -> Scene {
    scene_from_json(json!({
        "camera": {"position": [0, 0, 0.3], "look_at": [0, 0, -1], "vfov_deg": 60, "resolution": [8, 8]},
        "materials": {"wall": {"type": "diffuse", "reflectance": [rho, rho, rho]}},
        "objects": [{"name": "sphere", "shape": {"type": "sphere", "segments": 64}, "material": "wall"}],
        "lights": [{"name": "centre", "emitter": {"type": "point", "intensity": [1, 1, 1]}}]
    }))
}

/// How many scattering events the technique's paths reach before it truncates them, as its
/// configuration or stats say: path and bdpt stop at l_m vertices, photon paths at B photons,
/// an instant-cache VPL path at its VPL cap (plus direct light), particle light after the
/// emission, the first bounce and n_b more.
fn truncation_depth(config: &TechniqueConfig, detail: &TechniqueStats) -> f32 {
    match (config, detail) {
        (_, TechniqueStats::Path(s)) => s.max_path_length as f32,
        (_, TechniqueStats::Bdpt(s)) => s.lanes.max_path_length as f32,
        (TechniqueConfig::PhotonReuse(c), _) => c.max_photons as f32,
        (_, TechniqueStats::InstantCache(s)) => (s.vpls / s.vpl_paths.max(1)) as f32 + 1.0,
        (_, TechniqueStats::ParticleGi(s)) => s.bounces as f32 + 2.0,
        _ => panic!("no truncation depth for {}", config.id()),
    }
}

#[test]
fn extreme_albedo_terminates_and_stays_finite() {
    // Properties: at ρ = 1 the closed furnace's radiance diverges, yet every technique stops
    // with finite values. Truncated after k scattering events, the answer is the series
    // (I/πR²) Σ_{j=1..k} ρ^j = k/π: each technique must give its own k/π within 10% (one tick
    // of 8×8 pixels). Negative control: ρ = 0.9 (a series below 9/π) must fail that bound for
    // every technique, so the bound tells a truncated ρ = 1 series from a converging one.
    // At ρ = 0 nothing is reflected: exact black (the light is a point, so not seen directly).
    for config in small_techniques() {
        let within = |rho: f32| {
            let frame = render(furnace(rho), config.clone(), 2, 1, 2);
            assert_finite_non_negative(&frame.image);
            let k = truncation_depth(&config, &frame.stats.detail);
            let got = frame.image.mean().g * std::f32::consts::PI;
            eprintln!("{} at ρ = {rho}: {got:.3}/π against {k}/π", config.id());
            ((got - k).abs() <= 0.1 * k, got, k)
        };
        let (ok, got, k) = within(1.0);
        assert!(ok, "{}: ρ = 1 gives {got}/π, the truncated series {k}/π", config.id());
        assert!(!within(0.9).0, "{}: the bound cannot tell ρ = 0.9 from ρ = 1", config.id());
        let black = render(furnace(0.0), config.clone(), 2, 1, 2).image;
        assert!(black.pixels.iter().all(|p| p.max_component() == 0.0), "{}", config.id());
    }
}

#[test]
fn the_same_seed_gives_the_same_image_on_one_and_two_threads() {
    // Property: random streams are keyed by (seed, tick, pixel, sample) and by path, never by
    // thread, so results do not depend on scheduling, for every technique.
    let mut scene = load("bunnies-1.json");
    scene.set_resolution(24, 24);
    for config in small_techniques() {
        let one = render(scene.clone(), config.clone(), 17, 2, 1).image;
        let two = render(scene.clone(), config.clone(), 17, 2, 2).image;
        assert_eq!(one, two, "{}", config.id());
    }
}
