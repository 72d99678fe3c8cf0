//! `particle_gi` against the furnace and the `path` reference, and its incremental link update
//! against a full rebuild.
mod common;
use common::*;
use relume::embree::Device;
use relume::engine::{thread_pool, Frame, Session};
use relume::scene::edits::Edit;
use relume::scene::{Scene, Trs};
use relume::technique::particle_gi::{ParticleGiConfig, ParticleStats};
use relume::technique::{TechniqueConfig, TechniqueStats};

/// How closely particle_gi must match `path` on the Cornell box, allowing the discretisation
/// error at 40 000 particles; the negative control must fail it.
const CORNELL_TOLERANCE: Tolerance = Tolerance { channel: 0.03, block: 0.10, floor: 0.003 };

fn stats(frame: &Frame) -> ParticleStats {
    match &frame.stats.detail {
        TechniqueStats::ParticleGi(s) => (**s).clone(),
        other => panic!("particle_gi stats expected, got {other:?}"),
    }
}

fn config(particles: u32) -> ParticleGiConfig {
    ParticleGiConfig { particles: Some(particles), gather_links: 8, ..ParticleGiConfig::default() }
}

#[test]
fn furnace_is_within_one_percent() {
    // Property: in the furnace (a point light at the centre of a ρ = 0.5 sphere) every
    // particle receives the same direct flux I·ΔA/R², scattering sums the geometric series and
    // the gather returns ρ·E_total, so L = 1/π up to the walk's truncation, which 30 bounces
    // make negligible (0.5³² ≈ 2e-10). Discretisation adds nothing here: the field is uniform.
    let expected = furnace_radiance(None);
    let mut scene = load("furnace.json");
    scene.set_resolution(16, 16);
    let c = ParticleGiConfig { bounces: Some(30), ..config(6000) };
    let frame = render(scene, TechniqueConfig::ParticleGi(c), 2, 1, 2);
    assert_finite_non_negative(&frame.image);
    let mean = frame.image.mean().g as f64;
    eprintln!("furnace: {mean:.5} (expected {expected:.5}); {:?}", stats(&frame));
    assert!((mean - expected).abs() < 0.01 * expected, "{mean} vs {expected}");
}

/// Relative RMS difference of 4×4 block means.
fn block_error(image: &relume::film::LinearImage, reference: &relume::film::LinearImage) -> f64 {
    let (a, b) = (block_means(image), block_means(reference));
    let sum: f64 = a.iter().zip(&b).map(|(x, y)| ((x - y) / y.max(1e-3)).powi(2)).sum();
    (sum / a.len() as f64).sqrt()
}

#[test]
fn the_cornell_box_approaches_the_path_reference_as_particles_grow() {
    // Property: particle_gi estimates the same image as `path`, with a discretisation error
    // that shrinks as the particle count grows: 4×4 block means within 5% RMS at 40 000
    // particles (measured 1.9%; 3.6% at 4 000), and closer than at 4 000; channel means within
    // 3% at 40 000. 32 ticks
    // average the direct light's noise, which is not what is being measured.
    let mut scene = load("cornell-box.json");
    scene.set_resolution(32, 32);
    let reference = render(scene.clone(), TechniqueConfig::Path(path(512)), 3, 1, 2).image;
    let mut errors = Vec::new();
    for particles in [4_000, 40_000] {
        let frame = render(scene.clone(), TechniqueConfig::ParticleGi(config(particles)), 5, 32, 2);
        let e = block_error(&frame.image, &reference);
        eprintln!("{particles} particles: block error {e:.4}, mean {:?}; {:?}", frame.image.mean(), stats(&frame));
        errors.push(e);
        if particles == 40_000 {
            assert_matches_reference("particle_gi 40k", &frame.image, &reference, CORNELL_TOLERANCE);
            assert!(e < 0.05, "block error {e}");
        }
    }
    assert!(errors[1] < errors[0], "more particles did not help: {errors:?}");
    // Negative control: particle light without the n_b bounces after the first fails the same
    // bounds.
    let broken = ParticleGiConfig { bounces: Some(0), ..config(40_000) };
    let frame = render(scene, TechniqueConfig::ParticleGi(broken), 5, 32, 2);
    assert_rejected_by_reference("particle_gi, no further bounces", &frame.image, &reference, CORNELL_TOLERANCE);
}

const SLAB_SCALE: [f32; 3] = [0.3, 0.05, 0.3];

