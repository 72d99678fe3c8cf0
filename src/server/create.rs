//! Creating a session: from a bundled scene's name, an inline scene document, or a snapshot
//! another node took (`snapshot.rs`). Every path is checked against the same [`Limits`]
//! (resolution, spp, photon paths, tick rate, estimated memory) and the same scene
//! confinement before anything is built; a creation holds its place among `max_sessions`
//! from the start, so concurrent creations cannot exceed it.
//!
//! [`Limits`]: super::Limits
use super::error::ApiError;
use super::protocol::{CreateSession, PlayingAnimation, SessionView};
use super::state::{
    bundled_scene_file, valid_scene_name, view, AppState, Limits, Reservation, Running, SessionEntry, SessionSettings,
    MIN_TICK_HZ,
};
use super::worker::{SessionHandle, WorkerContext};
use crate::engine::{Progress, Session};
use crate::film::DenoiseError;
use crate::scene::animation::Animation;
use crate::scene::{LoadedScene, Scene, SceneError};
use crate::technique::{path::PathConfig, TechniqueConfig, TechniqueError};
use axum::http::StatusCode;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// A session about to start: its scene loaded, its request parsed, not yet checked against
/// the limits.
pub(super) struct Plan {
    pub scene_name: String,
    /// Folder of the scene file, where its animations live (`None` for inline scenes).
    pub scene_dir: Option<PathBuf>,
    pub scene: Scene,
    pub running: Running,
    pub settings: SessionSettings,
    /// A restore: where the snapshot's session stood, and what it was playing.
    pub resume: Option<(Progress, Option<PlayingAnimation>)>,
    /// Prefix of the fields errors name: `""`, or `"snapshot."` for a restore.
    pub field: &'static str,
    /// The scene's load report (what a glTF file held that relume reads only in part).
    pub warnings: Vec<String>,
    /// A glTF scene's own animations, by name.
    pub animations: Vec<(String, Animation)>,
}

/// A scene sent as base64 binary glTF: decoded and imported within the limits.
fn inline_glb(
    glb: &str,
    root: &std::path::Path,
    options: &crate::scene::gltf::ImportOptions,
) -> Result<LoadedScene, ApiError> {
    use base64::Engine;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(glb.trim())
        .map_err(|e| ApiError::invalid(format!("scene_glb: not base64: {e}")))?;
    let imported = crate::scene::gltf::import_slice(&bytes, None, options).map_err(|e| scene_error("scene_glb.", e))?;
    Scene::from_loaded_desc(imported.desc, (root, root), options, imported.warnings, imported.animations)
        .map_err(|e| scene_error("scene_glb: ", e))
}

/// The denoiser could not start: 422 when this build lacks it, 503 when OIDN is missing.
pub(super) fn denoise_error(e: crate::engine::EngineError) -> ApiError {
    match e {
        crate::engine::EngineError::Denoise(d @ DenoiseError::NotBuilt) => ApiError::invalid(d.to_string()),
        crate::engine::EngineError::Denoise(d @ DenoiseError::Unavailable(_)) => {
            ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "denoise_unavailable", d.to_string())
        }
        other => ApiError::internal(other.to_string()),
    }
}

/// A scene that failed to load: 413 over the budget, 422 otherwise; `prefix` names where.
pub(super) fn scene_error(prefix: &str, e: SceneError) -> ApiError {
    match e {
        SceneError::TooLarge { .. } => ApiError::too_large(format!("{prefix}{e}")),
        _ => ApiError::invalid(format!("{prefix}{e}")),
    }
}

impl AppState {
    /// Loads, checks against the limits and starts a session, or restores one from a
    /// snapshot. CPU-heavy: call from `spawn_blocking`.
    pub fn create_session(&self, mut req: CreateSession) -> Result<SessionView, ApiError> {
        let reservation = self.reserve_session()?;
        let plan = match req.snapshot.take() {
            Some(snapshot) => {
                let extra = req.fields_besides_snapshot();
                if !extra.is_empty() {
                    return Err(ApiError::invalid(format!(
                        "{}: a restore takes only 'snapshot', which carries them",
                        extra.join(", ")
                    )));
                }
                self.plan_restore(*snapshot)?
            }
            None => self.plan_new(req)?,
        };
        self.start(plan, reservation)
    }

