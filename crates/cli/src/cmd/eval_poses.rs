//! `romosplat eval poses --pred PATH --gt PATH`: ATE / RPE of a camera
//! trajectory against ground truth, evo's conventions (see `pose::metrics`).

use crate::Ctx;
use anyhow::Context;
use pose::metrics::{Alignment, PoseMetricsOptions, evaluate};
use pose::trajectory::load_trajectory;
use std::path::PathBuf;

/// Alignment choice on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum AlignArg {
    /// Rotation, translation and scale (`evo_ape -as`).
    Sim3,
    /// Rotation and translation (`evo_ape -a`).
    Se3,
    /// None.
    None,
}

/// `romosplat eval poses ...`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Predicted poses: COLMAP model folder, scene folder or transforms.json.
    #[arg(long)]
    pub pred: PathBuf,
    /// Ground-truth poses: COLMAP model folder, scene folder or transforms.json.
    #[arg(long)]
    pub gt: PathBuf,
    /// Alignment estimated on camera centres before scoring.
    #[arg(long, value_enum, default_value = "sim3")]
    pub align: AlignArg,
    /// RPE frame delta.
    #[arg(long, default_value_t = 1)]
    pub delta: usize,
}

/// Run `romosplat eval poses`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let (pred, pred_src) =
        load_trajectory(&args.pred).with_context(|| "reading the predicted poses".to_string())?;
    let (gt, gt_src) =
        load_trajectory(&args.gt).with_context(|| "reading the ground-truth poses".to_string())?;
    let opts = PoseMetricsOptions {
        alignment: match args.align {
            AlignArg::Sim3 => Alignment::Sim3,
            AlignArg::Se3 => Alignment::Se3,
            AlignArg::None => Alignment::None,
        },
        delta: args.delta,
    };
    let m = evaluate(&pred, &gt, &opts)?;
    ctx.info(format!(
        "registered {}/{}{}",
        m.registered,
        m.total,
        if m.missing.is_empty() {
            String::new()
        } else {
            format!(" — missing: {}", m.missing.join(", "))
        }
    ));
    ctx.info(format!(
        "ATE (RMSE, {:?}-aligned): {:.6}   ({:.3}% of the {:.4} path; scale {:.6})",
        m.alignment,
        m.ate.rmse,
        100.0 * m.ate.rmse / m.gt_path_length.max(f64::MIN_POSITIVE),
        m.gt_path_length,
        m.sim3.scale
    ));
    if let (Some(t), Some(r)) = (&m.rpe_trans, &m.rpe_rot_deg) {
        ctx.info(format!(
            "RPE (delta {}, {} pairs): translation RMSE {:.6}, rotation RMSE {:.4}°",
            m.delta, t.count, t.rmse, r.rmse
        ));
    }
    let mut v = serde_json::to_value(&m)?;
    if let serde_json::Value::Object(map) = &mut v {
        map.insert("pred_source".into(), serde_json::to_value(&pred_src)?);
        map.insert("gt_source".into(), serde_json::to_value(&gt_src)?);
    }
    Ok(v)
}
