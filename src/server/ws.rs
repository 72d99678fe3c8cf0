//! The WebSocket at `/v1/sessions/{id}/ws`.
//!
//! Client → server: JSON text [`ClientMessage`]s (`edits`, `tick`, `subscribe`, `play`,
//! `pause`, `update`). Server → client: JSON text [`ServerMessage`]s (stats, edit
//! acknowledgements, what an update left running, errors) and binary frames: a 32-byte
//! [`FrameHeader`] followed by the encoded image.
//!
//! Watch semantics: a consumer slower than the ticks receives only the newest frame; the frames
//! it never saw are counted (`frames_dropped` in each stats message and in `/metrics`). Edits are
//! never dropped: each batch is acknowledged (`edits_accepted`) or answered with an `error`.
//! A bad message gets an `error` reply and the connection stays open. Replies keep the order of
//! their messages, but reading never waits for a tick: a batch is queued at once and
//! acknowledged when the worker takes it (before its next tick), and a `tick` joins the
//! session's pending tick, so a client sending faster than the session ticks has its edits
//! merged into the next tick instead of queueing behind ticks. With [`IN_FLIGHT`] replies
//! outstanding, the socket is not read until one is sent: the client's own sends slow down,
//! and nothing it sent is refused.
use super::encoded::EncodingKey;
use super::error::ApiError;
use super::protocol::EditsAccepted;
use super::protocol::{
    ClientMessage, EditBatch, FrameFormat, FrameHeader, PlayingAnimation, ServerMessage, UpdateSession,
};
use super::routes::{parse_body, update, Shared};
use super::state::{valid_name, SessionEntry};
use super::worker::{gone, Answer, PublishedFrame};
use crate::film::ImageFormat;
use crate::scene::animation::Animation;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, State};
use axum::response::Response;
use futures_util::stream::{FuturesOrdered, StreamExt};
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// Close code sent when the session is deleted (by a client or for being idle) while the
/// socket is open; the reason is a JSON `{error, detail}`.
pub const CLOSE_SESSION_GONE: u16 = 4410;

/// Close code sent when the session fails (a panic or an error inside a tick); the reason is a
/// JSON `{error: "session_failed", detail}` with the failure. The session stays inspectable over
/// HTTP until it is deleted.
pub const CLOSE_SESSION_FAILED: u16 = 4409;

/// Replies a socket may wait for before the server stops reading it: a client that sends
/// faster than its session takes commands is slowed by its own socket (TCP backpressure), and
/// never fills the session's command queue ([`super::worker::COMMAND_QUEUE`]) alone.
const IN_FLIGHT: usize = 32;

/// How often the server pings an open socket; a pong counts as activity, so an open viewer
/// keeps its session from expiring.
const PING_EVERY: std::time::Duration = std::time::Duration::from_secs(30);

pub async fn upgrade(
    State(s): State<Shared>,
    Path(id): Path<String>,
    headers: axum::http::HeaderMap,
    ws: WebSocketUpgrade,
) -> Result<Response, ApiError> {
    check_origin(&s, &headers)?;
    let entry = s.session(&id)?;
    let max = s.config.limits.max_connections;
    let permit = s.sockets.clone().try_acquire_owned().map_err(|_| {
        ApiError::new(
            axum::http::StatusCode::SERVICE_UNAVAILABLE,
            "too_many_connections",
            format!("the server holds its maximum of {max} WebSockets (--max-connections); retry later"),
        )
    })?;
    // One size limit for HTTP bodies and WebSocket messages (the library's default is 64 MiB).
    let limit = s.config.limits.max_body_bytes;
    Ok(ws.max_message_size(limit).max_frame_size(limit).on_upgrade(move |socket| async move {
        serve(socket, s, entry).await;
        drop(permit);
    }))
}

