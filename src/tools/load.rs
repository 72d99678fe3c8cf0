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
//! Every wait has a bound (`--timeout`): connecting, each HTTP request, each WebSocket send,
//! each tick (or each period's edits, open loop) awaiting its frame, and the final drain. An
//! `error` message from the server ends the tick it answers, so a failing session cannot wedge
//! the run.
use super::UsageError;
use crate::scene::animation::Animation;
use crate::server::protocol::{ClientMessage, FrameFormat, FrameHeader, ServerMessage};
use crate::technique::TechniqueConfig;
use anyhow::{Context, Result};
use futures_util::{SinkExt, StreamExt};
use serde::Serialize;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Message;

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
    /// there to the end (a soak's measure of leaks, after caches and pools have filled).
    #[arg(long, default_value = "10s", value_parser = humantime::parse_duration)]
    pub warmup: Duration,
    /// Also write the report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What one session saw.
#[derive(Debug, Default, Clone, Serialize)]
pub struct SessionReport {
    pub ticks: u64,
    pub latencies_ms: Vec<f64>,
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

/// The server's (resident bytes, seconds spent encoding frames, seconds spent ticking).
async fn server_figures(http: &reqwest::Client, url: &str) -> (u64, f64, f64) {
    let Ok(resp) = http.get(format!("{url}/metrics")).send().await else { return (0, 0.0, 0.0) };
    let text = resp.text().await.unwrap_or_default();
    let value = |name: &str| -> f64 {
        text.lines()
            .find_map(|l| l.strip_prefix(name).and_then(|v| v.strip_prefix(' ')))
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or(0.0)
    };
    (
        value("relume_resident_memory_bytes") as u64,
        value("relume_encode_seconds_total"),
        value("relume_tick_seconds_sum"),
    )
}

/// Runs the load and returns the report (used by the CLI and by tests).
pub async fn run_load(args: &LoadArgs) -> Result<LoadReport> {
    if args.sessions == 0 || !(args.hz > 0.0 && args.hz <= 1000.0) {
        return Err(UsageError("--sessions must be at least 1 and --hz in (0, 1000]".into()).into());
    }
    let anim = Animation::load(&args.anim).map_err(|e| UsageError(format!("{}: {e}", args.anim.display())))?;
    let config = technique(&args.technique)?;
    let frames: FrameFormat = serde_json::from_value(serde_json::Value::String(args.frames.clone()))
        .map_err(|_| UsageError("--frames: png, jpg, exr or none".into()))?;
    let base = args.url.trim_end_matches('/').to_string();
    let mut headers = reqwest::header::HeaderMap::new();
    if let Some(t) = &args.token {
        headers.insert(
            reqwest::header::AUTHORIZATION,
            format!("Bearer {t}").parse().context("token is not a valid header value")?,
        );
    }
    let http = reqwest::Client::builder().default_headers(headers).timeout(args.timeout).build()?;
    let (rss_start, encode_start, tick_start) = server_figures(&http, &base).await;

    // Create the sessions first, so every stream starts together.
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
            // Those created so far would otherwise wait out the server's idle expiry.
            delete_sessions(&http, &base, &ids).await;
            return Err(anyhow::anyhow!("creating a session: {status}: {}", v["detail"].as_str().unwrap_or("")));
        }
        ids.push(v["id"].as_str().unwrap_or_default().to_string());
    }
    let started = Instant::now();
    let warm = {
        let (http, base, warmup) = (http.clone(), base.clone(), args.warmup);
        tokio::spawn(async move {
            tokio::time::sleep(warmup).await;
            server_figures(&http, &base).await.0
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
    let (rss_end, encode_end, tick_end) = server_figures(&http, &base).await;
    let rss_warm = warm.await.unwrap_or(0);
    delete_sessions(&http, &base, &ids).await;

    let mut lat: Vec<f64> = reports.iter().flat_map(|r| r.latencies_ms.iter().copied()).collect();
    lat.sort_by(f64::total_cmp);
    let sum = |f: fn(&SessionReport) -> u64| reports.iter().map(f).sum::<u64>();
    let (sent, received) = (sum(|r| r.edits_sent), sum(|r| r.edits_received_by_server));
    let coalesced = sum(|r| r.edits_coalesced);
    let errors: Vec<String> = reports.iter().flat_map(|r| r.errors.iter().cloned()).collect();
    Ok(LoadReport {
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
        server_rss_start_bytes: rss_start,
        server_rss_end_bytes: rss_end,
        server_rss_warm_bytes: rss_warm,
        rss_growth_after_warmup: if rss_warm > 0 { rss_end as f64 / rss_warm as f64 - 1.0 } else { 0.0 },
        encode_to_tick_ratio: if tick_end > tick_start {
            (encode_end - encode_start) / (tick_end - tick_start)
        } else {
            0.0
        },
    })
}

/// How a session's stream is paced and bounded.
#[derive(Clone, Copy, Debug)]
struct Pace {
    hz: f64,
    duration: Duration,
    open_loop: bool,
    timeout: Duration,
}

/// Where a session's stream is.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Sending edits every period, and ticks as the pace says.
    Streaming,
    /// Time is up: one last tick drains the queued edits; waiting for what is in flight.
    Draining { drain_tick_sent: bool, until: Instant },
}

type Socket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// One session's stream over its WebSocket.
struct Stream {
    ws: Socket,
    pace: Pace,
    ledger: Ledger,
}

/// What a stream has sent and is waiting for, and its report.
#[derive(Default)]
struct Ledger {
    report: SessionReport,
    /// Without frames, a tick is done at its stats message; with frames, at its frame.
    stats_only: bool,
    /// Closed loop: when the tick in flight was sent.
    in_flight: Option<Instant>,
    /// Open loop: scheduled times of the periods whose edits await their acknowledgement.
    unacknowledged: VecDeque<Instant>,
    /// Open loop: (seq, scheduled time) of acknowledged periods awaiting the frame that applies them.
    unapplied: VecDeque<(u64, Instant)>,
    /// `edits_applied_through` of the stats whose frame has not arrived yet.
    applied_pending: Option<u64>,
}

/// One session's stream: connects, subscribes, streams for the duration, drains.
async fn drive(url: String, anim: Animation, pace: Pace, frames: FrameFormat) -> SessionReport {
    let mut report = SessionReport::default();
    let ws = match tokio::time::timeout(pace.timeout, tokio_tungstenite::connect_async(&url)).await {
        Ok(Ok((ws, _))) => ws,
        Ok(Err(e)) => {
            report.errors.push(format!("websocket: {e}"));
            return report;
        }
        Err(_) => {
            report.errors.push(format!("websocket: no connection within {:?}", pace.timeout));
            return report;
        }
    };
    let ledger = Ledger { report, stats_only: frames == FrameFormat::None, ..Ledger::default() };
    let mut stream = Stream { ws, pace, ledger };
    let subscribe = ClientMessage::Subscribe { frames, stats: true, every: 1, denoised: true };
    if stream.send(&subscribe, "subscribing").await {
        stream.run(&anim).await;
    }
    let _ = tokio::time::timeout(Duration::from_secs(1), stream.ws.close(None)).await;
    stream.ledger.report
}

impl Stream {
    async fn run(&mut self, anim: &Animation) {
        let period = Duration::from_secs_f64(1.0 / self.pace.hz);
        let start = Instant::now();
        let end = start + self.pace.duration;
        let mut next = start;
        let mut phase = Phase::Streaming;
        let mut check = tokio::time::interval((self.pace.timeout / 8).max(Duration::from_millis(10)));
        loop {
            tokio::select! {
                _ = tokio::time::sleep_until(next), if phase == Phase::Streaming => {
                    if Instant::now() >= end {
                        phase = Phase::Draining { drain_tick_sent: false, until: Instant::now() + self.pace.timeout };
                    } else if !self.period(anim, start, next).await {
                        return;
                    } else {
                        next += period;
                        // Closed loop: a period the client could not keep is skipped. Open loop
                        // keeps the schedule: late periods go out at once, timed from schedule.
                        if !self.pace.open_loop && next < Instant::now() {
                            next = Instant::now() + period;
                        }
                    }
                }
                msg = self.ws.next() => {
                    let Some(Ok(msg)) = msg else {
                        self.ledger.report.errors.push("websocket closed by the server".into());
                        return;
                    };
                    self.ledger.receive(msg);
                }
                _ = check.tick() => self.ledger.expire(self.pace.timeout),
            }
            if let Phase::Draining { drain_tick_sent, until } = phase {
                if Instant::now() > until {
                    self.ledger
                        .report
                        .errors
                        .push(format!("the last tick did not come back within {:?}", self.pace.timeout));
                    return;
                }
                if drain_tick_sent && !self.ledger.waiting() {
                    return;
                }
                // Closed loop waits for the tick in flight first; open loop sends at once.
                if !drain_tick_sent && (self.pace.open_loop || self.ledger.in_flight.is_none()) {
                    if !self.send(&ClientMessage::Tick, "draining").await {
                        return;
                    }
                    if !self.pace.open_loop {
                        self.ledger.in_flight = Some(Instant::now());
                    }
                    phase = Phase::Draining { drain_tick_sent: true, until };
                }
            }
        }
    }

    /// One period scheduled at `at`: its edits, and a tick as the pace says. False when the
    /// socket failed.
    async fn period(&mut self, anim: &Animation, start: Instant, at: Instant) -> bool {
        let edits = anim.edits_at(at.duration_since(start).as_secs_f32());
        self.ledger.report.edits_sent += edits.len() as u64;
        if !self.send(&ClientMessage::Edits { edits }, "sending edits").await {
            return false;
        }
        if self.pace.open_loop {
            self.ledger.unacknowledged.push_back(at);
            return self.send(&ClientMessage::Tick, "sending a tick").await;
        }
        if self.ledger.in_flight.is_none() {
            if !self.send(&ClientMessage::Tick, "sending a tick").await {
                return false;
            }
            self.ledger.in_flight = Some(Instant::now());
        }
        true
    }

    /// Sends a message within the timeout; records an error and answers false otherwise.
    async fn send(&mut self, m: &ClientMessage, what: &str) -> bool {
        let text = Message::Text(serde_json::to_string(m).unwrap_or_default().into());
        match tokio::time::timeout(self.pace.timeout, self.ws.send(text)).await {
            Ok(Ok(())) => true,
            Ok(Err(e)) => {
                self.ledger.report.errors.push(format!("websocket failed while {what}: {e}"));
                false
            }
            Err(_) => {
                let timeout = self.pace.timeout;
                self.ledger.report.errors.push(format!("the server did not read for {timeout:?} while {what}"));
                false
            }
        }
    }
}

impl Ledger {
    /// Something sent is still unanswered.
    fn waiting(&self) -> bool {
        self.in_flight.is_some() || !self.unacknowledged.is_empty() || !self.unapplied.is_empty()
    }

    fn receive(&mut self, msg: Message) {
        match msg {
            Message::Text(t) => {
                self.report.bytes += t.len() as u64;
                match serde_json::from_str::<ServerMessage>(&t) {
                    Ok(ServerMessage::Stats { stats, frames_dropped }) => {
                        let r = &mut self.report;
                        r.ticks += 1;
                        r.frames_dropped = frames_dropped;
                        r.edits_received_by_server += stats.edits_received as u64;
                        r.edits_coalesced += stats.edits_coalesced as u64;
                        r.applied_through = r.applied_through.max(stats.edits_applied_through);
                        if self.stats_only {
                            self.frame_done(stats.edits_applied_through);
                        } else {
                            self.applied_pending = Some(stats.edits_applied_through);
                        }
                    }
                    Ok(ServerMessage::EditsAccepted { queued, seq, .. }) => {
                        self.report.batches_accepted.push((seq, queued as u64));
                        if let Some(at) = self.unacknowledged.pop_front() {
                            self.unapplied.push_back((seq, at));
                        }
                    }
                    Ok(ServerMessage::Error { error, detail }) => {
                        // An error answers the tick in flight (or an edit batch): either way the
                        // tick will not come back, so stop waiting for it.
                        self.report.errors.push(format!("{error}: {detail}"));
                        self.in_flight = None;
                    }
                    Err(e) => self.report.errors.push(format!("unreadable message: {e}")),
                }
            }
            Message::Binary(b) => {
                self.report.bytes += b.len() as u64;
                if FrameHeader::decode(&b).is_some() {
                    self.report.frames_received += 1;
                    if let Some(applied) = self.applied_pending.take() {
                        self.frame_done(applied);
                    }
                }
            }
            _ => {}
        }
    }

    /// A tick's frame (or stats, without frames) arrived, having applied batches up to `applied`.
    fn frame_done(&mut self, applied: u64) {
        if let Some(sent) = self.in_flight.take() {
            self.report.latencies_ms.push(sent.elapsed().as_secs_f64() * 1e3);
        }
        while self.unapplied.front().is_some_and(|&(seq, _)| seq <= applied) {
            if let Some((_, at)) = self.unapplied.pop_front() {
                self.report.latencies_ms.push(at.elapsed().as_secs_f64() * 1e3);
            }
        }
    }

    /// Gives up on what has waited longer than `timeout`, counting each as an error.
    fn expire(&mut self, timeout: Duration) {
        if self.in_flight.is_some_and(|t| t.elapsed() > timeout) {
            self.in_flight = None;
            self.report.errors.push(format!("a tick did not come back within {timeout:?}"));
        }
        let stale = |at: &Instant| at.elapsed() > timeout;
        while self.unacknowledged.front().is_some_and(stale) {
            self.unacknowledged.pop_front();
            self.report.errors.push(format!("an edit batch was not acknowledged within {timeout:?}"));
        }
        while self.unapplied.front().is_some_and(|(_, at)| stale(at)) {
            self.unapplied.pop_front();
            self.report.errors.push(format!("an edit batch was not applied by a frame within {timeout:?}"));
        }
    }
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
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let report = runtime.block_on(run_load(&args))?;
    print_table(&report);
    super::write_json_report(args.json.as_deref(), &report)?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::server::protocol::ServerMessage;

    fn text(m: &ServerMessage) -> Message {
        Message::Text(serde_json::to_string(m).expect("message").into())
    }

    fn stats(applied_through: u64) -> Message {
        let frame = crate::engine::TickStats {
            tick: 0,
            technique: "path".into(),
            times: Default::default(),
            rays: Default::default(),
            edits_received: 1,
            edits_coalesced: 0,
            edits_unchanged: 0,
            edits_applied_through: applied_through,
            moved_surfaces: 0,
            spp: 1,
            paths_per_pixel: 1.0,
            accumulation_id: 0,
            aux_rays: 0,
            detail: crate::technique::TechniqueStats::Path(Default::default()),
        };
        text(&ServerMessage::Stats { stats: Box::new(frame), frames_dropped: 0 })
    }

    fn ago(ms: u64) -> Instant {
        Instant::now() - Duration::from_millis(ms)
    }

    /// Hazard: `relume load` waited forever for a tick the server had answered with an error.
    #[test]
    fn an_error_ends_the_tick_in_flight() {
        let mut ledger = Ledger { stats_only: true, in_flight: Some(Instant::now()), ..Ledger::default() };
        ledger.receive(text(&ServerMessage::Error { error: "session_failed".into(), detail: "panic".into() }));
        assert!(!ledger.waiting(), "the stream would wait for a tick that is not coming");
        assert_eq!(ledger.report.errors.len(), 1);
    }

    #[test]
    fn open_loop_latency_runs_from_the_scheduled_time_to_the_frame_that_applies_the_batch() {
        let mut ledger = Ledger { stats_only: true, ..Ledger::default() };
        // Two periods scheduled 900 and 400 ms ago; both acknowledged (seq 1, 2).
        ledger.unacknowledged.extend([ago(900), ago(400)]);
        ledger.receive(text(&ServerMessage::EditsAccepted { queued: 1, pending: 1, seq: 1 }));
        ledger.receive(text(&ServerMessage::EditsAccepted { queued: 1, pending: 1, seq: 2 }));
        // A tick that applied only seq 1 answers the first period alone.
        ledger.receive(stats(1));
        assert_eq!(ledger.report.latencies_ms.len(), 1);
        assert!(ledger.report.latencies_ms[0] >= 900.0, "{:?}", ledger.report.latencies_ms);
        assert!(ledger.waiting());
        ledger.receive(stats(2));
        assert_eq!(ledger.report.latencies_ms.len(), 2);
        assert!((400.0..900.0).contains(&ledger.report.latencies_ms[1]), "{:?}", ledger.report.latencies_ms);
        assert!(!ledger.waiting());
    }

    #[test]
    fn with_frames_a_tick_is_done_at_its_frame_not_its_stats() {
        let mut ledger = Ledger { in_flight: Some(Instant::now()), ..Ledger::default() };
        ledger.receive(stats(0));
        assert!(ledger.waiting(), "stats alone ended the tick");
        let header = FrameHeader { tick: 0, accumulation_id: 0, format: FrameFormat::Png, width: 1, height: 1 };
        ledger.receive(Message::Binary(header.encode().to_vec().into()));
        assert!(!ledger.waiting());
        assert_eq!((ledger.report.frames_received, ledger.report.latencies_ms.len()), (1, 1));
    }

    #[test]
    fn what_waits_past_the_timeout_is_an_error_and_is_dropped() {
        let mut ledger = Ledger { in_flight: Some(ago(2000)), ..Ledger::default() };
        ledger.unacknowledged.push_back(ago(2000));
        ledger.unapplied.push_back((3, ago(2000)));
        ledger.unapplied.push_back((4, ago(10)));
        ledger.expire(Duration::from_secs(1));
        assert_eq!(ledger.report.errors.len(), 3, "{:?}", ledger.report.errors);
        // The recent batch still waits.
        assert_eq!(ledger.unapplied.len(), 1);
        assert!(ledger.in_flight.is_none() && ledger.unacknowledged.is_empty());
    }
}
