//! Command-line tools built on the library: rendering, benchmarks and the server's entry point. These use `anyhow`, as
//! binaries do; the library modules below them return typed errors.
pub mod bench;
pub mod bench_error;
pub mod bench_fairness;
pub mod bench_icache;
pub mod bench_particles;
pub mod bench_reuse;
pub mod export;
pub mod load;
pub mod migrate;
pub mod plot;
pub mod render;
pub mod serve;

use std::path::{Path, PathBuf};

/// The scene a command renders, at what size, on how many threads (shared by render and bench).
#[derive(clap::Args, Debug, Clone)]
pub struct SceneArgs {
    /// Scene file: relume JSON, or glTF 2.0 (`.gltf`, `.glb`).
    pub scene: PathBuf,
    /// glTF only: the camera to render through, by camera or node name (default: the first
    /// perspective camera, or one framing the scene).
    #[arg(long, value_name = "NAME")]
    pub camera: Option<String>,
    /// glTF only: uniform scale for the whole scene (glTF is in metres).
    #[arg(long, value_name = "FACTOR")]
    pub scale: Option<f32>,
    /// The environment to light the scene with, over the file's own, as scene JSON gives it:
    /// '{"radiance": [1, 1, 1]}'.
    #[arg(long, value_name = "JSON", value_parser = environment_json)]
    pub environment: Option<crate::scene::EnvironmentDesc>,
    /// Image width (default: the scene camera's).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height (default: the scene camera's).
    #[arg(long)]
    pub height: Option<u32>,
    /// Rendering threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = thread_count)]
    pub threads: Option<usize>,
    /// Cap Embree's kernels at this ISA: sse2, sse4.2, avx, avx2 or avx512 (default: the
    /// widest this CPU has).
    #[arg(long, env = "RELUME_EMBREE_ISA")]
    pub isa: Option<crate::embree::Isa>,
}

/// `--environment`: scene JSON's `environment`, validated.
fn environment_json(text: &str) -> Result<crate::scene::EnvironmentDesc, String> {
    let env: crate::scene::EnvironmentDesc = serde_json::from_str(text).map_err(|e| e.to_string())?;
    crate::scene::load::validate_environment("environment", &env).map_err(|e| e.to_string())?;
    Ok(env)
}

impl SceneArgs {
    /// Loads the scene file (JSON or glTF) at the requested size, printing the load report's
    /// warnings on stderr. Mistakes in the file or the flags are usage errors.
    pub fn load(&self) -> anyhow::Result<crate::scene::LoadedScene> {
        let path = &self.scene;
        let gltf = crate::scene::gltf::is_gltf_path(path);
        if !gltf && (self.camera.is_some() || self.scale.is_some()) {
            return Err(UsageError("--camera and --scale apply to glTF scenes (.gltf, .glb)".into()).into());
        }
        let options = crate::scene::gltf::ImportOptions {
            camera: self.camera.clone(),
            scale: self.scale.unwrap_or(1.0),
            environment: self.environment,
            ..Default::default()
        };
        let mut loaded = crate::scene::Scene::load_file(path, &scenes_root_for(path), &options)
            .map_err(|e| UsageError(format!("{}: {e}", path.display())))?;
        for w in &loaded.warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
        if self.width.is_some() || self.height.is_some() {
            let scene = &mut loaded.scene;
            let (w, h) = (self.width.unwrap_or(scene.camera.width), self.height.unwrap_or(scene.camera.height));
            let max = crate::scene::load::MAX_RESOLUTION;
            if w == 0 || h == 0 || w > max || h > max {
                return Err(UsageError(format!("--width/--height must lie in 1..={max}")).into());
            }
            scene.set_resolution(w, h);
        }
        Ok(loaded)
    }

    /// The scene alone (see [`SceneArgs::load`]).
    pub fn load_scene(&self) -> anyhow::Result<crate::scene::Scene> {
        Ok(self.load()?.scene)
    }

    /// The animation `anim` names: a `NAME.anim.json` file, or for a glTF scene one of the
    /// file's animations by name. It is checked against the scene.
    pub fn load_animation(
        &self,
        loaded: &crate::scene::LoadedScene,
        anim: &Path,
    ) -> anyhow::Result<crate::scene::animation::Animation> {
        let in_file = loaded.animations.iter().find(|(n, _)| Path::new(n) == anim).map(|(_, a)| a.clone());
        let animation = match in_file {
            Some(a) => a,
            None if anim.is_file() || loaded.animations.is_empty() => crate::scene::animation::Animation::load(anim)
                .map_err(|e| UsageError(format!("{}: {e}", anim.display())))?,
            None => {
                let names: Vec<&str> = loaded.animations.iter().map(|(n, _)| n.as_str()).collect();
                return Err(UsageError(format!(
                    "--anim {}: neither a file nor an animation of {} (it has: {})",
                    anim.display(),
                    self.scene.display(),
                    names.join(", ")
                ))
                .into());
            }
        };
        animation.validate(&loaded.scene).map_err(|e| UsageError(format!("{}: {e}", anim.display())))?;
        Ok(animation)
    }

