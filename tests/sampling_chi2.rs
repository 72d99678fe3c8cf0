//! χ² goodness-of-fit tests of the sampling routines: sampled directions are binned over
//! (cos θ, φ) and compared with the counts the routines' own pdfs predict. A routine whose
//! samples disagree with its pdf biases every MIS weight it takes part in.
use glam::Vec3;
use relume::core::sampling;
use relume::core::{Rgb, Rng};
use relume::scene::model::{EmitterDesc, LightDesc, Trs};
use relume::scene::{LightGeometry, Outside};
use statrs::distribution::{ChiSquared, ContinuousCDF};

const COS_BINS: usize = 10;
const PHI_BINS: usize = 20;
const SAMPLES: usize = 200_000;

fn bin_of(d: Vec3) -> usize {
    // cos θ ∈ [-1, 1] and φ ∈ [0, 2π) on a regular grid.
    let c = (((d.z + 1.0) * 0.5 * COS_BINS as f32) as usize).min(COS_BINS - 1);
    let phi = d.y.atan2(d.x).rem_euclid(std::f32::consts::TAU);
    let p = ((phi / std::f32::consts::TAU * PHI_BINS as f32) as usize).min(PHI_BINS - 1);
    c * PHI_BINS + p
}

/// Expected probability of each bin: the pdf integrated by a 12×12 midpoint rule per bin.
fn expected_probabilities(pdf: impl Fn(Vec3) -> f64) -> Vec<f64> {
    let sub = 12;
    let mut out = vec![0.0; COS_BINS * PHI_BINS];
    for (b, e) in out.iter_mut().enumerate() {
        let (ci, pi) = (b / PHI_BINS, b % PHI_BINS);
        let dc = 2.0 / COS_BINS as f64;
        let dp = std::f64::consts::TAU / PHI_BINS as f64;
        for i in 0..sub {
            for j in 0..sub {
                let c = -1.0 + dc * (ci as f64 + (i as f64 + 0.5) / sub as f64);
                let p = dp * (pi as f64 + (j as f64 + 0.5) / sub as f64);
                let s = (1.0 - c * c).max(0.0).sqrt();
                let d = Vec3::new((s * p.cos()) as f32, (s * p.sin()) as f32, c as f32);
                *e += pdf(d) * dc * dp / (sub * sub) as f64;
            }
        }
    }
    out
}

/// Pearson's χ² over bins with at least 5 expected samples (others pooled); returns the p-value.
fn chi2_p_value(observed: &[u64], expected_p: &[f64], n: usize) -> f64 {
    let (mut chi2, mut dof) = (0.0, 0i64);
    let (mut pooled_o, mut pooled_e) = (0.0, 0.0);
    for (o, p) in observed.iter().zip(expected_p) {
        let e = p * n as f64;
        if e < 5.0 {
            pooled_o += *o as f64;
            pooled_e += e;
        } else {
            chi2 += (*o as f64 - e).powi(2) / e;
            dof += 1;
        }
    }
    if pooled_e >= 5.0 {
        chi2 += (pooled_o - pooled_e).powi(2) / pooled_e;
        dof += 1;
    } else {
        assert!(pooled_o <= 5.0 + 3.0 * pooled_e.sqrt(), "{pooled_o} samples where the pdf expects {pooled_e}");
    }
    let dist = ChiSquared::new((dof - 1) as f64).expect("degrees of freedom");
    1.0 - dist.cdf(chi2)
}

fn run(sample: impl Fn(&mut Rng) -> Option<Vec3>, pdf: impl Fn(Vec3) -> f64) -> f64 {
    let mut rng = Rng::new(12345, 7);
    let mut observed = vec![0u64; COS_BINS * PHI_BINS];
    let mut n = 0;
    for _ in 0..SAMPLES {
        if let Some(d) = sample(&mut rng) {
            observed[bin_of(d)] += 1;
            n += 1;
        }
    }
    let expected = expected_probabilities(pdf);
    // The pdf must integrate to the fraction of successful samples (here: all of them).
    let total: f64 = expected.iter().sum();
    assert!((total - n as f64 / SAMPLES as f64).abs() < 0.01, "pdf integrates to {total}");
    chi2_p_value(&observed, &expected, n)
}

