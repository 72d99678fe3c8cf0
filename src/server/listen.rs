//! The accept loop: HTTP/1.1 connections served by hyper, with the protections `axum::serve`
//! leaves out.
//!
//! - **Header-read timeout** (`Limits::header_read_timeout`): a connection that has not sent a
//!   request's complete headers within it is closed (slow-loris). It applies to every request
//!   on a kept-alive connection; a WebSocket, once upgraded, is the socket loop's (pings).
//! - **Connection limit** (`Limits::max_connections`): past it, a new connection is answered
//!   `503` with the JSON `{error: "too_many_connections", detail}` body and closed, so one client
//!   holding many idle sockets cannot exhaust the process's file descriptors. An upgraded
//!   WebSocket leaves this count for its own, of the same size (`ws.rs`).
//! - **Graceful shutdown**: when `shutdown` resolves, the listener closes, every connection
//!   finishes its request in flight, and [`serve`] returns once they have, or when
//!   `Limits::drain_deadline` has passed (whichever is first).
//!
//! HTTP/2 is not offered: clients of this service are browsers and tools on HTTP/1.1, and a
//! WebSocket upgrades from HTTP/1.1.
use super::metrics::Metrics;
use super::state::Limits;
use axum::Router;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::future::Future;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Semaphore};

/// Serves `app` on `listener` until `shutdown` resolves, then drains the connections (bounded by
/// the drain deadline). Returns how long the drain may still take for the sessions.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: &Limits,
    metrics: Arc<Metrics>,
    shutdown: impl Future<Output = ()>,
) -> Duration {
    let mut builder = http1::Builder::new();
    builder.header_read_timeout(limits.header_read_timeout).timer(TokioTimer::new());
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    // `closing` tells every connection to finish; `open` resolves once each has dropped its
    // receiver (the same two channels axum::serve uses).
    let (closing, closing_rx) = watch::channel(());
    let (open, open_rx) = watch::channel(());
    tokio::pin!(shutdown);
    loop {
        let stream = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    // Out of file descriptors and the like: wait instead of spinning.
                    tracing::warn!(target: "relume::server", "accept failed: {e}");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
            _ = &mut shutdown => break,
        };
        let Ok(permit) = permits.clone().try_acquire_owned() else {
            metrics.connections_refused.fetch_add(1, Ordering::Relaxed);
            tokio::spawn(refuse(stream, limits.max_connections));
            continue;
        };
        let _ = stream.set_nodelay(true);
        let conn =
            builder.serve_connection(TokioIo::new(stream), TowerToHyperService::new(app.clone())).with_upgrades();
        let (mut closing, open, metrics) = (closing_rx.clone(), open_rx.clone(), metrics.clone());
        metrics.connections_open.fetch_add(1, Ordering::Relaxed);
        tokio::spawn(async move {
            let mut conn = std::pin::pin!(conn);
            let mut finishing = false;
            loop {
                tokio::select! {
                    ended = conn.as_mut() => {
                        if let Err(e) = ended {
                            tracing::debug!(target: "relume::server", "connection ended: {e}");
                        }
                        break;
                    }
                    _ = closing.changed(), if !finishing => {
                        finishing = true;
                        conn.as_mut().graceful_shutdown();
                    }
                }
            }
            metrics.connections_open.fetch_sub(1, Ordering::Relaxed);
            drop((open, permit));
        });
    }
    drop(listener);
    let started = tokio::time::Instant::now();
    let _ = closing.send(());
    drop((closing_rx, open_rx));
    if tokio::time::timeout(limits.drain_deadline, open.closed()).await.is_err() {
        tracing::warn!(
            target: "relume::server",
            "connections still open after the {:?} drain deadline; closing them",
            limits.drain_deadline
        );
    }
    limits.drain_deadline.saturating_sub(started.elapsed())
}

/// Answers a connection over the limit with 503 and the JSON error body, then closes it.
async fn refuse(mut stream: TcpStream, max: usize) {
    let body = serde_json::json!({
        "error": "too_many_connections",
        "detail": format!("the server holds its maximum of {max} connections (--max-connections); retry later"),
    })
    .to_string();
    let response = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\nretry-after: 1\r\nconnection: close\r\n\r\n{body}",
        body.len()
    );
    let write = async {
        stream.write_all(response.as_bytes()).await?;
        stream.shutdown().await
    };
    let _ = tokio::time::timeout(Duration::from_secs(1), write).await;
}
