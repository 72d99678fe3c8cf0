//! The viewer page in headless Chromium (Debian `chromium` + `chromium-driver`, installed by
//! scripts/test.sh): load the page, start a session, drag an object on the image, and check that
//! a new frame arrived and differs; pick every technique of the registry and see its frames;
//! click to select an object through the pick route; drop a .glb.
mod common;
use common::server::TestServer;
use fantoccini::actions::{InputSource, MouseActions, PointerAction, MOUSE_BUTTON_LEFT};
use fantoccini::{ClientBuilder, Locator};
use relume::server::Limits;
use serde_json::{json, Value};
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

/// chromedriver in a process group of its own, with the browser it starts. Dropping it kills
/// the whole group: killing chromedriver alone left Chromium running (and taking CPU) after a
/// test that failed before closing its session.
struct Driver(Child);

impl Drop for Driver {
    fn drop(&mut self) {
        let group = format!("-{}", self.0.id());
        let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

async fn start_driver() -> (Driver, u16) {
    assert!(
        std::path::Path::new(CHROMIUM).exists() && std::path::Path::new(CHROMEDRIVER).exists(),
        "headless Chromium is missing: run scripts/test.sh, which installs chromium and chromium-driver"
    );
    let port = free_port();
    let child = Command::new(CHROMEDRIVER)
        .process_group(0)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromedriver starts");
    let deadline = Instant::now() + Duration::from_secs(20);
    while tokio::net::TcpStream::connect(("127.0.0.1", port)).await.is_err() {
        assert!(Instant::now() < deadline, "chromedriver did not listen");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    (Driver(child), port)
}

/// Polls a JS expression until `done` holds; returns its last value.
async fn wait_for(c: &fantoccini::Client, script: &str, done: impl Fn(&Value) -> bool, what: &str) -> Value {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let v = c.execute(script, vec![]).await.unwrap();
        if done(&v) {
            return v;
        }
        assert!(Instant::now() < deadline, "timed out waiting for {what} (last: {v})");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// A WebDriver session on headless Chromium, through a chromedriver of its own. The driver's
/// port is found free and then bound by chromedriver, so another process (the other test's
/// server or browser) can take it in between; then the session request meets the wrong
/// listener and fails. Such a start is retried on a new port, up to three times.
async fn browser() -> (Driver, fantoccini::Client) {
    let caps = json!({
        "goog:chromeOptions": {
            "binary": CHROMIUM,
            "args": ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-quic",
                     "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync",
                     "--window-size=1280,900"]
        }
    });
    let mut attempt = 0;
    loop {
        attempt += 1;
        let (driver, port) = start_driver().await;
        let connector = hyper_util::client::legacy::connect::HttpConnector::new();
        let session = ClientBuilder::new(connector)
            .capabilities(caps.as_object().unwrap().clone())
            .connect(&format!("http://127.0.0.1:{port}"))
            .await;
        match session {
            Ok(c) => return (driver, c),
            Err(e) if attempt < 3 => eprintln!("WebDriver session on port {port} failed ({e}); retrying"),
            Err(e) => panic!("WebDriver session: {e}"),
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_viewer_starts_a_session_and_a_drag_moves_the_object() {
    let server = TestServer::start(None, Limits::default()).await;
    let (_driver, c) = browser().await;

    c.goto(&server.url("/")).await.unwrap();
    assert_eq!(c.title().await.unwrap(), "relume viewer");
    // Pick a small scene with a movable object, and start.
    wait_for(
        &c,
        "return document.querySelectorAll('#scene option').length",
        |v| v.as_u64() > Some(3),
        "the scene list",
    )
    .await;
    c.execute(
        "document.getElementById('scene').value = 'bunnies-1'; document.getElementById('size').value = '128'; \
         document.getElementById('denoise').value = 'fast';",
        vec![],
    )
    .await
    .unwrap();
    c.find(Locator::Id("start")).await.unwrap().click().await.unwrap();
    wait_for(&c, "return window.relume.frames", |v| v.as_u64() >= Some(2), "the first frames").await;
    let before = c
        .execute("return [window.relume.fingerprint, window.relume.accumulation, window.relume.frames]", vec![])
        .await
        .unwrap();
    let target = c.execute("return document.getElementById('target').value", vec![]).await.unwrap();
    assert_eq!(target, "object/bunny-1");
    // Under the server's Content-Security-Policy the frame (a blob: image) decodes at the
    // session's size, and the stage bars (styled through the DOM, not inline attributes) have
    // their widths: a policy that blocked either would leave them empty.
    let shown = wait_for(
        &c,
        "const f = document.getElementById('frame'); return f.complete ? f.naturalWidth : 0",
        |v| v.as_u64() > Some(0),
        "a decoded frame",
    )
    .await;
    assert_eq!(shown.as_u64(), Some(128), "the frame image is not the session's 128 pixels wide");
    let bar = c.execute("return document.querySelector('#stages .bar').style.width", vec![]).await.unwrap();
    assert!(bar.as_str().is_some_and(|w| w.ends_with('%')), "a stage bar has no width: {bar}");

    // Drag across the image with real pointer input.
    let img = c.find(Locator::Id("frame")).await.unwrap();
    let drag = MouseActions::new("mouse".into())
        .then(PointerAction::MoveToElement { element: img, duration: None, x: 0, y: 0 })
        .then(PointerAction::Down { button: MOUSE_BUTTON_LEFT })
        .then(PointerAction::MoveBy { duration: Some(Duration::from_millis(200)), x: 80, y: -40 })
        .then(PointerAction::MoveBy { duration: Some(Duration::from_millis(200)), x: 60, y: 0 })
        .then(PointerAction::Up { button: MOUSE_BUTTON_LEFT });
    c.perform_actions(drag).await.unwrap();

    // A new accumulation (the object moved) and a different frame arrive.
    let acc0 = before[1].as_u64().unwrap();
    wait_for(&c, "return window.relume.accumulation", |v| v.as_u64() > Some(acc0), "a frame after the drag").await;
    let after = c.execute("return [window.relume.id, window.relume.edits || 0]", vec![]).await.unwrap();
    assert!(after[1].as_u64() > Some(0), "the drag sent no edits");
    // The session's scene (not a frame of another tick, whose noise differs anyway) shows the
    // bunny somewhere else than the bundled scene puts it.
    let id = after[0].as_str().expect("the viewer's session id");
    let view = server.get_json(&format!("/v1/sessions/{id}")).await;
    assert_eq!(view["denoise"]["quality"], "fast", "the viewer's denoise choice did not reach the session");
    let scene: Value =
        server.http.get(server.url(&format!("/v1/sessions/{id}/scene"))).send().await.unwrap().json().await.unwrap();
    let bundled: Value =
        serde_json::from_str(&std::fs::read_to_string(common::scenes_dir().join("bunnies-1.json")).unwrap()).unwrap();
    let bunny = |s: &Value| {
        s["objects"].as_array().unwrap().iter().find(|o| o["name"] == "bunny-1").unwrap()["transform"]["translation"]
            .clone()
    };
    assert_ne!(bunny(&scene), bunny(&bundled), "the drag did not move the bunny");
    switching_keeps_the_drag(&c, &server, id, &bunny(&scene)).await;
    // The stats panel shows the tick's numbers.
    let stats_rows = c.execute("return document.querySelectorAll('#stats tr').length", vec![]).await.unwrap();
    assert!(stats_rows.as_u64() >= Some(5));
    // Keep a screenshot for people to look at (target/ is never committed).
    let shot = c.screenshot().await.unwrap();
    std::fs::write(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/viewer-test.png"), shot).unwrap();
    // Leaving the page deletes its session (pagehide), rather than leaving it to expire.
    assert_eq!(server.state.session_count(), 1);
    c.goto("about:blank").await.unwrap();
    let left = std::time::Instant::now();
    while server.state.session_count() > 0 && left.elapsed() < Duration::from_secs(10) {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert_eq!(server.state.session_count(), 0, "the viewer left its session behind");
    c.close().await.unwrap();
    server.shutdown().await.unwrap();
}

/// Switches the viewer's session to `instant_cache` with its button: the session keeps its id
/// and the bunny stays where the drag left it (`dragged`, its translation).
async fn switching_keeps_the_drag(c: &fantoccini::Client, server: &TestServer, id: &str, dragged: &Value) {
    let acc = c.execute("return window.relume.accumulation", vec![]).await.unwrap().as_u64();
    c.execute(
        "const t = document.getElementById('technique'); t.value = 'instant_cache'; t.dispatchEvent(new Event('change')); \
         document.getElementById('param-vpls').value = '64'; document.getElementById('switch').click();",
        vec![],
    )
    .await
    .unwrap();
    wait_for(c, "return window.relume.accumulation", |v| v.as_u64() > acc, "a frame after the switch").await;
    let view = server.get_json(&format!("/v1/sessions/{id}")).await;
    assert_eq!((&view["technique"]["id"], &view["technique"]["vpls"]), (&json!("instant_cache"), &json!(64)));
    let scene = server.get_json(&format!("/v1/sessions/{id}/scene")).await;
    let bunny = scene["objects"].as_array().unwrap().iter().find(|o| o["name"] == "bunny-1").expect("bunny-1");
    assert_eq!(&bunny["transform"]["translation"], dragged, "the switch lost the drag");
}

/// Starts a session from the page and waits for two frames that arrived after its id did (the
/// previous session's last frames do not count); returns its id.
async fn start_and_wait(c: &fantoccini::Client) -> String {
    let old = c.execute("return window.relume.id", vec![]).await.unwrap();
    c.find(Locator::Id("start")).await.unwrap().click().await.unwrap();
    let started = wait_for(
        c,
        "return [window.relume.id, window.relume.frames]",
        |v| v[0] != old && !v[0].is_null(),
        "the new session",
    )
    .await;
    let frames = started[1].as_u64().unwrap_or(0);
    wait_for(c, "return window.relume.frames", |v| v.as_u64() >= Some(frames + 2), "its frames").await;
    started[0].as_str().expect("session id").to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_viewer_runs_every_technique_picks_by_click_and_takes_a_dropped_glb() {
    let scenes = common::scenes_copy("viewer");
    let server = TestServer::start_in(&scenes, Limits::default()).await;
    let (_driver, c) = browser().await;
    c.goto(&server.url("/")).await.unwrap();
    runs_every_technique(&c, &server).await;
    picks_by_click(&c, &server).await;
    takes_a_dropped_glb(&c, &server).await;
    uploads_a_dropped_zip(&c, &server).await;
    c.close().await.unwrap();
    server.shutdown().await.unwrap();
    let _ = std::fs::remove_dir_all(&scenes);
}

/// Each technique with its parameters from the registry (small counts keep it quick): the
/// session gets the technique and the controls' values, and its ticks reach the plots.
async fn runs_every_technique(c: &fantoccini::Client, server: &TestServer) {
    let ids = relume::technique::TECHNIQUE_IDS;
    wait_for(
        c,
        "return document.querySelectorAll('#technique option').length",
        |v| v.as_u64() == Some(ids.len() as u64),
        "the technique list",
    )
    .await;
    c.execute(
        "document.getElementById('scene').value = 'cornell-box'; document.getElementById('size').value = '128';",
        vec![],
    )
    .await
    .unwrap();
    let small = [("paths", "20000"), ("particles", "4000"), ("vpls", "64")];
    for id in ids {
        c.execute(
            "const t = document.getElementById('technique'); t.value = arguments[0]; t.dispatchEvent(new Event('change')); \
             for (const [k, v] of arguments[1]) { const el = document.getElementById('param-' + k); if (el) el.value = v; }",
            vec![json!(id), json!(small)],
        )
        .await
        .unwrap();
        let session = start_and_wait(c).await;
        let view = server.get_json(&format!("/v1/sessions/{session}")).await;
        assert_eq!(view["technique"]["id"], *id, "{view}");
        for (k, v) in small {
            if !view["technique"][k].is_null() {
                assert_eq!(view["technique"][k].to_string(), v, "{id}: the {k} control did not reach the session");
            }
        }
        wait_for(c, "return window.relume.history.length", |v| v.as_u64() >= Some(1), "ticks in the plots").await;
    }
}

/// Click to pick: bunnies-2 has two moving bunnies; a click on a pixel over the one not
/// selected selects it.
async fn picks_by_click(c: &fantoccini::Client, server: &TestServer) {
    c.execute(
        "document.getElementById('scene').value = 'bunnies-2'; const t = document.getElementById('technique'); \
               t.value = 'path'; t.dispatchEvent(new Event('change'));",
        vec![],
    )
    .await
    .unwrap();
    let session = start_and_wait(c).await;
    let view = server.get_json(&format!("/v1/sessions/{session}")).await;
    assert_eq!((view["scene"].as_str(), view["width"].as_u64()), (Some("bunnies-2"), Some(128)), "{view}");
    let selected = c.execute("return document.getElementById('target').value", vec![]).await.unwrap();
    let mut under = None;
    'grid: for py in (2..128).step_by(4) {
        for px in (2..128).step_by(4) {
            let p = server.get_json(&format!("/v1/sessions/{session}/pick?x={px}.5&y={py}.5")).await;
            if p["dynamic"] == true && json!(format!("object/{}", p["name"].as_str().unwrap_or(""))) != selected {
                under = Some((px, py, p["name"].as_str().unwrap().to_string()));
                break 'grid;
            }
        }
    }
    let (px, py, name) = under.expect("the other bunny in view");
    let img = c.find(Locator::Id("frame")).await.unwrap();
    let scale =
        c.execute("return document.getElementById('frame').clientWidth / 128", vec![]).await.unwrap().as_f64().unwrap();
    let (dx, dy) =
        (((px as f64 + 0.5) * scale - 64.0 * scale) as i64, ((py as f64 + 0.5) * scale - 64.0 * scale) as i64);
    let click = MouseActions::new("mouse".into())
        .then(PointerAction::MoveToElement { element: img, duration: None, x: dx, y: dy })
        .then(PointerAction::Down { button: MOUSE_BUTTON_LEFT })
        .then(PointerAction::Up { button: MOUSE_BUTTON_LEFT });
    c.perform_actions(click).await.unwrap();
    let want = json!(format!("object/{name}"));
    wait_for(c, "return document.getElementById('target').value", |v| *v == want, "the clicked bunny selected").await;
}

/// Drops `bytes` as the file `name` on the page; returns the view of the session it started
/// once frames of it arrive.
async fn drop_file(c: &fantoccini::Client, server: &TestServer, bytes: Vec<u8>, name: &str) -> serde_json::Value {
    let b64 = base64::Engine::encode(&base64::engine::general_purpose::STANDARD, bytes);
    let before = c.execute("return window.relume.id", vec![]).await.unwrap();
    c.execute(
        "const b = atob(arguments[0]); const u = new Uint8Array(b.length); for (let i = 0; i < b.length; i++) u[i] = b.charCodeAt(i); \
         window.relume.startFile(new File([u], arguments[1]));",
        vec![json!(b64), json!(name)],
    )
    .await
    .unwrap();
    let started = wait_for(
        c,
        "return [window.relume.id, window.relume.frames]",
        |v| v[0] != before && !v[0].is_null(),
        &format!("the session on the dropped {name}"),
    )
    .await;
    let frames = started[1].as_u64().unwrap();
    wait_for(c, "return window.relume.frames", |v| v.as_u64() >= Some(frames + 2), "frames of the dropped scene").await;
    server.get_json(&format!("/v1/sessions/{}", started[0].as_str().unwrap())).await
}

/// Drop a .glb: the page starts a session on it (inline) and frames arrive.
async fn takes_a_dropped_glb(c: &fantoccini::Client, server: &TestServer) {
    let glb = std::fs::read(common::scenes_dir().join("cornell-box.glb")).unwrap();
    let view = drop_file(c, server, glb, "cornell-box.glb").await;
    assert_eq!(view["scene"], "inline", "{view}");
}

/// Drop a .zip (a .gltf with its buffer): the page uploads it, lists it, and starts a session
/// on it by name, and frames arrive.
async fn uploads_a_dropped_zip(c: &fantoccini::Client, server: &TestServer) {
    use common::archive::{as_gltf, zip_of, Entry};
    let (gltf, bin) = as_gltf(&std::fs::read(common::scenes_dir().join("cornell-box.glb")).unwrap());
    let archive = zip_of(&[Entry::File("box.gltf", &gltf), Entry::File("scene.bin", &bin)]);
    let view = drop_file(c, server, archive, "My Box (v2).zip").await;
    assert_eq!(view["scene"], "My-Box-v2.zip", "{view}");
    let listed = server.get_json("/v1/scenes").await;
    let entry = listed["scenes"].as_array().unwrap().iter().find(|s| s["name"] == "My-Box-v2.zip").cloned();
    assert!(entry.is_some_and(|e| e["triangles"].as_u64() > Some(0)), "{listed}");
}
