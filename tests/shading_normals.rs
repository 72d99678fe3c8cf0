//! Smooth shading from vertex normals: how they load (OBJ `vn`, inline `normals`) and follow a
//! transform, and that every technique shades with them, against an analytic answer (direct
//! light) and against `path` (light reflected off a smooth-shaded floor, which the light-side
//! techniques carry with the adjoint shading factor).
mod common;
use common::*;
use glam::Vec3;
use relume::scene::{Scene, SurfaceId};
use relume::technique::TechniqueConfig;
use serde_json::{json, Value};

/// How far the quad's vertex normals lean from its geometric normal (+Y), towards +X.
const TILT_DEG: f32 = 40.0;
const RHO: f32 = 0.5;
const INTENSITY: f32 = 2.0;
const LAMP: [f32; 3] = [0.0, 1.0, 0.0];

/// The unit vector `tilt_deg` from +Y towards +X.
fn leaning(tilt_deg: f32) -> Vec3 {
    let t = tilt_deg.to_radians();
    Vec3::new(t.sin(), t.cos(), 0.0)
}

/// A square of side 2·`half` in the XZ plane facing +Y, as inline triangles with every vertex
/// normal `normal` (none: flat shaded).
fn floor_shape(half: f32, normal: Option<Vec3>) -> Value {
    let mut shape = json!({
        "type": "triangles",
        "positions": [[-half, 0.0, -half], [half, 0.0, -half], [half, 0.0, half], [-half, 0.0, half]],
        "indices": [[0, 2, 1], [0, 3, 2]],
    });
    if let Some(n) = normal {
        shape["normals"] = json!(vec![n.to_array(); 4]);
    }
    shape
}

/// The quad alone under a point lamp 1 m above its centre, seen from straight above by a
/// narrow camera (the view spans ±0.28 m): nothing else to reflect light, so each pixel is
/// direct light only.
fn lone_quad(normal: Option<Vec3>) -> Scene {
    scene_from_json(json!({
        "camera": {"position": [0, 4, 0], "look_at": [0, 0, 0], "up": [0, 0, -1], "vfov_deg": 8, "resolution": [16, 16]},
        "materials": {"grey": {"type": "diffuse", "reflectance": [RHO, RHO, RHO]}},
        "objects": [{"name": "quad", "shape": floor_shape(1.0, normal), "material": "grey"}],
        "lights": [{"name": "lamp", "emitter": {"type": "point", "intensity": [INTENSITY, INTENSITY, INTENSITY]},
                    "transform": {"translation": LAMP}}]
    }))
}

/// The image mean of [`lone_quad`] with shading normal `ns`, integrated over 8 × 8 points per
/// pixel: L = ρ/π · I · max(0, ns·ω)/d² at each point the camera sees.
fn analytic_mean(scene: &Scene, ns: Vec3) -> f64 {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let lamp = Vec3::from(LAMP);
    let mut sum = 0.0f64;
    let n = 8;
    for y in 0..h {
        for x in 0..w {
            for k in 0..n * n {
                let (sx, sy) = ((k % n) as f32 + 0.5, (k / n) as f32 + 0.5);
                let ray = scene.camera.ray(x as f32 + sx / n as f32, y as f32 + sy / n as f32);
                let p = ray.origin + ray.dir * (-ray.origin.y / ray.dir.y);
                let to_lamp = lamp - p;
                let cos = ns.dot(to_lamp.normalize()).max(0.0);
                sum += (RHO / std::f32::consts::PI * INTENSITY * cos / to_lamp.length_squared()) as f64;
            }
        }
    }
    sum / (w * h * n * n) as f64
}

