//! Encoded frames, made once per (image, format, exposure) and shared by every HTTP client and
//! WebSocket subscriber that asks for the same one (docs/architecture.md, "Publish"). An image is
//! named by the tick that made it, so the frames of a view at rest (whose ticks reuse the last
//! image) share one encoding and one ETag.
//!
//! A session keeps the last [`EncodedFrames::CAPACITY`] encodings. Two requests for the same
//! key at once encode it once: the second waits for the first's result. Each encoding carries
//! a strong ETag naming its key, so an HTTP client that already holds it gets 304.
use super::metrics::Metrics;
use super::worker::PublishedFrame;
use crate::film::{encode, ImageFormat};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, OnceLock};

/// Which encoding of which frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EncodingKey {
    /// The tick that made the image: the frame's `image_tick`, or `denoised_tick` for its
    /// denoised image.
    pub image_tick: u64,
    pub accumulation_id: u64,
    pub format: ImageFormat,
    /// The raw image of a denoising session rather than the denoised one.
    pub raw: bool,
    /// Stops, for the 8-bit formats (compared bit for bit).
    pub exposure: f32,
}

impl EncodingKey {
    pub fn new(frame: &PublishedFrame, format: ImageFormat, raw: bool, exposure: f32) -> EncodingKey {
        // A session without a denoised image has one image: raw or not, the bytes are the same.
        let raw = raw && frame.denoised.is_some();
        let linear = matches!(format, ImageFormat::Exr | ImageFormat::F32);
        let exposure = if linear { 0.0 } else { exposure };
        let image_tick = if frame.denoised.is_some() && !raw { frame.denoised_tick } else { frame.image_tick };
        EncodingKey { image_tick, accumulation_id: frame.accumulation_id, format, raw, exposure }
    }

    /// A strong ETag: the same key always encodes to the same bytes.
    pub fn etag(&self) -> String {
        let image = if self.raw { "raw" } else { "shown" };
        format!(
            "\"t{}-a{}-{:?}-{image}-e{:08x}\"",
            self.image_tick,
            self.accumulation_id,
            self.format,
            self.exposure.to_bits()
        )
    }
}

type Slot = Arc<OnceLock<Result<Arc<Vec<u8>>, String>>>;

/// The last few encodings of one session's frames.
#[derive(Default)]
pub struct EncodedFrames {
    entries: Mutex<VecDeque<(EncodingKey, Slot)>>,
}

impl EncodedFrames {
    /// Encodings kept per session: a few formats and exposures of the newest ticks.
    pub const CAPACITY: usize = 8;

    /// The bytes of `frame` encoded as `key` says, encoding them only if no earlier call did.
    /// Blocking (it may encode, or wait for another caller's encoding): call from
    /// `spawn_blocking`.
    pub fn get(&self, frame: &PublishedFrame, key: EncodingKey, metrics: &Metrics) -> Result<Arc<Vec<u8>>, String> {
        let slot = {
            let mut entries = self.entries.lock().map_err(|_| "encoding cache lock poisoned".to_string())?;
            match entries.iter().find(|(k, _)| *k == key) {
                Some((_, slot)) => slot.clone(),
                None => {
                    if entries.len() == Self::CAPACITY {
                        entries.pop_front();
                    }
                    let slot = Slot::default();
                    entries.push_back((key, slot.clone()));
                    slot
                }
            }
        };
        slot.get_or_init(|| {
            let t = std::time::Instant::now();
            let bytes = encode(frame.shown(key.raw), key.format, key.exposure).map(Arc::new).map_err(|e| e.to_string());
            metrics.observe_encode(t.elapsed().as_secs_f64());
            bytes
        })
        .clone()
    }
}
