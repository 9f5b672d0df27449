//! `romosplat export --splats F --format ply|splat|glb|spz [--clean] [--scene DIR] --out FILE`:
//! convert a trained splat file to the formats other tools read, optionally
//! cleaning it first (see `splat::export::clean`).

use crate::Ctx;
use splat::export::{self, CleanOptions, ExportFormat, ExportOptions, SceneGeometry};
use std::path::{Path, PathBuf};

/// `romosplat export`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input splats: .ply (INRIA layout), .spz, .splat or .glb.
    #[arg(long)]
    pub splats: PathBuf,
    /// Output format; must match the extension of --out, which alone decides it when absent.
    #[arg(long, value_enum)]
    pub format: Option<ExportFormat>,
    /// Output file (written atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Remove near-transparent, unseen, oversized and out-of-bounds splats first.
    #[arg(long)]
    pub clean: bool,
    /// Scene folder (or COLMAP model folder) whose cameras and points3D the
    /// clean pass uses; without it the "unseen" test is skipped and the bounds
    /// come from the splats.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Clean: minimum opacity after the sigmoid (INRIA prune threshold).
    #[arg(long, default_value_t = CleanOptions::default().min_opacity)]
    pub min_opacity: f32,
    /// Clean: remove splats whose largest σ exceeds this × the median.
    #[arg(long, default_value_t = CleanOptions::default().max_scale_over_median)]
    pub max_scale_over_median: f32,
    /// Clean: remove splats whose 3σ radius in the nearest training camera
    /// exceeds this × the image's larger side (0 = off; needs --scene).
    #[arg(long, default_value_t = CleanOptions::default().max_footprint)]
    pub max_footprint: f32,
    /// Clean: remove splats whose largest σ exceeds this × the scene extent
    /// (INRIA's big_points_ws uses 0.1; 0 = off).
    #[arg(long, default_value_t = CleanOptions::default().max_scale_extent_fraction)]
    pub max_scale_extent_fraction: f32,
    /// Clean: grow the robust (1st–99th percentile) box by this fraction per side.
    #[arg(long, default_value_t = CleanOptions::default().bounds_margin)]
    pub bounds_margin: f32,
    /// SPZ: format version to write (2 or 3).
    #[arg(long, default_value_t = 3)]
    pub spz_version: u32,
    /// Keep COLMAP's y-down axes in .glb/.spz instead of rotating to their y-up frame.
    #[arg(long)]
    pub keep_axes: bool,
}

/// The output format: the extension of `out`, which `--format` (when
/// given) must agree with, so every file we write is named for what it holds
/// and `inspect` / `export --splats` can read it back.
pub fn output_format(out: &Path, flag: Option<ExportFormat>) -> anyhow::Result<ExportFormat> {
    let is_dir_like = out.as_os_str().to_string_lossy().ends_with('/') || out.is_dir();
    if is_dir_like {
        anyhow::bail!(
            "{}: is a folder; --out takes a file path such as {}",
            out.display(),
            out.join("splats.spz").display()
        );
    }
    match (ExportFormat::from_path(out), flag) {
        (Some(ext), Some(f)) if ext != f => anyhow::bail!(
            "{}: the extension says {ext} but --format is {f}; use a .{f} file name",
            out.display()
        ),
        (Some(ext), _) => Ok(ext),
        (None, Some(f)) => anyhow::bail!(
            "{}: the file name must end in .{f} for --format {f}",
            out.display()
        ),
        (None, None) => anyhow::bail!(
            "{}: unknown extension (expected .ply, .splat, .glb or .spz)",
            out.display()
        ),
    }
}

/// Training cameras and static points of `--scene`: a scene folder (poses
/// from sparse/0 or transforms.json) or a bare COLMAP model folder.
fn scene_geometry(dir: &Path) -> anyhow::Result<SceneGeometry> {
    if loader::colmap::detect_format(dir).is_some() {
        let model = loader::colmap::read_model(dir)?;
        return Ok(SceneGeometry::from_colmap(&model));
    }
    let scene = loader::scene::Scene::load(dir, &loader::scene::SceneOptions::default())?;
    let geo = SceneGeometry::from_scene(&scene);
    if geo.cameras.is_empty() {
        anyhow::bail!("{}: the scene has no posed training frames", dir.display());
    }
    Ok(geo)
}

/// An export, typed: what [`export_splats`] needs.
#[derive(Debug, Clone)]
pub struct ExportJob {
    /// Input splats (.ply, .spz or .splat).
    pub splats: PathBuf,
    pub format: ExportFormat,
    /// Output file (written atomically).
    pub out: PathBuf,
    /// Clean first with these options.
    pub clean: Option<CleanOptions>,
    /// Scene or COLMAP model folder for the clean pass's cameras and points.
    pub scene: Option<PathBuf>,
    pub options: ExportOptions,
}

/// What [`export_splats`] wrote.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ExportOutcome {
    pub export: export::ExportSummary,
    pub clean: Option<export::CleanReport>,
}

/// Run `romosplat export`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    Ok(serde_json::to_value(export_splats(&args.job()?, ctx)?)?)
}

impl Args {
    /// The typed job these flags describe.
    pub fn job(&self) -> anyhow::Result<ExportJob> {
        let args = self;
        let format = output_format(&args.out, args.format)?;
        let mut options = ExportOptions::default();
        options.spz.version = args.spz_version;
        options.spz.convert_axes = !args.keep_axes;
        options.glb.to_gltf_axes = !args.keep_axes;
        Ok(ExportJob {
            splats: args.splats.clone(),
            format,
            out: args.out.clone(),
            clean: args.clean.then(|| CleanOptions {
                min_opacity: args.min_opacity,
                max_scale_over_median: args.max_scale_over_median,
                max_scale_extent_fraction: args.max_scale_extent_fraction,
                max_footprint: args.max_footprint,
                bounds_margin: args.bounds_margin,
                ..CleanOptions::default()
            }),
            scene: args.scene.clone(),
            options,
        })
    }
}

/// Read, optionally clean, and write splats.
pub fn export_splats(job: &ExportJob, ctx: &Ctx) -> anyhow::Result<ExportOutcome> {
    let mut splats = splat::io::read_splats(&job.splats)?;
    ctx.info(format!(
        "read {} splats (SH degree {}) from {}",
        splats.len(),
        splats.sh_degree,
        job.splats.display()
    ));
    let mut clean_report = None;
    if let Some(opts) = &job.clean {
        let scene = match &job.scene {
            Some(dir) => scene_geometry(dir)?,
            None => SceneGeometry::default(),
        };
        let (kept, rep) = export::clean(&splats, &scene, opts)?;
        ctx.info(format!(
            "clean: kept {} of {}; removed {} transparent, {} unseen{}, {} oversized, {} outside bounds ({})",
            rep.kept,
            rep.input,
            rep.removed_transparent,
            rep.removed_unseen,
            if rep.unseen_checked {
                format!(" by {} cameras", rep.cameras)
            } else {
                " (skipped: no --scene)".into()
            },
            rep.removed_oversized,
            rep.removed_outside_bounds,
            rep.bounds_source
        ));
        splats = kept;
        clean_report = Some(rep);
    }
    let summary = export::export(&splats, job.format, &job.out, &job.options)?;
    ctx.info(format!(
        "wrote {} splats as {} to {} ({} bytes, {:.1} bytes/splat)",
        summary.splats,
        job.format,
        summary.path.display(),
        summary.bytes,
        summary.bytes as f64 / summary.splats.max(1) as f64
    ));
    Ok(ExportOutcome {
        export: summary,
        clean: clean_report,
    })
}
