//! The golden wire messages in proto/examples/ round-trip through the protocol types: parsing
//! then serialising gives back the same JSON, so the documents and the code cannot drift.
use relume::server::protocol::*;
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::Value;
use std::path::Path;

fn round_trip<T: DeserializeOwned + Serialize>(file: &str) -> usize {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/examples").join(file);
    let original: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let parsed: T = serde_json::from_value(original.clone()).unwrap_or_else(|e| panic!("{file}: {e}"));
    // Through text, as on the wire (f32 fields print as their shortest f32 form).
    let back: Value = serde_json::from_str(&serde_json::to_string(&parsed).unwrap()).unwrap();
    assert_eq!(back, original, "{file} does not round-trip");
    1
}

#[test]
fn every_golden_example_round_trips() {
    let mut n = 0;
    n += round_trip::<CreateSession>("create-session.request.json");
    n += round_trip::<SessionView>("create-session.response.json");
    n += round_trip::<UpdateSession>("update-session.request.json");
    n += round_trip::<EditBatch>("edits.request.json");
    n += round_trip::<EditsAccepted>("edits.response.json");
    n += round_trip::<TickDone>("tick.response.json");
    n += round_trip::<StatsHistory>("stats.response.json");
    n += round_trip::<SceneList>("scenes.response.json");
    n += round_trip::<ErrorBody>("error.response.json");
    for f in [
        "ws-client-edits.json",
        "ws-client-tick.json",
        "ws-client-subscribe.json",
        "ws-client-play.json",
        "ws-client-pause.json",
        "ws-client-update.json",
    ] {
        n += round_trip::<ClientMessage>(f);
    }
    for f in ["ws-server-stats.json", "ws-server-edits-accepted.json", "ws-server-error.json", "ws-server-updated.json"]
    {
        n += round_trip::<ServerMessage>(f);
    }
    let on_disk = std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/examples")).unwrap().count();
    assert_eq!(n, on_disk, "an example file is not covered by this test");
}

#[test]
fn a_changed_example_fails_the_round_trip() {
    // The check can fail: an unknown field is rejected, and a wrong type is too.
    let bad: Result<CreateSession, _> = serde_json::from_value(serde_json::json!({"scene": "x", "colour": 1}));
    assert!(bad.is_err());
    let bad: Result<ClientMessage, _> =
        serde_json::from_value(serde_json::json!({"type": "subscribe", "every": "often"}));
    assert!(bad.is_err());
}
