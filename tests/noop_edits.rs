//! An edit that changes nothing is not a change, for every technique.
//!
//! Clients and the animation player re-send current values (every track, every frame). Such a
//! tick must be exactly the tick of a twin session that received no edits at all: the same
//! accumulation (the film keeps adding samples), the same image bit for bit, and the same stats
//! apart from timings, so no technique verified, invalidated or retraced anything. The negative
//! control sends a real (1 mm) move through the same comparison, which must fail it.
mod common;
use common::*;
use relume::engine::{Frame, Session};
use relume::scene::animation::Animation;
use relume::scene::edits::Edit;
use relume::scene::model::Trs;
use relume::scene::Scene;
use relume::technique::TechniqueConfig;

fn room() -> Scene {
    slab_room([0.0, 1.2, -3.5], [0.0, 0.9, 0.0], [0.3, 0.35, 0.6], [0.35, 0.35, 0.35], [0.0, 1.8, 0.2])
}

/// Every edit a client could send that leaves the scene as it is: the slab's and the lamp's
/// transforms (the slab's with the negated quaternion of the same rotation), the lamp's
/// emitter, the camera, and each material.
fn noop_edits(scene: &Scene) -> Vec<Edit> {
    let desc = scene.desc();
    let slab = &desc.objects[scene.object_index("slab").expect("slab")];
    let lamp = &desc.lights[scene.light_index("lamp").expect("lamp")];
    let negated = Trs { rotation: slab.transform.rotation.map(|q| -q), ..slab.transform };
    let mut edits = vec![
        Edit::Object { name: "slab".into(), transform: slab.transform },
        Edit::Object { name: "slab".into(), transform: negated },
        Edit::Light { name: "lamp".into(), transform: Some(lamp.transform), emitter: Some(lamp.emitter.clone()) },
        Edit::Camera {
            position: Some(desc.camera.position),
            look_at: Some(desc.camera.look_at),
            up: Some(desc.camera.up),
            vfov_deg: Some(desc.camera.vfov_deg),
        },
    ];
    for (name, m) in scene.material_names.iter().zip(&scene.materials) {
        edits.push(Edit::Material { name: name.clone(), material: m.clone() });
    }
    edits
}

/// A 1 mm move of the slab: a real change.
fn nudge(scene: &Scene) -> Vec<Edit> {
    let t = scene.desc().objects[scene.object_index("slab").expect("slab")].transform;
    vec![Edit::Object {
        name: "slab".into(),
        transform: Trs { translation: [t.translation[0] + 1e-3, t.translation[1], t.translation[2]], ..t },
    }]
}

/// Stats that may differ between twins: timings and the edit counts.
fn ignored(key: &str) -> bool {
    key.ends_with("_ms") || key == "times" || key.starts_with("edits_")
}

/// Ticks a session and its twin once, then sends `edits` to the session alone and ticks both
/// again. Returns (the session's first frame, its second frame, the twin's second frame).
fn twin_ticks(config: &TechniqueConfig, edits: impl Fn(&Scene) -> Vec<Edit> + Sync) -> (Frame, Frame, Frame) {
    let device = relume::embree::Device::new(2).expect("device");
    let pool = relume::engine::thread_pool(2).expect("pool");
    pool.install(|| {
        let mut s = Session::new(room(), config, 9, &device).expect("session");
        let mut twin = Session::new(room(), config, 9, &device).expect("twin");
        let first = s.tick().expect("tick");
        twin.tick().expect("tick");
        let batch = edits(s.scene());
        s.queue_edits(batch).expect("valid edits");
        (first, s.tick().expect("tick"), twin.tick().expect("tick"))
    })
}

/// The assertion the test and its negative control share.
fn same_as_twin(first: &Frame, after: &Frame, twin: &Frame) -> Result<(), String> {
    if after.accumulation_id != first.accumulation_id {
        return Err(format!("the film was reset ({} -> {})", first.accumulation_id, after.accumulation_id));
    }
    if after.spp <= first.spp {
        return Err(format!("no samples were added ({} -> {} spp)", first.spp, after.spp));
    }
    same_as_twin_frame(after, twin, ignored)
}

#[test]
fn a_tick_of_no_op_edits_is_the_tick_of_a_twin_without_edits() {
    for config in small_techniques() {
        let (first, after, twin) = twin_ticks(&config, noop_edits);
        let sent = noop_edits(&room()).len();
        // The two slab edits coalesce into one; every kept edit is unchanged.
        assert_eq!((after.stats.edits_received, after.stats.edits_coalesced), (sent, 1), "{}", config.id());
        assert_eq!(after.stats.edits_unchanged, sent - 1, "{}", config.id());
        assert_eq!(after.stats.moved_surfaces, 0, "{}", config.id());
        if let Err(e) = same_as_twin(&first, &after, &twin) {
            panic!("{}: {e}", config.id());
        }
        // Negative control: a real move fails the same comparison.
        let (first, after, twin) = twin_ticks(&config, nudge);
        assert_eq!(after.stats.edits_unchanged, 0);
        assert!(same_as_twin(&first, &after, &twin).is_err(), "{}: a 1 mm move went unnoticed", config.id());
    }
}

