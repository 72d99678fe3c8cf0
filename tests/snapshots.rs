//! Session snapshots: `GET …/snapshot` and `POST /v1/sessions {"snapshot"}` against a real
//! server, the restored session against a twin that never moved, and bad snapshots.
mod common;
use common::server::TestServer;
use common::{assert_matches_reference, assert_rejected_by_reference, Tolerance};
use jsonschema::Resource;
use relume::engine::Session;
use relume::scene::edits::Edit;
use relume::scene::Scene;
use relume::server::Limits;
use relume::technique::TechniqueConfig;
use serde_json::{json, Value};
use std::path::Path;

/// A restored session's frame against its twin's: both are fresh accumulations of the same
/// scene with independent photons, so they agree as two runs of photon_reuse do.
const TWIN_TOLERANCE: Tolerance = Tolerance { channel: 0.03, block: 0.10, floor: 0.002 };

fn photon_reuse() -> Value {
    json!({"id": "photon_reuse", "paths": 20000})
}

fn camera_edit(z: f32) -> Value {
    json!({"target": "camera", "position": [278, 273, z], "look_at": [278, 273, 0]})
}

async fn post(s: &TestServer, path: &str, body: &Value) -> (u16, Value) {
    let r = s.http.post(s.url(path)).json(body).send().await.unwrap();
    (r.status().as_u16(), r.json().await.unwrap_or(Value::Null))
}

async fn get(s: &TestServer, path: &str) -> Value {
    let r = s.http.get(s.url(path)).send().await.unwrap();
    assert_eq!(r.status(), 200, "GET {path}");
    r.json().await.unwrap()
}

fn proto(name: &str) -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("proto").join(name);
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Errors of `doc` against proto/snapshot.schema.json (with the schemas it refers to).
fn schema_errors(doc: &Value) -> Vec<String> {
    let resource = |name: &str| Resource::from_contents(proto(name)).unwrap();
    let base = "https://relume.invalid/proto";
    let v = jsonschema::options()
        .with_resource(format!("{base}/scene.schema.json"), resource("scene.schema.json"))
        .with_resource(format!("{base}/animation.schema.json"), resource("animation.schema.json"))
        .with_resource(format!("{base}/ws.schema.json"), resource("ws.schema.json"))
        .build(&proto("snapshot.schema.json"))
        .unwrap();
    v.iter_errors(doc).map(|e| format!("{e} at {}", e.instance_path)).collect()
}

