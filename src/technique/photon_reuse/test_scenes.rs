//! Scenes and edits the unit tests of `photon_reuse` share.
use crate::scene::edits::Edit;
use crate::scene::{Scene, Trs};
use std::path::Path;

/// The Cornell box at 16² with its short block and its light dynamic.
pub fn cornell() -> Scene {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let text = std::fs::read_to_string(root.join("cornell-box.json")).expect("bundled scene");
    let mut desc: crate::scene::SceneDesc = serde_json::from_str(&text).expect("scene JSON");
    for o in desc.objects.iter_mut().filter(|o| o.name == "short-block") {
        o.dynamic = true;
    }
    for l in &mut desc.lights {
        l.dynamic = true;
    }
    desc.camera.resolution = [16, 16];
    Scene::from_desc(desc, &root, &root).expect("valid scene")
}

/// Tick `tick`'s edit: the block slides; every third tick the light moves and tilts too (a
/// tilt rescales the flux of the paths it keeps).
pub fn edits_at(scene: &Scene, tick: u32) -> Vec<Edit> {
    let block = &scene.desc().objects[scene.object_index("short-block").expect("block")];
    let mut edits = vec![Edit::Object {
        name: "short-block".into(),
        transform: Trs { translation: [-12.0 * tick as f32, 0.0, 8.0 * tick as f32], ..block.transform },
    }];
    if tick % 3 == 0 {
        let light = &scene.desc().lights[0];
        let t = light.transform.translation;
        let tilt = glam::Quat::from_rotation_x(0.15) * glam::Quat::from_array(light.transform.rotation);
        edits.push(Edit::Light {
            name: light.name.clone(),
            transform: Some(Trs {
                translation: [t[0] + 5.0, t[1], t[2] - 5.0],
                rotation: tilt.to_array(),
                ..light.transform
            }),
            emitter: None,
        });
    }
    edits
}

/// A `photon_reuse` technique driven tick by tick over [`cornell`] and [`edits_at`], the way
/// the engine drives it (apply, commit, update), without an engine in between.
pub struct CornellRun {
    pub scene: Scene,
    pub accel: crate::scene::SceneAccel,
    pub technique: super::PhotonReuse,
}

impl CornellRun {
    pub fn new(device: &crate::embree::Device, reuse: super::ReuseMode) -> CornellRun {
        let scene = cornell();
        let accel = crate::scene::SceneAccel::build(device, &scene).expect("accel");
        let config = super::PhotonReuseConfig { paths: 20_000, reuse, ..super::PhotonReuseConfig::default() };
        let technique = super::PhotonReuse::new(config, &scene).expect("technique");
        CornellRun { scene, accel, technique }
    }

    /// Applies tick `tick`'s edits (none on tick 0) to the scene and commits them, without
    /// telling the technique.
    pub fn apply_edits(&mut self, tick: u32) -> crate::scene::edits::SceneDelta {
        let delta = match tick {
            0 => crate::scene::edits::SceneDelta::default(),
            _ => {
                let batch = edits_at(&self.scene, tick);
                crate::scene::edits::apply(&mut self.scene, batch).expect("valid edits")
            }
        };
        let moved: Vec<_> = delta.moved.iter().map(|m| m.surface).collect();
        self.accel.update_instances(&self.scene, &moved).expect("commit");
        delta
    }

    /// Applies tick `tick`'s edits (none on tick 0), commits them and updates the technique.
    /// Returns the update's figures, for the tick's render.
    pub fn update(&mut self, tick: u32, seed: u64) -> crate::technique::UpdateStats {
        use crate::technique::Technique;
        let delta = self.apply_edits(tick);
        let ctx = crate::technique::RenderContext { scene: &self.scene, accel: &self.accel, seed, tick: tick as u64 };
        self.technique.update(&ctx, &delta).expect("update")
    }
}
