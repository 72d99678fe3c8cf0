//! glTF scenes through a real server on 127.0.0.1:0: bundled `.glb` files listed with their
//! animations and created by file name, a `.glb` sent inline as base64 with its load report,
//! a glTF animation played by its name, and bad glTF bodies refused with a 4xx naming the part.
mod common;

use base64::Engine;
use common::server::TestServer;
use common::ws::{next_text, send};
use relume::server::Limits;
use serde_json::{json, Value};

async fn connect(s: &TestServer, id: &str) -> common::ws::Socket {
    common::ws::open(&s.ws_url(&format!("/v1/sessions/{id}/ws"))).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bundled_glb_scenes_are_listed_created_and_play_their_animations() {
    let s = TestServer::start(None, Limits::default()).await;
    let list = s.get_json("/v1/scenes").await;
    let walker = list["scenes"].as_array().unwrap().iter().find(|e| e["name"] == "walker.glb").cloned();
    assert_eq!(walker.expect("walker.glb listed")["animations"], json!(["walker"]), "{list}");
    let id = s.session(json!({"scene": "walker.glb", "width": 16, "height": 16})).await;
    let mut ws = connect(&s, &id).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "none", "stats": true})).await;
    send(&mut ws, json!({"type": "play", "anim": "walker", "speed": 2.0})).await;
    // Ticks arrive without the client asking, each moving the walker's limbs.
    for _ in 0..3 {
        let st = next_text(&mut ws).await;
        assert_eq!(st["type"], "stats", "{st}");
        assert!(st["stats"]["moved_surfaces"].as_u64().unwrap() > 0, "{st}");
    }
    // An animation the file does not hold is an error on the socket.
    send(&mut ws, json!({"type": "play", "anim": "no-such-animation"})).await;
    let e = next_text(&mut ws).await;
    assert_eq!(e["type"], "error", "{e}");
    s.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_inline_glb_creates_a_session_and_returns_its_load_report() {
    let s = TestServer::start(None, Limits::default()).await;
    // The Cornell box as shipped, with one material given a texture the importer will not read.
    let glb = std::fs::read(common::scenes_dir().join("cornell-box.glb")).unwrap();
    let plain = base64::engine::general_purpose::STANDARD.encode(&glb);
    let r = s
        .http
        .post(s.url("/v1/sessions"))
        .json(&json!({"scene_glb": plain, "width": 16, "height": 16}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["scene"], "inline");
    assert!(v.get("warnings").is_none(), "the exporter's own file reads whole: {v}");
    let id = v["id"].as_str().unwrap();
    let tick = s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    assert_eq!(tick.status(), 200);
    let frame = s.http.get(s.url(&format!("/v1/sessions/{id}/frame.png"))).send().await.unwrap();
    assert_eq!(frame.status(), 200);
    // A .gltf document with a texture: read, with a warning naming the material.
    let mut doc: Value = serde_json::from_slice(&gltf_json_of(&glb)).unwrap();
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    doc["textures"] = json!([{"source": 0}]);
    doc["images"] = json!([{"uri": "data:image/png;base64,"}]);
    let bin = &glb[glb.len() - bin_len(&glb)..];
    doc["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(bin)
    ));
    let body = base64::engine::general_purpose::STANDARD.encode(serde_json::to_vec(&doc).unwrap());
    let v = s.post_json("/v1/sessions", &json!({"scene_glb": body, "width": 16, "height": 16})).await;
    let warnings = v["warnings"].to_string();
    assert!(warnings.contains("base colour textures") && warnings.contains("materials[0]"), "{v}");
    s.shutdown().await.unwrap();
}

/// The JSON chunk of a GLB.
fn gltf_json_of(glb: &[u8]) -> Vec<u8> {
    let len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    glb[20..20 + len].to_vec()
}

/// The length of a GLB's binary chunk (its data runs to the end of the file).
fn bin_len(glb: &[u8]) -> usize {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    u32::from_le_bytes(glb[20 + json_len..24 + json_len].try_into().unwrap()) as usize
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_gltf_bodies_get_a_4xx_naming_the_part() {
    let s = TestServer::start(None, Limits::default()).await;
    let glb = std::fs::read(common::scenes_dir().join("cornell-box.glb")).unwrap();
    let mut doc: Value = serde_json::from_slice(&gltf_json_of(&glb)).unwrap();
    doc["buffers"][0]["uri"] = json!("../../../etc/passwd");
    let escaping = base64::engine::general_purpose::STANDARD.encode(serde_json::to_vec(&doc).unwrap());
    let both = json!({"scene": "cornell-box", "scene_glb": "AAAA"});
    for (body, status, words) in [
        (json!({"scene_glb": "%%% not base64"}), 422, "scene_glb: not base64"),
        (json!({"scene_glb": "AAAA"}), 422, "scene_glb.gltf"),
        (json!({"scene_glb": escaping}), 422, "buffers[0].uri"),
        (both, 422, "either scene or scene_glb"),
        (json!({"scene": "../walker.glb"}), 422, "not a scene name"),
        (json!({"scene": "nothing.glb"}), 404, "no bundled scene"),
    ] {
        let r = s.http.post(s.url("/v1/sessions")).json(&body).send().await.unwrap();
        let code = r.status().as_u16();
        let v: Value = r.json().await.unwrap();
        assert_eq!(code, status, "{body}: {v}");
        assert!(v["detail"].as_str().unwrap_or("").contains(words), "{v} lacks '{words}'");
    }
    // The server is unharmed: a good glTF session still starts.
    s.session(json!({"scene": "cornell-box.glb", "width": 8, "height": 8})).await;
    s.shutdown().await.unwrap();
}
