//! Helpers shared by the integration tests: load bundled scenes and run sessions on real Embree.
#![allow(dead_code)]
pub mod archive;
pub mod gltf_doc;
pub mod process;
pub mod server;
pub mod ws;
use relume::embree::{Device, Isa};
use relume::engine::{thread_pool, Frame, Session};
use relume::film::LinearImage;
use relume::scene::Scene;
use relume::technique::path::PathConfig;
use relume::technique::TechniqueConfig;
use std::path::{Path, PathBuf};

pub fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

/// An empty folder of its own under the system temp dir for `tag` (emptied if it was there).
pub fn fresh_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("relume-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// A copy of the bundled scenes for a server that tests upload to (never the repository's).
pub fn scenes_copy(tag: &str) -> PathBuf {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).expect("scenes copy");
        for entry in std::fs::read_dir(from).expect("scenes").flatten() {
            let target = to.join(entry.file_name());
            match entry.file_type().expect("file type").is_dir() {
                true => copy(&entry.path(), &target),
                false => drop(std::fs::copy(entry.path(), target).expect("copied")),
            }
        }
    }
    let to = fresh_dir(&format!("scenes-{tag}"));
    copy(&scenes_dir(), &to);
    to
}

pub fn load(name: &str) -> Scene {
    let root = scenes_dir();
    Scene::load(&root.join(name), &root).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Runs `ticks` ticks of a fresh session on a pool of `threads` and returns the last frame.
pub fn render(scene: Scene, config: TechniqueConfig, seed: u64, ticks: u32, threads: usize) -> Frame {
    let device = Device::new(threads).expect("device");
    render_on(&device, scene, config, seed, ticks, threads)
}

/// As [`render`], on the given Embree device.
pub fn render_on(
    device: &Device,
    scene: Scene,
    config: TechniqueConfig,
    seed: u64,
    ticks: u32,
    threads: usize,
) -> Frame {
    let pool = thread_pool(threads).expect("thread pool");
    pool.install(|| {
        let mut session = Session::new(scene, &config, seed, device).expect("session");
        let mut last = None;
        for _ in 0..ticks {
            last = Some(session.tick().expect("tick"));
        }
        last.expect("at least one tick")
    })
}

/// Rotation (quaternion [x, y, z, w]) turning a quad's or rect light's +Z normal to +Y.
pub const FACE_UP: [f32; 4] = [-std::f32::consts::FRAC_1_SQRT_2, 0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2];
/// Rotation turning +Z to −Y.
pub const FACE_DOWN: [f32; 4] = [std::f32::consts::FRAC_1_SQRT_2, 0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2];

/// A scene from inline JSON (mesh paths resolve against the bundled scenes folder).
pub fn scene_from_json(v: serde_json::Value) -> Scene {
    let desc: relume::scene::SceneDesc = serde_json::from_value(v).expect("scene JSON");
    Scene::from_desc(desc, &scenes_dir(), &scenes_dir()).expect("valid scene")
}

/// The stats of a `photon_reuse` frame.
pub fn photon_stats(frame: &Frame) -> relume::technique::photon_reuse::PhotonStats {
    match &frame.stats.detail {
        relume::technique::TechniqueStats::PhotonReuse(s) => (**s).clone(),
        other => panic!("photon_reuse stats expected, got {other:?}"),
    }
}

/// Furnace (scenes/README.md): L = ρ I / (π R² (1 − ρ)) = 1/π inside the sphere. With paths cut
/// after k scattering vertices the sum stops at ρ^k: L_k = (I/πR²) Σ_{j=1..k} ρ^j.
pub fn furnace_radiance(max_vertices: Option<u32>) -> f64 {
    let rho = 0.5f64;
    let scale = 1.0 / std::f64::consts::PI;
    match max_vertices {
        None => scale * rho / (1.0 - rho),
        Some(k) => scale * (1..=k).map(|j| rho.powi(j as i32)).sum::<f64>(),
    }
}

/// Independent batch estimates of the furnace's mean radiance (green channel; all are equal),
/// one per seed, at `side`² pixels (the scene's own resolution if `None`).
pub fn furnace_batches(config: &TechniqueConfig, batches: u64, side: Option<u32>, ticks: u32) -> Vec<f64> {
    (0..batches)
        .map(|seed| {
            let mut scene = load("furnace.json");
            if let Some(side) = side {
                scene.set_resolution(side, side);
            }
            let frame = render(scene, config.clone(), 1000 + seed, ticks, 2);
            assert_finite_non_negative(&frame.image);
            frame.image.mean().g as f64
        })
        .collect()
}

/// The two-sided 99.9% quantile of Student's t for the mean of `n` batches (n − 1 degrees of
/// freedom); it tends to the normal 3.29 only for many batches.
pub fn student_t_999(n: usize) -> f64 {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    assert!(n >= 2, "a standard error needs at least two batches");
    StudentsT::new(0.0, 1.0, (n - 1) as f64).expect("degrees of freedom").inverse_cdf(0.9995)
}

/// Asserts batch estimates match `expected` within 1%, including the 99.9% two-sided
/// confidence interval of their mean (Student's t for the batch count, not the normal 3.29).
pub fn assert_within_one_percent(label: &str, batches: &[f64], expected: f64) {
    let (mean, se) = mean_and_standard_error(batches);
    let t = student_t_999(batches.len());
    eprintln!("{label}: {mean:.6} ± {se:.2e} (t = {t:.2}; expected {expected:.6})");
    assert!((mean - expected).abs() + t * se < 0.01 * expected, "{label}: {mean} (se {se}, t {t}) vs {expected}");
}

/// Every technique (and every instant_cache mode), small enough to run many times: the test
/// matrix of the hard cases and the ISA tests, from each registry entry's `test_specs`.
pub fn small_techniques() -> Vec<TechniqueConfig> {
    let all: Vec<TechniqueConfig> = relume::technique::registry::REGISTRY
        .iter()
        .flat_map(|d| d.test_specs.iter())
        .map(|spec| TechniqueConfig::from_spec(spec).unwrap_or_else(|e| panic!("{spec}: {e}")))
        .collect();
    for id in relume::technique::TECHNIQUE_IDS {
        assert!(all.iter().any(|c| c.id() == id), "the registry gives '{id}' no test configuration");
    }
    all
}

/// Runs `f` with a device for each Embree kernel family this CPU has, narrowest first, and
/// prints a line for each family it skips.
pub fn for_each_isa(mut f: impl FnMut(Isa, &Device)) {
    for isa in Isa::ALL {
        if !isa.supported_by_cpu() {
            println!("skipped: Embree's {isa} kernels (this CPU does not have {isa})");
            continue;
        }
        println!("testing Embree's {isa} kernels");
        let device = Device::with_isa(2, Some(isa)).unwrap_or_else(|e| panic!("{isa}: {e}"));
        assert_eq!(device.isa(), isa);
        f(isa, &device);
    }
}

pub fn path(spp: u32) -> PathConfig {
    PathConfig { spp, ..PathConfig::default() }
}

/// An edit that moves the Cornell box's camera 100 units closer.
pub fn camera_dolly() -> relume::scene::edits::Edit {
    relume::scene::edits::Edit::Camera {
        position: Some([278.0, 273.0, -700.0]),
        look_at: None,
        up: None,
        vfov_deg: None,
    }
}

/// Mean and standard error of the mean over independent batch estimates.
pub fn mean_and_standard_error(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// relMSE (ε = 0.01) of an image against a reference.
pub fn rel_mse(img: &LinearImage, reference: &LinearImage) -> f64 {
    let mut sum = 0.0;
    for (a, b) in img.pixels.iter().zip(&reference.pixels) {
        for (x, y) in a.to_array().iter().zip(b.to_array()) {
            let d = (*x - y) as f64;
            sum += d * d / ((y as f64).powi(2) + 0.01);
        }
    }
    sum / (img.pixels.len() * 3) as f64
}

pub fn assert_finite_non_negative(img: &LinearImage) {
    for (i, p) in img.pixels.iter().enumerate() {
        assert!(p.is_finite() && p.min_component() >= 0.0, "pixel {i} = {p:?}");
    }
}

/// Mean luminance of each of 4×4 blocks, row by row (the image's sides must divide by 4).
pub fn block_means(img: &LinearImage) -> Vec<f64> {
    let (bw, bh) = (img.width / 4, img.height / 4);
    let mut out = Vec::with_capacity(16);
    for by in 0..4 {
        for bx in 0..4 {
            let mut s = 0.0f64;
            for y in by * bh..(by + 1) * bh {
                for x in bx * bw..(bx + 1) * bw {
                    s += img.get(x, y).luminance() as f64;
                }
            }
            out.push(s / (bw * bh) as f64);
        }
    }
    out
}

/// How closely an image must match a reference: every channel mean within `channel`
/// (relative), and every 4×4 block's mean luminance within `block` (relative) plus `floor`
/// (absolute, for dark blocks).
#[derive(Clone, Copy, Debug)]
pub struct Tolerance {
    pub channel: f32,
    pub block: f64,
    pub floor: f64,
}

/// Whether `image` matches `reference` within `tol`; `Err` says which comparison failed.
pub fn matches_reference(image: &LinearImage, reference: &LinearImage, tol: Tolerance) -> Result<(), String> {
    let (a, b) = (image.mean(), reference.mean());
    for (x, y) in a.to_array().iter().zip(b.to_array()) {
        if (x - y).abs() >= tol.channel * y {
            return Err(format!("channel {x} vs {y} (means {a:?} vs {b:?})"));
        }
    }
    for (i, (p, r)) in block_means(image).iter().zip(block_means(reference)).enumerate() {
        if (p - r).abs() >= tol.block * r + tol.floor {
            return Err(format!("block {i}: {p} vs {r}"));
        }
    }
    Ok(())
}

/// Asserts `image` matches `reference` within `tol` ([`matches_reference`]).
pub fn assert_matches_reference(label: &str, image: &LinearImage, reference: &LinearImage, tol: Tolerance) {
    assert_finite_non_negative(image);
    eprintln!("{label}: {:?} against the reference {:?}", image.mean(), reference.mean());
    if let Err(e) = matches_reference(image, reference, tol) {
        panic!("{label}: {e}");
    }
}

/// The negative control of [`assert_matches_reference`]: a deliberately broken variant's
/// `image` must fail the same tolerance, or it could not tell a broken technique from a
/// working one.
pub fn assert_rejected_by_reference(label: &str, image: &LinearImage, reference: &LinearImage, tol: Tolerance) {
    match matches_reference(image, reference, tol) {
        Ok(()) => {
            panic!("{label}: the broken variant passes the tolerance ({:?} vs {:?})", image.mean(), reference.mean())
        }
        Err(e) => eprintln!("{label} (negative control) fails as it must: {e}"),
    }
}

/// Turns a quad's +Z normal to −Z (a back wall facing the camera), and to +X and −X.
pub const FACE_BACK: [f32; 4] = [0.0, 1.0, 0.0, 0.0];
pub const FACE_RIGHT: [f32; 4] = [0.0, std::f32::consts::FRAC_1_SQRT_2, 0.0, std::f32::consts::FRAC_1_SQRT_2];
pub const FACE_LEFT: [f32; 4] = [0.0, -std::f32::consts::FRAC_1_SQRT_2, 0.0, std::f32::consts::FRAC_1_SQRT_2];

/// A 4 m × 4 m room 2.2 m high, open towards −Z (white floor, ceiling and side walls, a red
/// back wall at z = 2), lit by a dynamic point light "lamp" of intensity 4 W/sr at `lamp`, with
/// a dynamic white box "slab" at `slab` scaled by `slab_scale`, seen from `camera` towards
/// `look_at` at 24 × 24.
pub fn slab_room(camera: [f32; 3], look_at: [f32; 3], slab: [f32; 3], slab_scale: [f32; 3], lamp: [f32; 3]) -> Scene {
    scene_from_json(slab_room_json(camera, look_at, slab, slab_scale, lamp))
}

/// The JSON of [`slab_room`], for tests that add to it.
pub fn slab_room_json(
    camera: [f32; 3],
    look_at: [f32; 3],
    slab: [f32; 3],
    slab_scale: [f32; 3],
    lamp: [f32; 3],
) -> serde_json::Value {
    serde_json::json!({
        "camera": {"position": camera, "look_at": look_at, "vfov_deg": 40, "resolution": [24, 24]},
        "materials": {
            "white": {"type": "diffuse", "reflectance": [0.8, 0.8, 0.8]},
            "red": {"type": "diffuse", "reflectance": [0.7, 0.2, 0.1]}
        },
        "objects": [
            {"name": "floor", "shape": {"type": "quad"}, "material": "white",
             "transform": {"rotation": FACE_UP, "scale": [2, 2, 1]}},
            {"name": "wall", "shape": {"type": "quad"}, "material": "red",
             "transform": {"translation": [0, 1.1, 2], "rotation": FACE_BACK, "scale": [2, 1.1, 1]}},
            {"name": "ceiling", "shape": {"type": "quad"}, "material": "white",
             "transform": {"translation": [0, 2.2, 0], "rotation": FACE_DOWN, "scale": [2, 2, 1]}},
            {"name": "left", "shape": {"type": "quad"}, "material": "white",
             "transform": {"translation": [-2, 1.1, 0], "rotation": FACE_RIGHT, "scale": [2, 1.1, 1]}},
            {"name": "right", "shape": {"type": "quad"}, "material": "white",
             "transform": {"translation": [2, 1.1, 0], "rotation": FACE_LEFT, "scale": [2, 1.1, 1]}},
            {"name": "slab", "shape": {"type": "box"}, "material": "white", "dynamic": true,
             "transform": {"translation": slab, "scale": slab_scale}}
        ],
        "lights": [{"name": "lamp", "dynamic": true, "emitter": {"type": "point", "intensity": [4, 4, 4]},
                    "transform": {"translation": lamp}}]
    })
}

/// A frame against its twin's: the same image bit for bit, and the same stats apart from the
/// keys `ignored` names (at any depth), which may differ between the two by construction.
pub fn same_as_twin_frame(after: &Frame, twin: &Frame, ignored: impl Fn(&str) -> bool + Copy) -> Result<(), String> {
    fn strip(v: &mut serde_json::Value, ignored: impl Fn(&str) -> bool + Copy) {
        if let serde_json::Value::Object(map) = v {
            map.retain(|k, _| !ignored(k));
            map.values_mut().for_each(|v| strip(v, ignored));
        }
    }
    let comparable = |frame: &Frame| {
        let mut v = serde_json::to_value(&frame.stats).expect("stats JSON");
        strip(&mut v, ignored);
        v
    };
    if after.image != twin.image {
        return Err("the image differs from the twin's".into());
    }
    let (a, b) = (comparable(after), comparable(twin));
    if a != b {
        return Err(format!("stats differ from the twin's:\n{a}\n{b}"));
    }
    Ok(())
}
