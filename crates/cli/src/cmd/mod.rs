//! One module per subcommand of the CLI contract in DESIGN.md.

pub mod bench_mask;
pub mod eval_masks;
pub mod eval_poses;
pub mod export;
pub mod mask;
pub mod pose;
pub mod scene;

use crate::Ctx;
use clap::Subcommand;

/// Every subcommand.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Built-in synthetic scenes (`scene generate scenes/X.toml --out DIR`).
    Scene(scene::Args),
    /// RoMo motion masks (`mask --scene DIR [--out DIR]`).
    Mask(mask::Args),
    /// Camera poses with COLMAP, ignoring moving pixels (`pose --scene DIR`).
    Pose(pose::Args),
    /// Export splats as ply, splat, glb or spz, optionally cleaned
    /// (`export --splats F --format ply|splat|glb|spz [--clean] --out FILE`).
    Export(export::Args),
    /// Evaluate masks, poses or rendered views.
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Benchmarks printing JSON.
    #[command(subcommand)]
    Bench(BenchCommand),
}

/// `romosplat eval ...`
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// DAVIS J / precision / recall of motion masks against ground truth.
    Masks(eval_masks::Args),
    /// ATE / RPE of predicted poses against ground truth.
    Poses(eval_poses::Args),
}

/// `romosplat bench ...`
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Speed of the mask stage (per-stage medians, frames/s).
    Mask(bench_mask::Args),
}

/// Run one command and return its JSON summary.
pub fn dispatch(cmd: &Command, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let _ = ctx;
    match cmd {
        Command::Scene(a) => scene::run(a, ctx),
        Command::Mask(a) => mask::run(a, ctx),
        Command::Pose(a) => pose::run(a, ctx),
        Command::Export(a) => export::run(a, ctx),
        Command::Eval(e) => match e {
            EvalCommand::Masks(a) => eval_masks::run(a, ctx),
            EvalCommand::Poses(a) => eval_poses::run(a, ctx),
        },
        Command::Bench(b) => match b {
            BenchCommand::Mask(a) => bench_mask::run(a, ctx),
        },
    }
}
