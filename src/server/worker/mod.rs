//! One session's worker: a dedicated thread that owns the [`Session`] and runs its ticks on the
//! shared rayon pool, so no CPU work runs on the async runtime.
//!
//! Commands arrive from the server's [`SessionHandle`] (`handle.rs`) over a bounded channel
//! ([`COMMAND_QUEUE`] deep: a client that sends faster than the session works gets 429
//! `session_busy` instead of growing the queue); replies go back through oneshot channels.
//! Ticks are client-driven (`Tick`), or server-driven at `tick_hz` and while an animation
//! plays. A tick request that finds a tick already queued and not yet started joins it instead
//! of queueing another, so a session has at most one tick waiting however many clients ask,
//! and every one of them gets that tick's stats. Each tick's frame is published through a
//! `watch` channel (newest frame wins) and its stats are kept in a bounded history. A panic
//! inside a tick marks the session failed with the panic's message; the process and the other
//! sessions carry on.
//!
//! Fairness: every tick runs in a turn on the shared pool ([`Turns`], round-robin across
//! sessions), and client-driven ticks of one session run at most `max_tick_hz` times a second
//! (a request that comes sooner is answered by the tick at the next allowed instant).
//!
//! A failed session drops its technique, its film and its frame publisher at once, so its
//! memory (and its share of `--server-memory`) is free before a client deletes it; WebSocket
//! subscribers are closed with [`super::ws::CLOSE_SESSION_FAILED`]. Its entry, failure reason
//! and stats history stay inspectable until it is deleted.
use super::error::ApiError;
use super::metrics::Metrics;
use super::protocol::{EditsAccepted, PlayingAnimation, UpdateSession};
use super::state::{MemoryReservation, Running};
use super::turns::Turns;
use crate::engine::{Session, TickStats};
use crate::scene::edits::Edit;
use axum::http::StatusCode;
use std::collections::VecDeque;
use std::panic::AssertUnwindSafe;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{oneshot, watch};

mod handle;
pub use handle::{Answer, SessionHandle};

/// Commands a session's queue holds before new ones are refused with 429.
pub const COMMAND_QUEUE: usize = 64;

/// A client waiting for a tick's stats.
type Waiter = oneshot::Sender<Result<TickStats, ApiError>>;

/// Clients waiting for the queued tick.
type TickWaiters = Arc<Mutex<Vec<Waiter>>>;

/// How many ticks' stats a session keeps.
pub const STATS_HISTORY: usize = 256;
/// The longest period between scheduled ticks (`tick_hz` is validated to at least 0.01).
const MAX_PERIOD: Duration = Duration::from_secs(100);

/// Tick rate while an animation plays in a session without `tick_hz`.
pub const DEFAULT_PLAY_HZ: f32 = 30.0;

/// The newest frame of a session, as published after a tick (raw and, when the session
/// denoises, denoised).
pub type PublishedFrame = crate::engine::Frame;

pub enum Command {
    Edits {
        batch: Vec<Edit>,
        reply: oneshot::Sender<Result<EditsAccepted, ApiError>>,
    },
    /// Run one tick and answer every client waiting in [`SessionHandle`]'s tick waiters.
    Tick,
    Play {
        playing: Box<PlayingAnimation>,
        reply: oneshot::Sender<Result<(), ApiError>>,
    },
    Pause,
    /// The current scene description (edits applied).
    Scene {
        reply: oneshot::Sender<Result<crate::scene::SceneDesc, ApiError>>,
    },
    /// What the camera sees under a film position (pixels).
    Pick {
        x: f32,
        y: f32,
        reply: oneshot::Sender<Result<Option<crate::scene::accel::Picked>, ApiError>>,
    },
    /// The scene, where the session stands, and the animation playing.
    Snapshot {
        reply: oneshot::Sender<Result<SnapshotParts, ApiError>>,
    },
    /// Applies `update` (`PATCH /v1/sessions/{id}`) from the next tick on, if the session's
    /// estimated bytes with it, worked out by `bytes` on the scene as edited, fit its share of
    /// `server_memory`.
    Update {
        update: UpdateSession,
        bytes: SessionBytes,
        server_memory: u64,
        reply: oneshot::Sender<Result<Running, ApiError>>,
    },
    Shutdown,
    /// Panics inside a tick's turn, as a failing technique would (tests of the failure path).
    #[cfg(test)]
    Panic,
}

