//! `romosplat pose --scene DIR`: camera poses with COLMAP, ignoring moving
//! pixels through the scene's motion masks (see `pose::colmap_runner`).

use crate::Ctx;
use anyhow::Context;
use pose::colmap_runner::{
    ColmapOptions, ColmapPaths, MapperOptions, Matcher, Progress, run_colmap,
};
use pose::metrics::{PoseMetricsOptions, evaluate};
use std::path::PathBuf;

/// Mapper settings on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MapperPreset {
    /// COLMAP's own defaults.
    Colmap,
    /// COLMAP's video preset with its low-quality bundle-adjustment bounds
    /// (`automatic_reconstructor --data_type video --quality low`).
    Video,
}

/// COLMAP options shared by `pose`, `run` and `demo`. Each is optional:
/// unset keeps the command's default (in `run`: the plan's choice).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct PoseOpts {
    /// COLMAP pair selection.
    #[arg(long, value_enum)]
    pub matcher: Option<Matcher>,
    /// COLMAP camera model (SIMPLE_RADIAL, OPENCV, PINHOLE, RADIAL, ...).
    #[arg(long)]
    pub camera_model: Option<String>,
    /// Most SIFT features per image [pose default: 8192].
    #[arg(long)]
    pub pose_features: Option<u32>,
    /// Sequential matching: frames matched after each frame [pose default: 10].
    #[arg(long, alias = "overlap")]
    pub pose_overlap: Option<u32>,
    /// Longest image side used for SIFT, pixels [pose default: 3200].
    #[arg(long, alias = "max-image-size")]
    pub pose_max_image_size: Option<u32>,
    /// Give COLMAP every Nth frame [pose default: 1].
    #[arg(long)]
    pub pose_stride: Option<usize>,
    /// Mapper settings [pose default: colmap].
    #[arg(long, value_enum)]
    pub mapper_preset: Option<MapperPreset>,
    /// The colmap executable [default: colmap on PATH].
    #[arg(long)]
    pub colmap: Option<PathBuf>,
}

impl PoseOpts {
    /// Apply the options that were given onto `base`.
    pub fn apply(&self, base: &mut ColmapOptions) -> anyhow::Result<()> {
        if let Some(m) = self.matcher {
            base.matcher = m;
        }
        if let Some(name) = &self.camera_model {
            base.camera_model = loader::CameraModel::from_name(name)
                .ok_or_else(|| anyhow::anyhow!("unknown COLMAP camera model `{name}`"))?;
        }
        if let Some(v) = self.pose_features {
            base.max_num_features = v;
        }
        if let Some(v) = self.pose_overlap {
            base.overlap = v;
        }
        if let Some(v) = self.pose_max_image_size {
            base.max_image_size = v;
        }
        if let Some(v) = self.pose_stride {
            base.stride = v;
        }
        if let Some(p) = self.mapper_preset {
            base.mapper = match p {
                MapperPreset::Colmap => MapperOptions::default(),
                MapperPreset::Video => MapperOptions::video(),
            };
        }
        if let Some(c) = &self.colmap {
            base.colmap = c.clone();
        }
        base.validate()?;
        Ok(())
    }
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
    #[command(flatten)]
    pub colmap_opts: PoseOpts,
    /// One camera per image instead of one shared camera (photo collections).
    #[arg(long)]
    pub per_image_cameras: bool,
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
    /// The database is kept and reused by a rerun on the same inputs.
    #[arg(long)]
    pub work: Option<PathBuf>,
    /// Undistorted copy folder; default `scene/undistorted`.
    #[arg(long)]
    pub undistorted: Option<PathBuf>,
    /// Also score the result against ground-truth poses (COLMAP model or
    /// transforms.json; read before the run, so `scene/sparse/0` works).
    #[arg(long)]
    pub gt: Option<PathBuf>,
}

/// Run `romosplat pose`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
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
    let mut opts = ColmapOptions {
        single_camera: !args.per_image_cameras,
        use_masks: !args.no_masks,
        threads: args.threads,
        seed: args.seed,
        undistort: !args.no_undistort,
        ..ColmapOptions::default()
    };
    args.colmap_opts.apply(&mut opts)?;
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
    let report = colmap(&paths, &opts, ctx)
        .with_context(|| format!("pose stage on {}", args.scene.display()))?;
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

/// Run COLMAP on `paths` with `opts`, showing its progress, and say how it went.
pub fn colmap(
    paths: &ColmapPaths,
    opts: &ColmapOptions,
    ctx: &Ctx,
) -> anyhow::Result<pose::ColmapReport> {
    ctx.info(format!(
        "COLMAP on {} ({}, {}, masks: {})",
        paths.images.display(),
        opts.camera_model.name(),
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

    let mut bar: Option<crate::ctx::Progress> = None;
    let mut on_progress = |p: Progress| match p {
        Progress::Started { step, index, of } => {
            let pb = ctx.progress(0, &step);
            pb.set_message(format!("step {}/{of}", index + 1));
            bar = Some(pb);
        }
        Progress::Count { count, .. } => {
            if let Some(pb) = &bar {
                if let Some(n) = count.total {
                    pb.set_length(n);
                }
                pb.set_position(count.done);
                pb.set_message(count.unit.name());
            }
        }
        Progress::Note { step, message } => ctx.info(format!("  {step}: {message}")),
        Progress::Finished { step, seconds } => {
            if let Some(pb) = bar.take() {
                pb.finish_and_clear();
            }
            ctx.info(format!("  {step}: {seconds:.1} s"));
        }
    };
    let report = run_colmap(paths, opts, &mut on_progress)?;
    ctx.info(format!(
        "registered {}/{} images, {} points, mean reprojection error {:.3} px, {:.1} s; model in {}",
        report.registered,
        report.total,
        report.model.points,
        report.model.mean_reprojection_error,
        report.total_seconds,
        report.model_dir.display()
    ));
    if report.features_reused > 0 {
        ctx.info(format!(
            "features of {} images reused from the kept database",
            report.features_reused
        ));
    }
    if !report.left_out.is_empty() {
        ctx.info(format!("left out: {}", report.left_out.join(", ")));
    }
    if report.models_found > 1 {
        ctx.info(format!(
            "COLMAP made {} models ({:?} images); kept the largest",
            report.models_found, report.model_sizes
        ));
    }
    Ok(report)
}
