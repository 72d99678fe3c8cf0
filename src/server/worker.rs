//! One session's worker: a dedicated thread that owns the [`Session`] and runs its ticks on the
//! shared rayon pool, so no CPU work runs on the async runtime.
//!
//! Commands arrive over a bounded channel ([`COMMAND_QUEUE`] deep: a client that sends faster
//! than the session works gets 429 `session_busy` instead of growing the queue); replies go
//! back through oneshot channels. Ticks are client-driven (`Tick`), or server-driven at
//! `tick_hz` and while an animation plays. A tick request that finds a tick already queued and
//! not yet started joins it instead of queueing another, so a session has at most one tick
//! waiting however many clients ask, and every one of them gets that tick's stats. Each
//! tick's frame is published through a `watch` channel (newest frame wins) and its stats are
//! kept in a bounded history. A panic inside a tick marks the session failed with the panic's
//! message; the process and the other sessions carry on.
use super::error::ApiError;
use super::metrics::Metrics;
use super::protocol::EditsAccepted;
use crate::engine::{Session, TickStats};
use crate::scene::animation::Animation;
use crate::scene::edits::Edit;
use axum::http::StatusCode;
use std::collections::VecDeque;
use std::panic::AssertUnwindSafe;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::{oneshot, watch};

/// Commands a session's queue holds before new ones are refused with 429.
pub const COMMAND_QUEUE: usize = 64;

/// Clients waiting for the queued tick.
type TickWaiters = Arc<Mutex<Vec<oneshot::Sender<Result<TickStats, ApiError>>>>>;

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
        anim: Box<Animation>,
        speed: f32,
        reply: oneshot::Sender<Result<(), ApiError>>,
    },
    Pause,
    /// The current scene description (edits applied).
    Scene {
        reply: oneshot::Sender<crate::scene::SceneDesc>,
    },
    Shutdown,
}

/// The handle the server keeps for a session.
pub struct SessionHandle {
    commands: Mutex<mpsc::SyncSender<Command>>,
    tick_waiters: TickWaiters,
    pub frames: watch::Receiver<Option<Arc<PublishedFrame>>>,
    pub history: Arc<Mutex<VecDeque<TickStats>>>,
    pub failure: Arc<Mutex<Option<String>>>,
    /// The last encodings of its frames, shared by every client.
    pub encoded: super::encoded::EncodedFrames,
    thread: Mutex<Option<JoinHandle<()>>>,
}

fn failed(reason: &str) -> ApiError {
    ApiError::new(
        StatusCode::CONFLICT,
        "session_failed",
        format!("the session failed earlier and accepts no more work: {reason}"),
    )
}

fn gone() -> ApiError {
    ApiError::new(StatusCode::GONE, "session_closed", "the session has shut down")
}

struct Worker {
    session: Session,
    pool: Arc<rayon::ThreadPool>,
    metrics: Arc<Metrics>,
    publish: watch::Sender<Option<Arc<PublishedFrame>>>,
    history: Arc<Mutex<VecDeque<TickStats>>>,
    failure: Arc<Mutex<Option<String>>>,
    tick_waiters: TickWaiters,
}

impl Worker {
    /// Runs the queued tick and answers everyone who asked for it.
    fn tick_for_waiters(&mut self) {
        let waiters = self.tick_waiters.lock().map(|mut w| std::mem::take(&mut *w)).unwrap_or_default();
        let result = self.tick();
        for reply in waiters {
            let _ = reply.send(result.clone());
        }
    }

    fn failure(&self) -> Option<String> {
        self.failure.lock().ok().and_then(|f| f.clone())
    }

    fn queue(&mut self, batch: Vec<Edit>) -> Result<EditsAccepted, ApiError> {
        if let Some(reason) = self.failure() {
            return Err(failed(&reason));
        }
        let queued = batch.len();
        let seq = self.session.queue_edits(batch)?;
        Ok(EditsAccepted { queued, pending: self.session.pending_edits(), seq })
    }

