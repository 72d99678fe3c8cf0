//! The film: progressive accumulation, resolve to a linear image, tonemapping and encoding.
//!
//! Units: pixel values are radiance (W/(sr·m²)), linear Rec.709. The sRGB transfer function is
//! applied only when encoding 8-bit formats; EXR stays linear. Accumulation is in f64 so a film
//! can run for hours without losing small contributions. The auxiliary images (albedo, normal)
//! and the OIDN denoiser live here too; the engine decides when they run.
mod accum;
mod aux;
mod denoise;
mod encode;
mod filter;
mod image;

pub use accum::{Film, FilmVersion, PixelAccum};
pub use aux::{AuxFilm, AuxImages, AuxSample};
pub use denoise::{DenoiseError, DenoiseQuality, DenoiseSettings, Denoiser};
pub use encode::{check_exposure, encode, write_image, EncodeError, ImageFormat};
pub use filter::bilateral_filter;
pub use image::LinearImage;
