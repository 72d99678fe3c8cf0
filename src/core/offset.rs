//! Robust ray origins: offset a hit point along its geometric normal by an amount bounded by the
//! point's floating-point error, not by a fixed epsilon.
//!
//! Wächter and Binder, "A Fast and Robust Method for Avoiding Self-Intersection", Ray Tracing
//! Gems (2019), ch. 6. Far from the origin the offset is a fixed number of ULPs, so it scales with
//! the magnitude of the coordinates (a scene translated by 1e5 still works); near the origin,
//! where ULPs vanish, a tiny absolute offset is used instead.
use glam::Vec3;

const ORIGIN: f32 = 1.0 / 32.0;
const FLOAT_SCALE: f32 = 1.0 / 65536.0;
const INT_SCALE: f32 = 256.0;

/// Offsets `p` off the surface along `n` (the side `n` points to). `n` must be unit length and
/// on the side the new ray leaves towards.
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    let of_i = [(INT_SCALE * n.x) as i32, (INT_SCALE * n.y) as i32, (INT_SCALE * n.z) as i32];
    let pa = p.to_array();
    let na = n.to_array();
    let mut out = [0.0f32; 3];
    for k in 0..3 {
        let bits = pa[k].to_bits() as i32;
        let shifted = f32::from_bits(bits.wrapping_add(if pa[k] < 0.0 { -of_i[k] } else { of_i[k] }) as u32);
        out[k] = if pa[k].abs() < ORIGIN { pa[k] + FLOAT_SCALE * na[k] } else { shifted };
    }
    Vec3::from_array(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_moves_to_the_normal_side_at_every_scale() {
        let n = Vec3::new(0.3, -0.5, 0.81).normalize();
        for scale in [0.0f32, 1e-3, 1.0, 1e3, 1e5] {
            let p = Vec3::new(1.0, -2.0, 0.5) * scale;
            let q = offset_ray_origin(p, n);
            assert!((q - p).dot(n) > 0.0, "scale {scale}: offset {:?}", q - p);
            // Bounded: a few hundred ULPs of the largest coordinate, or 2^-16 near the origin.
            let bound = (p.abs().max_element() * 256.0 * f32::EPSILON * 2.0).max(2.0 * FLOAT_SCALE);
            assert!((q - p).length() <= bound, "scale {scale}: {} > {bound}", (q - p).length());
        }
    }
}
