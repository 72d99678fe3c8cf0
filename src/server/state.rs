//! Server state: configuration, limits, the Embree device, the rayon pool and the sessions.
use super::error::ApiError;
use super::metrics::Metrics;
use super::protocol::{SceneEntry, SessionLinks, SessionView};
use super::worker::SessionHandle;
use crate::embree::Device;
use crate::film::DenoiseSettings;
use crate::scene::SceneBudget;
use crate::technique::TechniqueConfig;
use axum::http::StatusCode;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};
use std::time::Duration;

/// The slowest server-driven tick rate: one tick per 100 s.
pub const MIN_TICK_HZ: f32 = 0.01;

/// Limits on what clients may ask for. Each rejection answers 413 (too large) or 422/429.
#[derive(Clone, Debug)]
pub struct Limits {
    pub max_body_bytes: usize,
    /// Bytes one uploaded scene may take (`--upload-limit`): the `.glb` or `.zip` as sent, and
    /// an archive's files once unpacked.
    pub upload_limit: u64,
    /// Largest image side, and largest pixel count.
    pub max_side: u32,
    pub max_pixels: u64,
    pub max_sessions: usize,
    pub max_triangles: usize,
    /// Objects and lights in one scene.
    pub max_objects: usize,
    pub max_lights: usize,
    pub max_edits_per_message: usize,
    pub max_spp_per_tick: u32,
    pub max_photon_paths: u32,
    /// Estimated resident bytes one session may hold (413 beyond), and all sessions together
    /// (429 beyond).
    pub session_memory: u64,
    pub server_memory: u64,
    pub max_tick_hz: f32,
    /// A session with no request and no WebSocket message (or pong) for this long is deleted.
    pub session_idle: Duration,
    /// How long `GET frame?tick=N` waits for tick N.
    pub frame_wait: Duration,
    pub request_timeout: Duration,
    /// Open HTTP connections, and open WebSockets, each at most this many; past it, a new
    /// connection or upgrade gets 503.
    pub max_connections: usize,
    /// A connection must send a request's headers within this long (slow-loris).
    pub header_read_timeout: Duration,
    /// How long shutdown waits for connections and sessions to drain.
    pub drain_deadline: Duration,
}

impl Limits {
    /// Refuses a batch of more than `max_edits_per_message` edits (413 naming `field`), the
    /// one check for every path edits arrive by: HTTP, the WebSocket and a snapshot's queue.
    pub fn check_edit_count(&self, field: &str, count: usize) -> Result<(), ApiError> {
        let limit = self.max_edits_per_message;
        if count > limit {
            return Err(ApiError::too_large(format!("{field}: {count} edits exceed the limit of {limit} per message")));
        }
        Ok(())
    }

    /// What a session's scene may hold, checked before any mesh is built.
    pub fn scene_budget(&self) -> SceneBudget {
        SceneBudget {
            max_triangles: self.max_triangles as u64,
            max_objects: self.max_objects,
            max_lights: self.max_lights,
        }
    }
}

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            max_body_bytes: 8 << 20,
            upload_limit: 2 << 30,
            max_side: 2048,
            max_pixels: 1 << 20,
            max_sessions: 16,
            max_triangles: 4_000_000,
            max_objects: 10_000,
            max_lights: 256,
            max_edits_per_message: 4096,
            max_spp_per_tick: 64,
            max_photon_paths: 4_000_000,
            session_memory: 2 << 30,
            server_memory: 16 << 30,
            max_tick_hz: 120.0,
            session_idle: Duration::from_secs(600),
            frame_wait: Duration::from_secs(10),
            request_timeout: Duration::from_secs(60),
            max_connections: 512,
            header_read_timeout: Duration::from_secs(10),
            drain_deadline: Duration::from_secs(30),
        }
    }
}

#[derive(Clone, Debug)]
pub struct ServerConfig {
    pub scenes_root: PathBuf,
    pub token: Option<String>,
    pub threads: usize,
    /// Cap on Embree's kernel family (`None`: the widest this CPU has).
    pub isa: Option<crate::embree::Isa>,
    pub limits: Limits,
    pub access: Access,
    /// This process's node name ([`valid_node`]): every session id it makes starts with
    /// `NODE.`, and every response says it in `X-Relume-Node`, so a proxy can route a session's
    /// requests to the process that owns it.
    pub node: String,
}

/// A node name: a DNS label (letters, digits and `-`, 1 to 63 characters, no leading or
/// trailing `-`), so it can be a pod's name and a part of a URL path.
pub fn valid_node(name: &str) -> bool {
    (1..=63).contains(&name.len())
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-')
        && !name.starts_with('-')
        && !name.ends_with('-')
}

