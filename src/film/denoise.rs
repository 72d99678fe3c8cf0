//! The denoise stage: Intel Open Image Denoise (OIDN 2.x, its `RT` filter in HDR mode) on a
//! resolved linear image, optionally guided by first-hit albedo and normal images ([`AuxFilm`]).
//!
//! Units: the colour input is the film's radiance (HDR, unbounded, so `hdr` is on and OIDN
//! picks the input scale itself); albedo lies in [0, 1]; normals are world-space unit vectors,
//! or zero where no surface was hit (OIDN's convention for "no surface").
//!
//! Cost: a [`Denoiser`] creates its device, filter and buffers once and reuses them for every
//! image. OIDN's objects borrow their device and its API prefers one calling thread, so they
//! live together on one thread the denoiser owns; a call sends the image there and waits.
//! A panic inside OIDN ends that thread only: the call returns [`DenoiseError::Stopped`].
//!
//! Mean preservation: at 1 spp OIDN darkens the Cornell box by about 1.7% (it removes the
//! rare bright paths along with the noise). The denoised image is therefore rescaled, per
//! channel, so its mean equals the raw image's, whose expectation is the true mean; the factor
//! is clamped to [[`MIN_RESCALE`], [`MAX_RESCALE`]] so a single firefly in a raw frame cannot
//! brighten the whole image.
//!
//! Invariants: images passed to [`Denoiser::denoise`] have the size the denoiser was made for;
//! the raw image is never modified (the denoised one is a new image).
//!
//! Built without the `denoise` cargo feature, [`Denoiser::new`] fails with
//! [`DenoiseError::NotBuilt`], which callers report as a client error naming the feature.
use super::aux::AuxImages;
use super::image::LinearImage;
use crate::core::Rgb;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// OIDN's quality presets. `fast` suits interactive previews; `high` is OIDN's own default.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DenoiseQuality {
    Fast,
    Balanced,
    #[default]
    High,
}

impl DenoiseQuality {
    pub const NAMES: &'static [&'static str] = &["fast", "balanced", "high"];

    pub fn parse(name: &str) -> Option<DenoiseQuality> {
        match name {
            "fast" => Some(DenoiseQuality::Fast),
            "balanced" => Some(DenoiseQuality::Balanced),
            "high" => Some(DenoiseQuality::High),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            DenoiseQuality::Fast => "fast",
            DenoiseQuality::Balanced => "balanced",
            DenoiseQuality::High => "high",
        }
    }
}

/// Bounds of the per-channel factor that gives the denoised image the raw image's mean.
pub const MIN_RESCALE: f64 = 0.8;
pub const MAX_RESCALE: f64 = 1.25;

/// What a session asks of the denoise stage: `{"quality": "high", "aux": true}`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DenoiseSettings {
    /// Default `high`.
    #[serde(default)]
    pub quality: DenoiseQuality,
    /// Guide the filter with first-hit albedo and normal images. Default `true`.
    #[serde(default = "yes")]
    pub aux: bool,
}

fn yes() -> bool {
    true
}

impl DenoiseSettings {
    /// Bytes the stage holds at `pixels` pixels: OIDN's filter, its scratch tensors and
    /// buffers, and the auxiliary film. Measured with `relume render --denoise=high` (maximum
    /// resident set, against the same render without it): +51 MB at 256², +711 MB at 1024²,
    /// so about 680 bytes a pixel, plus the last output kept for unchanged ticks (12 bytes);
    /// rounded up here.
    pub fn resident_estimate(&self, pixels: u64) -> u64 {
        (32 << 20) + pixels.saturating_mul(768)
    }
}

impl Default for DenoiseSettings {
    fn default() -> Self {
        DenoiseSettings { quality: DenoiseQuality::default(), aux: true }
    }
}

