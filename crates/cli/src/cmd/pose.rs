//! `romosplat pose --scene DIR`: camera poses with COLMAP, ignoring moving
//! pixels through the scene's motion masks (see `pose::colmap_runner`).

use crate::Ctx;
use anyhow::Context;
use pose::colmap_runner::{ColmapOptions, ColmapPaths, Matcher, Progress, run_colmap};
use pose::metrics::{PoseMetricsOptions, evaluate};
use std::path::PathBuf;

/// Matcher choice on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum MatcherArg {
    /// Videos: each frame against the next `--overlap` frames.
    Sequential,
    /// Photo collections: every pair.
    Exhaustive,
}

/// `romosplat pose ...`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene folder (`images/`, `masks/`).
    #[arg(long)]
    pub scene: PathBuf,
    /// Run COLMAP without masks.
    #[arg(long)]
    pub no_masks: bool,
    /// Masks folder (`<image name>.png`, 255 keep, 0 ignore); default `scene/masks`.
    #[arg(long, conflicts_with = "no_masks")]
    pub masks: Option<PathBuf>,
    /// Use the scene's ground-truth motion (`gt_motion/`) as masks (oracle
    /// run; written to `<work>/gt_masks`).
    #[arg(long, conflicts_with_all = ["no_masks", "masks"])]
    pub gt_masks: bool,
    /// Images folder; default `scene/images`.
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Pair selection.
    #[arg(long, value_enum, default_value = "sequential")]
    pub matcher: MatcherArg,
    /// COLMAP camera model (SIMPLE_RADIAL, OPENCV, PINHOLE, RADIAL, ...).
    #[arg(long, default_value = "SIMPLE_RADIAL")]
    pub camera_model: String,
    /// One camera per image instead of one shared camera (photo collections).
    #[arg(long)]
    pub per_image_cameras: bool,
    /// Sequential matching overlap, frames.
    #[arg(long, default_value_t = 10)]
    pub overlap: u32,
    /// Longest image side used for SIFT, pixels.
    #[arg(long, default_value_t = 3200)]
    pub max_image_size: u32,
    /// COLMAP threads (-1 = all cores).
    #[arg(long, default_value_t = -1, allow_hyphen_values = true)]
    pub threads: i32,
    /// COLMAP's random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Do not write an undistorted PINHOLE copy.
    #[arg(long)]
    pub no_undistort: bool,
    /// Output model folder; default `scene/sparse/0` (replaced).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Work folder (database, raw models, COLMAP logs); default `scene/colmap`.
    #[arg(long)]
    pub work: Option<PathBuf>,
    /// Undistorted copy folder; default `scene/undistorted`.
    #[arg(long)]
    pub undistorted: Option<PathBuf>,
    /// Also score the result against ground-truth poses (COLMAP model or
    /// transforms.json; read before the run, so `scene/sparse/0` works).
    #[arg(long)]
    pub gt: Option<PathBuf>,
    /// The colmap executable.
    #[arg(long, default_value = "colmap")]
    pub colmap: PathBuf,
}

