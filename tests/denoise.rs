//! The denoise stage (OIDN) against the reference path tracer, and its auxiliary images
//! against the scene's own materials and geometry.
#![cfg(feature = "denoise")]
mod common;

use common::{assert_within_one_percent, load, rel_mse};
use relume::embree::Device;
use relume::engine::{thread_pool, Frame, Session};
use relume::film::{DenoiseQuality, DenoiseSettings, LinearImage};
use relume::technique::TechniqueConfig;

const SIDE: u32 = 256;

fn cornell() -> relume::scene::Scene {
    let mut scene = load("cornell-box.json");
    scene.set_resolution(SIDE, SIDE);
    scene
}

/// `ticks` ticks of 1-spp `path` on the Cornell box, denoised every tick when `denoise` is set.
fn run(seed: u64, ticks: u32, denoise: Option<DenoiseSettings>) -> (Frame, Session) {
    let device = Device::new(2).expect("device");
    let pool = thread_pool(2).expect("pool");
    pool.install(|| {
        let config = TechniqueConfig::from_spec("path:spp=1").expect("spec");
        let mut session = Session::new(cornell(), &config, seed, &device).expect("session");
        if let Some(settings) = denoise {
            session.set_denoise(Some(settings)).expect("OIDN starts (scripts/setup.sh installs it)");
        }
        let mut last = None;
        for _ in 0..ticks {
            last = Some(session.tick().expect("tick"));
        }
        (last.expect("a tick"), session)
    })
}

fn reference() -> LinearImage {
    let device = Device::new(2).expect("device");
    let config = TechniqueConfig::from_spec("path:spp=256").expect("spec");
    std::sync::Arc::unwrap_or_clone(common::render_on(&device, cornell(), config, 4242, 1, 2).image)
}

fn luminance_mean(img: &LinearImage) -> f64 {
    img.pixels.iter().map(|p| p.luminance() as f64).sum::<f64>() / img.pixels.len() as f64
}

/// A 3×3 box blur: a "denoiser" that averages noise away without seeing edges (the negative
/// control of the relMSE bound).
fn box_blur(img: &LinearImage) -> LinearImage {
    let mut out = img.clone();
    let (w, h) = (img.width as i64, img.height as i64);
    for y in 0..h {
        for x in 0..w {
            let mut s = relume::core::Rgb::BLACK;
            let mut n = 0.0;
            for (dx, dy) in (-1..=1).flat_map(|dx| (-1..=1).map(move |dy| (dx, dy))) {
                let (u, v) = (x + dx, y + dy);
                if (0..w).contains(&u) && (0..h).contains(&v) {
                    s += img.get(u as u32, v as u32);
                    n += 1.0;
                }
            }
            out.pixels[(y * w + x) as usize] = s * (1.0 / n);
        }
    }
    out
}

/// One denoised 1-spp frame is at least 20× closer to the reference (relMSE) than the raw
/// frame it came from, and its mean is the reference's within 1% (Student-t over 16 seeds).
/// Negative controls: a 3×3 box blur does not reach the relMSE bound, and the denoised frame
/// brightened by 3% fails the mean bound.
#[test]
fn denoised_one_spp_cornell_box_is_twenty_times_closer_and_keeps_the_mean() {
    let reference = reference();
    let expected = luminance_mean(&reference);
    let (mut ratios, mut blur_ratios, mut means, mut brightened) = (vec![], vec![], vec![], vec![]);
    for seed in 1..=16 {
        let (frame, _) = run(seed, 1, Some(DenoiseSettings::default()));
        let denoised = frame.denoised.as_ref().expect("a denoised image");
        let raw = rel_mse(&frame.image, &reference);
        ratios.push(rel_mse(denoised, &reference) / raw);
        blur_ratios.push(rel_mse(&box_blur(&frame.image), &reference) / raw);
        means.push(luminance_mean(denoised));
        brightened.push(luminance_mean(denoised) * 1.03);
        eprintln!("seed {seed}: raw relMSE {raw:.4}, denoised {:.5}", rel_mse(denoised, &reference));
    }
    let mean_ratio = ratios.iter().sum::<f64>() / ratios.len() as f64;
    let blur_ratio = blur_ratios.iter().sum::<f64>() / blur_ratios.len() as f64;
    eprintln!("denoised/raw relMSE {mean_ratio:.4} (3x3 blur: {blur_ratio:.4})");
    assert!(mean_ratio <= 1.0 / 20.0, "denoised relMSE is {mean_ratio} of the raw frame's, above 1/20");
    assert!(blur_ratio > 1.0 / 20.0, "negative control: a 3x3 blur reaches 1/20 ({blur_ratio}), so the bound is loose");
    assert_within_one_percent("denoised mean luminance", &means, expected);
    let control = std::panic::catch_unwind(|| assert_within_one_percent("brightened 3%", &brightened, expected));
    assert!(control.is_err(), "negative control: a frame 3% too bright passes the mean bound");
}

