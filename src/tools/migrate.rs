//! `relume migrate`: moves sessions between nodes, for a node about to drain or shut down.
//!
//! Each session moves in three requests: `GET …/snapshot` on the source, `POST /v1/sessions
//! {"snapshot"}` on the destination, and `DELETE` on the source once the restore succeeded. A
//! session whose snapshot or restore fails stays where it was, and the run exits 1. The moved
//! session has a new id (its new node's); the report maps old ids to new ones (`--json`).
//!
//! Edits a client sends to the old id between the snapshot and the delete are lost with it:
//! clients must switch to the new id, which the report gives.
use super::UsageError;
use anyhow::{anyhow, Context, Result};
use serde::Serialize;
use serde_json::Value;
use std::path::PathBuf;
use std::time::Duration;

#[derive(clap::Args, Debug, Clone)]
pub struct MigrateArgs {
    /// The node the sessions leave (its own URL, not the proxy's).
    #[arg(long)]
    pub from: String,
    /// The node (or the proxy) that takes them.
    #[arg(long)]
    pub to: String,
    /// Move every session of the source node.
    #[arg(long, conflicts_with = "session")]
    pub all: bool,
    /// A session to move (repeat for more).
    #[arg(long)]
    pub session: Vec<String>,
    /// Bearer token for both nodes.
    #[arg(long, env = "RELUME_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Bound on each request.
    #[arg(long, default_value = "60s", value_parser = humantime::parse_duration)]
    pub timeout: Duration,
    /// Write the report (old id → new id, tick) as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One session's move.
#[derive(Debug, Serialize)]
pub struct Moved {
    pub from: String,
    /// The new id, when the restore succeeded.
    pub to: Option<String>,
    /// The tick the session continues from.
    pub tick: Option<u64>,
    pub error: Option<String>,
}

/// The client of both nodes.
struct Nodes {
    http: reqwest::Client,
    from: String,
    to: String,
}

impl Nodes {
    /// The JSON answer of a request, or an error naming the node's `{error, detail}`.
    async fn json(&self, req: reqwest::RequestBuilder, what: &str) -> Result<Value> {
        let resp = req.send().await.with_context(|| what.to_string())?;
        let status = resp.status();
        let body: Value = resp.json().await.unwrap_or(Value::Null);
        if !status.is_success() {
            return Err(anyhow!("{what}: {status}: {} {}", body["error"], body["detail"]));
        }
        Ok(body)
    }

    async fn ids(&self) -> Result<Vec<String>> {
        let list =
            self.json(self.http.get(format!("{}/v1/sessions", self.from)), "listing the source's sessions").await?;
        let sessions = list["sessions"].as_array().cloned().unwrap_or_default();
        Ok(sessions
            .iter()
            .filter(|s| s["state"] == "running")
            .filter_map(|s| s["id"].as_str().map(String::from))
            .collect())
    }

    async fn move_one(&self, id: &str) -> Moved {
        match self.try_move(id).await {
            Ok((to, tick)) => Moved { from: id.to_string(), to: Some(to), tick: Some(tick), error: None },
            Err(e) => Moved { from: id.to_string(), to: None, tick: None, error: Some(format!("{e:#}")) },
        }
    }

    async fn try_move(&self, id: &str) -> Result<(String, u64)> {
        let snapshot = self
            .json(self.http.get(format!("{}/v1/sessions/{id}/snapshot", self.from)), &format!("snapshot of {id}"))
            .await?;
        let tick = snapshot["tick"].as_u64().unwrap_or(0);
        let created = self
            .json(
                self.http.post(format!("{}/v1/sessions", self.to)).json(&serde_json::json!({ "snapshot": snapshot })),
                &format!("restoring {id}"),
            )
            .await?;
        let new_id = created["id"].as_str().ok_or_else(|| anyhow!("restoring {id}: the answer has no id"))?.to_string();
        let deleted = self.http.delete(format!("{}/v1/sessions/{id}", self.from)).send().await;
        if let Err(e) = deleted
            .as_ref()
            .map_err(|e| e.to_string())
            .and_then(|r| r.error_for_status_ref().map_err(|e| e.to_string()))
        {
            eprintln!("relume: warning: {id} moved to {new_id}, but deleting it on the source failed ({e}); it expires when idle");
        }
        Ok((new_id, tick))
    }
}

pub async fn migrate(args: &MigrateArgs) -> Result<Vec<Moved>> {
    if !args.all && args.session.is_empty() {
        return Err(UsageError("give --all or at least one --session ID".into()).into());
    }
    let http = super::http_client(args.token.as_deref(), args.timeout)?;
    let nodes = Nodes {
        http,
        from: args.from.trim_end_matches('/').to_string(),
        to: args.to.trim_end_matches('/').to_string(),
    };
    let ids = if args.all { nodes.ids().await? } else { args.session.clone() };
    let mut report = Vec::with_capacity(ids.len());
    for (i, id) in ids.iter().enumerate() {
        let moved = nodes.move_one(id).await;
        match (&moved.to, &moved.error) {
            (Some(to), _) => {
                eprintln!("[{}/{}] {id} → {to} (continues at tick {})", i + 1, ids.len(), moved.tick.unwrap_or(0))
            }
            (None, e) => eprintln!("[{}/{}] {id}: not moved: {}", i + 1, ids.len(), e.as_deref().unwrap_or("?")),
        }
        report.push(moved);
    }
    Ok(report)
}

pub fn run(args: MigrateArgs) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let report = runtime.block_on(migrate(&args))?;
    super::write_json_report(args.json.as_deref(), &report)?;
    let failed = report.iter().filter(|m| m.error.is_some()).count();
    println!("moved {} of {} session(s) from {} to {}", report.len() - failed, report.len(), args.from, args.to);
    if failed > 0 {
        return Err(anyhow!("{failed} session(s) were not moved; they stay on {}", args.from));
    }
    Ok(())
}
