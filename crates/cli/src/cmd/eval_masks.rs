//! `romosplat eval masks --pred DIR --gt DIR [--scene DIR]`: DAVIS J
//! (per-frame IoU, mean, recall, decay) and pixel precision / recall of
//! predicted motion masks; `--scene` leaves out its held-out `extra` views.

use crate::Ctx;
use std::path::PathBuf;

/// `romosplat eval masks ...`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Predictions: a `masks/` folder (255 keep), a scene folder containing
    /// one, or 255-is-moving PNGs; or a folder of per-sequence folders.
    #[arg(long)]
    pub pred: PathBuf,
    /// Ground truth, 255 = moving (`gt_motion/`, or DAVIS `Annotations/480p[/seq]`).
    #[arg(long)]
    pub gt: PathBuf,
    /// A scene folder whose split.json `extra` views (held-out clean test
    /// views) are left out: their all-keep masks and empty ground truth
    /// would each count as a perfect frame (J = 1).
    #[arg(long)]
    pub scene: Option<PathBuf>,
}

/// Run `romosplat eval masks`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let exclude: Vec<String> = match &args.scene {
        Some(dir) => {
            let scene = loader::scene::Scene::load(dir, &Default::default())?;
            romo::held_out_stems(&scene)
        }
        None => Vec::new(),
    };
    if !exclude.is_empty() {
        ctx.info(format!(
            "leaving out {} held-out view(s) listed as `extra` in split.json",
            exclude.len()
        ));
    }
    let m = romo::metrics::evaluate_masks_excluding(&args.pred, &args.gt, &exclude)?;
    for s in &m.sequences {
        ctx.info(format!(
            "{:<16} frames {:>4}  J {:.3}  J-recall {:.3}  decay {:+.3}  precision {:.3}  recall {:.3}  (read predictions as {})",
            if s.name.is_empty() { "-" } else { &s.name },
            s.frames,
            s.j_mean,
            s.j_recall,
            s.j_decay,
            s.precision,
            s.recall,
            s.pred_convention
        ));
    }
    if m.sequences.len() > 1 {
        ctx.info(format!(
            "{:<16} J {:.3}  precision {:.3}  recall {:.3}",
            "mean", m.j_mean, m.precision, m.recall
        ));
    }
    Ok(serde_json::to_value(&m)?)
}
