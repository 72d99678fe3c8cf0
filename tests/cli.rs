//! The `relume` binary end to end: outputs exist and decode, bad input exits 2 with a message.
use std::path::{Path, PathBuf};
use std::process::Command;

fn relume() -> Command {
    Command::new(env!("CARGO_BIN_EXE_relume"))
}

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name)
}

fn out_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("relume-cli-{}-{tag}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn version_names_relume_and_the_embree_4_it_runs() {
    let out = relume().arg("--version").output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let device = relume::embree::Device::new(1).unwrap();
    assert_eq!(device.version().major, 4, "linked against Embree {}", device.version());
    let want = format!("relume {}, Embree {} ({} kernels)", env!("CARGO_PKG_VERSION"), device.version(), device.isa());
    assert_eq!(text.trim(), want);
}

#[test]
fn render_writes_png_and_exr() {
    let dir = out_dir("still");
    for ext in ["png", "exr"] {
        let out = dir.join(format!("cbox.{ext}"));
        let status = relume()
            .args([
                "render",
                scene("cornell-box.json").to_str().unwrap(),
                "--spp",
                "4",
                "--width",
                "32",
                "--height",
                "24",
            ])
            .arg("--out")
            .arg(&out)
            .status()
            .unwrap();
        assert!(status.success());
        let bytes = std::fs::read(&out).unwrap();
        if ext == "png" {
            let img = image::load_from_memory(&bytes).unwrap();
            assert_eq!((img.width(), img.height()), (32, 24));
        } else {
            assert_eq!(&bytes[..4], &[0x76, 0x2f, 0x31, 0x01], "EXR magic number");
        }
    }
}

#[test]
fn render_anim_writes_every_frame() {
    let dir = out_dir("anim");
    let status = relume()
        .args([
            "render",
            scene("bunnies-2.json").to_str().unwrap(),
            "--anim",
            scene("bunnies-2.anim.json").to_str().unwrap(),
        ])
        .args(["--frames", "3", "--spp", "1", "--width", "16", "--height", "16", "--out"])
        .arg(&dir)
        .status()
        .unwrap();
    assert!(status.success());
    for i in 0..3 {
        assert!(dir.join(format!("frame-{i:04}.png")).exists(), "frame {i} missing");
    }
}

/// `--denoise` writes the denoised still, which differs from the raw one of the same seed.
#[cfg(feature = "denoise")]
#[test]
fn render_denoise_writes_the_denoised_still() {
    let dir = out_dir("denoise");
    let render = |extra: &[&str], name: &str| {
        let out = dir.join(name);
        let o = relume()
            .args([
                "render",
                scene("cornell-box.json").to_str().unwrap(),
                "--spp",
                "1",
                "--width",
                "32",
                "--height",
                "32",
            ])
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (std::fs::read(&out).unwrap(), String::from_utf8_lossy(&o.stderr).to_string())
    };
    let (raw, _) = render(&[], "raw.exr");
    let (denoised, log) = render(&["--denoise=fast"], "denoised.exr");
    assert!(log.contains("denoised (fast)"), "{log}");
    assert_ne!(raw, denoised, "--denoise wrote the raw image");
}

#[test]
fn bad_input_exits_2_with_a_message() {
    let dir = out_dir("bad");
    let bad_scene = dir.join("bad.json");
    std::fs::write(&bad_scene, r#"{"camera": {"position": [0,0,0]}}"#).unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "render".into(),
                bad_scene.display().to_string(),
                "--out".into(),
                dir.join("x.png").display().to_string(),
            ],
            "camera",
        ),
        (
            vec![
                "render".into(),
                scene("cornell-box.json").display().to_string(),
                "--out".into(),
                dir.join("x.tiff").display().to_string(),
            ],
            "tiff",
        ),
        (
            vec![
                "render".into(),
                scene("cornell-box.json").display().to_string(),
                "--technique".into(),
                "magic".into(),
                "--out".into(),
                dir.join("x.png").display().to_string(),
            ],
            "unknown technique",
        ),
        (
            vec![
                "render".into(),
                scene("nope.json").display().to_string(),
                "--out".into(),
                dir.join("x.png").display().to_string(),
            ],
            "nope.json",
        ),
        (
            vec![
                "render".into(),
                scene("cornell-box.json").display().to_string(),
                "--denoise=ultra".into(),
                "--out".into(),
                dir.join("x.png").display().to_string(),
            ],
            "--denoise: unknown quality 'ultra'",
        ),
    ];
    // A render of the Cornell box with one flag's value, and the words its refusal must hold.
    let render_with = |flag: &str, value: &str, words: &'static str| {
        let png = dir.join("x.png").display().to_string();
        let args = ["render", &scene("cornell-box.json").display().to_string(), flag, value, "--out", &png];
        (args.map(String::from).to_vec(), words)
    };
    // An exposure of NaN (or beyond the service's ±32 stops) would write a black PNG; 100 000
    // threads once took the server seconds to spawn, while it answered nothing.
    let threads = "'--threads <THREADS>': must be a whole number from 1 to 1024";
    let cases = cases.into_iter().chain([
        render_with("--exposure", "NaN", "--exposure: "),
        render_with("--exposure", "inf", "--exposure: "),
        render_with("--exposure", "-33", "--exposure: "),
        render_with("--threads", "0", threads),
        render_with("--threads", "100000", threads),
    ]);
    for (args, words) in cases {
        let out = relume().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(words), "{args:?}: '{stderr}' lacks '{words}'");
    }
}

