//! `romosplat eval views --splats F --scene DIR [--split extra] [--mask-gt]`:
//! PSNR and SSIM (11×11 Gaussian window, σ = 1.5, as scikit-image / INRIA)
//! per image and mean, optionally excluding ground-truth moving pixels.

use super::train::make_backend;
use crate::Ctx;
use splat::train::data::load_views;
use splat::train::eval::evaluate;
use splat::types::RenderOptions;

/// `romosplat eval views`
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub views: super::render::ViewArgs,
    /// Exclude ground-truth moving pixels (gt_motion/) from the metrics.
    #[arg(long)]
    pub mask_gt: bool,
}

pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let (splats, scene, idx) = args.views.load()?;
    let mut views = load_views(&scene, &idx, false)?;
    let mut masked = 0;
    if args.mask_gt {
        for v in &mut views {
            if let Some(m) = scene.load_gt_motion(v.index)? {
                v.mask = Some(
                    m.into_raw()
                        .into_iter()
                        .map(|x| if x >= 128 { 0.0 } else { 1.0 })
                        .collect(),
                );
                masked += 1;
            }
        }
    }
    let mut backend = make_backend(args.views.backend, ctx)?;
    let opts = RenderOptions {
        sh_degree: splats.sh_degree,
        ..Default::default()
    };
    let (rep, _) = evaluate(backend.as_mut(), &splats, &views, &opts)?;
    for v in &rep.views {
        ctx.info(format!(
            "{:<24} PSNR {:6.2}  SSIM {:.4}",
            v.name, v.psnr, v.ssim
        ));
    }
    ctx.info(format!(
        "mean ({} views, {masked} with GT motion excluded): PSNR {:.2}  SSIM {:.4}",
        rep.views.len(),
        rep.mean_psnr,
        rep.mean_ssim
    ));
    let mut v = serde_json::to_value(&rep)?;
    v["split"] = serde_json::json!(args.views.split);
    v["mask_gt_views"] = serde_json::json!(masked);
    Ok(v)
}
