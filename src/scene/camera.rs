//! The pinhole camera: world position, orientation from `look_at`/`up`, vertical field of view.
//! Camera space looks down −Z with +Y up; pixel (0,0) is the top-left corner of the image.
use super::model::CameraDesc;
use crate::embree::Ray;
use glam::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    pub forward: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    pub tan_half_vfov: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// Builds the camera; the description must be valid (see `load::validate_camera`).
    pub fn from_desc(desc: &CameraDesc) -> Camera {
        let position = Vec3::from(desc.position);
        let forward = (Vec3::from(desc.look_at) - position).normalize();
        let right = forward.cross(Vec3::from(desc.up)).normalize();
        let up = right.cross(forward);
        Camera {
            position,
            forward,
            right,
            up,
            tan_half_vfov: (desc.vfov_deg.to_radians() * 0.5).tan(),
            width: desc.resolution[0],
            height: desc.resolution[1],
        }
    }

    /// The same camera at another resolution.
    pub fn with_resolution(mut self, width: u32, height: u32) -> Camera {
        self.width = width;
        self.height = height;
        self
    }

    /// The primary ray through film position (`x`, `y`) in pixels, `x` ∈ [0, width).
    pub fn ray(&self, x: f32, y: f32) -> Ray {
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * x / self.width as f32 - 1.0) * self.tan_half_vfov * aspect;
        let sy = (1.0 - 2.0 * y / self.height as f32) * self.tan_half_vfov;
        Ray::new(self.position, (self.forward + self.right * sx + self.up * sy).normalize())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_and_corners() {
        let cam = Camera::from_desc(&CameraDesc {
            position: [0.0, 0.0, 0.0],
            look_at: [0.0, 0.0, -1.0],
            up: [0.0, 1.0, 0.0],
            vfov_deg: 90.0,
            resolution: [200, 100],
        });
        let c = cam.ray(100.0, 50.0);
        assert!((c.dir - Vec3::NEG_Z).length() < 1e-6);
        // Top edge at 45° up; right edge at atan(2) because the image is twice as wide.
        let top = cam.ray(100.0, 0.0).dir;
        assert!((top.y - top.z.abs()).abs() < 1e-5 && top.y > 0.0);
        let right = cam.ray(200.0, 50.0).dir;
        assert!((right.x / right.z.abs() - 2.0).abs() < 1e-5);
    }
}
