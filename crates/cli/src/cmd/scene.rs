//! `romosplat scene generate scenes/X.toml --out DIR`: render a built-in
//! synthetic scene (see `loader::synth`) into a scene folder.

use crate::Ctx;
use anyhow::Context;
use std::path::PathBuf;

/// `romosplat scene ...`
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: SceneCommand,
}

/// Scene subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum SceneCommand {
    /// Render a synthetic scene from its TOML spec into a scene folder.
    Generate(GenerateArgs),
    /// Paste moving DAVIS objects onto a real capture (On-the-go layout).
    Composite(super::composite::Args),
}

/// `romosplat scene generate SPEC --out DIR`
#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    /// Scene spec (TOML), e.g. scenes/small.toml.
    pub spec: PathBuf,
    /// Output scene folder (created; existing files are overwritten).
    #[arg(long)]
    pub out: PathBuf,
    /// Override the spec's seed.
    #[arg(long)]
    pub seed: Option<u64>,
}

/// Run `romosplat scene ...`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    match &args.command {
        SceneCommand::Composite(c) => super::composite::run(c, ctx),
        SceneCommand::Generate(g) => {
            let mut spec = loader::synth::load_spec(&g.spec)?;
            if let Some(seed) = g.seed {
                spec.seed = seed;
            }
            ctx.info(format!(
                "generating '{}': {} frames + {} test views at {}x{} into {}",
                spec.name,
                spec.frames,
                spec.test_views,
                spec.width,
                spec.height,
                g.out.display()
            ));
            let report = loader::synth::generate(&spec, &g.out)
                .with_context(|| format!("generating {}", g.spec.display()))?;
            ctx.info(format!(
                "wrote {} frames, {} points; pedestrians cover {:.1}% of a frame on average ({:.1}–{:.1}%) in {:.2} s",
                report.frames,
                report.points3d,
                100.0 * report.coverage.mean,
                100.0 * report.coverage.min,
                100.0 * report.coverage.max,
                report.seconds
            ));
            Ok(serde_json::to_value(&report)?)
        }
    }
}
