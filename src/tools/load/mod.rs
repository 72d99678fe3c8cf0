//! `relume load`: a scripted-animation load client for a running server.
//!
//! It opens N sessions, each over its own WebSocket, and streams the animation's edits at H Hz
//! for the given duration. Each period sends the edits for the animation's current time and, if
//! the session has no tick in flight, a `tick`; edits sent while a tick is busy coalesce on the
//! server (and are counted as such). At the end every session ticks once more, so every edit sent
//! is either applied or reported coalesced: `lost_edits` must be 0. Lost edits are counted from
//! the server's own numbers: each accepted batch's sequence number (`edits_accepted.seq`)
//! against the last tick's `edits_applied_through`, plus any batch never acknowledged.
//!
//! Two ways to pace the stream:
//! - **closed loop** (default): a period sends a `tick` only when the last one has come back,
//!   and latency is measured from sending a tick to receiving its frame;
//! - **open loop** (`--open-loop`): every period sends its edits and a `tick` on a fixed
//!   schedule, whatever is in flight, and latency runs from the period's *scheduled* time to the
//!   first frame whose tick applied that period's edits (`edits_applied_through` ≥ the batch's
//!   `seq`). A slow tick then delays every period behind it and is counted as such, instead of
//!   slowing the client down and hiding itself (coordinated omission).
//!
//! The report gives each second of the run's latencies (`latency_by_second`: the ticks that
//! completed in it, p50, p95 and max), and `--plot DIR` draws them (`load_latency`), so a stall
//! or a slow drift shows where it happened.
//!
//! Every wait has a bound (`--timeout`): connecting, each HTTP request, each WebSocket send,
//! each tick (or each period's edits, open loop) awaiting its frame, and the final drain. An
//! `error` message from the server ends the tick it answers, so a failing session cannot wedge
//! the run.
mod stream;

use super::UsageError;
use crate::scene::animation::Animation;
use crate::server::protocol::FrameFormat;
use crate::technique::TechniqueConfig;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Duration;
use stream::{drive, Pace};
use tokio::time::Instant;

#[derive(clap::Args, Debug, Clone)]
pub struct LoadArgs {
    /// Server base URL.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    pub url: String,
    /// Bundled scene name on the server.
    #[arg(long)]
    pub scene: String,
    /// Animation file whose edits are streamed (NAME.anim.json).
    #[arg(long)]
    pub anim: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub sessions: usize,
    /// Edit messages per second per session.
    #[arg(long, default_value_t = 30.0)]
    pub hz: f64,
    /// How long to stream, e.g. 60s, 500ms, 2m.
    #[arg(long, default_value = "60s", value_parser = humantime::parse_duration)]
    pub duration: Duration,
    /// Technique: a spec as `render` and `bench error` take it (`photon_reuse:naive:paths=200000`)
    /// or a JSON TechniqueConfig.
    #[arg(long, default_value = "path")]
    pub technique: String,
    /// Send every period's edits and tick on schedule, measuring latency from the scheduled
    /// time (see the module doc).
    #[arg(long)]
    pub open_loop: bool,
    /// The longest any request, send or tick may take before it counts as an error.
    #[arg(long, default_value = "30s", value_parser = humantime::parse_duration)]
    pub timeout: Duration,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Frame encoding to receive: png, jpg, exr or none.
    #[arg(long, default_value = "png")]
    pub frames: String,
    #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// The server's RSS is sampled this long into the run too, and its growth reported from
    /// there to the end (a soak's measure of leaks, after caches and pools have filled); at most
    /// half of `--duration`.
    #[arg(long, default_value = "10s", value_parser = humantime::parse_duration)]
    pub warmup: Duration,
    /// Also write the report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw the latency of each second of the run (p50, p95 and max) into DIR (created if
    /// missing), as `load_latency.png` and `.svg`.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
}

/// One tick's latency, and when it was measured.
#[derive(Debug, Clone, Copy)]
pub struct Latency {
    pub at: Instant,
    pub ms: f64,
}

/// The latencies of the ticks measured in one second of the run.
#[derive(Debug, Clone, Serialize)]
pub struct LatencyWindow {
    /// Whole seconds from the start of the streams.
    pub second: u64,
    pub ticks: u64,
    pub p50_ms: f64,
    pub p95_ms: f64,
    pub max_ms: f64,
}

/// What one session saw.
#[derive(Debug, Default, Clone)]
pub struct SessionReport {
    pub ticks: u64,
    pub latencies: Vec<Latency>,
    pub frames_received: u64,
    pub frames_dropped: u64,
    pub edits_sent: u64,
    pub edits_received_by_server: u64,
    pub edits_coalesced: u64,
    /// (sequence number, edits) of each batch the server acknowledged, in order.
    pub batches_accepted: Vec<(u64, u64)>,
    /// The highest `edits_applied_through` a tick reported.
    pub applied_through: u64,
    pub bytes: u64,
    pub errors: Vec<String>,
}

