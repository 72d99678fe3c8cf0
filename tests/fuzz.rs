//! Fuzzing on the stable toolchain: property tests (proptest) that feed mutated documents to
//! every parser and validator that takes outside input, and mutated requests and WebSocket
//! messages to a real server.
//!
//! Each case takes a valid seed document (a bundled scene, the protocol examples, a spec of
//! every technique), replaces, removes or retypes one value at a random place in it, and
//! checks that the input is either accepted or refused with an error naming a field, never a
//! panic; against the server, that no answer is a 5xx and the server keeps serving. Values are
//! drawn to hit the validators' edges: huge and negative numbers, zero, wrong types, long
//! strings, nested containers. JSON has no NaN or Inf; 1e308 and -1e308 stand in for them, and
//! 3e38 and 1e-30 are finite in f32 but overflow or vanish in what is computed from them.
//!
//! CI runs a fixed-seed slice of a few seconds (`PROPTEST_CASES` unset: the counts below);
//! `scripts/fuzz.sh` runs over a million cases with fresh seeds.
mod common;
use common::server::TestServer;
use proptest::prelude::*;
use proptest::test_runner::{Config, FileFailurePersistence, RngAlgorithm, TestRng, TestRunner};
use relume::scene::edits::Edit;
use relume::scene::{Scene, SceneBudget, SceneDesc};
use relume::server::Limits;
use relume::technique::TechniqueConfig;
use serde_json::{json, Value};

/// Cases per property in CI (each a few milliseconds), unless `PROPTEST_CASES` says otherwise.
fn cases(ci: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|c| c.parse().ok()).unwrap_or(ci)
}

/// A runner with a fixed seed in CI, a fresh one under `scripts/fuzz.sh` (`RELUME_FUZZ_FRESH`).
fn runner(ci_cases: u32) -> TestRunner {
    let config = Config {
        cases: cases(ci_cases),
        failure_persistence: Some(Box::new(FileFailurePersistence::Off)),
        ..Config::default()
    };
    if std::env::var_os("RELUME_FUZZ_FRESH").is_some() {
        TestRunner::new(config)
    } else {
        TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &[7; 32]))
    }
}

/// A JSON value that probes validators: edge numbers, wrong types and small containers.
fn probe() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::from),
        prop_oneof![
            Just(0.0),
            Just(-1.0),
            Just(1e308),
            Just(-1e308),
            Just(1e-300),
            Just(4096.0),
            Just(1e9),
            Just(3e38),
            Just(1e-30)
        ]
        .prop_map(|f: f64| json!(f)),
        any::<i64>().prop_map(Value::from),
        any::<u32>().prop_map(Value::from),
        (-10.0f64..10.0).prop_map(|f| json!(f)),
        "[a-z_]{0,12}".prop_map(Value::from),
        prop_oneof![Just("../../etc/passwd"), Just("bunny-1"), Just("camera"), Just("photon_reuse"), Just("\u{0}")]
            .prop_map(Value::from),
    ];
    leaf.prop_recursive(2, 12, 4, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..4).prop_map(Value::from),
            prop::collection::btree_map("[a-z_]{1,10}", inner, 0..3)
                .prop_map(|m| Value::Object(m.into_iter().collect())),
        ]
    })
}

/// Every place in `v` (JSON pointers), the root included.
fn places(v: &Value, at: String, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => m.iter().for_each(|(k, x)| places(x, format!("{at}/{k}"), out)),
        Value::Array(a) => a.iter().enumerate().for_each(|(i, x)| places(x, format!("{at}/{i}"), out)),
        _ => {}
    }
    out.push(at);
}

/// `seed` with one change at place `pick` (modulo the places): replaced by `with`, removed, or
/// wrapped in an array.
fn mutate(seed: &Value, pick: usize, how: u8, with: Value) -> Value {
    let mut doc = seed.clone();
    let mut all = Vec::new();
    places(&doc, String::new(), &mut all);
    let at = &all[pick % all.len()];
    if at.is_empty() {
        return with;
    }
    let (parent, key) = at.rsplit_once('/').unwrap_or(("", at));
    let target = doc.pointer_mut(at).map(std::mem::take).unwrap_or(Value::Null);
    let new = match how % 3 {
        0 => Some(with),
        1 => None,
        _ => Some(json!([target])),
    };
    match (doc.pointer_mut(parent), new) {
        (Some(Value::Object(m)), Some(v)) => {
            m.insert(key.to_string(), v);
        }
        (Some(Value::Object(m)), None) => {
            m.remove(key);
        }
        (Some(Value::Array(a)), v) => {
            if let Ok(i) = key.parse::<usize>() {
                match v {
                    Some(v) => a[i] = v,
                    None => {
                        a.remove(i);
                    }
                }
            }
        }
        _ => {}
    }
    doc
}

