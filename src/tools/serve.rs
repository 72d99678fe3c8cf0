//! `relume serve`: runs the HTTP/WebSocket service until SIGINT, or SIGTERM and a drain.
use super::UsageError;
use crate::server::{self, valid_node, Access, AppState, Limits, ServerConfig};
use anyhow::{Context, Result};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

#[derive(clap::Args, Debug)]
pub struct ServeArgs {
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
    /// Folder of bundled scenes (and their meshes and animations).
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    /// Bearer token required on every /v1 route; required to bind beyond loopback.
    #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    #[arg(long, default_value_t = 16)]
    pub max_sessions: usize,
    /// Memory one session may hold, in MiB: a session whose estimate (technique, film) is
    /// larger is refused with 413 before anything is allocated.
    #[arg(long, default_value_t = 2048)]
    pub session_memory: u64,
    /// Memory all sessions together may hold, in MiB (default: three quarters of this
    /// machine's RAM); a session that would exceed it is refused with 429.
    #[arg(long)]
    pub server_memory: Option<u64>,
    /// Largest scene upload (`PUT /v1/scenes/NAME`), in MiB: the .glb or .zip as sent, and an
    /// archive's files unpacked.
    #[arg(long, default_value_t = 2048)]
    pub upload_limit: u64,
    /// Seconds without a request or WebSocket message after which a session is deleted.
    #[arg(long, default_value_t = 600)]
    pub session_idle: u64,
    /// Connections open at once (WebSockets included); more are answered 503 and closed.
    #[arg(long, default_value_t = 512)]
    pub max_connections: usize,
    /// Seconds a connection may take to send a request's headers before it is closed.
    #[arg(long, default_value_t = 10)]
    pub header_timeout: u64,
    /// Seconds shutdown waits for connections and sessions to finish.
    #[arg(long, default_value_t = 30)]
    pub drain_deadline: u64,
    /// Seconds a node keeps serving its sessions after SIGTERM, refusing new ones with 503,
    /// so they can be moved (`relume migrate`); it shuts down sooner when none is left.
    /// SIGINT (Ctrl-C) stops at once.
    #[arg(long, default_value_t = 30)]
    pub drain_grace: u64,
    /// A host name the `Host` header may carry besides IP addresses and localhost (repeat for
    /// more); other names get 421, which stops DNS rebinding.
    #[arg(long = "allow-host")]
    pub allow_hosts: Vec<String>,
    /// An origin (`https://app.example:8443`) whose pages may open WebSockets and read
    /// responses through CORS (repeat for more). CORS is off without it.
    #[arg(long = "allow-origin")]
    pub allow_origins: Vec<String>,
    /// Node name: every session id this process makes is `NODE.sID`, and every response carries
    /// `X-Relume-Node: NODE`, so a proxy can route a session to its owner (default: the
    /// hostname).
    #[arg(long)]
    pub node: Option<String>,
    /// Rendering threads shared by all sessions, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = super::thread_count)]
    pub threads: Option<usize>,
    /// Cap Embree's kernels at this ISA: sse2, sse4.2, avx, avx2 or avx512 (default: the
    /// widest this CPU has).
    #[arg(long, env = "RELUME_EMBREE_ISA")]
    pub isa: Option<crate::embree::Isa>,
}

/// Checks the flags: a non-loopback address needs a token; the scenes folder must exist.
pub fn config(args: &ServeArgs) -> Result<ServerConfig> {
    if !args.addr.ip().is_loopback() && args.token.as_deref().is_none_or(str::is_empty) {
        return Err(UsageError(format!(
            "refusing to listen on {} without a token: anyone on the network could drive the server. \
             Pass --token TOKEN (or set RELUME_TOKEN), or listen on 127.0.0.1",
            args.addr
        ))
        .into());
    }
    if !args.scenes.is_dir() {
        return Err(UsageError(format!("--scenes {}: not a folder", args.scenes.display())).into());
    }
    if args.max_sessions == 0 {
        return Err(UsageError("--max-sessions must be at least 1".into()).into());
    }
    if args.session_idle == 0 {
        return Err(UsageError("--session-idle must be at least 1 second".into()).into());
    }
    if args.max_connections == 0 || args.header_timeout == 0 {
        return Err(UsageError("--max-connections and --header-timeout must be at least 1".into()).into());
    }
    if args.session_memory == 0 || args.server_memory == Some(0) || args.upload_limit == 0 {
        return Err(
            UsageError("--session-memory, --server-memory and --upload-limit must be at least 1 MiB".into()).into()
        );
    }
    let node = args.node.clone().unwrap_or_else(hostname);
    if !valid_node(&node) {
        return Err(UsageError(format!(
            "--node {node:?}: a node name is 1 to 63 letters, digits and '-', not starting or ending with '-'"
        ))
        .into());
    }
    let threads = super::threads_or_all_cores(args.threads);
    let server_memory = args.server_memory.map_or_else(three_quarters_of_ram, |mib| mib << 20);
    Ok(ServerConfig {
        scenes_root: args.scenes.canonicalize().with_context(|| format!("resolving {}", args.scenes.display()))?,
        token: args.token.clone().filter(|t| !t.is_empty()),
        threads,
        isa: args.isa,
        limits: Limits {
            max_sessions: args.max_sessions,
            session_memory: args.session_memory << 20,
            upload_limit: args.upload_limit << 20,
            server_memory,
            session_idle: std::time::Duration::from_secs(args.session_idle),
            max_connections: args.max_connections,
            header_read_timeout: std::time::Duration::from_secs(args.header_timeout),
            drain_deadline: std::time::Duration::from_secs(args.drain_deadline),
            ..Limits::default()
        },
        access: Access { hosts: args.allow_hosts.clone(), origins: args.allow_origins.clone() },
        node,
    })
}

/// The machine's host name (the kernel's, as `hostname` prints it), or `relume` where it is
/// unknown or is not a valid node name.
fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .ok()
        .filter(|h| valid_node(h))
        .unwrap_or_else(|| "relume".into())
}

/// Three quarters of `MemTotal` in /proc/meminfo, or the default budget where it is unknown.
fn three_quarters_of_ram() -> u64 {
    let total_kib = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        let line = m.lines().find(|l| l.starts_with("MemTotal:"))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok()
    });
    total_kib.map_or(Limits::default().server_memory, |kib| kib * 1024 / 4 * 3)
}

pub fn run(args: ServeArgs) -> Result<()> {
    let config = config(&args)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let served = runtime.block_on(async move {
        let state = Arc::new(AppState::new(config)?);
        let listener =
            tokio::net::TcpListener::bind(args.addr).await.with_context(|| format!("binding {}", args.addr))?;
        tracing::info!(target: "relume::server", "listening on http://{} (Embree kernels: {})", listener.local_addr()?, state.device.isa());
        match crate::film::Denoiser::probe() {
            Ok(()) => tracing::info!(target: "relume::server", "denoise: Open Image Denoise is available"),
            Err(e) => eprintln!("relume: warning: {e}; sessions asking for \"denoise\" will be refused"),
        }
        tracing::info!(target: "relume::server", "node {}: session ids start with \"{}.\"", state.config.node, state.config.node);
        eprintln!("relume: serving {} on http://{}/ (Ctrl-C to stop)", args.scenes.display(), listener.local_addr()?);
        let grace = std::time::Duration::from_secs(args.drain_grace);
        server::run(listener, state.clone(), server::drain_on_terminate(state, grace)).await?;
        Ok(())
    });
    // A session still ticking past the drain deadline must not hold the process open.
    runtime.shutdown_timeout(std::time::Duration::from_secs(1));
    served
}