    pub fn threads(&self) -> usize {
        threads_or_all_cores(self.threads)
    }

    /// The Embree device for this command: one build thread per rendering thread, kernels
    /// capped at `--isa`.
    pub fn device(&self) -> anyhow::Result<crate::embree::Device> {
        use anyhow::Context;
        crate::embree::Device::with_isa(self.threads(), self.isa).context("creating the Embree device")
    }
}

/// An HTTP client for a relume server: every request carries `Authorization: Bearer TOKEN`
/// when a token is given, and gives up after `timeout`.
pub fn http_client(token: Option<&str>, timeout: std::time::Duration) -> anyhow::Result<reqwest::Client> {
    use anyhow::Context;
    let mut headers = reqwest::header::HeaderMap::new();
    if let Some(t) = token {
        let value = format!("Bearer {t}").parse().context("the token is not a valid header value")?;
        headers.insert(reqwest::header::AUTHORIZATION, value);
    }
    Ok(reqwest::Client::builder().default_headers(headers).timeout(timeout).build()?)
}

/// The settings for `--denoise[=QUALITY]` (`None` when the flag is absent; aux images on).
pub fn denoise_settings(flag: Option<&str>) -> Result<Option<crate::film::DenoiseSettings>, UsageError> {
    use crate::film::{DenoiseQuality, DenoiseSettings};
    flag.map(|q| {
        let quality = DenoiseQuality::parse(q).ok_or_else(|| {
            UsageError(format!("--denoise: unknown quality '{q}' (use {})", DenoiseQuality::NAMES.join(", ")))
        })?;
        Ok(DenoiseSettings { quality, aux: true })
    })
    .transpose()
}

/// Writes a report as pretty JSON when the command was given `--json FILE`.
pub fn write_json_report<T: serde::Serialize>(path: Option<&Path>, report: &T) -> anyhow::Result<()> {
    use anyhow::Context;
    if let Some(path) = path {
        std::fs::write(path, serde_json::to_string_pretty(report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The most rendering threads a command takes: far more than the cores of any machine it runs
/// on, and few enough to spawn at once (100 000 took the server seconds, and it answered
/// nothing meanwhile).
const MAX_THREADS: usize = 1024;

/// Parses `--threads`: a whole number in 1..=[`MAX_THREADS`].
fn thread_count(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=MAX_THREADS).contains(&n) => Ok(n),
        _ => Err(format!("must be a whole number from 1 to {MAX_THREADS}")),
    }
}

/// The requested thread count, or one per core.
pub fn threads_or_all_cores(requested: Option<usize>) -> usize {
    requested.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// A mistake in the command line or its input files (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// The scenes root for a scene file: the nearest ancestor folder named `scenes`, else the
/// scene's own folder. Mesh paths may not leave it.
pub fn scenes_root_for(scene: &Path) -> PathBuf {
    let dir = scene.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
    let dir = if dir.as_os_str().is_empty() { PathBuf::from(".") } else { dir };
    dir.ancestors().find(|a| a.file_name().is_some_and(|n| n == "scenes")).map(Path::to_path_buf).unwrap_or(dir)
}

/// The q-quantile of `values` (nearest rank; 0 for none).
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return 0.0;
    }
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// A progress bar on stderr counting `unit`s, with a message and the time left.
pub fn progress_bar(len: u64, unit: &str) -> anyhow::Result<indicatif::ProgressBar> {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{msg:28}} [{{bar:30}}] {{pos}}/{{len}} {unit} ({{eta}} left)"
        ))?
        .progress_chars("=> "),
    );
    Ok(bar)
}