/// A browser's upgrade must come from the page's own origin (its authority equals `Host`) or
/// from a configured `--allow-origin`; clients that send no `Origin` (not browsers) pass.
fn check_origin(s: &Shared, headers: &axum::http::HeaderMap) -> Result<(), ApiError> {
    let Some(origin) = headers.get(axum::http::header::ORIGIN) else { return Ok(()) };
    let origin = origin.to_str().unwrap_or_default();
    let host = headers.get(axum::http::header::HOST).and_then(|h| h.to_str().ok()).unwrap_or_default();
    let authority = origin.split_once("://").map_or("", |(_, rest)| rest);
    let same = !host.is_empty() && authority.eq_ignore_ascii_case(host);
    if same || s.config.access.origins.iter().any(|o| o.eq_ignore_ascii_case(origin)) {
        return Ok(());
    }
    Err(ApiError::new(
        axum::http::StatusCode::FORBIDDEN,
        "origin_not_allowed",
        format!("a page from {origin} may not open this WebSocket: start the server with --allow-origin {origin}"),
    ))
}

/// The longest close reason a WebSocket allows: a control frame carries at most 125 bytes,
/// two of them the code (RFC 6455 §5.5).
const MAX_CLOSE_REASON: usize = 123;

/// A close frame whose reason is the JSON `{error, detail}`, the detail shortened (ending in
/// "…") until the reason fits [`MAX_CLOSE_REASON`]; a longer one would be a protocol error at
/// the client, which then never sees the code.
fn close(code: u16, error: &str, detail: &str) -> Message {
    Message::Close(Some(axum::extract::ws::CloseFrame { code, reason: close_reason(error, detail).into() }))
}

fn close_reason(error: &str, detail: &str) -> String {
    let mut kept = detail.to_string();
    loop {
        let shown = if kept.len() < detail.len() { format!("{kept}…") } else { kept.clone() };
        let reason = serde_json::json!({"error": error, "detail": shown}).to_string();
        if reason.len() <= MAX_CLOSE_REASON || kept.is_empty() {
            return reason;
        }
        kept.pop();
    }
}

struct Subscription {
    frames: FrameFormat,
    stats: bool,
    every: u32,
    /// Send the denoised image when the session denoises (else the raw one).
    denoised: bool,
}

fn error_message(e: &ApiError) -> Message {
    text(&ServerMessage::Error { error: e.error.to_string(), detail: e.detail.clone() })
}

fn text(m: &ServerMessage) -> Message {
    Message::Text(serde_json::to_string(m).unwrap_or_default().into())
}

/// Sends one published frame as `sub` asks: its stats (with the frames this subscriber has
/// dropped so far), then the encoded image behind its header. A frame that fails to encode
/// is skipped; an error means the socket is gone.
async fn send_frame(
    socket: &mut WebSocket,
    state: &Shared,
    entry: &Arc<SessionEntry>,
    sub: &Subscription,
    frame: Arc<PublishedFrame>,
    dropped: u64,
) -> Result<(), axum::Error> {
    if sub.stats {
        let m = text(&ServerMessage::Stats { stats: Box::new(frame.stats.clone()), frames_dropped: dropped });
        if let Message::Text(t) = &m {
            state.metrics.sent(t.len());
        }
        socket.send(m).await?;
    }
    let format = match sub.frames {
        FrameFormat::Png => ImageFormat::Png,
        FrameFormat::Jpg => ImageFormat::Jpeg,
        FrameFormat::Exr => ImageFormat::Exr,
        FrameFormat::F32 => ImageFormat::F32,
        FrameFormat::None => return Ok(()),
    };
    let header = FrameHeader {
        tick: frame.tick,
        accumulation_id: frame.accumulation_id,
        format: sub.frames,
        width: frame.image.width,
        height: frame.image.height,
    };
    let key = EncodingKey::new(&frame, format, !sub.denoised, 0.0);
    let (metrics, shared) = (state.metrics.clone(), entry.clone());
    let encoded = tokio::task::spawn_blocking(move || shared.handle.encoded.get(&frame, key, &metrics));
    let Ok(Ok(bytes)) = encoded.await else { return Ok(()) };
    let mut payload = Vec::with_capacity(bytes.len() + 32);
    payload.extend_from_slice(&header.encode());
    payload.extend_from_slice(&bytes);
    state.metrics.sent(payload.len());
    socket.send(Message::Binary(payload.into())).await
}

