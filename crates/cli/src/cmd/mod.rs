//! One module per subcommand of the CLI contract in DESIGN.md.

pub mod eval_poses;
pub mod pose;
pub mod scene;

use crate::Ctx;
use clap::Subcommand;

/// Every subcommand.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Built-in synthetic scenes (`scene generate scenes/X.toml --out DIR`).
    Scene(scene::Args),
    /// Camera poses with COLMAP, ignoring moving pixels (`pose --scene DIR`).
    Pose(pose::Args),
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
    /// ATE / RPE of predicted poses against ground truth.
    Poses(eval_poses::Args),
}

/// `romosplat bench ...`
#[derive(Debug, Subcommand)]
pub enum BenchCommand {}

/// Run one command and return its JSON summary.
pub fn dispatch(cmd: &Command, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let _ = ctx;
    match cmd {
        Command::Scene(a) => scene::run(a, ctx),
        Command::Pose(a) => pose::run(a, ctx),
        Command::Eval(e) => match e {
            EvalCommand::Poses(a) => eval_poses::run(a, ctx),
        },
        Command::Bench(b) => match *b {},
    }
}
