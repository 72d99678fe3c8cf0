//! Switching a live session's technique (`Session::set_technique`, `PATCH /v1/sessions/{id}`).
//!
//! A switch must be exactly what a client could otherwise do by hand: take a snapshot, change
//! its technique, and restore it. So the twin of a switched session is a session restored
//! from the switched one's progress with the new technique: after one tick both must show the
//! same image bit for bit and the same stats apart from timings. The pending edits cross the
//! switch (they are queued before it). The negative control switches without restarting the
//! film, which the comparison must catch.
mod common;
use common::*;
use relume::engine::{Frame, Session};
use relume::scene::edits::Edit;
use relume::scene::model::Trs;
use relume::scene::Scene;
use relume::technique::TechniqueConfig;
use serde_json::Value;

fn room() -> Scene {
    slab_room([0.0, 1.2, -3.5], [0.0, 0.9, 0.0], [0.3, 0.35, 0.6], [0.35, 0.35, 0.35], [0.0, 1.8, 0.2])
}

/// A 10 cm move of the slab, queued before the switch.
fn slide(scene: &Scene) -> Vec<Edit> {
    let t = scene.desc().objects[scene.object_index("slab").expect("slab")].transform;
    vec![Edit::Object {
        name: "slab".into(),
        transform: Trs { translation: [t.translation[0] + 0.1, t.translation[1], t.translation[2]], ..t },
    }]
}

/// Stats a switched session and its restored twin may differ in: timings, `restored` (only the
/// twin reports it) and the edits received since the last tick (a restore carries the queue,
/// not how many edits were sent into it).
fn ignored(key: &str) -> bool {
    key.ends_with("_ms") || ["times", "restored", "edits_received", "edits_coalesced"].contains(&key)
}

/// A `path` session ticks once, queues [`slide`] if `edits`, and switches to `to` (with
/// `switch`, so the negative control can replace it); its twin is restored from its progress
/// with `to`. Returns the tick after the switch of both, and what `switch` answered.
fn switched_and_twin(
    to: &TechniqueConfig,
    edits: bool,
    switch: impl Fn(&mut Session, &TechniqueConfig) -> bool + Sync,
) -> (Frame, Frame, bool) {
    let device = relume::embree::Device::new(2).expect("device");
    let pool = relume::engine::thread_pool(2).expect("pool");
    pool.install(|| {
        let from = TechniqueConfig::Path(path(1));
        let mut s = Session::new(room(), &from, 5, &device).expect("session");
        s.tick().expect("tick");
        if edits {
            s.queue_edits(slide(s.scene())).expect("valid edits");
        }
        let scene = Scene::from_desc(s.scene().desc().clone(), &scenes_dir(), &scenes_dir()).expect("scene");
        let mut twin = Session::new(scene, to, 5, &device).expect("twin");
        twin.resume(s.progress()).expect("resume");
        let changed = switch(&mut s, to);
        (s.tick().expect("tick"), twin.tick().expect("tick"), changed)
    })
}

fn same_as_twin(after: &Frame, twin: &Frame) -> Result<(), String> {
    same_as_twin_frame(after, twin, ignored)
}

#[test]
fn a_switch_is_a_restore_with_the_new_technique_for_every_technique() {
    let configs: Vec<TechniqueConfig> =
        small_techniques().into_iter().chain([TechniqueConfig::Path(path(2))]).collect();
    for (to, edits) in configs.iter().flat_map(|c| [(c, false), (c, true)]) {
        let (after, twin, changed) = switched_and_twin(to, edits, |s, c| s.set_technique(c).expect("switch"));
        assert!(changed, "{}", to.id());
        assert_eq!(after.stats.technique, to.id());
        assert_eq!(after.stats.moved_surfaces, usize::from(edits), "{}: the queued edit crossed the switch", to.id());
        if let Err(e) = same_as_twin(&after, &twin) {
            panic!("{} (edits: {edits}): {e}", to.id());
        }
    }
    // Negative control: a session that did not switch (it keeps `path` at 1 spp and its film)
    // fails the comparison. Run by hand: a switch that does not restart the film fails it too.
    let (after, twin, _) = switched_and_twin(&TechniqueConfig::Path(path(2)), false, |_, _| true);
    assert!(same_as_twin(&after, &twin).is_err(), "a session that kept its technique passed for a switch");
}

#[test]
fn switching_to_the_running_configuration_changes_nothing() {
    let device = relume::embree::Device::new(2).expect("device");
    let pool = relume::engine::thread_pool(2).expect("pool");
    pool.install(|| {
        for config in small_techniques() {
            let mut s = Session::new(room(), &config, 3, &device).expect("session");
            let mut twin = Session::new(room(), &config, 3, &device).expect("twin");
            let first = s.tick().expect("tick");
            twin.tick().expect("tick");
            assert!(!s.set_technique(&config).expect("switch"), "{}", config.id());
            let (after, twin_after) = (s.tick().expect("tick"), twin.tick().expect("tick"));
            assert_eq!(after.accumulation_id, first.accumulation_id, "{}: the film restarted", config.id());
            assert!(after.image == twin_after.image, "{}: the image differs from the twin's", config.id());
        }
    })
}

