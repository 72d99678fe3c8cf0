//! `relume export SCENE --out FILE.glb [--anim A.anim.json]…`: a scene (relume JSON or glTF)
//! and its animations written as binary glTF 2.0, which `relume render`, the service and any
//! glTF viewer read.
use super::{SceneArgs, UsageError};
use anyhow::{Context, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    #[command(flatten)]
    pub target: SceneArgs,
    /// Output file (.glb).
    #[arg(long)]
    pub out: PathBuf,
    /// Animations to include (repeatable): NAME.anim.json files, named NAME in the output;
    /// a glTF scene's own animations are always included.
    #[arg(long)]
    pub anim: Vec<PathBuf>,
}

pub fn run(args: ExportArgs) -> Result<()> {
    if args.out.extension().and_then(|e| e.to_str()) != Some("glb") {
        return Err(UsageError(format!("--out {}: export writes binary glTF (.glb)", args.out.display())).into());
    }
    let loaded = args.target.load()?;
    let mut animations = loaded.animations.clone();
    for path in &args.anim {
        let animation = args.target.load_animation(&loaded, path)?;
        let file = path.file_name().and_then(|n| n.to_str()).unwrap_or("animation");
        let name = file.strip_suffix(".anim.json").or_else(|| file.strip_suffix(".json")).unwrap_or(file);
        animations.push((name.to_string(), animation));
    }
    let bytes = crate::scene::gltf::export_glb(&loaded.scene, &animations)
        .map_err(|e| UsageError(format!("{}: {e}", args.target.scene.display())))?;
    std::fs::write(&args.out, &bytes).with_context(|| format!("writing {}", args.out.display()))?;
    let scene = &loaded.scene;
    eprintln!(
        "wrote {} ({} bytes): {} objects, {} lights, {} animations",
        args.out.display(),
        bytes.len(),
        scene.objects.len(),
        scene.lights.len(),
        animations.len()
    );
    Ok(())
}
