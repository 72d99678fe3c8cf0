//! The wire protocol: HTTP request and response bodies and WebSocket messages, as documented
//! in `proto/openapi.yaml` and `proto/ws.schema.json`. Shared by the server, the load client
//! and the tests, so there is one definition of each message.
use crate::engine::TickStats;
use crate::film::DenoiseSettings;
use crate::scene::edits::Edit;
use crate::technique::TechniqueConfig;
use serde::{Deserialize, Serialize};

/// Every error answer over HTTP: a stable code and a message naming what was wrong.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ErrorBody {
    pub error: String,
    pub detail: String,
}

/// `POST /v1/sessions`. `scene` is a bundled scene's name or an inline scene document; or
/// `snapshot` alone restores a session from [`Snapshot`] (taken on any node).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CreateSession {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene: Option<serde_json::Value>,
    /// A binary glTF 2.0 scene (`.glb`), base64: buffers in its binary chunk or `data:`
    /// URIs, within the body and scene limits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene_glb: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub snapshot: Option<Box<Snapshot>>,
    #[serde(default)]
    pub technique: Option<TechniqueConfig>,
    #[serde(default)]
    pub width: Option<u32>,
    #[serde(default)]
    pub height: Option<u32>,
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Server-driven ticks per second; `None` for client-driven ticks only.
    #[serde(default)]
    pub tick_hz: Option<f32>,
    /// Denoise every frame with Open Image Denoise (absent: off).
    #[serde(default)]
    pub denoise: Option<DenoiseSettings>,
    /// The environment to light the scene with, over the scene's own (`{"radiance": [..]}`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment: Option<crate::scene::EnvironmentDesc>,
}

impl CreateSession {
    /// A create request for `scene` (a bundled name or an inline document) with the defaults.
    pub fn scene(scene: serde_json::Value) -> CreateSession {
        CreateSession { scene: Some(scene), seed: default_seed(), ..CreateSession::default() }
    }

    /// The fields a restore must leave out: the snapshot carries them all.
    pub fn fields_besides_snapshot(&self) -> Vec<&'static str> {
        let given = [
            ("scene", self.scene.is_some()),
            ("scene_glb", self.scene_glb.is_some()),
            ("technique", self.technique.is_some()),
            ("width", self.width.is_some()),
            ("height", self.height.is_some()),
            ("seed", self.seed != default_seed()),
            ("tick_hz", self.tick_hz.is_some()),
            ("denoise", self.denoise.is_some()),
            ("environment", self.environment.is_some()),
        ];
        given.iter().filter(|(_, g)| *g).map(|(f, _)| *f).collect()
    }
}

fn default_seed() -> u64 {
    1
}

/// `PATCH /v1/sessions/{id}`: what to change in a running session; an absent field stays as
/// it is.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UpdateSession {
    /// The technique to run from the next tick on, in [`CreateSession::technique`]'s format;
    /// the scene keeps its edits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub technique: Option<TechniqueConfig>,
    /// `{"quality": …}` denoises every frame from the next tick on, `null` stops.
    #[serde(default, deserialize_with = "present", skip_serializing_if = "Option::is_none")]
    pub denoise: Option<Option<DenoiseSettings>>,
}

impl UpdateSession {
    /// Nothing to change: neither field was given.
    pub fn is_empty(&self) -> bool {
        self.technique.is_none() && self.denoise.is_none()
    }
}

/// A field given, even as `null` (`Some(None)`); an absent one is `None` through `default`.
fn present<'de, D: serde::Deserializer<'de>, T: Deserialize<'de>>(d: D) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

/// The one snapshot format this server writes and reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum SnapshotFormat {
    #[serde(rename = "relume.snapshot/1")]
    V1,
}

