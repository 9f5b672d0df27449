//! Training one scene folder and scoring its held-out views, for the `demo`
//! and `run` pipelines: drives `romosplat train` and `romosplat render` with
//! their own argument parsers (so every default is the command's default),
//! and collects what the report needs.

use crate::Ctx;
use anyhow::{Context, Result};
use clap::Parser;
use std::path::{Path, PathBuf};

/// What a pipeline needs back from one training run.
#[derive(Debug, Clone, Default)]
pub struct VariantResult {
    pub psnr: f64,
    pub ssim: f64,
    pub splats: usize,
    pub seconds: f64,
    /// (step, loss) samples.
    pub loss_curve: Vec<(f64, f64)>,
    /// (step, training PSNR) samples.
    pub psnr_curve: Vec<(f64, f64)>,
    /// Rendered held-out views (PNG paths), in split order.
    pub renders: Vec<PathBuf>,
    /// The train command's JSON summary.
    pub summary: serde_json::Value,
}

#[derive(Debug, Parser)]
struct TrainCli {
    #[command(flatten)]
    args: super::train::Args,
}

#[derive(Debug, Parser)]
struct RenderCli {
    #[command(flatten)]
    args: super::render::Args,
}

fn curve(summary: &serde_json::Value, key: &str) -> Vec<(f64, f64)> {
    summary["history"]
        .as_array()
        .map(|h| {
            h.iter()
                .filter_map(|e| Some((e["step"].as_f64()?, e[key].as_f64()?)))
                .collect()
        })
        .unwrap_or_default()
}

/// Train `scene` (its split's `clutter` views; masks when present) for
/// `steps`, then render and score its `extra` views. `extra_args` are passed
/// to `romosplat train` as given (e.g. `["--no-masks"]`).
pub fn train_and_eval(
    ctx: &Ctx,
    scene: &Path,
    out: &Path,
    steps: usize,
    backend: &str,
    extra_args: &[String],
) -> Result<VariantResult> {
    let t0 = std::time::Instant::now();
    let mut argv: Vec<String> = vec![
        "train".into(),
        "--scene".into(),
        scene.display().to_string(),
        "--out".into(),
        out.display().to_string(),
        "--steps".into(),
        steps.to_string(),
        "--backend".into(),
        backend.into(),
    ];
    argv.extend(extra_args.iter().cloned());
    let cli = TrainCli::try_parse_from(&argv).context("train options")?;
    let summary = super::train::run(&cli.args, ctx)?;
    let ply = out.join("splats.ply");
    let render_dir = out.join("renders");
    let rargv = [
        "render".to_string(),
        "--splats".into(),
        ply.display().to_string(),
        "--scene".into(),
        scene.display().to_string(),
        "--split".into(),
        "extra".into(),
        "--out".into(),
        render_dir.display().to_string(),
        // Render at the training resolution.
        "--downscale".into(),
        cli.args.downscale.to_string(),
    ];
    let rcli = RenderCli::try_parse_from(&rargv).context("render options")?;
    let rendered = super::render::run(&rcli.args, ctx)?;
    let renders = rendered["images"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|p| p.as_str().map(PathBuf::from))
                .collect()
        })
        .unwrap_or_default();
    Ok(VariantResult {
        psnr: summary["test"]["mean_psnr"].as_f64().unwrap_or(f64::NAN),
        ssim: summary["test"]["mean_ssim"].as_f64().unwrap_or(f64::NAN),
        splats: summary["report"]["splats"].as_u64().unwrap_or(0) as usize,
        seconds: t0.elapsed().as_secs_f64(),
        loss_curve: curve(&summary, "loss"),
        psnr_curve: curve(&summary, "psnr"),
        renders,
        summary,
    })
}
