//! Scenes uploaded to a real server (`PUT /v1/scenes/{name}`, `DELETE`, `GET /v1/scenes`), on a
//! scenes folder of the test's own.
//!
//! What is uploaded must be the scene sent: its size and SHA-256 are the bytes' own, its
//! triangles what the library counts in the file, and a session on the upload (a `.glb`, or a
//! `.zip` of the same scene as `.gltf` + `.bin`) renders exactly the frame of a session on the
//! same bytes sent inline. Every bad upload is refused with the status and the field its
//! hazard calls for, and leaves the folder as it was; each refusal has a control beside it
//! that passes (the same limit with a scene under it, the same archive without the bad entry).
mod common;
use common::archive::{as_gltf, zip_of, Entry};
use common::process::Served;
use serde_json::{json, Value};
use sha2::{Digest, Sha256};
use std::collections::BTreeSet;
use std::path::Path;

/// Every name under `root`, hidden ones included: what a refused upload must leave unchanged.
fn names(root: &Path) -> BTreeSet<String> {
    std::fs::read_dir(root).expect("scenes folder").flatten().map(|e| e.file_name().to_string_lossy().into()).collect()
}

fn bundled_glb() -> Vec<u8> {
    std::fs::read(common::scenes_dir().join("cornell-box.glb")).expect("cornell-box.glb")
}

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

struct Client {
    http: reqwest::Client,
    served: Served,
}

impl Client {
    fn start(root: &Path, extra: &[&str]) -> Client {
        // No connection is reused: one the server closed after refusing a body must not be
        // picked for the next request.
        let http = reqwest::Client::builder().pool_max_idle_per_host(0).build().expect("client");
        Client { http, served: Served::start_in(root, extra) }
    }

    async fn put(&self, name: &str, body: Vec<u8>) -> (u16, Value) {
        let r = self.http.put(self.served.url(&format!("/v1/scenes/{name}"))).body(body).send().await.expect("PUT");
        (r.status().as_u16(), r.json().await.unwrap_or(Value::Null))
    }

    async fn call(&self, method: reqwest::Method, path: &str, body: Option<Value>) -> (u16, Value) {
        let mut request = self.http.request(method, self.served.url(path));
        if let Some(b) = body {
            request = request.json(&b);
        }
        let r = request.send().await.expect("request");
        (r.status().as_u16(), r.json().await.unwrap_or(Value::Null))
    }

    /// The linear frame of a session's first tick, on `scene` (a name, or inline with `glb`).
    async fn first_frame(&self, scene: Value) -> Vec<u8> {
        let mut body = json!({"width": 16, "height": 12, "seed": 7, "technique": {"id": "path", "spp": 2}});
        body.as_object_mut().expect("object").extend(scene.as_object().expect("object").clone());
        let (status, view) = self.call(reqwest::Method::POST, "/v1/sessions", Some(body)).await;
        assert_eq!(status, 201, "{view}");
        let id = view["id"].as_str().expect("id").to_string();
        let (status, _) = self.call(reqwest::Method::POST, &format!("/v1/sessions/{id}/tick"), None).await;
        assert_eq!(status, 200);
        let frame =
            self.http.get(self.served.url(&format!("/v1/sessions/{id}/frame.f32"))).send().await.expect("frame");
        frame.bytes().await.expect("bytes").to_vec()
    }

    async fn listed(&self, name: &str) -> Option<Value> {
        let (_, list) = self.call(reqwest::Method::GET, "/v1/scenes", None).await;
        list["scenes"].as_array().expect("scenes").iter().find(|s| s["name"] == name).cloned()
    }
}