#[test]
fn bench_rays_reports_rates_and_regeneration_rows() {
    let json = out_dir("bench").join("rays.json");
    let out = relume()
        .args([
            "bench",
            "rays",
            scene("cornell-box.json").to_str().unwrap(),
            "--width",
            "24",
            "--height",
            "24",
            "--seconds",
            "0.02",
            "--threads",
            "1",
            "--json",
        ])
        .arg(&json)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("regeneration (PR) vs none (NO)"));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let raw = v["raw"].as_array().unwrap();
    assert_eq!(raw[0]["accel"], "default", "the default layout comes first");
    for accel in ["nested", "flat", "frozen"] {
        assert!(raw.iter().any(|r| r["accel"] == accel), "{accel} measured");
    }
    assert!(raw.iter().all(|r| r["incoherent_closest_mrays"].as_f64().unwrap() > 0.0));
    assert!(v["path_to_raw_ratio"].as_f64().unwrap() > 0.0);
    // The rate at path's ray mix weighs the default layout's three raw rates by path's rays, so
    // it lies between the slowest and the fastest of them.
    let rates: Vec<f64> = ["coherent_primary_mrays", "incoherent_closest_mrays", "incoherent_occlusion_mrays"]
        .iter()
        .map(|k| raw[0][k].as_f64().unwrap())
        .collect();
    let mix = v["raw_at_path_mix_mrays"].as_f64().unwrap();
    let (slowest, fastest) =
        (rates.iter().copied().fold(f64::MAX, f64::min), rates.iter().copied().fold(0.0, f64::max));
    assert!(slowest <= mix && mix <= fastest, "{mix} outside the raw rates {rates:?}");
    let rows = v["regeneration"].as_array().unwrap();
    assert_eq!(rows.len(), 18, "path and bdpt × 3 variants × 3 widths");
    for technique in ["path", "bdpt"] {
        assert_eq!(rows.iter().filter(|r| r["technique"] == technique).count(), 9, "{technique}");
    }
    // Utilisation is a ratio of lane counts, not a time: regeneration must raise it at 16 lanes.
    for row in rows.iter().filter(|r| r["packet_width"] == 16) {
        assert!(row["regeneration_utilisation"].as_f64() > row["no_regeneration_utilisation"].as_f64(), "{row}");
    }
    let rho =
        |variant: &str| rows.iter().find(|r| r["variant"] == variant).unwrap()["mean_reflectance"].as_f64().unwrap();
    assert!(rho("dark") < rho("normal") && rho("normal") < rho("bright"));
}

/// Runs `relume bench <bench>` on bunnies-1 and its animation with `args`, and returns its JSON.
fn bench_bunnies(bench: &str, args: &[&str]) -> serde_json::Value {
    let json = out_dir(bench).join(format!("{bench}.json"));
    let out = relume()
        .args(["bench", bench, scene("bunnies-1.json").to_str().unwrap(), "--anim"])
        .arg(scene("bunnies-1.anim.json"))
        .args(args)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap()
}