impl SessionReport {
    /// Edits the server never applied: those of acknowledged batches past the last applied
    /// sequence number, and those of batches it never acknowledged.
    fn lost_edits(&self) -> u64 {
        let acknowledged: u64 = self.batches_accepted.iter().map(|&(_, n)| n).sum();
        let unapplied: u64 =
            self.batches_accepted.iter().filter(|&&(seq, _)| seq > self.applied_through).map(|&(_, n)| n).sum();
        unapplied + self.edits_sent.saturating_sub(acknowledged)
    }
}

#[derive(Debug, Serialize)]
pub struct LoadReport {
    pub scene: String,
    pub sessions: usize,
    pub hz: f64,
    pub open_loop: bool,
    pub duration_s: f64,
    pub ticks_per_second: f64,
    pub latency_p50_ms: f64,
    pub latency_p95_ms: f64,
    pub latency_p99_ms: f64,
    pub frames_received: u64,
    pub frames_dropped: u64,
    pub edits_sent: u64,
    pub edits_applied: u64,
    pub edits_coalesced: u64,
    /// Edits sent that the server never drained into a tick (must be 0).
    pub lost_edits: i64,
    pub bytes_received: u64,
    pub errors: u64,
    pub error_samples: Vec<String>,
    pub server_rss_start_bytes: u64,
    pub server_rss_end_bytes: u64,
    /// RSS `--warmup` into the run, and the growth from there to the end (end ÷ warm − 1).
    pub server_rss_warm_bytes: u64,
    pub rss_growth_after_warmup: f64,
    /// Server time spent encoding frames ÷ time spent ticking, during the run.
    pub encode_to_tick_ratio: f64,
    /// Each second of the run in which some tick's latency was measured, in order.
    pub latency_by_second: Vec<LatencyWindow>,
}

/// The `p`th percentile of sorted values (nearest rank).
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = ((p / 100.0) * (sorted.len() - 1) as f64).round() as usize;
    sorted[rank.min(sorted.len() - 1)]
}

/// A technique spec or JSON configuration, as `--technique` takes it.
pub fn technique(spec: &str) -> Result<TechniqueConfig> {
    if spec.trim_start().starts_with('{') {
        serde_json::from_str(spec).map_err(|e| UsageError(format!("--technique: {e}")).into())
    } else {
        TechniqueConfig::from_spec(spec).map_err(|e| UsageError(format!("--technique '{spec}': {e}")).into())
    }
}

/// What the server's metrics say at one moment (zeros if it could not be asked).
#[derive(Clone, Copy, Debug, Default)]
struct ServerFigures {
    resident_bytes: u64,
    /// Seconds spent encoding frames and ticking, since the server started.
    encode_s: f64,
    tick_s: f64,
}

async fn server_figures(http: &reqwest::Client, url: &str) -> ServerFigures {
    let Ok(resp) = http.get(format!("{url}/metrics")).send().await else { return ServerFigures::default() };
    let text = resp.text().await.unwrap_or_default();
    let value = |name: &str| -> f64 {
        text.lines()
            .find_map(|l| l.strip_prefix(name).and_then(|v| v.strip_prefix(' ')))
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or(0.0)
    };
    ServerFigures {
        resident_bytes: value("relume_resident_memory_bytes") as u64,
        encode_s: value("relume_encode_seconds_total"),
        tick_s: value("relume_tick_seconds_sum"),
    }
}

