//! The server's side of a session worker ([`super`]): the handle it keeps per session, which
//! starts the worker thread, queues commands on its bounded channel (429 `session_busy` when
//! full), waits for their replies, and joins a tick already queued instead of queueing another.
//! It also holds what the worker publishes for clients: the newest frame, the stats history,
//! the failure reason, what the session runs, and the frames' shared encodings.
use super::{
    failed, gone, read_failure, run, Command, Live, PublishedFrame, SessionBytes, SnapshotParts, TickWaiters, Worker,
    WorkerContext, COMMAND_QUEUE,
};
use crate::engine::{Session, TickStats};
use crate::scene::edits::Edit;
use crate::server::error::ApiError;
use crate::server::protocol::{EditsAccepted, PlayingAnimation, UpdateSession};
use crate::server::state::{MemoryReservation, Running};
use axum::http::StatusCode;
use std::collections::VecDeque;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use tokio::sync::{oneshot, watch};

/// Where a queued command's answer arrives.
pub type Answer<T> = oneshot::Receiver<Result<T, ApiError>>;

/// The handle the server keeps for a session.
pub struct SessionHandle {
    commands: Mutex<mpsc::SyncSender<Command>>,
    tick_waiters: TickWaiters,
    pub frames: watch::Receiver<Option<Arc<PublishedFrame>>>,
    pub history: Arc<Mutex<VecDeque<TickStats>>>,
    pub failure: Arc<Mutex<Option<String>>>,
    /// What it runs, which its worker publishes when a client changes it.
    running: Arc<Mutex<Running>>,
    /// The last encodings of its frames, shared by every client.
    pub encoded: crate::server::encoded::EncodedFrames,
    thread: Mutex<Option<JoinHandle<()>>>,
}

impl SessionHandle {
    /// Starts the worker thread for `session`, which holds `memory` of the server's budget.
    pub fn spawn(
        id: &str,
        session: Session,
        memory: MemoryReservation,
        tick_hz: Option<f32>,
        playing: Option<PlayingAnimation>,
        context: WorkerContext,
    ) -> std::io::Result<SessionHandle> {
        let (tx, rx) = mpsc::sync_channel(COMMAND_QUEUE);
        let (publish, frames) = watch::channel(None);
        let history = Arc::new(Mutex::new(VecDeque::new()));
        let failure = Arc::new(Mutex::new(None));
        let running = Arc::new(Mutex::new(Running::of(&session)));
        let tick_waiters = TickWaiters::default();
        let worker = Worker {
            live: Some(Live { session, publish, memory }),
            context,
            history: history.clone(),
            failure: failure.clone(),
            running: running.clone(),
            tick_waiters: tick_waiters.clone(),
            last_tick: None,
        };
        let thread = std::thread::Builder::new()
            .name(format!("session-{id}"))
            .spawn(move || run(worker, rx, tick_hz, playing))?;
        Ok(SessionHandle {
            commands: Mutex::new(tx),
            tick_waiters,
            frames,
            history,
            failure,
            running,
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
        read_failure(&self.failure)
    }

    /// Sends the command `command` makes around a reply channel, and waits for the reply.
    async fn ask<T>(
        &self,
        command: impl FnOnce(oneshot::Sender<Result<T, ApiError>>) -> Command,
    ) -> Result<T, ApiError> {
        let (reply, answer) = oneshot::channel();
        self.send(command(reply))?;
        answer.await.map_err(|_| gone())?
    }

    /// What the session runs now.
    pub fn running(&self) -> Running {
        match self.running.lock() {
            Ok(r) => r.clone(),
            Err(poisoned) => poisoned.into_inner().clone(),
        }
    }

    /// Applies `update` from the next tick on, keeping the scene as edited and the queued edits
    /// (see [`Command::Update`]); returns what the session then runs.
    pub async fn update(
        &self,
        update: UpdateSession,
        bytes: SessionBytes,
        server_memory: u64,
    ) -> Result<Running, ApiError> {
        self.ask(|reply| Command::Update { update, bytes, server_memory, reply }).await
    }

    pub async fn edits(&self, batch: Vec<Edit>) -> Result<EditsAccepted, ApiError> {
        self.send_edits(batch)?.await.map_err(|_| gone())?
    }

    /// [`SessionHandle::edits`]'s request alone, queued at once: the acknowledgement comes on
    /// the receiver, so a client's next message need not wait for it.
    pub fn send_edits(&self, batch: Vec<Edit>) -> Result<Answer<EditsAccepted>, ApiError> {
        let (reply, answer) = oneshot::channel();
        self.send(Command::Edits { batch, reply })?;
        Ok(answer)
    }

    /// Asks for a tick: joins the queued one if there is one (it has not started, so it will
    /// include everything this client sent before), else queues a new one.
    pub async fn tick(&self) -> Result<TickStats, ApiError> {
        self.request_tick()?.await.map_err(|_| gone())?
    }

    /// [`SessionHandle::tick`]'s request alone, at once: the answer comes on the receiver,
    /// which a client that reads the tick's frame and stats elsewhere may drop.
    pub fn request_tick(&self) -> Result<Answer<TickStats>, ApiError> {
        if let Some(reason) = self.failure() {
            return Err(failed(&reason));
        }
        let (reply, answer) = oneshot::channel();
        let mut waiters = self.tick_waiters.lock().map_err(|_| gone())?;
        waiters.push(reply);
        if waiters.len() == 1 {
            if let Err(e) = self.send(Command::Tick) {
                waiters.clear();
                return Err(e);
            }
        }
        Ok(answer)
    }

    /// Plays an animation on the server's clock from `playing.clock_s`; it is validated
    /// against the session's scene.
    pub async fn play(&self, playing: PlayingAnimation) -> Result<(), ApiError> {
        self.ask(|reply| Command::Play { playing: Box::new(playing), reply }).await
    }

    pub async fn snapshot(&self) -> Result<SnapshotParts, ApiError> {
        self.ask(|reply| Command::Snapshot { reply }).await
    }

    pub async fn scene(&self) -> Result<crate::scene::SceneDesc, ApiError> {
        self.ask(|reply| Command::Scene { reply }).await
    }

    /// What the camera sees at film position (`x`, `y`), as of the last tick.
    pub async fn pick(&self, x: f32, y: f32) -> Result<Option<crate::scene::accel::Picked>, ApiError> {
        self.ask(|reply| Command::Pick { x, y, reply }).await
    }

    /// Makes the session's next command panic inside a turn (tests of the failure path).
    #[cfg(test)]
    pub fn inject_panic(&self) -> Result<(), ApiError> {
        self.send(Command::Panic)
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
