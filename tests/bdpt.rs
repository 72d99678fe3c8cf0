//! `bdpt` against analytic answers and the `path` reference, and where it beats `path`.
mod common;
use common::*;
use relume::technique::bdpt::BdptConfig;
use relume::technique::TechniqueConfig;
use serde_json::json;

/// How closely bdpt must match the `path` reference on the Cornell box; the negative control
/// must fail the same tolerance.
const CORNELL_TOLERANCE: Tolerance = Tolerance { channel: 0.02, block: 0.06, floor: 0.002 };

fn bdpt(spp: u32) -> BdptConfig {
    BdptConfig { spp, ..BdptConfig::default() }
}

#[test]
fn furnace_matches_the_analytic_radiance_within_one_percent() {
    // Property: the weighted strategies sum to an unbiased estimate; c = 1e-4 makes the l_m
    // truncation negligible. The bound includes the 99.9% Student-t interval over independent seeds.
    for permute in [true, false] {
        let c = TechniqueConfig::Bdpt(BdptConfig { admitted_truncation: 1e-4, permute, ..bdpt(16) });
        assert_within_one_percent(
            &format!("furnace, permute {permute}"),
            &furnace_batches(&c, 10, Some(16), 1),
            furnace_radiance(None),
        );
    }
}

#[test]
fn cornell_box_matches_the_path_reference_with_and_without_permutation_and_batches() {
    // Property: light-subpath permutation changes which light subpath an eye vertex meets, never
    // the expectation: both variants converge to the path tracer's image.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(32, 32);
    let reference = render(scene.clone(), TechniqueConfig::Path(path(512)), 3, 1, 2).image;
    // So does one light subpath per eye path (each eye path's own) instead of a shared batch.
    for (permute, light_per_eye_path) in [(true, false), (false, false), (false, true)] {
        let c = BdptConfig { permute, light_per_eye_path, ..bdpt(128) };
        let img = render(scene.clone(), TechniqueConfig::Bdpt(c), 5, 1, 2).image;
        let label = format!("bdpt permute {permute}, light per eye path {light_per_eye_path}");
        assert_matches_reference(&label, &img, &reference, CORNELL_TOLERANCE);
    }
    // Negative control: bdpt cut to two-vertex paths (no indirect light) fails the same bound.
    let broken = BdptConfig { max_path_length: Some(2), ..BdptConfig { spp: 2, ..Default::default() } };
    let img = render(scene.clone(), TechniqueConfig::Bdpt(broken), 5, 1, 2).image;
    assert_rejected_by_reference("bdpt, two vertices", &img, &reference, CORNELL_TOLERANCE);
}

#[test]
fn a_light_hidden_in_a_narrow_gap_converges_faster_than_path() {
    // Property (BDPT's reason to exist): an area light faces the ceiling 5 cm below it, so the
    // room is lit only through that narrow gap. `path` must find the small lit patch of ceiling
    // by BSDF sampling before its light sample can see the light; `bdpt` connects every eye
    // vertex to light subpath vertices on that patch. At equal samples per pixel its relMSE
    // against a converged `path` reference is lower.
    let scene = scene_from_json(json!({
        "camera": {"position": [0, 1, -1.9], "look_at": [0, 0.8, 0], "vfov_deg": 70, "resolution": [24, 24]},
        "materials": {"white": {"type": "diffuse", "reflectance": [0.7, 0.7, 0.7]}},
        "objects": [{"name": "room", "shape": {"type": "box"}, "material": "white",
                     "transform": {"translation": [0, 1, 0], "scale": [2, 1, 2]}}],
        "lights": [{"name": "uplight", "emitter": {"type": "rect", "radiance": [30, 30, 30]},
                    "transform": {"translation": [0, 1.95, 0],
                                  "rotation": FACE_UP, "scale": [0.2, 0.2, 1]}}]
    }));
    let reference = render(scene.clone(), TechniqueConfig::Path(path(4096)), 1, 1, 2).image;
    assert!(reference.mean().g > 0.0, "the room should be lit through the gap");
    let spp = 16;
    let errors = |config: TechniqueConfig| {
        (0..3)
            .map(|seed| rel_mse(&render(scene.clone(), config.clone(), 40 + seed, 1, 2).image, &reference))
            .sum::<f64>()
            / 3.0
    };
    let p = errors(TechniqueConfig::Path(path(spp)));
    let b = errors(TechniqueConfig::Bdpt(bdpt(spp)));
    eprintln!("relMSE at {spp} spp: path {p:.4}, bdpt {b:.4}");
    assert!(b < 0.7 * p, "bdpt {b} should beat path {p} clearly");
}