/// The arguments `bench reuse` and `bench icache` share: a scene, an animation and how to play it.
#[derive(clap::Args, Debug)]
pub struct AnimationArgs {
    #[command(flatten)]
    pub target: SceneArgs,
    /// Animation to play: NAME.anim.json, or for a glTF scene an animation's name in the file.
    #[arg(long)]
    pub anim: PathBuf,
    #[arg(long, default_value_t = 60)]
    pub frames: u32,
    /// Animation frames per second (time step between frames).
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write the report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

impl AnimationArgs {
    /// Checks the frame count and rate, then loads the scene and animation.
    pub fn start(&self) -> anyhow::Result<AnimationRun> {
        if self.frames < 2 || !(self.fps > 0.0 && self.fps.is_finite()) {
            return Err(UsageError("--frames must be at least 2 and --fps positive".into()).into());
        }
        AnimationRun::load(&self.target, &self.anim)
    }

    /// Plays the animation in a fresh session of `config` on `run` (see [`AnimationRun::play`]).
    pub fn play(
        &self,
        run: &AnimationRun,
        config: &crate::technique::TechniqueConfig,
        each: impl FnMut(u32, &crate::engine::Frame) -> anyhow::Result<()> + Send,
    ) -> anyhow::Result<()> {
        run.play(config, self.seed, self.frames, self.fps, each)
    }
}

/// What an animation benchmark plays: the scene, its animation, a thread pool and a device.
pub struct AnimationRun {
    pub scene: crate::scene::Scene,
    pub anim: crate::scene::animation::Animation,
    pub threads: usize,
    pool: rayon::ThreadPool,
    device: crate::embree::Device,
}

impl AnimationRun {
    /// Loads and validates the scene and animation (mistakes are usage errors).
    pub fn load(target: &SceneArgs, anim: &Path) -> anyhow::Result<AnimationRun> {
        let loaded = target.load()?;
        let animation = target.load_animation(&loaded, anim)?;
        let scene = loaded.scene;
        let threads = target.threads();
        let pool = crate::engine::thread_pool(threads)?;
        let device = target.device()?;
        Ok(AnimationRun { scene, anim: animation, threads, pool, device })
    }

    /// A fresh session of `config` on the run's scene.
    pub fn session(
        &self,
        config: &crate::technique::TechniqueConfig,
        seed: u64,
    ) -> anyhow::Result<crate::engine::Session> {
        Ok(crate::engine::Session::new(self.scene.clone(), config, seed, &self.device)?)
    }

    /// Runs `f` on the run's thread pool.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    /// Plays `frames` frames at `fps` in a fresh session of `config`, handing each frame to
    /// `each` with its index.
    pub fn play(
        &self,
        config: &crate::technique::TechniqueConfig,
        seed: u64,
        frames: u32,
        fps: f32,
        mut each: impl FnMut(u32, &crate::engine::Frame) -> anyhow::Result<()> + Send,
    ) -> anyhow::Result<()> {
        let mut session = self.session(config, seed)?;
        self.install(|| {
            for i in 0..frames {
                session.queue_edits(self.anim.edits_at(i as f32 / fps))?;
                let frame = session.tick()?;
                each(i, &frame)?;
            }
            Ok(())
        })
    }
}

/// One mode of an animation benchmark: its first frame (which builds everything) apart, the
/// other frames, and their summary.
#[derive(Debug, serde::Serialize)]
pub struct ModeReport<F, S> {
    pub mode: String,
    pub initial: F,
    pub frames: Vec<F>,
    pub summary: S,
}

impl<F, S> ModeReport<F, S> {
    /// Splits off the first of `frames` (at least one) and summarises the rest.
    pub fn new(mode: String, mut frames: Vec<F>, summarize: impl FnOnce(&Frames<F>) -> S) -> anyhow::Result<Self> {
        anyhow::ensure!(!frames.is_empty(), "{mode}: no frame was played");
        let initial = frames.remove(0);
        let summary = summarize(&Frames(&frames));
        Ok(ModeReport { mode, initial, frames, summary })
    }

    /// The mode's label and one figure of every frame, the first included, as (frame, value)
    /// points to plot.
    pub fn per_frame(&self, figure: impl Fn(&F) -> f64) -> (String, Vec<(f64, f64)>) {
        let frames = std::iter::once(&self.initial).chain(&self.frames);
        (self.mode.clone(), frames.enumerate().map(|(i, f)| (i as f64, figure(f))).collect())
    }
}

/// A benchmark's frames after the first, as its summary reads them.
pub struct Frames<'a, F>(pub &'a [F]);

impl<F> Frames<'_, F> {
    /// One figure of every frame.
    pub fn column(&self, figure: impl Fn(&F) -> f64) -> Vec<f64> {
        self.0.iter().map(figure).collect()
    }

    /// The `q` quantile of one figure over the frames.
    pub fn quantile(&self, figure: impl Fn(&F) -> f64, q: f64) -> f64 {
        quantile(&self.column(figure), q)
    }
}
