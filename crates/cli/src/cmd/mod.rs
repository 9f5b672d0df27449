//! One module per subcommand of the CLI contract in `docs/design.md`.

pub mod bench_mask;
pub mod bench_train;
pub mod composite;
pub mod demo;
pub mod eval_masks;
pub mod eval_poses;
pub mod eval_views;
pub mod export;
pub mod frames;
pub mod inspect;
pub mod keyframes;
pub mod mask;
pub mod onthego;
pub mod plan;
pub mod pose;
pub mod render;
pub mod run;
pub mod run_report;
pub mod scene;
pub mod train;
pub mod train_common;

use crate::Ctx;
use clap::Subcommand;

/// Every subcommand.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// The whole pipeline on the built-in demo scene; prints a results table.
    Demo(demo::Args),
    /// The whole pipeline on a video or scene folder: frames → masks → poses → splats → export → report.
    Run(run::Args),
    /// Built-in synthetic scenes (`scene generate scenes/X.toml --out DIR`).
    Scene(scene::Args),
    /// RoMo motion masks (`mask --scene DIR [--out DIR]`).
    Mask(mask::Args),
    /// Camera poses with COLMAP, ignoring moving pixels (`pose --scene DIR`).
    Pose(pose::Args),
    /// Train Gaussian splats with masked loss
    /// (`train --scene DIR [--no-masks] [--poses PATH] [--steps N] [--backend auto|wgpu|cpu] --out DIR`).
    Train(train::Args),
    /// Render a split of a scene from trained splats (`render --splats FILE --scene DIR [--split extra] --out DIR`).
    Render(render::Args),
    /// Export splats as ply, splat, glb or spz, optionally cleaned
    /// (`export --splats F --format ply|splat|glb|spz [--clean] --out FILE`).
    Export(export::Args),
    /// Extract a video's frames into a scene folder (`frames --video FILE --out DIR [--fps N]`).
    Frames(frames::Args),
    /// Drop untextured, blurry and near-duplicate frames (`keyframes --scene DIR --out DIR`).
    Keyframes(keyframes::Args),
    /// The time-budget plan of `run` for an input (`plan --video FILE [--budget-minutes 20]`).
    Plan(plan::Args),
    /// Summarise a scene folder, COLMAP model, transforms.json or PLY (`inspect PATH`).
    Inspect(inspect::Args),
    /// The NeRF On-the-go protocol on a scene in its layout: no masks, RoMo
    /// masks, ground-truth masks, clean oracle side by side
    /// (`onthego --scene DIR --out DIR [--steps N]`).
    Onthego(onthego::Args),
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
    /// PSNR / SSIM / LPIPS of rendered views against the scene's images.
    Views(eval_views::Args),
}

/// `romosplat bench ...`
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Speed of the mask stage (per-stage medians, frames/s).
    Mask(bench_mask::Args),
    /// Training speed of each backend (steps/s, MP/s).
    Train(bench_train::Args),
}

/// Run one command and return its JSON summary.
pub fn dispatch(cmd: &Command, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    match cmd {
        Command::Demo(a) => demo::run(a, ctx),
        Command::Run(a) => run::run(a, ctx),
        Command::Scene(a) => scene::run(a, ctx),
        Command::Mask(a) => mask::run(a, ctx),
        Command::Pose(a) => pose::run(a, ctx),
        Command::Train(a) => train::run(a, ctx),
        Command::Export(a) => export::run(a, ctx),
        Command::Frames(a) => frames::run(a, ctx),
        Command::Inspect(a) => inspect::run(a, ctx),
        Command::Keyframes(a) => keyframes::run(a, ctx),
        Command::Plan(a) => plan::run(a, ctx),
        Command::Render(a) => render::run(a, ctx),
        Command::Onthego(a) => onthego::run(a, ctx),
        Command::Eval(e) => match e {
            EvalCommand::Masks(a) => eval_masks::run(a, ctx),
            EvalCommand::Poses(a) => eval_poses::run(a, ctx),
            EvalCommand::Views(a) => eval_views::run(a, ctx),
        },
        Command::Bench(b) => match b {
            BenchCommand::Mask(a) => bench_mask::run(a, ctx),
            BenchCommand::Train(a) => bench_train::run(a, ctx),
        },
    }
}
