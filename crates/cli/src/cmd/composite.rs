//! `romosplat scene composite --background DIR --distractors DAVIS --out DIR`:
//! a real-image NeRF On-the-go-style scene — moving DAVIS objects cut out
//! with their ground-truth masks and pasted onto a static capture's frames
//! (see `loader::composite`). Every 8th view stays clean (`extra`).

use crate::Ctx;
use anyhow::Context;
use loader::composite::{CompositeOptions, composite};
use std::path::PathBuf;

/// `romosplat scene composite`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Background scene folder with images/ and transforms.json (e.g. fox).
    #[arg(long)]
    pub background: PathBuf,
    /// DAVIS root (JPEGImages/480p/<seq>, Annotations/480p/<seq>).
    #[arg(long)]
    pub distractors: PathBuf,
    /// Output scene folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Integer downscale of the background frames.
    #[arg(long, default_value_t = 4)]
    pub downscale: u32,
    /// Hold out every N-th view (index % N == 0) as a clean test view.
    #[arg(long, default_value_t = 8)]
    pub test_every: usize,
    /// Consecutive frames sharing one DAVIS object.
    #[arg(long, default_value_t = 6)]
    pub run_length: usize,
    /// Comma-separated DAVIS sequences (default: all).
    #[arg(long, value_delimiter = ',')]
    pub sequences: Vec<String>,
    /// Seed for sequence order, object sizes and paths.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The camera follows each object: its box stays at one place in the
    /// image for its run while the background moves (a video that tracks a
    /// runner or a car).
    #[arg(long)]
    pub follow: bool,
    /// Objects pasted into each clutter frame, each with its own sequence,
    /// size and path (heavier clutter: 3 or more).
    #[arg(long, default_value_t = 1)]
    pub objects_per_frame: usize,
    /// Pasted object height as a fraction of the frame height, drawn per
    /// run from MIN,MAX.
    #[arg(long, value_delimiter = ',', default_values_t = [0.3, 0.55])]
    pub object_height: Vec<f64>,
}

pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let &[lo, hi] = args.object_height.as_slice() else {
        anyhow::bail!(
            "--object-height takes MIN,MAX, got {} values",
            args.object_height.len()
        );
    };
    let opts = CompositeOptions {
        downscale: args.downscale,
        test_every: args.test_every,
        run_length: args.run_length,
        sequences: args.sequences.clone(),
        seed: args.seed,
        follow: args.follow,
        objects_per_frame: args.objects_per_frame,
        object_height: [lo, hi],
        ..Default::default()
    };
    let t0 = std::time::Instant::now();
    let rep =
        composite(&args.background, &args.distractors, &args.out, &opts).with_context(|| {
            format!(
                "compositing {} onto {}",
                args.distractors.display(),
                args.background.display()
            )
        })?;
    ctx.info(format!(
        "wrote {} frames ({} clutter with distractors, {} clean extra) at {}x{} to {} in {:.1} s; \
         distractors cover {:.1}% of a clutter frame on average ({:.1}–{:.1}%)",
        rep.frames,
        rep.clutter,
        rep.extra,
        rep.width,
        rep.height,
        args.out.display(),
        t0.elapsed().as_secs_f64(),
        100.0 * rep.coverage_mean,
        100.0 * rep.coverage_min,
        100.0 * rep.coverage_max
    ));
    let mut v = serde_json::to_value(&rep)?;
    v["options"] = serde_json::to_value(&opts)?;
    Ok(v)
}