    /// A new session from a bundled scene's name, an inline scene document, or an inline
    /// binary glTF (`scene_glb`, base64).
    fn plan_new(&self, req: CreateSession) -> Result<Plan, ApiError> {
        let root = &self.config.scenes_root;
        let options = crate::scene::gltf::ImportOptions {
            budget: self.config.limits.scene_budget(),
            max_buffer_bytes: self.config.limits.max_body_bytes as u64,
            environment: req.environment,
            ..Default::default()
        };
        let (scene_name, scene_dir, loaded) = match (&req.scene, &req.scene_glb) {
            (Some(_), Some(_)) => return Err(ApiError::invalid("scene_glb: give either scene or scene_glb, not both")),
            (None, Some(glb)) => ("inline".to_string(), None, inline_glb(glb, root, &options)?),
            (Some(serde_json::Value::String(name)), None) => {
                if !valid_scene_name(name) {
                    return Err(ApiError::invalid(format!(
                        "scene: '{name}' is not a scene name (letters, digits, '-' and '_', or a .glb/.gltf file name)"
                    )));
                }
                let Some(path) = bundled_scene_file(root, name) else {
                    return Err(ApiError::not_found(format!("scene: no bundled scene '{name}' (see GET /v1/scenes)")));
                };
                let loaded = Scene::load_file(&path, root, &options)
                    .map_err(|e| scene_error(&format!("scene '{name}': "), e))?;
                (name.clone(), Some(root.clone()), loaded)
            }
            (Some(value @ serde_json::Value::Object(_)), None) => {
                let desc = crate::scene::load::parse_json(&value.to_string())
                    .map_err(|e| ApiError::invalid(format!("scene.{e}")))?;
                let loaded = Scene::from_loaded_desc(desc, (root, root), &options, Vec::new(), Vec::new())
                    .map_err(|e| scene_error("scene.", e))?;
                ("inline".to_string(), None, loaded)
            }
            (Some(_), None) => {
                return Err(ApiError::invalid("scene: expected a scene name (string) or an inline scene (object)"))
            }
            (None, None) => {
                return Err(ApiError::invalid(
                    "scene: missing: give a scene name, an inline scene, scene_glb, or a snapshot",
                ))
            }
        };
        let LoadedScene { scene, warnings, animations } = loaded;
        let (width, height) = (req.width.unwrap_or(scene.camera.width), req.height.unwrap_or(scene.camera.height));
        let technique = req.technique.unwrap_or(TechniqueConfig::Path(PathConfig::default()));
        let running = Running { technique, denoise: req.denoise };
        let settings = SessionSettings { width, height, seed: req.seed, tick_hz: req.tick_hz };
        Ok(Plan { scene_name, scene_dir, scene, running, settings, resume: None, field: "", warnings, animations })
    }

    /// Checks a plan against the limits, builds its session and starts its worker.
    fn start(&self, mut plan: Plan, reservation: Reservation) -> Result<SessionView, ApiError> {
        self.check_plan(&plan)?;
        plan.scene.set_resolution(plan.settings.width, plan.settings.height);
        let limits = &self.config.limits;
        let memory_bytes = session_bytes(limits, &plan.running, &plan.settings, &plan.scene, plan.field)?;
        let memory = reservation.memory(memory_bytes, limits.server_memory)?;
        let f = plan.field;
        let settings = plan.settings;
        let mut session = Session::new(plan.scene, &plan.running.technique, settings.seed, &self.device)
            .map_err(|e| engine_error(f, e))?;
        session.set_denoise(plan.running.denoise).map_err(denoise_error)?;
        let (progress, playing) = plan.resume.unzip();
        let first_tick = progress.as_ref().map_or(0, |p| p.tick);
        if let Some(progress) = progress {
            session.resume(progress).map_err(|e| ApiError::invalid(format!("snapshot.pending_edits: {e}")))?;
        }
        let id = self.new_session_id();
        let context = WorkerContext {
            pool: self.pool.clone(),
            turns: self.turns.clone(),
            metrics: self.metrics.clone(),
            max_tick_hz: self.config.limits.max_tick_hz,
        };
        let handle = SessionHandle::spawn(&id, session, memory, settings.tick_hz, playing.flatten(), context)
            .map_err(|e| ApiError::internal(format!("cannot start the session thread: {e}")))?;
        let entry = Arc::new(SessionEntry {
            id: id.clone(),
            scene: plan.scene_name,
            scene_dir: plan.scene_dir,
            warnings: plan.warnings,
            animations: plan.animations,
            settings,
            first_tick,
            last_active: AtomicU64::new(self.now_ms()),
            handle,
            _reservation: reservation,
        });
        self.sessions.write().map_err(|_| ApiError::internal("session table lock poisoned"))?.insert(id, entry.clone());
        self.metrics.sessions_created.fetch_add(1, Ordering::Relaxed);
        Ok(view(&entry))
    }