/// A session's estimated resident bytes running something else, on its scene (checked against
/// `--session-memory` by the server, which knows the limits).
pub type SessionBytes = Box<dyn FnOnce(&crate::scene::Scene, &Running) -> Result<u64, ApiError> + Send>;

/// What a snapshot takes from the worker: the scene with its edits applied, what it runs, the
/// session's progress, and the animation playing with its clock now.
pub struct SnapshotParts {
    pub scene: crate::scene::SceneDesc,
    pub running: Running,
    pub progress: crate::engine::Progress,
    pub animation: Option<PlayingAnimation>,
}

/// 409: the session failed earlier.
pub fn failed(reason: &str) -> ApiError {
    ApiError::new(
        StatusCode::CONFLICT,
        "session_failed",
        format!("the session failed earlier and accepts no more work: {reason}"),
    )
}

/// 410: the session's worker has shut down.
pub fn gone() -> ApiError {
    ApiError::new(StatusCode::GONE, "session_closed", "the session has shut down")
}

/// What a running session holds; dropped whole when the session fails.
struct Live {
    session: Session,
    publish: watch::Sender<Option<Arc<PublishedFrame>>>,
    /// The session's share of `--server-memory`, given back when it fails or is deleted.
    memory: MemoryReservation,
}

/// What the worker needs from the server to run a session.
pub struct WorkerContext {
    pub pool: Arc<rayon::ThreadPool>,
    pub turns: Arc<Turns>,
    pub metrics: Arc<Metrics>,
    /// Client-driven ticks run at most this often (the server's `max_tick_hz`).
    pub max_tick_hz: f32,
}

struct Worker {
    live: Option<Live>,
    context: WorkerContext,
    history: Arc<Mutex<VecDeque<TickStats>>>,
    failure: Arc<Mutex<Option<String>>>,
    running: Arc<Mutex<Running>>,
    tick_waiters: TickWaiters,
    /// When the last tick started.
    last_tick: Option<Instant>,
}

impl Worker {
    fn take_waiters(&self) -> Vec<Waiter> {
        self.tick_waiters.lock().map(|mut w| std::mem::take(&mut *w)).unwrap_or_default()
    }

    /// Runs one tick and gives its result to every one of `waiters` too.
    fn tick_answering(&mut self, waiters: Vec<Waiter>) -> Result<TickStats, ApiError> {
        let result = self.tick();
        for reply in waiters {
            let _ = reply.send(result.clone());
        }
        result
    }

    /// When a client-driven tick asked for now may run: at least `1 / max_tick_hz` after the
    /// last tick started.
    fn client_tick_due(&self) -> Instant {
        let period = Duration::try_from_secs_f32(1.0 / self.context.max_tick_hz).unwrap_or(MAX_PERIOD);
        let now = Instant::now();
        self.last_tick.map_or(now, |t| (t + period).max(now))
    }

    fn live(&mut self) -> Result<&mut Live, ApiError> {
        let reason = self.failure();
        self.live.as_mut().ok_or_else(|| failed(&reason.unwrap_or_default()))
    }

    fn failure(&self) -> Option<String> {
        read_failure(&self.failure)
    }

    /// Marks the session failed and drops what it holds: technique, film, frame publisher (its
    /// subscribers see the channel close) and its memory reservation.
    fn fail(&mut self, reason: String) {
        record_failure(&self.context.metrics, &self.failure, reason);
        self.live = None;
    }