/// The room seen from above, the slab hovering on the left.
fn room() -> Scene {
    slab_room([0.0, 1.0, -2.5], [0.0, 0.6, 1.0], [-0.5, 0.5, 0.5], SLAB_SCALE, [0.0, 1.7, 0.3])
}

/// [`room`] with a dynamic mirror pane standing at `PANE_X`: links that hit it end on no
/// particle, so only their hit distance says they met a moved surface.
fn room_with_pane() -> Scene {
    let mut json = slab_room_json([0.0, 1.0, -2.5], [0.0, 0.6, 1.0], [-0.5, 0.5, 0.5], SLAB_SCALE, [0.0, 1.7, 0.3]);
    json["materials"]["mirror"] = serde_json::json!({"type": "mirror", "reflectance": [0.9, 0.9, 0.9]});
    let objects = json["objects"].as_array_mut().expect("objects");
    objects.push(serde_json::json!({"name": "pane", "shape": {"type": "quad"}, "material": "mirror", "dynamic": true,
        "transform": {"translation": [PANE_X, 0.5, 0.9], "rotation": FACE_BACK, "scale": [0.3, 0.5, 1]}}));
    scene_from_json(json)
}

const PANE_X: f32 = 0.9;

fn move_pane(dx: f32) -> Edit {
    let transform = Trs { translation: [PANE_X + dx, 0.5, 0.9], rotation: FACE_BACK, scale: [0.3, 0.5, 1.0] };
    Edit::Object { name: "pane".into(), transform }
}

/// The slab at `x`, its width and depth scaled by `k`.
fn scale_slab(x: f32, k: f32) -> Edit {
    let scale = [SLAB_SCALE[0] * k, SLAB_SCALE[1], SLAB_SCALE[2] * k];
    let transform = Trs { translation: [x, 0.5, 0.5], rotation: [0.0, 0.0, 0.0, 1.0], scale };
    Edit::Object { name: "slab".into(), transform }
}

#[test]
fn the_incremental_link_update_equals_a_full_rebuild() {
    // Property: moving the slab and a mirror pane, and then scaling the slab, and updating
    // links incrementally gives, tick by tick, the image a full rebuild of every link gives
    // with the same seed, bit for bit, while tracing a fraction of the links: a change of scale
    // within the layout's hysteresis rescales the slab's particles in place (same indices, the
    // areas a rebuild computes), re-tessellates the slab alone and retraces only links that may
    // touch it. Links that ended on the pane must be traced again in full, and links that may
    // newly meet either object only up to their old hit.
    let device = Device::new(2).unwrap();
    let pool = thread_pool(2).unwrap();
    pool.install(|| {
        let make = |incremental| {
            let c = ParticleGiConfig { incremental, ..config(8_000) };
            Session::new(room_with_pane(), &TechniqueConfig::ParticleGi(c), 7, &device).expect("session")
        };
        let (mut inc, mut full) = (make(true), make(false));
        let first = stats(&inc.tick().unwrap());
        full.tick().unwrap();
        for (step, (x, k)) in
            [(0.0f32, 1.0f32), (0.4, 1.0), (-0.2, 1.0), (-0.2, 1.3), (0.1, 0.8)].into_iter().enumerate()
        {
            let edits = || vec![scale_slab(x, k), move_pane(0.3 * x)];
            inc.queue_edits(edits()).unwrap();
            full.queue_edits(edits()).unwrap();
            let (a, b) = (inc.tick().unwrap(), full.tick().unwrap());
            let (sa, sb) = (stats(&a), stats(&b));
            eprintln!(
                "step {step}: incremental traced {} of {} links, full {}",
                sa.links_traced, sa.links_total, sb.links_traced
            );
            assert_eq!(sb.links_traced, sb.links_total, "the full rebuild traces every link it holds");
            let updated = sa.links_traced - sa.links_built_lazily;
            assert!(updated > 0 && updated < first.links_total / 2, "{sa:?}");
            assert_eq!(sa.objects_rescaled, u64::from(step >= 3), "{sa:?}");
            assert_finite_non_negative(&a.image);
            assert!(a.image.mean().g > 0.0);
            assert!(
                a.image == b.image,
                "step {step}: the images differ (means {:?} vs {:?})",
                a.image.mean(),
                b.image.mean()
            );
        }
    });
}