/// Asserts a refusal: its status, and that its detail names `field`.
fn refused(label: &str, (status, body): &(u16, Value), want: u16, field: &str) {
    assert_eq!(*status, want, "{label}: {body}");
    let detail = body["detail"].as_str().unwrap_or_default();
    assert!(detail.contains(field), "{label}: the detail does not name '{field}': {body}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_uploaded_scene_is_the_scene_sent_and_renders_as_it_does_inline() {
    let root = common::fresh_dir("same");
    let c = Client::start(&root, &[]);
    let glb = bundled_glb();
    let (gltf, bin) = as_gltf(&glb);
    let archive = zip_of(&[Entry::File("box/scene.gltf", &gltf), Entry::File("box/scene.bin", &bin)]);

    let (status, record) = c.put("box.glb", glb.clone()).await;
    assert_eq!(status, 201, "{record}");
    let options = relume::scene::gltf::ImportOptions::default();
    let imported = relume::scene::gltf::import_file(
        &common::scenes_dir().join("cornell-box.glb"),
        &common::scenes_dir(),
        &options,
    )
    .expect("the bundled scene imports");
    let triangles = relume::scene::load::count_triangles(&imported.desc, &common::scenes_dir(), &common::scenes_dir())
        .expect("counted");
    assert_eq!(record["bytes"], glb.len() as u64);
    assert_eq!(record["sha256"], sha256_hex(&glb));
    assert_eq!(record["triangles"], triangles);
    assert_eq!(
        c.listed("box.glb").await.as_ref(),
        Some(&json!({
            "name": "box.glb", "animations": [], "bytes": glb.len(), "sha256": sha256_hex(&glb), "triangles": triangles
        }))
    );
    let (status, zipped) = c.put("box.zip", archive.clone()).await;
    assert_eq!(status, 201, "{zipped}");
    assert_eq!((zipped["bytes"].as_u64(), zipped["triangles"].as_u64()), (Some(archive.len() as u64), Some(triangles)));
    assert_eq!(zipped["scene_file"], "box/scene.gltf");

    let inline = base64::Engine::encode(&base64::engine::general_purpose::STANDARD, &glb);
    let want = c.first_frame(json!({"scene_glb": inline})).await;
    assert_eq!(want.len(), 16 * 12 * 12);
    assert!(want == c.first_frame(json!({"scene": "box.glb"})).await, "the uploaded .glb renders differently");
    assert!(want == c.first_frame(json!({"scene": "box.zip"})).await, "the uploaded .zip renders differently");

    // Sent again, a name is replaced (200), and the listing follows the new bytes.
    let (status, again) =
        c.put("box.zip", zip_of(&[Entry::File("scene.gltf", &gltf), Entry::File("scene.bin", &bin)])).await;
    assert_eq!((status, again["scene_file"].as_str()), (200, Some("scene.gltf")), "{again}");
    assert_eq!(c.listed("box.zip").await.expect("listed")["sha256"], again["sha256"]);
    assert!(want == c.first_frame(json!({"scene": "box.zip"})).await);

    // Deleted, an upload is gone; a bundled scene cannot be deleted.
    let (status, _) = c.call(reqwest::Method::DELETE, "/v1/scenes/box.zip", None).await;
    assert_eq!(status, 204);
    assert_eq!(c.listed("box.zip").await, None);
    refused("deleted twice", &c.call(reqwest::Method::DELETE, "/v1/scenes/box.zip", None).await, 404, "box.zip");
    std::fs::write(root.join("bundled.glb"), &glb).expect("a bundled scene");
    refused("bundled", &c.call(reqwest::Method::DELETE, "/v1/scenes/bundled.glb", None).await, 403, "bundled.glb");
    assert_eq!(names(&root), BTreeSet::from(["box.glb".into(), ".box.glb.upload.json".into(), "bundled.glb".into()]));
    let _ = std::fs::remove_dir_all(&root);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_upload_is_refused_by_name_and_leaves_nothing_behind() {
    let root = common::fresh_dir("bad");
    let c = Client::start(&root, &["--upload-limit", "1"]);
    let glb = bundled_glb();
    let (gltf, bin) = as_gltf(&glb);
    let before = names(&root);
    let large = std::fs::read(common::scenes_dir().join("furnace.glb")).expect("furnace.glb");
    assert!(large.len() > 1 << 20 && glb.len() < 1 << 20, "the limit lies between the two scenes");
    // A run of zeros deflates about 1 000 to 1: a zip bomb's material.
    let zeros = vec![0u8; 8 << 20];
    let escape = zip_of(&[Entry::File("scene.gltf", &gltf), Entry::File("../scene.bin", &bin)]);
    let link = zip_of(&[Entry::File("scene.gltf", &gltf), Entry::Link("scene.bin", "/etc/passwd")]);
    let bomb =
        zip_of(&[Entry::File("scene.gltf", &gltf), Entry::File("scene.bin", &bin), Entry::File("pad.bin", &zeros)]);
    let two = zip_of(&[Entry::File("a.gltf", &gltf), Entry::File("b.gltf", &gltf), Entry::File("scene.bin", &bin)]);
    let cases: Vec<(&str, &str, Vec<u8>, u16, &str)> = vec![
        ("over the limit", "big.glb", large, 413, "--upload-limit"),
        ("truncated", "cut.glb", glb[..glb.len() / 2].to_vec(), 422, "body"),
        ("not a zip", "junk.zip", b"PK not really".to_vec(), 422, "body"),
        ("a path escape", "escape.zip", escape, 422, "../scene.bin"),
        ("a symbolic link", "link.zip", link, 422, "scene.bin"),
        ("a zip bomb", "bomb.zip", bomb, 413, "pad.bin"),
        ("two scenes", "two.zip", two, 422, "a.gltf"),
        ("a hidden name", ".hidden.glb", glb.clone(), 400, "name"),
        ("another kind", "scene.gltf", gltf.clone(), 400, "name"),
        ("a path in the name", "..%2Fup.glb", glb.clone(), 400, "name"),
    ];
    for (label, name, body, status, field) in cases {
        refused(label, &c.put(name, body).await, status, field);
        assert_eq!(names(&root), before, "{label}: the refused upload left files behind");
    }
    assert!(!root.parent().expect("parent").join("scene.bin").exists(), "the escape was written");
    // Controls: under the same limit, the scene and its archive without the bad entries pass.
    assert_eq!(c.put("box.glb", glb.clone()).await.0, 201);
    let good = zip_of(&[Entry::File("scene.gltf", &gltf), Entry::File("scene.bin", &bin)]);
    assert_eq!(c.put("box.zip", good).await.0, 201);
    let _ = std::fs::remove_dir_all(&root);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_upload_streamed_past_the_limit_without_a_length_is_cut_off() {
    let root = common::fresh_dir("stream");
    let c = Client::start(&root, &["--upload-limit", "1"]);
    let before = names(&root);
    // Chunked, so the server learns the size only as it reads: 64 KiB chunks, 2 MiB in all.
    let chunks = (0..32).map(|_| Ok::<_, std::io::Error>(vec![7u8; 64 << 10]));
    let body = reqwest::Body::wrap_stream(futures_util::stream::iter(chunks));
    let r = c.http.put(c.served.url("/v1/scenes/stream.glb")).body(body).send().await.expect("PUT");
    refused("streamed", &(r.status().as_u16(), r.json().await.unwrap_or(Value::Null)), 413, "--upload-limit");
    assert_eq!(names(&root), before);
    // Control: the same stream under the limit is read whole (and refused only as no scene).
    let chunks = (0..8).map(|_| Ok::<_, std::io::Error>(vec![7u8; 64 << 10]));
    let body = reqwest::Body::wrap_stream(futures_util::stream::iter(chunks));
    let r = c.http.put(c.served.url("/v1/scenes/stream.glb")).body(body).send().await.expect("PUT");
    refused("under the limit", &(r.status().as_u16(), r.json().await.unwrap_or(Value::Null)), 422, "body");
    assert_eq!(names(&root), before);
    let _ = std::fs::remove_dir_all(&root);
}

/// Bytes no compressor shrinks (xorshift), so an archive of them is as large as they are.
fn noise(len: usize, mut state: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(len + 8);
    while out.len() < len {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        out.extend_from_slice(&state.to_le_bytes());
    }
    out.truncate(len);
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_100_mb_upload_is_streamed_to_disk_not_held_in_memory() {
    // Hazard: a body read whole before it is written costs the server its size in memory.
    // The server's peak resident memory may grow by a fifth of the upload at most; reading it
    // whole would grow it by all of it, at least five times the bound. (Run with the body held
    // in memory as it arrives, as a control: 107.5 MB for 104.9 MB sent; streamed: 4.1 MB.)
    let root = common::fresh_dir("uploads-big");
    let c = Client::start(&root, &[]);
    let (gltf, bin) = as_gltf(&bundled_glb());
    let pad = noise(100 << 20, 0x9e37_79b9_7f4a_7c15);
    let archive =
        zip_of(&[Entry::File("scene.gltf", &gltf), Entry::File("scene.bin", &bin), Entry::File("pad.bin", &pad)]);
    drop(pad);
    let (size, sha) = (archive.len() as u64, sha256_hex(&archive));
    let before = c.served.peak_rss();
    let (status, record) = c.put("big.zip", archive).await;
    assert_eq!(status, 201, "{record}");
    assert_eq!((record["bytes"].as_u64(), record["sha256"].as_str()), (Some(size), Some(sha.as_str())));
    let grown = c.served.peak_rss().saturating_sub(before);
    println!("the server's peak memory grew by {grown} bytes for a {size}-byte upload");
    assert!(grown < size / 5, "the server's peak memory grew by {grown} bytes for a {size}-byte upload");
    assert_eq!(std::fs::metadata(root.join("big.zip/pad.bin")).expect("unpacked").len(), 100 << 20);
    let _ = std::fs::remove_dir_all(&root);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_uploads_of_one_name_leave_one_whole_upload() {
    // Four different archives sent to one name at once: each is answered as stored, the name
    // ends as exactly one of them (its listed SHA-256 is one of theirs, and its files are that
    // archive's), and no staging file or folder is left.
    let root = common::fresh_dir("uploads-same");
    let c = Client::start(&root, &[]);
    let (gltf, bin) = as_gltf(&bundled_glb());
    let bodies: Vec<Vec<u8>> = (0..4u64)
        .map(|k| {
            let pad = noise(2 << 20, k + 1);
            zip_of(&[Entry::File("scene.gltf", &gltf), Entry::File("scene.bin", &bin), Entry::File("pad.bin", &pad)])
        })
        .collect();
    let answers = futures_util::future::join_all(bodies.iter().map(|b| c.put("same.zip", b.clone()))).await;
    for (status, record) in &answers {
        assert!(*status == 201 || *status == 200, "{status}: {record}");
    }
    assert_eq!(answers.iter().filter(|(s, _)| *s == 201).count(), 1, "one of them created the name");
    let listed = c.listed("same.zip").await.expect("listed");
    let winner = bodies.iter().position(|b| listed["sha256"] == sha256_hex(b)).expect("the listed upload is one sent");
    let pad = std::fs::read(root.join("same.zip/pad.bin")).expect("pad.bin");
    assert!(pad == noise(2 << 20, winner as u64 + 1), "the files are not those of the listed upload");
    assert_eq!(names(&root), BTreeSet::from(["same.zip".into(), ".same.zip.upload.json".into()]));
    let _ = std::fs::remove_dir_all(&root);
}