#[derive(Debug, Error, Clone, PartialEq)]
pub enum DenoiseError {
    #[error("denoise: this relume was built without the `denoise` cargo feature (Open Image Denoise)")]
    NotBuilt,
    #[error("denoise: Open Image Denoise could not start ({0}); scripts/setup.sh installs it into .deps/oidn/lib")]
    Unavailable(String),
    #[error("denoise: {0}")]
    Failed(String),
    #[error("denoise: the denoiser thread stopped")]
    Stopped,
}

/// One image's worth of planar f32 RGB, sent to the denoiser thread and back.
struct Job {
    color: Vec<f32>,
    aux: Option<(Vec<f32>, Vec<f32>)>,
}

/// A denoiser for images of one size, with its OIDN objects on a thread of its own.
pub struct Denoiser {
    settings: DenoiseSettings,
    width: u32,
    height: u32,
    jobs: Option<std::sync::mpsc::Sender<Job>>,
    done: std::sync::mpsc::Receiver<Result<Vec<f32>, DenoiseError>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Denoiser {
    /// Starts OIDN's CPU device and a filter for `width`×`height` images, and waits until they
    /// are ready (the first filter commit loads the network's weights).
    pub fn new(settings: DenoiseSettings, width: u32, height: u32) -> Result<Denoiser, DenoiseError> {
        let (jobs, job_rx) = std::sync::mpsc::channel::<Job>();
        let (done_tx, done) = std::sync::mpsc::channel();
        let (ready_tx, ready) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("relume-denoise".into())
            .spawn(move || oidn_worker::run(settings, width as usize, height as usize, job_rx, done_tx, ready_tx))
            .map_err(|e| DenoiseError::Unavailable(e.to_string()))?;
        let mut denoiser = Denoiser { settings, width, height, jobs: Some(jobs), done, thread: Some(thread) };
        match ready.recv() {
            Ok(Ok(())) => Ok(denoiser),
            Ok(Err(e)) => Err(e),
            Err(_) => {
                denoiser.jobs = None;
                Err(DenoiseError::Stopped)
            }
        }
    }

    pub fn settings(&self) -> DenoiseSettings {
        self.settings
    }

    /// Whether denoising can start here: makes and drops a tiny denoiser, so a missing OIDN
    /// library is reported when the service starts rather than at the first session.
    pub fn probe() -> Result<(), DenoiseError> {
        Denoiser::new(DenoiseSettings { quality: DenoiseQuality::Fast, aux: false }, 8, 8).map(drop)
    }

    /// The denoised copy of `image`. When the settings ask for auxiliary images, `aux` brings
    /// new ones; `None` keeps those of the last call (OIDN's buffers still hold them), so
    /// unchanged images are not copied again.
    pub fn denoise(&mut self, image: &LinearImage, aux: Option<AuxImages>) -> Result<LinearImage, DenoiseError> {
        if image.width != self.width || image.height != self.height {
            return Err(DenoiseError::Failed(format!(
                "image is {}x{}, the denoiser was made for {}x{}",
                image.width, image.height, self.width, self.height
            )));
        }
        let color = image.pixels.iter().flat_map(|p| p.to_array()).collect();
        let aux = aux.filter(|_| self.settings.aux).map(|a| (a.albedo, a.normal));
        let jobs = self.jobs.as_ref().ok_or(DenoiseError::Stopped)?;
        jobs.send(Job { color, aux }).map_err(|_| DenoiseError::Stopped)?;
        let out = self.done.recv().map_err(|_| DenoiseError::Stopped)??;
        let pixels = out.chunks_exact(3).map(|c| Rgb::new(c[0], c[1], c[2])).collect();
        let mut denoised = LinearImage { width: self.width, height: self.height, pixels };
        preserve_mean(image, &mut denoised);
        Ok(denoised)
    }
}

/// Rescales `denoised` per channel so its mean is `raw`'s (within the clamp; a channel whose
/// denoised mean is not positive is left as it is).
fn preserve_mean(raw: &LinearImage, denoised: &mut LinearImage) {
    let (want, got) = (raw.mean().to_array(), denoised.mean().to_array());
    let factor: [f32; 3] = std::array::from_fn(|c| {
        if got[c] > 0.0 && want[c].is_finite() {
            (want[c] as f64 / got[c] as f64).clamp(MIN_RESCALE, MAX_RESCALE) as f32
        } else {
            1.0
        }
    });
    for p in &mut denoised.pixels {
        *p = Rgb::new(p.r * factor[0], p.g * factor[1], p.b * factor[2]);
    }
}

impl Drop for Denoiser {
    fn drop(&mut self) {
        // Closing the job channel ends the worker's loop; it then releases OIDN's objects.
        self.jobs = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(feature = "denoise")]
mod oidn_worker {
    use super::{DenoiseError, DenoiseQuality, DenoiseSettings, Job};
    use std::sync::mpsc::{Receiver, Sender};

