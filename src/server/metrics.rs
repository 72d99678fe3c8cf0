//! Server metrics in the Prometheus text exposition format (version 0.0.4).
//!
//! Counters are atomics updated once per request or tick (not per ray); the tick latency
//! histogram has fixed buckets in seconds.
use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Upper bounds of the tick latency histogram, seconds.
const TICK_BUCKETS: [f64; 12] = [0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0];

/// The server's state as `/metrics` reports it besides the counters.
pub struct Gauges {
    /// The Embree library the server traces with, and its kernel family.
    pub embree: crate::embree::Version,
    pub isa: crate::embree::Isa,
    pub sessions: usize,
    pub reserved_bytes: u64,
    pub draining: bool,
}

#[derive(Default)]
pub struct Metrics {
    pub sessions_created: AtomicU64,
    /// Sessions deleted for being idle longer than `--session-idle`.
    pub sessions_expired: AtomicU64,
    pub sessions_failed: AtomicU64,
    pub ticks: AtomicU64,
    pub rays: AtomicU64,
    pub bytes_sent: AtomicU64,
    pub frames_dropped: AtomicU64,
    pub edits_received: AtomicU64,
    pub edits_coalesced: AtomicU64,
    /// Connections answered 503 for being over `--max-connections`.
    pub connections_refused: AtomicU64,
    /// Connections open now.
    pub connections_open: AtomicU64,
    tick_buckets: [AtomicU64; TICK_BUCKETS.len()],
    tick_count: AtomicU64,
    encode_micros: AtomicU64,
    /// Encodings made (one per tick, format, image and exposure, however many clients asked).
    pub frames_encoded: AtomicU64,
    tick_sum_micros: AtomicU64,
    rejected: Mutex<BTreeMap<&'static str, u64>>,
}

