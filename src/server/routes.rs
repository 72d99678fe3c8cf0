//! HTTP handlers. Each maps client faults to a 4xx `{error, detail}` and never panics.
use super::encoded::EncodingKey;
use super::error::ApiError;
use super::protocol::{
    CreateSession, EditBatch, SceneList, SessionList, SessionView, StatsHistory, TechniqueEntry, TechniqueList,
    TickDone, UpdateSession,
};
use super::state::{view, AppState, Running, SessionEntry};
use super::worker::PublishedFrame;
use crate::film::{check_exposure, ImageFormat};
use axum::body::{Body, Bytes};
use axum::extract::{FromRequest, Path, Query, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::de::DeserializeOwned;
use serde::Deserialize;
use std::sync::Arc;
use std::time::Duration;

pub type Shared = Arc<AppState>;

/// A JSON body whose errors name the field at fault: 400 for malformed JSON, 422 for a valid
/// document of the wrong shape, 413 past the body limit.
pub struct ApiJson<T>(pub T);

impl<T: DeserializeOwned, S: Send + Sync> FromRequest<S> for ApiJson<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        // A body must say it is JSON: a web page can send `text/plain` to a loopback server
        // without a CORS preflight, but not `application/json`.
        let json = req
            .headers()
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.split(';').next())
            .is_some_and(|m| m.trim().eq_ignore_ascii_case("application/json"));
        if !json {
            return Err(ApiError::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported_media_type",
                "content-type: request bodies must be application/json",
            ));
        }
        let bytes = Bytes::from_request(req, state).await.map_err(|e| {
            if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::too_large(format!("request body: {}", e.body_text()))
            } else {
                ApiError::bad_request(format!("request body: {}", e.body_text()))
            }
        })?;
        parse_body(&bytes).map(ApiJson)
    }
}

/// Parses JSON with the path of the failing field in the error.
pub fn parse_body<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let de = &mut serde_json::Deserializer::from_slice(bytes);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let field = if path.is_empty() || path == "." { String::new() } else { format!("{path}: ") };
        match inner.classify() {
            serde_json::error::Category::Syntax
            | serde_json::error::Category::Eof
            | serde_json::error::Category::Io => {
                ApiError::new(StatusCode::BAD_REQUEST, "malformed_json", format!("{field}{inner}"))
            }
            serde_json::error::Category::Data => ApiError::invalid(format!("{field}{inner}")),
        }
    })
}

/// `ok` while the node takes sessions, then the versions it runs (`relume X`, `embree Y
/// (ISA)`); 503 `draining` (with `Retry-After`) once it drains, so a proxy's health check stops
/// sending it new sessions while its own still reach it.
pub async fn healthz(State(s): State<Shared>) -> Result<String, ApiError> {
    s.refuse_if_draining()?;
    Ok(format!("ok\nrelume {}\nembree {} ({})\n", env!("CARGO_PKG_VERSION"), s.device.version(), s.device.isa()))
}

pub async fn metrics(State(s): State<Shared>) -> Response {
    let now = super::metrics::Gauges {
        embree: s.device.version(),
        isa: s.device.isa(),
        sessions: s.session_count(),
        reserved_bytes: s.reserved_bytes(),
        draining: s.is_draining(),
    };
    let body = s.metrics.render(&now);
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], body).into_response()
}

pub async fn list_scenes(State(s): State<Shared>) -> Json<SceneList> {
    Json(SceneList { scenes: s.list_scenes() })
}

/// `GET /v1/techniques`: the registry, each entry with its defaults and this server's limits
/// on its parameters.
pub async fn list_techniques(State(s): State<Shared>) -> Json<TechniqueList> {
    let limits = &s.config.limits;
    let techniques = crate::technique::registry::REGISTRY
        .iter()
        .map(|d| TechniqueEntry {
            description: **d,
            defaults: crate::technique::registry::default_config(d.id)
                .and_then(|c| serde_json::to_value(c).ok())
                .unwrap_or_default(),
        })
        .collect();
    Json(TechniqueList {
        techniques,
        max_spp_per_tick: limits.max_spp_per_tick,
        max_photon_paths: limits.max_photon_paths,
    })
}

pub async fn create_session(
    State(s): State<Shared>,
    ApiJson(req): ApiJson<CreateSession>,
) -> Result<(StatusCode, Json<SessionView>), ApiError> {
    s.refuse_if_draining()?;
    let state = s.clone();
    let created = tokio::task::spawn_blocking(move || state.create_session(req).map(|v| Created::new(state, v)))
        .await
        .map_err(|e| ApiError::internal(e.to_string()))??;
    Ok((StatusCode::CREATED, Json(created.keep())))
}

