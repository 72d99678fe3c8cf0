//! The clients run their own tests against the release binary served on a free port: the
//! Python one (`clients/python`) with pytest, its packages from `.deps/pytools`
//! (scripts/pytools.sh, which scripts/test.sh runs); the JavaScript one (`clients/js`) with
//! Node's own test runner and, where Node has no WebSocket of its own, the `ws` package from
//! `.deps/nodetools` (scripts/nodetools.sh).
mod common;
use common::process::Served;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// How long a client's whole test run may take before it is stopped and failed with what it
/// printed: a bound against a run that hangs (an open socket keeps Node's runner waiting), far
/// above the few seconds a run takes.
const RUN_LIMIT: Duration = Duration::from_secs(300);

/// Runs a client's test `command` in `clients/DIR` against a fresh server (its URL in
/// `RELUME_URL`) on a copy of the bundled scenes, and returns what it printed; a failing run
/// fails the test with its report.
fn run_against_a_server(dir: &str, command: &mut Command) -> String {
    let scenes = common::scenes_copy(&format!("client-{dir}"));
    let served = Served::start_in(&scenes, &[]);
    let mut child = command
        .current_dir(root().join("clients").join(dir))
        .env("RELUME_URL", served.url(""))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the client's test runner starts (scripts/test.sh installs it)");
    let (stdout, stderr) = (drain(child.stdout.take()), drain(child.stderr.take()));
    let deadline = Instant::now() + RUN_LIMIT;
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break Some(status);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let report = stdout.join().unwrap_or_default();
    println!("{report}{}", stderr.join().unwrap_or_default());
    let status = status.unwrap_or_else(|| panic!("the {dir} client's tests ran past {RUN_LIMIT:?}:\n{report}"));
    assert!(status.success(), "the {dir} client's tests failed:\n{report}");
    served.terminate();
    let _ = std::fs::remove_dir_all(&scenes);
    report
}

/// Reads a child's pipe to its end on a thread of its own (so the child never blocks on it).
fn drain(pipe: Option<impl Read + Send + 'static>) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut text = String::new();
        if let Some(mut p) = pipe {
            let _ = p.read_to_string(&mut text);
        }
        text
    })
}

#[test]
fn the_python_client_passes_its_tests_against_a_real_server() {
    let tools = root().join(".deps/pytools");
    assert!(tools.join("pytest").is_dir(), "pytest is missing: run scripts/pytools.sh (scripts/test.sh does)");
    let client = root().join("clients/python");
    let report = run_against_a_server(
        "python",
        Command::new("python3")
            .args(["-m", "pytest", "-q", "-p", "no:cacheprovider", "tests"])
            .env("PYTHONPATH", format!("{}:{}", client.display(), tools.display()))
            .env("PYTHONDONTWRITEBYTECODE", "1"),
    );
    assert!(report.contains("6 passed"), "pytest ran other than the client's 6 tests:\n{report}");
}

#[test]
fn the_javascript_client_passes_its_tests_against_a_real_server() {
    let report = run_against_a_server(
        "js",
        Command::new("node")
            .args(["--test", "test/"])
            .env("RELUME_WS_MODULE", root().join(".deps/nodetools/node_modules/ws")),
    );
    assert!(report.contains("# pass 4"), "node ran other than the client's 4 tests:\n{report}");
}
