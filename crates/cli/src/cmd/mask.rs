//! `romosplat mask --scene DIR [--out DIR]`: RoMo motion masks for a scene,
//! written as `masks/<image name>.png` (255 keep, 0 moving).

use crate::Ctx;
use anyhow::Context;
use std::path::{Path, PathBuf};

/// `romosplat mask ...`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene folder (with `images/`).
    #[arg(long)]
    pub scene: PathBuf,
    /// Output folder for `masks/` (default: the scene folder).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Rounds of fit → label → train (paper: 2).
    #[arg(long, default_value_t = 2)]
    pub iterations: usize,
    /// Also write `probabilities/<stem>.exr` (moving probability).
    #[arg(long)]
    pub save_probabilities: bool,
    /// Also write `motion/<name>.png` overlays.
    #[arg(long)]
    pub overlays: bool,
    /// ONNX feature encoder (XFeat layout), concatenated with the built-in
    /// features; needs a build with `--features romo/onnx` and ORT_DYLIB_PATH.
    #[arg(long)]
    pub onnx_features: Option<PathBuf>,
    /// ONNX optical-flow model instead of the built-in DIS: two [1, 3, H, W]
    /// RGB images in, a [1, 2, h, w] flow (or [1, 4, h, w]: forward, then
    /// backward) out, e.g. GMFlow from `scripts/export_gmflow_onnx.py`;
    /// frames are padded (or shrunk) to a fixed input size. Needs a build
    /// with `--features onnx` and ORT_DYLIB_PATH.
    #[arg(long)]
    pub onnx_flow: Option<PathBuf>,
    /// Pixel values in [0, 1] are multiplied by this for the flow model
    /// (255 for RAFT exports that take 0–255).
    #[arg(long, default_value_t = 1.0)]
    pub onnx_flow_scale: f32,
    /// Full options as JSON (a partial `RomoOptions`; flags above override).
    #[arg(long)]
    pub options: Option<PathBuf>,
    /// Integer downscale of the frames on load (masks are still written at
    /// the images' own size).
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// How each pair chooses between the fundamental matrix and a
    /// homography (the low-parallax case): inlier-ratio (default; H when it
    /// explains ≥ --h-inlier-ratio × F's inliers), gric (Torr 1998),
    /// fundamental (always F, the paper) or homography (always H).
    #[arg(long, value_enum)]
    pub model_selection: Option<romo::geometry::robust::ModelSelection>,
    /// For --model-selection inlier-ratio: H is chosen when its inliers reach
    /// this fraction of F's (default 0.9).
    #[arg(long)]
    pub h_inlier_ratio: Option<f64>,
    /// Use F instead of the homography choice when F still labels at least
    /// this fraction of a pair's points moving (default 0.005; 0 = off).
    #[arg(long)]
    pub f_informative_fraction: Option<f32>,
    /// Spread moving (U) labels along the flow to this many neighbouring
    /// frames (default 0 = off).
    #[arg(long)]
    pub u_propagation_frames: Option<usize>,
    /// Weight w of each neighbouring frame in the temporal smoothing of the
    /// probabilities, (1 − 2w)·H_t + w·(H_{t−1} + H_{t+1}) (default 0.25; 0 = off).
    #[arg(long)]
    pub temporal_weight: Option<f32>,
    /// Passes of the temporal smoothing (default 1).
    #[arg(long)]
    pub temporal_passes: Option<usize>,
    /// Leave the two chromaticity channels out of the built-in features.
    #[arg(long)]
    pub no_chromaticity: bool,
    /// Turn off the cheirality test (flow along the epipolar line that only
    /// a point behind the cameras could make counts as motion; on by default).
    #[arg(long)]
    pub no_cheirality: bool,
    /// Focal length ÷ image width for the cheirality test (default: the
    /// scene's intrinsics, else 1.2 × long side ÷ width, COLMAP's prior).
    #[arg(long)]
    pub focal_ratio: Option<f64>,
    /// Turn off the three-view depth-consistency test (a pixel whose depths
    /// from its forward and backward pairs disagree is moving; on by
    /// default).
    #[arg(long)]
    pub no_three_view: bool,
    /// Turn off region completion (a segment of the flow field mostly
    /// called moving becomes moving as a whole, except its confidently
    /// static pixels; on by default).
    #[arg(long)]
    pub no_region_completion: bool,
    /// Felzenszwalb–Huttenlocher scale k of those segments (default 4;
    /// larger merges more).
    #[arg(long)]
    pub region_k: Option<f32>,
    /// Object-level refinement: graph-cut (one minimum cut over all frames
    /// from the geometric evidence, the MLP, a colour model, image contrast
    /// and the flow; default) or off.
    #[arg(long, value_enum)]
    pub objects: Option<romo::objects::ObjectMethod>,
}

/// Run `romosplat mask`.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    let opts = options(args)?;
    let (report, copy) = segment_with_copy(&args.scene, args.downscale, &opts, true, ctx)?;
    let mut out = serde_json::to_value(&report)?;
    if let Some(c) = &copy {
        ctx.info(format!(
            "nerfstudio transforms.json with mask_path: {}",
            c.display()
        ));
    }
    out["transforms_with_masks"] = serde_json::json!(copy);
    Ok(out)
}

/// A `RomoOptions` JSON file (a partial one: missing fields keep their defaults).
pub fn read_options(path: &Path) -> anyhow::Result<romo::RomoOptions> {
    let s = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
    serde_json::from_str(&s).with_context(|| format!("{}: not a RomoOptions JSON", path.display()))
}

