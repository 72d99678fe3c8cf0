//! Two `relume serve` nodes (the release binary) behind a real HAProxy running
//! deploy/haproxy/relume.cfg, on loopback: sticky routing by the session id's node, WebSockets
//! through the proxy, draining on SIGTERM, and `relume migrate` moving a drained node's
//! sessions to the other, each continuing from its tick with its edits applied and a frame
//! statistically equal to a twin that never moved (with a negative control). relume.cfg names
//! a third node; it is left down here, as a dead node would be.
mod common;
use common::process::{Served, BIN};
use common::ws::{next_frame, next_text, send};
use serde_json::{json, Value};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A port nothing listens on (bound, then released).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// HAProxy in the foreground with the repository's config; killed on drop.
struct Proxy {
    child: Child,
    addr: String,
}

impl Proxy {
    fn start(nodes: [&str; 3]) -> Proxy {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/haproxy");
        let addr = format!("127.0.0.1:{}", free_port());
        let child = Command::new("haproxy")
            .arg("-db")
            .arg("-f")
            .arg(dir.join("relume.cfg"))
            .env("RELUME_PROXY_BIND", &addr)
            .env("RELUME_NODE_MAP", dir.join("nodes.map"))
            .env("RELUME_NODE_0", nodes[0])
            .env("RELUME_NODE_1", nodes[1])
            .env("RELUME_NODE_2", nodes[2])
            .stdout(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("haproxy does not start ({e}): scripts/test.sh installs it (scripts/test-packages.txt)")
            });
        Proxy { child, addr }
    }

    fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }
}

