//! The engine: a [`Session`] owns a scene, its Embree scenes, a technique and a film, and runs
//! the tick pipeline (docs/architecture.md, "The tick"):
//!
//! 1. **Drain** the queue of client edits.
//! 2. **Apply** them to the scene model → [`SceneDelta`] (latest edit per target wins; the
//!    coalesced count is reported). An edit that leaves its target as it was is no change: it
//!    is counted (`edits_unchanged`) and resets, commits and invalidates nothing.
//! 3. **Commit** only the moved instances to Embree's top-level scene.
//! 4. **Update** the technique with the delta (verify / invalidate / retrace); the film is reset
//!    when anything changed, unless the technique restarts only the pixels the change touched.
//! 5. **Render** on rayon.
//! 6. **Resolve** the film into a linear image; encoding happens where the frame is consumed.
//!    A film unchanged since the last tick ([`Film::version`]) is not resolved again: the last
//!    image stands, shared (`resolve_reused`).
//! 7. **Denoise**, when the session asks for it ([`Session::set_denoise`]): OIDN on the
//!    resolved image, guided by auxiliary images ([`DenoiseStage`]); the raw image stays in the
//!    frame beside the denoised one. A film unchanged since the last tick ([`Film::version`])
//!    is not denoised again: the last output stands (`denoise_reused`).
//!
//! A session can switch technique between ticks ([`Session::set_technique`]): the scene keeps its
//! edits and the queue its pending ones, the new technique is built fresh, and the next tick
//! restarts the film, as a snapshot restored with that technique would. Denoising can start,
//! stop or change quality between ticks too ([`Session::set_denoise`]); the film goes on. A
//! switch to what is already running changes nothing.
//!
//! Nothing traces while Embree commits: the phases run in order inside one session. The engine
//! never touches tokio or axum; callers run `tick` on a rayon pool made by [`thread_pool`].
mod denoise;
mod stats;

pub use denoise::{AuxWork, DenoiseStage};
pub use stats::{PhaseTimes, TickStats};

use crate::embree::{self, Device, EmbreeError};
use crate::film::{bilateral_filter, DenoiseError, DenoiseSettings, Film, FilmVersion, LinearImage};
use crate::scene::edits::{self, Edit, SceneDelta};
use crate::scene::{Scene, SceneAccel, SceneError};
use crate::technique::{self, RenderContext, Technique, TechniqueConfig, TechniqueError};
use std::sync::Arc;
use std::time::Instant;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum EngineError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Embree(#[from] EmbreeError),
    #[error(transparent)]
    Technique(#[from] TechniqueError),
    #[error(transparent)]
    Denoise(#[from] DenoiseError),
    #[error("thread pool: {0}")]
    ThreadPool(String),
}

/// A rendered frame: the resolved image and the stats of the tick that made it.
#[derive(Clone, Debug)]
pub struct Frame {
    pub tick: u64,
    pub accumulation_id: u64,
    /// Render passes accumulated since the last reset.
    pub spp: u32,
    /// The raw resolved image (shared with the session while the film stays as it is).
    pub image: Arc<LinearImage>,
    /// The tick that resolved `image`: this one, or an earlier one when the film has not
    /// changed since (so frames with the same `image_tick` show the same image).
    pub image_tick: u64,
    /// The denoised image, when the session denoises (shared with the denoise stage while the
    /// film stays as it is).
    pub denoised: Option<Arc<LinearImage>>,
    /// The tick that denoised `denoised` (as `image_tick` is for `image`).
    pub denoised_tick: u64,
    pub stats: TickStats,
}

impl Frame {
    /// The image a client sees: the denoised one when there is one, unless `raw` is asked for.
    pub fn shown(&self, raw: bool) -> &LinearImage {
        match &self.denoised {
            Some(d) if !raw => d,
            _ => &self.image,
        }
    }
}

/// A rayon pool whose workers flush denormals to zero, as Embree asks.
pub fn thread_pool(threads: usize) -> Result<rayon::ThreadPool, EngineError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("relume-worker-{i}"))
        .start_handler(|_| embree::flush_denormals_to_zero())
        .build()
        .map_err(|e| EngineError::ThreadPool(e.to_string()))
}

/// What the resolve step makes of a film: its image, shared by the frames that show it, the
/// mean paths per pixel, and the tick that resolved them.
#[derive(Clone)]
struct Resolved {
    image: Arc<LinearImage>,
    paths_per_pixel: f64,
    tick: u64,
}

/// One scene, its light transport and its film, ticking.
pub struct Session {
    scene: Scene,
    accel: SceneAccel,
    technique: Box<dyn Technique>,
    config: TechniqueConfig,
    film: Film,
    seed: u64,
    tick: u64,
    /// Queued edits, already coalesced (latest per target), so the queue never holds more
    /// entries than the scene has targets.
    pending: Vec<Edit>,
    /// Edits received into `pending` since the last tick, before coalescing.
    pending_received: usize,
    /// Sequence number of the last accepted edit batch (the first is 1).
    accepted_batches: u64,
    denoise: Option<DenoiseStage>,
    /// The last resolve, and the film version it shows.
    resolved: Option<(FilmVersion, Resolved)>,
    /// The tick that made the denoise stage's current output.
    denoised_tick: u64,
    /// Set by [`Session::resume`]: the next tick's stats say the session was restored.
    restored: bool,
    /// Set by [`Session::set_technique`]: the next tick restarts the film.
    switched: bool,
}

