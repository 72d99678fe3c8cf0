//! A `relume serve` process (the binary cargo built for this test run: the release one under
//! `scripts/test.sh`) on a free loopback port, for the tests that drive the binary users run.
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

pub const BIN: &str = env!("CARGO_BIN_EXE_relume");

/// A running `relume serve` and the address it printed.
pub struct Served {
    child: Child,
    pub addr: String,
}

impl Served {
    /// Starts `relume serve --addr 127.0.0.1:0 --threads 2 --scenes scenes/` with `extra`
    /// arguments, and waits (bounded) for the address it prints.
    pub fn start(extra: &[&str]) -> Served {
        Served::start_in(&super::scenes_dir(), extra)
    }

    /// [`Served::start`] on the scenes folder `scenes` (a test's own, where it uploads).
    pub fn start_in(scenes: &std::path::Path, extra: &[&str]) -> Served {
        let mut child = Command::new(BIN)
            .args(["serve", "--addr", "127.0.0.1:0", "--threads", "2", "--scenes"])
            .arg(scenes)
            .args(extra)
            .stderr(Stdio::piped())
            .spawn()
            .expect("relume serve starts");
        // Stderr is read on its own thread (and drained after, so the server never blocks on a
        // full pipe); the address must come within a deadline, so a changed line fails the
        // test instead of hanging it.
        let stderr = child.stderr.take().expect("stderr");
        let (tx, rx) = std::sync::mpsc::channel::<String>();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        let deadline = Instant::now() + Duration::from_secs(60);
        let addr = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let Ok(line) = rx.recv_timeout(left) else {
                let _ = child.kill();
                panic!("relume serve printed no 'relume: serving … on http://ADDR/' line within 60 s");
            };
            // "relume: serving DIR on http://ADDR/ (Ctrl-C to stop)"
            if let Some(rest) = line.strip_prefix("relume: serving").and_then(|l| l.split(" on http://").nth(1)) {
                break rest.split('/').next().unwrap_or_default().to_string();
            }
        };
        Served { child, addr }
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    /// The server's peak resident memory so far (`VmHWM`), in bytes.
    pub fn peak_rss(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).expect("/proc status");
        let line = status.lines().find(|l| l.starts_with("VmHWM:")).expect("VmHWM");
        line.split_whitespace().nth(1).and_then(|kib| kib.parse::<u64>().ok()).expect("kB") * 1024
    }

    /// Sends SIGTERM (the node drains, then exits).
    pub fn sigterm(&self) {
        let pid = self.child.id().to_string();
        let killed = Command::new("kill").args(["-TERM", &pid]).status().expect("kill runs");
        assert!(killed.success());
    }

    /// The exit status once the process has ended, or `None` if it is still running.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        self.child.try_wait().expect("wait")
    }

    /// Waits up to `limit` for the process to exit.
    pub fn wait_exit(&mut self, limit: Duration) -> ExitStatus {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(status) = self.exited() {
                return status;
            }
            assert!(Instant::now() < deadline, "relume serve did not exit within {limit:?}");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Sends SIGTERM and waits (bounded) for the exit status.
    pub fn terminate(mut self) -> ExitStatus {
        self.sigterm();
        self.wait_exit(Duration::from_secs(60))
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