    fn queue(&mut self, batch: Vec<Edit>) -> Result<EditsAccepted, ApiError> {
        let session = &mut self.live()?.session;
        let queued = batch.len();
        let seq = session.queue_edits(batch)?;
        Ok(EditsAccepted { queued, pending: session.pending_edits(), seq })
    }

    /// Applies `update` between ticks: resizes the session's memory share to what `bytes`
    /// estimates, starts or stops the denoiser, builds the new technique on the scene as edited,
    /// and publishes what the session now runs, which it returns. On an error everything is as
    /// it was (the denoiser is made again). What equals what is running changes nothing and is
    /// not estimated.
    fn update(&mut self, update: UpdateSession, bytes: SessionBytes, server_memory: u64) -> Result<Running, ApiError> {
        let live = self.live()?;
        let now = Running::of(&live.session);
        let next = Running {
            technique: update.technique.unwrap_or_else(|| now.technique.clone()),
            denoise: update.denoise.unwrap_or(now.denoise),
        };
        if next == now {
            return Ok(now);
        }
        let before = live.memory.resize(bytes(live.session.scene(), &next)?, server_memory)?;
        if let Err(e) = live.session.set_denoise(next.denoise) {
            live.memory.resize(before, u64::MAX)?;
            return Err(super::create::denoise_error(e));
        }
        if let Err(e) = live.session.set_technique(&next.technique) {
            live.memory.resize(before, u64::MAX)?;
            live.session.set_denoise(now.denoise).map_err(super::create::denoise_error)?;
            return Err(super::create::engine_error("", e));
        }
        if let Ok(mut r) = self.running.lock() {
            *r = next.clone();
        }
        Ok(next)
    }

    /// Runs one tick in this session's turn on the pool, catching panics; on success publishes
    /// the frame, on failure fails the session.
    fn tick(&mut self) -> Result<TickStats, ApiError> {
        self.last_tick = Some(Instant::now());
        let WorkerContext { pool, turns, .. } = &self.context;
        let (pool, turns) = (pool.clone(), turns.clone());
        let live = self.live()?;
        let session = &mut live.session;
        let outcome = turns.run(|| std::panic::catch_unwind(AssertUnwindSafe(|| pool.install(|| session.tick()))));
        let reason = match outcome {
            Ok(Ok(frame)) => {
                let stats = frame.stats.clone();
                live.publish.send_replace(Some(Arc::new(frame)));
                self.record(&stats);
                return Ok(stats);
            }
            Ok(Err(e)) => format!("tick failed: {e}"),
            Err(panic) => format!("panic in the technique: {}", panic_message(&*panic)),
        };
        self.fail(reason.clone());
        Err(ApiError::internal(reason))
    }

    fn record(&self, stats: &TickStats) {
        let metrics = &self.context.metrics;
        metrics.observe_tick(stats.times.total_ms / 1e3, stats.rays.total());
        metrics.edits_coalesced.fetch_add(stats.edits_coalesced as u64, std::sync::atomic::Ordering::Relaxed);
        if let Ok(mut h) = self.history.lock() {
            if h.len() == STATS_HISTORY {
                h.pop_front();
            }
            h.push_back(stats.clone());
        }
    }

    /// A test's stand-in for a technique that panics: the same path as a real panic in a tick.
    #[cfg(test)]
    fn panic_in_a_turn(&mut self) {
        let turns = self.context.turns.clone();
        let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| turns.run(|| panic!("injected by a test"))));
        if let Err(panic) = outcome {
            self.fail(format!("panic in the technique: {}", panic_message(&*panic)));
        }
    }
}

/// The worker thread: the command loop under `catch_unwind`, so a panic anywhere in it (not
/// only inside a tick) marks the session failed, with its reason, instead of leaving it
/// "running" with no thread behind it.
fn run(w: Worker, rx: mpsc::Receiver<Command>, tick_hz: Option<f32>, playing: Option<PlayingAnimation>) {
    let failure = w.failure.clone();
    let metrics = w.context.metrics.clone();
    if let Err(panic) = std::panic::catch_unwind(AssertUnwindSafe(|| serve(w, rx, tick_hz, playing))) {
        let reason = format!("panic in the session worker: {}", panic_message(&*panic));
        record_failure(&metrics, &failure, reason);
    }
}