    /// Runs one tick, catching panics; on success publishes the frame.
    fn tick(&mut self) -> Result<TickStats, ApiError> {
        if let Some(reason) = self.failure() {
            return Err(failed(&reason));
        }
        let session = &mut self.session;
        let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| self.pool.install(|| session.tick())));
        let reason = match outcome {
            Ok(Ok(frame)) => {
                let stats = frame.stats.clone();
                self.metrics.observe_tick(stats.times.total_ms / 1e3, stats.rays.total());
                self.metrics
                    .edits_coalesced
                    .fetch_add(stats.edits_coalesced as u64, std::sync::atomic::Ordering::Relaxed);
                if let Ok(mut h) = self.history.lock() {
                    if h.len() == STATS_HISTORY {
                        h.pop_front();
                    }
                    h.push_back(stats.clone());
                }
                self.publish.send_replace(Some(Arc::new(frame)));
                return Ok(stats);
            }
            Ok(Err(e)) => format!("tick failed: {e}"),
            Err(panic) => format!("panic in the technique: {}", panic_message(&*panic)),
        };
        tracing::error!(target: "relume::server", "session failed: {reason}");
        self.metrics.sessions_failed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        if let Ok(mut f) = self.failure.lock() {
            *f = Some(reason.clone());
        }
        Err(ApiError::internal(reason))
    }
}

impl SessionHandle {
    /// Starts the worker thread for `session`.
    pub fn spawn(
        id: &str,
        session: Session,
        tick_hz: Option<f32>,
        pool: Arc<rayon::ThreadPool>,
        metrics: Arc<Metrics>,
    ) -> std::io::Result<SessionHandle> {
        let (tx, rx) = mpsc::sync_channel(COMMAND_QUEUE);
        let (publish, frames) = watch::channel(None);
        let history = Arc::new(Mutex::new(VecDeque::new()));
        let failure = Arc::new(Mutex::new(None));
        let tick_waiters = TickWaiters::default();
        let worker = Worker {
            session,
            pool,
            metrics,
            publish,
            history: history.clone(),
            failure: failure.clone(),
            tick_waiters: tick_waiters.clone(),
        };
        let thread =
            std::thread::Builder::new().name(format!("session-{id}")).spawn(move || run(worker, rx, tick_hz))?;
        Ok(SessionHandle {
            commands: Mutex::new(tx),
            tick_waiters,
            frames,
            history,
            failure,
            encoded: Default::default(),
            thread: Mutex::new(Some(thread)),
        })
    }

    /// Queues a command, or refuses it with 429 when the queue is full.
    fn send(&self, c: Command) -> Result<(), ApiError> {
        match self.commands.lock().map_err(|_| gone())?.try_send(c) {
            Ok(()) => Ok(()),
            Err(mpsc::TrySendError::Full(_)) => Err(ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "session_busy",
                format!("the session has {COMMAND_QUEUE} commands waiting; wait for their answers before sending more"),
            )),
            Err(mpsc::TrySendError::Disconnected(_)) => Err(gone()),
        }
    }

    pub fn failure(&self) -> Option<String> {
        self.failure.lock().ok().and_then(|f| f.clone())
    }

    pub async fn edits(&self, batch: Vec<Edit>) -> Result<EditsAccepted, ApiError> {
        let (reply, answer) = oneshot::channel();
        self.send(Command::Edits { batch, reply })?;
        answer.await.map_err(|_| gone())?
    }

    /// Asks for a tick: joins the queued one if there is one (it has not started, so it will
    /// include everything this client sent before), else queues a new one.
    pub async fn tick(&self) -> Result<TickStats, ApiError> {
        let (reply, answer) = oneshot::channel();
        {
            let mut waiters = self.tick_waiters.lock().map_err(|_| gone())?;
            waiters.push(reply);
            if waiters.len() == 1 {
                if let Err(e) = self.send(Command::Tick) {
                    waiters.clear();
                    return Err(e);
                }
            }
        }
        answer.await.map_err(|_| gone())?
    }

    /// Plays an animation on the server's clock; it is validated against the session's scene.
    pub async fn play(&self, anim: Animation, speed: f32) -> Result<(), ApiError> {
        let (reply, answer) = oneshot::channel();
        self.send(Command::Play { anim: Box::new(anim), speed, reply })?;
        answer.await.map_err(|_| gone())?
    }

    pub async fn scene(&self) -> Result<crate::scene::SceneDesc, ApiError> {
        let (reply, answer) = oneshot::channel();
        self.send(Command::Scene { reply })?;
        answer.await.map_err(|_| gone())
    }

    pub fn pause(&self) -> Result<(), ApiError> {
        self.send(Command::Pause)
    }

    /// Stops the worker after the command in progress and waits for it (blocking: call from
    /// `spawn_blocking`).
    pub fn shutdown_blocking(&self) {
        // Blocks while the queue is full: the worker drains it.
        if let Ok(commands) = self.commands.lock() {
            let _ = commands.send(Command::Shutdown);
        }
        if let Some(t) = self.thread.lock().ok().and_then(|mut t| t.take()) {
            let _ = t.join();
        }
    }
}