/// `GET /v1/sessions/{id}/snapshot`: everything needed to continue a session on another node
/// (`proto/snapshot.schema.json`). The technique's resident state is not in it: a restored
/// session rebuilds it on its first tick, which reports `restored: true`. The film's
/// accumulated samples are not in it either: the restored session starts a new accumulation
/// (`accumulation_id` + 1) at tick `tick`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Snapshot {
    pub format: SnapshotFormat,
    /// The session it was taken from, and that session's node (for the record only).
    pub session: String,
    /// The bundled scene's name (its animations stay playable by name), or `"inline"`.
    pub scene_name: String,
    /// The scene with every applied edit in it, at the session's resolution.
    pub scene: crate::scene::SceneDesc,
    pub technique: TechniqueConfig,
    pub seed: u64,
    pub tick_hz: Option<f32>,
    pub denoise: Option<DenoiseSettings>,
    /// Ticks run so far: the restored session's next tick has this number.
    pub tick: u64,
    /// Edit batches accepted so far: the restored session numbers the next one `+ 1`.
    pub edits_accepted: u64,
    /// The accumulation the last frame belonged to.
    pub accumulation_id: u64,
    /// Edits accepted but not applied yet (coalesced, one per target): the next tick applies
    /// them.
    pub pending_edits: Vec<Edit>,
    /// The animation the server was playing, and where its clock stood.
    pub animation: Option<PlayingAnimation>,
}

/// An animation the server plays for a session: `clock_s` animation seconds have elapsed, and
/// it advances `speed` animation seconds per second.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlayingAnimation {
    pub animation: crate::scene::animation::Animation,
    pub speed: f32,
    pub clock_s: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionLinks {
    pub frame: String,
    pub ws: String,
    pub edits: String,
    pub tick: String,
    pub stats: String,
}

/// A session as `GET /v1/sessions/{id}` and `POST /v1/sessions` report it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionView {
    pub id: String,
    /// The bundled scene's name, or `"inline"`.
    pub scene: String,
    pub technique: TechniqueConfig,
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    pub tick_hz: Option<f32>,
    pub denoise: Option<DenoiseSettings>,
    pub ticks: u64,
    /// `running` or `failed`.
    pub state: String,
    pub failure: Option<String>,
    pub last_stats: Option<TickStats>,
    /// The scene's load report: what a glTF file holds that relume reads only in part.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// A glTF scene's own animations, which `play` takes by name.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub animations: Vec<String>,
    pub links: SessionLinks,
}

/// `POST /v1/sessions/{id}/edits`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EditBatch {
    pub edits: Vec<Edit>,
}

/// The answer to an accepted edit batch: queued for the next tick.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EditsAccepted {
    pub queued: usize,
    /// Targets with an edit waiting for the next tick, this batch included (edits are
    /// coalesced, latest per target, as they are queued).
    pub pending: usize,
    /// The batch's sequence number in its session (1, 2, ...): it is applied by the first tick
    /// whose `edits_applied_through` reaches it.
    pub seq: u64,
}

/// `POST /v1/sessions/{id}/tick`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TickDone {
    pub stats: TickStats,
    pub frame_url: String,
}

/// `GET /v1/sessions/{id}/stats`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StatsHistory {
    pub stats: Vec<TickStats>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneEntry {
    pub name: String,
    pub animations: Vec<String>,
    /// For an uploaded scene: the bytes sent, their SHA-256, and the scene's triangles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sha256: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub triangles: Option<u64>,
}

impl SceneEntry {
    pub fn bundled(name: String, animations: Vec<String>) -> SceneEntry {
        SceneEntry { name, animations, bytes: None, sha256: None, triangles: None }
    }

    pub fn uploaded(r: super::uploads::store::UploadRecord) -> SceneEntry {
        SceneEntry {
            name: r.name,
            animations: r.animations,
            bytes: Some(r.bytes),
            sha256: Some(r.sha256),
            triangles: Some(r.triangles),
        }
    }
}

/// `GET /v1/sessions`: every session, in id order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionList {
    pub sessions: Vec<SessionView>,
}

/// `GET /v1/scenes`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneList {
    pub scenes: Vec<SceneEntry>,
}

/// One entry of `GET /v1/techniques`: a registry description and the configuration's defaults.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TechniqueEntry {
    #[serde(flatten)]
    pub description: crate::technique::registry::TechniqueDescription,
    pub defaults: serde_json::Value,
}

/// `GET /v1/techniques`: every technique, and the server's limits that bound their parameters.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TechniqueList {
    pub techniques: Vec<TechniqueEntry>,
    pub max_spp_per_tick: u32,
    pub max_photon_paths: u32,
}

/// Image encodings a client can ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameFormat {
    Png,
    Jpg,
    Exr,
    F32,
    None,
}