#[test]
fn vertex_normals_load_from_obj_and_inline_and_turn_with_the_transform() {
    // Property: the shading normal is the vertex normal under the inverse transpose of the
    // object's transform (a non-uniform scale turns it), interpolated and on the geometric
    // normal's side; a mesh without normals shades flat. The negative control is the plain
    // rotation of the normal (the transform without the inverse transpose), which the scale
    // makes differ.
    let dir = std::env::temp_dir().join(format!("relume-shading-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ns = leaning(TILT_DEG);
    let vn = format!("vn {} {} {}\n", ns.x, ns.y, ns.z).repeat(4);
    let obj = format!("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\n{vn}f 1//1 3//3 2//2\nf 1//1 4//4 3//3\n");
    std::fs::write(dir.join("smooth.obj"), obj).unwrap();
    std::fs::write(dir.join("flat.obj"), "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 3 2\nf 1 4 3\n").unwrap();
    let scale = [3.0f32, 1.0, 0.5];
    let scene_with = |shape: Value| {
        let desc = json!({
            "camera": {"position": [0, 4, 1], "look_at": [0, 0, 0], "vfov_deg": 40, "resolution": [8, 8]},
            "materials": {"grey": {"type": "diffuse", "reflectance": [RHO, RHO, RHO]}},
            "objects": [{"name": "quad", "shape": shape, "material": "grey", "transform": {"scale": scale}}],
        });
        Scene::from_desc(serde_json::from_value(desc).unwrap(), &dir, &dir).expect("valid scene")
    };
    let expected = (Vec3::from(scale).recip() * ns).normalize();
    let plain = (Vec3::from(scale) * ns).normalize();
    assert!(expected.dot(plain) < 0.99, "the scale must tell the two transforms apart");
    for (label, scene) in [
        ("OBJ vn", scene_with(json!({"type": "mesh", "path": "smooth.obj"}))),
        ("inline normals", scene_with(floor_shape(1.0, Some(ns)))),
    ] {
        let sp = scene.surface_point(SurfaceId::Object(0), 0, 0.2, 0.3);
        assert!((sp.n - Vec3::Y).length() < 1e-6, "{label}: geometric normal {:?}", sp.n);
        assert!((sp.ns - expected).length() < 1e-5, "{label}: shading normal {:?}, expected {expected:?}", sp.ns);
        assert!((sp.ns - plain).length() > 1e-2, "{label}: negative control");
    }
    for (label, scene) in [
        ("OBJ without vn", scene_with(json!({"type": "mesh", "path": "flat.obj"}))),
        ("no inline normals", scene_with(floor_shape(1.0, None))),
    ] {
        let sp = scene.surface_point(SurfaceId::Object(0), 1, 0.2, 0.3);
        assert_eq!(sp.ns, sp.n, "{label}");
        assert!(scene.objects[0].shading_normals.is_empty(), "{label}: a flat mesh keeps no normals");
    }
}

#[test]
fn every_technique_shades_direct_light_by_the_shading_normal() {
    // Property: direct light on a quad whose vertex normals lean 40° is ρ/π·I·max(0, ns·ω)/d²
    // (analytic, integrated over each pixel), in every technique. The image varies smoothly
    // and only the pixel jitter is random: the mean must hold within 1%. Negative control: the
    // flat quad (a technique that ignored the normals) is cos 40° darker and fails the bound.
    let ns = leaning(TILT_DEG);
    let expected = analytic_mean(&lone_quad(Some(ns)), ns);
    assert!((analytic_mean(&lone_quad(None), Vec3::Y) / expected - 1.0).abs() > 0.1, "the tilt must show");
    for config in small_techniques() {
        let label = config.label();
        for (normal, must_match) in [(Some(ns), true), (None, false)] {
            let frame = render(lone_quad(normal), config.clone(), 7, 4, 2);
            assert_finite_non_negative(&frame.image);
            let mean = frame.image.mean().g as f64;
            let error = mean / expected - 1.0;
            eprintln!("{label}, normals {normal:?}: {mean:.6} against {expected:.6} ({:+.2}%)", 100.0 * error);
            assert_eq!(error.abs() < 0.01, must_match, "{label}, normals {normal:?}: {:+.2}%", 100.0 * error);
        }
    }
}

/// A mirror quad whose vertex normals lean `tilt_deg` (`None`: flat), seen from straight above,
/// and a one-sided rect light of radiance `le` 2 m away along the direction the tilted normal
/// reflects a vertical view ray to (2·tilt from the vertical), facing the mirror.
fn mirror_and_light(tilt_deg: f32, normal: Option<Vec3>, reflectance: f32, le: f32) -> Scene {
    let towards = leaning(2.0 * tilt_deg);
    let facing = glam::Quat::from_rotation_arc(Vec3::Z, -towards);
    scene_from_json(json!({
        "camera": {"position": [0, 4, 0], "look_at": [0, 0, 0], "up": [0, 0, -1], "vfov_deg": 8, "resolution": [16, 16]},
        "materials": {"mirror": {"type": "mirror", "reflectance": [reflectance, reflectance, reflectance]}},
        "objects": [{"name": "mirror", "shape": floor_shape(1.0, normal), "material": "mirror"}],
        "lights": [{"name": "panel", "emitter": {"type": "rect", "radiance": [le, le, le]},
                    "transform": {"translation": (towards * 2.0).to_array(), "rotation": facing.to_array(),
                                  "scale": [1.0, 1.0, 1.0]}}]
    }))
}

#[test]
fn every_technique_sees_the_light_a_smooth_mirror_reflects_about_its_shading_normal() {
    // Property: a mirror reflects about its shading normal, so a vertical view ray off a mirror
    // whose normals lean 20° leaves 40° from the vertical and meets the panel there: every
    // pixel is R·Le exactly (the panel covers the view's whole reflected cone), in every
    // technique's camera chain. Negative control: the flat mirror reflects the view straight
    // up, and only the image's edge meets the panel (a mean of about a tenth of R·Le).
    let (tilt, r, le) = (20.0, 0.8, 3.0);
    let expected = (r * le) as f64;
    for config in small_techniques() {
        let label = config.label();
        for (normal, must_match) in [(Some(leaning(tilt)), true), (None, false)] {
            let frame = render(mirror_and_light(tilt, normal, r, le), config.clone(), 7, 2, 2);
            let mean = frame.image.mean().g as f64;
            eprintln!("{label}, normals {normal:?}: {mean:.5} against {expected}");
            assert_eq!((mean / expected - 1.0).abs() < 0.01, must_match, "{label}, normals {normal:?}: {mean}");
        }
    }
}

/// [`slab_room`] without its slab, its floor replaced by one with vertex normals `normal`
/// (`None`: flat), and its lamp by a spot 1 m above the floor pointing down: the ceiling and
/// walls, which the camera sees, get light only by way of the floor.
fn room_with_a_smooth_floor(normal: Option<Vec3>) -> Scene {
    let mut v = slab_room_json([0.0, 0.6, -3.8], [0.0, 2.6, 2.0], [0.0, 0.5, 0.0], [0.3, 0.3, 0.3], [0.0, 1.0, 0.0]);
    let objects = v["objects"].as_array_mut().expect("objects");
    objects.retain(|o| o["name"] != "slab");
    objects[0]["shape"] = floor_shape(2.0, normal);
    objects[0]["transform"] = json!({});
    v["lights"][0]["emitter"] = json!({"type": "spot", "intensity": [8, 8, 8], "cone_deg": 30});
    v["lights"][0]["transform"]["rotation"] = json!(FACE_DOWN);
    scene_from_json(v)
}

/// The green mean of `config`'s render of the room with the smooth floor over the flat one's
/// (same seed): what shading normals change in that technique's image.
fn smooth_over_flat(config: &TechniqueConfig, ns: Vec3, seed: u64) -> f64 {
    let smooth = render(room_with_a_smooth_floor(Some(ns)), config.clone(), seed, 16, 2).image;
    let flat = render(room_with_a_smooth_floor(None), config.clone(), seed, 16, 2).image;
    assert_finite_non_negative(&smooth);
    (smooth.mean().g / flat.mean().g) as f64
}

#[test]
fn light_off_a_smooth_floor_dims_the_room_as_much_in_every_technique_as_in_path() {
    // Property: a spot lights only the floor, whose normals lean 50°; the camera sees only the
    // ceiling and walls, which get light by way of the floor alone. The floor reflects
    // ρ/π·max(0, ns·ω) of what reaches it, which the light-side techniques (photons, VPLs,
    // particles, light subpaths) carry with the adjoint factor max(0, ns·ω)/|ng·ω| of the
    // direction light arrived from. Compared: each technique's image over its twin with a flat
    // floor (which cancels the technique's own bias), against `path`'s (1 024 spp, no adjoint
    // needed), within 3%; seeds vary the ratio by about 1%. particle_gi runs at 40 000
    // particles: at its test matrix's 4 000 the lit disc is a few particles wide and its ratio
    // is 6% low (it converges: 0.605 at 40 000 against path's 0.601). Negative control, by
    // hand: taking the factor out of importance transport (the BSDF's importance mode, photon
    // grid power, VPL intensity, particle emission and deposits) leaves photon_reuse, every
    // instant_cache mode and particle_gi at 1.000 and bdpt at 0.967 (the floor reflects as if
    // flat), far outside the bound.
    let ns = leaning(50.0);
    let expected = smooth_over_flat(&TechniqueConfig::Path(path(64)), ns, 3);
    assert!(expected < 0.9, "the floor's normals must dim the room: {expected}");
    for config in small_techniques() {
        let config = match config {
            TechniqueConfig::ParticleGi(_) => {
                TechniqueConfig::from_spec("particle_gi:particles=40000:gather_links=8").expect("particle_gi spec")
            }
            other => other,
        };
        let ratio = smooth_over_flat(&config, ns, 5);
        let label = config.label();
        eprintln!("{label}: smooth over flat {ratio:.4} against path's {expected:.4}");
        assert!((ratio / expected - 1.0).abs() < 0.03, "{label}: {ratio} against {expected}");
    }
}
