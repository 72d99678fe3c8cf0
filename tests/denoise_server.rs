//! The denoise stage through the service: sessions that ask for it serve the denoised frame by
//! default and the raw one with `?denoised=false` (HTTP) or `"denoised": false` (WebSocket),
//! and the raw one is the frame of a twin session that does not denoise.
mod common;
use common::server::TestServer;
#[cfg(feature = "denoise")]
use common::ws::{next, send};
#[cfg(feature = "denoise")]
use relume::server::protocol::FRAME_HEADER_LEN;
use relume::server::Limits;
use serde_json::{json, Value};
#[cfg(feature = "denoise")]
use tokio_tungstenite::tungstenite::Message;

fn body(denoise: Option<Value>) -> Value {
    let mut b = json!({"scene": "cornell-box", "width": 48, "height": 48, "seed": 5,
                       "technique": {"id": "path", "spp": 1}});
    if let Some(d) = denoise {
        b["denoise"] = d;
    }
    b
}

#[cfg(feature = "denoise")]
async fn tick(s: &TestServer, id: &str) {
    let r = s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    assert_eq!(r.status(), 200);
}

#[cfg(feature = "denoise")]
async fn exr(s: &TestServer, id: &str, query: &str) -> Vec<u8> {
    let r = s.http.get(s.url(&format!("/v1/sessions/{id}/frame.exr?tick=0{query}"))).send().await.unwrap();
    assert_eq!(r.status(), 200, "{query}");
    r.bytes().await.unwrap().to_vec()
}

/// The next binary frame's encoded image.
#[cfg(feature = "denoise")]
async fn ws_frame(ws: &mut common::ws::Socket) -> Vec<u8> {
    loop {
        if let Message::Binary(b) = next(ws).await {
            return b[FRAME_HEADER_LEN..].to_vec();
        }
    }
}

#[cfg(feature = "denoise")]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn denoised_and_raw_frames_over_http_and_websocket() {
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(body(Some(json!({"quality": "fast"})))).await;
    let twin = s.session(body(None)).await;
    let view: Value = s.http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().json().await.unwrap();
    assert_eq!(view["denoise"], json!({"quality": "fast", "aux": true}));

    // Two sockets on the denoising session: one asks for raw frames, one for the default.
    let ws_url = s.ws_url(&format!("/v1/sessions/{id}/ws"));
    let (mut raw_ws, mut den_ws) = (common::ws::open(&ws_url).await, common::ws::open(&ws_url).await);
    send(&mut raw_ws, json!({"type": "subscribe", "frames": "exr", "stats": false, "denoised": false})).await;
    send(&mut den_ws, json!({"type": "subscribe", "frames": "exr", "stats": false})).await;
    // The subscriptions are in place once a message sent after them is answered.
    for ws in [&mut raw_ws, &mut den_ws] {
        send(ws, json!({"type": "no-such-message"})).await;
        assert!(matches!(next(ws).await, Message::Text(_)), "an error reply");
    }
    tick(&s, &id).await;
    tick(&s, &twin).await;

    let denoised = exr(&s, &id, "").await;
    let raw = exr(&s, &id, "&denoised=false").await;
    let twin_frame = exr(&s, &twin, "").await;
    assert_eq!(raw, twin_frame, "the raw frame differs from a twin session without denoising");
    assert_ne!(denoised, raw, "the default frame of a denoising session is the raw one");
    assert_eq!(exr(&s, &twin, "&denoised=true").await, twin_frame, "a session without denoising has one image");

    let (ws_raw, ws_den) = (ws_frame(&mut raw_ws).await, ws_frame(&mut den_ws).await);
    assert_eq!(ws_raw, raw, "WebSocket raw frame");
    assert_eq!(ws_den, denoised, "WebSocket denoised frame");
    let stats: Value =
        s.http.get(s.url(&format!("/v1/sessions/{id}/stats"))).send().await.unwrap().json().await.unwrap();
    assert!(stats["stats"][0]["times"]["denoise_ms"].as_f64().unwrap() > 0.0, "{stats}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_denoise_settings_are_refused_naming_the_field() {
    let s = TestServer::start(None, Limits::default()).await;
    for (bad, names) in [
        (json!({"quality": "ultra"}), "denoise"),
        (json!({"aux": "yes"}), "denoise"),
        (json!({"quality": "fast", "strength": 2}), "denoise"),
        (json!("high"), "denoise"),
    ] {
        let r = s.http.post(s.url("/v1/sessions")).json(&body(Some(bad.clone()))).send().await.unwrap();
        assert_eq!(r.status(), 422, "{bad}");
        let e: Value = r.json().await.unwrap();
        assert!(e["detail"].as_str().unwrap().contains(names), "{bad}: {e}");
    }
}