/// A mutation of one of `seeds`.
fn mutated(seeds: Vec<Value>) -> impl Strategy<Value = Value> {
    (0..seeds.len(), any::<usize>(), any::<u8>(), probe())
        .prop_map(move |(s, pick, how, with)| mutate(&seeds[s], pick, how, with))
}

fn read_json(path: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("seed file")).expect("seed JSON")
}

fn examples(name: &str) -> Value {
    read_json(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/examples").join(name))
}

/// A refusal must name what it refuses: `field: message` (or `file: message`).
fn names_a_field(e: impl std::fmt::Display) -> Result<(), TestCaseError> {
    let text = e.to_string();
    prop_assert!(text.contains(':'), "an error without a field: {text}");
    Ok(())
}

/// A budget small enough that no accepted case allocates much.
const BUDGET: SceneBudget = SceneBudget { max_triangles: 200_000, max_objects: 200, max_lights: 16 };

#[test]
fn scene_documents_are_accepted_or_refused_by_field() {
    let root = common::scenes_dir();
    let seeds: Vec<Value> = ["cornell-box.json", "uplight.json", "bunnies-1.json", "furnace.json"]
        .iter()
        .map(|n| read_json(&root.join(n)))
        .collect();
    runner(300)
        .run(&mutated(seeds), |doc| match relume::scene::load::parse_json::<SceneDesc>(&doc.to_string()) {
            Ok(desc) => Scene::from_desc_within(desc, &root, &root, &BUDGET).map(|_| ()).or_else(names_a_field),
            Err(e) => names_a_field(e),
        })
        .unwrap();
}

/// A bundled `.glb` as one self-contained glTF JSON document (its binary chunk a `data:` URI).
fn gltf_seed(name: &str) -> Value {
    use base64::Engine;
    let glb = std::fs::read(common::scenes_dir().join(name)).expect("bundled glb");
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("GLB header")) as usize;
    let mut doc: Value = serde_json::from_slice(&glb[20..20 + json_len]).expect("JSON chunk");
    let bin = base64::engine::general_purpose::STANDARD.encode(&glb[28 + json_len..]);
    doc["buffers"][0]["uri"] = json!(format!("data:application/octet-stream;base64,{bin}"));
    doc
}

#[test]
fn gltf_documents_are_accepted_or_refused_by_field() {
    // glTF import over mutated documents: every node, material, light, camera, accessor and
    // animation field of real exports. Each is read (and builds within the budget) or refused
    // with an error naming its part; none panics.
    let root = common::scenes_dir();
    let seeds: Vec<Value> =
        ["cornell-box.glb", "walker.glb", "villa-torch.glb", "maze.glb"].iter().map(|n| gltf_seed(n)).collect();
    let options =
        relume::scene::gltf::ImportOptions { budget: BUDGET, max_buffer_bytes: 1 << 20, ..Default::default() };
    runner(300)
        .run(&mutated(seeds), |doc| {
            match relume::scene::gltf::import_slice(doc.to_string().as_bytes(), None, &options) {
                Ok(imported) => {
                    Scene::from_desc_within(imported.desc, &root, &root, &BUDGET).map(|_| ()).or_else(names_a_field)
                }
                Err(e) => names_a_field(e),
            }
        })
        .unwrap();
}

