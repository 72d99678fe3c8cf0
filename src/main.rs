//! The `relume` binary: thin argument parsing over the library.
//!
//! - `relume serve [--addr 127.0.0.1:8080] [--scenes DIR] [--token TOKEN] [--max-sessions N] [--threads T]`
//! - `relume render SCENE.json --technique path --spp N --out FILE.(png|jpg|exr)`
//! - `relume render SCENE.json --anim NAME.anim.json --frames N --out DIR/`
//! - `relume render SCENE.glb [--camera NAME] [--scale S] [--anim NAME] …` (glTF 2.0 scenes)
//! - `relume export SCENE.json --out SCENE.glb [--anim NAME.anim.json]…`
//! - `relume bench rays SCENE.json [--json FILE]`
//! - `relume bench reuse SCENE.json --anim NAME.anim.json --frames F [--paths N[,N2…]] [--json FILE]`
//! - `relume bench icache SCENE.json --anim NAME.anim.json --frames F [--vpls N] [--modes M,…] [--audit] [--plot DIR] [--json FILE]`
//! - `relume bench particles SCENE.json [--anim NAME.anim.json --frames F] [--particles N] [--json FILE]`
//! - `relume bench error SCENE.json [--anim NAME.anim.json --frames F --every K] --techniques LIST [--ref-spp S] [--out DIR]`
//! - `relume bench fairness [--url URL] [--scene NAME] [--technique SPEC] [--hz H] [--spammers K] [--duration 15s]`
//! - `relume migrate --from URL --to URL (--all | --session ID…) [--json FILE]`
//! - `relume load --url URL --scene NAME --anim NAME.anim.json --sessions N --hz H --duration 60s [--open-loop] [--timeout 30s]`
//!
//! Exit codes: 0 success, 1 runtime failure, 2 bad arguments or input.
use clap::{Parser, Subcommand};
use relume::tools::{
    bench, bench_error, bench_fairness, bench_icache, bench_particles, bench_reuse, export, load, migrate, render,
    serve,
};
use std::process::ExitCode;
use std::sync::OnceLock;

#[derive(Parser)]
#[command(
    name = "relume",
    version = version_line(),
    about = "Dynamic global illumination: resident light transport, verified and partly retraced every tick"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the HTTP/WebSocket service.
    Serve(serve::ServeArgs),
    /// Render a still image or an animation through the engine's tick pipeline.
    Render(render::RenderArgs),
    /// Load-test a running server with scripted animations over WebSocket.
    Load(load::LoadArgs),
    /// Move sessions from one node to another: snapshot, restore, delete.
    Migrate(migrate::MigrateArgs),
    /// Write a scene and its animations as binary glTF 2.0 (.glb).
    Export(export::ExportArgs),
    /// Benchmarks.
    Bench {
        #[command(subcommand)]
        which: BenchCommand,
    },
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Raw Embree throughput and the path tracer's ray rate, with and without path regeneration.
    Rays(bench::RaysArgs),
    /// Photon path reuse modes (off, naive, error) over the same animation.
    Reuse(bench_reuse::ReuseArgs),
    /// Instant caching modes (igi, static, temporal immediate and on demand) over the same animation.
    Icache(bench_icache::IcacheArgs),
    /// particle_gi's stages, its relight tick against a Whitted frame, incremental vs full link updates.
    Particles(bench_particles::ParticlesArgs),
    /// Speed against error: technique configurations against converged `path` references,
    /// with CSV, JSON, a Markdown report and plots.
    Error(bench_error::ErrorArgs),
    /// One session spamming ticks next to one ticking steadily: the steady one's latency alone
    /// and under the spam.
    Fairness(bench_fairness::FairnessArgs),
}

/// `relume --version`: relume's version and the Embree library it runs (from a device).
fn version_line() -> &'static str {
    static LINE: OnceLock<String> = OnceLock::new();
    LINE.get_or_init(|| {
        let relume = env!("CARGO_PKG_VERSION");
        match relume::embree::Device::new(1) {
            Ok(device) => format!("{relume}, Embree {} ({} kernels)", device.version(), device.isa()),
            Err(e) => format!("{relume}, Embree unavailable: {e}"),
        }
    })
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "relume=info".into()))
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Serve(args) => serve::run(args),
        Command::Render(args) => render::run(args),
        Command::Load(args) => load::run(args),
        Command::Migrate(args) => migrate::run(args),
        Command::Export(args) => export::run(args),
        Command::Bench { which: BenchCommand::Rays(args) } => bench::rays(args),
        Command::Bench { which: BenchCommand::Reuse(args) } => bench_reuse::run(args),
        Command::Bench { which: BenchCommand::Icache(args) } => bench_icache::run(args),
        Command::Bench { which: BenchCommand::Particles(args) } => bench_particles::run(args),
        Command::Bench { which: BenchCommand::Error(args) } => bench_error::run(args),
        Command::Bench { which: BenchCommand::Fairness(args) } => bench_fairness::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<relume::tools::UsageError>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}
