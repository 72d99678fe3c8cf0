//! `relume bench fairness`: one session spamming ticks must not starve another (issue 13).
//!
//! Two sessions of the same scene and technique share one server. The *steady* session asks
//! for a tick every `1/--hz` seconds (over HTTP; a request waits for its answer), and the
//! *spammer* keeps `--spammers` tick requests in flight without pause. The steady session's
//! latency (request to answer) is measured alone, then under the spam, in one run. The goal is
//! p50 and p95 under the spam at most 2× alone: the server serves ticks in round-robin turns
//! on its pool (`server/turns.rs`), so the steady session waits for at most the spammer's tick
//! in progress.
//!
//! Without `--url` it starts its own server on 127.0.0.1:0 with the bundled scenes, so nothing
//! but the two sessions runs on it. `--plot DIR` draws the steady session's latency tick by tick
//! in both phases (`fairness_latency`).
use super::load::{percentile, technique};
use super::UsageError;
use crate::server::{self, AppState, Limits, ServerConfig};
use anyhow::Result;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tokio::time::Instant;

#[derive(clap::Args, Debug)]
pub struct FairnessArgs {
    /// A running server (default: one started here on 127.0.0.1:0).
    #[arg(long)]
    pub url: Option<String>,
    /// Bundled scenes for the server started here.
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    #[arg(long, default_value = "cornell-box")]
    pub scene: String,
    /// Both sessions' technique, as a spec or JSON.
    #[arg(long, default_value = "path:spp=4")]
    pub technique: String,
    #[arg(long, default_value_t = 128)]
    pub width: u32,
    #[arg(long, default_value_t = 128)]
    pub height: u32,
    /// The steady session's tick rate.
    #[arg(long, default_value_t = 10.0)]
    pub hz: f64,
    /// The spammer's concurrent tick requests.
    #[arg(long, default_value_t = 4)]
    pub spammers: usize,
    /// How long each phase (alone, under spam) runs.
    #[arg(long, default_value = "15s", value_parser = humantime::parse_duration)]
    pub duration: Duration,
    #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Also write the report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw the steady session's latency per tick, alone and under the spam, into DIR
    /// (created if missing), as `fairness_latency.png` and `.svg`.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
}

/// The steady session's tick latencies in one phase, milliseconds.
#[derive(Debug, Serialize)]
pub struct Latency {
    pub ticks: usize,
    pub p50_ms: f64,
    pub p95_ms: f64,
    pub p99_ms: f64,
    /// Every tick's latency, in the order they ran.
    pub by_tick_ms: Vec<f64>,
}

#[derive(Debug, Serialize)]
pub struct FairnessReport {
    pub scene: String,
    pub technique: String,
    pub width: u32,
    pub height: u32,
    pub hz: f64,
    pub spammers: usize,
    pub phase_seconds: f64,
    pub alone: Latency,
    pub under_spam: Latency,
    /// Ticks the spammer's session ran per second during the spam phase.
    pub spammer_ticks_per_second: f64,
    /// Under spam ÷ alone (goal ≤ 2).
    pub p50_ratio: f64,
    pub p95_ratio: f64,
}

struct Client {
    http: reqwest::Client,
    base: String,
}

impl Client {
    async fn create(&self, args: &FairnessArgs, config: &serde_json::Value) -> Result<String> {
        let body =
            serde_json::json!({"scene": args.scene, "technique": config, "width": args.width, "height": args.height});
        let resp = self.http.post(format!("{}/v1/sessions", self.base)).json(&body).send().await?;
        let status = resp.status();
        let v: serde_json::Value = resp.json().await.unwrap_or_default();
        if !status.is_success() {
            return Err(anyhow::anyhow!("creating a session: {status}: {}", v["detail"].as_str().unwrap_or("")));
        }
        Ok(v["id"].as_str().unwrap_or_default().to_string())
    }

    /// One tick; its latency in milliseconds.
    async fn tick(&self, id: &str) -> Result<f64> {
        let started = Instant::now();
        let resp =
            self.http.post(format!("{}/v1/sessions/{id}/tick", self.base)).json(&serde_json::json!({})).send().await?;
        if !resp.status().is_success() {
            return Err(anyhow::anyhow!("tick: {}", resp.status()));
        }
        Ok(started.elapsed().as_secs_f64() * 1e3)
    }

    async fn delete(&self, id: &str) {
        let _ = self.http.delete(format!("{}/v1/sessions/{id}", self.base)).send().await;
    }
}

/// The steady session at `hz` for `duration`: each request waits for its answer.
async fn steady(client: &Client, id: &str, hz: f64, duration: Duration) -> Result<Latency> {
    let period = Duration::from_secs_f64(1.0 / hz);
    let end = Instant::now() + duration;
    let mut next = Instant::now();
    let mut latencies = Vec::new();
    while Instant::now() < end {
        tokio::time::sleep_until(next).await;
        latencies.push(client.tick(id).await?);
        next = (next + period).max(Instant::now());
    }
    let mut sorted = latencies.clone();
    sorted.sort_by(f64::total_cmp);
    Ok(Latency {
        ticks: latencies.len(),
        p50_ms: percentile(&sorted, 50.0),
        p95_ms: percentile(&sorted, 95.0),
        p99_ms: percentile(&sorted, 99.0),
        by_tick_ms: latencies,
    })
}

