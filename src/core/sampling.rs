//! Sampling warps from [0,1)² to directions and points, their densities, a discrete
//! distribution, and the MIS power heuristic (Veach 1997, §9.2).
//!
//! Local directions have `z` along the normal. Densities are per unit solid angle for directions
//! and per unit area for points.
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4, PI};

/// Shirley–Chiu concentric map of the square onto the unit disc (area-preserving).
pub fn concentric_disc(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    // The angle is π/4·(y/x), or π/2 − π/4·(x/y) whose cosine and sine are the sine and cosine
    // of π/4·(x/y): either way one |angle| ≤ π/4, where a short polynomial is exact to float.
    // Both cases share one polynomial and pick their operands by selects, not a branch that a
    // random sample mispredicts half the time.
    let wide = o.x.abs() > o.y.abs();
    let (num, den) = if wide { (o.y, o.x) } else { (o.x, o.y) };
    let (sin, cos) = sin_cos_quarter(FRAC_PI_4 * (num / den));
    den * if wide { Vec2::new(cos, sin) } else { Vec2::new(sin, cos) }
}

/// (sin x, cos x) for |x| ≤ π/4 by their Taylor series to x⁹ and x¹⁰, whose remainders there are
/// below 2·10⁻⁹, far under float precision: no libm call and no range reduction on the
/// sampling hot path.
#[inline]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let sin = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0)))));
    let cos =
        1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0 + x2 * (-1.0 / 3_628_800.0)))));
    (sin, cos)
}

/// Cosine-weighted direction on the upper hemisphere (Malley's method).
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = concentric_disc(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Density of [`cosine_hemisphere`] for a local direction with cosine `cos_theta`.
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Uniform direction on the unit sphere.
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform direction in the cone of half-angle `acos(cos_max)` around +z.
pub fn uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = 1.0 - u.x * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Uniform barycentrics `(b1, b2)` on a triangle (Heitz 2019, low-distortion map); the point is
/// `(1-b1-b2)·p0 + b1·p1 + b2·p2`.
pub fn uniform_triangle(u: Vec2) -> Vec2 {
    let (b0, b1) = if u.x < u.y {
        let b0 = u.x / 2.0;
        (b0, u.y - b0)
    } else {
        let b1 = u.y / 2.0;
        (u.x - b1, b1)
    };
    Vec2::new(b1, 1.0 - b0 - b1)
}

/// Veach's power heuristic with β = 2, for one sample from each of two strategies.
pub fn power_heuristic(pdf_this: f32, pdf_other: f32) -> f32 {
    let a = pdf_this * pdf_this;
    let b = pdf_other * pdf_other;
    if a == 0.0 || b.is_infinite() {
        0.0
    } else {
        a / (a + b)
    }
}

/// A discrete distribution over `weights.len()` items, sampled by inverting its CDF.
#[derive(Clone, Debug, Default)]
pub struct DiscreteDistribution {
    cdf: Vec<f32>,
    total: f32,
    /// Per item: its probability and the reciprocal of its weight (0 for a zero weight),
    /// worked out once so that sampling divides nothing.
    buckets: Vec<(f32, f32)>,
}

impl DiscreteDistribution {
    /// `None` if there are no weights or they sum to zero; negative or non-finite weights count
    /// as zero.
    pub fn new(weights: &[f32]) -> Option<DiscreteDistribution> {
        let mut cdf = Vec::with_capacity(weights.len());
        let mut acc = 0.0f64;
        for &w in weights {
            acc += if w.is_finite() && w > 0.0 { w as f64 } else { 0.0 };
            cdf.push(acc as f32);
        }
        let total = acc as f32;
        let buckets = (0..cdf.len())
            .map(|i| {
                let w = cdf[i] - if i == 0 { 0.0 } else { cdf[i - 1] };
                (w / total, if w > 0.0 { 1.0 / w } else { 0.0 })
            })
            .collect();
        (acc > 0.0).then_some(DiscreteDistribution { cdf, total, buckets })
    }

    pub fn len(&self) -> usize {
        self.cdf.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cdf.is_empty()
    }

    /// Returns `(index, probability, u remapped to [0,1) within the chosen bucket)`.
    pub fn sample(&self, u: f32) -> (usize, f32, f32) {
        let target = u * self.total;
        let i = match self.cdf.len() {
            1 => 0,
            n => self.cdf.partition_point(|&c| c <= target).min(n - 1),
        };
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let (pmf, inv_width) = self.buckets[i];
        let remapped = if inv_width > 0.0 { ((target - lo) * inv_width).clamp(0.0, 1.0 - f32::EPSILON) } else { 0.0 };
        (i, pmf, remapped)
    }

    pub fn pmf(&self, i: usize) -> f32 {
        self.buckets[i].0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::FRAC_PI_2;

    /// Largest error of a (sin, cos) approximation against f64 over |x| ≤ π/4.
    fn sin_cos_error(f: impl Fn(f32) -> (f32, f32)) -> f64 {
        (0..=100_000)
            .map(|i| -FRAC_PI_4 + FRAC_PI_2 * i as f32 / 100_000.0)
            .map(|x| {
                let (s, c) = f(x);
                let (xs, xc) = (x as f64).sin_cos();
                (s as f64 - xs).abs().max((c as f64 - xc).abs())
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn quarter_sin_cos_is_float_exact() {
        // Within 2 float ulps of 1 of the true values, like libm's own float sin and cos.
        let tolerance = 2.0 * f32::EPSILON as f64;
        let ours = sin_cos_error(sin_cos_quarter);
        assert!(ours < tolerance, "error {ours:e}");
        let libm = sin_cos_error(|x| (x.sin(), x.cos()));
        assert!(libm < tolerance, "libm error {libm:e}");
        // Negative control: the series one term shorter misses the tolerance.
        let short = sin_cos_error(|x| {
            let x2 = x * x;
            (
                x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0)))),
                1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0)))),
            )
        });
        assert!(short > tolerance, "the shorter series is within {short:e}");
    }

    #[test]
    fn discrete_distribution_skips_zero_weights() {
        let d = DiscreteDistribution::new(&[0.0, 1.0, 0.0, 3.0]).unwrap();
        assert_eq!(d.sample(0.0).0, 1);
        assert_eq!(d.sample(0.2).0, 1);
        assert_eq!(d.sample(0.3).0, 3);
        assert_eq!(d.sample(0.999).0, 3);
        assert!((d.pmf(3) - 0.75).abs() < 1e-6);
        assert!(DiscreteDistribution::new(&[0.0, f32::NAN]).is_none());
    }

    #[test]
    fn power_heuristic_limits() {
        assert_eq!(power_heuristic(1.0, 0.0), 1.0);
        assert_eq!(power_heuristic(0.0, 1.0), 0.0);
        assert!((power_heuristic(1.0, 1.0) - 0.5).abs() < 1e-6);
        assert_eq!(power_heuristic(1.0, f32::INFINITY), 0.0);
    }
}
