//! The binary users run, driven end to end as `scripts/run.sh` starts it.
//!
//! `scripts/test.sh` runs the suite with `cargo test --release`, so `CARGO_BIN_EXE_relume` is
//! the release binary, built with the profile users get. This starts `relume serve` on a free
//! loopback port and, for every technique, creates a session, ticks it over HTTP and over a
//! WebSocket, and fetches a PNG and an EXR; it runs `relume render` at packet widths 1, 8 and
//! 16 under every Embree kernel family this CPU has; it streams an animation at the server with
//! `relume load`, as a load test does; and it stops the server with SIGTERM, which must exit 0.
//! A crash anywhere (a signal instead of an exit code) fails the test. The disk check the build
//! scripts run first is tested here too.
mod common;
use common::process::Served;
use common::ws::{next_frame, next_text, send};
use serde_json::{json, Value};
use std::process::{Command, Stdio};

use common::process::BIN;

async fn drive_session(http: &reqwest::Client, served: &Served, technique: Value) {
    let label = technique["id"].as_str().unwrap_or("?").to_string();
    let body = json!({"scene": "cornell-box", "width": 24, "height": 24, "technique": technique});
    let r = http.post(served.url("/v1/sessions")).json(&body).send().await.expect("create");
    assert_eq!(r.status(), 201, "{label}: {}", r.text().await.unwrap_or_default());
    let id = r.json::<Value>().await.expect("json")["id"].as_str().expect("id").to_string();

    // Tick over HTTP; fetch that tick's PNG and EXR.
    let r = http.post(served.url(&format!("/v1/sessions/{id}/tick"))).send().await.expect("tick");
    assert_eq!(r.status(), 200, "{label}");
    // Every technique reports what it holds: `detail.memory`, a total and its parts.
    let done: Value = r.json().await.expect("tick JSON");
    let memory = &done["stats"]["detail"]["memory"];
    let parts: u64 = memory["parts"].as_object().expect("memory.parts").values().filter_map(Value::as_u64).sum();
    assert_eq!(memory["total_bytes"].as_u64(), Some(parts), "{label}: {memory}");
    let png = http.get(served.url(&format!("/v1/sessions/{id}/frame.png?tick=0"))).send().await.expect("png");
    assert_eq!(png.status(), 200, "{label}");
    let png = image::load_from_memory(&png.bytes().await.expect("bytes")).expect("a PNG");
    assert_eq!((png.width(), png.height()), (24, 24), "{label}");
    let exr = http.get(served.url(&format!("/v1/sessions/{id}/frame.exr?tick=0"))).send().await.expect("exr");
    assert_eq!(exr.status(), 200, "{label}");
    let exr = exr.bytes().await.expect("bytes");
    assert_eq!(&exr[..4], &[0x76, 0x2f, 0x31, 0x01], "{label}: not an OpenEXR file");

    // Tick over the WebSocket: stats and a frame of the next tick.
    let mut ws = common::ws::open(&format!("ws://{}/v1/sessions/{id}/ws", served.addr)).await;
    send(&mut ws, json!({"type": "subscribe", "frames": "png", "stats": true, "every": 1})).await;
    send(&mut ws, json!({"type": "tick"})).await;
    let stats = next_text(&mut ws).await;
    assert_eq!((stats["type"].as_str(), stats["stats"]["tick"].as_u64()), (Some("stats"), Some(1)), "{label}: {stats}");
    let (header, frame) = next_frame(&mut ws).await;
    assert_eq!((header.tick, frame.width()), (1, 24), "{label}");
    drop(ws);
    let r = http.delete(served.url(&format!("/v1/sessions/{id}"))).send().await.expect("delete");
    assert!(r.status().is_success(), "{label}");
}

#[test]
fn the_release_binary_serves_every_technique_and_stops_on_sigterm() {
    let served = Served::start(&[]);
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("runtime");
    runtime.block_on(async {
        let http = reqwest::Client::new();
        let mut seen = Vec::new();
        for config in common::small_techniques() {
            if seen.contains(&config.id()) {
                continue;
            }
            seen.push(config.id());
            drive_session(&http, &served, serde_json::to_value(&config).expect("config JSON")).await;
        }
    });
    let status = served.terminate();
    assert_eq!(status.code(), Some(0), "relume serve ended with {status:?} after SIGTERM");
}