#[test]
fn regeneration_changes_the_order_not_the_image_and_keeps_lanes_busier() {
    // Property: each eye path draws from its own stream and each packet's light batch from its
    // own, so regeneration on or off gives the identical image; with it, lanes idle less.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(32, 32);
    let run = |regeneration: bool| {
        let c = BdptConfig { regeneration, packet_width: Some(16), ..bdpt(2) };
        render(scene.clone(), TechniqueConfig::Bdpt(c), 8, 1, 2)
    };
    let (on, off) = (run(true), run(false));
    assert_eq!(on.image, off.image);
    let utilisation = |f: &relume::engine::Frame| match &f.stats.detail {
        relume::technique::TechniqueStats::Bdpt(s) => s.lanes.lane_utilisation(),
        other => panic!("bdpt stats expected, got {other:?}"),
    };
    eprintln!("utilisation: regeneration {:.3}, none {:.3}", utilisation(&on), utilisation(&off));
    assert!(utilisation(&on) > utilisation(&off));
}

#[test]
fn it_accumulates_progressively_and_restarts_when_the_scene_changes() {
    // Property: the same progressive contract as `path`: passes accumulate while nothing
    // changes (spp grows, accumulation id stays), and any edit restarts the film.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(16, 16);
    let device = relume::embree::Device::new(1).unwrap();
    let mut s = relume::engine::Session::new(scene, &TechniqueConfig::Bdpt(bdpt(2)), 1, &device).unwrap();
    let first = s.tick().unwrap();
    let second = s.tick().unwrap();
    assert_eq!((first.spp, second.spp), (2, 4));
    assert_eq!(first.accumulation_id, second.accumulation_id);
    s.queue_edits(vec![camera_dolly()]).unwrap();
    let after = s.tick().unwrap();
    assert_eq!(after.spp, 2);
    assert_ne!(after.accumulation_id, second.accumulation_id);
    assert_finite_non_negative(&after.image);
}

#[test]
fn light_subpath_roulette_does_not_depend_on_the_lights_units() {
    // Property: Russian roulette on light subpaths uses the throughput since the light, so with
    // the same seed a light 10⁴ times brighter traces the same light subpaths (rays per subpath
    // equal) and only the image scales. Roulette on the flux-carrying β, as before, never fired
    // for a bright light: its subpaths ran to l_m.
    let room = |radiance: f32, reflectance: f32| {
        scene_from_json(json!({
            "camera": {"position": [0, 1, -1.9], "look_at": [0, 1, 0], "vfov_deg": 70, "resolution": [16, 16]},
            "materials": {"wall": {"type": "diffuse", "reflectance": [reflectance, reflectance, reflectance]}},
            "objects": [{"name": "room", "shape": {"type": "box"}, "material": "wall",
                         "transform": {"translation": [0, 1, 0], "scale": [2, 1, 2]}}],
            "lights": [{"name": "panel", "emitter": {"type": "rect", "radiance": [radiance, radiance, radiance]},
                        "transform": {"translation": [0, 1.95, 0], "rotation": FACE_DOWN, "scale": [0.3, 0.3, 1]}}]
        }))
    };
    let run = |scene| {
        let frame = render(scene, TechniqueConfig::Bdpt(bdpt(2)), 3, 1, 1);
        let relume::technique::TechniqueStats::Bdpt(s) = &frame.stats.detail else { panic!("bdpt stats expected") };
        let mean = frame.image.pixels.iter().map(|p| p.r as f64).sum::<f64>() / frame.image.pixels.len() as f64;
        (s.light_subpath_rays as f64 / s.light_subpaths as f64, mean)
    };
    let (base_rays, base_mean) = run(room(1.0, 0.7));
    let (bright_rays, bright_mean) = run(room(1e4, 0.7));
    eprintln!("rays per light subpath: radiance 1 {base_rays:.3}, radiance 1e4 {bright_rays:.3}");
    let tolerance = 0.01;
    assert!((bright_rays / base_rays - 1.0).abs() < tolerance, "{bright_rays} vs {base_rays}");
    assert!((bright_mean / base_mean / 1e4 - 1.0).abs() < 1e-3, "image ratio {}", bright_mean / base_mean);
    // Negative control: halving the walls' reflectance shortens the subpaths beyond the tolerance.
    let (dark_rays, _) = run(room(1.0, 0.35));
    assert!((dark_rays / base_rays - 1.0).abs() > tolerance, "{dark_rays} vs {base_rays}");
}

/// `scenes/caustic-ball.json` (a glass ball imaging a point light onto the floor) at 32².
fn caustic_room() -> relume::scene::Scene {
    let mut scene = load("caustic-ball.json");
    scene.set_resolution(32, 32);
    scene
}