impl Metrics {
    pub fn observe_tick(&self, seconds: f64, rays: u64) {
        self.ticks.fetch_add(1, Ordering::Relaxed);
        self.rays.fetch_add(rays, Ordering::Relaxed);
        self.tick_count.fetch_add(1, Ordering::Relaxed);
        self.tick_sum_micros.fetch_add((seconds * 1e6) as u64, Ordering::Relaxed);
        for (i, bound) in TICK_BUCKETS.iter().enumerate() {
            if seconds <= *bound {
                self.tick_buckets[i].fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Time spent encoding frames for clients (the service's main cost besides ticking).
    pub fn observe_encode(&self, seconds: f64) {
        self.encode_micros.fetch_add((seconds * 1e6) as u64, Ordering::Relaxed);
        self.frames_encoded.fetch_add(1, Ordering::Relaxed);
    }

    pub fn reject(&self, reason: &'static str) {
        if let Ok(mut m) = self.rejected.lock() {
            *m.entry(reason).or_default() += 1;
        }
    }

    pub fn sent(&self, bytes: usize) {
        self.bytes_sent.fetch_add(bytes as u64, Ordering::Relaxed);
    }

    /// Resident set size of this process in bytes, from /proc (Linux).
    pub fn resident_bytes() -> u64 {
        let statm = std::fs::read_to_string("/proc/self/statm").unwrap_or_default();
        let pages: u64 = statm.split_whitespace().nth(1).and_then(|p| p.parse().ok()).unwrap_or(0);
        pages * 4096
    }

    pub fn render(&self, now: &Gauges) -> String {
        let sessions = now.sessions;
        let mut out = String::new();
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let _ = writeln!(
            out,
            "# HELP relume_build_info The relume build and the Embree library it runs.\n# TYPE relume_build_info gauge\n\
             relume_build_info{{version=\"{}\",embree=\"{}\",embree_isa=\"{}\"}} 1",
            env!("CARGO_PKG_VERSION"),
            now.embree,
            now.isa
        );
        let mut counter = |name: &str, help: &str, value: u64| {
            let _ = writeln!(out, "# HELP relume_{name} {help}\n# TYPE relume_{name} counter\nrelume_{name} {value}");
        };
        counter("sessions_created_total", "Sessions created.", get(&self.sessions_created));
        counter(
            "sessions_expired_total",
            "Sessions deleted after --session-idle without activity.",
            get(&self.sessions_expired),
        );
        counter("sessions_failed_total", "Sessions marked failed after a panic or error.", get(&self.sessions_failed));
        counter("ticks_total", "Ticks run.", get(&self.ticks));
        counter("rays_total", "Rays traced.", get(&self.rays));
        counter("bytes_sent_total", "Frame and stats bytes sent to clients.", get(&self.bytes_sent));
        counter("frames_dropped_total", "Frames a slow WebSocket consumer never received.", get(&self.frames_dropped));
        counter("edits_received_total", "Edits received.", get(&self.edits_received));
        counter(
            "edits_coalesced_total",
            "Edits replaced by a later edit to the same target.",
            get(&self.edits_coalesced),
        );
        counter(
            "connections_refused_total",
            "Connections answered 503 for being over --max-connections.",
            get(&self.connections_refused),
        );
        let _ = writeln!(
            out,
            "# HELP relume_connections Connections open.\n# TYPE relume_connections gauge\nrelume_connections {}",
            get(&self.connections_open)
        );
        let _ = writeln!(
            out,
            "# HELP relume_encode_seconds_total Time spent encoding frames.\n# TYPE relume_encode_seconds_total counter\nrelume_encode_seconds_total {}",
            get(&self.encode_micros) as f64 / 1e6
        );
        let _ = writeln!(
            out,
            "# HELP relume_frames_encoded_total Frame encodings made (each shared by every client asking for it).\n# TYPE relume_frames_encoded_total counter\nrelume_frames_encoded_total {}",
            get(&self.frames_encoded)
        );
        let _ = writeln!(
            out,
            "# HELP relume_sessions Sessions open.\n# TYPE relume_sessions gauge\nrelume_sessions {sessions}"
        );
        let _ = writeln!(
            out,
            "# HELP relume_session_memory_reserved_bytes The sessions' estimated memory, counted against --server-memory.\n# TYPE relume_session_memory_reserved_bytes gauge\nrelume_session_memory_reserved_bytes {}",
            now.reserved_bytes
        );
        let _ = writeln!(
            out,
            "# HELP relume_draining 1 once SIGTERM has set the node draining (new sessions refused), else 0.\n# TYPE relume_draining gauge\nrelume_draining {}",
            u8::from(now.draining)
        );
        let _ = writeln!(
            out,
            "# HELP relume_resident_memory_bytes Resident set size.\n# TYPE relume_resident_memory_bytes gauge\nrelume_resident_memory_bytes {}",
            Self::resident_bytes()
        );
        let _ = writeln!(out, "# HELP relume_tick_seconds Tick latency.\n# TYPE relume_tick_seconds histogram");
        for (i, bound) in TICK_BUCKETS.iter().enumerate() {
            let _ = writeln!(out, "relume_tick_seconds_bucket{{le=\"{bound}\"}} {}", get(&self.tick_buckets[i]));
        }
        let count = get(&self.tick_count);
        let _ = writeln!(out, "relume_tick_seconds_bucket{{le=\"+Inf\"}} {count}");
        let _ = writeln!(out, "relume_tick_seconds_sum {}", get(&self.tick_sum_micros) as f64 / 1e6);
        let _ = writeln!(out, "relume_tick_seconds_count {count}");
        let _ = writeln!(out, "# HELP relume_rejected_requests_total Requests rejected, by reason.\n# TYPE relume_rejected_requests_total counter");
        if let Ok(m) = self.rejected.lock() {
            for (reason, n) in m.iter() {
                let _ = writeln!(out, "relume_rejected_requests_total{{reason=\"{reason}\"}} {n}");
            }
        }
        out
    }
}