/// Who may reach the server from a browser.
///
/// - `hosts`: host names accepted in the `Host` header besides IP literals and `localhost`
///   (anything else is 421: a DNS-rebinding page reaches loopback under its own name).
/// - `origins`: origins (`https://app.example:8443`) that may open WebSockets from another
///   origin and read responses through CORS. CORS is off when it is empty.
#[derive(Clone, Debug, Default)]
pub struct Access {
    pub hosts: Vec<String>,
    pub origins: Vec<String>,
}

/// What a session runs with besides its scene, fixed for its life: checked against the limits
/// when it is created, shown in its view and carried by its snapshot.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionSettings {
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    pub tick_hz: Option<f32>,
}

/// What a session runs that a client can change while it runs (`PATCH /v1/sessions/{id}`): its
/// worker publishes it ([`super::worker::SessionHandle::running`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Running {
    pub technique: TechniqueConfig,
    pub denoise: Option<DenoiseSettings>,
}

impl Running {
    /// What `session` runs: its technique and its denoiser's settings.
    pub fn of(session: &crate::engine::Session) -> Running {
        Running {
            technique: session.config().clone(),
            denoise: session.denoise().map(crate::engine::DenoiseStage::settings),
        }
    }
}

/// What the server remembers about a session besides its worker.
pub struct SessionEntry {
    pub id: String,
    pub scene: String,
    /// Folder of the scene file, where its animations live (`None` for inline scenes).
    pub scene_dir: Option<PathBuf>,
    /// The scene's load report.
    pub warnings: Vec<String>,
    /// A glTF scene's own animations, which `play` finds by name.
    pub animations: Vec<(String, crate::scene::animation::Animation)>,
    pub settings: SessionSettings,
    /// The number of its first tick: 0, or the snapshot's tick for a restored session.
    pub first_tick: u64,
    /// Milliseconds after the server's start of the last request or WebSocket message.
    pub(super) last_active: AtomicU64,
    pub handle: SessionHandle,
    /// Its place in the session count, released when the entry drops.
    pub(super) _reservation: Reservation,
}

/// What the live sessions and those being created hold: a count and estimated bytes.
#[derive(Debug, Default)]
pub(super) struct Reserved {
    pub(super) sessions: usize,
    pub(super) bytes: u64,
}

/// A session's place among `max_sessions`, taken before its scene is loaded (so concurrent
/// creations cannot exceed the limit) and given back on drop, whether the creation failed or
/// the session was deleted.
pub struct Reservation {
    pub(super) table: Arc<std::sync::Mutex<Reserved>>,
}

impl Reservation {
    /// Reserves `bytes` of the server's memory budget unless its total would exceed `limit`.
    pub(super) fn memory(&self, bytes: u64, limit: u64) -> Result<MemoryReservation, ApiError> {
        let mut held = MemoryReservation { table: self.table.clone(), bytes: 0 };
        held.resize(bytes, limit)?;
        Ok(held)
    }
}

impl Drop for Reservation {
    fn drop(&mut self) {
        if let Ok(mut r) = self.table.lock() {
            r.sessions -= 1;
        }
    }
}

/// A session's estimated bytes in the server's memory budget. Its worker holds it with the
/// session, so the bytes come back when the session fails, not only when it is deleted.
pub struct MemoryReservation {
    table: Arc<std::sync::Mutex<Reserved>>,
    bytes: u64,
}

impl MemoryReservation {
    /// Holds `bytes` instead of what it holds, unless the server's total would then exceed
    /// `limit` (429 `server_memory_full`, holding what it held). Returns the bytes held before.
    pub(super) fn resize(&mut self, bytes: u64, limit: u64) -> Result<u64, ApiError> {
        let mut r = self.table.lock().map_err(|_| ApiError::internal("reservation lock poisoned"))?;
        let others = r.bytes - self.bytes;
        if others.saturating_add(bytes) > limit {
            return Err(ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "server_memory_full",
                format!(
                    "the session would hold about {} MiB; the server's other sessions already hold {} of its {} MiB (--server-memory)",
                    bytes >> 20,
                    others >> 20,
                    limit >> 20
                ),
            ));
        }
        r.bytes = others + bytes;
        Ok(std::mem::replace(&mut self.bytes, bytes))
    }
}

impl Drop for MemoryReservation {
    fn drop(&mut self) {
        if let Ok(mut r) = self.table.lock() {
            r.bytes -= self.bytes;
        }
    }
}

