//! proto/openapi.yaml and the router agree: every documented (method, path) is served (not the
//! fallback, not 405), every other method on a documented path is refused with 405, and the
//! spec's referenced examples exist; a running server serves the spec and every file it references.
mod common;
use common::server::TestServer;
use relume::server::Limits;
use serde_yaml_ng::Value;
use std::collections::BTreeSet;
use std::path::Path;

const METHODS: [&str; 5] = ["get", "post", "put", "delete", "patch"];

fn spec() -> Value {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/openapi.yaml")).unwrap();
    serde_yaml_ng::from_str(&text).expect("openapi.yaml parses")
}

fn documented() -> BTreeSet<(String, String)> {
    let spec = spec();
    assert_eq!(spec["openapi"].as_str(), Some("3.1.0"));
    let mut out = BTreeSet::new();
    for (path, item) in spec["paths"].as_mapping().unwrap() {
        for m in METHODS {
            if item.get(m).is_some() {
                out.insert((m.to_string(), path.as_str().unwrap().to_string()));
            }
        }
    }
    out
}

#[test]
fn spec_examples_exist() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/openapi.yaml")).unwrap();
    let mut n = 0;
    for part in text.split("\"examples/").skip(1) {
        let file: String = part.chars().take_while(|c| *c != '"').collect();
        assert!(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/examples").join(&file).is_file(),
            "missing example {file}"
        );
        n += 1;
    }
    assert!(n >= 5);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn routes_match_the_spec() {
    let s = TestServer::start(None, Limits::default()).await;
    let id = s.session(serde_json::json!({"scene": "cornell-box", "width": 8, "height": 8})).await;
    s.http.post(s.url(&format!("/v1/sessions/{id}/tick"))).send().await.unwrap();
    let routes = documented();
    assert!(routes.len() >= 13, "{routes:?}");
    let paths: BTreeSet<&String> = routes.iter().map(|(_, p)| p).collect();
    for path in paths {
        let file = if path.starts_with("/api/examples/") { "tick.response.json" } else { "openapi.yaml" };
        let concrete = path.replace("{id}", &id).replace("{file}", file);
        for m in METHODS {
            let method = reqwest::Method::from_bytes(m.to_uppercase().as_bytes()).unwrap();
            let mut req = s.http.request(method, s.url(&concrete));
            if m == "patch" {
                req = req.header("content-type", "application/json").body(r#"{"technique":{"id":"path"}}"#);
            }
            if m == "post" {
                req = req.header("content-type", "application/json").body(if path.ends_with("/sessions") {
                    r#"{"scene":"cornell-box","width":8,"height":8}"#
                } else {
                    r#"{"edits":[]}"#
                });
            }
            if path.ends_with("/ws") {
                // A plain GET without upgrade headers is refused by the upgrade extractor, not the router.
                let r = req.send().await.unwrap();
                if m == "get" {
                    assert_ne!(r.status(), 404, "GET {path} not routed");
                    assert_ne!(r.status(), 405);
                } else {
                    assert_eq!(r.status(), 405, "{m} {path} is served but not documented");
                }
                continue;
            }
            if m == "delete" && routes.contains(&(m.to_string(), path.clone())) {
                continue; // Checked last, so the session survives the other probes.
            }
            let r = req.send().await.unwrap();
            let status = r.status().as_u16();
            // A stream's body lasts as long as its session: its status and headers are the answer.
            let endless = status == 200 && path.ends_with("/stream.mjpeg");
            let body = if endless { String::new() } else { r.text().await.unwrap_or_default() };
            if routes.contains(&(m.to_string(), path.clone())) {
                assert!(
                    status != 405 && !body.contains("no such route"),
                    "{m} {path} is documented but not served ({status}: {body})"
                );
                let documented = &spec()["paths"][path.as_str()][m]["responses"];
                assert!(
                    documented.get(status.to_string()).is_some(),
                    "{m} {path} answered {status}, which the spec does not document ({body})"
                );
            } else {
                assert!(
                    status == 405 || (status == 404 && body.contains("no such route")),
                    "{m} {path} is served ({status}) but not documented"
                );
            }
        }
    }
    let r = s.http.delete(s.url(&format!("/v1/sessions/{id}"))).send().await.unwrap();
    assert_eq!(r.status(), 204);
    s.shutdown().await.unwrap();
}

#[test]
fn every_technique_configuration_is_documented() {
    // Property: the spec's TechniqueConfig accepts each technique's defaults as the server
    // serialises them, and refuses an unknown id: a new technique cannot land undocumented.
    let spec: serde_json::Value = serde_json::to_value(spec()).unwrap();
    let schema = &spec["components"]["schemas"]["TechniqueConfig"];
    let validator = jsonschema::validator_for(schema).expect("TechniqueConfig is a valid schema");
    for id in relume::technique::TECHNIQUE_IDS {
        let config = relume::technique::TechniqueConfig::from_spec(id).unwrap();
        let value = serde_json::to_value(&config).unwrap();
        let errors: Vec<String> = validator.iter_errors(&value).map(|e| e.to_string()).collect();
        assert!(errors.is_empty(), "{id}: {value} against the spec: {errors:?}");
    }
    assert!(!validator.is_valid(&serde_json::json!({"id": "warp"})));
}

/// Every operation: (path, method, operation).
fn operations(spec: &Value) -> Vec<(String, String, Value)> {
    let mut out = Vec::new();
    for (path, item) in spec["paths"].as_mapping().unwrap() {
        for m in METHODS {
            if let Some(op) = item.get(m) {
                out.push((path.as_str().unwrap().to_string(), m.to_string(), op.clone()));
            }
        }
    }
    out
}

#[test]
fn every_operation_has_an_id_and_documents_what_every_route_can_answer() {
    // A client generator or fuzzer needs operationIds, and every status the server can send:
    // every /v1 route passes the token check (401), the request timeout (408), the Host check
    // (421) and the connection limit (503), and can fail inside (500); a session route can
    // find no session (404); a route with a body checks its size (413) and content (422), and
    // a JSON body its type (415).
    let spec = spec();
    let mut ids = BTreeSet::new();
    for (path, m, op) in operations(&spec) {
        let id = op["operationId"].as_str().unwrap_or_else(|| panic!("{m} {path} has no operationId"));
        assert!(ids.insert(id.to_string()), "operationId {id} is used twice");
        if !path.starts_with("/v1/") {
            continue;
        }
        let mut needed = vec!["401", "408", "421", "500", "503"];
        if path.contains("{id}") {
            needed.push("404");
        }
        if let Some(body) = op.get("requestBody") {
            needed.extend(["413", "422"]);
            // A JSON body is refused under another type; an upload takes its bytes as sent.
            if body["content"].get("application/json").is_some() {
                needed.push("415");
            }
        }
        for status in needed {
            assert!(op["responses"].get(status).is_some(), "{m} {path} does not document {status}");
        }
    }
}

#[test]
fn session_creation_links_to_every_operation_on_a_session() {
    // A stateful API fuzzer follows links: without them it never learns a session id and
    // every session operation only ever answers it 404.
    let spec = spec();
    let links = spec["paths"]["/v1/sessions"]["post"]["responses"]["201"]["links"].as_mapping().expect("links");
    let linked: BTreeSet<String> =
        links.values().map(|l| l["operationId"].as_str().expect("operationId").to_string()).collect();
    for link in links.values() {
        assert_eq!(link["parameters"]["id"].as_str(), Some("$response.body#/id"), "{link:?}");
    }
    for (path, m, op) in operations(&spec) {
        if path.contains("{id}") {
            let id = op["operationId"].as_str().unwrap_or_default();
            assert!(linked.contains(id), "{m} {path} ({id}) is not linked from session creation");
        }
    }
    let ids: BTreeSet<String> =
        operations(&spec).iter().filter_map(|(_, _, op)| op["operationId"].as_str().map(str::to_string)).collect();
    assert!(linked.is_subset(&ids), "a link names an operation that does not exist");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_registry_the_spec_and_get_techniques_agree() {
    // Every registry parameter is a field of its technique's schema, its range lies inside the
    // schema's and holds the default, and its choices are the schema's enum; the served list
    // validates against the spec. Negative control: a parameter the schema lacks is caught.
    let spec: serde_json::Value = serde_json::to_value(spec()).unwrap();
    let variants = spec["components"]["schemas"]["TechniqueConfig"]["oneOf"].as_array().unwrap().clone();
    let schema_of = |id: &str| {
        variants
            .iter()
            .find(|v| v["properties"]["id"]["const"] == id)
            .unwrap_or_else(|| panic!("{id}: no schema"))
            .clone()
    };
    let check = |id: &str, p: &relume::technique::registry::Parameter| -> Result<(), String> {
        use relume::technique::registry::ParameterKind;
        let field = &schema_of(id)["properties"][p.name];
        if field.is_null() {
            return Err(format!("{id}.{}: not in the schema", p.name));
        }
        let default =
            serde_json::to_value(relume::technique::registry::default_config(id).unwrap()).unwrap()[p.name].clone();
        match p.kind {
            ParameterKind::Integer { min, max } => {
                let (lo, hi) = (field["minimum"].as_u64().unwrap_or(0), field["maximum"].as_u64().unwrap_or(u64::MAX));
                // A null default (chosen from the scene) must be allowed by the schema.
                let nullable = field["type"].as_array().is_some_and(|t| t.iter().any(|x| x == "null"));
                let d = match default.as_u64() {
                    Some(d) => d,
                    None if default.is_null() && nullable => min,
                    None => return Err(format!("{id}.{}: default {default} is not an integer", p.name)),
                };
                if min < lo || max > hi || !(min..=max).contains(&d) {
                    return Err(format!("{id}.{}: [{min}, {max}] vs schema [{lo}, {hi}], default {d}", p.name));
                }
            }
            ParameterKind::Number { min, max } => {
                let (lo, hi) =
                    (field["minimum"].as_f64().unwrap_or(f64::MIN), field["maximum"].as_f64().unwrap_or(f64::MAX));
                let d = default.as_f64().ok_or(format!("{id}.{}: default is not a number", p.name))?;
                if min < lo || max > hi || !(min..=max).contains(&d) {
                    return Err(format!("{id}.{}: [{min}, {max}] vs schema [{lo}, {hi}], default {d}", p.name));
                }
            }
            ParameterKind::Choice { choices } => {
                let enumed: Vec<&str> =
                    field["enum"].as_array().map(|a| a.iter().filter_map(|v| v.as_str()).collect()).unwrap_or_default();
                if enumed != choices {
                    return Err(format!("{id}.{}: {choices:?} vs schema {enumed:?}", p.name));
                }
            }
            ParameterKind::Boolean => {
                if field["type"] != "boolean" {
                    return Err(format!("{id}.{}: not a boolean in the schema", p.name));
                }
            }
        }
        Ok(())
    };
    for d in relume::technique::registry::REGISTRY {
        for p in d.parameters {
            check(d.id, p).unwrap();
        }
    }
    let bogus = relume::technique::registry::Parameter {
        name: "warp_factor",
        kind: relume::technique::registry::ParameterKind::Boolean,
        help: "",
    };
    assert!(check("path", &bogus).is_err(), "a parameter missing from the schema went unseen");
    let s = TestServer::start(None, Limits::default()).await;
    let list: serde_json::Value = s.http.get(s.url("/v1/techniques")).send().await.unwrap().json().await.unwrap();
    let mut root = spec.clone();
    root["$ref"] = serde_json::json!("#/components/schemas/TechniqueList");
    let validator = jsonschema::validator_for(&root).expect("TechniqueList schema");
    let errors: Vec<String> = validator.iter_errors(&list).map(|e| e.to_string()).collect();
    assert!(errors.is_empty(), "{errors:?}");
    let ids: Vec<&str> = list["techniques"].as_array().unwrap().iter().map(|t| t["id"].as_str().unwrap()).collect();
    assert_eq!(ids, relume::technique::TECHNIQUE_IDS);
    s.shutdown().await.unwrap();
}

/// Every file under `proto/`, as its path relative to it (`examples/…` for the examples).
fn proto_files() -> BTreeSet<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("proto");
    let mut out = BTreeSet::new();
    let mut dirs = vec![root.clone()];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else {
                out.insert(path.strip_prefix(&root).unwrap().to_string_lossy().replace('\\', "/"));
            }
        }
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_serves_the_spec_and_every_file_it_references() {
    // Property: GET /api/<file> answers every file under proto/ byte for byte, with its media
    // type, without a token on a server that has one (it is documentation, like the viewer);
    // a name outside proto/ is a JSON 404 naming it, and never reaches the file system.
    // Negative control, by hand: leaving one example out of `api_docs::FILES` fails the first
    // loop; a new file under proto/ that the table lacks fails it too.
    let files = proto_files();
    assert!(files.len() >= 10 && files.contains("openapi.yaml"), "{files:?}");
    let s = TestServer::start(Some("secret"), Limits::default()).await;
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("proto");
    for file in &files {
        let r = s.http.get(s.url(&format!("/api/{file}"))).send().await.unwrap();
        assert_eq!(r.status(), 200, "/api/{file}");
        let kind = r.headers()["content-type"].to_str().unwrap().to_string();
        let want = if file.ends_with(".yaml") { "application/yaml" } else { "application/json" };
        assert_eq!(kind, want, "/api/{file}");
        let body = r.bytes().await.unwrap();
        assert!(body == std::fs::read(root.join(file)).unwrap(), "/api/{file} differs from proto/{file}");
    }
    for bad in ["nothing.json", "examples/nothing.json", "..%2FCargo.toml", "examples/..%2F..%2FCargo.toml"] {
        let r = s.http.get(s.url(&format!("/api/{bad}"))).send().await.unwrap();
        assert_eq!(r.status(), 404, "/api/{bad}");
        let body: serde_json::Value = r.json().await.unwrap();
        assert_eq!(body["error"], "not_found", "/api/{bad}: {body}");
        assert!(body["detail"].as_str().unwrap().starts_with("file: "), "/api/{bad}: {body}");
    }
    s.shutdown().await.unwrap();
}
