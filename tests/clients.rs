//! The clients run their own tests against the release binary served on a free port: the
//! Python one (`clients/python`) with pytest, its packages from `.deps/pytools`
//! (scripts/pytools.sh, which scripts/test.sh runs); the JavaScript one (`clients/js`) with
//! Node's own test runner, no packages.
mod common;
use common::process::Served;
use std::path::Path;
use std::process::Command;

#[test]
fn the_python_client_passes_its_tests_against_a_real_server() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tools = root.join(".deps/pytools");
    assert!(tools.join("pytest").is_dir(), "pytest is missing: run scripts/pytools.sh (scripts/test.sh does)");
    let served = Served::start(&[]);
    let client = root.join("clients/python");
    let output = Command::new("python3")
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider", "tests"])
        .current_dir(&client)
        .env("PYTHONPATH", format!("{}:{}", client.display(), tools.display()))
        .env("RELUME_URL", served.url(""))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("python3 runs");
    let report = String::from_utf8_lossy(&output.stdout);
    println!("{report}{}", String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "the Python client's tests failed:\n{report}");
    assert!(report.contains(" passed"), "pytest ran no tests:\n{report}");
    served.terminate();
}

#[test]
fn the_javascript_client_passes_its_tests_against_a_real_server() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let served = Served::start(&[]);
    let output = Command::new("node")
        .args(["--test", "test/"])
        .current_dir(root.join("clients/js"))
        .env("RELUME_URL", served.url(""))
        .env("RELUME_WS_MODULE", root.join(".deps/nodetools/node_modules/ws"))
        .output()
        .expect("node runs (scripts/test.sh installs it)");
    let report = String::from_utf8_lossy(&output.stdout);
    println!("{report}{}", String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "the JavaScript client's tests failed:\n{report}");
    assert!(report.contains("# pass 3"), "node ran other than the client's 3 tests:\n{report}");
    served.terminate();
}
