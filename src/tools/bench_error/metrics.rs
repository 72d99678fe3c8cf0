//! Image error against a reference, all computed on linear radiance unless noted:
//! - relMSE = mean over pixels and channels of (x − r)² / (r² + ε), ε = 0.01;
//! - RMSE = √(mean (x − r)²);
//! - mean bias: the image mean's relative gap to the reference's, Σx / Σr − 1, for the channel
//!   where it is largest in magnitude (signed: negative is too dark);
//! - PSNR (dB) of the tonemapped images (the 8-bit sRGB the service serves, clamped at 1);
//! - LDR-FLIP (Andersson et al. 2020, through the `nv-flip` crate) of those 8-bit images,
//!   at 67 pixels per degree;
//! - HDR-FLIP (Andersson et al. 2021, §4): the per-pixel maximum of LDR-FLIP over a range of
//!   exposures, from the one that maps the reference's brightest pixel to 1 to the one that maps
//!   its median to 1, one stop apart (at least two). The tone mapper is the service's sRGB
//!   clamp rather than the paper's ACES fit, so the figures are comparable within relume.
use crate::film::LinearImage;
use nv_flip::{FlipImageFloat, FlipImageRgb8, DEFAULT_PIXELS_PER_DEGREE};
use serde::Serialize;

/// ε of relMSE's denominator.
pub const REL_MSE_EPSILON: f64 = 0.01;

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ImageError {
    pub rel_mse: f64,
    pub rmse: f64,
    pub psnr_db: f64,
    pub flip_ldr: f64,
    pub flip_hdr: f64,
    pub mean_bias: f64,
}

/// The error of `test` against `reference` (same size), and the HDR-FLIP error map.
pub fn compare(test: &LinearImage, reference: &LinearImage) -> (ImageError, FlipImageFloat) {
    let (mut rel, mut sq) = (0.0f64, 0.0f64);
    let (mut sum_test, mut sum_ref) = ([0.0f64; 3], [0.0f64; 3]);
    for (x, r) in test.pixels.iter().zip(&reference.pixels) {
        for (c, (a, b)) in x.to_array().iter().zip(r.to_array()).enumerate() {
            let d = (*a as f64) - b as f64;
            rel += d * d / ((b as f64) * (b as f64) + REL_MSE_EPSILON);
            sq += d * d;
            sum_test[c] += *a as f64;
            sum_ref[c] += b as f64;
        }
    }
    let mean_bias = (0..3)
        .map(|c| if sum_ref[c] > 0.0 { sum_test[c] / sum_ref[c] - 1.0 } else { 0.0 })
        .fold(0.0f64, |worst, g| if g.abs() > worst.abs() { g } else { worst });
    let n = (test.pixels.len() * 3).max(1) as f64;
    let (t8, r8) = (test.to_srgb8(0.0), reference.to_srgb8(0.0));
    let mse8: f64 = t8.iter().zip(&r8).map(|(a, b)| ((*a as f64 - *b as f64) / 255.0).powi(2)).sum::<f64>() / n;
    let psnr_db = if mse8 > 0.0 { 10.0 * (1.0 / mse8).log10() } else { f64::INFINITY };
    let ldr = flip_map(test, reference, 0.0);
    let hdr = hdr_flip_map(test, reference);
    let error = ImageError {
        rel_mse: rel / n,
        rmse: (sq / n).sqrt(),
        psnr_db,
        flip_ldr: mean(&ldr),
        flip_hdr: mean(&hdr),
        mean_bias,
    };
    (error, hdr)
}

fn mean(map: &FlipImageFloat) -> f64 {
    let v = map.to_vec();
    v.iter().map(|&x| x as f64).sum::<f64>() / v.len().max(1) as f64
}

fn flip_map(test: &LinearImage, reference: &LinearImage, exposure_ev: f32) -> FlipImageFloat {
    let (w, h) = (reference.width, reference.height);
    let r = FlipImageRgb8::with_data(w, h, &reference.to_srgb8(exposure_ev));
    let t = FlipImageRgb8::with_data(w, h, &test.to_srgb8(exposure_ev));
    nv_flip::flip(r, t, DEFAULT_PIXELS_PER_DEGREE)
}

