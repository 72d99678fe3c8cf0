//! Hazards from hostile and sloppy clients, each against a real server on 127.0.0.1:0. Each
//! test names the hazard it guards; each failed before its fix.
mod common;
use common::server::TestServer;
use relume::server::Limits;
use serde_json::{json, Value};

fn small(scene: &str) -> Value {
    json!({"scene": scene, "width": 16, "height": 16})
}

async fn post(s: &TestServer, path: &str, body: Value) -> (u16, Value) {
    let r = s.http.post(s.url(path)).json(&body).send().await.expect("request");
    let status = r.status().as_u16();
    (status, r.json().await.unwrap_or(Value::Null))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tick_rate_that_would_overflow_the_period_is_refused() {
    // Hazard: tick_hz = 1e-30 was accepted, and 1/hz overflowed a Duration inside the worker
    // loop: a panic outside the tick's catch_unwind, the session "running" with no thread.
    let s = TestServer::start(None, Limits::default()).await;
    for hz in [1e-30, 0.001, 0.0, -1.0] {
        let (status, body) =
            post(&s, "/v1/sessions", json!({"scene": "cornell-box", "width": 16, "height": 16, "tick_hz": hz})).await;
        assert_eq!(status, 422, "tick_hz {hz}: {body}");
        assert!(body["detail"].as_str().unwrap_or_default().contains("tick_hz"), "{body}");
    }
    assert_eq!(s.state.session_count(), 0);
    let (status, body) =
        post(&s, "/v1/sessions", json!({"scene": "cornell-box", "width": 16, "height": 16, "tick_hz": 0.01})).await;
    assert_eq!(status, 201, "{body}");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batches_valid_alone_but_not_together_are_refused_at_queue_time() {
    // Hazard: `{camera, position: X}` then `{camera, look_at: X}` were each valid, merged at
    // the tick into a camera looking at itself, and failed the session (409 from then on).
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(small("cornell-box")).await;
    let edits = format!("/v1/sessions/{id}/edits");
    let (status, body) = post(&s, &edits, json!({"edits": [{"target": "camera", "position": [278, 273, -300]}]})).await;
    assert_eq!(status, 202, "{body}");
    let (status, body) = post(&s, &edits, json!({"edits": [{"target": "camera", "look_at": [278, 273, -300]}]})).await;
    assert_eq!(status, 422, "{body}");
    // The field is named by its place in the batch that was refused.
    assert!(body["detail"].as_str().unwrap_or_default().contains("edits[0].camera.look_at"), "{body}");
    // The accepted edit applies and the session keeps working.
    let (status, body) = post(&s, &format!("/v1/sessions/{id}/tick"), json!({})).await;
    assert_eq!(status, 200, "{body}");
    let (status, _) = post(&s, &format!("/v1/sessions/{id}/tick"), json!({})).await;
    assert_eq!(status, 200);
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_pending_queue_holds_one_entry_per_target() {
    // Hazard: accepted batches piled up while nothing ticked. They are coalesced at queue time,
    // so the queue never holds more entries than there are targets, and the tick still reports
    // every edit received and how many were coalesced.
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(small("bunnies-1")).await;
    let edits = format!("/v1/sessions/{id}/edits");
    let batches = 300;
    let mut pending = 0;
    for i in 0..batches {
        let bunny = json!({"target": "object", "name": "bunny-1", "transform": {"translation": [200 + i, 0, 250], "scale": [120, 120, 120]}});
        let camera = json!({"target": "camera", "position": [278, 273, -800 + i as i64]});
        let (status, body) = post(&s, &edits, json!({"edits": [bunny, camera]})).await;
        assert_eq!(status, 202, "{body}");
        pending = body["pending"].as_u64().unwrap_or(u64::MAX);
    }
    assert_eq!(pending, 2, "two targets, so two queued entries");
    let (status, body) = post(&s, &format!("/v1/sessions/{id}/tick"), json!({})).await;
    assert_eq!(status, 200, "{body}");
    let stats = &body["stats"];
    assert_eq!(
        (stats["edits_received"].as_u64(), stats["edits_coalesced"].as_u64()),
        (Some(2 * batches), Some(2 * batches - 2))
    );
    assert_eq!(stats["moved_surfaces"], 1);
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bodies_that_are_not_json_get_415() {
    // Hazard: any web page can POST `text/plain` to 127.0.0.1 without a CORS preflight. Only
    // `application/json` bodies are read; the rest get a 415 with the JSON error body.
    let s = TestServer::start(None, Limits::default()).await;
    let body = json!({"scene": "cornell-box", "width": 16, "height": 16}).to_string();
    for content_type in [None, Some("text/plain"), Some("application/x-www-form-urlencoded")] {
        let mut req = s.http.post(s.url("/v1/sessions")).body(body.clone());
        if let Some(ct) = content_type {
            req = req.header("content-type", ct);
        }
        let r = req.send().await.expect("request");
        assert_eq!(r.status(), 415, "{content_type:?}");
        let v: Value = r.json().await.expect("a JSON error body");
        assert_eq!(v["error"], "unsupported_media_type");
        assert!(v["detail"].as_str().unwrap_or_default().contains("content-type"), "{v}");
    }
    assert_eq!(s.state.session_count(), 0);
    let r = s
        .http
        .post(s.url("/v1/sessions"))
        .header("content-type", "application/json; charset=utf-8")
        .body(body)
        .send()
        .await
        .expect("request");
    assert_eq!(r.status(), 201);
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_are_listed_and_websocket_messages_share_the_body_limit() {
    // `GET /v1/sessions` lists what the server holds (so a client or an operator can find and
    // delete what it left behind); a WebSocket message larger than the HTTP body limit is
    // refused like an HTTP body of that size would be (the library default was 64 MiB).
    let limits = Limits { max_body_bytes: 64 << 10, ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let a = s.session(small("cornell-box")).await;
    let b = s.session(small("cornell-box")).await;
    let list: Value = s.http.get(s.url("/v1/sessions")).send().await.unwrap().json().await.unwrap();
    let ids: Vec<&str> = list["sessions"].as_array().unwrap().iter().map(|v| v["id"].as_str().unwrap()).collect();
    let mut expected = vec![a.as_str(), b.as_str()];
    expected.sort();
    assert_eq!(ids, expected);

    use futures_util::{SinkExt, StreamExt};
    let mut ws = common::ws::open(&s.ws_url(&format!("/v1/sessions/{a}/ws"))).await;
    let big = format!("{{\"type\":\"tick\",\"pad\":\"{}\"}}", "x".repeat(128 << 10));
    let _ = ws.send(tokio_tungstenite::tungstenite::Message::Text(big.into())).await;
    // The server closes the socket instead of reading 128 KiB into memory.
    let closed = tokio::time::timeout(std::time::Duration::from_secs(10), async {
        loop {
            match ws.next().await {
                None | Some(Err(_)) | Some(Ok(tokio_tungstenite::tungstenite::Message::Close(_))) => return true,
                Some(Ok(_)) => continue,
            }
        }
    })
    .await;
    assert_eq!(closed, Ok(true), "an oversized message did not close the socket");
    // The session itself is unharmed.
    let r = s.http.post(s.url(&format!("/v1/sessions/{a}/tick"))).send().await.unwrap();
    assert_eq!(r.status(), 200);
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn framework_errors_have_the_json_error_body_too() {
    // A wrong method and a plain GET on the WebSocket route got the framework's empty or
    // plain-text answers; every error now has `{error, detail}`.
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(small("cornell-box")).await;
    for (method, path, status) in [
        (reqwest::Method::GET, format!("/v1/sessions/{id}/tick"), 405u16),
        (reqwest::Method::PUT, "/v1/sessions".to_string(), 405),
        (reqwest::Method::GET, format!("/v1/sessions/{id}/ws"), 0),
    ] {
        let r = s.http.request(method.clone(), s.url(&path)).send().await.expect("request");
        let got = r.status().as_u16();
        assert!(if status == 0 { (400..500).contains(&got) } else { got == status }, "{method} {path}: {got}");
        let v: Value = r.json().await.unwrap_or_else(|e| panic!("{method} {path}: not JSON: {e}"));
        assert!(v["error"].is_string() && v["detail"].as_str().is_some_and(|d| d.contains("/v1/sessions")), "{v}");
    }
    s.shutdown().await.unwrap();
}

/// An inline scene of `objects` spheres of `segments` and `lights` point lights.
fn inline_scene(objects: usize, segments: u32, lights: usize) -> Value {
    let objects: Vec<Value> = (0..objects)
        .map(|i| json!({"name": format!("s{i}"), "shape": {"type": "sphere", "segments": segments}, "material": "white"}))
        .collect();
    let lights: Vec<Value> = (0..lights)
        .map(|i| json!({"name": format!("l{i}"), "emitter": {"type": "point", "intensity": [1, 1, 1]}, "transform": {"translation": [0, 3, 0]}}))
        .collect();
    json!({
        "camera": {"position": [0, 0, -5], "look_at": [0, 0, 0], "vfov_deg": 40, "resolution": [16, 16]},
        "materials": {"white": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "objects": objects,
        "lights": lights
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn meshes_objects_and_lights_are_counted_before_anything_is_built() {
    // Hazard: meshes were built and then counted, so a small body of finely tessellated spheres
    // cost seconds of CPU, and a few hundred would exhaust memory, before the 413. Built first,
    // this scene's 300 spheres of 4096 segments (5·10⁹ triangles) could not come back at all.
    let s = TestServer::start(None, Limits::default()).await;
    let (status, body) = post(&s, "/v1/sessions", json!({"scene": inline_scene(300, 4096, 1)})).await;
    assert_eq!(status, 413, "{body}");
    let detail = body["detail"].as_str().unwrap_or_default();
    assert!(detail.contains("scene.objects") && detail.contains("triangles"), "{body}");
    let limits = Limits::default();
    let (status, body) = post(&s, "/v1/sessions", json!({"scene": inline_scene(limits.max_objects + 1, 3, 1)})).await;
    assert_eq!(status, 413, "{body}");
    assert!(body["detail"].as_str().unwrap_or_default().contains("objects exceed"), "{body}");
    let (status, body) = post(&s, "/v1/sessions", json!({"scene": inline_scene(1, 8, limits.max_lights + 1)})).await;
    assert_eq!(status, 413, "{body}");
    assert!(body["detail"].as_str().unwrap_or_default().contains("scene.lights"), "{body}");
    assert_eq!(s.state.session_count(), 0);
    // The same scenes within the limits load.
    let (status, body) = post(&s, "/v1/sessions", json!({"scene": inline_scene(3, 64, limits.max_lights)})).await;
    assert_eq!(status, 201, "{body}");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_technique_is_bounded_before_it_allocates() {
    // Hazard: `particle_area` overrode the particle cap (1e-9 m² asks for ~10¹² particles on
    // the Cornell box), and nothing weighed VPLs × cache records or paths × bounces against
    // memory. Each is now estimated at creation and refused with 413 naming its field.
    let limits = Limits { session_memory: 256 << 20, server_memory: 300 << 20, ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let cases = [
        (json!({"id": "particle_gi", "particle_area": 1e-9}), "technique.particle_area"),
        (json!({"id": "instant_cache", "vpls": 65536}), "technique.vpls"),
        (json!({"id": "photon_reuse", "paths": 4_000_000}), "technique.paths"),
        (json!({"id": "photon_reuse", "paths": 1000, "radius": 1e6}), "technique.radius"),
    ];
    for (technique, field) in cases {
        let (status, body) = post(&s, "/v1/sessions", json!({"scene": "cornell-box", "technique": technique})).await;
        assert_eq!(status, 413, "{technique}: {body}");
        assert!(body["detail"].as_str().unwrap_or_default().contains(field), "{technique}: {body}");
    }
    assert_eq!(s.state.session_count(), 0);
    // The server's budget: two sessions that fit one at a time do not fit together, and a
    // deleted session gives its share back.
    let big = json!({"scene": "cornell-box", "width": 16, "height": 16, "technique": {"id": "photon_reuse", "paths": 250_000}});
    let first = s.session(big.clone()).await;
    let (status, body) = post(&s, "/v1/sessions", big.clone()).await;
    assert_eq!(status, 429, "{body}");
    assert!(body["detail"].as_str().unwrap_or_default().contains("--server-memory"), "{body}");
    // /metrics counts the refusal under its own code, not under another 429's (too_many_sessions,
    // session_busy), and the 413s under theirs.
    let m = s.http.get(s.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let count = |reason: &str| {
        let key = format!("relume_rejected_requests_total{{reason=\"{reason}\"}} ");
        m.lines().find_map(|l| l.strip_prefix(key.as_str())).map(|v| v.parse::<u64>().unwrap())
    };
    assert_eq!(count("server_memory_full"), Some(1), "{m}");
    assert_eq!(count("too_large"), Some(4), "the four refused techniques above: {m}");
    assert_eq!(count("too_many_sessions"), None, "{m}");
    let r = s.http.delete(s.url(&format!("/v1/sessions/{first}"))).send().await.expect("delete");
    assert_eq!(r.status().as_u16(), 204);
    let (status, body) = post(&s, "/v1/sessions", big).await;
    assert_eq!(status, 201, "{body}");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_creations_never_exceed_max_sessions() {
    // Hazard: the session count was checked before loading and the session inserted after,
    // so creations racing through the load all passed the check. Places are now reserved
    // atomically before loading.
    let limits = Limits { max_sessions: 2, ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let tries = (0..8).map(|_| post(&s, "/v1/sessions", small("cornell-box")));
    let answers = futures_util::future::join_all(tries).await;
    let created = answers.iter().filter(|(status, _)| *status == 201).count();
    assert_eq!(created, 2, "{answers:?}");
    assert!(answers.iter().all(|(status, _)| *status == 201 || *status == 429), "{answers:?}");
    assert_eq!(s.state.session_count(), 2);
    s.shutdown().await.unwrap();
}

/// A GET of `path` with the given headers; the status and the `Access-Control-Allow-Origin`
/// answer, if any.
async fn get_with(s: &TestServer, path: &str, headers: &[(&str, &str)]) -> (u16, Option<String>) {
    let mut req = s.http.get(s.url(path));
    for (k, v) in headers {
        req = req.header(*k, *v);
    }
    let r = req.send().await.expect("request");
    let cors = r.headers().get("access-control-allow-origin").and_then(|v| v.to_str().ok()).map(str::to_string);
    (r.status().as_u16(), cors)
}

/// Opens the session's WebSocket with an `Origin` header; the HTTP status of a refusal, or 101.
async fn upgrade_from(s: &TestServer, id: &str, origin: &str) -> u16 {
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let mut req = s.ws_url(&format!("/v1/sessions/{id}/ws")).into_client_request().expect("request");
    req.headers_mut().insert("origin", origin.parse().expect("header"));
    match tokio_tungstenite::connect_async(req).await {
        Ok(_) => 101,
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => r.status().as_u16(),
        Err(e) => panic!("upgrade from {origin}: {e}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn browser_origins_are_held_to_the_host_and_origin_lists() {
    // Hazards: a DNS-rebinding page reached loopback under its own name; any page could open a
    // session's WebSocket; nothing said whether CORS was on. Now: names outside the Host list
    // get 421, cross-origin upgrades 403, and CORS answers only configured origins.
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let access =
        relume::server::Access { hosts: vec!["relume.test".into()], origins: vec!["https://app.example".into()] };
    let s = TestServer::start_with_access(listener, None, Limits::default(), access).await;
    let port = s.addr.port();
    for (host, want) in [
        (format!("rebind.attacker.example:{port}"), 421),
        (format!("localhost:{port}"), 200),
        (format!("127.0.0.1:{port}"), 200),
        (format!("[::1]:{port}"), 200),
        (format!("relume.test:{port}"), 200),
    ] {
        assert_eq!(get_with(&s, "/healthz", &[("host", &host)]).await.0, want, "Host {host}");
    }
    let id = s.session(small("cornell-box")).await;
    assert_eq!(upgrade_from(&s, &id, "http://evil.example").await, 403);
    assert_eq!(upgrade_from(&s, &id, &format!("http://{}", s.addr)).await, 101, "same origin");
    assert_eq!(upgrade_from(&s, &id, "https://app.example").await, 101, "configured origin");
    let origin = |o: &'static str| [("origin", o)];
    assert_eq!(
        get_with(&s, "/v1/scenes", &origin("https://app.example")).await.1.as_deref(),
        Some("https://app.example")
    );
    assert_eq!(get_with(&s, "/v1/scenes", &origin("http://evil.example")).await.1, None);
    s.shutdown().await.unwrap();
    // With no origins configured, no CORS header is sent at all.
    let s = TestServer::start(None, Limits::default()).await;
    assert_eq!(get_with(&s, "/v1/scenes", &origin("https://app.example")).await.1, None);
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_sessions_expire_and_their_sockets_are_told() {
    // Hazard: nothing expired sessions, and each photon_reuse session holds hundreds of MiB.
    // A session left alone for longer than session_idle is deleted and its WebSocket closed
    // with 4410 and a JSON reason; a twin kept busy with requests survives the same wait.
    let limits = Limits { session_idle: std::time::Duration::from_millis(1500), ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let idle = s.session(small("cornell-box")).await;
    let busy = s.session(small("cornell-box")).await;
    let (mut ws, _) = tokio_tungstenite::connect_async(s.ws_url(&format!("/v1/sessions/{idle}/ws"))).await.expect("ws");
    let started = std::time::Instant::now();
    while started.elapsed() < std::time::Duration::from_millis(4500) {
        let (status, _) = get_with(&s, &format!("/v1/sessions/{busy}"), &[]).await;
        assert_eq!(status, 200, "the busy session expired");
        tokio::time::sleep(std::time::Duration::from_millis(250)).await;
    }
    assert_eq!(get_with(&s, &format!("/v1/sessions/{idle}"), &[]).await.0, 404, "the idle session survived");
    let closed = loop {
        use futures_util::StreamExt;
        match tokio::time::timeout(std::time::Duration::from_secs(5), ws.next()).await.expect("a close in time") {
            Some(Ok(tokio_tungstenite::tungstenite::Message::Close(frame))) => break frame,
            Some(Ok(_)) => continue,
            other => panic!("socket ended without a close frame: {other:?}"),
        }
    };
    let frame = closed.expect("a close frame with a code");
    assert_eq!(u16::from(frame.code), 4410);
    let reason: Value = serde_json::from_str(&frame.reason).expect("a JSON reason");
    assert_eq!(reason["error"], "session_closed");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_accepted_batch_is_numbered_and_ticks_say_which_are_applied() {
    // Hazard: a client could not tell whether an edit it sent had been applied, coalesced or
    // lost. Each accepted batch now gets a sequence number, a refused one none, and each tick
    // reports the last number it applied.
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(small("bunnies-1")).await;
    let edits = format!("/v1/sessions/{id}/edits");
    let tick = format!("/v1/sessions/{id}/tick");
    let (_, body) = post(&s, &tick, json!({})).await;
    assert_eq!(body["stats"]["edits_applied_through"], 0, "{body}");
    let camera = |z: f64| json!({"edits": [{"target": "camera", "position": [278, 273, z]}]});
    let (status, first) = post(&s, &edits, camera(-800.0)).await;
    assert_eq!((status, first["seq"].as_u64()), (202, Some(1)), "{first}");
    let (status, _) = post(&s, &edits, json!({"edits": [{"target": "object", "name": "nope", "transform": {}}]})).await;
    assert_eq!(status, 422);
    let (status, second) = post(&s, &edits, camera(-900.0)).await;
    assert_eq!((status, second["seq"].as_u64()), (202, Some(2)), "a refused batch took a number: {second}");
    let (_, body) = post(&s, &tick, json!({})).await;
    assert_eq!(body["stats"]["edits_applied_through"], 2, "{body}");
    assert_eq!(
        (body["stats"]["edits_received"].as_u64(), body["stats"]["edits_coalesced"].as_u64()),
        (Some(2), Some(1))
    );
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tick_requests_join_the_queued_tick_instead_of_piling_up() {
    // Hazard: every POST /tick queued its own tick, so one client firing 40 at once made the
    // session run 40 ticks back to back on the shared pool, the other sessions waiting.
    let s = TestServer::start(None, Limits::default()).await;
    let id = s
        .session(json!({"scene": "cornell-box", "width": 64, "height": 64, "technique": {"id": "path", "spp": 4}}))
        .await;
    let path = format!("/v1/sessions/{id}/tick");
    let answers = futures_util::future::join_all((0..40).map(|_| post(&s, &path, Value::Null))).await;
    let mut ticks: Vec<u64> = answers
        .iter()
        .map(|(status, body)| {
            assert_eq!(*status, 200, "{body}");
            body["stats"]["tick"].as_u64().expect("tick")
        })
        .collect();
    ticks.sort_unstable();
    ticks.dedup();
    let view: Value = s.http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().json().await.unwrap();
    eprintln!("40 concurrent tick requests ran {} ticks: {ticks:?}", ticks.len());
    assert_eq!(view["ticks"].as_u64(), Some(ticks.len() as u64), "every tick run answered someone");
    assert!(ticks.len() < 40, "no request joined a queued tick");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_flooding_a_busy_session_gets_429_and_the_queue_stays_bounded() {
    // Hazard: the command channel was unbounded: while a slow tick ran, a client could queue
    // edit batches (each up to the body limit) without end.
    let s = TestServer::start(None, Limits::default()).await;
    let id = s
        .session(json!({"scene": "cornell-box", "width": 128, "height": 128, "technique": {"id": "path", "spp": 64}}))
        .await;
    let tick = {
        let (http, url) = (s.http.clone(), s.url(&format!("/v1/sessions/{id}/tick")));
        tokio::spawn(async move { http.post(url).send().await.map(|r| r.status().as_u16()) })
    };
    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    let edit = json!({"edits": [{"target": "camera", "vfov_deg": 39.5}]});
    let path = format!("/v1/sessions/{id}/edits");
    let answers = futures_util::future::join_all(
        (0..3 * relume::server::worker::COMMAND_QUEUE).map(|_| post(&s, &path, edit.clone())),
    )
    .await;
    let busy = answers.iter().filter(|(status, body)| *status == 429 && body["error"] == "session_busy").count();
    let accepted = answers.iter().filter(|(status, _)| *status == 202).count();
    eprintln!("{accepted} batches accepted, {busy} refused as busy");
    assert!(busy > 0, "no batch was refused while the queue was full");
    assert_eq!(busy + accepted, answers.len(), "every batch was either accepted or refused as busy");
    assert_eq!(tick.await.unwrap().unwrap(), 200);
    // The session is healthy once the queue drains.
    assert_eq!(post(&s, &path, edit).await.0, 202);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn edits_that_overflow_world_space_are_refused_and_the_largest_accepted_ones_render() {
    // Hazard: a finite but huge edit (translation 3e38, scale 1e30, radiance 3e38) was accepted.
    // The bunny's area overflowed; `particle_gi` derived its particle spacing from it and asked
    // for 34 GB, and the failed allocation aborted the whole server with every session in it.
    // Coordinates, scales and emission are now bounded where edits are validated; at the bounds,
    // every technique still ticks and the server keeps serving.
    let s = TestServer::start(None, Limits::default()).await;
    let object = |transform: Value| json!({"edits": [{"target": "object", "name": "bunny-1", "transform": transform}]});
    let refused = [
        (object(json!({"translation": [3e38, 0, 0]})), "edits[0].transform.translation[0]"),
        (object(json!({"scale": [1e30, 1, 1]})), "edits[0].transform.scale[0]"),
        (object(json!({"scale": [1, 1e-30, 1]})), "edits[0].transform.scale[1]"),
        // Each part within its bound, the bunny's far side (0.51 from its origin) beyond 1e8.
        (object(json!({"translation": [9.99e7, 0, 0], "scale": [1e6, 1e6, 1e6]})), "edits[0].transform"),
        (
            json!({"edits": [{"target": "light", "name": "ceiling-light", "emitter": {"type": "rect", "radiance": [3e38, 1, 1]}}]}),
            "edits[0].emitter.radiance",
        ),
        (json!({"edits": [{"target": "camera", "position": [0, -2e8, 0]}]}), "edits[0].camera.position[1]"),
    ];
    for config in common::small_techniques() {
        let spec = serde_json::to_value(&config).expect("spec");
        let id = s.session(json!({"scene": "bunnies-1", "width": 16, "height": 16, "technique": spec})).await;
        let (edits, tick) = (format!("/v1/sessions/{id}/edits"), format!("/v1/sessions/{id}/tick"));
        for (body, field) in &refused {
            let (status, answer) = post(&s, &edits, body.clone()).await;
            assert_eq!(status, 422, "{}: {body} → {answer}", config.id());
            let detail = answer["detail"].as_str().unwrap_or_default();
            assert!(detail.starts_with(&format!("{field}:")), "{}: {body} → {answer}", config.id());
        }
        let largest = json!({"edits": [
            {"target": "object", "name": "bunny-1", "transform": {"translation": [9.9e7, 0, 0], "scale": [1e6, 1e6, 1e6]}},
            {"target": "light", "name": "ceiling-light", "emitter": {"type": "rect", "radiance": [1e20, 1e20, 1e20]}}
        ]});
        let (status, answer) = post(&s, &edits, largest).await;
        assert_eq!(status, 202, "{}: {answer}", config.id());
        let (status, answer) = post(&s, &tick, json!({})).await;
        assert_eq!(status, 200, "{}: {answer}", config.id());
        let r = s.http.delete(s.url(&format!("/v1/sessions/{id}"))).send().await.expect("delete");
        assert_eq!(r.status().as_u16(), 204);
    }
    let healthy = s.http.get(s.url("/healthz")).send().await.map(|r| r.status().as_u16());
    assert_eq!(healthy.ok(), Some(200));
    s.shutdown().await.unwrap();
}
