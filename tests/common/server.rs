//! A real relume server on 127.0.0.1:0 for tests, with an HTTP and a WebSocket client.
use relume::server::{self, Access, AppState, Limits, ServerConfig};
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;
use tokio::sync::oneshot;

pub struct TestServer {
    pub addr: SocketAddr,
    pub http: reqwest::Client,
    pub state: Arc<AppState>,
    stop: Option<oneshot::Sender<()>>,
    pub done: Option<tokio::task::JoinHandle<std::io::Result<()>>>,
}

impl TestServer {
    pub async fn start(token: Option<&str>, limits: Limits) -> TestServer {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        TestServer::start_on(listener, token, limits).await
    }

    /// A server whose accepted sockets have small send buffers (they inherit the listener's),
    /// so a client that stops reading makes the server block on sending.
    pub async fn start_with_small_send_buffers(limits: Limits) -> TestServer {
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.set_send_buffer_size(4096).unwrap();
        socket.bind("127.0.0.1:0".parse().unwrap()).unwrap();
        TestServer::start_on(socket.listen(64).unwrap(), None, limits).await
    }

    pub async fn start_on(listener: tokio::net::TcpListener, token: Option<&str>, limits: Limits) -> TestServer {
        TestServer::start_with_access(listener, token, limits, Access::default()).await
    }

    /// A server that also accepts the given `Host` names and browser origins.
    pub async fn start_with_access(
        listener: tokio::net::TcpListener,
        token: Option<&str>,
        limits: Limits,
        access: Access,
    ) -> TestServer {
        let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        TestServer::start_with_config(listener, token, limits, access, &scenes).await
    }

    /// A server on the scenes folder `scenes` (a copy, where a test uploads).
    pub async fn start_in(scenes: &Path, limits: Limits) -> TestServer {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        TestServer::start_with_config(listener, None, limits, Access::default(), scenes).await
    }

    async fn start_with_config(
        listener: tokio::net::TcpListener,
        token: Option<&str>,
        limits: Limits,
        access: Access,
        scenes: &Path,
    ) -> TestServer {
        let config = ServerConfig {
            scenes_root: scenes.canonicalize().unwrap(),
            token: token.map(str::to_string),
            threads: 2,
            isa: None,
            limits,
            access,
            node: "test-node".into(),
        };
        let state = Arc::new(AppState::new(config).expect("server state"));
        let addr = listener.local_addr().unwrap();
        let (stop, stopped) = oneshot::channel::<()>();
        let done = tokio::spawn(server::run(listener, state.clone(), async move {
            let _ = stopped.await;
        }));
        TestServer { addr, http: reqwest::Client::new(), state, stop: Some(stop), done: Some(done) }
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    pub fn ws_url(&self, path: &str) -> String {
        format!("ws://{}{path}", self.addr)
    }

    /// `GET path` as JSON (any status).
    pub async fn get_json(&self, path: &str) -> serde_json::Value {
        self.http.get(self.url(path)).send().await.unwrap().json().await.unwrap()
    }

    /// `POST path` with a JSON body, answered as JSON (any status).
    pub async fn post_json(&self, path: &str, body: &serde_json::Value) -> serde_json::Value {
        self.http.post(self.url(path)).json(body).send().await.unwrap().json().await.unwrap()
    }

    /// Creates a session and returns its id.
    pub async fn session(&self, body: serde_json::Value) -> String {
        let r = self.http.post(self.url("/v1/sessions")).json(&body).send().await.unwrap();
        let status = r.status();
        let v: serde_json::Value = r.json().await.unwrap();
        assert_eq!(status, 201, "{v}");
        v["id"].as_str().unwrap().to_string()
    }

    /// Signals shutdown and waits for `run` to return (sessions drained).
    pub async fn shutdown(mut self) -> std::io::Result<()> {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        match self.done.take() {
            Some(d) => d.await.expect("server task"),
            None => Ok(()),
        }
    }
}