impl Drop for Proxy {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Polls `f` every 100 ms until it is true, failing after `limit` with `what`.
async fn eventually(limit: Duration, what: &str, mut f: impl AsyncFnMut() -> bool) {
    let deadline = Instant::now() + limit;
    while !f().await {
        assert!(Instant::now() < deadline, "{what} within {limit:?}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

fn node_of(resp: &reqwest::Response) -> String {
    resp.headers().get("x-relume-node").and_then(|v| v.to_str().ok()).unwrap_or_default().to_string()
}

async fn post(http: &reqwest::Client, url: String, body: &Value) -> (u16, String, Value) {
    let r = http.post(url).json(body).send().await.expect("request");
    let (status, node) = (r.status().as_u16(), node_of(&r));
    (status, node, r.json().await.unwrap_or(Value::Null))
}

/// The session's frame as mean channel values per 4×4 block of its PNG, for comparing a
/// migrated session with its twin.
async fn frame(http: &reqwest::Client, url: String) -> relume::film::LinearImage {
    let r = http.get(url).send().await.expect("frame");
    assert_eq!(r.status(), 200);
    let png = image::load_from_memory(&r.bytes().await.unwrap()).unwrap().to_rgb32f();
    let pixels = png.pixels().map(|p| relume::core::rgb::Rgb::new(p[0], p[1], p[2])).collect();
    relume::film::LinearImage { width: png.width(), height: png.height(), pixels }
}

const SESSIONS: usize = 8;
/// Two path-traced frames of the same scene, 32² at 256 spp: every channel mean within 3%,
/// every 4×4 block within 10%.
const TWIN: common::Tolerance = common::Tolerance { channel: 0.03, block: 0.10, floor: 0.01 };

fn create_body(seed: u64) -> Value {
    json!({"scene": "cornell-box", "width": 32, "height": 32, "seed": seed, "technique": {"id": "path", "spp": 32}})
}

fn light_edit() -> Value {
    json!({"edits": [{"target": "camera", "position": [278, 273, -600], "look_at": [278, 273, 0]}]})
}

#[test]
fn two_nodes_behind_haproxy_route_drain_and_migrate() {
    // One scenes folder shared by both nodes, as a shared volume is in a deployment.
    let scenes = common::scenes_copy("cluster");
    let mut a = Served::start_in(&scenes, &["--node", "relume-0", "--drain-grace", "60"]);
    let b = Served::start_in(&scenes, &["--node", "relume-1"]);
    let dead = format!("127.0.0.1:{}", free_port());
    let proxy = Proxy::start([&a.addr, &b.addr, &dead]);
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let http = reqwest::Client::builder().timeout(Duration::from_secs(60)).build().unwrap();
    let ids = runtime.block_on(route_through(&http, &proxy, &a));
    runtime.block_on(an_upload_through_the_proxy_opens_on_every_node(&http, &proxy));
    // Drain relume-0: it refuses creates, the proxy stops sending it any, its sessions tick on.
    a.sigterm();
    let on_a: Vec<String> = ids.iter().filter(|id| id.starts_with("relume-0.")).cloned().collect();
    let report = runtime.block_on(drain_and_migrate(&http, &proxy, &a, &on_a));
    assert_eq!(report.len(), on_a.len(), "{report:?}");
    runtime.block_on(continue_like_twins(&http, &proxy, &b, &report));
    // With its sessions gone, the drained node exits cleanly before its grace ends.
    let status = a.wait_exit(Duration::from_secs(30));
    assert_eq!(status.code(), Some(0), "relume-0 ended with {status:?}");
    let _ = std::fs::remove_dir_all(&scenes);
}

/// A scene uploaded through the proxy lands on one node; the nodes share their scenes folder,
/// so sessions on it open on every node the proxy balances creates to.
async fn an_upload_through_the_proxy_opens_on_every_node(http: &reqwest::Client, proxy: &Proxy) {
    let glb = std::fs::read(common::scenes_dir().join("cornell-box.glb")).unwrap();
    let r = http.put(proxy.url("/v1/scenes/shared.glb")).body(glb).send().await.unwrap();
    assert_eq!(r.status(), 201, "{}", r.text().await.unwrap_or_default());
    let mut nodes = std::collections::BTreeMap::new();
    for i in 0..6 {
        let body = json!({"scene": "shared.glb", "width": 8, "height": 8, "seed": i});
        let (status, node, v) = post(http, proxy.url("/v1/sessions"), &body).await;
        assert_eq!(status, 201, "{node}: {v}");
        nodes.entry(node).or_insert_with(Vec::new).push(v["id"].as_str().unwrap().to_string());
    }
    assert_eq!(nodes.len(), 2, "the creates reached only {:?}", nodes.keys());
    for id in nodes.values().flatten() {
        let r = http.delete(proxy.url(&format!("/v1/sessions/{id}"))).send().await.unwrap();
        assert_eq!(r.status(), 204);
    }
}

/// Creates [`SESSIONS`] sessions through the proxy, checks that creates are balanced, that
/// every later request lands on the session's owner and that WebSocket frames flow through;
/// returns the session ids.
async fn route_through(http: &reqwest::Client, proxy: &Proxy, a: &Served) -> Vec<String> {
    eventually(Duration::from_secs(20), "the proxy answers", async || {
        http.get(proxy.url("/healthz")).send().await.is_ok_and(|r| r.status() == 200)
    })
    .await;
    let metrics = http.get(a.url("/metrics")).send().await.unwrap().text().await.unwrap();
    assert!(metrics.contains("\nrelume_draining 0\n"), "{metrics}");
    let mut ids = Vec::new();
    for i in 0..SESSIONS {
        let (status, node, v) = post(http, proxy.url("/v1/sessions"), &create_body(i as u64)).await;
        assert_eq!(status, 201, "{v}");
        let id = v["id"].as_str().unwrap().to_string();
        assert!(id.starts_with(&format!("{node}.")), "{id} was answered by {node}");
        ids.push(id);
    }
    for node in ["relume-0", "relume-1"] {
        assert!(ids.iter().any(|id| id.starts_with(node)), "no session on {node}: {ids:?}");
    }
    for id in &ids {
        let owner = id.split('.').next().unwrap();
        let (s, node, _) = post(http, proxy.url(&format!("/v1/sessions/{id}/edits")), &light_edit()).await;
        assert_eq!((s, node.as_str()), (202, owner));
        let (s, node, _) = post(http, proxy.url(&format!("/v1/sessions/{id}/tick")), &Value::Null).await;
        assert_eq!((s, node.as_str()), (200, owner));
        let r = http.get(proxy.url(&format!("/v1/sessions/{id}/frame.png?tick=0"))).send().await.unwrap();
        assert_eq!((r.status().as_u16(), node_of(&r).as_str()), (200, owner));
    }
    let mut ws = common::ws::open(&format!("ws://{}/v1/sessions/{}/ws", proxy.addr, ids[0])).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "png", "stats": true, "every": 1})).await;
    send(&mut ws, json!({"type": "tick"})).await;
    let stats = next_text(&mut ws).await;
    assert_eq!(stats["stats"]["tick"], 1, "{stats}");
    assert_eq!(next_frame(&mut ws).await.0.tick, 1);
    ids
}

/// With relume-0 (`a`) draining: it reports so and refuses creates, the proxy sends creates to
/// relume-1, relume-0's sessions (`on_a`) tick on, and `relume migrate` moves them, each with
/// an edit queued that only the migrated session will apply. Returns migrate's JSON report.
async fn drain_and_migrate(http: &reqwest::Client, proxy: &Proxy, a: &Served, on_a: &[String]) -> Vec<Value> {
    eventually(Duration::from_secs(10), "relume-0 reports draining", async || {
        http.get(a.url("/healthz")).send().await.is_ok_and(|r| r.status() == 503)
    })
    .await;
    let metrics = http.get(a.url("/metrics")).send().await.unwrap().text().await.unwrap();
    assert!(metrics.contains("\nrelume_draining 1\n"), "{metrics}");
    let reserved = metrics.lines().find_map(|l| l.strip_prefix("relume_session_memory_reserved_bytes "));
    assert!(reserved.and_then(|b| b.parse::<u64>().ok()).is_some_and(|b| b > 0), "{reserved:?}");
    let r = http.post(a.url("/v1/sessions")).json(&create_body(1)).send().await.unwrap();
    assert_eq!(r.status(), 503);
    assert_eq!(r.headers().get("retry-after").and_then(|v| v.to_str().ok()), Some("1"));
    assert_eq!(r.json::<Value>().await.unwrap()["error"], "draining");
    for seed in 0..4 {
        let (status, node, v) = post(http, proxy.url("/v1/sessions"), &create_body(100 + seed)).await;
        assert_eq!((status, node.as_str()), (201, "relume-1"), "{v}");
        let id = v["id"].as_str().unwrap();
        assert_eq!(http.delete(proxy.url(&format!("/v1/sessions/{id}"))).send().await.unwrap().status(), 204);
    }
    for id in on_a {
        let (s, node, t) = post(http, proxy.url(&format!("/v1/sessions/{id}/tick")), &Value::Null).await;
        assert_eq!((s, node.as_str()), (200, "relume-0"), "a draining node's session must tick on: {t}");
    }
    // Queue an edit that only the migrated session will apply, so its scene must travel.
    for id in on_a {
        post(http, proxy.url(&format!("/v1/sessions/{id}/edits")), &light_edit()).await;
    }
    let out = Command::new(BIN)
        .args(["migrate", "--from", &a.url(""), "--to", &proxy.url(""), "--all", "--json", "/dev/stdout"])
        .output()
        .expect("relume migrate runs");
    assert!(out.status.success(), "relume migrate failed: {}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let json_end = text.rfind(']').expect("a JSON report") + 1;
    serde_json::from_str::<Vec<Value>>(&text[..json_end]).expect("the report parses")
}

/// Each moved session in `report` continues from its tick on relume-1 (`b`): its scene equals
/// a twin's that never moved and got the same edit, and its frame matches the twin's, while a
/// twin without the edit is rejected (the negative control).
async fn continue_like_twins(http: &reqwest::Client, proxy: &Proxy, b: &Served, report: &[Value]) {
    for moved in report {
        let (old, new) = (moved["from"].as_str().unwrap(), moved["to"].as_str().unwrap());
        assert!(new.starts_with("relume-1."), "{moved}");
        let view: Value =
            http.get(proxy.url(&format!("/v1/sessions/{new}"))).send().await.unwrap().json().await.unwrap();
        let seed = view["seed"].as_u64().unwrap();
        assert_eq!(Some(view["ticks"].as_u64().unwrap()), moved["tick"].as_u64(), "{old} → {new}");
        let (_, _, twin) = post(http, b.url("/v1/sessions"), &create_body(seed)).await;
        let twin = twin["id"].as_str().unwrap().to_string();
        let (_, _, stale) = post(http, b.url("/v1/sessions"), &create_body(seed)).await;
        let stale = stale["id"].as_str().unwrap().to_string();
        post(http, b.url(&format!("/v1/sessions/{twin}/edits")), &light_edit()).await;
        let mut last = [Value::Null, Value::Null, Value::Null];
        for _ in 0..8 {
            for (k, id) in [new, twin.as_str(), stale.as_str()].into_iter().enumerate() {
                last[k] = post(http, proxy.url(&format!("/v1/sessions/{id}/tick")), &Value::Null).await.2;
            }
        }
        let scene = |id: String| {
            let http = http.clone();
            async move { http.get(id).send().await.unwrap().json::<Value>().await.unwrap() }
        };
        assert_eq!(
            scene(proxy.url(&format!("/v1/sessions/{new}/scene"))).await,
            scene(proxy.url(&format!("/v1/sessions/{twin}/scene"))).await,
            "{new}: the moved session's scene differs from its twin's"
        );
        let tick = |k: usize| last[k]["stats"]["tick"].as_u64().unwrap();
        let moved_image = frame(http, proxy.url(&format!("/v1/sessions/{new}/frame.png?tick={}", tick(0)))).await;
        let twin_image = frame(http, proxy.url(&format!("/v1/sessions/{twin}/frame.png?tick={}", tick(1)))).await;
        let stale_image = frame(http, proxy.url(&format!("/v1/sessions/{stale}/frame.png?tick={}", tick(2)))).await;
        common::assert_matches_reference(&format!("{new} vs its twin"), &moved_image, &twin_image, TWIN);
        common::assert_rejected_by_reference("a twin without the edit", &stale_image, &twin_image, TWIN);
        for id in [twin, stale] {
            http.delete(b.url(&format!("/v1/sessions/{id}"))).send().await.unwrap();
        }
    }
}
