//! The service: axum HTTP + WebSocket over the engine.
//!
//! Structure (after the axum examples and mini-redis): [`app`] builds the `Router` from shared
//! [`AppState`]; [`run`] serves a bound listener until a shutdown future resolves, then drains
//! every session. `main` only parses flags and calls these.
//!
//! Concurrency: handlers are async and never trace rays; each session's CPU work runs on its own
//! worker thread (`worker/`) inside the shared rayon pool. No lock is held across `.await`.
//! Errors: every client fault is a 4xx JSON `{error, detail}`; internal faults are 500s with a
//! log line. When a token is configured, every `/v1` route requires `Authorization: Bearer`.
mod api_docs;
mod create;
pub mod encoded;
pub mod error;
mod listen;
pub mod metrics;
pub mod mjpeg;
pub mod protocol;
pub mod routes;
pub mod snapshot;
pub mod state;
pub mod turns;
pub mod uploads;
pub mod worker;
pub mod ws;

pub use error::ApiError;
pub use state::{valid_node, Access, AppState, Limits, ServerConfig};

use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::StatusCode;
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, put};
use axum::Router;
use routes::Shared;
use std::future::Future;
use std::sync::Arc;
use tower_http::timeout::TimeoutLayer;

/// Rejects `/v1` requests without the configured bearer token. The token comes in
/// `Authorization: Bearer <token>` (the scheme in any case); `?token=` (percent-decoded) is
/// accepted only on the GETs a browser opens without setting headers: the WebSocket, frames
/// and the MJPEG stream, and is taken out of the query before the handler reads it. Tokens are
/// compared in constant time.
async fn require_token(State(s): State<Shared>, mut req: Request, next: Next) -> Result<Response, ApiError> {
    if let Some(token) = &s.config.token {
        let matches = |t: &[u8]| bool::from(subtle::ConstantTimeEq::ct_eq(t, token.as_bytes()));
        let header_ok = req
            .headers()
            .get(axum::http::header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.trim().split_once(' '))
            .is_some_and(|(scheme, t)| scheme.eq_ignore_ascii_case("bearer") && matches(t.trim().as_bytes()));
        let path = req.uri().path();
        let browser_get = req.method() == axum::http::Method::GET
            && (path.ends_with("/ws")
                || path.ends_with("/stream.mjpeg")
                || path.rsplit('/').next().is_some_and(|f| f.starts_with("frame.")));
        let query_ok = browser_get
            && req
                .uri()
                .query()
                .into_iter()
                .flat_map(|q| q.split('&'))
                .filter_map(|kv| kv.strip_prefix("token="))
                .any(|t| matches(&percent_encoding::percent_decode_str(t).collect::<Vec<u8>>()));
        if !header_ok && !query_ok {
            return Err(ApiError::new(
                StatusCode::UNAUTHORIZED,
                "unauthorized",
                "this server requires 'Authorization: Bearer <token>' (or ?token= on WebSocket, frame and stream URLs)",
            ));
        }
        if query_ok {
            without_token(&mut req);
        }
    }
    Ok(next.run(req).await)
}

/// Drops `token=` from an authorised request's query, so a handler's query parameters (which
/// refuse unknown fields) never see it.
fn without_token(req: &mut Request) {
    let uri = req.uri();
    let Some(query) = uri.query() else { return };
    let kept: Vec<&str> = query.split('&').filter(|kv| !kv.starts_with("token=")).collect();
    let path_and_query =
        if kept.is_empty() { uri.path().to_string() } else { format!("{}?{}", uri.path(), kept.join("&")) };
    let mut parts = uri.clone().into_parts();
    if let Ok(pq) = path_and_query.parse() {
        parts.path_and_query = Some(pq);
        if let Ok(uri) = axum::http::Uri::from_parts(parts) {
            *req.uri_mut() = uri;
        }
    }
}