#[test]
fn bench_reuse_reports_each_mode_with_the_named_fields() {
    // `--plot` creates its directory and draws both plots, as PNG and SVG, with a legend entry
    // for each mode and, in the stage plot, each stage. Negative control, by hand: plotting
    // only the first mode leaves `naive` out of the SVGs.
    let plots = out_dir("reuse-plots").join("new/dir");
    let args = ["--frames", "4", "--paths", "4000", "--width", "16", "--height", "16", "--threads", "1", "--plot"];
    let v = bench_bunnies("reuse", &[&args[..], &[plots.to_str().unwrap()]].concat());
    for (stem, labels) in
        [("reuse_tick_by_frame", &["off", "naive", "error"][..]), ("reuse_stages", &["naive", "trace", "render"])]
    {
        let png = image::open(plots.join(format!("{stem}.png"))).unwrap_or_else(|e| panic!("{stem}.png: {e}"));
        assert!(png.width() >= 640 && png.height() >= 400, "{stem}.png is {}x{}", png.width(), png.height());
        let svg = std::fs::read_to_string(plots.join(format!("{stem}.svg"))).unwrap();
        for label in labels {
            // plotters writes each text element's string on a line of its own.
            assert!(svg.contains(&format!("\n{label}\n")), "{stem}.svg lacks {label}");
        }
    }
    let modes = v["modes"].as_array().unwrap();
    assert_eq!(modes.iter().map(|m| m["mode"].as_str().unwrap()).collect::<Vec<_>>(), ["off", "naive", "error"]);
    for m in modes {
        assert_eq!(m["frames"].as_array().unwrap().len(), 3, "frame 0 is reported as initial");
        let f = &m["frames"][0];
        assert!(f["rays_traced"].is_u64() && f["tick_ms"].is_f64() && f["stages_ms"]["verify"].is_f64());
        for key in ["rays_per_tick_median", "tick_ms_median", "verify_ms_median", "memory_bytes"] {
            assert!(m["summary"][key].is_number(), "summary.{key}");
        }
    }
    // A bouncing bunny touches only some paths: naive traces fewer photon rays than off, and
    // error mode no more than naive.
    let rays = |i: usize| modes[i]["summary"]["rays_per_tick_median"].as_f64().unwrap();
    assert!(rays(1) < rays(0), "naive {} vs off {}", rays(1), rays(0));
    assert!(rays(2) <= rays(1), "error {} vs naive {}", rays(2), rays(1));
    for stage in ["origins_and_dm", "verify", "prune", "fill", "trace", "grid", "render"] {
        assert!(modes[2]["frames"][0]["stages_ms"][stage].is_f64(), "stage {stage}");
    }
}