#[cfg(not(feature = "denoise"))]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_build_without_the_feature_refuses_denoise_naming_it() {
    let s = TestServer::start(None, Limits::default()).await;
    let r = s.http.post(s.url("/v1/sessions")).json(&body(Some(json!({"quality": "fast"})))).send().await.unwrap();
    assert_eq!(r.status(), 422);
    let e: Value = r.json().await.unwrap();
    assert!(e["detail"].as_str().unwrap().contains("`denoise` cargo feature"), "{e}");
}

/// Tick `tick`'s EXR frame (`query`: `""` or `"&denoised=false"`).
#[cfg(feature = "denoise")]
async fn exr_at(s: &TestServer, id: &str, tick: u64, query: &str) -> Vec<u8> {
    let r = s.http.get(s.url(&format!("/v1/sessions/{id}/frame.exr?tick={tick}{query}"))).send().await.unwrap();
    assert_eq!(r.status(), 200, "{query}");
    r.bytes().await.unwrap().to_vec()
}

/// `PATCH /v1/sessions/{id}`: the session view it answers.
#[cfg(feature = "denoise")]
async fn patch(s: &TestServer, id: &str, body: Value) -> Value {
    let r = s.http.patch(s.url(&format!("/v1/sessions/{id}"))).json(&body).send().await.unwrap();
    assert_eq!(r.status(), 200, "{body}");
    r.json().await.unwrap()
}

#[cfg(feature = "denoise")]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn denoising_starts_and_stops_on_a_running_session_without_restarting_its_film() {
    // Negative control, by hand: an update that ignores `denoise` serves the raw frame as the
    // default one after the start, and fails.
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(body(None)).await;
    let twin = s.session(body(None)).await;
    tick(&s, &id).await;
    tick(&s, &twin).await;
    let view = patch(&s, &id, json!({"denoise": {"quality": "fast"}})).await;
    assert_eq!(view["denoise"], json!({"quality": "fast", "aux": true}));
    tick(&s, &id).await;
    tick(&s, &twin).await;
    let raw = exr_at(&s, &id, 1, "&denoised=false").await;
    assert_eq!(
        raw,
        exr_at(&s, &twin, 1, "").await,
        "the film restarted or changed: the raw frame differs from the twin's"
    );
    assert_ne!(exr_at(&s, &id, 1, "").await, raw, "the session does not denoise after the start");
    let stats: Value = s.get_json(&format!("/v1/sessions/{id}/stats")).await;
    assert!(stats["stats"][1]["times"]["denoise_ms"].as_f64().unwrap() > 0.0, "{stats}");
    let view = patch(&s, &id, json!({"denoise": null})).await;
    assert!(view["denoise"].is_null(), "{view}");
    tick(&s, &id).await;
    tick(&s, &twin).await;
    let twin_frame = exr_at(&s, &twin, 2, "").await;
    assert_eq!(exr_at(&s, &id, 2, "").await, twin_frame, "the session still denoises after the stop");
    s.shutdown().await.unwrap();
}