/// Both phases against the server at `base`.
async fn measure(args: &FairnessArgs, base: String) -> Result<FairnessReport> {
    let http = super::http_client(args.token.as_deref(), Duration::from_secs(120))?;
    let client = Arc::new(Client { http, base });
    let config = serde_json::to_value(technique(&args.technique)?)?;
    let (quiet, noisy) = (client.create(args, &config).await?, client.create(args, &config).await?);
    let outcome = async {
        for _ in 0..3 {
            client.tick(&quiet).await?;
            client.tick(&noisy).await?;
        }
        eprintln!("bench fairness: the steady session alone at {} Hz for {:?}", args.hz, args.duration);
        let alone = steady(&client, &quiet, args.hz, args.duration).await?;
        eprintln!("bench fairness: the same, with {} tick requests in flight on the other session", args.spammers);
        let stop = Arc::new(AtomicBool::new(false));
        let spammed = Arc::new(AtomicU64::new(0));
        let spam: Vec<_> = (0..args.spammers)
            .map(|_| {
                let (client, id, stop, spammed) = (client.clone(), noisy.clone(), stop.clone(), spammed.clone());
                tokio::spawn(async move {
                    while !stop.load(Ordering::Relaxed) && client.tick(&id).await.is_ok() {
                        spammed.fetch_add(1, Ordering::Relaxed);
                    }
                })
            })
            .collect();
        let started = Instant::now();
        let under_spam = steady(&client, &quiet, args.hz, args.duration).await;
        let spam_seconds = started.elapsed().as_secs_f64();
        stop.store(true, Ordering::Relaxed);
        for s in spam {
            let _ = s.await;
        }
        let under_spam = under_spam?;
        Ok::<_, anyhow::Error>(FairnessReport {
            scene: args.scene.clone(),
            technique: args.technique.clone(),
            width: args.width,
            height: args.height,
            hz: args.hz,
            spammers: args.spammers,
            phase_seconds: args.duration.as_secs_f64(),
            p50_ratio: under_spam.p50_ms / alone.p50_ms,
            p95_ratio: under_spam.p95_ms / alone.p95_ms,
            spammer_ticks_per_second: spammed.load(Ordering::Relaxed) as f64 / spam_seconds,
            alone,
            under_spam,
        })
    }
    .await;
    client.delete(&quiet).await;
    client.delete(&noisy).await;
    outcome
}

pub fn run(args: FairnessArgs) -> Result<()> {
    if !(args.hz > 0.0 && args.hz <= 1000.0) || args.spammers == 0 {
        return Err(UsageError("--hz must lie in (0, 1000] and --spammers be at least 1".into()).into());
    }
    super::plot::make_dir(args.plot.as_deref())?;
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    let report = runtime.block_on(async {
        if let Some(url) = &args.url {
            return measure(&args, url.trim_end_matches('/').to_string()).await;
        }
        let scenes_root = args.scenes.canonicalize().map_err(|e| UsageError(format!("--scenes: {e}")))?;
        let config = ServerConfig {
            scenes_root,
            token: None,
            threads: super::threads_or_all_cores(None),
            isa: None,
            limits: Limits::default(),
            access: Default::default(),
            node: "fairness".into(),
        };
        let state = Arc::new(AppState::new(config)?);
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let base = format!("http://{}", listener.local_addr()?);
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let served = tokio::spawn(server::run(listener, state, async move {
            let _ = stopped.await;
        }));
        let report = measure(&args, base).await;
        let _ = stop.send(());
        let _ = served.await;
        report
    })?;
    print(&report);
    super::write_json_report(args.json.as_deref(), &report)?;
    super::plot::draw_into(args.plot.as_deref(), |dir| plot(dir, &report))?;
    Ok(())
}

/// Draws `fairness_latency` into `dir`, which exists.
fn plot(dir: &std::path::Path, r: &FairnessReport) -> Result<()> {
    let line = |l: &Latency| l.by_tick_ms.iter().enumerate().map(|(i, &ms)| (i as f64, ms)).collect();
    let series = vec![("alone".to_string(), line(&r.alone)), ("under spam".to_string(), line(&r.under_spam))];
    let caption =
        format!("Steady session's tick latency at {} Hz, alone and with {} spam requests in flight", r.hz, r.spammers);
    let lines = super::plot::Lines { caption, x: "tick", unit: "ms".into(), series };
    super::plot::write_both(dir, "fairness_latency", &lines)
}

fn print(r: &FairnessReport) {
    println!(
        "relume bench fairness: '{}' {} at {}x{}; steady session at {} Hz, {} spam requests in flight, {:.0} s a phase",
        r.scene, r.technique, r.width, r.height, r.hz, r.spammers, r.phase_seconds
    );
    println!("  {:<26} {:>6} {:>9} {:>9} {:>9}", "steady session", "ticks", "p50 ms", "p95 ms", "p99 ms");
    for (name, l) in [("alone", &r.alone), ("under spam", &r.under_spam)] {
        println!("  {name:<26} {:>6} {:>9.1} {:>9.1} {:>9.1}", l.ticks, l.p50_ms, l.p95_ms, l.p99_ms);
    }
    println!(
        "  under spam / alone: p50 {:.2}x, p95 {:.2}x (goal <= 2x); the spammer ran {:.1} ticks/s",
        r.p50_ratio, r.p95_ratio, r.spammer_ticks_per_second
    );
}