/// The threshold: with several tests, a p-value below 1e-3 is a real mismatch, not bad luck.
const SIGNIFICANCE: f64 = 1e-3;

#[test]
fn cosine_hemisphere_matches_its_pdf() {
    let p = run(|r| Some(sampling::cosine_hemisphere(r.next_2d())), |d| sampling::cosine_hemisphere_pdf(d.z) as f64);
    assert!(p > SIGNIFICANCE, "p = {p}");
}

#[test]
fn uniform_sphere_and_cone_match_their_pdfs() {
    let p = run(|r| Some(sampling::uniform_sphere(r.next_2d())), |_| sampling::UNIFORM_SPHERE_PDF as f64);
    assert!(p > SIGNIFICANCE, "sphere p = {p}");
    let cos_max = 0.6f32;
    let p = run(
        |r| Some(sampling::uniform_cone(r.next_2d(), cos_max)),
        |d| if d.z >= cos_max { sampling::uniform_cone_pdf(cos_max) as f64 } else { 0.0 },
    );
    assert!(p > SIGNIFICANCE, "cone p = {p}");
}

#[test]
fn sun_and_environment_directions_match_their_pdfs() {
    // A sun of 60° angular diameter travelling along −Z (its cone's edge along the bins' rows,
    // which a tilted cone would cut into slivers the midpoint rule misses), and the
    // environment seen from a surface whose normal is tilted off +Z: each light's sampled
    // directions against its own `pdf_direction`, which MIS uses for the rays that escape.
    let outside = Outside { center: Vec3::ZERO, radius: 1.0 };
    let sun = LightGeometry::new(
        &LightDesc {
            name: "sun".into(),
            emitter: EmitterDesc::Directional { direction: [0.0, 0.0, -1.0], irradiance: Rgb::WHITE, angle_deg: 60.0 },
            transform: Trs::default(),
            dynamic: false,
        },
        None,
        outside,
    );
    let side = Vec3::new(0.3, 0.0, 1.0).normalize();
    let env = LightGeometry::environment(Rgb::WHITE, outside);
    for (name, light, side) in [("sun", &sun, Vec3::ZERO), ("environment", &env, side)] {
        let p = run(
            |r| light.sample_incident(Vec3::ZERO, side, r.next_2d()).map(|s| s.wi),
            |d| light.pdf_direction(d, side) as f64,
        );
        assert!(p > SIGNIFICANCE, "{name}: p = {p}");
    }
}

#[test]
fn a_mismatched_pdf_is_detected() {
    // The test must be able to fail: uniform hemisphere samples against the cosine pdf.
    let p = run(
        |r| {
            let d = sampling::uniform_sphere(r.next_2d());
            Some(Vec3::new(d.x, d.y, d.z.abs()))
        },
        |d| sampling::cosine_hemisphere_pdf(d.z) as f64,
    );
    assert!(p < SIGNIFICANCE, "χ² failed to notice a wrong pdf (p = {p})");
}

fn area_light(emitter: EmitterDesc, transform: Trs) -> LightGeometry {
    let desc = LightDesc { name: "l".into(), emitter: emitter.clone(), transform, dynamic: false };
    let mesh = relume::scene::light::emitter_mesh(&emitter);
    LightGeometry::new(&desc, mesh.as_ref(), Outside { center: Vec3::ZERO, radius: 1.0 })
}

/// A light facing down (−Z) at height `h` above the origin, scaled by `sx`, `sy`.
fn overhead(emitter: EmitterDesc, h: f32, sx: f32, sy: f32) -> LightGeometry {
    let t = Trs {
        translation: [0.0, 0.0, h],
        rotation: glam::Quat::from_rotation_x(std::f32::consts::PI).to_array(),
        scale: [sx, sy, 1.0],
    };
    area_light(emitter, t)
}