/// Refuses a `Host` that is not an IP literal, `localhost` or a configured name with 421: a
/// page that rebinds its own DNS name to 127.0.0.1 reaches the server under that name. A
/// request without `Host` (HTTP/1.0) is let through: rebinding needs a name.
async fn check_host(State(s): State<Shared>, req: Request, next: Next) -> Result<Response, ApiError> {
    if let Some(host) = req.headers().get(axum::http::header::HOST) {
        let host = host.to_str().unwrap_or_default();
        let name = host_name(host);
        let allowed = name.eq_ignore_ascii_case("localhost")
            || name.parse::<std::net::IpAddr>().is_ok()
            || s.config.access.hosts.iter().any(|h| h.eq_ignore_ascii_case(name));
        if !allowed {
            return Err(ApiError::new(
                StatusCode::MISDIRECTED_REQUEST,
                "host_not_allowed",
                format!("Host '{host}' is not served here: use an IP address or localhost, or start the server with --allow-host {name}"),
            ));
        }
    }
    Ok(next.run(req).await)
}

/// The name part of a `Host` value: `[::1]:8080` → `::1`, `localhost:80` → `localhost`.
pub fn host_name(host: &str) -> &str {
    match host.strip_prefix('[') {
        Some(rest) => rest.split(']').next().unwrap_or_default(),
        None => host.rsplit_once(':').map_or(host, |(name, _)| name),
    }
}

/// Deletes idle sessions every eighth of `--session-idle` (at least every second) until the
/// server shuts down.
async fn expire_idle(state: Arc<AppState>) {
    let period = (state.config.limits.session_idle / 8).max(std::time::Duration::from_secs(1));
    let mut closing = state.shutting_down.subscribe();
    let mut tick = tokio::time::interval(period);
    loop {
        tokio::select! {
            _ = tick.tick() => {
                let s = state.clone();
                let _ = tokio::task::spawn_blocking(move || s.expire_idle_blocking()).await;
            }
            _ = closing.changed() => return,
        }
    }
}

/// Stamps every answer, errors and CORS answers included, with the node that gave it
/// (`X-Relume-Node`), `X-Content-Type-Options: nosniff` (a browser never guesses a type other
/// than the one sent) and the [`CONTENT_SECURITY_POLICY`].
async fn stamp_response(State(s): State<Shared>, req: Request, next: Next) -> Response {
    let mut resp = next.run(req).await;
    let headers = resp.headers_mut();
    if let Ok(node) = axum::http::HeaderValue::from_str(&s.config.node) {
        headers.insert(NODE_HEADER, node);
    }
    headers.insert(axum::http::header::X_CONTENT_TYPE_OPTIONS, axum::http::HeaderValue::from_static("nosniff"));
    headers.insert(
        axum::http::header::CONTENT_SECURITY_POLICY,
        axum::http::HeaderValue::from_static(CONTENT_SECURITY_POLICY),
    );
    resp
}

/// The viewer loads its script, style, frames and socket from its own origin only, runs no
/// inline script or style attribute, and shows frames as `blob:` images; nothing may frame it.
pub const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; script-src 'self'; style-src 'self'; \
     img-src 'self' blob: data:; connect-src 'self'; object-src 'none'; base-uri 'none'; \
     form-action 'self'; frame-ancestors 'none'";

/// The response header naming the node that answered.
pub const NODE_HEADER: &str = "x-relume-node";

/// Counts every 4xx/5xx answer for `/metrics` by its `error` code ([`error::ErrorCode`]), or,
/// for the few the framework writes itself before any handler runs, by a name for its status.
async fn count_rejections(State(s): State<Shared>, req: Request, next: Next) -> Response {
    let resp = next.run(req).await;
    let status = resp.status();
    if status.is_client_error() || status.is_server_error() {
        let reason = match resp.extensions().get::<error::ErrorCode>() {
            Some(code) => code.0,
            None => match status {
                StatusCode::BAD_REQUEST => "bad_request",
                StatusCode::NOT_FOUND => "not_found",
                StatusCode::METHOD_NOT_ALLOWED => "method_not_allowed",
                StatusCode::PAYLOAD_TOO_LARGE => "too_large",
                StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported_media_type",
                _ if status.is_server_error() => "internal",
                _ => "other",
            },
        };
        s.metrics.reject(reason);
    }
    resp
}

