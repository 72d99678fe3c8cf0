//! `GET /v1/sessions/{id}/stream.mjpeg`: a session's frames as a Motion JPEG stream
//! (`multipart/x-mixed-replace`), which an `<img>` tag, VLC or ffmpeg shows without code.
//!
//! Each part is one published frame as JPEG (8-bit sRGB, `?exposure=` in stops, `?denoised=`
//! as for `frame.jpg`), encoded through the session's shared encoding cache, so a stream and
//! `frame.jpg` of the same tick cost one encoding. Every part carries the frame's tick in
//! `X-Relume-Tick`.
//!
//! Invariant: the stream holds no queue. It is pulled by the connection: while a reader does
//! not read, nothing is encoded or buffered for it beyond what the socket holds, and when it
//! reads again it gets the newest frame (the frame channel keeps only the newest), so a slow
//! or stalled reader costs the server one channel receiver and never slows the session's
//! ticks. The stream ends when the session does.
use super::encoded::EncodingKey;
use super::error::ApiError;
use super::routes::Shared;
use super::state::SessionEntry;
use crate::film::{check_exposure, ImageFormat};
use axum::body::{Body, Bytes};
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderValue};
use axum::response::Response;
use serde::Deserialize;
use std::sync::Arc;

/// The multipart boundary between frames.
pub const BOUNDARY: &str = "relume-frame";

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StreamQuery {
    #[serde(default)]
    pub exposure: Option<f32>,
    /// `false` for the raw image of a denoising session (default: denoised when it denoises).
    #[serde(default)]
    pub denoised: Option<bool>,
}

/// What the stream carries from one part to the next.
struct Stream {
    frames: tokio::sync::watch::Receiver<Option<Arc<super::worker::PublishedFrame>>>,
    entry: Arc<SessionEntry>,
    metrics: Arc<super::metrics::Metrics>,
    raw: bool,
    exposure: f32,
}

pub async fn stream(
    State(s): State<Shared>,
    Path(id): Path<String>,
    query: Result<Query<StreamQuery>, axum::extract::rejection::QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) = query.map_err(|e| ApiError::invalid(format!("query: {}", e.body_text())))?;
    let exposure = q.exposure.unwrap_or(0.0);
    check_exposure(exposure).map_err(|m| ApiError::invalid(format!("exposure: {m}")))?;
    let entry = s.session(&id)?;
    let mut frames = entry.handle.frames.clone();
    // The frame already published is the first part; then each newer one.
    frames.mark_changed();
    let start = Stream { frames, entry, metrics: s.metrics.clone(), raw: q.denoised == Some(false), exposure };
    let parts = futures_util::stream::unfold(start, |mut st| async move {
        let part = next_part(&mut st).await?;
        Some((Ok::<Bytes, std::convert::Infallible>(part), st))
    });
    let mut resp = Response::new(Body::from_stream(parts));
    let kind = format!("multipart/x-mixed-replace; boundary={BOUNDARY}");
    let h = resp.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_str(&kind).map_err(|e| ApiError::internal(e.to_string()))?);
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache, no-store"));
    Ok(resp)
}

/// Waits for the next frame newer than the last one sent and encodes it as one multipart part;
/// `None` ends the stream (the session is gone, or its frame cannot be encoded).
async fn next_part(st: &mut Stream) -> Option<Bytes> {
    let frame = loop {
        st.frames.changed().await.ok()?;
        if let Some(frame) = st.frames.borrow_and_update().clone() {
            break frame;
        }
    };
    let key = EncodingKey::new(&frame, ImageFormat::Jpeg, st.raw, st.exposure);
    let (entry, metrics, f) = (st.entry.clone(), st.metrics.clone(), frame.clone());
    let encoded = tokio::task::spawn_blocking(move || entry.handle.encoded.get(&f, key, &metrics)).await.ok()?;
    let jpeg = match encoded {
        Ok(jpeg) => jpeg,
        Err(e) => {
            tracing::error!(target: "relume::server", "stream.mjpeg: tick {} not encoded: {e}", frame.tick);
            return None;
        }
    };
    let head = format!(
        "--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\nX-Relume-Tick: {}\r\n\r\n",
        jpeg.len(),
        frame.tick
    );
    let mut part = Vec::with_capacity(head.len() + jpeg.len() + 2);
    part.extend_from_slice(head.as_bytes());
    part.extend_from_slice(&jpeg);
    part.extend_from_slice(b"\r\n");
    st.metrics.sent(part.len());
    Some(Bytes::from(part))
}
