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

    /// Where a ray from the camera to `p` crosses the film: (`x`, `y`) in pixels as
    /// [`Camera::ray`] takes them, and the cosine between that ray and the view axis. `None`
    /// behind the camera or outside the image.
    pub fn raster(&self, p: Vec3) -> Option<(f32, f32, f32)> {
        let (x, y) = self.film_point(p)?;
        let d = p - self.position;
        let inside = (0.0..self.width as f32).contains(&x) && (0.0..self.height as f32).contains(&y);
        inside.then(|| (x, y, d.dot(self.forward) / d.length()))
    }

    /// Where a ray from the camera to `p` crosses the film plane, in pixels as [`Camera::ray`]
    /// takes them (inside the image or not); `None` when `p` is not in front of the camera.
    pub fn film_point(&self, p: Vec3) -> Option<(f32, f32)> {
        let d = p - self.position;
        let depth = d.dot(self.forward);
        if depth <= 0.0 || d.length() == 0.0 {
            return None;
        }
        let aspect = self.width as f32 / self.height as f32;
        let sx = d.dot(self.right) / depth / (self.tan_half_vfov * aspect);
        let sy = d.dot(self.up) / depth / self.tan_half_vfov;
        Some(((sx + 1.0) * 0.5 * self.width as f32, (1.0 - sy) * 0.5 * self.height as f32))
    }

    /// Area of the image on the plane one unit in front of the pinhole.
    pub fn film_area(&self) -> f32 {
        let aspect = self.width as f32 / self.height as f32;
        4.0 * self.tan_half_vfov * self.tan_half_vfov * aspect
    }

    /// Solid-angle density of a primary ray through a uniformly chosen point of the whole
    /// image, at cosine `cos` to the view axis: 1 / (film area · cos³), since a point on the
    /// unit-distance plane lies 1/cos away and its area projects by cos.
    pub fn pdf_direction(&self, cos: f32) -> f32 {
        if cos <= 0.0 {
            return 0.0;
        }
        1.0 / (self.film_area() * cos * cos * cos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera with +Y up.
    fn camera(position: [f32; 3], look_at: [f32; 3], vfov_deg: f32, resolution: [u32; 2]) -> Camera {
        Camera::from_desc(&CameraDesc { position, look_at, up: [0.0, 1.0, 0.0], vfov_deg, resolution })
    }

    #[test]
    fn centre_and_corners() {
        let cam = camera([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], 90.0, [200, 100]);
        let c = cam.ray(100.0, 50.0);
        assert!((c.dir - Vec3::NEG_Z).length() < 1e-6);
        // Top edge at 45° up; right edge at atan(2) because the image is twice as wide.
        let top = cam.ray(100.0, 0.0).dir;
        assert!((top.y - top.z.abs()).abs() < 1e-5 && top.y > 0.0);
        let right = cam.ray(200.0, 50.0).dir;
        assert!((right.x / right.z.abs() - 2.0).abs() < 1e-5);
    }

    #[test]
    fn raster_inverts_ray() {
        let cam = camera([1.0, 2.0, 3.0], [0.0, 0.5, -1.0], 50.0, [64, 48]);
        for (x, y) in [(0.5, 0.5), (10.25, 40.75), (63.5, 1.0), (32.0, 24.0)] {
            let r = cam.ray(x, y);
            let (rx, ry, cos) = cam.raster(r.origin + r.dir * 7.0).unwrap();
            assert!((rx - x).abs() < 1e-3 && (ry - y).abs() < 1e-3, "({x}, {y}) -> ({rx}, {ry})");
            assert!((cos - r.dir.dot(cam.forward)).abs() < 1e-6);
        }
        assert!(cam.raster(cam.position - cam.forward).is_none(), "behind the camera");
        let outside = cam.ray(-1.0, 10.0);
        assert!(cam.raster(outside.origin + outside.dir).is_none(), "left of the image");
    }

    #[test]
    fn the_direction_density_integrates_to_one_over_the_image() {
        // Monte Carlo over the whole sphere of directions: 4π · E[pdf · inside] = 1, with the
        // image's solid angle found by `raster`, not by the cos³ the density assumes.
        let cam = camera([0.0; 3], [0.0, 0.0, -1.0], 70.0, [40, 30]);
        let mut rng = crate::core::Rng::new(7, 0);
        let n = 400_000;
        let (mut total, mut one_cosine_short) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let dir = crate::core::sampling::uniform_sphere(rng.next_2d());
            if let Some((_, _, cos)) = cam.raster(dir) {
                total += cam.pdf_direction(cos) as f64;
                one_cosine_short += (cam.pdf_direction(cos) * cos) as f64;
            }
        }
        let scale = 4.0 * std::f64::consts::PI / n as f64;
        let (integral, control) = (total * scale, one_cosine_short * scale);
        assert!((integral - 1.0).abs() < 0.02, "{integral}");
        // Negative control: a density falling as 1/cos² (missing one cosine) fails the bound.
        assert!((control - 1.0).abs() > 0.02, "{control}");
    }
}
