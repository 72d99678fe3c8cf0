//! Every HTTP route against a real server on 127.0.0.1:0, and a table of bad inputs that must
//! each get their 4xx while the server and other sessions stay healthy.
mod common;
use common::server::TestServer;
use relume::server::Limits;
use serde_json::{json, Value};

fn small(scene: &str) -> Value {
    json!({"scene": scene, "width": 32, "height": 32})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_answers() {
    let s = TestServer::start(None, Limits::default()).await;
    let http = &s.http;

    // Health names the Embree library this process loaded, which must be Embree 4.
    let embree = relume::embree::Device::new(1).unwrap();
    assert_eq!(embree.version().major, 4, "linked against Embree {}", embree.version());
    let health = http.get(s.url("/healthz")).send().await.unwrap().text().await.unwrap();
    let want =
        format!("ok\nrelume {}\nembree {} ({})\n", env!("CARGO_PKG_VERSION"), embree.version(), s.state.device.isa());
    assert_eq!(health, want);
    let scenes: Value = http.get(s.url("/v1/scenes")).send().await.unwrap().json().await.unwrap();
    let names: Vec<&str> = scenes["scenes"].as_array().unwrap().iter().map(|e| e["name"].as_str().unwrap()).collect();
    assert!(names.contains(&"cornell-box") && names.contains(&"walker"), "{names:?}");

    // Create, inspect.
    let id = s.session(small("bunnies-1")).await;
    let v: Value = http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().json().await.unwrap();
    assert_eq!(v["scene"], "bunnies-1");
    assert_eq!(v["state"], "running");
    assert_eq!(v["ticks"], 0);
    assert_eq!(v["technique"]["id"], "path");

    // The scene document lists what can move.
    let scene: Value = http.get(s.url(&format!("/v1/sessions/{id}/scene"))).send().await.unwrap().json().await.unwrap();
    let bunny = scene["objects"].as_array().unwrap().iter().find(|o| o["name"] == "bunny-1").unwrap();
    assert_eq!(bunny["dynamic"], true);

    // No frame before the first tick.
    assert_eq!(http.get(s.url(&format!("/v1/sessions/{id}/frame.png"))).send().await.unwrap().status(), 404);

    // Edits queue; tick applies them and reports the coalesced count.
    let edit = |x: f32| json!({"target": "object", "name": "bunny-1", "transform": {"translation": [x, 0, 250], "scale": [120, 120, 120]}});
    let r = http
        .post(s.url(&format!("/v1/sessions/{id}/edits")))
        .json(&json!({"edits": [edit(150.0), edit(200.0)]}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let acc: Value = r.json().await.unwrap();
    // Both edits target the bunny: the queue holds one entry for it.
    assert_eq!((acc["queued"].as_u64(), acc["pending"].as_u64()), (Some(2), Some(1)));
    let tick: Value = http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap().json().await.unwrap();
    assert_eq!(tick["stats"]["edits_received"], 2);
    assert_eq!(tick["stats"]["edits_coalesced"], 1);
    assert_eq!(tick["stats"]["moved_surfaces"], 1);
    assert!(tick["frame_url"].as_str().unwrap().contains("frame.png?tick=0"));

    // Frames in three encodings, with tick and accumulation headers.
    for (file, mime) in [("frame.png", "image/png"), ("frame.jpg", "image/jpeg"), ("frame.exr", "image/x-exr")] {
        let r = http.get(s.url(&format!("/v1/sessions/{id}/{file}?tick=0"))).send().await.unwrap();
        assert_eq!(r.status(), 200, "{file}");
        assert_eq!(r.headers()["content-type"], mime);
        assert_eq!(r.headers()["x-relume-tick"], "0");
        assert!(r.headers().contains_key("x-relume-accumulation-id"));
        let body = r.bytes().await.unwrap();
        if file != "frame.exr" {
            let img = image::load_from_memory(&body).unwrap();
            assert_eq!((img.width(), img.height()), (32, 32));
        }
    }

    // Stats history, and GET reflects the ticks.
    http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    let hist: Value =
        http.get(s.url(&format!("/v1/sessions/{id}/stats?n=5"))).send().await.unwrap().json().await.unwrap();
    assert_eq!(hist["stats"].as_array().unwrap().len(), 2);
    let v: Value = http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().json().await.unwrap();
    assert_eq!(v["ticks"], 2);
    assert_eq!(v["last_stats"]["tick"], 1);

    // Metrics count what happened.
    let m = http.get(s.url("/metrics")).send().await.unwrap().text().await.unwrap();
    assert!(m.contains("relume_sessions 1"), "{m}");
    let info = format!("relume_build_info{{version=\"{}\",embree=\"{}\",", env!("CARGO_PKG_VERSION"), embree.version());
    assert!(m.contains(&info), "{m}");
    assert!(m.contains("relume_ticks_total 2"));
    assert!(m.contains("relume_tick_seconds_count 2"));
    assert!(!m.contains("relume_encode_seconds_total 0\n"), "three frames were encoded: {m}");
    assert!(m.contains("relume_rejected_requests_total{reason=\"not_found\"} 1"));

    // Delete ends it.
    assert_eq!(http.delete(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().status(), 204);
    assert_eq!(http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().status(), 404);
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn server_driven_ticks_and_frame_waits() {
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(json!({"scene": "cornell-box", "width": 16, "height": 16, "tick_hz": 50})).await;
    // ?tick=3 waits until the server's own clock reaches tick 3.
    let r = s.http.get(s.url(&format!("/v1/sessions/{id}/frame.png?tick=3"))).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let tick: u64 = r.headers()["x-relume-tick"].to_str().unwrap().parse().unwrap();
    assert!(tick >= 3);
    // A reachable tick that never comes (nothing ticks this session) times out after the
    // bounded wait, with a JSON error. (0.2 s at the default 120 ticks a second reaches tick
    // 24; an unreachable one is refused at once, a_frame_for_an_unreachable_tick_is_refused_at_once.)
    let short =
        TestServer::start(None, Limits { frame_wait: std::time::Duration::from_millis(200), ..Limits::default() })
            .await;
    let id2 = short.session(small("cornell-box")).await;
    let r = short.http.get(short.url(&format!("/v1/sessions/{id2}/frame.png?tick=20"))).send().await.unwrap();
    assert_eq!(r.status(), 408);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["error"], "timeout");
    s.shutdown().await.unwrap();
    short.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bearer_token_guards_v1_routes() {
    let s = TestServer::start(Some("sesame"), Limits::default()).await;
    assert_eq!(s.http.get(s.url("/healthz")).send().await.unwrap().status(), 200);
    let r = s.http.get(s.url("/v1/scenes")).send().await.unwrap();
    assert_eq!(r.status(), 401);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["error"], "unauthorized");
    assert_eq!(s.http.get(s.url("/v1/scenes")).bearer_auth("wrong").send().await.unwrap().status(), 401);
    assert_eq!(s.http.get(s.url("/v1/scenes")).bearer_auth("sesame").send().await.unwrap().status(), 200);
    // The scheme in any case; a same-length wrong token is refused.
    let with = |auth: &'static str| s.http.get(s.url("/v1/scenes")).header("authorization", auth).send();
    assert_eq!(with("bearer sesame").await.unwrap().status(), 200);
    assert_eq!(with("BEARER sesame").await.unwrap().status(), 200);
    assert_eq!(with("Bearer sesamf").await.unwrap().status(), 401);
    // `?token=` only where a browser cannot set a header (WebSocket and frame GETs),
    // percent-decoded; not on other routes.
    assert_eq!(s.http.get(s.url("/v1/scenes?token=sesame")).send().await.unwrap().status(), 401);
    let frame = s.http.get(s.url("/v1/sessions/nope/frame.png?token=ses%61me")).send().await.unwrap();
    assert_ne!(frame.status(), 401, "the percent-encoded token was refused");
    // On a real session, the token is the query's only foreign field, and the frame answers.
    let created = s
        .http
        .post(s.url("/v1/sessions"))
        .header("authorization", "Bearer sesame")
        .json(&small("cornell-box"))
        .send()
        .await
        .unwrap();
    let id = created.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string();
    let frame = s.http.get(s.url(&format!("/v1/sessions/{id}/frame.png?tick=0&token=sesame"))).send();
    let tick = s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).header("authorization", "Bearer sesame").send();
    let (frame, tick) = tokio::join!(frame, tick);
    assert_eq!(tick.unwrap().status(), 200);
    let frame = frame.unwrap();
    assert_eq!(frame.status(), 200, "{:?}", frame.text().await);
    let frame =
        s.http.get(s.url(&format!("/v1/sessions/{id}/frame.png?token=sesame&exposure=1"))).send().await.unwrap();
    assert_eq!(frame.status(), 200, "{:?}", frame.text().await);
    let frame = s.http.get(s.url("/v1/sessions/nope/frame.png?token=wrong")).send().await.unwrap();
    assert_eq!(frame.status(), 401);
    s.shutdown().await.unwrap();
}

/// (method, path, body, expected status, words the detail must contain)
type BadCase = (&'static str, String, Option<String>, u16, &'static str);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_inputs_get_their_4xx_and_harm_nothing() {
    let limits = Limits { max_sessions: 3, max_body_bytes: 64 * 1024, max_edits_per_message: 10, ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let bystander = s.session(small("cornell-box")).await;
    let victim = s.session(small("bunnies-1")).await;
    let v = |p: &str| format!("/v1/sessions/{victim}{p}");
    let cases = bad_cases(&victim);
    assert!(cases.len() >= 30);
    for case in &cases {
        answers_with_its_4xx(&s, case).await;
    }
    // Too many sessions: the limit is 3 and two exist.
    s.session(small("cornell-box")).await;
    let r = s.http.post(s.url("/v1/sessions")).json(&small("cornell-box")).send().await.unwrap();
    assert_eq!(r.status(), 429);
    // The server is healthy, and both sessions still tick and answer.
    assert_eq!(s.http.get(s.url("/healthz")).send().await.unwrap().status(), 200);
    for id in [&bystander, &victim] {
        let r = s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
        assert_eq!(r.status(), 200, "session {id} harmed");
    }
    // The refused switches left the victim running what it ran.
    let view: Value = s.http.get(s.url(&v(""))).send().await.unwrap().json().await.unwrap();
    assert_eq!(view["technique"]["id"], "path", "{view}");
    // Nothing from the rejected batches was queued: the victim's tick applied no edits.
    let hist: Value = s.http.get(s.url(&v("/stats"))).send().await.unwrap().json().await.unwrap();
    assert_eq!(hist["stats"][0]["edits_received"], 0);
    let m = s.http.get(s.url("/metrics")).send().await.unwrap().text().await.unwrap();
    assert!(m.contains("relume_rejected_requests_total{reason=\"invalid\"}"));
    s.shutdown().await.unwrap();
}

/// The bad requests: each is refused with its status and a detail naming what was wrong.
/// `victim` is the session the per-session requests go to.
fn bad_cases(victim: &str) -> Vec<BadCase> {
    let v = |p: &str| format!("/v1/sessions/{victim}{p}");
    let huge = format!("{{\"edits\": [{}]}}", vec![r#"{"target":"camera","vfov_deg":40}"#; 3000].join(","));
    let many = format!("{{\"edits\": [{}]}}", [r#"{"target":"camera","vfov_deg":40}"#; 11].join(","));
    vec![
        ("POST", "/v1/sessions".into(), Some("{".into()), 400, "EOF"),
        ("POST", "/v1/sessions".into(), Some("not json".into()), 400, "expected"),
        ("POST", "/v1/sessions".into(), Some("[]".into()), 422, "scene: missing"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": 5}"#.into()), 422, "scene"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "colour": 1}"#.into()), 422, "unknown field"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "../../etc/passwd"}"#.into()), 422, "not a scene name"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "no-such-scene"}"#.into()), 404, "no bundled scene"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "width": 100000}"#.into()), 413, "exceeds"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "width": 0}"#.into()), 422, "at least 1"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "width": -3}"#.into()), 422, "width"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "width": "wide"}"#.into()), 422, "invalid type"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "technique": {"id": "magic"}}"#.into()), 422, "unknown variant"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "technique": {"id": "path", "spp": 1000000}}"#.into()), 413, "spp"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "technique": {"id": "path", "packet_width": 7}}"#.into()), 422, "packet_width"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": "cornell-box", "tick_hz": 100000}"#.into()), 422, "tick_hz"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": {"camera": {}}}"#.into()), 422, "scene.camera"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": {"camera": {"position":[0,0,1],"look_at":[0,0,0],"vfov_deg":40,"resolution":[8,8]}, "materials": {"m": {"type":"diffuse","reflectance":[0.5,0.5,0.5]}}, "objects": [{"name":"o","shape":{"type":"mesh","path":"../../../etc/passwd"},"material":"m"}]}}"#.into()), 422, "escapes the scenes root"),
        ("POST", "/v1/sessions".into(), Some(r#"{"scene": {"camera": {"position":[0,0,1],"look_at":[0,0,0],"vfov_deg":40,"resolution":[8,8]}, "materials": {"m": {"type":"diffuse","reflectance":[0.5,0.5,0.5]}}, "objects": [{"name":"o","shape":{"type":"quad"},"material":"m","transform":{"translation":[1e39,0,0]}}]}}"#.into()), 422, "not a finite number"),
        ("GET", "/v1/sessions/nope".into(), None, 404, "no session"),
        ("DELETE", "/v1/sessions/nope".into(), None, 404, "no session"),
        ("POST", "/v1/sessions/nope/tick".into(), None, 404, "no session"),
        ("POST", "/v1/sessions/nope/edits".into(), Some(r#"{"edits": []}"#.into()), 404, "no session"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "object", "name": "ghost", "transform": {}}]}"#.into()), 422, "unknown object"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "object", "name": "floor", "transform": {}}]}"#.into()), 422, "static"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "object", "name": "bunny-1", "transform": {"rotation": [0, 0, 0, 3]}}]}"#.into()), 422, "quaternion"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "object", "name": "bunny-1", "transform": {"scale": [1, 0, 1]}}]}"#.into()), 422, "zero"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "object", "name": "bunny-1", "transform": {"translation": [1e39, 0, 0]}}]}"#.into()), 422, "finite"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "planet", "name": "x"}]}"#.into()), 422, "unknown variant"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "camera", "vfov_deg": 400}]}"#.into()), 422, "vfov_deg"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "material", "name": "bunny", "material": {"type": "diffuse", "reflectance": [2, 0, 0]}}]}"#.into()), 422, "energy"),
        ("POST", v("/edits"), Some(r#"{"edits": [{"target": "light", "name": "ceiling-light", "emitter": {"type": "point", "intensity": [1, 1, 1]}}]}"#.into()), 422, "emitter type"),
        ("POST", v("/edits"), Some(r#"{"edits": {"target": "camera"}}"#.into()), 422, "invalid type"),
        ("POST", v("/edits"), Some(many), 413, "limit of 10"),
        ("POST", v("/edits"), Some(huge), 413, "request body"),
        ("PATCH", v(""), Some("{}".into()), 422, "nothing to change"),
        ("PATCH", v(""), Some(r#"{"denoise": {"quality": "best"}}"#.into()), 422, "denoise"),
        ("PATCH", v(""), Some(r#"{"technique": {"id": "magic"}}"#.into()), 422, "unknown variant"),
        ("PATCH", v(""), Some(r#"{"technique": {"id": "path"}, "scene": "maze"}"#.into()), 422, "unknown field"),
        ("PATCH", v(""), Some(r#"{"technique": {"id": "path", "spp": 1000000}}"#.into()), 413, "technique.spp"),
        ("PATCH", v(""), Some(r#"{"technique": {"id": "path", "spp": 0}}"#.into()), 422, "technique"),
        ("PATCH", v(""), Some(r#"{"technique": {"id": "photon_reuse", "paths": 4000000000}}"#.into()), 413, "technique.paths"),
        ("PATCH", "/v1/sessions/nope".into(), Some(r#"{"technique": {"id": "path"}}"#.into()), 404, "no session"),
        ("GET", v("/frame.gif"), None, 404, "frame.png"),
        ("GET", v("/frame.png?tick=abc"), None, 422, "query"),
        ("GET", v("/frame.png?exposure=1e39"), None, 422, "exposure"),
        ("GET", v("/stats?n=0"), None, 422, "n:"),
        ("GET", v("/stats?n=99999"), None, 422, "n:"),
        ("GET", "/v2/anything".into(), None, 404, "no such route"),
    ]
}

/// Sends one bad request and checks its status and `{error, detail}` body.
async fn answers_with_its_4xx(s: &TestServer, (method, path, body, status, words): &BadCase) {
    let mut req = match *method {
        "GET" => s.http.get(s.url(path)),
        "POST" => s.http.post(s.url(path)),
        "PATCH" => s.http.patch(s.url(path)),
        _ => s.http.delete(s.url(path)),
    };
    if let Some(b) = body {
        req = req.header("content-type", "application/json").body(b.clone());
    }
    let r = req.send().await.unwrap();
    let got = r.status().as_u16();
    let text = r.text().await.unwrap();
    assert_eq!(got, *status, "{method} {path} {body:?}: {text}");
    let v: Value = serde_json::from_str(&text).unwrap_or_else(|_| panic!("{method} {path}: not JSON: {text}"));
    assert!(v["error"].is_string(), "{text}");
    let detail = v["detail"].as_str().unwrap();
    assert!(detail.contains(words), "{method} {path}: detail '{detail}' lacks '{words}'");
}

/// Every client asking for the same frame shares one encoding: repeated GETs and WebSocket
/// subscribers of the same tick and format encode once, and a client holding the bytes gets 304
/// for its ETag. The count would rise with every request if each one encoded.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_are_encoded_once_per_tick_and_format_and_revalidate_by_etag() {
    use common::ws::{next, send};
    use std::sync::atomic::Ordering;
    use tokio_tungstenite::tungstenite::Message;
    let s = TestServer::start(None, Limits::default()).await;
    let encoded = || s.state.metrics.frames_encoded.load(Ordering::Relaxed);
    let id = s.session(small("cornell-box")).await;
    s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    let get = |path: String, etag: Option<String>| {
        let mut r = s.http.get(s.url(&path));
        if let Some(e) = etag {
            r = r.header("if-none-match", e);
        }
        r.send()
    };
    let png = format!("/v1/sessions/{id}/frame.png?tick=0");
    let first = get(png.clone(), None).await.unwrap();
    assert_eq!(first.status(), 200);
    let etag = first.headers()["etag"].to_str().unwrap().to_string();
    let bytes = first.bytes().await.unwrap();
    let after_first = encoded();
    let again = get(png.clone(), None).await.unwrap();
    assert_eq!(again.bytes().await.unwrap(), bytes, "the same frame encoded differently");
    assert_eq!(encoded(), after_first, "a second GET of the same frame encoded it again");
    let revalidated = get(png.clone(), Some(etag.clone())).await.unwrap();
    assert_eq!(revalidated.status(), 304);
    assert_eq!(revalidated.headers()["etag"].to_str().unwrap(), etag);
    let exr = get(format!("/v1/sessions/{id}/frame.exr?tick=0"), Some(etag.clone())).await.unwrap();
    assert_eq!(exr.status(), 200, "another format's ETag differs");
    assert_eq!(encoded(), after_first + 1, "the EXR is a second encoding");

    // Three WebSocket subscribers and an HTTP client of the next tick: one PNG encoding.
    let url = s.ws_url(&format!("/v1/sessions/{id}/ws"));
    let mut sockets = Vec::new();
    for _ in 0..3 {
        let mut ws = common::ws::open(&url).await;
        send(&mut ws, json!({"type": "subscribe", "frames": "png", "stats": false})).await;
        send(&mut ws, json!({"type": "no-such-message"})).await;
        assert!(matches!(next(&mut ws).await, Message::Text(_)), "the subscription is in place");
        sockets.push(ws);
    }
    let before_tick = encoded();
    s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    let mut frames = Vec::new();
    for ws in &mut sockets {
        loop {
            if let Message::Binary(b) = next(ws).await {
                frames.push(b[relume::server::protocol::FRAME_HEADER_LEN..].to_vec());
                break;
            }
        }
    }
    let http_tick1 = get(format!("/v1/sessions/{id}/frame.png?tick=1"), None).await.unwrap().bytes().await.unwrap();
    assert!(frames.iter().all(|f| f[..] == http_tick1[..]), "subscribers got different bytes");
    assert_eq!(encoded(), before_tick + 1, "each subscriber encoded its own copy");
}

/// A view at rest costs its clients nothing: the frames of ticks that left the film as it was
/// (an `instant_cache` view after its refinement) are the same image, so they share one
/// encoding and one ETag, and a client holding the last frame gets 304 for the next. Each
/// tick's frame is fetched after that tick. Control: `path` adds a pass every tick, so each
/// tick's frame has its own ETag and encoding.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_frames_of_a_view_at_rest_share_one_encoding_and_etag() {
    use std::sync::atomic::Ordering;
    let s = TestServer::start(None, Limits::default()).await;
    let encoded = || s.state.metrics.frames_encoded.load(Ordering::Relaxed);
    // Per tick: the frame's ETag, the status of a GET sending the last tick's ETag, and the
    // encodings that GET (and a plain one) made.
    let run = |technique: Value| async {
        let mut body = small("cornell-box");
        body["technique"] = technique;
        let id = s.session(body).await;
        let mut seen: Vec<(String, u16, u64)> = Vec::new();
        for tick in 0..5 {
            s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
            let url = s.url(&format!("/v1/sessions/{id}/frame.png?tick={tick}"));
            let before = encoded();
            let mut conditional = s.http.get(url.clone());
            if let Some((etag, _, _)) = seen.last() {
                conditional = conditional.header("if-none-match", etag.clone());
            }
            let status = conditional.send().await.unwrap().status().as_u16();
            let plain = s.http.get(url).send().await.unwrap();
            let etag = plain.headers()["etag"].to_str().unwrap().to_string();
            seen.push((etag, status, encoded() - before));
        }
        seen
    };
    let resting = run(json!({"id": "instant_cache", "refine_ticks": 2})).await;
    let statuses: Vec<u16> = resting.iter().map(|r| r.1).collect();
    assert_eq!(statuses, [200, 200, 200, 304, 304], "ticks 3 and 4 rest: {resting:?}");
    assert!(resting[2].0 == resting[3].0 && resting[3].0 == resting[4].0, "{resting:?}");
    assert_eq!(resting.iter().map(|r| r.2).collect::<Vec<_>>(), [1, 1, 1, 0, 0], "a resting frame encoded again");
    let path = run(json!({"id": "path", "spp": 1})).await;
    assert!(path.iter().skip(1).all(|r| r.1 == 200 && r.2 == 1), "path's frames change every tick: {path:?}");
}

#[tokio::test]
async fn every_response_names_its_node_and_session_ids_start_with_it() {
    // Property: a proxy can route by the session id's node prefix and check which node
    // answered: ids are `NODE.sID`, and every response (a success, a 404, a refused body, the
    // health check) carries `X-Relume-Node`. The test server's node is "test-node".
    let s = TestServer::start(None, Limits::default()).await;
    let http = &s.http;
    let node = |r: &reqwest::Response| r.headers().get("x-relume-node").map(|v| v.to_str().unwrap_or("").to_string());
    let id = s.session(small("cornell-box")).await;
    assert!(id.starts_with("test-node.s"), "{id}");
    let (prefix, rest) = id.split_once('.').expect("a node prefix");
    assert!(prefix == "test-node" && !rest.contains('.'), "{id}");
    http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    for r in [
        http.get(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap(),
        http.get(s.url("/v1/sessions/nobody.s1-0")).send().await.unwrap(),
        http.post(s.url("/v1/sessions")).body("{").header("content-type", "application/json").send().await.unwrap(),
        http.get(s.url("/healthz")).send().await.unwrap(),
        http.get(s.url("/")).send().await.unwrap(),
        http.get(s.url(&format!("/v1/sessions/{id}/frame.png?tick=0"))).send().await.unwrap(),
    ] {
        assert_eq!(node(&r).as_deref(), Some("test-node"), "{} {:?}", r.status(), r.url().path());
        // Every page and frame also tells the browser not to sniff types, and what it may load.
        let header = |name: &str| r.headers().get(name).map(|v| v.to_str().unwrap_or("").to_string());
        assert_eq!(header("x-content-type-options").as_deref(), Some("nosniff"), "{:?}", r.url().path());
        assert_eq!(
            header("content-security-policy").as_deref(),
            Some(relume::server::CONTENT_SECURITY_POLICY),
            "{:?}",
            r.url().path()
        );
    }
    let csp = relume::server::CONTENT_SECURITY_POLICY;
    assert!(csp.contains("script-src 'self'") && !csp.contains("unsafe-inline"), "{csp}");
}

/// A frame for a tick the session cannot reach within the frame wait, even ticking as fast as
/// the server allows, is refused at once (422 naming `tick`), not held for the whole wait. At
/// the edge of the bound, the last reachable tick is waited for (and here times out, 408).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_frame_for_an_unreachable_tick_is_refused_at_once() {
    // 10 ticks a second for 0.1 s: one tick can arrive, so with no tick run yet tick 1 is the
    // last reachable one.
    let limits = Limits { frame_wait: std::time::Duration::from_millis(100), max_tick_hz: 10.0, ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let id = s.session(small("cornell-box")).await;
    let get = |tick: u64| s.http.get(s.url(&format!("/v1/sessions/{id}/frame.exr?tick={tick}"))).send();
    for tick in [2, 445_724_606_459_404, u64::MAX] {
        let r = get(tick).await.unwrap();
        assert_eq!(r.status(), 422, "tick {tick}");
        let v: Value = r.json().await.unwrap();
        assert!(v["detail"].as_str().unwrap().starts_with("tick: "), "{v}");
    }
    // The bound's edge: tick 1 is reachable, so it is waited for until the frame wait ends.
    assert_eq!(get(1).await.unwrap().status(), 408);
    s.shutdown().await.unwrap();
}

/// One multipart part at the start of `buf`: (its tick, its JPEG bytes, the bytes after it), or
/// `None` while the part has not fully arrived.
fn mjpeg_part(buf: &[u8]) -> Option<(u64, Vec<u8>, Vec<u8>)> {
    let end = buf.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = std::str::from_utf8(&buf[..end]).expect("part headers are text");
    let boundary = format!("--{}\r\n", relume::server::mjpeg::BOUNDARY);
    assert!(head.starts_with(boundary.trim_end()), "a part starts with {head:?}");
    let field = |name: &str| {
        head.lines().find_map(|l| l.strip_prefix(name)).map(|v| v.trim().parse::<u64>().expect(name)).expect(name)
    };
    let (len, tick) = (field("Content-Length:") as usize, field("X-Relume-Tick:"));
    let body = end + 4;
    (buf.len() >= body + len + 2).then(|| (tick, buf[body..body + len].to_vec(), buf[body + len + 2..].to_vec()))
}

/// `GET …/stream.mjpeg` (what an `<img>` tag, VLC or ffmpeg opens): each part is a JPEG of the
/// session's size, ticks only go forward, and a reader that stops reading does not stop the
/// session ticking.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_mjpeg_stream_sends_newest_frames_and_a_stalled_reader_costs_the_session_nothing() {
    use tokio::io::AsyncWriteExt;
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(json!({"scene": "cornell-box", "width": 48, "height": 32, "tick_hz": 60})).await;
    let mut r = s.http.get(s.url(&format!("/v1/sessions/{id}/stream.mjpeg"))).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let kind = r.headers()["content-type"].to_str().unwrap().to_string();
    assert_eq!(kind, format!("multipart/x-mixed-replace; boundary={}", relume::server::mjpeg::BOUNDARY));
    let (mut buf, mut ticks) = (Vec::new(), Vec::new());
    while ticks.len() < 4 {
        if let Some((tick, jpeg, rest)) = mjpeg_part(&buf) {
            let image = image::load_from_memory_with_format(&jpeg, image::ImageFormat::Jpeg).expect("a valid JPEG");
            assert_eq!((image.width(), image.height()), (48, 32), "tick {tick}");
            ticks.push(tick);
            buf = rest;
            continue;
        }
        buf.extend_from_slice(&r.chunk().await.unwrap().expect("the stream ended early"));
    }
    assert!(ticks.windows(2).all(|w| w[0] < w[1]), "ticks went back or repeated: {ticks:?}");
    // A reader that asks for the stream and never reads holds a connection, nothing more: the
    // session goes on ticking at its rate.
    let mut stalled = tokio::net::TcpStream::connect(s.addr).await.unwrap();
    let ask = format!("GET /v1/sessions/{id}/stream.mjpeg HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n");
    stalled.write_all(ask.as_bytes()).await.unwrap();
    let later = ticks.last().unwrap() + 30;
    let frame = s.http.get(s.url(&format!("/v1/sessions/{id}/frame.jpg?tick={later}"))).send().await.unwrap();
    assert_eq!(frame.status(), 200, "the session stopped ticking behind a stalled stream reader");
    drop((stalled, r));
    s.shutdown().await.unwrap();
}