/// The worker thread: the command loop under `catch_unwind`, so a panic anywhere in it (not
/// only inside a tick) marks the session failed, with its reason, instead of leaving it
/// "running" with no thread behind it.
fn run(w: Worker, rx: mpsc::Receiver<Command>, tick_hz: Option<f32>) {
    let failure = w.failure.clone();
    let metrics = w.metrics.clone();
    if let Err(panic) = std::panic::catch_unwind(AssertUnwindSafe(|| serve(w, rx, tick_hz))) {
        let reason = format!("panic in the session worker: {}", panic_message(&*panic));
        tracing::error!(target: "relume::server", "session failed: {reason}");
        metrics.sessions_failed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        if let Ok(mut f) = failure.lock() {
            *f = Some(reason);
        }
    }
}

fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}

/// The command loop: serve commands; tick on schedule while `tick_hz` is set or an animation
/// plays.
fn serve(mut w: Worker, rx: mpsc::Receiver<Command>, tick_hz: Option<f32>) {
    let mut playing: Option<(Box<Animation>, f32, Instant)> = None;
    let mut next_tick = tick_hz.map(|_| Instant::now());
    loop {
        let command = match next_tick {
            Some(at) => match rx.recv_timeout(at.saturating_duration_since(Instant::now())) {
                Ok(c) => Some(c),
                Err(RecvTimeoutError::Timeout) => None,
                Err(RecvTimeoutError::Disconnected) => break,
            },
            None => match rx.recv() {
                Ok(c) => Some(c),
                Err(_) => break,
            },
        };
        match command {
            Some(Command::Edits { batch, reply }) => {
                let _ = reply.send(w.queue(batch));
            }
            Some(Command::Tick) => w.tick_for_waiters(),
            Some(Command::Play { anim, speed, reply }) => {
                let checked = anim.validate(w.session.scene()).map_err(|e| ApiError::invalid(format!("anim: {e}")));
                if checked.is_ok() {
                    playing = Some((anim, speed, Instant::now()));
                    next_tick.get_or_insert_with(Instant::now);
                }
                let _ = reply.send(checked);
            }
            Some(Command::Pause) => {
                playing = None;
                if tick_hz.is_none() {
                    next_tick = None;
                }
            }
            Some(Command::Scene { reply }) => {
                let _ = reply.send(w.session.scene().desc().clone());
            }
            Some(Command::Shutdown) => break,
            None => {
                // A scheduled tick: advance the animation, then tick.
                if let Some((anim, speed, started)) = &playing {
                    let t = started.elapsed().as_secs_f32() * speed;
                    if w.queue(anim.edits_at(t)).is_err() {
                        playing = None;
                    }
                }
                if w.tick().is_err() {
                    next_tick = None;
                    playing = None;
                    continue;
                }
                let hz = tick_hz.unwrap_or(DEFAULT_PLAY_HZ);
                let period = Duration::try_from_secs_f32(1.0 / hz).unwrap_or(MAX_PERIOD);
                let now = Instant::now();
                next_tick = next_tick.map(|at| if at + period > now { at + period } else { now + period });
            }
        }
    }
}