/// Runs `f` on two sessions of the room (6 000 particles, seed 3) after their first tick, with
/// the first session's frame.
fn room_twins(f: impl FnOnce(Session, Session, Frame) + Send) {
    let device = Device::new(2).unwrap();
    let pool = thread_pool(2).unwrap();
    pool.install(|| {
        let c = TechniqueConfig::ParticleGi(config(6_000));
        let mut s = Session::new(room(), &c, 3, &device).expect("session");
        let mut twin = Session::new(room(), &c, 3, &device).expect("session");
        let first = s.tick().unwrap();
        twin.tick().unwrap();
        f(s, twin, first)
    });
}

#[test]
fn a_moving_light_does_no_geometry_work() {
    // Property: a light that moves re-runs the lighting stage only: no link is retraced or
    // tested (gathering links are built for first-gathered particles exactly as in the twin),
    // and estimation lists are built exactly as in a twin session whose light moves by
    // only 0.1 mm (lists follow the camera samples, which jitter from tick to tick; a change
    // restarts the accumulation, so the twin needs a real one too), while the image changes:
    // the twin's mean is the unmoved light's to about 1e-4, so a 1% difference is the move.
    room_twins(|mut s, mut twin, _| {
        let lamp = |translation| {
            let transform = Trs { translation, rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3] };
            vec![Edit::Light { name: "lamp".into(), transform: Some(transform), emitter: None }]
        };
        s.queue_edits(lamp([0.6, 1.5, 0.8])).unwrap();
        twin.queue_edits(lamp([0.0, 1.7, 0.3001])).unwrap();
        let after = s.tick().unwrap();
        let twin_frame = twin.tick().unwrap();
        let still = stats(&twin_frame);
        let st = stats(&after);
        eprintln!("relight: {st:?}");
        assert_eq!((st.links_traced - st.links_built_lazily, st.link_box_tests), (0, 0), "{st:?}");
        assert_eq!(st.links_built_lazily, still.links_built_lazily, "{st:?}");
        assert_eq!(st.lists_built, still.lists_built, "the light move built lists: {st:?}");
        assert!(st.emission_rays > 0, "the lighting stage did not run: {st:?}");
        let (a, b) = (after.image.mean().luminance(), twin_frame.image.mean().luminance());
        assert!((a - b).abs() > 0.01 * b, "the light move did not change the frame: {a} vs {b}");
    });
}

#[test]
fn adaptive_supersampling_resamples_only_contrasted_pixels() {
    // Properties: pixels that see another object than a neighbour, or whose noise-free
    // radiance differs from it by more than the contrast, get `supersample` extra camera
    // samples each (and only they): none in the furnace (one object, uniform light), some on
    // the Cornell box's edges, whose image still matches the `path` reference.
    let c = ParticleGiConfig { supersample: 4, supersample_contrast: 0.3, bounces: Some(30), ..config(6000) };
    let mut furnace = load("furnace.json");
    furnace.set_resolution(16, 16);
    let uniform = stats(&render(furnace, TechniqueConfig::ParticleGi(c), 2, 1, 2));
    assert_eq!((uniform.supersampled_pixels, uniform.camera_rays), (0, 16 * 16), "{uniform:?}");
    let mut scene = load("cornell-box.json");
    scene.set_resolution(32, 32);
    let reference = render(scene.clone(), TechniqueConfig::Path(path(512)), 3, 1, 2).image;
    let c = ParticleGiConfig { supersample: 4, supersample_contrast: 0.3, ..config(20_000) };
    let frame = render(scene, TechniqueConfig::ParticleGi(c), 5, 16, 2);
    let st = stats(&frame);
    eprintln!("supersampling: {} pixels, {} camera rays", st.supersampled_pixels, st.camera_rays);
    assert!(st.supersampled_pixels > 0 && st.supersampled_pixels < 32 * 32, "{st:?}");
    assert_eq!(st.camera_rays, 32 * 32 + 4 * st.supersampled_pixels);
    assert_matches_reference("particle_gi supersampled", &frame.image, &reference, CORNELL_TOLERANCE);
}

/// Largest per-channel difference between `a` and `k·b`, relative to `b`'s brightest channel.
fn scaled_difference(a: &relume::film::LinearImage, b: &relume::film::LinearImage, k: f32) -> f32 {
    let peak = b.pixels.iter().map(|p| p.max_component()).fold(0.0f32, f32::max).max(f32::MIN_POSITIVE);
    let worst = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(x, y)| (x.r - k * y.r).abs().max((x.g - k * y.g).abs()).max((x.b - k * y.b).abs()))
        .fold(0.0f32, f32::max);
    worst / (k * peak)
}