/// Runs the load and returns the report (used by the CLI and by tests).
pub async fn run_load(args: &LoadArgs) -> Result<LoadReport> {
    if args.sessions == 0 || !(args.hz > 0.0 && args.hz <= 1000.0) {
        return Err(UsageError("--sessions must be at least 1 and --hz in (0, 1000]".into()).into());
    }
    if args.timeout.is_zero() {
        return Err(UsageError("--timeout must be longer than zero".into()).into());
    }
    // The warm sample is taken during the run: at most halfway through it.
    let warmup = args.warmup.min(args.duration / 2);
    if warmup < args.warmup {
        eprintln!("relume load: --warmup {:?} is past half of --duration; sampling at {warmup:?}", args.warmup);
    }
    let anim = Animation::load(&args.anim).map_err(|e| UsageError(format!("{}: {e}", args.anim.display())))?;
    let config = technique(&args.technique)?;
    let frames: FrameFormat = serde_json::from_value(serde_json::Value::String(args.frames.clone()))
        .map_err(|_| UsageError("--frames: png, jpg, exr or none".into()))?;
    let base = args.url.trim_end_matches('/').to_string();
    let http = super::http_client(args.token.as_deref(), args.timeout)?;
    let start = server_figures(&http, &base).await;

    // Create the sessions first, so every stream starts together.
    let ids = create_sessions(&http, &base, args, &config).await?;
    let started = Instant::now();
    let warm = {
        let (http, base) = (http.clone(), base.clone());
        tokio::spawn(async move {
            tokio::time::sleep(warmup).await;
            server_figures(&http, &base).await.resident_bytes
        })
    };
    let ws_base = base.replacen("http", "ws", 1);
    let tasks: Vec<_> = ids
        .iter()
        .map(|id| {
            let url = match &args.token {
                Some(t) => format!("{ws_base}/v1/sessions/{id}/ws?token={t}"),
                None => format!("{ws_base}/v1/sessions/{id}/ws"),
            };
            let pace = Pace { hz: args.hz, duration: args.duration, open_loop: args.open_loop, timeout: args.timeout };
            tokio::spawn(drive(url, anim.clone(), pace, frames))
        })
        .collect();
    let mut reports = Vec::new();
    for t in tasks {
        reports.push(
            t.await
                .unwrap_or_else(|e| SessionReport { errors: vec![format!("session task: {e}")], ..Default::default() }),
        );
    }
    let elapsed = started.elapsed().as_secs_f64();
    let end = server_figures(&http, &base).await;
    let rss_warm = warm.await.unwrap_or(0);
    delete_sessions(&http, &base, &ids).await;
    Ok(summarise(args, &reports, (started, elapsed), (start, end), rss_warm))
}

/// Creates `args.sessions` sessions; if one fails, deletes those made so far (they would
/// otherwise wait out the server's idle expiry) and returns the server's error.
async fn create_sessions(
    http: &reqwest::Client,
    base: &str,
    args: &LoadArgs,
    config: &TechniqueConfig,
) -> Result<Vec<String>> {
    let mut ids = Vec::new();
    for _ in 0..args.sessions {
        let body =
            serde_json::json!({"scene": args.scene, "technique": config, "width": args.width, "height": args.height});
        let resp = http
            .post(format!("{base}/v1/sessions"))
            .json(&body)
            .send()
            .await
            .with_context(|| format!("connecting to {base}"))?;
        let status = resp.status();
        let v: serde_json::Value = resp.json().await.unwrap_or_default();
        if !status.is_success() {
            delete_sessions(http, base, &ids).await;
            return Err(anyhow::anyhow!("creating a session: {status}: {}", v["detail"].as_str().unwrap_or("")));
        }
        ids.push(v["id"].as_str().unwrap_or_default().to_string());
    }
    Ok(ids)
}

/// The run's report from the sessions' reports, the elapsed seconds, the server's figures at
/// the start and end, and its resident bytes after the warm-up.
fn summarise(
    args: &LoadArgs,
    reports: &[SessionReport],
    (started, elapsed): (Instant, f64),
    (start, end): (ServerFigures, ServerFigures),
    rss_warm: u64,
) -> LoadReport {
    let mut lat: Vec<f64> = reports.iter().flat_map(|r| r.latencies.iter().map(|l| l.ms)).collect();
    lat.sort_by(f64::total_cmp);
    let sum = |f: fn(&SessionReport) -> u64| reports.iter().map(f).sum::<u64>();
    let (sent, received) = (sum(|r| r.edits_sent), sum(|r| r.edits_received_by_server));
    let coalesced = sum(|r| r.edits_coalesced);
    let errors: Vec<String> = reports.iter().flat_map(|r| r.errors.iter().cloned()).collect();
    LoadReport {
        scene: args.scene.clone(),
        sessions: args.sessions,
        hz: args.hz,
        open_loop: args.open_loop,
        duration_s: elapsed,
        ticks_per_second: sum(|r| r.ticks) as f64 / elapsed,
        latency_p50_ms: percentile(&lat, 50.0),
        latency_p95_ms: percentile(&lat, 95.0),
        latency_p99_ms: percentile(&lat, 99.0),
        frames_received: sum(|r| r.frames_received),
        frames_dropped: sum(|r| r.frames_dropped),
        edits_sent: sent,
        edits_applied: received - coalesced,
        edits_coalesced: coalesced,
        lost_edits: reports.iter().map(SessionReport::lost_edits).sum::<u64>() as i64,
        bytes_received: sum(|r| r.bytes),
        errors: errors.len() as u64,
        error_samples: errors.into_iter().take(5).collect(),
        server_rss_start_bytes: start.resident_bytes,
        server_rss_end_bytes: end.resident_bytes,
        server_rss_warm_bytes: rss_warm,
        rss_growth_after_warmup: if rss_warm > 0 { end.resident_bytes as f64 / rss_warm as f64 - 1.0 } else { 0.0 },
        encode_to_tick_ratio: if end.tick_s > start.tick_s {
            (end.encode_s - start.encode_s) / (end.tick_s - start.tick_s)
        } else {
            0.0
        },
        latency_by_second: by_second(reports, started),
    }
}