/// Plays 41 frames (2 s at 20 fps) of `anim` in a fresh session, as the player does.
fn play(
    pool: &rayon::ThreadPool,
    device: &relume::embree::Device,
    anim: &Animation,
    config: &TechniqueConfig,
) -> Vec<Frame> {
    pool.install(|| {
        let mut s = Session::new(room(), config, 4, device).expect("session");
        (0..=40)
            .map(|i| {
                s.queue_edits(anim.edits_at(i as f32 * 0.05)).expect("edits");
                s.tick().expect("tick")
            })
            .collect()
    })
}

#[test]
fn an_animation_hold_accumulates_and_converges() {
    // Property: the player re-sends every track every frame; while the keys hold still the
    // edits change nothing, so the film accumulates (one accumulation, growing spp) and the
    // error against a converged reference falls as 1/spp. The slab moves from t = 0 to 0.5 s,
    // then holds until 2 s.
    let key = |time: f32, x: f32| serde_json::json!({"time": time, "transform": {"translation": [x, 0.35, 0.5], "scale": [0.35, 0.35, 0.35]}});
    let lamp = serde_json::json!({"time": 0.0, "transform": {"translation": [0.0, 1.8, 0.2]}});
    let anim: Animation = serde_json::from_value(serde_json::json!({
        "duration": 2.0,
        "tracks": [
            {"target": "object", "name": "slab", "keyframes": [key(0.0, 0.3), key(0.5, -0.4), key(2.0, -0.4)]},
            {"target": "light", "name": "lamp", "keyframes": [lamp]}
        ]
    }))
    .expect("animation JSON");
    anim.validate(&room()).expect("valid animation");
    let device = relume::embree::Device::new(2).expect("device");
    let pool = relume::engine::thread_pool(2).expect("pool");
    for config in small_techniques() {
        let frames = play(&pool, &device, &anim, &config);
        // From frame 10 (t = 0.5 s) on, the pose holds: one accumulation, spp growing each tick.
        let hold = &frames[10..];
        assert!(
            hold.iter().all(|f| f.accumulation_id == hold[0].accumulation_id),
            "{}: the hold reset the film",
            config.id()
        );
        assert!(hold.windows(2).all(|w| w[1].spp > w[0].spp), "{}: the hold added no samples", config.id());
        assert!(hold[1..].iter().all(|f| f.stats.edits_unchanged == f.stats.edits_received), "{}", config.id());
        assert!(frames[9].accumulation_id != frames[10].accumulation_id, "{}: the move itself was missed", config.id());
    }
    // Convergence during the hold, for the reference tracer: 30 ticks of accumulation against
    // 1 tick, relMSE against a 1024-spp reference must fall by well over half (expected 1/30).
    let held = slab_room([0.0, 1.2, -3.5], [0.0, 0.9, 0.0], [-0.4, 0.35, 0.5], [0.35, 0.35, 0.35], [0.0, 1.8, 0.2]);
    let reference = render(held, TechniqueConfig::Path(path(1024)), 77, 1, 2).image;
    let c = TechniqueConfig::Path(path(4));
    let frames = play(&pool, &device, &anim, &c);
    let (early, late) = (rel_mse(&frames[10].image, &reference), rel_mse(&frames[40].image, &reference));
    eprintln!("hold: relMSE after 1 tick {early:.4}, after 31 ticks {late:.4}");
    assert!(late < 0.5 * early, "the hold did not converge: {early} -> {late}");
}

/// A tick that leaves the film as it was resolves nothing: an `instant_cache` view at rest
/// (refinement done, no pass added) shares the last tick's image, with `resolve_reused`. Every
/// frame equals a fresh resolve of the film after its tick, so a shared image is never stale;
/// the ticks that add a pass, and the tick after a move, resolve. Control: `path` adds a pass
/// every tick and resolves every tick.
#[test]
fn a_tick_that_leaves_the_film_as_it_was_resolves_nothing() {
    let device = relume::embree::Device::new(2).expect("device");
    let pool = relume::engine::thread_pool(2).expect("pool");
    pool.install(|| {
        let run = |spec: &str| -> Vec<(Frame, relume::film::LinearImage)> {
            let config = TechniqueConfig::from_spec(spec).expect("spec");
            let mut session = Session::new(room(), &config, 1, &device).expect("session");
            let mut frames = Vec::new();
            for k in 0..6 {
                if k == 5 {
                    session.queue_edits(nudge(session.scene())).expect("valid edit");
                }
                let frame = session.tick().expect("tick");
                frames.push((frame, session.film().resolve()));
            }
            frames
        };
        let resting = run("instant_cache:temporal:refine_ticks=2");
        let reused: Vec<bool> = resting.iter().map(|(f, _)| f.stats.resolve_reused).collect();
        assert_eq!(reused, [false, false, false, true, true, false], "ticks 3 and 4 rest");
        for (frame, fresh) in &resting {
            assert!(*frame.image == *fresh, "tick {}: the frame is not the film's image", frame.tick);
        }
        assert!(std::sync::Arc::ptr_eq(&resting[4].0.image, &resting[2].0.image), "a resting tick copied the image");
        assert!(resting[5].0.image != resting[4].0.image, "the move changed nothing in the image");
        let path = run("path:spp=1");
        assert!(path.iter().all(|(f, _)| !f.stats.resolve_reused), "path's film changes every tick");
    });
}