#[test]
fn a_dimmed_light_scales_the_frame_without_rays_or_walks() {
    // Property: every term of the frame is linear in the lamp's intensity, so dimming it by k
    // is applied as a scale of its share of the field and of the cached estimates: no
    // emission rays, no scattering walks, no links but the gathering links of particles the
    // tick's camera samples gather for the first time. The frame equals, to float rounding
    // (1e-4 of the peak), the frame of a twin that recomputes its lighting stage for the same
    // lamp (it reaches the same state by a move, which re-emits), and k times an undimmed
    // twin's. All three render tick 1 with the same camera jitter; a point lamp has no light
    // samples to differ. Negative control: the undimmed frame times 1.01·k fails.
    let device = Device::new(2).unwrap();
    let pool = thread_pool(2).unwrap();
    let lamp_at = [0.0, 1.7, 0.3];
    let lamp = |translation: [f32; 3], intensity: f32| {
        let transform = Trs { translation, rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3] };
        let emitter = relume::scene::EmitterDesc::Point { intensity: relume::core::Rgb::splat(intensity) };
        vec![Edit::Light { name: "lamp".into(), transform: Some(transform), emitter: Some(emitter) }]
    };
    pool.install(|| {
        let c = TechniqueConfig::ParticleGi(config(6_000));
        let session = || Session::new(room(), &c, 3, &device).expect("session");
        let (mut dimmed, mut recomputed, mut undimmed) = (session(), session(), session());
        let k = 0.4;
        dimmed.tick().unwrap();
        for s in [&mut recomputed, &mut undimmed] {
            s.queue_edits(lamp([0.5, 1.6, 0.6], 4.0)).unwrap();
            s.tick().unwrap();
        }
        dimmed.queue_edits(lamp(lamp_at, 4.0 * k)).unwrap();
        recomputed.queue_edits(lamp(lamp_at, 4.0 * k)).unwrap();
        undimmed.queue_edits(lamp(lamp_at, 4.0)).unwrap();
        let (a, b, u) = (dimmed.tick().unwrap(), recomputed.tick().unwrap(), undimmed.tick().unwrap());
        let (sa, sb) = (stats(&a), stats(&b));
        eprintln!("dimmed: {sa:?}\nrecomputed: {sb:?}");
        let updated = sa.links_traced - sa.links_built_lazily;
        assert_eq!((sa.emission_rays, sa.scatter_deposits, updated), (0, 0, 0), "{sa:?}");
        assert_eq!(sa.lights_rescaled, 1);
        assert!(sb.emission_rays > 0 && sb.scatter_deposits > 0, "the twin did not recompute: {sb:?}");
        assert!(u.image.mean().g > 0.0);
        let (to_twin, to_scaled) = (scaled_difference(&a.image, &b.image, 1.0), scaled_difference(&a.image, &u.image, k));
        let control = scaled_difference(&a.image, &u.image, 1.01 * k);
        eprintln!("relative difference: to the recomputed twin {to_twin:.2e}, to k × undimmed {to_scaled:.2e}, control {control:.2e}");
        assert!(to_twin < 1e-4 && to_scaled < 1e-4, "{to_twin} {to_scaled}");
        assert!(control >= 1e-4, "the negative control passed: {control}");
    });
}

#[test]
fn no_light_crosses_a_contact() {
    // Property: a closed box standing on a lit floor is dark inside: no light reaches its
    // inner faces, and estimation lists take particles of the radiance particle's own object
    // only, so the floor's lit particles, within R of the box's bottom and facing the same way
    // as its inner side, add nothing. A camera inside sees exactly 0. (The unit test
    // `radiance::tests::the_floor_lies_within_the_lists_reach_of_the_box_bottom` is the
    // negative control: without the object rule those floor particles would be admitted.)
    let scene = scene_from_json(serde_json::json!({
        "camera": {"position": [0.05, 0.3, -0.1], "look_at": [0.1, 0.0, 0.15], "vfov_deg": 120, "resolution": [24, 24]},
        "materials": {"white": {"type": "diffuse", "reflectance": [0.8, 0.8, 0.8]}},
        "objects": [
            {"name": "floor", "shape": {"type": "quad"}, "material": "white",
             "transform": {"rotation": FACE_UP, "scale": [2, 2, 1]}},
            {"name": "crate", "shape": {"type": "box"}, "material": "white",
             "transform": {"translation": [0, 0.302, 0], "scale": [0.3, 0.3, 0.3]}}
        ],
        "lights": [{"name": "lamp", "emitter": {"type": "point", "intensity": [6, 6, 6]},
                    "transform": {"translation": [1.0, 1.5, -0.8]}}]
    }));
    let frame = render(scene, TechniqueConfig::ParticleGi(config(6_000)), 3, 1, 2);
    let st = stats(&frame);
    eprintln!(
        "inside the crate: peak {:?}; {st:?}",
        frame.image.pixels.iter().map(|p| p.max_component()).fold(0.0f32, f32::max)
    );
    assert!(st.radiance_particles_estimated > 0 && st.particles_lit > 0, "{st:?}");
    assert!(frame.image.pixels.iter().all(|p| p.is_black()), "light leaked into the crate");
}