/// χ² p-value of a light's sampled points (seen from the origin), mapped by `to_unit` back to
/// its [0,1]² parameters, against an even fill of a 10×20 grid; a point off the light (outside
/// [0,1]² by more than rounding) fails at once.
fn unit_square_p_value(light: &LightGeometry, seed: u64, to_unit: impl Fn(Vec3) -> (f32, f32)) -> f64 {
    let mut rng = Rng::new(seed, 9);
    let mut observed = vec![0u64; COS_BINS * PHI_BINS];
    let inside = |t: f32| (-1e-5..=1.0 + 1e-5).contains(&t);
    for _ in 0..SAMPLES {
        let s = light.sample_incident(Vec3::ZERO, Vec3::ZERO, rng.next_2d()).expect("the light faces the origin");
        let q = s.wi * s.dist;
        let (u, v) = to_unit(q);
        assert!(inside(u) && inside(v), "off the light: {q}");
        let bin = ((v * COS_BINS as f32) as usize).min(COS_BINS - 1) * PHI_BINS
            + ((u * PHI_BINS as f32) as usize).min(PHI_BINS - 1);
        observed[bin] += 1;
    }
    let expected = vec![1.0 / (COS_BINS * PHI_BINS) as f64; COS_BINS * PHI_BINS];
    chi2_p_value(&observed, &expected, SAMPLES)
}

#[test]
fn rect_light_points_are_uniform_by_area() {
    let light = overhead(EmitterDesc::Rect { radiance: Rgb::WHITE }, 1.0, 1.0, 0.5);
    assert!(matches!(light, LightGeometry::Area { parallelogram: Some(_), .. }), "not sampled over its edges");
    // Rect spans x ∈ [-1, 1], y ∈ [-0.5, 0.5] (rotated by π about X, y flips sign).
    let p = unit_square_p_value(&light, 3, |q| ((q.x + 1.0) / 2.0, (-q.y + 0.5) / 1.0));
    assert!(p > SIGNIFICANCE, "p = {p}");
}

/// A mesh light 1 above the origin, facing down, from corners in the plane z = 1.
fn mesh_light(corners: [[f32; 2]; 4], indices: [[u32; 3]; 2]) -> LightGeometry {
    let positions = corners.map(|[x, y]| [x, y, 1.0]);
    let emitter = EmitterDesc::Mesh { radiance: Rgb::WHITE, positions: positions.into(), indices: indices.into() };
    area_light(emitter, Trs::default())
}

#[test]
fn a_parallelogram_mesh_light_is_sampled_uniformly_over_its_edges() {
    // A sheared parallelogram (0,0), (2,0), (3,1), (1,1), split along (2,0)–(1,1) and listed
    // from that diagonal, so the corner and edges are not the vertices' first three.
    let light = mesh_light([[0.0, 0.0], [2.0, 0.0], [3.0, 1.0], [1.0, 1.0]], [[1, 3, 2], [1, 0, 3]]);
    assert!(matches!(light, LightGeometry::Area { parallelogram: Some(_), .. }), "not seen as a parallelogram");
    // q = (0,0) + a·(2,0) + b·(1,1): b = y, a = (x − y) / 2.
    let p = unit_square_p_value(&light, 4, |q| ((q.x - q.y) / 2.0, q.y));
    assert!(p > SIGNIFICANCE, "p = {p}");
    // Two triangles that are not one parallelogram (a trapezoid, and two facing opposite ways)
    // keep the choice of triangle by area.
    let trapezoid = mesh_light([[0.0, 0.0], [2.0, 0.0], [3.5, 1.0], [1.0, 1.0]], [[1, 3, 2], [1, 0, 3]]);
    let folded = mesh_light([[0.0, 0.0], [2.0, 0.0], [3.0, 1.0], [1.0, 1.0]], [[1, 3, 2], [1, 3, 0]]);
    for light in [trapezoid, folded] {
        assert!(matches!(light, LightGeometry::Area { parallelogram: None, .. }), "{light:?}");
    }
}

