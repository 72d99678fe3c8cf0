//! The Python client (`clients/python`) runs its own tests, with pytest, against the release
//! binary served on a free port. Its packages come from `.deps/pytools` (scripts/pytools.sh,
//! which scripts/test.sh runs).
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