#[test]
fn a_still_scene_does_no_lighting_work_and_refines() {
    // Properties: after the first tick of a still scene, no tick emits, scatters or retraces
    // a link (the field and the links are kept; only gathering links of particles gathered for
    // the first time are built), fewer radiance particles need estimating as the cache warms,
    // and the image refines toward the `path` reference: its jittered camera samples
    // accumulate, so the relMSE after 16 still ticks is below the first tick's.
    let device = Device::new(2).unwrap();
    let pool = thread_pool(2).unwrap();
    let mut scene = load("cornell-box.json");
    scene.set_resolution(24, 24);
    let reference = render(scene.clone(), TechniqueConfig::Path(path(512)), 3, 1, 2).image;
    pool.install(|| {
        let c = TechniqueConfig::ParticleGi(config(6_000));
        let mut s = Session::new(scene, &c, 5, &device).expect("session");
        let first = s.tick().unwrap();
        let (mut estimated, mut last) = (Vec::new(), first.clone());
        for _ in 1..16 {
            last = s.tick().unwrap();
            let st = stats(&last);
            let updated = st.links_traced - st.links_built_lazily;
            assert_eq!((st.emission_rays, st.scatter_deposits, updated), (0, 0, 0), "{st:?}");
            estimated.push(st.radiance_particles_estimated);
        }
        let (e1, e16) = (rel_mse(&first.image, &reference), rel_mse(&last.image, &reference));
        eprintln!("estimated per still tick: {estimated:?}; relMSE tick 1 {e1:.4}, tick 16 {e16:.4}");
        assert!(estimated[estimated.len() - 1] < estimated[0], "{estimated:?}");
        assert!(e16 < e1, "the still image did not refine: {e1} -> {e16}");
    });
}

/// Half the side of the pebble: a white cube whose area, 24·h², is 1% of the room's 58.4 m².
const PEBBLE: f32 = 0.156;

/// The room with the slab shrunk to the pebble, resting on the floor, and the lamp behind it,
/// so the pebble's face towards the camera (−Z) gets no direct light: only indirect.
fn pebble_room(reflectance: f32) -> Scene {
    let mut scene = slab_room([0.0, 1.0, -2.5], [0.5, 0.3, 0.0], [0.5, PEBBLE, 0.0], [PEBBLE; 3], [0.0, 1.7, 1.5]);
    scene.set_resolution(64, 64);
    let pebble = scene.objects.iter().position(|o| o.name == "slab").expect("the slab");
    scene.materials.push(relume::scene::Material::Diffuse { reflectance: relume::core::Rgb::splat(reflectance) });
    scene.objects[pebble].material = (scene.materials.len() - 1) as _;
    scene
}

/// Pixels whose centre ray meets the pebble's −Z face, away from its edges.
fn pebble_face_pixels(scene: &Scene) -> Vec<usize> {
    let camera = &scene.camera;
    let inner = 0.8 * PEBBLE;
    let mut pixels = Vec::new();
    for y in 0..camera.height {
        for x in 0..camera.width {
            let ray = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
            let t = (-PEBBLE - ray.origin.z) / ray.dir.z;
            let p = ray.origin + ray.dir * t;
            if t > 0.0 && (p.x - 0.5).abs() < inner && (p.y - PEBBLE).abs() < inner {
                pixels.push((y * camera.width + x) as usize);
            }
        }
    }
    pixels
}

fn region_luminance(image: &relume::film::LinearImage, pixels: &[usize]) -> f64 {
    pixels.iter().map(|&i| image.pixels[i].luminance() as f64).sum::<f64>() / pixels.len() as f64
}