/// Logs and counts a session's failure, and keeps its `reason` for clients.
fn record_failure(metrics: &Metrics, failure: &Mutex<Option<String>>, reason: String) {
    tracing::error!(target: "relume::server", "session failed: {reason}");
    metrics.sessions_failed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    if let Ok(mut f) = failure.lock() {
        *f = Some(reason);
    }
}

fn read_failure(failure: &Mutex<Option<String>>) -> Option<String> {
    failure.lock().ok().and_then(|f| f.clone())
}

fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}

/// What woke the command loop.
enum Wake {
    Command(Command),
    /// The scheduled tick (`tick_hz`, or a playing animation) is due.
    Scheduled,
    /// A client-driven tick held back by the rate cap is due.
    ClientTick,
}

/// Waits for a command, or until the earlier of the two deadlines. `None`: the server is gone.
fn wait(rx: &mpsc::Receiver<Command>, next_tick: Option<Instant>, client_tick: Option<Instant>) -> Option<Wake> {
    let deadline = match (next_tick, client_tick) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    };
    let Some(at) = deadline else { return rx.recv().ok().map(Wake::Command) };
    match rx.recv_timeout(at.saturating_duration_since(Instant::now())) {
        Ok(c) => Some(Wake::Command(c)),
        Err(RecvTimeoutError::Timeout) if client_tick == Some(at) => Some(Wake::ClientTick),
        Err(RecvTimeoutError::Timeout) => Some(Wake::Scheduled),
        Err(RecvTimeoutError::Disconnected) => None,
    }
}

/// An animation playing since `started`, from `from.clock_s`.
struct Playing {
    from: PlayingAnimation,
    started: Instant,
}

impl Playing {
    /// The animation with its clock as of now.
    fn now(&self) -> PlayingAnimation {
        let clock_s = self.from.clock_s + self.started.elapsed().as_secs_f64() * f64::from(self.from.speed);
        PlayingAnimation { clock_s, ..self.from.clone() }
    }
}

/// What serving one command asks of the loop.
enum Step {
    Continue,
    /// A client-driven tick may run now.
    Tick,
    Shutdown,
}

/// The command loop's schedule: the animation playing, when the next scheduled tick is due,
/// and when a client-driven tick held back by the rate cap may run.
struct Schedule {
    tick_hz: Option<f32>,
    playing: Option<Playing>,
    next_tick: Option<Instant>,
    client_tick: Option<Instant>,
}

/// The command loop: serve commands; tick on schedule while `tick_hz` is set or an animation
/// plays (from the start when a restored session was playing one), and for clients no
/// sooner than the rate cap allows.
///
/// Pending work collapses: before any tick runs, every command already queued is served, so
/// the edits sent while the last tick ran are acknowledged at once and all ride on this tick,
/// and the tick requests among them join it. However fast clients send, a request waits for
/// at most the tick in progress and the next one, never for a queue of ticks.
fn serve(mut w: Worker, rx: mpsc::Receiver<Command>, tick_hz: Option<f32>, restored: Option<PlayingAnimation>) {
    let playing = restored.map(|from| Playing { from, started: Instant::now() });
    let next_tick = (tick_hz.is_some() || playing.is_some()).then(Instant::now);
    let mut schedule = Schedule { tick_hz, playing, next_tick, client_tick: None };
    while let Some(wake) = wait(&rx, schedule.next_tick, schedule.client_tick) {
        let scheduled = match wake {
            Wake::Command(c) => match serve_command(&mut w, &mut schedule, c) {
                Step::Continue => continue,
                Step::Tick => false,
                Step::Shutdown => break,
            },
            Wake::ClientTick => {
                schedule.client_tick = None;
                false
            }
            Wake::Scheduled => true,
        };
        // The clients this tick answers are those waiting now: each sent its edits before it
        // asked, so serving what is queued after taking them gives the tick all their edits.
        let waiters = w.take_waiters();
        // Collapse what queued up behind the last tick before running this one. A tick asked
        // for from here on is not in `waiters`: it is left to the next tick.
        let mut asked = false;
        while let Ok(c) = rx.try_recv() {
            match serve_command(&mut w, &mut schedule, c) {
                Step::Shutdown => return,
                Step::Tick => asked = true,
                Step::Continue => {}
            }
        }
        if scheduled {
            scheduled_tick(&mut w, &mut schedule, waiters);
        } else if !waiters.is_empty() {
            let _ = w.tick_answering(waiters);
        }
        let asked = asked || schedule.client_tick.is_some();
        schedule.client_tick = asked.then(|| w.client_tick_due());
    }
}

