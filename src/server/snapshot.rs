//! Session snapshots (`proto/snapshot.schema.json`): `GET /v1/sessions/{id}/snapshot` writes
//! one, and `POST /v1/sessions` with `{"snapshot": …}` restores it, on this node or any other.
//!
//! A snapshot is the session's inputs, not its technique's state: the scene with every
//! applied edit, the technique configuration, the seed, the tick and edit counters, the
//! accumulation id, the queued edits and the playing animation with its clock. A restored
//! session rebuilds its technique from the scene (its first tick retraces and reports
//! `restored: true`), continues at the snapshot's tick number, numbers edit batches on from
//! the snapshot's, and starts a new accumulation (the snapshot's id + 1). Because every
//! random stream is keyed by seed and tick, the restored session's frames are statistically
//! those of the session it came from, not the same bits.
//!
//! A restore is client input: it is validated like a create (limits, scene confinement,
//! meshes, NaN), its edits like an edit batch and its animation like a `play`, and every
//! error names the field under `snapshot.`.
use super::create::{scene_error, Plan};
use super::error::ApiError;
use super::protocol::{Snapshot, SnapshotFormat};
use super::state::{bundled_scene_file, AppState, Running, SessionEntry, SessionSettings};
use super::worker::SnapshotParts;
use crate::engine::Progress;
use crate::scene::Scene;

/// The largest counter a snapshot carries: JSON numbers are exact up to 2^53 - 1.
pub const MAX_COUNTER: u64 = (1 << 53) - 1;

/// The snapshot of `entry` from what its worker reported.
pub fn snapshot_of(entry: &SessionEntry, parts: SnapshotParts) -> Snapshot {
    Snapshot {
        format: SnapshotFormat::V1,
        session: entry.id.clone(),
        scene_name: entry.scene.clone(),
        scene: parts.scene,
        technique: parts.running.technique,
        seed: entry.settings.seed,
        tick_hz: entry.settings.tick_hz,
        denoise: parts.running.denoise,
        tick: parts.progress.tick,
        edits_accepted: parts.progress.edits_accepted,
        accumulation_id: parts.progress.accumulation_id,
        pending_edits: parts.progress.pending,
        animation: parts.animation,
    }
}

impl AppState {
    /// A session to start from `snapshot`, its scene loaded and confined to the scenes root.
    pub(super) fn plan_restore(&self, snapshot: Snapshot) -> Result<Plan, ApiError> {
        for (field, value) in [
            ("tick", snapshot.tick),
            ("edits_accepted", snapshot.edits_accepted),
            ("accumulation_id", snapshot.accumulation_id),
        ] {
            if value > MAX_COUNTER {
                return Err(ApiError::invalid(format!("snapshot.{field}: {value} exceeds {MAX_COUNTER}")));
            }
        }
        self.config.limits.check_edit_count("snapshot.pending_edits", snapshot.pending_edits.len())?;
        let root = &self.config.scenes_root;
        let [width, height] = snapshot.scene.camera.resolution;
        let scene = Scene::from_desc_within(snapshot.scene, root, root, &self.config.limits.scene_budget())
            .map_err(|e| scene_error("snapshot.scene.", e))?;
        if let Some(playing) = &snapshot.animation {
            super::ws::check_speed("snapshot.animation.speed", playing.speed)?;
            if !(playing.clock_s.is_finite() && playing.clock_s >= 0.0) {
                return Err(ApiError::invalid("snapshot.animation.clock_s: must be a finite number of seconds ≥ 0"));
            }
            playing.animation.validate(&scene).map_err(|e| ApiError::invalid(format!("snapshot.animation.{e}")))?;
        }
        // Animations are found by name next to a bundled scene of this node's root.
        let bundled = bundled_scene_file(root, &snapshot.scene_name);
        // A bundled glTF scene's animations come from its file again (the snapshot holds the
        // scene, not the file's animations).
        let animations = match &bundled {
            Some(path) if crate::scene::gltf::is_gltf_path(path) => {
                let options = crate::scene::gltf::ImportOptions {
                    budget: self.config.limits.scene_budget(),
                    ..Default::default()
                };
                crate::scene::gltf::import_file(path, root, &options).map(|i| i.animations).unwrap_or_default()
            }
            _ => Vec::new(),
        };
        let (scene_name, scene_dir) = match bundled {
            Some(_) => (snapshot.scene_name, Some(root.clone())),
            None => ("inline".to_string(), None),
        };
        let progress = Progress {
            tick: snapshot.tick,
            edits_accepted: snapshot.edits_accepted,
            accumulation_id: snapshot.accumulation_id,
            pending: snapshot.pending_edits,
        };
        let settings = SessionSettings { width, height, seed: snapshot.seed, tick_hz: snapshot.tick_hz };
        Ok(Plan {
            scene_name,
            scene_dir,
            scene,
            running: Running { technique: snapshot.technique, denoise: snapshot.denoise },
            settings,
            resume: Some((progress, snapshot.animation)),
            field: "snapshot.",
            warnings: Vec::new(),
            animations,
        })
    }
}
