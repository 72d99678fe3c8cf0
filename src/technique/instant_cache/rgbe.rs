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

/// Unpacks to the centre of each mantissa step.
pub fn unpack(v: u32) -> Rgb {
    let e = (v & 0xFF) as i32;
    if e == 0 && v >> 8 == 0 {
        return Rgb::BLACK;
    }
    let scale = pow2(e - 136);
    let d = |shift: u32| {
        let m = (v >> shift) & 0xFF;
        if m == 0 {
            0.0
        } else {
            (m as f32 + 0.5) * scale
        }
    };
    Rgb::new(d(24), d(16), d(8))
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
            for (a, b) in c.to_array().iter().zip(back.to_array()) {
                // Half a mantissa step of the shared exponent: at most 2⁻⁸ of 2^e ≤ 2m.
                assert!((a - b).abs() <= m / 128.0 + 1e-30, "{c:?} → {back:?}");
            }
        }
        for k in -149..=127 {
            assert_eq!(pow2(k), (k as f32).exp2(), "2^{k}");
        }
        assert_eq!(unpack(pack(Rgb::BLACK)), Rgb::BLACK);
        assert_eq!(unpack(pack(Rgb::new(-1.0, f32::NAN, 0.0))), Rgb::BLACK);
    }
}
