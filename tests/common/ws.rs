//! A WebSocket client for the integration tests (tokio-tungstenite against a real server).
use futures_util::{SinkExt, StreamExt};
use relume::server::protocol::{FrameHeader, FRAME_HEADER_LEN};
use serde_json::Value;
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;

/// Opens a WebSocket to `url` (`ws://host:port/v1/sessions/{id}/ws`).
pub async fn open(url: &str) -> Socket {
    let (ws, _) = tokio_tungstenite::connect_async(url).await.expect("websocket connects");
    ws
}

pub type Socket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

pub async fn send(ws: &mut Socket, v: Value) {
    ws.send(Message::Text(v.to_string().into())).await.unwrap();
}

/// The next message, skipping pings; panics after 20 s.
pub async fn next(ws: &mut Socket) -> Message {
    loop {
        let m = tokio::time::timeout(Duration::from_secs(20), ws.next())
            .await
            .expect("message in time")
            .expect("open")
            .expect("ok");
        if !matches!(m, Message::Ping(_) | Message::Pong(_)) {
            return m;
        }
    }
}

pub async fn next_text(ws: &mut Socket) -> Value {
    match next(ws).await {
        Message::Text(t) => serde_json::from_str(&t).unwrap(),
        other => panic!("expected text, got {other:?}"),
    }
}

pub async fn next_frame(ws: &mut Socket) -> (FrameHeader, image::DynamicImage) {
    loop {
        if let Message::Binary(b) = next(ws).await {
            let h = FrameHeader::decode(&b).expect("frame header");
            return (h, image::load_from_memory(&b[FRAME_HEADER_LEN..]).expect("png decodes"));
        }
    }
}