pub struct AppState {
    pub config: ServerConfig,
    pub metrics: Arc<Metrics>,
    pub device: Device,
    pub pool: Arc<rayon::ThreadPool>,
    /// Round-robin turns on the pool for every session's ticks.
    pub turns: Arc<super::turns::Turns>,
    /// Open WebSockets, at most `max_connections` (an upgraded socket has left hyper's
    /// connection count).
    pub sockets: Arc<tokio::sync::Semaphore>,
    pub sessions: RwLock<HashMap<String, Arc<SessionEntry>>>,
    pub(super) reserved: Arc<std::sync::Mutex<Reserved>>,
    pub(super) next_id: AtomicU64,
    /// The clock of every session's `last_active`.
    started: std::time::Instant,
    /// Flips to true when the server begins shutting down; WebSocket loops watch it.
    pub shutting_down: tokio::sync::watch::Sender<bool>,
    /// Set on SIGTERM ([`super::drain`]): creates are refused with 503, `/healthz` says
    /// `draining`, and the sessions go on being served until the grace period ends.
    pub draining: std::sync::atomic::AtomicBool,
}

/// A bundled scene name: letters, digits, `-` and `_`; no path separators.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty() && name.len() <= 64 && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

/// A scene's name: `NAME` (the file `NAME.json`), a glTF file's name `NAME.glb` /
/// `NAME.gltf`, or an uploaded archive's `NAME.zip`, with `NAME` a [`valid_name`].
pub fn valid_scene_name(name: &str) -> bool {
    match name.rsplit_once('.') {
        Some((stem, "glb" | "gltf" | "zip")) => valid_name(stem),
        Some(_) => false,
        None => valid_name(name),
    }
}

/// The file of a scene named as [`valid_scene_name`] says, if it exists in `root` (for an
/// uploaded archive, the glTF file inside its folder).
pub fn bundled_scene_file(root: &std::path::Path, name: &str) -> Option<PathBuf> {
    if !valid_scene_name(name) {
        return None;
    }
    if name.ends_with(".zip") {
        return super::uploads::store::zip_scene_file(root, name);
    }
    let file = if name.contains('.') { name.to_string() } else { format!("{name}.json") };
    Some(root.join(file)).filter(|p| p.is_file())
}

impl AppState {
    pub fn new(config: ServerConfig) -> Result<AppState, crate::engine::EngineError> {
        let pool = Arc::new(crate::engine::thread_pool(config.threads)?);
        let device = Device::with_isa(config.threads, config.isa)?;
        let (shutting_down, _) = tokio::sync::watch::channel(false);
        let sockets = config.limits.max_connections;
        Ok(AppState {
            config,
            metrics: Arc::new(Metrics::default()),
            device,
            pool,
            turns: Arc::default(),
            sockets: Arc::new(tokio::sync::Semaphore::new(sockets)),
            sessions: RwLock::new(HashMap::new()),
            reserved: Arc::default(),
            next_id: AtomicU64::new(1),
            started: std::time::Instant::now(),
            shutting_down,
            draining: Default::default(),
        })
    }

    /// The session `id`, marked active now (every route and WebSocket message comes here).
    pub fn session(&self, id: &str) -> Result<Arc<SessionEntry>, ApiError> {
        let entry = self
            .sessions
            .read()
            .map_err(|_| ApiError::internal("session table lock poisoned"))?
            .get(id)
            .cloned()
            .ok_or_else(|| ApiError::not_found(format!("no session '{id}'")))?;
        self.touch(&entry);
        Ok(entry)
    }

    /// Marks `entry` active now.
    pub fn touch(&self, entry: &SessionEntry) {
        entry.last_active.store(self.now_ms(), Ordering::Relaxed);
    }

    pub(super) fn now_ms(&self) -> u64 {
        self.started.elapsed().as_millis() as u64
    }

    /// Deletes every session idle for longer than `session_idle` (blocking: call from
    /// `spawn_blocking`). Returns the ids it deleted.
    pub fn expire_idle_blocking(&self) -> Vec<String> {
        let idle = self.config.limits.session_idle.as_millis() as u64;
        let now = self.now_ms();
        let expired: Vec<String> = match self.sessions.read() {
            Ok(s) => s
                .values()
                .filter(|e| now.saturating_sub(e.last_active.load(Ordering::Relaxed)) > idle)
                .map(|e| e.id.clone())
                .collect(),
            Err(_) => return Vec::new(),
        };
        for id in &expired {
            if self.remove_session_blocking(id).is_ok() {
                self.metrics.sessions_expired.fetch_add(1, Ordering::Relaxed);
                tracing::info!(target: "relume::server", "session {id} expired after {} s idle", idle / 1000);
            }
        }
        expired
    }

    /// Bytes the live sessions hold in the server's memory budget (their estimates).
    pub fn reserved_bytes(&self) -> u64 {
        self.reserved.lock().map(|r| r.bytes).unwrap_or(0)
    }

    /// Whether this node is draining (SIGTERM): it takes no new sessions.
    pub fn is_draining(&self) -> bool {
        self.draining.load(Ordering::Relaxed)
    }