/// Gives every error answer the JSON `{error, detail}` body, including those the framework
/// writes itself as plain text or nothing: 405 (wrong method), 408 (request timeout) and
/// failed WebSocket upgrades (a plain GET on `/ws`).
async fn json_errors(req: Request, next: Next) -> Response {
    let method = req.method().clone();
    let path = req.uri().path().to_string();
    let resp = next.run(req).await;
    let status = resp.status();
    let is_json = resp
        .headers()
        .get(axum::http::header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("application/json"));
    if !(status.is_client_error() || status.is_server_error()) || is_json {
        return resp;
    }
    let (error, detail) = match status {
        StatusCode::METHOD_NOT_ALLOWED => ("method_not_allowed", format!("{method} is not allowed on {path}")),
        StatusCode::REQUEST_TIMEOUT => {
            ("timeout", format!("{method} {path} took longer than the server's request timeout"))
        }
        _ if path.ends_with("/ws") => {
            ("upgrade_failed", format!("{path} is a WebSocket: connect with an Upgrade request"))
        }
        _ => ("error", format!("{method} {path}: {}", status.canonical_reason().unwrap_or("error"))),
    };
    ApiError::new(status, error, detail).into_response()
}

/// The HTTP application.
pub fn app(state: Arc<AppState>) -> Router {
    let limits = state.config.limits.clone();
    let v1 = Router::new()
        .route("/scenes", get(routes::list_scenes))
        .route("/techniques", get(routes::list_techniques))
        .route("/sessions", post(routes::create_session).get(routes::list_sessions))
        .route("/sessions/{id}", get(routes::get_session).patch(routes::update_session).delete(routes::delete_session))
        .route("/sessions/{id}/scene", get(routes::get_scene))
        .route("/sessions/{id}/edits", post(routes::post_edits))
        .route("/sessions/{id}/tick", post(routes::post_tick))
        .route("/sessions/{id}/stats", get(routes::get_stats))
        .route("/sessions/{id}/snapshot", get(routes::get_snapshot))
        .route("/sessions/{id}/pick", get(routes::pick))
        .route("/sessions/{id}/ws", get(ws::upgrade))
        .route("/sessions/{id}/stream.mjpeg", get(mjpeg::stream))
        .route("/sessions/{id}/{file}", get(routes::get_frame))
        .layer(middleware::from_fn_with_state(state.clone(), require_token));
    // Uploads stream any size up to --upload-limit and bound their own pauses
    // (uploads::receive), so neither the body limit nor the whole-request timeout applies.
    let uploads = Router::new()
        .route("/v1/scenes/{name}", put(uploads::put_scene).delete(uploads::delete_scene))
        .layer(DefaultBodyLimit::disable())
        .layer(middleware::from_fn_with_state(state.clone(), require_token));
    let app = Router::new()
        .route("/", get(routes::viewer_page))
        .route("/viewer.js", get(routes::viewer_script))
        .route("/relume.js", get(routes::client_module))
        .route("/viewer.css", get(routes::viewer_style))
        .route("/healthz", get(routes::healthz))
        .route("/metrics", get(routes::metrics))
        .route("/api/{file}", get(api_docs::file))
        .route("/api/examples/{file}", get(api_docs::example))
        .nest("/v1", v1)
        .layer(DefaultBodyLimit::max(limits.max_body_bytes))
        .layer(TimeoutLayer::with_status_code(StatusCode::REQUEST_TIMEOUT, limits.request_timeout))
        .merge(uploads)
        .fallback(routes::not_found)
        .layer(middleware::from_fn_with_state(state.clone(), check_host))
        .layer(middleware::from_fn_with_state(state.clone(), count_rejections))
        .layer(middleware::from_fn(json_errors));
    let app = match cors(&state.config.access.origins) {
        Some(c) => app.layer(c),
        None => app,
    };
    app.layer(middleware::from_fn_with_state(state.clone(), stamp_response)).with_state(state)
}