/// Pixels whose centre ray meets the floor within `radius` of the point under the ball without
/// passing through the ball: where the caustic falls, seen directly.
fn caustic_pixels(scene: &relume::scene::Scene, radius: f32) -> Vec<usize> {
    let camera = &scene.camera;
    let (centre, ball) = (glam::Vec3::new(0.0, 0.9, 0.0), 0.3);
    let mut pixels = Vec::new();
    for y in 0..camera.height {
        for x in 0..camera.width {
            let ray = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
            let t = -ray.origin.y / ray.dir.y;
            if t <= 0.0 {
                continue;
            }
            let floor = ray.origin + ray.dir * t;
            // Distance from the ball's centre to the ray's line, before the floor.
            let along = (centre - ray.origin).dot(ray.dir).clamp(0.0, t);
            let clear = (ray.origin + ray.dir * along - centre).length() > ball;
            if clear && glam::Vec2::new(floor.x, floor.z).length() < radius {
                pixels.push((y * camera.width + x) as usize);
            }
        }
    }
    pixels
}

/// The caustic region's mean (green) over independent seeds `seeds`, one render each.
fn region_batches(
    scene: &relume::scene::Scene,
    config: TechniqueConfig,
    pixels: &[usize],
    seeds: std::ops::Range<u64>,
) -> Vec<f64> {
    seeds
        .map(|seed| {
            let image = render(scene.clone(), config.clone(), seed, 1, 2).image;
            pixels.iter().map(|&i| image.pixels[i].g as f64).sum::<f64>() / pixels.len() as f64
        })
        .collect()
}

/// Whether two sets of batch means agree within the 99.9% Student-t interval of their difference.
fn agree(label: &str, a: &[f64], b: &[f64]) -> bool {
    let ((ma, sa), (mb, sb)) = (mean_and_standard_error(a), mean_and_standard_error(b));
    let bound = student_t_999(a.len().min(b.len())) * (sa * sa + sb * sb).sqrt();
    eprintln!(
        "{label}: {ma:.5} ± {sa:.1e} vs {mb:.5} ± {sb:.1e}, |difference| {:.2e}, bound {bound:.2e}",
        (ma - mb).abs()
    );
    (ma - mb).abs() <= bound
}

#[test]
fn a_glass_ball_under_a_point_light_casts_a_caustic_that_bdpt_finds_and_path_cannot() {
    // Property: the light reaching the floor through the ball travels point light → glass →
    // glass → floor → camera; its only non-specular connection is floor → camera, the t = 1
    // strategy. `bdpt` shows the caustic; `path` (whose light samples the ball blocks) shows
    // none; and `bdpt`'s mean over the caustic agrees with light tracing alone, an independent
    // estimator with every splat weighted 1.
    let scene = caustic_room();
    let pixels = caustic_pixels(&scene, 0.12);
    assert!(pixels.len() >= 10, "the caustic region should cover pixels, got {}", pixels.len());
    let seeds = 8;
    let full = BdptConfig { light_per_eye_path: true, ..bdpt(48) };
    // Disjoint seeds: bdpt and light tracing key their light subpaths alike, and the Student-t
    // interval of the difference needs independent estimates.
    let bdpt_batches = region_batches(&scene, TechniqueConfig::Bdpt(full), &pixels, 100..100 + seeds);
    let tracing = BdptConfig { light_tracing_only: true, ..bdpt(48) };
    let tracing_batches = region_batches(&scene, TechniqueConfig::Bdpt(tracing), &pixels, 200..200 + seeds);
    let path_batches = region_batches(&scene, TechniqueConfig::Path(path(48)), &pixels, 300..300 + seeds);
    let (b, p) = (mean_and_standard_error(&bdpt_batches).0, mean_and_standard_error(&path_batches).0);
    assert!(b > 3.0 * p, "bdpt's caustic {b} should stand out over path's {p}");
    assert!(agree("bdpt against light tracing", &bdpt_batches, &tracing_batches));
    // Negative control: path's region, without the caustic, fails the same agreement.
    assert!(!agree("path against light tracing", &path_batches, &tracing_batches));
}

#[test]
fn light_tracing_alone_matches_the_path_reference_on_the_cornell_box() {
    // Property: the t = 1 splat (importance 1/(A_pixel cos⁴θ), the pass's light subpath count,
    // the light's own vertex) is an unbiased estimator of the whole image by itself.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(32, 32);
    let reference = render(scene.clone(), TechniqueConfig::Path(path(512)), 3, 1, 2).image;
    let tracing = BdptConfig { light_tracing_only: true, ..bdpt(256) };
    let img = render(scene.clone(), TechniqueConfig::Bdpt(tracing.clone()), 5, 1, 2).image;
    assert_matches_reference("light tracing", &img, &reference, CORNELL_TOLERANCE);
    // Negative control: light tracing cut to two-vertex paths fails the same bound.
    let broken = BdptConfig { max_path_length: Some(2), ..tracing };
    let img = render(scene.clone(), TechniqueConfig::Bdpt(broken), 5, 1, 2).image;
    assert_rejected_by_reference("light tracing, two vertices", &img, &reference, CORNELL_TOLERANCE);
}