async fn serve(mut socket: WebSocket, state: Shared, entry: Arc<SessionEntry>) {
    let mut frames = entry.handle.frames.clone();
    frames.mark_unchanged();
    let mut closing = state.shutting_down.subscribe();
    let mut sub = Subscription { frames: FrameFormat::Png, stats: true, every: 1, denoised: true };
    let mut last_seen: Option<u64> = None;
    let mut dropped = 0u64;
    let mut ping = tokio::time::interval_at(tokio::time::Instant::now() + PING_EVERY, PING_EVERY);
    // Replies in the order their messages came, each sent once it is ready: reading goes on
    // while a batch waits for its acknowledgement (at most the tick in progress).
    let mut replies: FuturesOrdered<Reply> = FuturesOrdered::new();
    loop {
        tokio::select! {
            incoming = socket.recv(), if replies.len() < IN_FLIGHT => {
                state.touch(&entry);
                let reply = match incoming {
                    Some(Ok(Message::Text(t))) => handle(&state, &entry, &mut sub, t.as_bytes()).await,
                    Some(Ok(Message::Binary(_))) => ready(Some(error_message(&ApiError::bad_request("binary messages are for frames; send JSON text")))),
                    Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                    Some(Ok(_)) => ready(None),
                };
                replies.push_back(reply);
            }
            Some(reply) = replies.next(), if !replies.is_empty() => {
                if let Some(r) = reply {
                    if socket.send(r).await.is_err() {
                        break;
                    }
                }
            }
            _ = ping.tick() => {
                if socket.send(Message::Ping(Default::default())).await.is_err() {
                    break;
                }
            }
            changed = frames.changed() => {
                if changed.is_err() {
                    let message = match entry.handle.failure() {
                        Some(reason) => close(CLOSE_SESSION_FAILED, "session_failed", &format!("session {} failed: {reason}", entry.id)),
                        None => close(CLOSE_SESSION_GONE, "session_closed", &format!("session {} deleted (by a client, or idle past --session-idle)", entry.id)),
                    };
                    let _ = socket.send(message).await;
                    break;
                }
                let Some(frame) = frames.borrow_and_update().clone() else { continue };
                // Ticks this consumer never saw (skipped because it was slower) are dropped frames.
                if let Some(prev) = last_seen {
                    let skipped = frame.tick.saturating_sub(prev + 1);
                    dropped += skipped;
                    state.metrics.frames_dropped.fetch_add(skipped, Ordering::Relaxed);
                }
                last_seen = Some(frame.tick);
                if frame.tick % sub.every as u64 != 0 {
                    continue;
                }
                if send_frame(&mut socket, &state, &entry, &sub, frame, dropped).await.is_err() {
                    break;
                }
            }
            _ = closing.changed() => {
                let _ = socket.send(close(axum::extract::ws::close_code::AWAY, "shutting_down", "the server is shutting down")).await;
                break;
            }
        }
    }
}

/// A reply to one client message, once it is ready (`None`: the message has no reply).
type Reply = Pin<Box<dyn Future<Output = Option<Message>> + Send>>;

fn ready(reply: Option<Message>) -> Reply {
    Box::pin(std::future::ready(reply))
}

/// An edit batch's acknowledgement, once the worker has queued it.
fn acknowledgement(answer: Answer<EditsAccepted>) -> Reply {
    Box::pin(async move {
        let outcome = answer.await.unwrap_or_else(|_| Err(gone()));
        Some(match outcome {
            Ok(a) => text(&ServerMessage::EditsAccepted { queued: a.queued, pending: a.pending, seq: a.seq }),
            Err(e) => error_message(&e),
        })
    })
}

/// Handles one client message; returns its reply. Edits and ticks are queued at once and never
/// wait for a tick here: an edit batch's acknowledgement comes when the worker has queued it,
/// and a tick's frame and stats through the subscription.
async fn handle(state: &Shared, entry: &SessionEntry, sub: &mut Subscription, bytes: &[u8]) -> Reply {
    let message = match parse_message(bytes) {
        Ok(m) => m,
        Err(e) => return ready(Some(error_message(&e))),
    };
    let outcome: Result<Option<ServerMessage>, ApiError> = match message {
        ClientMessage::Edits { edits } => {
            let sent = state.config.limits.check_edit_count("edits", edits.len()).and_then(|()| {
                state.metrics.edits_received.fetch_add(edits.len() as u64, Ordering::Relaxed);
                entry.handle.send_edits(edits)
            });
            return match sent {
                Ok(answer) => acknowledgement(answer),
                Err(e) => ready(Some(error_message(&e))),
            };
        }
        ClientMessage::Tick => entry.handle.request_tick().map(|_| None),
        ClientMessage::Subscribe { frames, stats, every, denoised } => {
            if every == 0 {
                Err(ApiError::invalid("every: must be at least 1"))
            } else {
                *sub = Subscription { frames, stats, every, denoised };
                Ok(None)
            }
        }
        ClientMessage::Play { anim, speed } => play(entry, &anim, speed).await.map(|_| None),
        ClientMessage::Pause => entry.handle.pause().map(|_| None),
        ClientMessage::Update(req) => update(state, entry, req)
            .await
            .map(|running| Some(ServerMessage::Updated { technique: running.technique, denoise: running.denoise })),
    };
    ready(match outcome {
        Ok(reply) => reply.map(|m| text(&m)),
        Err(e) => Some(error_message(&e)),
    })
}