#[test]
fn a_small_object_gets_particles_and_its_indirect_light() {
    // Property (PG-1): a cube with 1% of the scene's area has particles on every side, so its
    // face lit only indirectly (the lamp is behind it) shows the indirect light `path`
    // computes, up to the discretisation of its few particles, and converges to it as they
    // grow. Rounding global shares used to give such an object none, and the face went black
    // (−100%). At the default count here (2 000, so about 3 particles per side) the face is
    // within 25% (measured −17%); at 32 000 (about 53 per side) within 5% (measured −2%).
    // Negative control: the same pebble at half the reflectance fails both bounds.
    let scene = pebble_room(0.8);
    let pixels = pebble_face_pixels(&scene);
    assert!(pixels.len() >= 30, "the face should cover pixels: {}", pixels.len());
    let reference = region_luminance(&render(scene.clone(), TechniqueConfig::Path(path(1024)), 3, 1, 2).image, &pixels);
    assert!(reference > 0.0, "the face should be lit indirectly");
    let gap = |particles: Option<u32>, reflectance: f32| {
        let c = TechniqueConfig::ParticleGi(ParticleGiConfig { particles, ..ParticleGiConfig::default() });
        let frame = render(pebble_room(reflectance), c, 5, 16, 2);
        let r = region_luminance(&frame.image, &pixels) / reference - 1.0;
        eprintln!("pebble ρ {reflectance}, {} particles: face {r:+.4} against path", stats(&frame).area_particles);
        r
    };
    let mut errors = Vec::new();
    for (particles, tolerance) in [(None, 0.25), (Some(32_000), 0.05)] {
        let error = gap(particles, 0.8);
        assert!(error.abs() < tolerance, "{particles:?} particles: the pebble's face is {error:+.3} off path's");
        assert!(gap(particles, 0.4).abs() >= tolerance, "{particles:?} particles: the control passed");
        errors.push(error.abs());
    }
    assert!(errors[1] < errors[0], "more particles did not help: {errors:?}");
}

#[test]
fn a_material_edit_regathers_the_view_in_place() {
    // Property: after a material edit, the estimates cached for the view are gathered again in
    // place from the new field, and the frame equals (to 1e-4 of each channel's mean) that of
    // a twin whose camera also moved by 10 µm, which ages every estimate, so its render
    // estimates the whole view afresh. A stale estimate would keep the red wall's old colour
    // bleeding; negative control: the frame before the edit (the red wall turned green) fails
    // the same tolerance.
    room_twins(|mut s, mut twin, before| {
        let green = relume::scene::Material::Diffuse { reflectance: relume::core::Rgb::new(0.2, 0.7, 0.1) };
        let edit = Edit::Material { name: "red".into(), material: green };
        let nudge = Edit::Camera { position: Some([0.0, 1.0, -2.50001]), look_at: None, up: None, vfov_deg: None };
        s.queue_edits(vec![edit.clone()]).unwrap();
        twin.queue_edits(vec![edit, nudge]).unwrap();
        let (after, fresh) = (s.tick().unwrap(), twin.tick().unwrap());
        let (st, ft) = (stats(&after), stats(&fresh));
        eprintln!("material edit: {st:?}\ntwin: {ft:?}");
        assert!(st.scatter_deposits > 0 && st.emission_rays == 0, "no re-scatter from the kept flux: {st:?}");
        let m = |f: &Frame| f.image.mean();
        let off = |a: relume::core::Rgb, b: relume::core::Rgb| {
            [(a.r - b.r) / b.r, (a.g - b.g) / b.g, (a.b - b.b) / b.b].into_iter().fold(0.0f32, |x, y| x.max(y.abs()))
        };
        let (edited, control) = (off(m(&after), m(&fresh)), off(m(&before), m(&fresh)));
        eprintln!("largest channel difference to the twin: edited {edited:.2e}, before the edit {control:.2e}");
        assert!(edited < 1e-4, "the edited frame is {edited} off the twin");
        assert!(control > 1e-4, "the control passes: {control}");
    });
}

#[test]
fn sides_that_can_never_be_lit_get_no_scattering_links() {
    // Property: scattering links are traced only for the particles the lighting walks can
    // reach from the directly lit ones. In the room, lit from inside and open towards the
    // camera, the walls' outer sides and the slab's inside are never reached: about half the
    // particles, whose links building every side (the control: every particle, 1.0) traced.
    let frame = render(room(), TechniqueConfig::ParticleGi(config(6_000)), 3, 1, 2);
    let st = stats(&frame);
    let all = st.area_particles * u64::from(ParticleGiConfig::default().scatter_links.pow(2));
    let share = st.scattering_links as f64 / all as f64;
    eprintln!("scattering links: {} of {all} ({share:.3})", st.scattering_links);
    assert!((0.35..0.65).contains(&share), "{share}");
}