/// Mean and standard error of `f(sample)` over light samples seen from the origin.
fn light_estimate(light: &LightGeometry, f: impl Fn(&relume::scene::IncidentSample) -> f64) -> (f64, f64) {
    let mut rng = Rng::new(11, 2);
    let xs: Vec<f64> = (0..SAMPLES)
        .map(|_| light.sample_incident(Vec3::ZERO, Vec3::ZERO, rng.next_2d()).map_or(0.0, |s| f(&s)))
        .collect();
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn rect_light_pdf_integrates_to_its_solid_angle() {
    // E[1/pdf] is the solid angle. On axis, a 2a×2b rectangle at distance d subtends
    // Ω = 4·asin(ab / sqrt((a² + d²)(b² + d²))).
    let (a, b, d) = (1.0f64, 0.5f64, 1.0f64);
    let light = overhead(EmitterDesc::Rect { radiance: Rgb::WHITE }, d as f32, a as f32, b as f32);
    let omega = 4.0 * (a * b / ((a * a + d * d) * (b * b + d * d)).sqrt()).asin();
    let (mean, se) = light_estimate(&light, |s| 1.0 / s.pdf as f64);
    assert!((mean - omega).abs() < 4.0 * se + 1e-4 * omega, "E[1/pdf] = {mean} ± {se}, Ω = {omega}");
}

#[test]
fn disc_light_pdf_integrates_to_its_projected_solid_angle() {
    // E[cos θ / pdf] is the projected solid angle: π r² / (r² + d²) for a disc on axis (256
    // segments make the polygon's area within 1e-4 of the disc's).
    let (r, d) = (0.7f64, 0.8f64);
    let light = overhead(EmitterDesc::Disc { radiance: Rgb::WHITE, segments: 256 }, d as f32, r as f32, r as f32);
    let expected = std::f64::consts::PI * r * r / (r * r + d * d);
    let (mean, se) = light_estimate(&light, |s| s.wi.z as f64 / s.pdf as f64);
    assert!((mean - expected).abs() < 4.0 * se + 2e-4 * expected, "E[cos/pdf] = {mean} ± {se}, expected {expected}");
}

#[test]
fn light_selection_follows_power() {
    let d = sampling::DiscreteDistribution::new(&[1.0, 3.0, 0.0, 6.0]).unwrap();
    let mut rng = Rng::new(1, 2);
    let mut observed = [0u64; 4];
    for _ in 0..SAMPLES {
        observed[d.sample(rng.next_f32()).0] += 1;
    }
    assert_eq!(observed[2], 0);
    let p = chi2_p_value(&[observed[0], observed[1], observed[3]], &[0.1, 0.3, 0.6], SAMPLES);
    assert!(p > SIGNIFICANCE, "p = {p}");
}

#[test]
fn the_remapped_number_is_uniform_within_each_item() {
    // Light sampling reuses it to pick a point on the chosen triangle, so it must be a fresh
    // uniform number in [0, 1) within every item, a single item included.
    for weights in [&[1.0, 3.0, 0.0, 6.0][..], &[2.5]] {
        let d = sampling::DiscreteDistribution::new(weights).unwrap();
        let mut rng = Rng::new(3, 4);
        let mut bins = vec![[0u64; 10]; weights.len()];
        for _ in 0..SAMPLES {
            let (i, _, v) = d.sample(rng.next_f32());
            assert!((0.0..1.0).contains(&v), "remapped {v}");
            bins[i][(v * 10.0) as usize] += 1;
        }
        for (i, b) in bins.iter().enumerate().filter(|(i, _)| weights[*i] > 0.0) {
            let n = b.iter().sum::<u64>() as usize;
            let p = chi2_p_value(b, &[0.1; 10], n);
            assert!(p > SIGNIFICANCE, "item {i} of {weights:?}: p = {p}, bins {b:?}");
        }
    }
}

#[test]
fn triangle_sampling_is_uniform_by_area() {
    // Uniform barycentrics: the fraction landing in the sub-triangle b1 + b2 < 1/2 is 1/4.
    let mut rng = Rng::new(5, 5);
    let n = 100_000;
    let inside = (0..n).filter(|_| {
        let b = sampling::uniform_triangle(rng.next_2d());
        assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
        b.x + b.y < 0.5
    });
    let frac = inside.count() as f64 / n as f64;
    assert!((frac - 0.25).abs() < 4.0 * (0.25f64 * 0.75 / n as f64).sqrt(), "fraction {frac}");
}