/// Where a session stands between ticks, beyond its scene: what a snapshot carries so another
/// process can continue it ([`Session::progress`], [`Session::resume`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Progress {
    /// Ticks run so far.
    pub tick: u64,
    /// Edit batches accepted so far.
    pub edits_accepted: u64,
    /// The film's accumulation id.
    pub accumulation_id: u64,
    /// Queued edits, coalesced.
    pub pending: Vec<Edit>,
}

impl Session {
    pub fn new(scene: Scene, config: &TechniqueConfig, seed: u64, device: &Device) -> Result<Session, EngineError> {
        let technique = technique::build(config, &scene)?;
        let accel = SceneAccel::build(device, &scene)?;
        let film = Film::new(scene.camera.width, scene.camera.height);
        Ok(Session {
            scene,
            accel,
            technique,
            config: config.clone(),
            film,
            seed,
            tick: 0,
            pending: Vec::new(),
            pending_received: 0,
            accepted_batches: 0,
            denoise: None,
            resolved: None,
            denoised_tick: 0,
            restored: false,
            switched: false,
        })
    }

    /// Where the session stands (for a snapshot).
    pub fn progress(&self) -> Progress {
        Progress {
            tick: self.tick,
            edits_accepted: self.accepted_batches,
            accumulation_id: self.film.accumulation_id,
            pending: self.pending.clone(),
        }
    }

    /// Continues from `progress` (a snapshot's): the next tick is `progress.tick`, the pending
    /// edits are validated against the scene and queued, and that tick starts a new
    /// accumulation after the snapshot's (until then [`Session::progress`] is the snapshot's).
    /// The technique's state was built fresh with the session, and the next tick's stats say
    /// `restored`.
    pub fn resume(&mut self, progress: Progress) -> Result<(), SceneError> {
        self.pending = edits::queue(&self.scene, &[], progress.pending)?;
        self.tick = progress.tick;
        self.accepted_batches = progress.edits_accepted;
        self.film.accumulation_id = progress.accumulation_id;
        self.restored = true;
        Ok(())
    }

    /// Runs `config` from the next tick on, built fresh on the scene as edited; the pending
    /// edits stay queued and that tick restarts the film. Returns `false`, changing nothing,
    /// when `config` is the configuration running. On an error the session keeps its technique.
    /// The old technique's state is freed here, and every technique's constructor only checks
    /// its configuration (its state is built on its first tick), so a switch holds at most the
    /// larger of the two, never both.
    pub fn set_technique(&mut self, config: &TechniqueConfig) -> Result<bool, EngineError> {
        if *config == self.config {
            return Ok(false);
        }
        self.technique = technique::build(config, &self.scene)?;
        self.config = config.clone();
        self.switched = true;
        Ok(true)
    }

    /// Denoises every frame from the next tick on with `settings` (OIDN's device and filter are
    /// made now, once), or stops with `None`; the film goes on accumulating. Returns `false`,
    /// changing nothing, when these are the settings running. On an error the session keeps its
    /// stage.
    pub fn set_denoise(&mut self, settings: Option<DenoiseSettings>) -> Result<bool, EngineError> {
        if self.denoise.as_ref().map(DenoiseStage::settings) == settings {
            return Ok(false);
        }
        self.denoise = settings.map(|s| DenoiseStage::new(s, self.film.width, self.film.height)).transpose()?;
        Ok(true)
    }

    /// `image` (a frame of this session) denoised once with `settings`, its auxiliary images
    /// traced to convergence first: for a still, where denoising every tick would be wasted.
    pub fn denoise_once(&self, settings: DenoiseSettings, image: &LinearImage) -> Result<LinearImage, EngineError> {
        let mut stage = DenoiseStage::new(settings, self.film.width, self.film.height)?;
        Ok(stage.run(&self.scene, &self.accel, self.seed, image, crate::film::AuxFilm::TARGET_PASSES)?.0)
    }