/// `PATCH /v1/sessions/{id}` with `body`: (status, JSON answer).
async fn patch(s: &common::server::TestServer, id: &str, body: Value) -> (u16, Value) {
    let r = s.http.patch(s.url(&format!("/v1/sessions/{id}"))).json(&body).send().await.unwrap();
    (r.status().as_u16(), r.json().await.unwrap())
}

/// A tick's stats.
async fn tick(s: &common::server::TestServer, id: &str) -> Value {
    let done = s.post_json(&format!("/v1/sessions/{id}/tick"), &serde_json::json!({})).await;
    done["stats"].clone()
}

/// The server's reserved session memory, from `/metrics`.
async fn reserved_bytes(s: &common::server::TestServer) -> u64 {
    let text = s.http.get(s.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let line = text.lines().find(|l| l.starts_with("relume_session_memory_reserved_bytes ")).expect("gauge");
    line.rsplit(' ').next().and_then(|v| v.parse().ok()).expect("a byte count")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_served_session_switches_and_keeps_its_scene_as_edited() {
    let s = common::server::TestServer::start(None, relume::server::Limits::default()).await;
    let create =
        serde_json::json!({"scene": "bunnies-1", "width": 24, "height": 24, "technique": {"id": "path", "spp": 1}});
    let id = s.session(create).await;
    let translation = serde_json::json!([300.0, 0.0, 280.0]);
    let edit = serde_json::json!({"edits": [{"target": "object", "name": "bunny-1", "transform": {"translation": translation, "scale": [140, 140, 140]}}]});
    s.post_json(&format!("/v1/sessions/{id}/edits"), &edit).await;
    let before = tick(&s, &id).await;
    let to = serde_json::json!({"id": "instant_cache", "vpls": 32});
    let (status, view) = patch(&s, &id, serde_json::json!({ "technique": to })).await;
    assert_eq!(status, 200, "{view}");
    assert_eq!((&view["technique"]["id"], &view["technique"]["vpls"]), (&to["id"], &to["vpls"]));
    assert_eq!(s.get_json(&format!("/v1/sessions/{id}")).await["technique"], view["technique"]);
    let after = tick(&s, &id).await;
    assert_eq!(after["technique"], "instant_cache");
    assert_eq!(after["accumulation_id"].as_u64(), before["accumulation_id"].as_u64().map(|a| a + 1), "{after}");
    let scene = s.get_json(&format!("/v1/sessions/{id}/scene")).await;
    let bunny = scene["objects"].as_array().unwrap().iter().find(|o| o["name"] == "bunny-1").expect("bunny-1");
    assert_eq!(bunny["transform"]["translation"], translation, "the edit was lost");
    let snapshot = s.get_json(&format!("/v1/sessions/{id}/snapshot")).await;
    assert_eq!(snapshot["technique"], view["technique"]);
    // The same configuration again changes nothing: the film keeps accumulating.
    let (status, _) = patch(&s, &id, serde_json::json!({ "technique": view["technique"] })).await;
    assert_eq!(status, 200);
    let again = tick(&s, &id).await;
    assert_eq!(again["accumulation_id"], after["accumulation_id"], "an equal configuration restarted the film");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_switch_resizes_the_memory_share_or_is_refused_changing_nothing() {
    // Negative control, by hand: a resize that adds the new estimate without giving back the
    // old one leaves more reserved after switching back, and fails the last assertion.
    let limits = relume::server::Limits { server_memory: 64 << 20, ..relume::server::Limits::default() };
    let s = common::server::TestServer::start(None, limits).await;
    let create = serde_json::json!({"scene": "bunnies-1", "width": 24, "height": 24});
    let id = s.session(create).await;
    let path_bytes = reserved_bytes(&s).await;
    let (status, answer) = patch(&s, &id, serde_json::json!({"technique": {"id": "photon_reuse"}})).await;
    assert_eq!((status, answer["error"].as_str()), (429, Some("server_memory_full")), "{answer}");
    assert_eq!(reserved_bytes(&s).await, path_bytes, "a refused switch changed the reservation");
    assert_eq!(tick(&s, &id).await["technique"], "path", "a refused switch changed the technique");
    let (status, answer) = patch(&s, &id, serde_json::json!({"technique": {"id": "bdpt"}})).await;
    assert_eq!(status, 200, "{answer}");
    let bdpt_bytes = reserved_bytes(&s).await;
    assert_ne!(bdpt_bytes, path_bytes, "the share was not resized to bdpt's estimate");
    assert_eq!(tick(&s, &id).await["technique"], "bdpt");
    let (status, answer) = patch(&s, &id, serde_json::json!({"technique": {"id": "path"}})).await;
    assert_eq!(status, 200, "{answer}");
    assert_eq!(reserved_bytes(&s).await, path_bytes, "switching back did not give bdpt's share back");
    s.shutdown().await.unwrap();
}