/// A session just created, on its way to the client that asked for it. If the request is
/// dropped first (it timed out with 408, or the client went away), nobody will ever learn its
/// id, so dropping this deletes it instead of leaving it to idle expiry.
struct Created {
    view: SessionView,
    state: Shared,
    kept: bool,
}

impl Created {
    fn new(state: Shared, view: SessionView) -> Created {
        Created { view, state, kept: false }
    }

    /// The client has it: keep the session.
    fn keep(mut self) -> SessionView {
        self.kept = true;
        self.view.clone()
    }
}

impl Drop for Created {
    fn drop(&mut self) {
        if !self.kept {
            let id = self.view.id.clone();
            tracing::info!(target: "relume::server", "session {id} deleted: its creation request was dropped");
            // Stopping the worker joins its thread: not on the async runtime.
            let state = self.state.clone();
            std::thread::spawn(move || state.remove_session_blocking(&id));
        }
    }
}

pub async fn list_sessions(State(s): State<Shared>) -> Result<Json<SessionList>, ApiError> {
    let mut sessions: Vec<SessionView> = s
        .sessions
        .read()
        .map_err(|_| ApiError::internal("session table lock poisoned"))?
        .values()
        .map(|e| view(e))
        .collect();
    sessions.sort_by(|a, b| a.id.cmp(&b.id));
    Ok(Json(SessionList { sessions }))
}

pub async fn get_session(State(s): State<Shared>, Path(id): Path<String>) -> Result<Json<SessionView>, ApiError> {
    let entry = s.session(&id)?;
    Ok(Json(view(&entry)))
}

/// Switches the session's technique or denoiser from its next tick on, keeping its scene as
/// edited and its queued edits (`PATCH /v1/sessions/{id}`). What it will run is checked against
/// the limits as a create is (spp, photon paths, `--session-memory`), and the session's share
/// of `--server-memory` is resized to it; what equals what is running changes nothing.
pub async fn update_session(
    State(s): State<Shared>,
    Path(id): Path<String>,
    ApiJson(req): ApiJson<UpdateSession>,
) -> Result<Json<SessionView>, ApiError> {
    let entry = s.session(&id)?;
    update(&s, &entry, req).await?;
    Ok(Json(view(&entry)))
}

/// Applies `req` to the session of `entry` between its ticks, checked against `s`'s limits: the
/// work of `PATCH /v1/sessions/{id}` and of the WebSocket's `update`. Returns what the session
/// runs from its next tick on.
pub async fn update(s: &Shared, entry: &SessionEntry, req: UpdateSession) -> Result<Running, ApiError> {
    if req.is_empty() {
        return Err(ApiError::invalid("technique, denoise: nothing to change; give either or both"));
    }
    let limits = s.config.limits.clone();
    if let Some(technique) = &req.technique {
        super::create::check_technique(&limits, technique, "")?;
    }
    let settings = entry.settings.clone();
    let server_memory = limits.server_memory;
    let bytes: super::worker::SessionBytes =
        Box::new(move |scene, running| super::create::session_bytes(&limits, running, &settings, scene, ""));
    entry.handle.update(req, bytes, server_memory).await
}

pub async fn delete_session(State(s): State<Shared>, Path(id): Path<String>) -> Result<StatusCode, ApiError> {
    s.session(&id)?;
    let state = s.clone();
    tokio::task::spawn_blocking(move || state.remove_session_blocking(&id))
        .await
        .map_err(|e| ApiError::internal(e.to_string()))??;
    Ok(StatusCode::NO_CONTENT)
}

pub async fn get_scene(
    State(s): State<Shared>,
    Path(id): Path<String>,
) -> Result<Json<crate::scene::SceneDesc>, ApiError> {
    let entry = s.session(&id)?;
    Ok(Json(entry.handle.scene().await?))
}

/// `?x=&y=` of `GET /v1/sessions/{id}/pick`: a film position in pixels.
#[derive(serde::Deserialize)]
pub struct PickQuery {
    x: f32,
    y: f32,
}

/// What lies under a pixel of the session's frame: `{"hit": false}`, or the object or light
/// with its name, whether it can move, and the world point.
pub async fn pick(
    State(s): State<Shared>,
    Path(id): Path<String>,
    query: Result<axum::extract::Query<PickQuery>, axum::extract::rejection::QueryRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let axum::extract::Query(q) = query.map_err(|e| ApiError::invalid(format!("x, y: {}", e.body_text())))?;
    let entry = s.session(&id)?;
    let (w, h) = (entry.settings.width as f32, entry.settings.height as f32);
    for (field, v, max) in [("x", q.x, w), ("y", q.y, h)] {
        if !(v.is_finite() && (0.0..max).contains(&v)) {
            return Err(ApiError::invalid(format!("{field}: {v} is outside the frame [0, {max})")));
        }
    }
    Ok(Json(match entry.handle.pick(q.x, q.y).await? {
        Some(p) => {
            serde_json::json!({"hit": true, "target": p.target, "name": p.name, "dynamic": p.dynamic, "position": p.position})
        }
        None => serde_json::json!({"hit": false}),
    }))
}

