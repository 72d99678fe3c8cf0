//! `GET /v1/sessions/{id}/pick`: what lies under a pixel, on a scene whose answer is known
//! from its geometry (two quads, one on each half of the view), before and after an edit moves
//! one away; bad coordinates get a 422 naming the field.
mod common;
use common::server::TestServer;
use relume::server::Limits;
use serde_json::{json, Value};

/// A camera at the origin looking down −Z at two unit quads 5 m away: `left` (static) centred
/// at x = −1, `right` (dynamic) at x = +1. At 5 m the view spans ±5.8 m across and ±2.9 m
/// up (60° vfov, 64×32 pixels).
fn two_quads() -> Value {
    json!({
        "camera": {"position": [0, 0, 0], "look_at": [0, 0, -1], "vfov_deg": 60, "resolution": [64, 32]},
        "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "objects": [
            {"name": "left", "shape": {"type": "quad"}, "material": "grey", "transform": {"translation": [-1, 0, -5]}},
            {"name": "right", "shape": {"type": "quad"}, "material": "grey", "transform": {"translation": [1, 0, -5]}, "dynamic": true},
        ],
        "lights": [{"name": "sun", "emitter": {"type": "point", "intensity": [1, 1, 1]}}],
    })
}

async fn pick(s: &TestServer, id: &str, x: f32, y: f32) -> Value {
    let r = s.http.get(s.url(&format!("/v1/sessions/{id}/pick?x={x}&y={y}"))).send().await.unwrap();
    assert_eq!(r.status(), 200);
    r.json().await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pick_names_the_surface_under_a_pixel_as_of_the_last_tick() {
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(json!({"scene": two_quads()})).await;
    s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    // Pixel column 24.5 looks at x ≈ −1.35 m: inside `left`; column 40.5 at +1.54 m: `right`.
    let left = pick(&s, &id, 24.5, 16.5).await;
    assert_eq!(
        (left["target"].as_str(), left["name"].as_str(), left["dynamic"].as_bool()),
        (Some("object"), Some("left"), Some(false)),
        "{left}"
    );
    assert!((left["position"][2].as_f64().unwrap() + 5.0).abs() < 1e-3, "{left}");
    let right = pick(&s, &id, 40.5, 16.5).await;
    assert_eq!((right["name"].as_str(), right["dynamic"].as_bool()), (Some("right"), Some(true)), "{right}");
    // The top row sees above both quads (they reach y = ±1 m; that row looks at y ≈ 2.8 m).
    assert_eq!(pick(&s, &id, 40.5, 0.5).await, json!({"hit": false}));
    // Move `right` out of view: once the tick applies it, nothing is under that pixel.
    let edit = json!({"edits": [{"target": "object", "name": "right", "transform": {"translation": [100, 0, -5]}}]});
    s.http.post(s.url(&format!("/v1/sessions/{id}/edits"))).json(&edit).send().await.unwrap();
    s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    assert_eq!(pick(&s, &id, 40.5, 16.5).await, json!({"hit": false}));
    for (query, field) in [("x=-1&y=3", "x"), ("x=3&y=32", "y"), ("x=NaN&y=3", "x"), ("x=3", "x, y")] {
        let r = s.http.get(s.url(&format!("/v1/sessions/{id}/pick?{query}"))).send().await.unwrap();
        assert_eq!(r.status(), 422, "{query}");
        let v: Value = r.json().await.unwrap();
        assert!(v["detail"].as_str().unwrap().starts_with(field), "{query}: {v}");
    }
    s.shutdown().await.unwrap();
}
