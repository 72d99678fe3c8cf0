//! Every technique renders under every Embree kernel family this CPU has.
//!
//! Embree's SSE, AVX, AVX2 and AVX-512 kernels load packets and masks with different
//! instructions, so a contract broken for one family (a misaligned valid mask) can pass under
//! another. This renders the Cornell box with each technique of the small test matrix, and
//! `path` at each packet width, on a device capped at each family; the images must be finite
//! and agree with the widest family's.
mod common;
use common::*;
use relume::technique::TechniqueConfig;

fn cornell() -> relume::scene::Scene {
    let mut scene = load("cornell-box.json");
    scene.set_resolution(16, 16);
    scene
}

fn matrix() -> Vec<TechniqueConfig> {
    let mut all = small_techniques();
    for width in [1, 8, 16] {
        all.push(TechniqueConfig::from_spec(&format!("path:spp=4:packet_width={width}")).expect("spec"));
    }
    all
}

/// Relative agreement of image means across families. The families trace the same rays and
/// differ only in the last bits of a few hits, so their means agree far more closely than the
/// noise of a different seed (checked below as the negative control).
const AGREEMENT: f64 = 1e-3;

fn mean_luminance(device: &relume::embree::Device, config: &TechniqueConfig, seed: u64) -> f64 {
    let frame = render_on(device, cornell(), config.clone(), seed, 2, 2);
    assert_finite_non_negative(&frame.image);
    frame.image.mean().luminance() as f64
}

#[test]
fn under_every_isa_every_technique_renders() {
    let configs = matrix();
    let mut rows: Vec<(relume::embree::Isa, Vec<f64>)> = Vec::new();
    for_each_isa(|isa, device| {
        let row: Vec<f64> = configs.iter().map(|c| mean_luminance(device, c, 7)).collect();
        for (c, m) in configs.iter().zip(&row) {
            assert!(*m > 0.0, "{isa} {}: black image", c.id());
        }
        rows.push((isa, row));
    });
    let (widest, reference) = rows.last().cloned().expect("every x86-64 CPU has SSE2");
    for (isa, row) in &rows {
        for ((c, m), r) in configs.iter().zip(row).zip(&reference) {
            assert!((m - r).abs() <= AGREEMENT * r, "{}: {isa} gives {m}, {widest} gives {r}", c.id());
        }
    }
    // Negative control: another seed's noise is far larger than the tolerance, so a family
    // that traced different rays would be caught.
    let device = relume::embree::Device::new(2).expect("device");
    let (a, b) = (mean_luminance(&device, &configs[0], 7), mean_luminance(&device, &configs[0], 8));
    assert!((a - b).abs() > AGREEMENT * a, "seeds 7 and 8 agree too well: {a} vs {b}");
}

/// Lanes per packet a render used, from its stats.
fn packet_width(frame: &relume::engine::Frame) -> u32 {
    match &frame.stats.detail {
        relume::technique::TechniqueStats::Path(p) => p.packet_width,
        relume::technique::TechniqueStats::Bdpt(b) => b.lanes.packet_width,
        other => panic!("path or bdpt stats expected, got {other:?}"),
    }
}

#[test]
fn without_a_packet_width_packets_are_as_wide_as_the_devices_kernels() {
    // The width follows the device's kernel family, not the CPU: a device capped at AVX2 on an
    // AVX-512 machine traces 8-wide packets, where 16-wide ones run slower (`Isa::packet_lanes`).
    // A width given explicitly is kept under every family.
    for_each_isa(|isa, device| {
        for spec in ["path:spp=1", "bdpt:spp=1"] {
            let config = TechniqueConfig::from_spec(spec).expect("spec");
            let native = packet_width(&render_on(device, cornell(), config, 3, 1, 1));
            assert_eq!(native, isa.packet_lanes(), "{spec} under {isa}");
            let given = TechniqueConfig::from_spec(&format!("{spec}:packet_width=1")).expect("spec");
            assert_eq!(packet_width(&render_on(device, cornell(), given, 3, 1, 1)), 1, "{spec} under {isa}");
        }
    });
}
