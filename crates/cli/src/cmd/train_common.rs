//! Training for the `demo` and `run` pipelines: the short-run schedule they
//! share, and one call that trains a scene folder, scores and renders its
//! held-out views and hands back what the report needs, all typed.

use super::train::{TrainJob, TrainOutcome};
use crate::Ctx;
use anyhow::Result;
use splat::train::TrainOptions;
use std::path::PathBuf;

/// What a pipeline needs back from one training run.
#[derive(Debug, Clone)]
pub struct VariantResult {
    /// Mean held-out PSNR / SSIM (NaN when nothing is held out).
    pub psnr: f64,
    pub ssim: f64,
    /// Mean held-out LPIPS-Alex, when its weights are found.
    pub lpips: Option<f64>,
    pub splats: usize,
    /// Wall time of the whole call (load, train, score, render).
    pub seconds: f64,
    /// (step, loss) samples.
    pub loss_curve: Vec<(f64, f64)>,
    /// (step, training PSNR) samples.
    pub psnr_curve: Vec<(f64, f64)>,
    /// Rendered held-out views (PNG paths), in evaluation order.
    pub renders: Vec<PathBuf>,
}

impl VariantResult {
    /// The report's view of a training outcome that took `seconds`.
    pub fn new(outcome: TrainOutcome, seconds: f64) -> Self {
        let (psnr, ssim) = outcome
            .test
            .as_ref()
            .map_or((f64::NAN, f64::NAN), |t| (t.mean_psnr, t.mean_ssim));
        VariantResult {
            psnr,
            ssim,
            lpips: outcome.test_lpips,
            splats: outcome.report.splats,
            seconds,
            loss_curve: outcome.loss_curve(),
            psnr_curve: outcome.psnr_curve(),
            renders: outcome.test_renders,
        }
    }
}

/// Training options for a short run: INRIA's schedule (SH degree +1 every
/// 1000 of 30k steps, densify from 500 every 100 until 15k, opacity reset
/// every 3000) compressed to `steps`, so a 300- or 2000-step run densifies
/// and reaches SH degree 3 too; splats capped at 20k (≤ 500 steps) or 60k so
/// a run stays within a CPU time budget. Everything else is the default.
pub fn short_schedule(steps: u32, use_masks: bool) -> TrainOptions {
    let s = steps.max(1);
    // Densify 4–8 times: each round needs view-space gradients accumulated
    // over many views, and more rounds multiply the splat count (and step
    // time) without a matching gain in a short run.
    let every = (s / 8).clamp(1, 250);
    let cap = if s <= 500 { 20_000 } else { 60_000 };
    let d = TrainOptions::default();
    let mut o = TrainOptions {
        steps: s,
        use_masks,
        sh_degree_every: (s / 8).max(1),
        strategy: splat::strategy::DefaultStrategyOptions {
            max_splats: cap,
            densify_from: every,
            densify_every: every,
            densify_until: s * 3 / 4,
            opacity_reset_every: 0,
            ..d.strategy
        },
        ..d
    };
    o.cap_mcmc_at_max_splats();
    o
}

/// Train `job` (its held-out renders go to `job.out/renders` unless the job
/// says where) and collect what the report needs.
pub fn train_and_eval(ctx: &Ctx, job: &TrainJob) -> Result<VariantResult> {
    let t0 = std::time::Instant::now();
    let mut job = job.clone();
    if job.test_renders.is_none() {
        job.test_renders = Some(job.out.join("renders"));
    }
    let outcome = super::train::train(&job, ctx)?;
    Ok(VariantResult::new(outcome, t0.elapsed().as_secs_f64()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_schedule_compresses_inria() {
        let o = short_schedule(800, true);
        assert_eq!(o.steps, 800);
        assert_eq!(o.strategy.densify_from, 100);
        assert_eq!(o.strategy.densify_every, 100);
        assert_eq!(o.strategy.densify_until, 600);
        assert_eq!(o.sh_degree_every, 100);
        assert_eq!(o.strategy.opacity_reset_every, 0);
        assert_eq!(o.strategy.max_splats, 60_000);
        assert!(o.validate().is_ok());
        let q = short_schedule(200, false);
        assert_eq!(q.strategy.max_splats, 20_000);
        assert!(!q.use_masks);
        // Long runs densify at most every 250 steps.
        assert_eq!(short_schedule(30_000, true).strategy.densify_every, 250);
    }
}