    /// The denoise stage, when the session denoises.
    pub fn denoise(&self) -> Option<&DenoiseStage> {
        self.denoise.as_ref()
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The Embree scenes as of the last tick's commit.
    pub fn accel(&self) -> &SceneAccel {
        &self.accel
    }

    pub fn config(&self) -> &TechniqueConfig {
        &self.config
    }

    pub fn tick_count(&self) -> u64 {
        self.tick
    }

    pub fn film(&self) -> &Film {
        &self.film
    }

    /// Validates edits against the current scene with the pending edits merged in (two
    /// batches each valid alone, such as a camera position and a look-at at that position,
    /// may not be valid together), and queues them for the next tick, coalesced. A rejected
    /// batch queues nothing, so an accepted edit never fails a tick. Returns the batch's
    /// sequence number: the next tick reports it applied (`edits_applied_through`).
    pub fn queue_edits(&mut self, batch: Vec<Edit>) -> Result<u64, SceneError> {
        let received = batch.len();
        self.pending = edits::queue(&self.scene, &self.pending, batch)?;
        self.pending_received += received;
        self.accepted_batches += 1;
        Ok(self.accepted_batches)
    }

    /// Distinct targets with a queued edit.
    pub fn pending_edits(&self) -> usize {
        self.pending.len()
    }

    /// Runs one tick: drain → apply → commit → update → render → resolve → denoise.
    pub fn tick(&mut self) -> Result<Frame, EngineError> {
        let start = Instant::now();
        let mut times = PhaseTimes::default();
        let delta = self.drain_apply_commit(start, &mut times)?;

        // Let the technique verify and invalidate; restart accumulation where it says.
        let t = Instant::now();
        let ctx = RenderContext { scene: &self.scene, accel: &self.accel, seed: self.seed, tick: self.tick };
        let update = self.technique.update(&ctx, &delta)?;
        let switched = std::mem::take(&mut self.switched);
        if self.technique.restarts_whole_film(&delta) || self.restored || switched {
            self.film.reset();
        }
        if let Some(stage) = &mut self.denoise {
            stage.update(&delta);
        }
        times.update_ms = ms(t);

        let t = Instant::now();
        let render = self.technique.render(&ctx, &mut self.film, update)?;
        times.render_ms = ms(t);

        let t = Instant::now();
        let (Resolved { image, paths_per_pixel, tick: image_tick }, resolve_reused) = self.resolve();
        times.resolve_ms = ms(t);

        // Denoise, keeping the raw image.
        let t = Instant::now();
        let (denoised, aux) = self.denoise_step(&image)?;
        if !aux.reused {
            self.denoised_tick = self.tick;
        }
        times.denoise_ms = if self.denoise.is_some() { ms(t) } else { 0.0 };
        times.total_ms = ms(start);

        let stats = TickStats {
            tick: self.tick,
            technique: self.technique.id().to_string(),
            times,
            rays: render.rays,
            edits_received: delta.received,
            edits_coalesced: delta.coalesced,
            edits_unchanged: delta.unchanged,
            edits_applied_through: self.accepted_batches,
            moved_surfaces: delta.moved.len(),
            spp: self.film.passes,
            paths_per_pixel,
            accumulation_id: self.film.accumulation_id,
            aux_rays: aux.rays,
            denoise_reused: aux.reused,
            resolve_reused,
            restored: std::mem::take(&mut self.restored),
            detail: render.detail,
        };
        let frame = Frame {
            tick: self.tick,
            accumulation_id: self.film.accumulation_id,
            spp: self.film.passes,
            image,
            image_tick,
            denoised,
            denoised_tick: self.denoised_tick,
            stats,
        };
        self.tick += 1;
        Ok(frame)
    }

    /// The tick's first three steps: drains the queue (timed from `start`), applies it to the
    /// model, and commits only the moved instances to Embree.
    fn drain_apply_commit(&mut self, start: Instant, times: &mut PhaseTimes) -> Result<SceneDelta, EngineError> {
        let batch = std::mem::take(&mut self.pending);
        let received = std::mem::take(&mut self.pending_received);
        times.drain_ms = ms(start);
        let t = Instant::now();
        let kept = batch.len();
        let mut delta = edits::apply(&mut self.scene, batch)?;
        delta.received = received;
        delta.coalesced = received - kept;
        times.apply_ms = ms(t);

        let t = Instant::now();
        let moved: Vec<_> = delta.moved.iter().map(|m| m.surface).collect();
        self.accel.update_instances(&self.scene, &moved)?;
        times.commit_ms = ms(t);
        Ok(delta)
    }

    /// The film as an image (preview-filtered if the technique asks) and its mean paths per
    /// pixel, and whether they are the last tick's: an unchanged film version resolves to the
    /// same image.
    fn resolve(&mut self) -> (Resolved, bool) {
        let version = self.film.version();
        if let Some((_, last)) = self.resolved.as_ref().filter(|(v, _)| *v == version) {
            return (last.clone(), true);
        }
        let mut image = self.film.resolve();
        if let Some(f) = self.technique.preview_filter() {
            image = bilateral_filter(&image, f.sigma_spatial_px, f.sigma_range);
        }
        let paths_per_pixel = self.film.mean_paths_per_pixel();
        let resolved = Resolved { image: Arc::new(image), paths_per_pixel, tick: self.tick };
        self.resolved = Some((version, resolved.clone()));
        (resolved, false)
    }

    /// The denoised image when the session denoises, and what the stage did (its auxiliary
    /// rays; whether it reused the last output because the film had not changed).
    fn denoise_step(&mut self, image: &LinearImage) -> Result<(Option<Arc<LinearImage>>, AuxWork), EngineError> {
        match &mut self.denoise {
            Some(stage) => {
                let (denoised, work) = stage.tick(&self.scene, &self.accel, self.seed, image, self.film.version())?;
                Ok((Some(denoised), work))
            }
            None => Ok((None, AuxWork::default())),
        }
    }
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}
