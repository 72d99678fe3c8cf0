//! Orthonormal shading frames around a normal (Duff et al. 2017, "Building an Orthonormal Basis,
//! Revisited"), so local directions have `z` along the normal.
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub struct ShadingFrame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl ShadingFrame {
    /// `n` must be unit length.
    pub fn from_normal(n: Vec3) -> ShadingFrame {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        ShadingFrame { s, t, n }
    }

    pub fn to_world(&self, local: Vec3) -> Vec3 {
        self.s * local.x + self.t * local.y + self.n * local.z
    }

    pub fn to_local(&self, world: Vec3) -> Vec3 {
        Vec3::new(world.dot(self.s), world.dot(self.t), world.dot(self.n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_for_awkward_normals() {
        for n in [
            Vec3::Z,
            Vec3::NEG_Z,
            Vec3::X,
            Vec3::new(1e-8, 0.0, -1.0).normalize(),
            Vec3::new(0.3, -0.8, 0.1).normalize(),
        ] {
            let f = ShadingFrame::from_normal(n);
            assert!((f.s.length() - 1.0).abs() < 1e-5 && (f.t.length() - 1.0).abs() < 1e-5);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5 && f.t.dot(n).abs() < 1e-5);
            let v = Vec3::new(0.2, -0.4, 0.7);
            assert!((f.to_local(f.to_world(v)) - v).length() < 1e-5);
        }
    }
}