    /// 503 with `Retry-After` while draining: another node should take the session.
    pub fn refuse_if_draining(&self) -> Result<(), ApiError> {
        if self.is_draining() {
            return Err(ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "draining",
                format!("node '{}' is draining before it shuts down and takes no new sessions: retry, and the proxy will send you to another node", self.config.node),
            ));
        }
        Ok(())
    }

    pub fn session_count(&self) -> usize {
        self.sessions.read().map(|s| s.len()).unwrap_or(0)
    }

    /// Bundled scenes (`NAME.json`) with their animations (`NAME*.anim.json`), glTF scenes
    /// (`NAME.glb`, `NAME.gltf`, listed by file name) with the animations they hold, and
    /// uploads (`NAME.glb`, `NAME.zip`) with their sizes and triangle counts from their records.
    /// Hidden names (uploads being received, records) are not scenes.
    pub fn list_scenes(&self) -> Vec<SceneEntry> {
        let root = &self.config.scenes_root;
        let mut names: Vec<String> = Vec::new();
        let mut anims: Vec<String> = Vec::new();
        let mut files: Vec<SceneEntry> = Vec::new();
        for entry in std::fs::read_dir(root).into_iter().flatten().flatten() {
            let file = entry.file_name().to_string_lossy().to_string();
            if file.starts_with('.') {
                continue;
            }
            if let Some(record) = super::uploads::store::read_record(root, &file) {
                files.push(SceneEntry::uploaded(record));
            } else if let Some(a) = file.strip_suffix(".anim.json") {
                anims.push(a.to_string());
            } else if let Some(s) = file.strip_suffix(".json") {
                names.push(s.to_string());
            } else if valid_scene_name(&file) && crate::scene::gltf::is_gltf_path(std::path::Path::new(&file)) {
                files.push(SceneEntry::bundled(file.clone(), self.gltf_animation_names(&entry.path())));
            }
        }
        names.sort();
        anims.sort();
        let mut out: Vec<SceneEntry> = names
            .into_iter()
            .map(|name| {
                let animations =
                    anims.iter().filter(|a| *a == &name || a.starts_with(&format!("{name}-"))).cloned().collect();
                SceneEntry::bundled(name, animations)
            })
            .collect();
        out.extend(files);
        out.sort_by(|a, b| a.name.cmp(&b.name));
        out
    }

    /// The names of a bundled glTF file's animations (none if it does not load).
    fn gltf_animation_names(&self, path: &std::path::Path) -> Vec<String> {
        let options =
            crate::scene::gltf::ImportOptions { budget: self.config.limits.scene_budget(), ..Default::default() };
        match crate::scene::gltf::import_file(path, &self.config.scenes_root, &options) {
            Ok(imported) => imported.animations.into_iter().map(|(name, _)| name).collect(),
            Err(e) => {
                tracing::warn!("{}: {e}", path.display());
                Vec::new()
            }
        }
    }

    /// Removes a session and stops its worker (blocking: call from `spawn_blocking`).
    pub fn remove_session_blocking(&self, id: &str) -> Result<(), ApiError> {
        let entry = self
            .sessions
            .write()
            .map_err(|_| ApiError::internal("session table lock poisoned"))?
            .remove(id)
            .ok_or_else(|| ApiError::not_found(format!("no session '{id}'")))?;
        entry.handle.shutdown_blocking();
        Ok(())
    }

    /// Stops every session (blocking).
    pub fn drain_blocking(&self) {
        let all: Vec<Arc<SessionEntry>> =
            self.sessions.write().map(|mut s| s.drain().map(|(_, e)| e).collect()).unwrap_or_default();
        for e in all {
            e.handle.shutdown_blocking();
        }
    }
}

pub fn links(id: &str) -> SessionLinks {
    SessionLinks {
        frame: format!("/v1/sessions/{id}/frame.png"),
        ws: format!("/v1/sessions/{id}/ws"),
        edits: format!("/v1/sessions/{id}/edits"),
        tick: format!("/v1/sessions/{id}/tick"),
        stats: format!("/v1/sessions/{id}/stats"),
    }
}

pub fn view(e: &SessionEntry) -> SessionView {
    let last_stats = e.handle.history.lock().ok().and_then(|h| h.back().cloned());
    let failure = e.handle.failure();
    let running = e.handle.running();
    SessionView {
        id: e.id.clone(),
        scene: e.scene.clone(),
        technique: running.technique,
        width: e.settings.width,
        height: e.settings.height,
        seed: e.settings.seed,
        tick_hz: e.settings.tick_hz,
        denoise: running.denoise,
        ticks: last_stats.as_ref().map_or(e.first_tick, |s| s.tick + 1),
        state: if failure.is_some() { "failed".into() } else { "running".into() },
        failure,
        last_stats,
        warnings: e.warnings.clone(),
        animations: e.animations.iter().map(|(name, _)| name.clone()).collect(),
        links: links(&e.id),
    }
}

#[cfg(test)]
#[path = "state_tests.rs"]
mod tests;