/// Run `romosplat pose`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let camera_model = loader::CameraModel::from_name(&args.camera_model)
        .ok_or_else(|| anyhow::anyhow!("unknown COLMAP camera model `{}`", args.camera_model))?;
    let mut paths = ColmapPaths::for_scene(&args.scene);
    if let Some(p) = &args.images {
        paths.images = p.clone();
    }
    if let Some(p) = &args.masks {
        paths.masks = p.clone();
    }
    if let Some(p) = &args.out {
        paths.out = p.clone();
    }
    if let Some(p) = &args.work {
        paths.work = p.clone();
    }
    if let Some(p) = &args.undistorted {
        paths.undistorted = p.clone();
    }
    let opts = ColmapOptions {
        colmap: args.colmap.clone(),
        matcher: match args.matcher {
            MatcherArg::Sequential => Matcher::Sequential,
            MatcherArg::Exhaustive => Matcher::Exhaustive,
        },
        camera_model,
        single_camera: !args.per_image_cameras,
        use_masks: !args.no_masks,
        overlap: args.overlap,
        max_image_size: args.max_image_size,
        threads: args.threads,
        seed: args.seed,
        undistort: !args.no_undistort,
        ..ColmapOptions::default()
    };
    opts.validate()?;
    let gt = match &args.gt {
        Some(p) => Some(pose::trajectory::load_trajectory(p)?.0),
        None => None,
    };
    if args.gt_masks {
        let dir = paths.work.join("gt_masks");
        let (n, from_gt) = pose::gt_masks::masks_from_gt_motion(
            &paths.images,
            &args.scene.join("gt_motion"),
            &dir,
        )?;
        anyhow::ensure!(
            from_gt > 0,
            "{}: no ground-truth motion masks found",
            args.scene.join("gt_motion").display()
        );
        ctx.info(format!(
            "ground-truth masks: {n} written ({from_gt} from gt_motion) to {}",
            dir.display()
        ));
        paths.masks = dir;
    }
    ctx.info(format!(
        "COLMAP on {} ({}, {}, masks: {})",
        paths.images.display(),
        args.camera_model,
        match opts.matcher {
            Matcher::Sequential => "sequential",
            Matcher::Exhaustive => "exhaustive",
        },
        if opts.use_masks {
            paths.masks.display().to_string()
        } else {
            "off".into()
        }
    ));

    let mut bar: Option<indicatif::ProgressBar> = None;
    let mut on_progress = |p: Progress| match p {
        Progress::Started { step, index, of } => {
            let pb = ctx.progress(0, &step);
            pb.set_message(format!("step {}/{of}", index + 1));
            bar = Some(pb);
        }
        Progress::Line { line, .. } => {
            if let Some(pb) = &bar {
                if let Some((i, n)) = bracket_fraction(&line) {
                    pb.set_length(n);
                    pb.set_position(i);
                } else {
                    pb.set_message(line);
                }
            }
        }
        Progress::Finished { step, seconds } => {
            if let Some(pb) = bar.take() {
                pb.finish_and_clear();
            }
            ctx.info(format!("  {step}: {seconds:.1} s"));
        }
    };
    let report = run_colmap(&paths, &opts, &mut on_progress)
        .with_context(|| format!("pose stage on {}", args.scene.display()))?;
    ctx.info(format!(
        "registered {}/{} images, {} points, mean reprojection error {:.3} px, {:.1} s; model in {}",
        report.registered,
        report.total,
        report.points,
        report.mean_reprojection_error,
        report.total_seconds,
        report.model_dir.display()
    ));
    if !report.left_out.is_empty() {
        ctx.info(format!("left out: {}", report.left_out.join(", ")));
    }
    if report.models_found > 1 {
        ctx.info(format!(
            "COLMAP made {} models ({:?} images); kept the largest",
            report.models_found, report.model_sizes
        ));
    }
    let mut value = serde_json::to_value(&report)?;
    if let Some(gt) = gt {
        let pred = pose::trajectory::from_colmap(&paths.out)?;
        let m = evaluate(&pred, &gt, &PoseMetricsOptions::default())?;
        ctx.info(format!(
            "vs ground truth: ATE {:.5} (path length {:.3}), RPE-T {:.5}, RPE-R {:.4}°, {}/{} matched",
            m.ate.rmse,
            m.gt_path_length,
            m.rpe_trans.as_ref().map_or(f64::NAN, |s| s.rmse),
            m.rpe_rot_deg.as_ref().map_or(f64::NAN, |s| s.rmse),
            m.registered,
            m.total
        ));
        if let serde_json::Value::Object(map) = &mut value {
            map.insert("metrics".into(), serde_json::to_value(&m)?);
        }
    }
    Ok(value)
}

/// `[i/n]` in a COLMAP progress line.
fn bracket_fraction(line: &str) -> Option<(u64, u64)> {
    let inner = line.split('[').nth(1)?.split(']').next()?;
    let (i, n) = inner.split_once('/')?;
    Some((i.trim().parse().ok()?, n.trim().parse().ok()?))
}
