//! The clients run their own tests against the release binary served on a free port: the
//! Python one (`clients/python`) with pytest, its packages from `.deps/pytools`
//! (scripts/pytools.sh, which scripts/test.sh runs); the JavaScript one (`clients/js`) with
//! Node's own test runner and, where Node has no WebSocket of its own, the `ws` package from
//! `.deps/nodetools` (scripts/nodetools.sh).
mod common;
use common::process::Served;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// Runs a client's test `command` in `clients/DIR` against a fresh server (its URL in
/// `RELUME_URL`), and returns what it printed; a failing run fails the test with its report.
fn run_against_a_server(dir: &str, command: &mut Command) -> String {
    let served = Served::start(&[]);
    let output = command
        .current_dir(root().join("clients").join(dir))
        .env("RELUME_URL", served.url(""))
        .output()
        .expect("the client's test runner starts (scripts/test.sh installs it)");
    let report = String::from_utf8_lossy(&output.stdout).to_string();
    println!("{report}{}", String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "the {dir} client's tests failed:\n{report}");
    served.terminate();
    report
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
    assert!(report.contains("5 passed"), "pytest ran other than the client's 5 tests:\n{report}");
}

#[test]
fn the_javascript_client_passes_its_tests_against_a_real_server() {
    let report = run_against_a_server(
        "js",
        Command::new("node")
            .args(["--test", "test/"])
            .env("RELUME_WS_MODULE", root().join(".deps/nodetools/node_modules/ws")),
    );
    assert!(report.contains("# pass 3"), "node ran other than the client's 3 tests:\n{report}");
}