/// The sessions' latencies by the second of the run (from `started`) they were measured in.
fn by_second(reports: &[SessionReport], started: Instant) -> Vec<LatencyWindow> {
    let mut seconds: std::collections::BTreeMap<u64, Vec<f64>> = Default::default();
    for l in reports.iter().flat_map(|r| &r.latencies) {
        seconds.entry(l.at.saturating_duration_since(started).as_secs()).or_default().push(l.ms);
    }
    seconds
        .into_iter()
        .map(|(second, mut ms)| {
            ms.sort_by(f64::total_cmp);
            let max_ms = ms.last().copied().unwrap_or(0.0);
            let (p50_ms, p95_ms) = (percentile(&ms, 50.0), percentile(&ms, 95.0));
            LatencyWindow { second, ticks: ms.len() as u64, p50_ms, p95_ms, max_ms }
        })
        .collect()
}

/// Draws `load_latency` into `dir`, which exists.
fn plot(dir: &std::path::Path, r: &LoadReport) -> Result<()> {
    let line = |value: fn(&LatencyWindow) -> f64| -> Vec<(f64, f64)> {
        r.latency_by_second.iter().map(|w| (w.second as f64, value(w))).collect()
    };
    let series = vec![
        ("p50".to_string(), line(|w| w.p50_ms)),
        ("p95".to_string(), line(|w| w.p95_ms)),
        ("max".to_string(), line(|w| w.max_ms)),
    ];
    let pace = if r.open_loop { "open loop" } else { "closed loop" };
    let caption = format!("Tick latency, {} sessions of {} at {} Hz ({pace})", r.sessions, r.scene, r.hz);
    let lines = super::plot::Lines { caption, x: "second of the run", unit: "ms".into(), series };
    super::plot::write_both(dir, "load_latency", &lines)
}

pub fn print_table(r: &LoadReport) {
    let pace = if r.open_loop { "open loop" } else { "closed loop" };
    println!("relume load: {} sessions of '{}' at {} Hz ({pace}) for {:.1} s", r.sessions, r.scene, r.hz, r.duration_s);
    let rows: Vec<(&str, String)> = vec![
        ("ticks per second (all sessions)", format!("{:.1}", r.ticks_per_second)),
        (
            "tick latency p50 / p95 / p99 (ms)",
            format!("{:.1} / {:.1} / {:.1}", r.latency_p50_ms, r.latency_p95_ms, r.latency_p99_ms),
        ),
        ("frames received / dropped", format!("{} / {}", r.frames_received, r.frames_dropped)),
        ("edits sent / applied / coalesced", format!("{} / {} / {}", r.edits_sent, r.edits_applied, r.edits_coalesced)),
        ("edits lost", r.lost_edits.to_string()),
        ("bytes received", r.bytes_received.to_string()),
        ("errors", r.errors.to_string()),
        (
            "server RSS start / end (MiB)",
            format!(
                "{:.1} / {:.1}",
                r.server_rss_start_bytes as f64 / 1048576.0,
                r.server_rss_end_bytes as f64 / 1048576.0
            ),
        ),
        (
            "server RSS after warm-up / growth since",
            format!(
                "{:.1} MiB / {:+.2}%",
                r.server_rss_warm_bytes as f64 / 1048576.0,
                100.0 * r.rss_growth_after_warmup
            ),
        ),
        ("server encode time / tick time", format!("{:.3}", r.encode_to_tick_ratio)),
    ];
    for (k, v) in rows {
        println!("  {k:<36} {v}");
    }
    for e in &r.error_samples {
        println!("  error: {e}");
    }
}

pub fn run(args: LoadArgs) -> Result<()> {
    super::plot::make_dir(args.plot.as_deref())?;
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let report = runtime.block_on(run_load(&args))?;
    print_table(&report);
    super::write_json_report(args.json.as_deref(), &report)?;
    super::plot::draw_into(args.plot.as_deref(), |dir| plot(dir, &report))?;
    if report.errors > 0 || report.lost_edits != 0 {
        return Err(anyhow::anyhow!("{} errors, {} edits lost", report.errors, report.lost_edits));
    }
    Ok(())
}

/// Deletes the sessions this run created (best effort: the server expires what is left).
async fn delete_sessions(http: &reqwest::Client, base: &str, ids: &[String]) {
    for id in ids {
        let _ = http.delete(format!("{base}/v1/sessions/{id}")).send().await;
    }
}