    /// `NODE.sN-XXXXXXXX`: the node routes it, `N` counts this process's sessions, and the
    /// salt keeps ids from repeating across restarts of a node.
    fn new_session_id(&self) -> String {
        let n = self.next_id.fetch_add(1, Ordering::Relaxed);
        let salt = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0);
        format!("{}.s{n}-{:08x}", self.config.node, crate::core::rng::mix64(salt ^ n) as u32)
    }

    /// The resolution, spp, photon paths and tick rate against the limits.
    fn check_plan(&self, plan: &Plan) -> Result<(), ApiError> {
        let limits = &self.config.limits;
        let (f, settings) = (plan.field, &plan.settings);
        let (w, h) = (settings.width, settings.height);
        if w == 0 || h == 0 {
            return Err(ApiError::invalid(format!("{f}width/height: must be at least 1")));
        }
        if w > limits.max_side || h > limits.max_side || u64::from(w) * u64::from(h) > limits.max_pixels {
            return Err(ApiError::too_large(format!(
                "{f}width/height: {w}x{h} exceeds the limit ({} per side, {} pixels)",
                limits.max_side, limits.max_pixels
            )));
        }
        check_technique(limits, &plan.running.technique, f)?;
        match settings.tick_hz {
            Some(hz) if !(hz.is_finite() && (MIN_TICK_HZ..=limits.max_tick_hz).contains(&hz)) => {
                Err(ApiError::invalid(format!(
                    "{f}tick_hz: must lie in [{MIN_TICK_HZ}, {}] ticks per second",
                    limits.max_tick_hz
                )))
            }
            _ => Ok(()),
        }
    }

    /// Takes a place among `max_sessions` atomically (429 when there is none).
    fn reserve_session(&self) -> Result<Reservation, ApiError> {
        let max = self.config.limits.max_sessions;
        let mut r = self.reserved.lock().map_err(|_| ApiError::internal("reservation lock poisoned"))?;
        if r.sessions >= max {
            return Err(ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "too_many_sessions",
                format!("the server holds its maximum of {max} sessions"),
            ));
        }
        r.sessions += 1;
        Ok(Reservation { table: self.reserved.clone() })
    }
}

/// A technique's spp per tick and photon paths against the limits (413 naming the field under
/// `f`).
pub(super) fn check_technique(limits: &Limits, technique: &TechniqueConfig, f: &str) -> Result<(), ApiError> {
    if technique.spp_per_tick() > limits.max_spp_per_tick {
        return Err(ApiError::too_large(format!(
            "{f}technique.spp: {} exceeds the limit of {} per tick",
            technique.spp_per_tick(),
            limits.max_spp_per_tick
        )));
    }
    if technique.photon_paths() > limits.max_photon_paths {
        return Err(ApiError::too_large(format!(
            "{f}technique.paths: {} exceeds the limit of {} photon paths per session",
            technique.photon_paths(),
            limits.max_photon_paths
        )));
    }
    Ok(())
}

/// A session's estimated resident bytes (technique, film and denoiser) running `running` with
/// `settings` on `scene`, refused with 413 naming the technique's sizing field (or `denoise`)
/// when over `session_memory`.
pub(super) fn session_bytes(
    limits: &Limits,
    running: &Running,
    settings: &SessionSettings,
    scene: &Scene,
    f: &str,
) -> Result<u64, ApiError> {
    let limit = limits.session_memory;
    let pixels = u64::from(settings.width) * u64::from(settings.height);
    let estimate = running.technique.resident_estimate(scene, pixels).map_err(|e| match e {
        TechniqueError::TooLarge { .. } => ApiError::too_large(format!("{f}technique.{e}")),
        other => ApiError::invalid(format!("{f}technique: {other}")),
    })?;
    let film = pixels * crate::film::Film::BYTES_PER_PIXEL;
    let denoiser = running.denoise.map_or(0, |d| d.resident_estimate(pixels));
    let bytes = estimate.bytes.saturating_add(film).saturating_add(denoiser);
    if bytes > limit && denoiser > 0 && estimate.bytes.saturating_add(film) <= limit {
        return Err(ApiError::too_large(format!(
            "{f}denoise: the session would hold about {} MiB with its denoiser, above the {} MiB a session may hold (--session-memory)",
            bytes >> 20,
            limit >> 20
        )));
    }
    if bytes > limit {
        return Err(ApiError::too_large(format!(
            "{f}technique.{}: the session would hold about {} MiB, above the {} MiB a session may hold (--session-memory)",
            estimate.field,
            bytes >> 20,
            limit >> 20
        )));
    }
    Ok(bytes)
}

/// A session or technique that could not be built: 422 for a configuration it refuses, 413
/// past a size, 500 otherwise; `f` prefixes the field.
pub(super) fn engine_error(f: &str, e: crate::engine::EngineError) -> ApiError {
    match e {
        crate::engine::EngineError::Technique(t @ TechniqueError::InvalidConfig { .. }) => {
            ApiError::invalid(format!("{f}technique: {t}"))
        }
        crate::engine::EngineError::Technique(t @ TechniqueError::TooLarge { .. }) => {
            ApiError::too_large(format!("{f}technique.{t}"))
        }
        crate::engine::EngineError::Scene(s) => ApiError::invalid(format!("{f}scene: {s}")),
        other => ApiError::internal(other.to_string()),
    }
}
