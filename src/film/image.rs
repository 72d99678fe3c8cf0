//! A linear RGB image and its tonemapping to 8-bit sRGB.
use crate::core::Rgb;

/// Linear radiance per pixel, row-major from the top-left.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Rgb>,
}

/// The sRGB opto-electronic transfer function for a value in [0, 1].
pub fn srgb_encode(linear: f32) -> f32 {
    if linear <= 0.003_130_8 {
        12.92 * linear
    } else {
        1.055 * linear.powf(1.0 / 2.4) - 0.055
    }
}

impl LinearImage {
    pub fn new(width: u32, height: u32) -> LinearImage {
        LinearImage { width, height, pixels: vec![Rgb::BLACK; (width * height) as usize] }
    }

    pub fn get(&self, x: u32, y: u32) -> Rgb {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Mean of all pixels, per channel (f64 sum).
    pub fn mean(&self) -> Rgb {
        let mut s = [0.0f64; 3];
        for p in &self.pixels {
            s[0] += p.r as f64;
            s[1] += p.g as f64;
            s[2] += p.b as f64;
        }
        let n = self.pixels.len().max(1) as f64;
        Rgb::new((s[0] / n) as f32, (s[1] / n) as f32, (s[2] / n) as f32)
    }

    /// 8-bit sRGB after multiplying by 2^`exposure_ev` and clamping to [0, 1].
    pub fn to_srgb8(&self, exposure_ev: f32) -> Vec<u8> {
        let scale = exposure_ev.exp2();
        let mut out = Vec::with_capacity(self.pixels.len() * 3);
        for p in &self.pixels {
            for c in p.to_array() {
                let v = srgb_encode((c * scale).clamp(0.0, 1.0));
                out.push((v * 255.0 + 0.5) as u8);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_endpoints_and_midpoint() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        // 18% grey encodes to about 46% (118/255).
        assert!((srgb_encode(0.18) * 255.0 - 117.7).abs() < 1.0);
    }
}
