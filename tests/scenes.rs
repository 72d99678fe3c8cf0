//! The bundled scenes and animations: they load, validate, and drive sessions through the
//! ordinary edit path.
mod common;
use common::*;
use relume::embree::{Device, Ray};
use relume::engine::Session;
use relume::scene::animation::Animation;
use relume::scene::edits::Edit;
use relume::scene::{SceneError, SurfaceId, Trs};
use relume::technique::TechniqueConfig;

const ANIMATED: [&str; 8] =
    ["merry-go-round", "walker", "villa-torch", "maze", "bunnies-1", "bunnies-2", "bunnies-4", "bunnies-9"];

#[test]
fn every_bundled_scene_loads_without_dropping_triangles() {
    for name in ["cornell-box", "furnace"].iter().chain(ANIMATED.iter()) {
        let scene = load(&format!("{name}.json"));
        assert!(scene.dropped_degenerate.is_empty(), "{name}: {:?}", scene.dropped_degenerate);
        assert!(scene.camera.width <= 256 && scene.camera.height <= 256, "{name} renders above 256²");
        assert!(scene.light_selection.is_some(), "{name} has no light");
    }
}

#[test]
fn every_animation_validates_against_its_scene() {
    for name in ANIMATED {
        let scene = load(&format!("{name}.json"));
        let anim =
            Animation::load(&scenes_dir().join(format!("{name}.anim.json"))).unwrap_or_else(|e| panic!("{name}: {e}"));
        anim.validate(&scene).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(!anim.edits_at(0.0).is_empty());
        relume::scene::edits::validate(&scene, &anim.edits_at(anim.duration * 0.37))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
}

#[test]
fn an_animation_moves_instances_and_changes_the_frame() {
    // Property: edits flow drain → apply → commit and restart the film. The frame is compared
    // with a twin session (same seed, same tick) that got no edits, so only the move can make
    // them differ. The animation's first pose is the scene's own: it changes nothing.
    let mut scene = load("bunnies-1.json");
    scene.set_resolution(32, 32);
    let anim = Animation::load(&scenes_dir().join("bunnies-1.anim.json")).unwrap();
    let device = Device::new(1).unwrap();
    let config = TechniqueConfig::Path(path(2));
    let mut session = Session::new(scene.clone(), &config, 5, &device).unwrap();
    let mut twin = Session::new(scene, &config, 5, &device).unwrap();
    session.queue_edits(anim.edits_at(0.0)).unwrap();
    let first = session.tick().unwrap();
    twin.tick().unwrap();
    assert_eq!((first.stats.moved_surfaces, first.stats.edits_unchanged), (0, 1));
    session.queue_edits(anim.edits_at(anim.duration * 0.5)).unwrap();
    let moved = session.tick().unwrap();
    let still = twin.tick().unwrap();
    assert_eq!(moved.stats.moved_surfaces, 1);
    assert_ne!(moved.accumulation_id, still.accumulation_id);
    assert_ne!(moved.image, still.image, "the move did not change the frame");
}

#[test]
fn moved_objects_are_hit_at_their_new_place() {
    let scene = load("bunnies-1.json");
    let device = Device::new(1).unwrap();
    let mut session = Session::new(scene, &TechniqueConfig::Path(path(1)), 1, &device).unwrap();
    let bunny = session.scene().object_index("bunny-1").unwrap();
    let old = session.scene().desc().objects[bunny].transform;
    // Lift the bunny 200 units: a ray down through its old middle now hits the floor instead.
    let lifted = Trs { translation: [old.translation[0], 300.0, old.translation[2]], ..old };
    session.queue_edits(vec![Edit::Object { name: "bunny-1".into(), transform: lifted }]).unwrap();
    session.tick().unwrap();
    let probe_from = |y: f32| Ray::new(glam::Vec3::new(old.translation[0], y, old.translation[2]), glam::Vec3::NEG_Y);
    // The session's own accel, updated incrementally by the tick (not rebuilt).
    let accel = session.accel();
    let hit = accel.scene().intersect1(&probe_from(100.0)).unwrap();
    assert_ne!(accel.resolve(&hit).unwrap().0, SurfaceId::Object(bunny as u32), "old place still occupied");
    let probe = probe_from(540.0);
    let hit = accel.scene().intersect1(&probe).unwrap();
    let (surface, prim) = accel.resolve(&hit).unwrap();
    assert_eq!(surface, SurfaceId::Object(bunny as u32), "new place empty");
    // The scene's per-triangle hit records moved too: the resolved point is where Embree hit,
    // and the normal faces the ray (the bunny is closed and wound outward).
    let sp = session.scene().surface_point(surface, prim, hit.u, hit.v);
    let traced = probe.origin + probe.dir * hit.t;
    assert!(sp.p.distance(traced) < 1e-3 * hit.t.max(1.0), "resolved at {} but hit at {traced}", sp.p);
    assert!(sp.n.dot(probe.dir) < 0.0, "normal {} does not face the ray", sp.n);
}

#[test]
fn bad_edits_are_rejected_whole_and_change_nothing() {
    let scene = load("bunnies-2.json");
    let device = Device::new(1).unwrap();
    let mut session = Session::new(scene, &TechniqueConfig::Path(path(1)), 1, &device).unwrap();
    let good = Edit::Object { name: "bunny-1".into(), transform: Trs::default() };
    let cases: Vec<(Edit, &str)> = vec![
        (Edit::Object { name: "floor".into(), transform: Trs::default() }, "static"),
        (Edit::Object { name: "nobody".into(), transform: Trs::default() }, "unknown object"),
        (
            Edit::Object {
                name: "bunny-2".into(),
                transform: Trs { rotation: [0.0, 0.0, 0.0, 2.0], ..Trs::default() },
            },
            "quaternion",
        ),
        (
            Edit::Object {
                name: "bunny-2".into(),
                transform: Trs { translation: [f32::NAN, 0.0, 0.0], ..Trs::default() },
            },
            "finite",
        ),
        (
            Edit::Camera {
                position: Some([278.0, 273.0, 0.0]),
                look_at: Some([278.0, 273.0, 0.0]),
                up: None,
                vfov_deg: None,
            },
            "zero length",
        ),
        (
            Edit::Material { name: "gold".into(), material: relume::scene::Material::Glass { ior: 1.5 } },
            "unknown material",
        ),
        (Edit::Light { name: "ceiling-light".into(), transform: Some(Trs::default()), emitter: None }, "static"),
    ];
    for (bad, words) in cases {
        match session.queue_edits(vec![good.clone(), bad.clone()]) {
            Err(SceneError::Invalid { field, message }) => {
                assert!(field.starts_with("edits[1]"), "{field}");
                assert!(message.contains(words) || field.contains(words), "{bad:?}: {field}: {message}");
            }
            other => panic!("{bad:?} accepted: {other:?}"),
        }
        assert_eq!(session.pending_edits(), 0, "a rejected batch queued something");
    }
}