    fn quality(q: DenoiseQuality) -> oidn::Quality {
        match q {
            DenoiseQuality::Fast => oidn::Quality::Fast,
            DenoiseQuality::Balanced => oidn::Quality::Balanced,
            DenoiseQuality::High => oidn::Quality::High,
        }
    }

    fn failed(e: oidn::Error) -> DenoiseError {
        DenoiseError::Failed(format!("{:?}: {}", e.kind(), e.message()))
    }

    /// The denoiser thread: makes the device, filter and buffers, reports readiness, then
    /// filters each job until the job channel closes.
    pub(super) fn run(
        settings: DenoiseSettings,
        width: usize,
        height: usize,
        jobs: Receiver<Job>,
        done: Sender<Result<Vec<f32>, DenoiseError>>,
        ready: Sender<Result<(), DenoiseError>>,
    ) {
        let device = match oidn::Device::cpu() {
            Ok(d) => d,
            Err(e) => {
                let _ = ready.send(Err(DenoiseError::Unavailable(format!("{:?}: {}", e.kind(), e.message()))));
                return;
            }
        };
        let zeros = vec![0.0f32; width * height * 3];
        let setup = || -> Result<_, oidn::Error> {
            let mut filter = oidn::RayTracing::try_new(&device)?;
            filter.hdr(true).image_dimensions(width, height).filter_quality(quality(settings.quality));
            let color = device.create_buffer(&zeros)?;
            let output = device.create_buffer(&zeros)?;
            if settings.aux {
                filter.albedo_normal(&zeros, &zeros);
            }
            // Commit once now, so the first frame does not pay for loading the weights.
            filter.filter_buffer(&color, &output)?;
            Ok((filter, color, output))
        };
        let (mut filter, color, output) = match setup() {
            Ok(s) => s,
            Err(e) => {
                let _ = ready.send(Err(failed(e)));
                return;
            }
        };
        if ready.send(Ok(())).is_err() {
            return;
        }
        for job in jobs {
            let result = (|| -> Result<Vec<f32>, oidn::Error> {
                let mut out = job.color;
                color.write(&out)?;
                if let Some((albedo, normal)) = &job.aux {
                    filter.albedo_normal(albedo, normal);
                }
                filter.filter_buffer(&color, &output)?;
                output.read_to_slice(&mut out)?;
                Ok(out)
            })();
            if done.send(result.map_err(failed)).is_err() {
                return;
            }
        }
    }
}

#[cfg(not(feature = "denoise"))]
mod oidn_worker {
    use super::{DenoiseError, DenoiseSettings, Job};
    use std::sync::mpsc::{Receiver, Sender};

    /// Without OIDN: reports that it cannot start, and answers any job the same way.
    pub(super) fn run(
        _: DenoiseSettings,
        _: usize,
        _: usize,
        jobs: Receiver<Job>,
        done: Sender<Result<Vec<f32>, DenoiseError>>,
        ready: Sender<Result<(), DenoiseError>>,
    ) {
        let _ = ready.send(Err(DenoiseError::NotBuilt));
        for Job { color, aux } in jobs {
            drop((color, aux));
            let _ = done.send(Err(DenoiseError::NotBuilt));
        }
    }
}