#[test]
fn edits_and_websocket_messages_are_accepted_or_refused_by_field() {
    let mut scene = common::load("bunnies-1.json");
    scene.set_resolution(8, 8);
    let mut seeds = vec![examples("edits.request.json")];
    seeds.extend(WS_SEEDS.iter().map(|n| examples(n)));
    runner(400)
        .run(&mutated(seeds), |doc| {
            if let Some(edits) = doc.get("edits") {
                if let Ok(batch) = serde_json::from_value::<Vec<Edit>>(edits.clone()) {
                    match relume::scene::edits::queue(&scene, &[], batch) {
                        Ok(queued) => {
                            let mut s = scene.clone();
                            relume::scene::edits::apply(&mut s, queued)
                                .map_err(|e| TestCaseError::fail(e.to_string()))?;
                        }
                        Err(e) => prop_assert!(e.to_string().contains("edits["), "unnamed: {e}"),
                    }
                }
            }
            let _ = serde_json::from_value::<relume::server::protocol::ClientMessage>(doc);
            Ok(())
        })
        .unwrap();
}

#[test]
fn technique_specs_are_accepted_or_refused_by_field() {
    let mut scene = common::load("cornell-box.json");
    scene.set_resolution(8, 8);
    let seeds: Vec<Value> = common::small_techniques().iter().map(|c| serde_json::to_value(c).expect("spec")).collect();
    runner(400)
        .run(&mutated(seeds), |doc| {
            if let Ok(config) = serde_json::from_value::<TechniqueConfig>(doc) {
                match config.resident_estimate(&scene, 64) {
                    Ok(_) => relume::technique::build(&config, &scene).map(|_| ()).or_else(names_a_field)?,
                    Err(e) => names_a_field(e)?,
                }
            }
            Ok(())
        })
        .unwrap();
}

/// Routes a fuzzed request may go to (`{id}`: a live session's id).
const ROUTES: &[(&str, &str)] = &[
    ("POST", "/v1/sessions"),
    ("POST", "/v1/sessions/{id}/edits"),
    ("POST", "/v1/sessions/{id}/tick"),
    ("GET", "/v1/sessions/{id}/frame.png?tick=1"),
    ("GET", "/v1/sessions/{id}/stats"),
    ("DELETE", "/v1/sessions/{id}"),
    ("PATCH", "/v1/sessions/{id}"),
    ("GET", "/v1/sessions/{id}/scene"),
    ("GET", "/v1/sessions/{id}/snapshot"),
    ("POST", "/v1/sessions/nope/edits"),
];

