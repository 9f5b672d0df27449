//! `romosplat keyframes --scene DIR --out DIR`: drop frames without texture,
//! blurry frames and near-duplicates of a video's frames (see `crate::keyframes`); `OUT/images`
//! and `OUT/masks` link the kept frames and their masks.

use crate::Ctx;
use crate::keyframes::{KeyframeOptions, link_keyframes, select_keyframes};
use std::path::PathBuf;

/// `romosplat keyframes`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene folder with `images/` (and `masks/`: static pixels only count
    /// towards parallax).
    #[arg(long)]
    pub scene: PathBuf,
    /// Folder for the links to the kept frames (`images/`, `masks/`).
    #[arg(long)]
    pub out: PathBuf,
    /// Smallest parallax to the last kept frame, fraction of the diagonal.
    #[arg(long, default_value_t = 0.01)]
    pub min_parallax: f64,
    /// Blurry below this fraction of the neighbours' median sharpness.
    #[arg(long, default_value_t = 0.5)]
    pub blur_ratio: f64,
    /// Keep at least every Nth frame.
    #[arg(long, default_value_t = 4)]
    pub max_gap: usize,
}

/// Run `romosplat keyframes`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    anyhow::ensure!(
        args.min_parallax >= 0.0 && args.blur_ratio >= 0.0 && args.max_gap >= 1,
        "--min-parallax and --blur-ratio must be ≥ 0 and --max-gap ≥ 1"
    );
    let images = args.scene.join("images");
    let names = loader::scene::list_images(&images)?;
    let masks = args.scene.join("masks");
    let masks = masks.is_dir().then_some(masks);
    let opts = KeyframeOptions {
        min_parallax: args.min_parallax,
        blur_ratio: args.blur_ratio,
        max_gap: args.max_gap,
        ..KeyframeOptions::default()
    };
    let k = select_keyframes(&images, masks.as_deref(), &names, &opts)?;
    link_keyframes(&args.scene, &k.kept, &args.out)?;
    ctx.info(format!(
        "kept {} of {} frames ({} dropped) → {}",
        k.kept.len(),
        names.len(),
        k.dropped(),
        args.out.display()
    ));
    Ok(serde_json::to_value(&k)?)
}