/// The session's snapshot (`proto/snapshot.schema.json`), to restore with `POST /v1/sessions`.
pub async fn get_snapshot(
    State(s): State<Shared>,
    Path(id): Path<String>,
) -> Result<Json<super::protocol::Snapshot>, ApiError> {
    let entry = s.session(&id)?;
    let parts = entry.handle.snapshot().await?;
    Ok(Json(super::snapshot::snapshot_of(&entry, parts)))
}

pub async fn post_edits(
    State(s): State<Shared>,
    Path(id): Path<String>,
    ApiJson(batch): ApiJson<EditBatch>,
) -> Result<Response, ApiError> {
    let entry = s.session(&id)?;
    s.config.limits.check_edit_count("edits", batch.edits.len())?;
    s.metrics.edits_received.fetch_add(batch.edits.len() as u64, std::sync::atomic::Ordering::Relaxed);
    let accepted = entry.handle.edits(batch.edits).await?;
    Ok((StatusCode::ACCEPTED, Json(accepted)).into_response())
}

pub async fn post_tick(State(s): State<Shared>, Path(id): Path<String>) -> Result<Json<TickDone>, ApiError> {
    let entry = s.session(&id)?;
    let stats = entry.handle.tick().await?;
    Ok(Json(TickDone { frame_url: format!("/v1/sessions/{id}/frame.png?tick={}", stats.tick), stats }))
}

/// Shared encoded bytes as a response body, without copying them.
struct ArcBytes(Arc<Vec<u8>>);

