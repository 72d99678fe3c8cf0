//! Ward's RGBE (Graphics Gems II, "Real Pixels"): an RGB triple in 4 bytes, three 8-bit
//! mantissas sharing one exponent. Relative precision about 1% of the largest channel; channels
//! below 2⁻⁸ of it round to zero. The instant cache stores one per VPL per record (§3.2).
use crate::core::Rgb;

/// Packs non-negative `c` (negative and non-finite channels are taken as 0).
pub fn pack(c: Rgb) -> u32 {
    let clean = |x: f32| if x.is_finite() && x > 0.0 { x } else { 0.0 };
    let (r, g, b) = (clean(c.r), clean(c.g), clean(c.b));
    let m = r.max(g).max(b);
    if m < 1e-32 {
        return 0;
    }
    // m = f · 2^e with f in [0.5, 1), read off m's exponent bits (m ≥ 1e-32 is normal).
    let e = ((m.to_bits() >> 23) & 0xFF) as i32 - 126;
    let scale = 256.0 * pow2(-e);
    let q = |x: f32| ((x * scale) as u32).min(255);
    (q(r) << 24) | (q(g) << 16) | (q(b) << 8) | ((e + 128).clamp(0, 255) as u32)
}

/// Lanes of [`sum`]: its partial sums, one per lane, are added in a fixed tree at the end.
const LANES: usize = 8;

/// The sum of `values` unpacked: lane j adds values j, j + 8, j + 16, … in order, and the eight
/// lanes are then added pairwise, so the result is a function of the values alone and the loop
/// vectorises (a sequential sum waits on each add in turn).
pub fn sum(values: &[u32]) -> Rgb {
    let mut lanes = [[0.0f32; LANES]; 3];
    let chunks = values.chunks_exact(LANES);
    let tail = chunks.remainder();
    for chunk in chunks {
        for (j, &v) in chunk.iter().enumerate() {
            let [r, g, b] = unpack(v);
            lanes[0][j] += r;
            lanes[1][j] += g;
            lanes[2][j] += b;
        }
    }
    for (j, &v) in tail.iter().enumerate() {
        let [r, g, b] = unpack(v);
        lanes[0][j] += r;
        lanes[1][j] += g;
        lanes[2][j] += b;
    }
    let fold = |l: &[f32; LANES]| ((l[0] + l[1]) + (l[2] + l[3])) + ((l[4] + l[5]) + (l[6] + l[7]));
    Rgb::new(fold(&lanes[0]), fold(&lanes[1]), fold(&lanes[2]))
}

/// Unpacks to the centre of each mantissa step: (m + ½)·2^(e − 136), a zero mantissa to zero.
/// Without branches on the exponent, so [`sum`] vectorises: 2^(e − 136) is the product of two
/// powers of two that are normal floats, which is exact, subnormal or not.
#[inline]
fn unpack(v: u32) -> [f32; 3] {
    let k = (v & 0xFF) as i32 - 136;
    let normal = f32::from_bits(((k.max(-126) + 127) as u32) << 23);
    let below = f32::from_bits(((k.min(-126) + 126 + 127) as u32) << 23);
    let scale = normal * below;
    let d = |shift: u32| {
        let m = (v >> shift) & 0xFF;
        let x = (m as f32 + 0.5) * scale;
        if m == 0 {
            0.0
        } else {
            x
        }
    };
    [d(24), d(16), d(8)]
}

/// 2^k, exact, built from its bits where it is a normal float (libm's `exp2f` is the slow
/// path, for the subnormal rest).
fn pow2(k: i32) -> f32 {
    if (-126..=127).contains(&k) {
        f32::from_bits(((k + 127) as u32) << 23)
    } else {
        (k as f32).exp2()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_within_its_precision() {
        let mut rng = crate::core::Rng::new(5, 6);
        for _ in 0..10_000 {
            let exponent = rng.next_f32() * 60.0 - 30.0;
            let c = Rgb::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * exponent.exp2();
            let back = unpack(pack(c));
            let m = c.max_component();
            for (a, b) in c.to_array().iter().zip(back) {
                // Half a mantissa step of the shared exponent: at most 2⁻⁸ of 2^e ≤ 2m.
                assert!((a - b).abs() <= m / 128.0 + 1e-30, "{c:?} → {back:?}");
            }
        }
        for k in -149..=127 {
            assert_eq!(pow2(k), (k as f32).exp2(), "2^{k}");
        }
        assert_eq!(unpack(pack(Rgb::BLACK)), [0.0; 3]);
        assert_eq!(sum(&[]), Rgb::BLACK);
        assert_eq!(unpack(pack(Rgb::new(-1.0, f32::NAN, 0.0))), [0.0; 3]);
    }

    #[test]
    fn every_value_unpacks_to_its_step_centre_and_sums_within_rounding() {
        // Property: every exponent and mantissa unpacks to (m + ½)·2^(e − 136) rounded once to
        // f32 (worked out in f64, where it is exact), subnormal results included; and sums of
        // random values agree with an f64 sum within f32 rounding. Negative control, by hand:
        // dropping the `below` factor (exponents under 10 then unpack as if 10) fails the first
        // assertion.
        for e in 0..=255u32 {
            for m in [0u32, 1, 2, 127, 128, 255] {
                let v = (m << 24) | (((m * 7) & 0xFF) << 16) | ((255 - m) << 8) | e;
                let centre = |m: u32| if m == 0 { 0.0 } else { ((m as f64 + 0.5) * 2f64.powi(e as i32 - 136)) as f32 };
                let expected = [centre(v >> 24), centre((v >> 16) & 0xFF), centre((v >> 8) & 0xFF)];
                assert_eq!(unpack(v), expected, "{v:#010x}");
            }
        }
        let mut rng = crate::core::Rng::new(7, 8);
        for n in [1usize, 7, 8, 9, 221, 256] {
            let values: Vec<u32> =
                (0..n).map(|_| pack(Rgb::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 3.0)).collect();
            let exact = values.iter().fold([0.0f64; 3], |s, &v| {
                let c = unpack(v);
                [s[0] + c[0] as f64, s[1] + c[1] as f64, s[2] + c[2] as f64]
            });
            let ours = sum(&values).to_array();
            for (a, b) in ours.iter().zip(exact) {
                assert!((*a as f64 - b).abs() <= 1e-6 * b.abs().max(1e-30), "{n} values: {a} against {b}");
            }
        }
    }
}