#[test]
fn bench_icache_runs_the_modes_asked_and_splits_the_tick_by_stage() {
    // Property: `--modes` picks the modes and their order (a repeat runs once), and each frame's
    // new-record time is a part of its indirect pixel time (it is timed inside it), zero for
    // `igi`, which makes no records. `--plot` creates its directory and draws both plots, as
    // PNG and SVG, with a legend entry for each mode run and none for a mode not run. Negative
    // controls, by hand: ignoring `--modes` runs all four modes; timing records around the
    // whole pass makes `records_ms` exceed `indirect_ms`; plotting only the first mode leaves
    // `igi` out of the SVGs.
    let plots = out_dir("icache-plots").join("new/dir");
    let args = ["--frames", "4", "--vpls", "32", "--width", "24", "--height", "24", "--threads", "1", "--plot"];
    let modes = ["--modes", "temporal,igi,temporal"];
    let v = bench_bunnies("icache", &[&args[..], &[plots.to_str().unwrap()], &modes].concat());
    for stem in ["icache_indirect_by_frame", "icache_stages"] {
        let png = image::open(plots.join(format!("{stem}.png"))).unwrap_or_else(|e| panic!("{stem}.png: {e}"));
        assert!(png.width() >= 640 && png.height() >= 400, "{stem}.png is {}x{}", png.width(), png.height());
        let svg = std::fs::read_to_string(plots.join(format!("{stem}.svg"))).unwrap();
        for (mode, drawn) in [("temporal", true), ("igi", true), ("static", false)] {
            // plotters writes each text element's string on a line of its own.
            assert_eq!(svg.contains(&format!("\n{mode}\n")), drawn, "{stem}.svg and the mode {mode}");
        }
    }
    let modes = v["modes"].as_array().unwrap();
    assert_eq!(modes.iter().map(|m| m["mode"].as_str().unwrap()).collect::<Vec<_>>(), ["temporal", "igi"]);
    for m in modes {
        for f in m["frames"].as_array().unwrap() {
            let ms = |key: &str| f["stats"][key].as_f64().unwrap_or_else(|| panic!("stats.{key}"));
            assert!(
                ms("records_ms") <= ms("indirect_ms"),
                "{}: records {} > pixels {}",
                m["mode"],
                ms("records_ms"),
                ms("indirect_ms")
            );
            assert!(ms("camera_ms") > 0.0, "{}: no camera time", m["mode"]);
            if m["mode"] == "igi" {
                assert_eq!(ms("records_ms"), 0.0, "igi makes no records");
            }
        }
        for key in ["camera", "vpls", "invalidate", "pixels", "records"] {
            assert!(m["summary"]["stage_ms_median"][key].is_f64(), "stage_ms_median.{key}");
        }
    }
    // Bad arguments exit 2 with a message: the stderr of `bench icache` on bunnies-1 with `extra`.
    let refused = |extra: [&str; 2]| {
        let out = relume()
            .args(["bench", "icache", scene("bunnies-1.json").to_str().unwrap(), "--anim"])
            .arg(scene("bunnies-1.anim.json"))
            .args(extra)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{extra:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    assert!(refused(["--modes", "temporal,fast"]).contains("temporal-on-demand"), "the error lists the modes");
    // A plot directory that cannot be made is a usage error naming `--plot`.
    let plot = refused(["--plot", "/proc/relume-plots"]);
    assert!(plot.contains("--plot /proc/relume-plots"), "the error names --plot: {plot}");
}

#[test]
fn bench_error_judges_a_caustic_against_bdpt_references() {
    // Property: `path` cannot render the point light's caustic in caustic-ball, so against a
    // `--reference bdpt` its image is too dark by the caustic's share, while bdpt's own frames
    // are not. Negative control: against the default `path` references the same path frames
    // show no such gap, so the option really changes the reference.
    let out = out_dir("caustic");
    let mean_bias = |reference: &str| {
        let report = out.join(reference);
        let o = relume()
            .args(["bench", "error", scene("caustic-ball.json").to_str().unwrap()])
            .args(["--width", "24", "--height", "24", "--frames", "1", "--ref-spp", "512", "--repeats", "1"])
            .args(["--threads", "2", "--techniques", "path:spp=64,bdpt:spp=64:light_per_eye_path=true"])
            .args(["--reference", reference, "--out"])
            .arg(&report)
            .arg("--cache")
            .arg(out.join("cache"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(report.join("results.json")).unwrap()).unwrap();
        assert_eq!(v["reference"], reference);
        let bias = |config: &str| {
            let frame =
                v["frames"].as_array().unwrap().iter().find(|f| f["config"].as_str().unwrap().starts_with(config));
            frame.expect("a frame")["error"]["mean_bias"].as_f64().unwrap()
        };
        (bias("path"), bias("bdpt"))
    };
    let (path_vs_bdpt, bdpt_vs_bdpt) = mean_bias("bdpt");
    let (path_vs_path, _) = mean_bias("path");
    eprintln!(
        "mean bias against bdpt: path {path_vs_bdpt:.3}, bdpt {bdpt_vs_bdpt:.3}; against path: {path_vs_path:.3}"
    );
    let gap = 0.05;
    assert!(path_vs_bdpt < -gap, "path should miss the caustic: {path_vs_bdpt}");
    assert!(bdpt_vs_bdpt.abs() < gap, "bdpt against its own reference: {bdpt_vs_bdpt}");
    assert!(path_vs_path.abs() < gap, "the control: path against path references: {path_vs_path}");
}

#[test]
fn bench_error_writes_its_files_and_reuses_cached_references() {
    let out = out_dir("error");
    let cache = out.join("cache");
    let run = || {
        relume()
            .args(["bench", "error", scene("cornell-box.json").to_str().unwrap()])
            .args(["--width", "16", "--height", "16", "--frames", "3", "--every", "2", "--ref-spp", "16"])
            .args(["--repeats", "2", "--threads", "1", "--techniques", "path:spp=2,photon_reuse:naive:paths=3000"])
            .arg("--out")
            .arg(out.join("report"))
            .arg("--cache")
            .arg(&cache)
            .output()
            .unwrap()
    };
    let first = run();
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    let refs: Vec<_> = std::fs::read_dir(&cache).unwrap().map(|e| e.unwrap().path()).collect();
    let exr = refs.iter().find(|p| p.extension().is_some_and(|e| e == "exr")).expect("a cached reference");
    let stamp = std::fs::metadata(exr).unwrap().modified().unwrap();
    let second = run();
    assert!(second.status.success());
    assert_eq!(std::fs::metadata(exr).unwrap().modified().unwrap(), stamp, "the reference was rendered again");
    for file in [
        "results.csv",
        "results.json",
        "report.md",
        "time_vs_error.png",
        "time_vs_error.svg",
        "rays_per_frame.png",
        "rays_per_frame.svg",
        "error_by_frame.png",
        "error_by_frame.svg",
        "stage_times.png",
        "stage_times.svg",
        "errors/path_spp_2.png",
        "errors/photon_reuse_naive_paths_3000.png",
    ] {
        let p = out.join("report").join(file);
        assert!(std::fs::metadata(&p).is_ok_and(|m| m.len() > 0), "{} missing", p.display());
    }
    let csv = std::fs::read_to_string(out.join("report/results.csv")).unwrap();
    assert!(csv.starts_with("config,frame,time_s,tick_ms,"), "{csv}");
    assert_eq!(csv.lines().count(), 1 + 2 * 3, "a row per configuration and frame");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report/results.json")).unwrap()).unwrap();
    let summaries = v["summaries"].as_array().unwrap();
    assert_eq!(summaries.len(), 2);
    assert!(summaries.iter().any(|s| s["pareto"] == true));
    for s in summaries {
        let flip = s["flip_hdr"].as_f64().unwrap();
        assert!(flip > 0.0 && flip < 1.0, "{s}");
    }
    // A bad spec is a usage error naming what is wrong.
    let bad = relume()
        .args(["bench", "error", scene("cornell-box.json").to_str().unwrap(), "--techniques", "path:warp=9"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown field `warp`"));
}

#[test]
fn bench_fairness_reports_each_phase_by_its_own_ticks_and_plots_both() {
    // Property: each phase's percentiles are percentiles of the ticks it lists (`by_tick_ms`,
    // `ticks` of them): p50 ≤ p95 ≤ p99, each one of the ticks, with at least half of them at
    // or below the p50 and at least 95% at or below the p95; the ratios are the phases'. `--plot`
    // creates its directory and draws a line per phase. Negative controls, by hand: taking the
    // percentiles of the unsorted ticks fails the counts; plotting one phase fails the legend.
    let out = out_dir("fairness");
    let (json, plots) = (out.join("fairness.json"), out.join("new/plots"));
    let run = relume()
        .args(["bench", "fairness", "--scenes"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes"))
        .args(["--duration", "1s", "--width", "16", "--height", "16", "--hz", "20", "--spammers", "2", "--json"])
        .arg(&json)
        .arg("--plot")
        .arg(&plots)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for phase in ["alone", "under_spam"] {
        let l = &v[phase];
        let ticks: Vec<f64> = l["by_tick_ms"].as_array().unwrap().iter().map(|t| t.as_f64().unwrap()).collect();
        assert!(ticks.len() >= 3 && l["ticks"].as_u64() == Some(ticks.len() as u64), "{phase}: {l}");
        let p = |q: &str| l[q].as_f64().unwrap();
        assert!(p("p50_ms") <= p("p95_ms") && p("p95_ms") <= p("p99_ms"), "{phase}: {l}");
        for (q, share) in [("p50_ms", 0.5), ("p95_ms", 0.95), ("p99_ms", 0.99)] {
            assert!(ticks.contains(&p(q)), "{phase}: {q} is not one of the ticks");
            let at_or_below = ticks.iter().filter(|&&t| t <= p(q)).count() as f64;
            assert!(at_or_below >= share * ticks.len() as f64, "{phase}: {q} has {at_or_below} ticks at or below");
        }
    }
    // serde_json reads a float to within an ulp or so (no `float_roundtrip`), hence 1e-12.
    let ratio = v["under_spam"]["p50_ms"].as_f64().unwrap() / v["alone"]["p50_ms"].as_f64().unwrap();
    let reported = v["p50_ratio"].as_f64().unwrap();
    assert!((reported - ratio).abs() <= 1e-12 * ratio, "p50_ratio {reported} against {ratio}");
    image::open(plots.join("fairness_latency.png")).unwrap();
    let svg = std::fs::read_to_string(plots.join("fairness_latency.svg")).unwrap();
    for line in ["alone", "under spam"] {
        // plotters writes each text element's string on a line of its own.
        assert!(svg.contains(&format!("\n{line}\n")), "fairness_latency.svg has no {line} line");
    }
}
