//! Encoding: PNG and JPEG as 8-bit sRGB after exposure; EXR as linear f32 with ZIP compression,
//! which every EXR reader supports (not PIZ).
use super::image::LinearImage;
use std::path::Path;
use thiserror::Error;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    Png,
    Jpeg,
    Exr,
    /// Raw linear radiance: little-endian f32 R, G, B per pixel, rows from the top, no header
    /// (the size travels beside it), for clients that compute on frames (numpy).
    F32,
}

#[derive(Debug, Error)]
pub enum EncodeError {
    #[error("unsupported image extension '{0}' (use .png, .jpg, .exr or .f32)")]
    UnknownFormat(String),
    #[error("encoding {format:?}: {message}")]
    Encode { format: ImageFormat, message: String },
    #[error("writing {path}: {message}")]
    Io { path: String, message: String },
}

impl ImageFormat {
    pub fn from_extension(ext: &str) -> Result<ImageFormat, EncodeError> {
        match ext.to_ascii_lowercase().as_str() {
            "png" => Ok(ImageFormat::Png),
            "jpg" | "jpeg" => Ok(ImageFormat::Jpeg),
            "exr" => Ok(ImageFormat::Exr),
            "f32" => Ok(ImageFormat::F32),
            other => Err(EncodeError::UnknownFormat(other.to_string())),
        }
    }

    pub fn from_path(path: &Path) -> Result<ImageFormat, EncodeError> {
        ImageFormat::from_extension(path.extension().and_then(|e| e.to_str()).unwrap_or(""))
    }

    pub fn mime(self) -> &'static str {
        match self {
            ImageFormat::Png => "image/png",
            ImageFormat::Jpeg => "image/jpeg",
            ImageFormat::Exr => "image/x-exr",
            ImageFormat::F32 => "application/octet-stream",
        }
    }
}

/// The exposure the service and `relume render` take, in stops either way: a factor of up to
/// 2^32 (about 4·10⁹) brighter or darker, beyond any useful view of an image.
pub const MAX_EXPOSURE_STOPS: f32 = 32.0;

/// Checks an exposure for the 8-bit formats: a finite number of stops within
/// ±[`MAX_EXPOSURE_STOPS`] (NaN would make every pixel NaN, then 0).
pub fn check_exposure(exposure_ev: f32) -> Result<(), String> {
    if exposure_ev.is_finite() && exposure_ev.abs() <= MAX_EXPOSURE_STOPS {
        Ok(())
    } else {
        Err(format!("{exposure_ev} is not a finite number of stops in [-{MAX_EXPOSURE_STOPS}, {MAX_EXPOSURE_STOPS}]"))
    }
}

/// Encodes an image into bytes. `exposure_ev` applies to the 8-bit formats only.
pub fn encode(img: &LinearImage, format: ImageFormat, exposure_ev: f32) -> Result<Vec<u8>, EncodeError> {
    let err = |message: String| EncodeError::Encode { format, message };
    let mut out = Vec::new();
    match format {
        ImageFormat::Png | ImageFormat::Jpeg => {
            let rgb = image::RgbImage::from_raw(img.width, img.height, img.to_srgb8(exposure_ev))
                .ok_or_else(|| err("pixel buffer does not match the image size".into()))?;
            let fmt = if format == ImageFormat::Png { image::ImageFormat::Png } else { image::ImageFormat::Jpeg };
            rgb.write_to(&mut std::io::Cursor::new(&mut out), fmt).map_err(|e| err(e.to_string()))?;
        }
        ImageFormat::Exr => {
            use exr::prelude::*;
            let (w, h) = (img.width as usize, img.height as usize);
            let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
                let p = img.pixels[pos.y() * w + pos.x()];
                (p.r, p.g, p.b)
            });
            let encoding = Encoding { compression: Compression::ZIP16, ..Encoding::FAST_LOSSLESS };
            let layer = Layer::new((w, h), LayerAttributes::named("rgb"), encoding, channels);
            Image::from_layer(layer)
                .write()
                .to_buffered(std::io::Cursor::new(&mut out))
                .map_err(|e| err(e.to_string()))?;
        }
        ImageFormat::F32 => {
            out.reserve(img.pixels.len() * 12);
            for p in &img.pixels {
                for c in [p.r, p.g, p.b] {
                    out.extend_from_slice(&c.to_le_bytes());
                }
            }
        }
    }
    Ok(out)
}

/// Encodes by the path's extension and writes the file.
pub fn write_image(img: &LinearImage, path: &Path, exposure_ev: f32) -> Result<(), EncodeError> {
    let bytes = encode(img, ImageFormat::from_path(path)?, exposure_ev)?;
    std::fs::write(path, bytes)
        .map_err(|e| EncodeError::Io { path: path.display().to_string(), message: e.to_string() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::Rgb;

    #[test]
    fn exr_round_trips_linear_values() {
        let mut img = LinearImage::new(3, 2);
        img.pixels[4] = Rgb::new(17.0, 0.001, 2.5);
        let bytes = encode(&img, ImageFormat::Exr, 0.0).unwrap();
        let dir = std::env::temp_dir().join(format!("relume-exr-{}.exr", std::process::id()));
        std::fs::write(&dir, &bytes).unwrap();
        let back = exr::prelude::read_first_rgba_layer_from_file(
            &dir,
            |res: exr::math::Vec2<usize>, _| vec![[0.0f32; 3]; res.width() * res.height()],
            |px: &mut Vec<[f32; 3]>, pos: exr::math::Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * 3 + pos.x()] = [r, g, b]
            },
        )
        .unwrap();
        std::fs::remove_file(&dir).ok();
        assert_eq!(back.layer_data.channel_data.pixels[4], [17.0, 0.001, 2.5]);
    }

    #[test]
    fn png_decodes_to_the_srgb_values() {
        let mut img = LinearImage::new(2, 1);
        img.pixels[1] = Rgb::new(1.0, 0.18, 0.0);
        let bytes = encode(&img, ImageFormat::Png, 0.0).unwrap();
        let dec = image::load_from_memory(&bytes).unwrap().to_rgb8();
        assert_eq!(dec.get_pixel(1, 0).0, [255, 118, 0]);
        assert!(ImageFormat::from_extension("tiff").is_err());
    }
}
