//! `romosplat plan (--video FILE | --scene DIR) [--budget-minutes 20]`: the
//! time-budget plan `run` would follow (see `crate::plan`), with the training
//! step rate probed on this machine's adapter.

use super::pose::PoseOpts;
use super::train::{BackendKind, make_backend};
use crate::Ctx;
use crate::plan::{
    FEATURE_PROBE_FRAMES, Fixed, Input, PX_PER_FEATURE, Rates, plan, probe_px_per_feature,
    probe_sift_size, probe_train_rates,
};
use std::path::Path;

/// `romosplat plan`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The input (a video's frame count and size are read with ffprobe).
    #[command(flatten)]
    pub input: super::run::InputArgs,
    /// Wall-time budget for the whole run, minutes.
    #[arg(long, default_value_t = 20.0)]
    pub budget_minutes: f64,
    /// Training steps (planned when not given).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Training downscale (planned when not given).
    #[arg(long)]
    pub downscale: Option<u32>,
    /// Plan one training, as `run --no-baseline` or `run --no-masks` do
    /// (default: the masked model and the unmasked baseline share the time).
    #[arg(long)]
    pub no_baseline: bool,
    /// Training backend the probe runs on.
    #[arg(long, value_enum, default_value_t = BackendKind::Auto)]
    pub backend: BackendKind,
    #[command(flatten)]
    pub pose: PoseOpts,
}

/// What the SIFT probe reads: the input's frames (decoded with `ffmpeg`
/// from a video) and the `colmap` program the pose stage will run.
pub struct SiftProbe<'a> {
    pub input: &'a super::run::InputArgs,
    pub ffmpeg: &'a Path,
    pub colmap: &'a Path,
}

/// Pixels per SIFT feature of the input's frames: [`probe_px_per_feature`]
/// on [`FEATURE_PROBE_FRAMES`] of them at the size COLMAP's first tier would
/// use; the assumed [`PX_PER_FEATURE`], with a line saying why, when COLMAP
/// or the frames cannot be read.
fn feature_density(sift: &SiftProbe, (width, height): (u32, u32), fixed: &Fixed, ctx: &Ctx) -> f64 {
    let probe = || -> anyhow::Result<f64> {
        let dir = tempfile::Builder::new()
            .prefix("romosplat-probe-frames")
            .tempdir()?;
        let frames = (sift.input).sample_frames(sift.ffmpeg, FEATURE_PROBE_FRAMES, dir.path())?;
        probe_px_per_feature(sift.colmap, &frames, probe_sift_size(width, height, fixed))
    };
    match probe() {
        Ok(v) => v,
        Err(e) => {
            ctx.info(format!(
                "SIFT probe: {e:#}; assuming one feature per {PX_PER_FEATURE:.0} px"
            ));
            PX_PER_FEATURE
        }
    }
}

/// Plan for an input with the probed adapter and, with `sift` (COLMAP will
/// run), the frames' probed feature density.
pub fn plan_for(
    input: &Input,
    budget_minutes: f64,
    fixed: &Fixed,
    backend: BackendKind,
    sift: Option<SiftProbe>,
    ctx: &Ctx,
) -> anyhow::Result<crate::plan::Plan> {
    anyhow::ensure!(
        budget_minutes > 0.0 && budget_minutes.is_finite(),
        "--budget-minutes must be > 0, got {budget_minutes}"
    );
    let px_per_feature = sift.map_or(PX_PER_FEATURE, |s| {
        feature_density(&s, (input.width, input.height), fixed, ctx)
    });
    // Steps and resolution both set: nothing to plan for training, so no probe
    // (its estimate is then left out of the plan's total).
    if fixed.steps.is_some() && fixed.downscale.is_some() {
        let rates = Rates {
            px_per_feature,
            ..Rates::measured(Default::default(), crate::plan::probe_cpu_factor()?)
        };
        let mut p = plan(input, &rates, budget_minutes * 60.0, fixed);
        p.train_estimated = false;
        return Ok(p);
    }
    let mut b = make_backend(backend, ctx)?;
    let train = probe_train_rates(b.as_mut(), input.width, input.height)?;
    let rates = Rates {
        px_per_feature,
        ..Rates::measured(train, crate::plan::probe_cpu_factor()?)
    };
    Ok(plan(input, &rates, budget_minutes * 60.0, fixed))
}

/// Run `romosplat plan`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let (frames, w, h, fps) = args.input.probe(std::path::Path::new("ffmpeg"), None)?;
    let mut colmap = pose::ColmapOptions::default();
    args.pose.apply(&mut colmap)?;
    let fixed = Fixed {
        steps: args.steps,
        downscale: args.downscale,
        pose_stride: args.pose.pose_stride,
        pose_features: args.pose.pose_features,
        pose_max_image_size: args.pose.pose_max_image_size,
    };
    let input = Input {
        frames,
        width: w,
        height: h,
        overlap: colmap.overlap,
        exhaustive: args.input.exhaustive(args.pose.matcher)?,
        trainings: if args.no_baseline { 1 } else { 2 },
        masks: true,
        fps,
    };
    let sift = SiftProbe {
        input: &args.input,
        ffmpeg: Path::new("ffmpeg"),
        colmap: &colmap.colmap,
    };
    let p = plan_for(
        &input,
        args.budget_minutes,
        &fixed,
        args.backend,
        Some(sift),
        ctx,
    )?;
    ctx.info(format!("plan for {frames} frames of {w}×{h}:"));
    for l in p.lines() {
        ctx.info(format!("  {l}"));
    }
    Ok(serde_json::to_value(&p)?)
}
