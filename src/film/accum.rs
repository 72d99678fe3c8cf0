//! Progressive accumulation: per pixel, the f64 sum of path contributions and the number of
//! paths, so that techniques that start a variable number of paths per pixel (path regeneration)
//! stay consistent: the ratio of sums converges to the pixel's expected radiance. Light-tracing
//! splats (`bdpt`'s t = 1) land on any pixel, so they sum separately, each pass's splats being
//! that pass's estimate, and resolve to their average over passes.
use super::image::LinearImage;
use crate::core::Rgb;
use rayon::prelude::*;

/// One pixel's running sums.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelAccum {
    pub sum: [f64; 3],
    /// Number of estimates added (paths, or 1 per pass for techniques that average themselves).
    pub count: f64,
}

impl PixelAccum {
    /// Adds one estimate's value (the count is the caller's: see `count`).
    pub fn add(&mut self, value: Rgb) {
        self.sum[0] += value.r as f64;
        self.sum[1] += value.g as f64;
        self.sum[2] += value.b as f64;
    }

    pub fn mean(&self) -> Rgb {
        if self.count <= 0.0 {
            return Rgb::BLACK;
        }
        let inv = 1.0 / self.count;
        Rgb::new((self.sum[0] * inv) as f32, (self.sum[1] * inv) as f32, (self.sum[2] * inv) as f32)
    }
}

/// The accumulation buffer of a session.
#[derive(Clone, Debug)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    pixels: Vec<PixelAccum>,
    /// Changes on every reset, so clients can tell a new accumulation from a continued one.
    pub accumulation_id: u64,
    /// Render passes accumulated since the last reset.
    pub passes: u32,
    /// Light-tracing splats: per pixel, the sum over passes of each pass's splatted estimate,
    /// so the splatted part of a pixel is `splats / passes`. Empty until a technique splats.
    splats: Vec<[f64; 3]>,
    /// Bumped by every method that may change a pixel or a splat.
    writes: u64,
}

/// What a film's image depends on: two equal versions of one film resolve to the same image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FilmVersion {
    writes: u64,
    passes: u32,
    accumulation_id: u64,
}

impl Film {
    /// Bytes a film holds per pixel.
    pub const BYTES_PER_PIXEL: u64 = std::mem::size_of::<PixelAccum>() as u64;
    /// Bytes the splat buffer adds per pixel once a technique splats.
    pub const SPLAT_BYTES_PER_PIXEL: u64 = std::mem::size_of::<[f64; 3]>() as u64;

    pub fn new(width: u32, height: u32) -> Film {
        Film {
            width,
            height,
            pixels: vec![PixelAccum::default(); (width * height) as usize],
            accumulation_id: 0,
            passes: 0,
            splats: Vec::new(),
            writes: 0,
        }
    }

    /// Discards the accumulation (something in the scene changed).
    pub fn reset(&mut self) {
        self.pixels.iter_mut().for_each(|p| *p = PixelAccum::default());
        self.splats.iter_mut().for_each(|s| *s = [0.0; 3]);
        self.accumulation_id += 1;
        self.passes = 0;
        self.writes += 1;
    }

    /// Restarts the accumulation of only the listed pixels, each with one estimate: for a
    /// technique that knows which pixels a change touched (the rest keep accumulating). A
    /// new accumulation id tells clients the image restarted; `passes` becomes 1, the fewest
    /// any pixel now holds.
    pub fn restart_pixels(&mut self, restarts: &[(u32, Rgb)]) {
        if restarts.is_empty() {
            return;
        }
        for &(index, value) in restarts {
            let mut p = PixelAccum { count: 1.0, ..PixelAccum::default() };
            p.add(value);
            self.pixels[index as usize] = p;
        }
        self.accumulation_id += 1;
        self.passes = 1;
        self.writes += 1;
    }