/// Parses a client message. Serde reads a message tagged by `type` through a buffer, which
/// loses the path to a bad field; so a message that fails is read again as its variant's body
/// alone, whose error names the field (`edits[0]`, `denoise.quality`).
fn parse_message(bytes: &[u8]) -> Result<ClientMessage, ApiError> {
    parse_body(bytes).map_err(|e| {
        let Ok(serde_json::Value::Object(mut body)) = serde_json::from_slice(bytes) else { return e };
        let kind = body.remove("type");
        let body = serde_json::Value::Object(body).to_string();
        let named = match kind.as_ref().and_then(serde_json::Value::as_str) {
            Some("update") => parse_body::<UpdateSession>(body.as_bytes()).err(),
            Some("edits") => parse_body::<EditBatch>(body.as_bytes()).err(),
            _ => None,
        };
        named.unwrap_or(e)
    })
}

/// An animation's playback speed must lie in (0, 100]; `field` names it in the error.
pub fn check_speed(field: &str, speed: f32) -> Result<(), ApiError> {
    if speed.is_finite() && speed > 0.0 && speed <= 100.0 {
        Ok(())
    } else {
        Err(ApiError::invalid(format!("{field}: must lie in (0, 100]")))
    }
}

async fn play(entry: &SessionEntry, name: &str, speed: f32) -> Result<(), ApiError> {
    check_speed("speed", speed)?;
    if let Some((_, a)) = entry.animations.iter().find(|(n, _)| n == name) {
        let animation = a.clone();
        return entry.handle.play(PlayingAnimation { animation, speed, clock_s: 0.0 }).await;
    }
    if !valid_name(name) {
        return Err(ApiError::invalid(format!("anim: '{name}' is not an animation name")));
    }
    let Some(dir) = &entry.scene_dir else {
        return Err(ApiError::invalid("anim: inline scenes have no bundled animations"));
    };
    let path = dir.join(format!("{name}.anim.json"));
    if !path.is_file() {
        return Err(ApiError::not_found(format!("anim: no animation '{name}' (see GET /v1/scenes)")));
    }
    let anim = Animation::load(&path).map_err(|e| ApiError::invalid(format!("anim: {e}")))?;
    entry.handle.play(PlayingAnimation { animation: anim, speed, clock_s: 0.0 }).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn close_reasons_fit_a_control_frame_and_stay_json() {
        // Property: however long the detail (a failure message, a long node name in the
        // session id, characters JSON escapes or that take several bytes), the reason fits 123
        // bytes and parses as {error, detail}; a short detail is kept whole. Negative control:
        // the untruncated reason of the long detail does not fit.
        let long = format!("session {}.s1-0 failed: \"quoted\" ünïcode {}", "n".repeat(63), "x".repeat(200));
        let whole = serde_json::json!({"error": "session_failed", "detail": long}).to_string();
        assert!(whole.len() > MAX_CLOSE_REASON);
        for detail in [long.as_str(), "short", ""] {
            let reason = close_reason("session_failed", detail);
            assert!(reason.len() <= MAX_CLOSE_REASON, "{} bytes: {reason}", reason.len());
            let parsed: serde_json::Value = serde_json::from_str(&reason).expect("JSON");
            assert_eq!(parsed["error"], "session_failed");
            let shown = parsed["detail"].as_str().expect("detail");
            match detail.len() < 60 {
                true => assert_eq!(shown, detail),
                false => assert!(shown.ends_with('…') && detail.starts_with(shown.trim_end_matches('…'))),
            }
        }
    }
}