/// Serves one command; a tick request is left to the loop (now, or at the rate cap's instant).
fn serve_command(w: &mut Worker, schedule: &mut Schedule, command: Command) -> Step {
    match command {
        Command::Edits { batch, reply } => {
            let _ = reply.send(w.queue(batch));
        }
        Command::Tick => {
            let due = w.client_tick_due();
            if due <= Instant::now() {
                return Step::Tick;
            }
            schedule.client_tick = Some(due);
        }
        Command::Play { playing: p, reply } => {
            let checked = w.live().and_then(|l| {
                p.animation.validate(l.session.scene()).map_err(|e| ApiError::invalid(format!("anim: {e}")))
            });
            if checked.is_ok() {
                schedule.playing = Some(Playing { from: *p, started: Instant::now() });
                schedule.next_tick.get_or_insert_with(Instant::now);
            }
            let _ = reply.send(checked);
        }
        Command::Snapshot { reply } => {
            let parts = w.live().map(|l| SnapshotParts {
                scene: l.session.scene().desc().clone(),
                running: Running::of(&l.session),
                progress: l.session.progress(),
                animation: schedule.playing.as_ref().map(Playing::now),
            });
            let _ = reply.send(parts);
        }
        Command::Pause => {
            schedule.playing = None;
            if schedule.tick_hz.is_none() {
                schedule.next_tick = None;
            }
        }
        Command::Update { update, bytes, server_memory, reply } => {
            let _ = reply.send(w.update(update, bytes, server_memory));
        }
        Command::Scene { reply } => {
            let _ = reply.send(w.live().map(|l| l.session.scene().desc().clone()));
        }
        Command::Pick { x, y, reply } => {
            let picked = w.live().map(|l| crate::scene::accel::pick(l.session.scene(), l.session.accel(), x, y));
            let _ = reply.send(picked);
        }
        Command::Shutdown => return Step::Shutdown,
        #[cfg(test)]
        Command::Panic => w.panic_in_a_turn(),
    }
    Step::Continue
}

/// The scheduled tick: advance the animation, tick, and set the next one a period on (or a
/// period from now, when ticks run late: late ticks are skipped, not made up).
fn scheduled_tick(w: &mut Worker, schedule: &mut Schedule, waiters: Vec<Waiter>) {
    if let Some(p) = &schedule.playing {
        let now = p.now();
        if w.queue(now.animation.edits_at(now.clock_s as f32)).is_err() {
            schedule.playing = None;
        }
    }
    if w.tick_answering(waiters).is_err() {
        schedule.next_tick = None;
        schedule.playing = None;
        return;
    }
    let hz = schedule.tick_hz.unwrap_or(DEFAULT_PLAY_HZ);
    let period = Duration::try_from_secs_f32(1.0 / hz).unwrap_or(MAX_PERIOD);
    let now = Instant::now();
    schedule.next_tick = schedule.next_tick.map(|at| if at + period > now { at + period } else { now + period });
}
