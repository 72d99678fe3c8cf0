//! One session's stream for `relume load`: a WebSocket that sends an animation's edits and
//! ticks at the pace asked for ([`Pace`]: closed or open loop, with a timeout on every wait),
//! and a [`Ledger`] of what it sent and is waiting for, from which the session's report is
//! made. The ledger has no socket, so its bookkeeping is tested on its own.
use super::{Latency, SessionReport};
use crate::scene::animation::Animation;
use crate::server::protocol::{ClientMessage, FrameFormat, FrameHeader, ServerMessage};
use futures_util::{SinkExt, StreamExt};
use std::collections::VecDeque;
use std::time::Duration;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Message;

/// How a session's stream is paced and bounded.
#[derive(Clone, Copy, Debug)]
pub struct Pace {
    pub hz: f64,
    pub duration: Duration,
    pub open_loop: bool,
    pub timeout: Duration,
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
pub async fn drive(url: String, anim: Animation, pace: Pace, frames: FrameFormat) -> SessionReport {
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
                    // This client never sends `update`, so an answer to one is the server's error.
                    Ok(ServerMessage::Updated { .. }) => self.report.errors.push("an update nobody sent".into()),
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
            self.report.latencies.push(Latency { at: Instant::now(), ms: sent.elapsed().as_secs_f64() * 1e3 });
        }
        while self.unapplied.front().is_some_and(|&(seq, _)| seq <= applied) {
            if let Some((_, at)) = self.unapplied.pop_front() {
                self.report.latencies.push(Latency { at: Instant::now(), ms: at.elapsed().as_secs_f64() * 1e3 });
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

#[cfg(test)]
mod tests {
    use super::*;

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
            denoise_reused: false,
            resolve_reused: false,
            restored: false,
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
        assert_eq!(ledger.report.latencies.len(), 1);
        assert!(ledger.report.latencies[0].ms >= 900.0, "{:?}", ledger.report.latencies);
        assert!(ledger.waiting());
        ledger.receive(stats(2));
        assert_eq!(ledger.report.latencies.len(), 2);
        assert!((400.0..900.0).contains(&ledger.report.latencies[1].ms), "{:?}", ledger.report.latencies);
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
        assert_eq!((ledger.report.frames_received, ledger.report.latencies.len()), (1, 1));
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
