//! Connection-level hazards from hostile and sloppy clients, each against a real server on
//! 127.0.0.1:0: slow headers, too many sockets, tick spam, and a shutdown that a long tick would
//! hold up. Each test names its hazard; each failed before its fix.
mod common;
use common::server::TestServer;
use relume::server::Limits;
use serde_json::{json, Value};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Reads until the server closes the connection or `within` passes; `None` on the timeout.
async fn read_until_closed(stream: &mut TcpStream, within: Duration) -> Option<String> {
    let mut got = Vec::new();
    let read = async {
        let mut buf = [0u8; 1024];
        loop {
            match stream.read(&mut buf).await {
                Ok(0) | Err(_) => break,
                Ok(n) => got.extend_from_slice(&buf[..n]),
            }
        }
    };
    tokio::time::timeout(within, read).await.ok()?;
    Some(String::from_utf8_lossy(&got).into_owned())
}

async fn healthz_over(stream: &mut TcpStream) -> String {
    stream.write_all(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n").await.expect("write");
    read_until_closed(stream, Duration::from_secs(10)).await.unwrap_or_default()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_connection_that_does_not_finish_its_headers_is_closed() {
    // Hazard (slow-loris): axum::serve sets no header-read timeout, so a client could hold a
    // connection open forever by sending a header line now and then, or nothing at all.
    let limits = Limits { header_read_timeout: Duration::from_millis(300), ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let mut partial = TcpStream::connect(s.addr).await.expect("connect");
    partial.write_all(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n").await.expect("write");
    let mut silent = TcpStream::connect(s.addr).await.expect("connect");
    // Far longer than the timeout: a server without it keeps both open.
    for (what, stream) in [("partial headers", &mut partial), ("no bytes at all", &mut silent)] {
        let answer = read_until_closed(stream, Duration::from_secs(10)).await;
        assert!(answer.is_some(), "a connection that sent {what} was still open after 10 s");
        let answer = answer.unwrap_or_default();
        assert!(answer.is_empty() || answer.starts_with("HTTP/1.1 408"), "{what}: {answer}");
    }
    // A complete request is served as before.
    let mut whole = TcpStream::connect(s.addr).await.expect("connect");
    assert!(healthz_over(&mut whole).await.starts_with("HTTP/1.1 200"));
    s.shutdown().await.expect("shutdown");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn connections_over_the_limit_get_503_with_the_json_body() {
    // Hazard: nothing bounded the number of open connections, so one client holding idle
    // sockets could use up the process's file descriptors and lock every other client out.
    let limits = Limits { max_connections: 3, ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    // The server accepts in arrival order, so these three are accepted before the fourth.
    let mut held = Vec::new();
    for _ in 0..3 {
        held.push(TcpStream::connect(s.addr).await.expect("connect"));
    }
    let mut over = TcpStream::connect(s.addr).await.expect("connect");
    let answer = read_until_closed(&mut over, Duration::from_secs(10)).await.expect("the server closes it");
    assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
    let body: Value = serde_json::from_str(answer.split("\r\n\r\n").nth(1).unwrap_or_default()).expect("JSON body");
    assert_eq!(body["error"], "too_many_connections", "{body}");
    assert!(body["detail"].as_str().unwrap_or_default().contains("--max-connections"), "{body}");
    // Once a held connection goes, a new one is served.
    held.pop();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let mut next = TcpStream::connect(s.addr).await.expect("connect");
        if healthz_over(&mut next).await.starts_with("HTTP/1.1 200") {
            break;
        }
        assert!(Instant::now() < deadline, "no connection was served after one of the three closed");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    drop(held);
    assert!(metric(&s, "relume_connections_refused_total").await >= 1.0);
    assert!(metric(&s, "relume_connections").await <= 3.0);
    s.shutdown().await.expect("shutdown");
}

/// A metric's value from `/metrics`.
async fn metric(s: &TestServer, name: &str) -> f64 {
    let text = reqwest::get(s.url("/metrics")).await.expect("metrics").text().await.unwrap_or_default();
    text.lines()
        .find_map(|l| l.strip_prefix(name).and_then(|v| v.strip_prefix(' ')))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(0.0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn client_driven_ticks_are_capped_at_max_tick_hz() {
    // Hazard: a client could drive a session's ticks as fast as it could send requests;
    // `max_tick_hz` bounded only the server's own schedule.
    let limits = Limits { max_tick_hz: 5.0, ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let id = s.session(json!({"scene": "cornell-box", "width": 16, "height": 16})).await;
    let url = s.url(&format!("/v1/sessions/{id}/tick"));
    let started = Instant::now();
    let mut ticks = Vec::new();
    for _ in 0..6 {
        let v: Value = s.http.post(&url).json(&json!({})).send().await.expect("tick").json().await.expect("stats");
        ticks.push(v["stats"]["tick"].as_u64().unwrap_or_else(|| panic!("no tick number in {v}")));
    }
    // Six distinct ticks, one after another, each at least 1/5 s after the one before it: a
    // lower bound that no machine, however fast, can beat (16x16 ticks take milliseconds).
    assert_eq!(ticks, (0..6).collect::<Vec<_>>());
    let elapsed = started.elapsed();
    assert!(elapsed >= Duration::from_millis(5 * 200 - 20), "six ticks in {elapsed:?} at max_tick_hz 5");
    s.shutdown().await.expect("shutdown");
}

#[test]
fn shutdown_does_not_wait_past_its_deadline_for_a_long_tick() {
    // Hazard: the shutdown drain waited for every session's tick in progress, however long,
    // so SIGTERM could hang the process for as long as a client's heaviest tick.
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("runtime");
    runtime.block_on(async {
        let limits = Limits { drain_deadline: Duration::from_millis(300), max_spp_per_tick: 1024, ..Limits::default() };
        let s = TestServer::start(None, limits).await;
        // About 8M paths: seconds of work on any machine this runs on.
        let body =
            json!({"scene": "cornell-box", "width": 256, "height": 256, "technique": {"id": "path", "spp": 128}});
        let id = s.session(body).await;
        let entry = s.state.session(&id).expect("session");
        let (http, url) = (s.http.clone(), s.url(&format!("/v1/sessions/{id}/tick")));
        tokio::spawn(async move { http.post(url).json(&json!({})).send().await.map(|r| r.status()) });
        // Wait until the tick holds its turn on the pool.
        while s.state.turns.waiting() == 0 {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        s.shutdown().await.expect("shutdown");
        let finished = entry.handle.history.lock().map(|h| h.len()).unwrap_or(0);
        assert_eq!(finished, 0, "shutdown returned only after the long tick had finished");
    });
    // The tick still running is the process's to end, as `relume serve` does.
    runtime.shutdown_background();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_creation_that_times_out_leaves_no_session_behind() {
    // Hazard: a creation answered 408 (or whose client went away) went on loading in the
    // background and added a session nobody knew the id of, holding its memory until idle
    // expiry.
    // The creation (about 15 ms here) outlasts the 1 ms timeout unless the runtime's timer is
    // starved for that long (the other tests of this file load both cores), so a creation that
    // beat it is deleted and tried again.
    let limits = Limits { request_timeout: Duration::from_millis(1), ..Limits::default() };
    let s = TestServer::start(None, limits).await;
    let body =
        json!({"scene": "bunnies-9", "width": 64, "height": 64, "technique": {"id": "photon_reuse", "paths": 100000}});
    let mut tries = 0u64;
    loop {
        let r = s.http.post(s.url("/v1/sessions")).json(&body).send().await.expect("request");
        if r.status() == 408 {
            break;
        }
        assert_eq!(r.status(), 201);
        let id = r.json::<serde_json::Value>().await.expect("view")["id"].as_str().expect("id").to_string();
        assert_eq!(s.http.delete(s.url(&format!("/v1/sessions/{id}"))).send().await.expect("delete").status(), 204);
        tries += 1;
        assert!(tries < 20, "no creation took longer than the 1 ms timeout in {tries} tries");
    }
    // The creation finishes in the background; then the session must be gone again.
    let created = Instant::now();
    let before = tries;
    while s.state.metrics.sessions_created.load(std::sync::atomic::Ordering::Relaxed) == before {
        assert!(created.elapsed() < Duration::from_secs(60), "the creation never finished");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while s.state.session_count() > 0 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert_eq!(s.state.session_count(), 0, "an orphaned session is left");
    assert_eq!(s.state.reserved_bytes(), 0);
    s.shutdown().await.expect("shutdown");
}