/// The auxiliary images hold the first hit's reflectance and normal: the red wall's albedo is
/// its material's (0.65, 0.05, 0.05) and the floor's normal is +Y. Control: the green wall's
/// albedo is not the red one.
#[test]
fn auxiliary_images_hold_the_first_hits_albedo_and_normal() {
    let settings = DenoiseSettings { quality: DenoiseQuality::Fast, aux: true };
    let (_, session) = run(7, 3, Some(settings));
    let aux = session.denoise().expect("denoising").aux();
    assert_eq!(aux.passes, 3, "one auxiliary pass per tick until converged");
    let red = aux.pixel(12, SIDE / 2);
    let green = aux.pixel(SIDE - 12, SIDE / 2);
    let floor = aux.pixel(SIDE / 2, SIDE - 8);
    eprintln!("red wall {red:?}, green wall {green:?}, floor {floor:?}");
    for (got, want) in red.albedo.to_array().iter().zip([0.65, 0.05, 0.05]) {
        assert!((got - want).abs() < 1e-4, "red wall albedo {:?}", red.albedo);
    }
    assert!((green.albedo.r - 0.65).abs() > 0.1, "control: the green wall reads as red");
    assert!((floor.normal - glam::Vec3::Y).length() < 1e-4, "floor normal {:?}", floor.normal);
}

/// The raw image of a denoising session is the image of a twin session without denoising
/// (the stage only adds an image), and the denoised one differs from it.
#[test]
fn raw_image_equals_a_twin_without_denoising() {
    let (with, _) = run(3, 2, Some(DenoiseSettings { quality: DenoiseQuality::Fast, aux: false }));
    let (without, _) = run(3, 2, None);
    assert_eq!(with.image, without.image, "denoising changed the raw image");
    assert!(without.denoised.is_none());
    assert_ne!(with.denoised.as_deref(), Some(&*with.image), "the denoised image is the raw one");
    assert!(with.stats.times.denoise_ms > 0.0 && without.stats.times.denoise_ms == 0.0);
}

/// Once the auxiliary images have their samples, a still scene's denoise stage traces nothing;
/// a camera edit restarts them (cost follows the change).
#[test]
fn auxiliary_pass_stops_when_converged_and_restarts_on_camera_edits() {
    let settings = DenoiseSettings { quality: DenoiseQuality::Fast, aux: true };
    let device = Device::new(2).expect("device");
    let pool = thread_pool(2).expect("pool");
    pool.install(|| {
        let config = TechniqueConfig::from_spec("path:spp=1").expect("spec");
        let mut scene = cornell();
        scene.set_resolution(32, 32);
        let mut session = Session::new(scene, &config, 1, &device).expect("session");
        session.set_denoise(Some(settings)).expect("OIDN");
        let target = relume::film::AuxFilm::TARGET_PASSES;
        let rays: Vec<u64> = (0..target + 2).map(|_| session.tick().expect("tick").stats.aux_rays).collect();
        assert!(rays[..target as usize].iter().all(|&r| r >= 32 * 32), "aux rays {rays:?}");
        assert_eq!(&rays[target as usize..], &[0, 0], "a converged still scene traces aux rays");
        session.queue_edits(vec![common::camera_dolly()]).expect("edit");
        assert!(session.tick().expect("tick").stats.aux_rays >= 32 * 32, "a camera edit left the aux images stale");
    });
}