/// A photon_reuse session that has ticked twice after a camera edit and holds one more edit
/// queued.
async fn session_with_history(s: &TestServer) -> String {
    let id = s.session(json!({"scene": "cornell-box", "width": 24, "height": 24, "technique": photon_reuse()})).await;
    assert_eq!(post(s, &format!("/v1/sessions/{id}/edits"), &json!({"edits": [camera_edit(-700.0)]})).await.0, 202);
    for _ in 0..2 {
        assert_eq!(post(s, &format!("/v1/sessions/{id}/tick"), &Value::Null).await.0, 200);
    }
    assert_eq!(post(s, &format!("/v1/sessions/{id}/edits"), &json!({"edits": [camera_edit(-760.0)]})).await.0, 202);
    id
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_snapshot_restores_to_the_same_document_and_continues_from_its_tick() {
    let s = TestServer::start(None, Limits::default()).await;
    let id = session_with_history(&s).await;
    let snap = get(&s, &format!("/v1/sessions/{id}/snapshot")).await;
    let errors = schema_errors(&snap);
    assert!(errors.is_empty(), "the snapshot does not match proto/snapshot.schema.json: {errors:?}");
    assert_eq!((snap["tick"].as_u64(), snap["edits_accepted"].as_u64()), (Some(2), Some(2)));
    assert_eq!(snap["pending_edits"].as_array().map(Vec::len), Some(1), "the queued edit travels");
    assert_eq!(snap["scene"]["camera"]["position"][2], -700.0, "the applied edit is in the scene");

    let (status, restored) = post(&s, "/v1/sessions", &json!({"snapshot": snap})).await;
    assert_eq!(status, 201, "{restored}");
    let new_id = restored["id"].as_str().unwrap().to_string();
    assert_ne!(new_id, id);
    assert_eq!(restored["ticks"], 2, "the restored session continues from the snapshot's tick");

    // Snapshot, restore, snapshot: the same document but for the session it came from.
    let mut again = get(&s, &format!("/v1/sessions/{new_id}/snapshot")).await;
    assert_eq!(again["session"], new_id.as_str());
    again["session"] = snap["session"].clone();
    assert_eq!(again, snap, "a restored session's snapshot differs from the one it came from");

    // Its first tick is the snapshot's next one, applies the queued edit, retraces and says so.
    let (_, tick) = post(&s, &format!("/v1/sessions/{new_id}/tick"), &Value::Null).await;
    let stats = &tick["stats"];
    assert_eq!(stats["tick"], 2);
    assert_eq!(stats["restored"], true);
    assert_eq!(stats["edits_applied_through"], 2);
    assert_eq!(stats["accumulation_id"].as_u64(), snap["accumulation_id"].as_u64().map(|a| a + 1));
    let (_, tick) = post(&s, &format!("/v1/sessions/{new_id}/tick"), &Value::Null).await;
    assert!(tick["stats"].get("restored").is_none(), "only the first tick after a restore says restored");
    // The original, ticked once, holds the same scene.
    post(&s, &format!("/v1/sessions/{id}/tick"), &Value::Null).await;
    let (a, b) =
        (get(&s, &format!("/v1/sessions/{id}/scene")).await, get(&s, &format!("/v1/sessions/{new_id}/scene")).await);
    assert_eq!(a, b, "the restored session's scene differs from the original's");
    assert_eq!(b["camera"]["position"][2], -760.0);
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_playing_animation_goes_on_playing_from_its_clock() {
    let s = TestServer::start(None, Limits::default()).await;
    let id =
        s.session(json!({"scene": "walker", "width": 16, "height": 16, "technique": {"id": "path", "spp": 1}})).await;
    let mut ws = common::ws::open(&s.ws_url(&format!("/v1/sessions/{id}/ws"))).await;
    common::ws::send(&mut ws, json!({"type": "subscribe", "frames": "none"})).await;
    common::ws::send(&mut ws, json!({"type": "play", "anim": "walker", "speed": 2.0})).await;
    while common::ws::next_text(&mut ws).await["type"] != "stats" {}
    let snap = get(&s, &format!("/v1/sessions/{id}/snapshot")).await;
    let playing = &snap["animation"];
    assert_eq!(playing["speed"], 2.0, "{playing}");
    let clock = playing["clock_s"].as_f64().unwrap();
    assert!(clock > 0.0, "the clock has run: {clock}");
    assert!(schema_errors(&snap).is_empty(), "{:?}", schema_errors(&snap));
    let (status, restored) = post(&s, "/v1/sessions", &json!({"snapshot": snap})).await;
    assert_eq!(status, 201, "{restored}");
    assert_eq!(restored["scene"], "walker", "a bundled scene keeps its name, so its animations stay playable");
    let new_id = restored["id"].as_str().unwrap();
    let later = get(&s, &format!("/v1/sessions/{new_id}/snapshot")).await;
    let later_clock = later["animation"]["clock_s"].as_f64().unwrap();
    assert!(later_clock >= clock, "the restored clock went back: {later_clock} < {clock}");
    assert_eq!(later["animation"]["animation"], playing["animation"]);
    // The restored session plays on by itself: its ticks advance without a client.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    loop {
        let v = get(&s, &format!("/v1/sessions/{new_id}")).await;
        if v["ticks"].as_u64().unwrap() > snap["tick"].as_u64().unwrap() + 2 {
            break;
        }
        assert!(std::time::Instant::now() < deadline, "the restored session does not tick on its own: {v}");
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_snapshots_get_a_4xx_naming_the_field_and_cost_nothing() {
    let limits = Limits { max_triangles: 100, ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let id = s.session(json!({"scene": "cornell-box", "width": 16, "height": 16})).await;
    let snap = get(&s, &format!("/v1/sessions/{id}/snapshot")).await;
    for (label, body, status, field) in bad_snapshots(&snap) {
        let (got, err) = post(&s, "/v1/sessions", &body).await;
        assert_eq!(got, status, "{label}: {err}");
        assert!(err["detail"].as_str().unwrap_or_default().contains(field), "{label}: {err} does not name {field}");
    }
    truncated_and_oversize(&s, &snap).await;
    // None of it cost a session or harmed the one there.
    assert_eq!(s.state.session_count(), 1);
    assert_eq!(post(&s, &format!("/v1/sessions/{id}/tick"), &Value::Null).await.0, 200);
    s.shutdown().await.unwrap();
}

/// Broken variants of `snap`, each with its label, the status it must get and the text its
/// `detail` must contain (the field it names).
fn bad_snapshots(snap: &Value) -> Vec<(&'static str, Value, u16, &'static str)> {
    let with = |f: &dyn Fn(&mut Value)| {
        let mut v = snap.clone();
        f(&mut v);
        json!({ "snapshot": v })
    };
    vec![
        (
            "path escape",
            with(&|v| v["scene"]["objects"][0]["shape"]["path"] = json!("../../../etc/passwd")),
            422,
            "snapshot.scene.objects[0].shape.path",
        ),
        ("wrong format", with(&|v| v["format"] = json!("relume.snapshot/9")), 422, "snapshot.format"),
        (
            "missing field",
            with(&|v| {
                v.as_object_mut().unwrap().remove("technique");
            }),
            422,
            "snapshot: missing field `technique`",
        ),
        ("unknown field", with(&|v| v["film"] = json!([1, 2])), 422, "snapshot.film: unknown field `film`"),
        ("counter past 2^53", with(&|v| v["tick"] = json!(1u64 << 60)), 422, "snapshot.tick"),
        (
            "bad pending edit",
            with(&|v| {
                v["pending_edits"] =
                    json!([{"target": "object", "name": "nobody", "transform": {"translation": [0, 0, 0]}}])
            }),
            422,
            "snapshot.pending_edits",
        ),
        ("bad technique", with(&|v| v["technique"] = json!({"id": "path", "spp": -1})), 422, "snapshot.technique"),
        ("too many spp", with(&|v| v["technique"] = json!({"id": "path", "spp": 1000})), 413, "snapshot.technique.spp"),
        (
            "oversize resolution",
            with(&|v| v["scene"]["camera"]["resolution"] = json!([4096, 4096])),
            413,
            "snapshot.width/height",
        ),
        (
            "zero speed",
            with(&|v| v["animation"] = json!({"animation": {"duration": 1, "tracks": []}, "speed": 0, "clock_s": 0})),
            422,
            "snapshot.animation.speed",
        ),
        (
            "snapshot and scene",
            json!({"snapshot": snap, "scene": "cornell-box"}),
            422,
            "scene: a restore takes only 'snapshot'",
        ),
    ]
}

/// A truncated snapshot gets a 400 naming where it stopped; one whose scene holds more
/// triangles than the server allows gets a 413 naming the scene.
async fn truncated_and_oversize(s: &TestServer, snap: &Value) {
    // Truncated: malformed JSON, 400, naming where it stopped.
    let text = json!({ "snapshot": snap }).to_string();
    let r = s
        .http
        .post(s.url("/v1/sessions"))
        .header("content-type", "application/json")
        .body(text[..text.len() / 2].to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 400);
    let err: Value = r.json().await.unwrap();
    assert!(err["detail"].as_str().unwrap().starts_with("snapshot."), "{err}");
    // Oversize: a snapshot whose scene holds more triangles than the server allows.
    let mut big = snap.clone();
    let tri = json!({"name": "extra", "shape": {"type": "mesh", "path": "meshes/bunny.obj"}, "material": "white"});
    big["scene"]["objects"].as_array_mut().unwrap().push(tri);
    let (got, err) = post(s, "/v1/sessions", &json!({ "snapshot": big })).await;
    assert_eq!(got, 413, "{err}");
    assert!(err["detail"].as_str().unwrap().starts_with("snapshot.scene."), "{err}");
}

/// The engine half of a restore, against a twin that never moved: the same scene state, the
/// same tick numbers, and frames that agree within photon_reuse's run-to-run tolerance. The
/// negative control restores without the queued edit, and must fail the same tolerance.
#[test]
fn a_restored_session_renders_what_its_twin_renders() {
    let device = relume::embree::Device::new(2).unwrap();
    let pool = relume::engine::thread_pool(2).unwrap();
    let config: TechniqueConfig = serde_json::from_value(json!({"id": "photon_reuse", "paths": 60000})).unwrap();
    let mut scene = common::load("cornell-box.json");
    scene.set_resolution(24, 24);
    let edit = |z: f32| -> Edit { serde_json::from_value(camera_edit(z)).unwrap() };
    let mut twin = Session::new(scene, &config, 5, &device).unwrap();
    twin.queue_edits(vec![edit(-700.0)]).unwrap();
    pool.install(|| (0..3).for_each(|_| drop(twin.tick().unwrap())));
    twin.queue_edits(vec![edit(-900.0)]).unwrap();

    let restore = |keep_pending: bool| {
        let mut progress = twin.progress();
        if !keep_pending {
            progress.pending.clear();
        }
        let root = common::scenes_dir();
        let scene = Scene::from_desc(twin.scene().desc().clone(), &root, &root).unwrap();
        let mut s = Session::new(scene, &config, 5, &device).unwrap();
        s.resume(progress).unwrap();
        s
    };
    let (mut moved, mut broken) = (restore(true), restore(false));
    let ticks = 12;
    let run = |s: &mut Session| pool.install(|| (0..ticks).map(|_| s.tick().unwrap()).last().unwrap());
    let (a, b, c) = (run(&mut twin), run(&mut moved), run(&mut broken));
    assert_eq!(a.tick, b.tick, "the restored session's ticks are numbered as its twin's");
    assert_eq!(twin.scene().desc(), moved.scene().desc());
    assert_eq!(a.spp, b.spp);
    assert_matches_reference("restored vs twin", &b.image, &a.image, TWIN_TOLERANCE);
    assert_rejected_by_reference("restored without its queued edit", &c.image, &a.image, TWIN_TOLERANCE);
}