    /// Runs `f(first_pixel_index, chunk)` on consecutive chunks of `chunk_len` pixels in
    /// parallel and reduces what they return with `merge`. Chunks are fixed by index, so pixel
    /// values do not depend on scheduling.
    pub fn accumulate_chunks<T, F, M>(&mut self, chunk_len: usize, f: F, merge: M) -> T
    where
        T: Default + Send,
        F: Fn(usize, &mut [PixelAccum]) -> T + Sync + Send,
        M: Fn(T, T) -> T + Sync + Send,
    {
        self.writes += 1;
        self.pixels
            .par_chunks_mut(chunk_len.max(1))
            .enumerate()
            .map(|(i, chunk)| f(i * chunk_len, chunk))
            .reduce(T::default, merge)
    }

    /// Renders `spp` passes over the chunks of [`Film::accumulate_chunks`]: `f(pass,
    /// first_pixel_index, chunk)`, where `pass` counts the technique's passes since its last
    /// reset (`passes`, which keys its sample streams and is advanced here, as is the film's own
    /// count). A chunk runs all its passes in order within one task, so there is no barrier
    /// between passes and every pixel still sums its passes in pass order. Returns the merged
    /// figures of all passes.
    pub fn accumulate_passes<T, F, M>(&mut self, spp: u32, passes: &mut u64, chunk_len: usize, f: F, merge: M) -> T
    where
        T: Default + Send,
        F: Fn(u64, usize, &mut [PixelAccum]) -> T + Sync + Send,
        M: Fn(T, T) -> T + Sync + Send,
    {
        let first_pass = *passes;
        let total = self.accumulate_chunks(
            chunk_len,
            |first, chunk| {
                (first_pass..first_pass + u64::from(spp)).fold(T::default(), |t, pass| merge(t, f(pass, first, chunk)))
            },
            &merge,
        );
        *passes += u64::from(spp);
        self.passes += spp;
        total
    }

    pub fn pixels(&self) -> &[PixelAccum] {
        &self.pixels
    }

    /// Adds one pass's splats, (pixel index, value), each value already that pass's estimate
    /// for its pixel. The pass itself is counted by [`Film::accumulate_passes`].
    pub fn add_splats(&mut self, splats: &[(u32, Rgb)]) {
        if splats.is_empty() {
            return;
        }
        if self.splats.is_empty() {
            self.splats = vec![[0.0; 3]; self.pixels.len()];
        }
        self.writes += 1;
        for &(index, v) in splats {
            let s = &mut self.splats[index as usize];
            s[0] += v.r as f64;
            s[1] += v.g as f64;
            s[2] += v.b as f64;
        }
    }

    /// The film's version: it changes whenever its image may have.
    pub fn version(&self) -> FilmVersion {
        FilmVersion { writes: self.writes, passes: self.passes, accumulation_id: self.accumulation_id }
    }

    /// Bytes the splat buffer holds (0 until a technique splats).
    pub fn splat_bytes(&self) -> u64 {
        self.splats.len() as u64 * Film::SPLAT_BYTES_PER_PIXEL
    }

    /// Mean estimates per pixel (`count`-weighted average of what was added).
    pub fn mean_paths_per_pixel(&self) -> f64 {
        self.pixels.iter().map(|p| p.count).sum::<f64>() / self.pixels.len().max(1) as f64
    }

    /// The image: each pixel's mean, plus its splats averaged over the passes.
    pub fn resolve(&self) -> LinearImage {
        let mut pixels: Vec<Rgb> = self.pixels.iter().map(PixelAccum::mean).collect();
        if !self.splats.is_empty() && self.passes > 0 {
            let inv = 1.0 / self.passes as f64;
            for (p, s) in pixels.iter_mut().zip(&self.splats) {
                *p += Rgb::new((s[0] * inv) as f32, (s[1] * inv) as f32, (s[2] * inv) as f32);
            }
        }
        LinearImage { width: self.width, height: self.height, pixels }
    }
}
