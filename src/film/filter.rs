//! An edge-preserving bilateral filter for noisy previews (Tomasi and Manduchi 1998), as Novák
//! et al. (2010, §4) offer while the image is still converging. It biases the image: previews only.
use super::image::LinearImage;
use crate::core::Rgb;
use rayon::prelude::*;

/// Filters with a Gaussian of `sigma_spatial` pixels and a range Gaussian of `sigma_range` in
/// relative luminance difference (`|ΔY| / (Y_centre + 1e-3)`), over a (2r+1)² window, r = ⌈2σ⌉.
pub fn bilateral_filter(img: &LinearImage, sigma_spatial: f32, sigma_range: f32) -> LinearImage {
    let r = (2.0 * sigma_spatial).ceil() as i32;
    let (w, h) = (img.width as i32, img.height as i32);
    let inv_s = -0.5 / (sigma_spatial * sigma_spatial);
    let inv_r = -0.5 / (sigma_range * sigma_range);
    let pixels = (0..h * w)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let c = img.pixels[i as usize];
            let yc = c.luminance();
            let mut acc = Rgb::BLACK;
            let mut wsum = 0.0;
            for dy in -r..=r {
                for dx in -r..=r {
                    let (sx, sy) = (x + dx, y + dy);
                    if sx < 0 || sy < 0 || sx >= w || sy >= h {
                        continue;
                    }
                    let p = img.pixels[(sy * w + sx) as usize];
                    let dr = (p.luminance() - yc) / (yc + 1e-3);
                    let wt = ((dx * dx + dy * dy) as f32 * inv_s + dr * dr * inv_r).exp();
                    acc += p * wt;
                    wsum += wt;
                }
            }
            acc / wsum
        })
        .collect();
    LinearImage { width: img.width, height: img.height, pixels }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_a_step_edge_and_smooths_noise() {
        let mut img = LinearImage::new(16, 8);
        for y in 0..8 {
            for x in 0..16 {
                let base = if x < 8 { 0.1 } else { 1.0 };
                let noise = if (x + y) % 2 == 0 { 1.1 } else { 0.9 };
                img.pixels[(y * 16 + x) as usize] = Rgb::splat(base * noise);
            }
        }
        let out = bilateral_filter(&img, 1.5, 0.3);
        // The edge survives: left stays dark, right stays bright.
        assert!(out.get(6, 4).r < 0.15 && out.get(9, 4).r > 0.85);
        // Noise shrinks away from the edge.
        assert!((out.get(3, 4).r - 0.1).abs() < (img.get(3, 4).r - 0.1).abs());
    }
}
