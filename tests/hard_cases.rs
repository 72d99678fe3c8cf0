//! Numerically hard cases. Each test states the property it protects.
mod common;
use common::*;
use relume::film::LinearImage;
use relume::scene::{Scene, SceneDesc};
use relume::technique::TechniqueConfig;

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
    render(scene, TechniqueConfig::Path(path(64)), 11, 1, 2).image
}

fn block_means(img: &LinearImage) -> Vec<f64> {
    let mut out = Vec::new();
    for by in 0..4 {
        for bx in 0..4 {
            let mut s = 0.0f64;
            for y in by * 8..(by + 1) * 8 {
                for x in bx * 8..(bx + 1) * 8 {
                    s += img.get(x, y).luminance() as f64;
                }
            }
            out.push(s / 64.0);
        }
    }
    out
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