impl AsRef<[u8]> for ArcBytes {
    fn as_ref(&self) -> &[u8] {
        self.0.as_slice()
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameQuery {
    pub tick: Option<u64>,
    #[serde(default)]
    pub exposure: Option<f32>,
    /// `false` for the raw image of a denoising session (default: denoised when it denoises).
    #[serde(default)]
    pub denoised: Option<bool>,
}

pub async fn get_frame(
    State(s): State<Shared>,
    Path((id, file)): Path<(String, String)>,
    headers: HeaderMap,
    query: Result<Query<FrameQuery>, axum::extract::rejection::QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query.map_err(|e| ApiError::invalid(format!("query: {}", e.body_text())))?;
    let format = frame_format(&file)?;
    let exposure = q.exposure.unwrap_or(0.0);
    check_exposure(exposure).map_err(|m| ApiError::invalid(format!("exposure: {m}")))?;
    let entry = s.session(&id)?;
    let frame = wait_for_frame(&s, &entry, q.tick).await?;
    let key = EncodingKey::new(&frame, format, q.denoised == Some(false), exposure);
    let etag = HeaderValue::from_str(&key.etag()).map_err(|e| ApiError::internal(e.to_string()))?;
    let mut resp = if headers.get(header::IF_NONE_MATCH) == Some(&etag) {
        // The client holds these bytes already.
        Response::builder()
            .status(StatusCode::NOT_MODIFIED)
            .body(Body::empty())
            .map_err(|e| ApiError::internal(e.to_string()))?
    } else {
        let (metrics, shared, f) = (s.metrics.clone(), entry.clone(), frame.clone());
        let bytes = tokio::task::spawn_blocking(move || shared.handle.encoded.get(&f, key, &metrics))
            .await
            .map_err(|e| ApiError::internal(e.to_string()))?
            .map_err(ApiError::internal)?;
        s.metrics.sent(bytes.len());
        Response::new(Body::from(Bytes::from_owner(ArcBytes(bytes))))
    };
    let h = resp.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(format.mime()));
    // Clients may keep a frame, but must ask again (If-None-Match) before showing it.
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(header::ETAG, etag);
    h.insert("x-relume-tick", HeaderValue::from(frame.tick));
    h.insert("x-relume-accumulation-id", HeaderValue::from(frame.accumulation_id));
    h.insert("x-relume-spp", HeaderValue::from(frame.spp));
    h.insert("x-relume-width", HeaderValue::from(frame.image.width));
    h.insert("x-relume-height", HeaderValue::from(frame.image.height));
    Ok(resp)
}

/// The image format a frame's file name asks for.
fn frame_format(file: &str) -> Result<ImageFormat, ApiError> {
    match file {
        "frame.png" => Ok(ImageFormat::Png),
        "frame.jpg" => Ok(ImageFormat::Jpeg),
        "frame.exr" => Ok(ImageFormat::Exr),
        "frame.f32" => Ok(ImageFormat::F32),
        _ => Err(ApiError::not_found(format!(
            "no resource '{file}' (frames are frame.png, frame.jpg, frame.exr or frame.f32)"
        ))),
    }
}

/// How many ticks a session can run in `wait` at `max_hz` at the most.
fn ticks_within(wait: Duration, max_hz: f32) -> u64 {
    (wait.as_secs_f64() * f64::from(max_hz)).ceil() as u64
}

/// The session's latest frame once it is at least tick `wanted` (any frame when `None`),
/// waiting at most the server's frame wait. A tick the session cannot reach within that wait,
/// even ticking as fast as the server lets it, is refused at once (422 naming `tick`) instead
/// of holding the connection for the whole wait.
async fn wait_for_frame(
    s: &AppState,
    entry: &SessionEntry,
    wanted: Option<u64>,
) -> Result<Arc<PublishedFrame>, ApiError> {
    let mut frames = entry.handle.frames.clone();
    if let Some(t) = wanted {
        let next = frames.borrow().as_ref().map_or(0, |f| f.tick + 1);
        let reachable = next.saturating_add(ticks_within(s.config.limits.frame_wait, s.config.limits.max_tick_hz));
        if t > reachable {
            return Err(ApiError::invalid(format!(
                "tick: {t} cannot arrive within the frame wait ({:?}): the session's next tick is {next}, and it ticks at most {} times a second",
                s.config.limits.frame_wait, s.config.limits.max_tick_hz
            )));
        }
    }
    // Wait (bounded) for the wanted tick; the watch borrow ends inside this block.
    let waited = tokio::time::timeout(s.config.limits.frame_wait, async {
        frames
            .wait_for(|f| match (f, wanted) {
                (Some(f), Some(t)) => f.tick >= t,
                (_, None) => true,
                (None, Some(_)) => false,
            })
            .await
            .map(|f| f.clone())
    })
    .await;
    match waited {
        Ok(Ok(Some(f))) => Ok(f),
        Ok(Ok(None)) => {
            Err(ApiError::not_found("no frame yet: POST .../tick first, or ask for ?tick=0 to wait for the first one"))
        }
        Ok(Err(_)) => Err(match entry.handle.failure() {
            Some(reason) => super::worker::failed(&reason),
            None => ApiError::new(StatusCode::GONE, "session_closed", "the session has shut down"),
        }),
        Err(_) => Err(ApiError::new(
            StatusCode::REQUEST_TIMEOUT,
            "timeout",
            format!("tick {} did not arrive within {:?}", wanted.unwrap_or(0), s.config.limits.frame_wait),
        )),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StatsQuery {
    pub n: Option<usize>,
}

pub async fn get_stats(
    State(s): State<Shared>,
    Path(id): Path<String>,
    query: Result<Query<StatsQuery>, axum::extract::rejection::QueryRejection>,
) -> Result<Json<StatsHistory>, ApiError> {
    let Query(q) = query.map_err(|e| ApiError::invalid(format!("query: {}", e.body_text())))?;
    let n = q.n.unwrap_or(32);
    if n == 0 || n > super::worker::STATS_HISTORY {
        return Err(ApiError::invalid(format!("n: must lie in 1..={}", super::worker::STATS_HISTORY)));
    }
    let entry = s.session(&id)?;
    let history = entry.handle.history.lock().map_err(|_| ApiError::internal("stats lock poisoned"))?;
    let skip = history.len().saturating_sub(n);
    Ok(Json(StatsHistory { stats: history.iter().skip(skip).cloned().collect() }))
}

/// The viewer: plain HTML, CSS and JS embedded in the binary (no build step).
pub async fn viewer_page() -> Response {
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], include_str!("viewer/index.html")).into_response()
}

pub async fn viewer_script() -> Response {
    ([(header::CONTENT_TYPE, "text/javascript; charset=utf-8")], include_str!("viewer/viewer.js")).into_response()
}

/// The JavaScript client module (`clients/js/relume.js`), which the viewer imports.
pub async fn client_module() -> Response {
    ([(header::CONTENT_TYPE, "text/javascript; charset=utf-8")], include_str!("../../clients/js/relume.js"))
        .into_response()
}

pub async fn viewer_style() -> Response {
    ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], include_str!("viewer/viewer.css")).into_response()
}

pub async fn not_found() -> ApiError {
    ApiError::not_found("no such route (see /api/openapi.yaml)")
}