#[test]
fn the_release_load_client_streams_an_animation_and_plots_its_latency() {
    // `relume load` against `relume serve`, both the release binary: the run exits 0 (no
    // errors, no lost edits), its JSON report has the run's seconds, and `--plot` draws them
    // with a line for each of p50, p95 and max.
    let served = Served::start(&[]);
    let dir = std::env::temp_dir().join(format!("relume-e2e-load-{}", std::process::id()));
    let (json, plots) = (dir.join("load.json"), dir.join("plots"));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let anim = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/merry-go-round.anim.json");
    let out = Command::new(BIN)
        .args(["load", "--url", &served.url(""), "--scene", "merry-go-round", "--anim"])
        .arg(&anim)
        .args(["--sessions", "2", "--duration", "3s", "--warmup", "1s", "--width", "32", "--height", "32"])
        .arg("--json")
        .arg(&json)
        .arg("--plot")
        .arg(&plots)
        .output()
        .expect("relume load");
    assert!(out.status.success(), "relume load: {}", String::from_utf8_lossy(&out.stderr));
    let report: Value = serde_json::from_str(&std::fs::read_to_string(&json).expect("report")).expect("JSON");
    let seconds = report["latency_by_second"].as_array().expect("latency_by_second");
    assert!(!seconds.is_empty() && seconds.iter().all(|w| w["ticks"].as_u64() > Some(0)), "{seconds:?}");
    image::open(plots.join("load_latency.png")).expect("load_latency.png");
    let svg = std::fs::read_to_string(plots.join("load_latency.svg")).expect("load_latency.svg");
    for line in ["p50", "p95", "max"] {
        // plotters writes each text element's string on a line of its own.
        assert!(svg.contains(&format!("\n{line}\n")), "load_latency.svg has no {line} line");
    }
    let _ = std::fs::remove_dir_all(&dir);
    let status = served.terminate();
    assert_eq!(status.code(), Some(0), "relume serve ended with {status:?} after SIGTERM");
}

#[test]
fn the_release_binary_renders_at_every_packet_width_under_every_isa() {
    let dir = std::env::temp_dir().join(format!("relume-e2e-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    common::for_each_isa(|isa, _| {
        for width in [1, 8, 16] {
            let out = dir.join(format!("{isa}-{width}.png"));
            let status = Command::new(BIN)
                .args(["render", "--width", "32", "--height", "32", "--spp", "2", "--isa", isa.name()])
                .arg(common::scenes_dir().join("cornell-box.json"))
                .arg("--technique")
                .arg(format!("path:packet_width={width}"))
                .arg("--out")
                .arg(&out)
                .stderr(Stdio::null())
                .status()
                .expect("relume render runs");
            assert_eq!(status.code(), Some(0), "render under {isa} at width {width} ended with {status:?}");
            let img = image::open(&out).expect("the PNG it wrote");
            assert_eq!((img.width(), img.height()), (32, 32));
        }
    });
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_build_scripts_warn_of_a_disk_too_small_and_never_stop_for_it() {
    // `scripts/check-disk.sh GIB`, which run.sh and test.sh call before building: asked for more
    // free space than any disk has, it warns and names the linker's symptom; asked for none, it
    // is silent (the control: a script that always warned, or never, fails one of the two). It
    // exits 0 either way, because a warm target/ needs far less than a cold build, and also when
    // `df` fails (a `df` that exits 1 is put first on PATH), where it cannot tell.
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/check-disk.sh");
    let check = |gib: &str| {
        let mut c = Command::new("bash");
        c.arg(&script).arg(gib);
        c
    };
    let short = check("1000000").output().expect("bash runs");
    let warning = String::from_utf8_lossy(&short.stderr);
    assert!(short.status.success(), "{warning}");
    assert!(warning.contains("GiB free") && warning.contains("Bus error"), "{warning}");
    let enough = check("0").output().expect("bash runs");
    assert!(enough.status.success());
    assert!(enough.stderr.is_empty(), "{}", String::from_utf8_lossy(&enough.stderr));
    let no_df = std::env::temp_dir().join(format!("relume-no-df-{}", std::process::id()));
    std::fs::create_dir_all(&no_df).expect("temp dir");
    std::fs::write(no_df.join("df"), "#!/bin/sh\nexit 1\n").expect("write df");
    let executable = std::os::unix::fs::PermissionsExt::from_mode(0o755);
    std::fs::set_permissions(no_df.join("df"), executable).expect("chmod df");
    let path = format!("{}:{}", no_df.display(), std::env::var("PATH").unwrap_or_default());
    let blind = check("1000000").env("PATH", path).output().expect("bash runs");
    let _ = std::fs::remove_dir_all(&no_df);
    assert!(blind.status.success(), "{}", String::from_utf8_lossy(&blind.stderr));
    assert!(blind.stderr.is_empty(), "{}", String::from_utf8_lossy(&blind.stderr));
}