/// The exposures (stops) HDR-FLIP evaluates for a reference.
pub fn hdr_exposures(reference: &LinearImage) -> Vec<f32> {
    let mut lum: Vec<f32> = reference.pixels.iter().map(|p| p.luminance().max(0.0)).collect();
    lum.sort_by(f32::total_cmp);
    let floor = 1e-6f32;
    let max = lum.last().copied().unwrap_or(1.0).max(floor);
    let median = lum.get(lum.len() / 2).copied().unwrap_or(1.0).max(floor);
    let (start, stop) = (-max.log2(), -median.log2());
    let steps = ((stop - start).ceil() as usize).max(1);
    (0..=steps).map(|i| start + (stop - start) * i as f32 / steps as f32).collect()
}

fn hdr_flip_map(test: &LinearImage, reference: &LinearImage) -> FlipImageFloat {
    let mut worst: Vec<f32> = vec![0.0; reference.pixels.len()];
    for ev in hdr_exposures(reference) {
        for (w, e) in worst.iter_mut().zip(flip_map(test, reference, ev).to_vec()) {
            *w = w.max(e);
        }
    }
    FlipImageFloat::with_data(reference.width, reference.height, &worst)
}

/// The error map in FLIP's magma colours, as 8-bit RGB.
pub fn false_colour(map: &FlipImageFloat) -> Vec<u8> {
    map.apply_color_lut(&nv_flip::magma_lut()).to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::Rgb;

    fn image(v: f32) -> LinearImage {
        LinearImage { width: 16, height: 16, pixels: vec![Rgb::splat(v); 256] }
    }

    #[test]
    fn identical_images_have_no_error_and_known_offsets_have_known_error() {
        let (e, _) = compare(&image(0.5), &image(0.5));
        assert_eq!((e.rel_mse, e.rmse, e.flip_ldr, e.flip_hdr), (0.0, 0.0, 0.0, 0.0));
        assert!(e.psnr_db.is_infinite());
        let (e, _) = compare(&image(0.6), &image(0.5));
        assert!((e.rmse - 0.1).abs() < 1e-6);
        assert!((e.rel_mse - 0.01 / (0.25 + REL_MSE_EPSILON)).abs() < 1e-6);
        assert!((e.mean_bias - 0.2).abs() < 1e-6, "0.6 against 0.5 is 20% bright: {e:?}");
        assert!(e.flip_ldr > 0.0, "{e:?}");
        // The mean bias is signed and takes the worst channel: only blue is 10% dark here.
        let dim_blue = LinearImage { pixels: vec![Rgb::new(0.5, 0.5, 0.45); 256], ..image(0.5) };
        assert!((compare(&dim_blue, &image(0.5)).0.mean_bias + 0.1).abs() < 1e-6);
        // HDR-FLIP looks through the exposures of the reference: a 30% change shows at each.
        let mut reference = image(0.25);
        reference.pixels[..128].iter_mut().for_each(|p| *p = Rgb::splat(4.0));
        let brighter = LinearImage { pixels: reference.pixels.iter().map(|p| *p * 1.3).collect(), ..reference.clone() };
        let (e, map) = compare(&brighter, &reference);
        assert!(e.flip_hdr > 0.0 && e.flip_hdr <= 1.0, "{e:?}");
        assert_eq!(false_colour(&map).len(), 16 * 16 * 3);
    }

    #[test]
    fn hdr_exposures_span_brightest_to_median() {
        let mut img = image(0.25);
        img.pixels[0] = Rgb::splat(4.0);
        let ev = hdr_exposures(&img);
        assert_eq!(ev.first().copied(), Some(-2.0));
        assert_eq!(ev.last().copied(), Some(2.0));
        assert_eq!(ev.len(), 5);
    }
}