/// After the auxiliary images converge the stage stops sending them, and OIDN keeps the last
/// ones: the frame must equal a fresh denoise of the same raw image with freshly traced
/// auxiliary images (same seed). Control: the same image denoised without them differs.
#[test]
fn kept_auxiliary_images_denoise_like_freshly_traced_ones() {
    let settings = DenoiseSettings { quality: DenoiseQuality::Fast, aux: true };
    let (frame, mut session) = run(11, relume::film::AuxFilm::TARGET_PASSES + 3, Some(settings));
    let pool = thread_pool(2).expect("pool");
    let mut denoise_once = |settings: DenoiseSettings| {
        let (s, raw) = (&mut session, &frame.image);
        pool.install(move || s.denoise_once(settings, raw)).expect("denoise")
    };
    let fresh = denoise_once(settings);
    let colour_only = denoise_once(DenoiseSettings { aux: false, ..settings });
    let denoised = frame.denoised.as_ref().expect("denoised");
    assert_eq!(frame.stats.aux_rays, 0, "the auxiliary images were still being traced");
    let worst = denoised
        .pixels
        .iter()
        .zip(&fresh.pixels)
        .flat_map(|(a, b)| (*a - *b).to_array().map(f32::abs))
        .fold(0.0, f32::max);
    assert!(worst < 1e-5, "kept auxiliary images differ from fresh ones by {worst}");
    assert_ne!(&**denoised, &colour_only, "control: the auxiliary images change nothing");
}

/// A tick that changes nothing in the film is not denoised again: an `instant_cache` view at
/// rest (refinement done, no pass added) returns the last output, bit for bit, with
/// `denoise_reused`. Every tick before it added a pass and was denoised; so is the tick after
/// a change. Control: `path` adds a pass every tick and is denoised every tick.
#[test]
fn an_unchanged_film_is_not_denoised_again() {
    let settings = DenoiseSettings { quality: DenoiseQuality::Fast, aux: false };
    let device = Device::new(2).expect("device");
    let pool = thread_pool(2).expect("pool");
    pool.install(|| {
        let run = |spec: &str| -> Vec<Frame> {
            let mut scene = cornell();
            scene.set_resolution(32, 32);
            let config = TechniqueConfig::from_spec(spec).expect("spec");
            let mut session = Session::new(scene, &config, 1, &device).expect("session");
            session.set_denoise(Some(settings)).expect("OIDN");
            let mut frames: Vec<Frame> = (0..5).map(|_| session.tick().expect("tick")).collect();
            session.queue_edits(vec![common::camera_dolly()]).expect("edit");
            frames.push(session.tick().expect("tick"));
            frames
        };
        let resting = run("instant_cache:temporal:refine_ticks=2");
        let reused: Vec<bool> = resting.iter().map(|f| f.stats.denoise_reused).collect();
        assert_eq!(reused, [false, false, false, true, true, false], "ticks 3 and 4 rest");
        let spp: Vec<u32> = resting.iter().map(|f| f.spp).collect();
        assert_eq!(spp, [1, 2, 3, 3, 3, 1], "the resting ticks added a pass");
        // The resting frames name the tick that made their images, so clients can tell them apart.
        let made: Vec<(u64, u64)> = resting.iter().map(|f| (f.image_tick, f.denoised_tick)).collect();
        assert_eq!(made, [(0, 0), (1, 1), (2, 2), (2, 2), (2, 2), (5, 5)], "the ticks that made each frame's images");
        for f in &resting[3..5] {
            assert_eq!(f.denoised.as_ref().map(|d| &d.pixels), resting[2].denoised.as_ref().map(|d| &d.pixels));
        }
        let path = run("path:spp=1");
        assert!(path.iter().all(|f| !f.stats.denoise_reused), "path's film changes every tick");
    });
}
