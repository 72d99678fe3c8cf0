//! The deployment files against what they deploy.
//!
//! The Dockerfile against the setup scripts: it builds on Debian trixie with Debian's Embree 4,
//! installs the package list scripts/setup.sh installs, and runs only scripts that exist.
//!
//! deploy/kubernetes/ against the Kubernetes API schemas (kubernetes-validate, installed into
//! .deps/pytools by scripts/test.sh, offline), with a negative control, and against the rest of
//! the repository: the proxy's ConfigMap carries deploy/haproxy/ unchanged, it names one node
//! per StatefulSet replica, and every flag the pods pass exists in the binary.
use serde_yaml_ng::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn manifests() -> Vec<PathBuf> {
    ["relume.yaml", "haproxy.yaml"].iter().map(|f| root().join("deploy/kubernetes").join(f)).collect()
}

/// Runs kubernetes-validate --strict on `files` for Kubernetes `version`: (passed, output).
fn validate(files: &[PathBuf], version: &str) -> (bool, String) {
    let tools = root().join(".deps/pytools");
    assert!(
        tools.join("kubernetes_validate").is_dir(),
        "kubernetes-validate is missing: run scripts/pytools.sh (scripts/test.sh does)"
    );
    let out = Command::new("python3")
        .args(["-m", "kubernetes_validate", "--strict", "-k", version])
        .args(files)
        .env("PYTHONPATH", tools)
        .output()
        .expect("python3 runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.success(), text)
}

/// Every document of a manifest file.
fn documents(path: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(path).unwrap();
    serde_yaml_ng::Deserializer::from_str(&text).map(|d| serde::Deserialize::deserialize(d).unwrap()).collect()
}

fn find<'a>(docs: &'a [Value], kind: &str, name: &str) -> &'a Value {
    docs.iter()
        .find(|d| d["kind"].as_str() == Some(kind) && d["metadata"]["name"].as_str() == Some(name))
        .unwrap_or_else(|| panic!("no {kind} {name}"))
}

#[test]
fn the_manifests_validate_against_the_kubernetes_schemas() {
    for version in ["1.30.0", "1.37.0"] {
        let (ok, out) = validate(&manifests(), version);
        assert!(ok, "Kubernetes {version}:\n{out}");
        assert_eq!(out.matches("passed").count(), 7, "every resource is checked:\n{out}");
    }
    // Negative control: a misspelt field and a wrong type must fail the same check.
    let text = std::fs::read_to_string(&manifests()[0]).unwrap();
    for (from, to) in [("readinessProbe:", "readinesProbe:"), ("replicas: 3", "replicas: three")] {
        assert!(text.contains(from));
        let broken = std::env::temp_dir().join(format!("relume-broken-{}.yaml", std::process::id()));
        std::fs::write(&broken, text.replacen(from, to, 1)).unwrap();
        let (ok, out) = validate(std::slice::from_ref(&broken), "1.30.0");
        std::fs::remove_file(&broken).unwrap();
        assert!(!ok, "a manifest with {to} passed:\n{out}");
    }
}