#[test]
fn a_real_server_answers_every_mutated_request_below_500() {
    let limits = Limits {
        max_photon_paths: 20_000,
        max_pixels: 64 * 64,
        max_side: 64,
        max_spp_per_tick: 4,
        max_sessions: 4,
        session_memory: 64 << 20,
        frame_wait: std::time::Duration::from_millis(200),
        ..Limits::default()
    };
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let s = rt.block_on(TestServer::start(None, limits));
    let mut create = examples("create-session.request.json");
    create["width"] = json!(16);
    create["height"] = json!(16);
    // A restore body, from a real snapshot: the mutations reach its scene, counters, edits and
    // animation, which are validated like a create's.
    let snapshot = rt.block_on(async {
        let id = s.session(json!({"scene": "bunnies-1", "width": 16, "height": 16})).await;
        let snap: Value =
            s.http.get(s.url(&format!("/v1/sessions/{id}/snapshot"))).send().await.unwrap().json().await.unwrap();
        s.http.delete(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap();
        snap
    });
    let seeds = vec![
        create,
        examples("edits.request.json"),
        examples("update-session.request.json"),
        json!({}),
        json!({ "snapshot": snapshot }),
    ];
    let body = prop_oneof![4 => mutated(seeds).prop_map(|v| v.to_string().into_bytes()), 1 => prop::collection::vec(any::<u8>(), 0..64)];
    let strategy = (0..ROUTES.len(), body, any::<bool>());
    runner(60)
        .run(&strategy, |(route, body, json_type)| {
            rt.block_on(async {
                let live = s.state.sessions.read().ok().and_then(|m| m.keys().next().cloned());
                let id = match live {
                    Some(id) => id,
                    None => s.session(json!({"scene": "bunnies-1", "width": 16, "height": 16})).await,
                };
                let (method, path) = ROUTES[route];
                let url = s.url(&path.replace("{id}", &id));
                let req = match method {
                    "POST" => s.http.post(url).body(body),
                    "PATCH" => s.http.patch(url).body(body),
                    "DELETE" => s.http.delete(url),
                    _ => s.http.get(url),
                };
                let req = if json_type { req.header("content-type", "application/json") } else { req };
                let r = req.send().await.map_err(|e| TestCaseError::fail(format!("no answer: {e}")))?;
                let status = r.status().as_u16();
                prop_assert!(status < 500, "{method} {path}: {status} {}", r.text().await.unwrap_or_default());
                Ok(())
            })
        })
        .unwrap();
    let healthy = rt.block_on(async { s.http.get(s.url("/healthz")).send().await.map(|r| r.status().as_u16()) });
    assert_eq!(healthy.ok(), Some(200), "the server stopped serving");
    rt.block_on(s.shutdown()).unwrap();
}

/// The WebSocket's golden client messages, the seeds of its fuzzing.
const WS_SEEDS: [&str; 6] = [
    "ws-client-edits.json",
    "ws-client-play.json",
    "ws-client-pause.json",
    "ws-client-subscribe.json",
    "ws-client-tick.json",
    "ws-client-update.json",
];

#[test]
fn a_real_server_websocket_answers_every_mutated_message_and_stays_open() {
    // Mutated client messages on one socket of a live session. Each is answered, if at all,
    // by messages of the protocol and never by an `internal` error, and the socket stays open:
    // after every message a sentinel (a `play` of an animation no mutation can name, always
    // refused by name) must come back. The session keeps ticking and the server keeps serving.
    // Negative control, by hand: a handler that answers `update` with an internal error fails.
    use common::ws::{next, send};
    use relume::server::protocol::ServerMessage;
    use tokio_tungstenite::tungstenite::Message;
    let limits = Limits {
        max_photon_paths: 20_000,
        max_pixels: 64 * 64,
        max_side: 64,
        max_spp_per_tick: 4,
        session_memory: 64 << 20,
        ..Limits::default()
    };
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let s = rt.block_on(TestServer::start(None, limits));
    let id = rt.block_on(s.session(json!({"scene": "bunnies-1", "width": 16, "height": 16})));
    let sentinel = json!({"type": "play", "anim": "sentinel-42"});
    let ws = tokio::sync::Mutex::new(rt.block_on(async {
        let mut ws = common::ws::open(&s.ws_url(&format!("/v1/sessions/{id}/ws"))).await;
        send(&mut ws, json!({"type": "subscribe", "frames": "none", "stats": false})).await;
        ws
    }));
    // Everything the server sends until the sentinel's refusal; fails on a close or an
    // `internal` error.
    let exchange = |message: Value| -> Result<Vec<ServerMessage>, TestCaseError> {
        rt.block_on(async {
            let mut ws = ws.lock().await;
            send(&mut ws, message.clone()).await;
            send(&mut ws, sentinel.clone()).await;
            let mut answers = Vec::new();
            loop {
                let text = match next(&mut ws).await {
                    Message::Text(t) => t,
                    Message::Binary(_) => continue,
                    other => return Err(TestCaseError::fail(format!("{message}: the socket answered {other:?}"))),
                };
                let answer: ServerMessage = serde_json::from_str(&text)
                    .map_err(|e| TestCaseError::fail(format!("{message}: {text} is not a server message: {e}")))?;
                if let ServerMessage::Error { error, detail } = &answer {
                    prop_assert_ne!(error.as_str(), "internal", "{}: {}", message, detail);
                    if detail.contains("sentinel-42") {
                        return Ok(answers);
                    }
                }
                answers.push(answer);
            }
        })
    };
    let valid = exchange(examples("ws-client-update.json")).expect("the golden update");
    assert!(matches!(valid.as_slice(), [ServerMessage::Updated { .. }]), "{valid:?}");
    let seeds = WS_SEEDS.iter().map(|n| examples(n)).collect();
    runner(60).run(&mutated(seeds), |message| exchange(message).map(|_| ())).unwrap();
    let healthy = rt.block_on(async {
        let tick = s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.map(|r| r.status().as_u16());
        let health = s.http.get(s.url("/healthz")).send().await.map(|r| r.status().as_u16());
        (tick.ok(), health.ok())
    });
    assert_eq!(healthy, (Some(200), Some(200)), "the session or the server stopped");
    rt.block_on(s.shutdown()).unwrap();
}
