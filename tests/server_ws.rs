//! The WebSocket protocol with a real client (tokio-tungstenite) against a real server.
mod common;
use common::server::TestServer;
use common::ws::{next, next_frame, next_text, send, Socket};
use futures_util::{SinkExt, StreamExt};
use relume::server::protocol::{FrameFormat, FrameHeader};
use relume::server::Limits;
use serde_json::{json, Value};
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;

async fn connect(s: &TestServer, id: &str) -> Socket {
    common::ws::open(&s.ws_url(&format!("/v1/sessions/{id}/ws"))).await
}

/// Asks for a tick and returns its stats (the socket subscribes to stats and no frames).
async fn ticked(ws: &mut Socket) -> Value {
    send(ws, json!({"type": "tick"})).await;
    let st = next_text(ws).await;
    assert_eq!(st["type"], "stats", "{st}");
    st["stats"].clone()
}

fn bunny_at(x: f32) -> Value {
    json!({"target": "object", "name": "bunny-1", "transform": {"translation": [x, 0, 280], "scale": [140, 140, 140]}})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn edits_tick_frame_and_the_frame_changes_after_a_move() {
    let s = TestServer::start(None, Limits::default()).await;
    let id = s
        .session(json!({"scene": "bunnies-1", "width": 48, "height": 48, "technique": {"id": "path", "spp": 4}}))
        .await;
    let mut ws = connect(&s, &id).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "png", "stats": true, "every": 1})).await;
    send(&mut ws, json!({"type": "edits", "edits": [bunny_at(150.0)]})).await;
    let ack = next_text(&mut ws).await;
    assert_eq!(ack, json!({"type": "edits_accepted", "queued": 1, "pending": 1, "seq": 1}));
    send(&mut ws, json!({"type": "tick"})).await;
    let stats = next_text(&mut ws).await;
    assert_eq!(stats["type"], "stats");
    assert_eq!(stats["stats"]["moved_surfaces"], 1);
    let (h1, _) = next_frame(&mut ws).await;
    assert_eq!((h1.tick, h1.format, h1.width, h1.height), (0, FrameFormat::Png, 48, 48));

    // A twin session (same seed) gets the same first edit but not the second; at tick 1 only
    // the move can make the two frames differ.
    let twin = s
        .session(json!({"scene": "bunnies-1", "width": 48, "height": 48, "technique": {"id": "path", "spp": 4}}))
        .await;
    let mut tw = connect(&s, &twin).await;
    send(&mut tw, json!({"type": "subscribe", "frames": "png", "stats": false, "every": 1})).await;
    send(&mut tw, json!({"type": "edits", "edits": [bunny_at(150.0)]})).await;
    next_text(&mut tw).await;
    send(&mut tw, json!({"type": "tick"})).await;
    next_frame(&mut tw).await;

    send(&mut ws, json!({"type": "edits", "edits": [bunny_at(400.0)]})).await;
    next_text(&mut ws).await;
    send(&mut ws, json!({"type": "tick"})).await;
    send(&mut tw, json!({"type": "tick"})).await;
    let (h2, img2) = next_frame(&mut ws).await;
    let (t2, still) = next_frame(&mut tw).await;
    assert_eq!((h2.tick, t2.tick), (1, 1));
    assert_ne!(h2.accumulation_id, h1.accumulation_id);
    assert_eq!(t2.accumulation_id, h1.accumulation_id, "the twin's film kept accumulating");
    assert_ne!(still.to_rgb8().into_raw(), img2.to_rgb8().into_raw(), "moving the bunny must change the frame");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_messages_get_errors_and_the_socket_stays_open() {
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(json!({"scene": "bunnies-1", "width": 16, "height": 16})).await;
    let mut ws = connect(&s, &id).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "none", "stats": true})).await;
    for (bad, words) in [
        (json!({"type": "dance"}), "unknown variant"),
        (json!({"type": "edits", "edits": [{"target": "object", "name": "floor", "transform": {}}]}), "static"),
        (json!({"type": "subscribe", "every": 0}), "every"),
        (
            json!({"type": "edits", "edits": [{"target": "object", "name": "bunny-1", "transform": {"scale": "big"}}]}),
            "edits[0]: invalid type",
        ),
        (json!({"type": "play", "anim": "../../etc/passwd"}), "not an animation name"),
        (json!({"type": "play", "anim": "walker"}), "unknown object"),
        (json!({"type": "play", "anim": "bunnies-1", "speed": -1}), "speed"),
    ] {
        send(&mut ws, bad.clone()).await;
        let e = next_text(&mut ws).await;
        assert_eq!(e["type"], "error", "{bad}: {e}");
        assert!(e["detail"].as_str().unwrap().contains(words), "{bad}: {e}");
    }
    ws.send(Message::Text("{not json".into())).await.unwrap();
    assert_eq!(next_text(&mut ws).await["error"], "malformed_json");
    // Still open and working.
    send(&mut ws, json!({"type": "tick"})).await;
    assert_eq!(next_text(&mut ws).await["type"], "stats");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_update_switches_the_technique_and_a_refused_one_changes_nothing() {
    // `update` is PATCH /v1/sessions/{id} on the socket: the switch reaches the next tick's
    // stats (a restarted film, the scene as edited) and the session view; bad updates are
    // answered by errors naming the field and leave the technique as it was. Negative control,
    // by hand: a handler that answers `updated` without applying the update fails the check of
    // the next tick's technique.
    let s = TestServer::start(None, Limits::default()).await;
    let id = s
        .session(json!({"scene": "bunnies-1", "width": 24, "height": 24, "technique": {"id": "path", "spp": 1}}))
        .await;
    let mut ws = connect(&s, &id).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "none", "stats": true})).await;
    send(&mut ws, json!({"type": "edits", "edits": [bunny_at(300.0)]})).await;
    assert_eq!(next_text(&mut ws).await["type"], "edits_accepted");
    let before = ticked(&mut ws).await;
    assert_eq!(before["technique"], "path");
    send(&mut ws, json!({"type": "update", "technique": {"id": "instant_cache", "vpls": 32}})).await;
    let updated = next_text(&mut ws).await;
    assert_eq!(
        (&updated["type"], &updated["technique"]["id"]),
        (&json!("updated"), &json!("instant_cache")),
        "{updated}"
    );
    assert_eq!((&updated["technique"]["vpls"], &updated["denoise"]), (&json!(32), &Value::Null), "{updated}");
    let view: Value = s.http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().json().await.unwrap();
    assert_eq!(view["technique"], updated["technique"], "the view does not show the switch");
    let after = ticked(&mut ws).await;
    assert_eq!(after["technique"], "instant_cache");
    assert_eq!(after["accumulation_id"].as_u64(), before["accumulation_id"].as_u64().map(|a| a + 1), "{after}");
    let scene: Value =
        s.http.get(s.url(&format!("/v1/sessions/{id}/scene"))).send().await.unwrap().json().await.unwrap();
    let bunny = scene["objects"].as_array().unwrap().iter().find(|o| o["name"] == "bunny-1").expect("bunny-1");
    assert_eq!(bunny["transform"]["translation"], json!([300.0, 0.0, 280.0]), "the edit was lost");
    for (bad, words) in [
        (json!({"type": "update"}), "nothing to change"),
        (json!({"type": "update", "technique": {"id": "path", "spp": 100000000}}), "technique.spp"),
        (json!({"type": "update", "technique": {"id": "bogus"}}), "bogus"),
        (json!({"type": "update", "denoise": {"quality": "best"}}), "denoise.quality"),
        (json!({"type": "update", "colour": "red"}), "colour"),
    ] {
        send(&mut ws, bad.clone()).await;
        let e = next_text(&mut ws).await;
        assert_eq!(e["type"], "error", "{bad}: {e}");
        assert!(e["detail"].as_str().unwrap().contains(words), "{bad}: {e}");
    }
    assert_eq!(ticked(&mut ws).await["technique"], "instant_cache", "a refused update changed the technique");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn play_drives_the_animation_and_pause_stops_it() {
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(json!({"scene": "bunnies-2", "width": 16, "height": 16})).await;
    let mut ws = connect(&s, &id).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "none", "stats": true})).await;
    send(&mut ws, json!({"type": "play", "anim": "bunnies-2", "speed": 2.0})).await;
    // Ticks arrive without the client asking, each moving both bunnies.
    for _ in 0..3 {
        let st = next_text(&mut ws).await;
        assert_eq!(st["type"], "stats");
        assert_eq!(st["stats"]["moved_surfaces"], 2);
    }
    send(&mut ws, json!({"type": "pause"})).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let before: Value = s.http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().json().await.unwrap();
    tokio::time::sleep(Duration::from_millis(400)).await;
    let after: Value = s.http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().json().await.unwrap();
    assert_eq!(before["ticks"], after["ticks"], "ticks continued after pause");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_consumer_gets_the_newest_frame_and_counts_the_rest() {
    // Small socket buffers and 64×64 EXR frames (tens of kB of noise each): a client that stops
    // reading blocks the server's send, while the session keeps ticking at 100 Hz.
    let s = TestServer::start_with_small_send_buffers(Limits::default()).await;
    let id = s.session(json!({"scene": "cornell-box", "width": 64, "height": 64, "tick_hz": 100})).await;
    let (tcp, _) = {
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.set_recv_buffer_size(4096).unwrap();
        (socket.connect(s.addr).await.unwrap(), ())
    };
    let stream = tokio_tungstenite::MaybeTlsStream::Plain(tcp);
    let (mut ws, _) =
        tokio_tungstenite::client_async(s.ws_url(&format!("/v1/sessions/{id}/ws")), stream).await.unwrap();
    send(&mut ws, json!({"type": "subscribe", "frames": "exr", "stats": true})).await;
    tokio::time::sleep(Duration::from_millis(800)).await;
    let mut last_dropped = 0;
    let mut ticks = Vec::new();
    // Frames the server queued before it read the subscription (it was blocked sending to this
    // slow reader) are still PNG, the default; once an EXR frame arrives, every later one is EXR.
    let mut exr_frames = 0;
    while ticks.len() < 6 || exr_frames == 0 {
        match next(&mut ws).await {
            Message::Text(t) => {
                let st: Value = serde_json::from_str(&t).unwrap();
                ticks.push(st["stats"]["tick"].as_u64().unwrap());
                last_dropped = st["frames_dropped"].as_u64().unwrap();
            }
            Message::Binary(b) => match FrameHeader::decode(&b).unwrap().format {
                FrameFormat::Exr => exr_frames += 1,
                FrameFormat::Png => assert_eq!(exr_frames, 0, "a PNG frame after the EXR subscription took effect"),
                other => panic!("unexpected frame format {other:?}"),
            },
            other => panic!("unexpected {other:?}"),
        }
    }
    assert!(ticks.windows(2).all(|w| w[1] > w[0]), "ticks out of order: {ticks:?}");
    assert!(last_dropped > 0, "a slow consumer must see frames dropped (ticks {ticks:?})");
    assert!(ticks.windows(2).any(|w| w[1] > w[0] + 1), "no tick was skipped: {ticks:?}");
    let m = s.http.get(s.url("/metrics")).send().await.unwrap().text().await.unwrap();
    assert!(!m.contains("relume_frames_dropped_total 0\n"), "{m}");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn graceful_shutdown_completes_with_sessions_and_sockets_open() {
    let s = TestServer::start(None, Limits::default()).await;
    let a = s.session(json!({"scene": "cornell-box", "width": 16, "height": 16, "tick_hz": 30})).await;
    let b = s.session(json!({"scene": "bunnies-4", "width": 16, "height": 16})).await;
    let mut ws = connect(&s, &a).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "none", "stats": true})).await;
    next_text(&mut ws).await;
    let _ws_b = connect(&s, &b).await;
    let state = s.state.clone();
    tokio::time::timeout(Duration::from_secs(20), s.shutdown()).await.expect("shutdown in time").unwrap();
    assert_eq!(state.session_count(), 0, "sessions were not drained");
    // The socket was closed by the server.
    let end = tokio::time::timeout(Duration::from_secs(5), async {
        loop {
            match ws.next().await {
                None | Some(Err(_)) | Some(Ok(Message::Close(_))) => break,
                Some(Ok(_)) => continue,
            }
        }
    })
    .await;
    assert!(end.is_ok(), "socket still open after shutdown");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_edits_and_ticks_is_merged_acknowledged_and_ends_at_its_last_edit() {
    // Property: a client that sends edits and tick requests far faster than the session ticks
    // (open loop: it never waits for an answer) gets every batch acknowledged, in order, its
    // edits merged into few ticks, and ends where a twin session given only the last edit
    // ends. Run against the loop before pending work collapsed, which waited for each tick in
    // turn, it failed.
    const N: usize = 300;
    let s = TestServer::start(None, Limits::default()).await;
    let create = json!({"scene": "bunnies-1", "width": 32, "height": 32, "technique": {"id": "path"}});
    let id = s.session(create.clone()).await;
    let mut ws = connect(&s, &id).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "none", "stats": true})).await;
    for k in 0..N {
        send(&mut ws, json!({"type": "edits", "edits": [bunny_at(100.0 + k as f32)]})).await;
        send(&mut ws, json!({"type": "tick"})).await;
    }
    // Stats come with the newest frame only: ticks this reader did not see are counted in
    // `frames_dropped`, so seen + dropped is every tick the session ran.
    let (mut acks, mut seen, mut dropped, mut applied) = (Vec::new(), 0, 0, 0);
    while acks.len() < N || applied < N {
        let m = next_text(&mut ws).await;
        match m["type"].as_str() {
            Some("edits_accepted") => acks.push(m["seq"].as_u64().expect("seq") as usize),
            Some("stats") => {
                seen += 1;
                dropped = m["frames_dropped"].as_u64().expect("dropped") as usize;
                applied = m["stats"]["edits_applied_through"].as_u64().expect("applied") as usize;
            }
            _ => panic!("unexpected message {m}"),
        }
    }
    assert_eq!(acks, (1..=N).collect::<Vec<_>>(), "every batch is acknowledged, in order");
    let ticks = seen + dropped;
    assert!(ticks < N / 2, "{ticks} ticks for {N} requests: the flood was not merged");
    let twin = s.session(create).await;
    s.post_json(&format!("/v1/sessions/{twin}/edits"), &json!({"edits": [bunny_at(100.0 + (N - 1) as f32)]})).await;
    s.post_json(&format!("/v1/sessions/{twin}/tick"), &json!({})).await;
    let flooded = s.get_json(&format!("/v1/sessions/{id}/scene")).await;
    let only_last = s.get_json(&format!("/v1/sessions/{twin}/scene")).await;
    assert_eq!(flooded["objects"], only_last["objects"], "the flood did not end at its last edit");
    s.shutdown().await.unwrap();
}
