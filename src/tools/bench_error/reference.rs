//! Converged `path` (or `bdpt`) references, cached on disk.
//!
//! A reference is the average of two independent renders of `spp / 2` samples each, so
//! its own noise can be estimated without a third render: the relMSE between the halves is
//! about 4× the full reference's (each half has twice its variance, and the difference of two
//! independent estimates adds them). The report states that estimate next to the errors it
//! measures. References are EXR files under `--cache`, named by a hash of the scene file, the
//! animation file, the animation time, the resolution, the sample count, the seed and the
//! technique, so a
//! second run with the same settings reuses them.
use super::metrics::compare;
use crate::embree::Device;
use crate::engine::Session;
use crate::film::{write_image, LinearImage};
use crate::scene::animation::Animation;
use crate::scene::Scene;
use crate::technique::bdpt::BdptConfig;
use crate::technique::path::PathConfig;
use crate::technique::TechniqueConfig;
use anyhow::{Context, Result};
use indicatif::ProgressBar;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

/// Camera samples per pixel each reference tick renders.
const SPP_PER_TICK: u32 = 16;

/// What a reference depends on.
pub struct ReferenceKey<'a> {
    pub scene_file: &'a [u8],
    pub animation_file: Option<&'a [u8]>,
    pub time: f32,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub seed: u64,
    /// `path` or `bdpt`.
    pub technique: &'a str,
}

impl ReferenceKey<'_> {
    fn file_name(&self) -> String {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (self.scene_file, self.animation_file, self.time.to_bits(), self.width, self.height, self.spp, self.seed)
            .hash(&mut h);
        // A `path` reference keeps the name it had before `bdpt` references existed.
        if self.technique != "path" {
            self.technique.hash(&mut h);
        }
        format!("ref-{:016x}.exr", h.finish())
    }
}

/// A reference and the estimated relMSE of its own noise.
pub struct Reference {
    pub image: LinearImage,
    pub self_rel_mse: f64,
}

fn read_exr(path: &Path) -> Result<LinearImage> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        |resolution, _| LinearImage::new(resolution.width() as u32, resolution.height() as u32),
        |img: &mut LinearImage, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            let w = img.width as usize;
            img.pixels[pos.y() * w + pos.x()] = crate::core::Rgb::new(r, g, b);
        },
    )
    .with_context(|| format!("reading the cached reference {}", path.display()))?;
    Ok(image.layer_data.channel_data.pixels)
}

/// Renders `spp` samples of `scene` at `time` of `animation` with the key's technique and `seed`.
fn render_half(
    scene: &Scene,
    animation: Option<&Animation>,
    key: &ReferenceKey,
    spp: u32,
    seed: u64,
    device: &Device,
    bar: &ProgressBar,
) -> Result<LinearImage> {
    let per_tick = SPP_PER_TICK.min(spp);
    let config = match key.technique {
        "bdpt" => TechniqueConfig::Bdpt(BdptConfig { spp: per_tick, ..BdptConfig::default() }),
        _ => TechniqueConfig::Path(PathConfig { spp: per_tick, ..PathConfig::default() }),
    };
    let time = key.time;
    let mut session = Session::new(scene.clone(), &config, seed, device)?;
    if let Some(a) = animation {
        session.queue_edits(a.edits_at(time))?;
    }
    let ticks = spp.div_ceil(SPP_PER_TICK).max(1);
    let mut last = None;
    for _ in 0..ticks {
        last = Some(session.tick()?);
        bar.inc(SPP_PER_TICK.min(spp) as u64);
    }
    Ok(std::sync::Arc::unwrap_or_clone(last.context("no reference tick ran")?.image))
}

/// The cached reference for `key`, rendering and storing it if missing. Also returns whether
/// it was rendered now.
pub fn reference(
    cache: &Path,
    key: &ReferenceKey,
    scene: &Scene,
    animation: Option<&Animation>,
    device: &Device,
    bar: &ProgressBar,
) -> Result<(Reference, bool)> {
    let dir: PathBuf = cache.to_path_buf();
    let file = dir.join(key.file_name());
    let noise_file = file.with_extension("noise");
    if let (Ok(image), Ok(noise)) = (read_exr(&file), std::fs::read_to_string(&noise_file)) {
        if let Ok(self_rel_mse) = noise.trim().parse::<f64>() {
            bar.inc(key.spp as u64);
            return Ok((Reference { image, self_rel_mse }, false));
        }
    }
    let half = (key.spp / 2).max(1);
    let a = render_half(scene, animation, key, half, key.seed, device, bar)?;
    let b = render_half(scene, animation, key, half, key.seed ^ 0x9e37_79b9_7f4a_7c15, device, bar)?;
    let self_rel_mse = compare(&a, &b).0.rel_mse / 4.0;
    let image = LinearImage { pixels: a.pixels.iter().zip(&b.pixels).map(|(x, y)| (*x + *y) * 0.5).collect(), ..a };
    std::fs::create_dir_all(&dir).with_context(|| format!("creating the reference cache {}", dir.display()))?;
    write_image(&image, &file, 0.0).with_context(|| format!("writing {}", file.display()))?;
    std::fs::write(&noise_file, format!("{self_rel_mse:e}\n"))?;
    Ok((Reference { image, self_rel_mse }, true))
}