/// CORS for the configured origins only; `None` (no CORS headers at all) when there are none.
fn cors(origins: &[String]) -> Option<tower_http::cors::CorsLayer> {
    use axum::http::{header, HeaderValue, Method};
    let allowed: Vec<HeaderValue> = origins.iter().filter_map(|o| HeaderValue::from_str(o).ok()).collect();
    (!allowed.is_empty()).then(|| {
        tower_http::cors::CorsLayer::new()
            .allow_origin(allowed)
            .allow_methods([Method::GET, Method::POST, Method::PUT, Method::PATCH, Method::DELETE])
            .allow_headers([header::CONTENT_TYPE, header::AUTHORIZATION])
    })
}

/// Serves `listener` until `shutdown` resolves, then stops every session. Connections and
/// sessions drain within `Limits::drain_deadline` together; a session whose tick is still
/// running then is left to the process's exit, with a warning.
pub async fn run(
    listener: tokio::net::TcpListener,
    state: Arc<AppState>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let closing = state.shutting_down.clone();
    tokio::spawn(expire_idle(state.clone()));
    let signal = async move {
        shutdown.await;
        closing.send_replace(true);
    };
    let limits = state.config.limits.clone();
    let left = listen::serve(listener, app(state.clone()), &limits, state.metrics.clone(), signal).await;
    let drained = state.clone();
    let drain = tokio::task::spawn_blocking(move || drained.drain_blocking());
    match tokio::time::timeout(left, drain).await {
        Ok(joined) => {
            joined.map_err(std::io::Error::other)?;
            tracing::info!(target: "relume::server", "shut down; all sessions drained");
        }
        Err(_) => tracing::warn!(
            target: "relume::server",
            "shut down with sessions still ticking after the {:?} drain deadline",
            limits.drain_deadline
        ),
    }
    Ok(())
}

/// The signal that asked the process to stop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopSignal {
    /// SIGINT (Ctrl-C): stop now.
    Interrupt,
    /// SIGTERM (Kubernetes, systemd, `kill`): drain first.
    Terminate,
}

/// Resolves on SIGINT or SIGTERM, saying which.
pub async fn stop_signal() -> StopSignal {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => StopSignal::Interrupt,
        _ = term => StopSignal::Terminate,
    }
}

/// The shutdown future of `relume serve`. SIGINT stops at once. SIGTERM drains: the node
/// refuses new sessions (503 with `Retry-After`, and `/healthz` answers 503 `draining`, so a
/// proxy sends creates elsewhere) and goes on serving its sessions, so `relume migrate` can
/// move them, until `grace` has passed, no session is left, or a second signal comes.
pub async fn drain_on_terminate(state: Arc<AppState>, grace: std::time::Duration) {
    if stop_signal().await == StopSignal::Interrupt {
        return;
    }
    state.draining.store(true, std::sync::atomic::Ordering::Relaxed);
    tracing::info!(
        target: "relume::server",
        "SIGTERM: draining; new sessions are refused, {} session(s) served for up to {grace:?}",
        state.session_count()
    );
    let empty = async {
        while state.session_count() > 0 {
            tokio::time::sleep(std::time::Duration::from_millis(200)).await;
        }
    };
    tokio::select! {
        _ = tokio::time::sleep(grace) => tracing::info!(target: "relume::server", "drain grace over; shutting down"),
        _ = empty => tracing::info!(target: "relume::server", "no session left; shutting down"),
        _ = stop_signal() => tracing::info!(target: "relume::server", "second signal; shutting down"),
    }
}
