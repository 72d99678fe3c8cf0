//! Switching a live session's technique (`Session::set_technique`, `PATCH /v1/sessions/{id}`).
//!
//! A switch must be exactly what a client could otherwise do by hand: take a snapshot, change
//! its technique, and restore it. So the twin of a switched session is a session restored
//! from the switched one's progress with the new technique: after one tick both must show the
//! same image bit for bit and the same stats apart from timings. The pending edits cross the
//! switch (they are queued before it). The negative control switches without restarting the
//! film, which the comparison must catch.
mod common;
use common::*;
use relume::engine::{Frame, Session};
use relume::scene::edits::Edit;
use relume::scene::model::Trs;
use relume::scene::Scene;
use relume::technique::TechniqueConfig;
use serde_json::Value;

fn room() -> Scene {
    slab_room([0.0, 1.2, -3.5], [0.0, 0.9, 0.0], [0.3, 0.35, 0.6], [0.35, 0.35, 0.35], [0.0, 1.8, 0.2])
}

/// A 10 cm move of the slab, queued before the switch.
fn slide(scene: &Scene) -> Vec<Edit> {
    let t = scene.desc().objects[scene.object_index("slab").expect("slab")].transform;
    vec![Edit::Object {
        name: "slab".into(),
        transform: Trs { translation: [t.translation[0] + 0.1, t.translation[1], t.translation[2]], ..t },
    }]
}

/// The stats without timings, `restored` (only the twin reports it) and the edits received
/// since the last tick (a restore carries the queue, not how many edits were sent into it).
fn comparable(frame: &Frame) -> Value {
    fn strip(v: &mut Value) {
        if let Value::Object(map) = v {
            let dropped = ["times", "restored", "edits_received", "edits_coalesced"];
            map.retain(|k, _| !k.ends_with("_ms") && !dropped.contains(&k.as_str()));
            map.values_mut().for_each(strip);
        }
    }
    let mut v = serde_json::to_value(&frame.stats).expect("stats JSON");
    strip(&mut v);
    v
}

/// A `path` session ticks once, queues [`slide`] if `edits`, and switches to `to` (with
/// `switch`, so the negative control can replace it); its twin is restored from its progress
/// with `to`. Returns the tick after the switch of both, and what `switch` answered.
fn switched_and_twin(
    to: &TechniqueConfig,
    edits: bool,
    switch: impl Fn(&mut Session, &TechniqueConfig) -> bool + Sync,
) -> (Frame, Frame, bool) {
    let device = relume::embree::Device::new(2).expect("device");
    let pool = relume::engine::thread_pool(2).expect("pool");
    pool.install(|| {
        let from = TechniqueConfig::Path(path(1));
        let mut s = Session::new(room(), &from, 5, &device).expect("session");
        s.tick().expect("tick");
        if edits {
            s.queue_edits(slide(s.scene())).expect("valid edits");
        }
        let scene = Scene::from_desc(s.scene().desc().clone(), &scenes_dir(), &scenes_dir()).expect("scene");
        let mut twin = Session::new(scene, to, 5, &device).expect("twin");
        twin.resume(s.progress()).expect("resume");
        let changed = switch(&mut s, to);
        (s.tick().expect("tick"), twin.tick().expect("tick"), changed)
    })
}

fn same_as_twin(after: &Frame, twin: &Frame) -> Result<(), String> {
    if after.image != twin.image {
        return Err("the image differs from the restored twin's".into());
    }
    if comparable(after) != comparable(twin) {
        return Err(format!("stats differ from the twin's:\n{}\n{}", comparable(after), comparable(twin)));
    }
    Ok(())
}

#[test]
fn a_switch_is_a_restore_with_the_new_technique_for_every_technique() {
    let configs: Vec<TechniqueConfig> =
        small_techniques().into_iter().chain([TechniqueConfig::Path(path(2))]).collect();
    for (to, edits) in configs.iter().flat_map(|c| [(c, false), (c, true)]) {
        let (after, twin, changed) = switched_and_twin(to, edits, |s, c| s.set_technique(c).expect("switch"));
        assert!(changed, "{}", to.id());
        assert_eq!(after.stats.technique, to.id());
        assert_eq!(after.stats.moved_surfaces, usize::from(edits), "{}: the queued edit crossed the switch", to.id());
        if let Err(e) = same_as_twin(&after, &twin) {
            panic!("{} (edits: {edits}): {e}", to.id());
        }
    }
    // Negative control: a session that did not switch (it keeps `path` at 1 spp and its film)
    // fails the comparison. Run by hand: a switch that does not restart the film fails it too.
    let (after, twin, _) = switched_and_twin(&TechniqueConfig::Path(path(2)), false, |_, _| true);
    assert!(same_as_twin(&after, &twin).is_err(), "a session that kept its technique passed for a switch");
}

#[test]
fn switching_to_the_running_configuration_changes_nothing() {
    let device = relume::embree::Device::new(2).expect("device");
    let pool = relume::engine::thread_pool(2).expect("pool");
    pool.install(|| {
        for config in small_techniques() {
            let mut s = Session::new(room(), &config, 3, &device).expect("session");
            let mut twin = Session::new(room(), &config, 3, &device).expect("twin");
            let first = s.tick().expect("tick");
            twin.tick().expect("tick");
            assert!(!s.set_technique(&config).expect("switch"), "{}", config.id());
            let (after, twin_after) = (s.tick().expect("tick"), twin.tick().expect("tick"));
            assert_eq!(after.accumulation_id, first.accumulation_id, "{}: the film restarted", config.id());
            assert!(after.image == twin_after.image, "{}: the image differs from the twin's", config.id());
        }
    })
}