/// The RoMo options these flags select (`--options` file, then the flags).
pub fn options(args: &Args) -> anyhow::Result<romo::RomoOptions> {
    let mut opts: romo::RomoOptions = match &args.options {
        Some(p) => read_options(p)?,
        None => romo::RomoOptions::default(),
    };
    opts.iterations = args.iterations;
    opts.save_probabilities |= args.save_probabilities;
    opts.overlays |= args.overlays;
    opts.seed = args.seed;
    if let Some(m) = args.model_selection {
        opts.labels.robust.selection = m;
    }
    if let Some(r) = args.h_inlier_ratio {
        opts.labels.robust.h_inlier_ratio = r;
    }
    if let Some(f) = args.f_informative_fraction {
        opts.labels.f_informative_fraction = f;
    }
    if let Some(n) = args.u_propagation_frames {
        opts.labels.u_propagation_frames = n;
    }
    if let Some(w) = args.temporal_weight {
        opts.refine.temporal_weight = w;
    }
    if let Some(n) = args.temporal_passes {
        opts.refine.temporal_passes = n;
    }
    opts.chromaticity_features &= !args.no_chromaticity;
    opts.labels.cheirality &= !args.no_cheirality;
    if args.focal_ratio.is_some() {
        opts.focal_ratio = args.focal_ratio;
    }
    opts.regions.enabled &= !args.no_region_completion;
    opts.labels.three_view &= !args.no_three_view;
    if let Some(k) = args.region_k {
        opts.regions.k = k;
    }
    if let Some(m) = args.objects {
        opts.refine.objects.method = m;
    }
    if let Some(m) = &args.onnx_flow {
        opts.flow_backend = romo::FlowBackend::Onnx {
            model: m.clone(),
            input_scale: args.onnx_flow_scale,
        };
    }
    if let Some(m) = &args.onnx_features {
        opts.features = romo::FeatureBackend::Onnx { model: m.clone() };
    }
    if args.out.is_some() {
        opts.out = args.out.clone();
    }
    Ok(opts)
}

/// RoMo masks for the scene folder `scene_dir` (frames downscaled by
/// `downscale` on load), written where `opts.out` says (default the scene).
pub fn segment(
    scene_dir: &Path,
    downscale: u32,
    opts: &romo::RomoOptions,
    ctx: &Ctx,
) -> anyhow::Result<romo::RomoReport> {
    Ok(segment_with_copy(scene_dir, downscale, opts, false, ctx)?.0)
}

/// [`segment`], and with `nerfstudio_copy` also the scene's transforms.json
/// copy with every frame's `mask_path` ([`write_transforms_copy`]), staged
/// with the masks so that both appear or neither does. Returns the copy's
/// path when one was written.
fn segment_with_copy(
    scene_dir: &Path,
    downscale: u32,
    opts: &romo::RomoOptions,
    nerfstudio_copy: bool,
    ctx: &Ctx,
) -> anyhow::Result<(romo::RomoReport, Option<PathBuf>)> {
    let scene = loader::scene::Scene::load(scene_dir, &loader::scene::SceneOptions { downscale })
        .with_context(|| format!("loading scene {}", scene_dir.display()))?;
    // Masks (and overlays, probabilities) are staged and moved into place
    // together: a failure leaves no partial set behind.
    let out = opts.out.clone().unwrap_or_else(|| scene_dir.to_path_buf());
    let stage = loader::io::Staging::new(&out)?;
    let mut opts = opts.clone();
    opts.out = Some(stage.path().to_path_buf());
    ctx.info(format!(
        "romo: {} frames from {}",
        scene.frames.len(),
        scene_dir.display()
    ));
    let pb = ctx.progress(scene.frames.len() as u64, "mask");
    // Errors name the output folder, not the hidden staging folder.
    let staged = (|| -> anyhow::Result<_> {
        let report = romo::segment_scene(&scene, &opts, &|stage, done, total| {
            pb.set_message(stage.to_string());
            pb.set_length(total as u64);
            pb.set_position(done as u64);
        })?;
        pb.finish_and_clear();
        let copy = if nerfstudio_copy {
            write_transforms_copy(scene_dir, &out, stage.path())?
        } else {
            None
        };
        Ok((report, copy))
    })();
    let (report, copy) = staged.map_err(|e| anyhow::anyhow!(stage.public(&format!("{e:#}"))))?;
    stage.commit()?;
    let mut report = report;
    report.masks_dir = Some(out.join("masks"));
    for w in &report.warnings {
        ctx.info(format!("warning: {w}"));
    }
    let moving: f32 = report.frames.iter().map(|f| f.moving_fraction).sum::<f32>()
        / report.frames.len().max(1) as f32;
    ctx.info(format!(
        "masks in {} ({} frames, {:.1}% moving on average, {} dropped from training)",
        report
            .masks_dir
            .as_deref()
            .map(|p| p.display().to_string())
            .unwrap_or_default(),
        report.frames.len(),
        100.0 * moving,
        report.dropped_frames.len()
    ));
    Ok((report, copy))
}

/// When the scene has a transforms.json, write a copy with every frame's
/// nerfstudio `mask_path` set to its mask into the mask output folder `out`
/// (`loader::transforms::write_with_masks_staged`: images outside it are
/// linked into it, the user's transforms.json is never replaced), through
/// the staging folder `stage` of `out`.
fn write_transforms_copy(
    scene: &Path,
    out: &Path,
    stage: &Path,
) -> anyhow::Result<Option<PathBuf>> {
    let src = scene.join("transforms.json");
    if !src.is_file() {
        return Ok(None);
    }
    Ok(Some(loader::transforms::write_with_masks_staged(
        &src,
        scene,
        out,
        &out.join("masks"),
        stage,
    )?))
}