/// WebSocket client → server (JSON text).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    Edits {
        edits: Vec<Edit>,
    },
    Tick,
    Subscribe {
        #[serde(default = "default_frames")]
        frames: FrameFormat,
        #[serde(default = "yes")]
        stats: bool,
        #[serde(default = "one")]
        every: u32,
        /// Frames are the denoised image when the session denoises; `false` sends the raw one.
        #[serde(default = "yes")]
        denoised: bool,
    },
    /// The server drives the named animation itself (a file `NAME.anim.json` next to the scene).
    Play {
        anim: String,
        #[serde(default = "unit_speed")]
        speed: f32,
    },
    Pause,
    /// Switches the technique or the denoiser as `PATCH /v1/sessions/{id}` does (its body, with
    /// the `type`); answered by `updated` or `error`.
    Update(UpdateSession),
}

fn default_frames() -> FrameFormat {
    FrameFormat::Png
}
fn yes() -> bool {
    true
}
fn one() -> u32 {
    1
}
fn unit_speed() -> f32 {
    1.0
}

/// WebSocket server → client (JSON text). Frames travel as binary messages: see [`FrameHeader`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    Stats {
        stats: Box<TickStats>,
        frames_dropped: u64,
    },
    EditsAccepted {
        queued: usize,
        pending: usize,
        seq: u64,
    },
    /// An `update` was applied: what the session runs from its next tick on.
    Updated {
        technique: TechniqueConfig,
        denoise: Option<DenoiseSettings>,
    },
    Error {
        error: String,
        detail: String,
    },
}

/// The header in front of every binary frame message: 32 bytes, little-endian.
///
/// | bytes | field |
/// |---|---|
/// | 0..4 | magic `RLM1` |
/// | 4..12 | tick (u64) |
/// | 12..20 | accumulation id (u64) |
/// | 20 | format: 0 png, 1 jpg, 2 exr |
/// | 21..24 | reserved, zero |
/// | 24..28 | width (u32) |
/// | 28..32 | height (u32) |
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameHeader {
    pub tick: u64,
    pub accumulation_id: u64,
    pub format: FrameFormat,
    pub width: u32,
    pub height: u32,
}

pub const FRAME_MAGIC: &[u8; 4] = b"RLM1";
pub const FRAME_HEADER_LEN: usize = 32;

impl FrameHeader {
    pub fn encode(&self) -> [u8; FRAME_HEADER_LEN] {
        let mut b = [0u8; FRAME_HEADER_LEN];
        b[0..4].copy_from_slice(FRAME_MAGIC);
        b[4..12].copy_from_slice(&self.tick.to_le_bytes());
        b[12..20].copy_from_slice(&self.accumulation_id.to_le_bytes());
        b[20] = match self.format {
            FrameFormat::Png => 0,
            FrameFormat::Jpg => 1,
            FrameFormat::Exr => 2,
            FrameFormat::F32 => 3,
            FrameFormat::None => 255,
        };
        b[24..28].copy_from_slice(&self.width.to_le_bytes());
        b[28..32].copy_from_slice(&self.height.to_le_bytes());
        b
    }

    /// Parses a header; `None` if the bytes are not a frame message.
    pub fn decode(b: &[u8]) -> Option<FrameHeader> {
        if b.len() < FRAME_HEADER_LEN || &b[0..4] != FRAME_MAGIC {
            return None;
        }
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap_or_default());
        let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap_or_default());
        let format = match b[20] {
            0 => FrameFormat::Png,
            1 => FrameFormat::Jpg,
            2 => FrameFormat::Exr,
            3 => FrameFormat::F32,
            _ => return None,
        };
        Some(FrameHeader {
            tick: u64_at(4),
            accumulation_id: u64_at(12),
            format,
            width: u32_at(24),
            height: u32_at(28),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_header_round_trips() {
        let h = FrameHeader { tick: 7, accumulation_id: 3, format: FrameFormat::Jpg, width: 256, height: 128 };
        let b = h.encode();
        assert_eq!(FrameHeader::decode(&b), Some(h));
        assert_eq!(FrameHeader::decode(&b[..10]), None);
        let mut bad = b;
        bad[0] = b'X';
        assert_eq!(FrameHeader::decode(&bad), None);
    }
}