#[test]
fn the_manifests_agree_with_the_proxy_config_and_the_binary() {
    let relume = documents(&manifests()[0]);
    let proxy = documents(&manifests()[1]);
    // The proxy's ConfigMap is deploy/haproxy/, byte for byte.
    let config = find(&proxy, "ConfigMap", "relume-haproxy");
    for file in ["relume.cfg", "nodes.map"] {
        let repo = std::fs::read_to_string(root().join("deploy/haproxy").join(file)).unwrap();
        assert_eq!(
            config["data"][file].as_str(),
            Some(repo.as_str()),
            "the ConfigMap's {file} differs from deploy/haproxy/{file}"
        );
    }
    // One node address per replica, named as the StatefulSet names its pods.
    let set = find(&relume, "StatefulSet", "relume");
    let replicas = set["spec"]["replicas"].as_u64().unwrap();
    let service = set["spec"]["serviceName"].as_str().unwrap();
    let env = &find(&proxy, "Deployment", "relume-proxy")["spec"]["template"]["spec"]["containers"][0]["env"];
    for i in 0..replicas {
        let var = env.as_sequence().unwrap().iter().find(|e| e["name"].as_str() == Some(&format!("RELUME_NODE_{i}")));
        assert_eq!(var.and_then(|v| v["value"].as_str()), Some(format!("relume-{i}.{service}:8080").as_str()));
        let map = std::fs::read_to_string(root().join("deploy/haproxy/nodes.map")).unwrap();
        assert!(map.lines().any(|l| l.starts_with(&format!("relume-{i} "))), "nodes.map lacks relume-{i}");
    }
    // Every flag the pods pass is one relume serve takes.
    let help = Command::new(env!("CARGO_BIN_EXE_relume")).args(["serve", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    let args = set["spec"]["template"]["spec"]["containers"][0]["args"].as_sequence().unwrap();
    for arg in args.iter().filter_map(Value::as_str).filter(|a| a.starts_with("--")) {
        let flag = arg.split('=').next().unwrap();
        assert!(
            help.contains(&format!("{flag} ")) || help.contains(&format!("{flag} <")),
            "relume serve has no {flag}"
        );
    }
}

/// What is wrong with a Dockerfile's text, against scripts/packages.txt: empty when nothing is.
fn dockerfile_problems(docker: &str) -> Vec<String> {
    let mut problems = Vec::new();
    for from in docker.lines().filter(|l| l.starts_with("FROM ")) {
        if !from.contains("trixie") {
            problems.push(format!("`{from}` is not Debian trixie, whose libembree-dev is Embree 4"));
        }
    }
    for needed in [
        "COPY scripts/packages.txt scripts/packages.txt",
        "grep -v '^\\s*#' scripts/packages.txt",
        "--no-install-recommends libembree-dev",
        "--no-install-recommends libembree4-4",
    ] {
        if !docker.contains(needed) {
            problems.push(format!("the Dockerfile lacks `{needed}`"));
        }
    }
    for script in docker.split_whitespace().filter(|w| w.starts_with("scripts/") && w.ends_with(".sh")) {
        if !root().join(script).exists() {
            problems.push(format!("the Dockerfile runs {script}, which does not exist"));
        }
    }
    let packages = std::fs::read_to_string(root().join("scripts/packages.txt")).unwrap();
    if packages.lines().any(|l| l.trim().starts_with("libembree")) {
        problems.push("scripts/packages.txt installs a libembree: on bookworm that is Embree 3".into());
    }
    problems
}

#[test]
fn the_dockerfile_builds_on_trixie_with_debians_embree_4_and_the_scripts_package_list() {
    let docker = std::fs::read_to_string(root().join("Dockerfile")).unwrap();
    assert_eq!(dockerfile_problems(&docker), Vec::<String>::new());
    // Negative controls: each broken variant is caught.
    for (from, to) in [
        ("rust:1-trixie", "rust:1-bookworm"),
        ("debian:trixie-slim", "debian:bookworm-slim"),
        (" libembree-dev ", " "),
        ("libembree4-4", "libembree3-3"),
        ("scripts/oidn.sh", "scripts/oidn-gone.sh"),
        ("COPY scripts/packages.txt", "COPY scripts/other.txt"),
    ] {
        assert!(docker.contains(from), "the control's `{from}` is not in the Dockerfile");
        let broken = docker.replace(from, to);
        assert!(!dockerfile_problems(&broken).is_empty(), "a Dockerfile with `{to}` for `{from}` passed");
    }
}

/// The lines of `text` that point outside the repository: at the developers' shared folder, its
/// papers or its architecture page. A clone has none of them, so the repository carries its own
/// map (docs/architecture.md) and cites papers in full.
fn outside_references(text: &str) -> Vec<&str> {
    let outside = outside_names();
    text.lines().filter(|line| outside.iter().any(|o| line.contains(o.as_str()))).collect()
}

/// The names a reference outside the repository uses, built from parts so that this file,
/// which holds them, is not itself such a reference.
fn outside_names() -> [String; 3] {
    let shared = ["sha", "red"].concat();
    [format!("../{shared}"), format!("{shared}/papers"), ["ARCHITECTURE", ".md"].concat()]
}

#[test]
fn no_file_in_the_repository_points_outside_it() {
    let listed = Command::new("git").args(["ls-files", "-z"]).current_dir(root()).output().unwrap();
    assert!(listed.status.success(), "git ls-files failed");
    let files: Vec<String> =
        String::from_utf8_lossy(&listed.stdout).split('\0').filter(|f| !f.is_empty()).map(str::to_string).collect();
    assert!(files.len() > 100, "only {} files listed", files.len());
    let mut found = Vec::new();
    for file in &files {
        let Ok(text) = std::fs::read_to_string(root().join(file)) else { continue };
        found.extend(outside_references(&text).into_iter().map(|line| format!("{file}: {}", line.trim())));
    }
    assert!(found.is_empty(), "files point outside the repository:\n{}", found.join("\n"));
    // Negative control: each kind of outside reference is caught.
    let [up, papers, map] = outside_names();
    for line in [format!("see {up}/{map}"), format!("(`{papers}/x.md`)"), format!("{map}, tick step 7")] {
        assert_eq!(outside_references(&line), vec![line.as_str()], "{line} was not caught");
    }
}
