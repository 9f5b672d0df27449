//! `romosplat demo`: the whole pipeline on the built-in demo scene, with the
//! comparison the paper is about. It generates the scene, computes RoMo masks
//! (J against the exact ground truth), runs COLMAP without masks, with RoMo
//! masks and with ground-truth masks (ATE against the generator's poses), and
//! trains four splats on the same (ground-truth) poses — (a) no masks, (b)
//! RoMo masks, (c) ground-truth masks, (d) the clean oracle (distractor-free
//! frames) — evaluated on the clean held-out views. One table at the end,
//! `report.html` beside it.

use super::train_common::{VariantResult, short_schedule, train_and_eval};
use crate::Ctx;
use crate::report::{self, Chart, Figure, Report, Series, Table};
use anyhow::{Context, Result, bail};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

const DEMO_TOML: &str = include_str!("../../../../scenes/demo.toml");
const SMALL_TOML: &str = include_str!("../../../../scenes/small.toml");

/// `romosplat demo [--out DIR] [--quick]`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder (scene, masks, COLMAP runs, splats, report.html).
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// The small scene and fewer steps: a check that everything runs (< 2 min).
    #[arg(long)]
    pub quick: bool,
    /// Training steps per variant (default: 800, quick: 200; the 10-minute
    /// budget on 2 cores, see the README).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Training backend.
    #[arg(long, value_enum, default_value_t = super::train::BackendKind::Auto)]
    pub backend: super::train::BackendKind,
    /// COLMAP runs on every Nth training frame (default: 3, quick: 2); CPU
    /// COLMAP on all 90 demo frames takes tens of minutes on 2 cores.
    #[arg(long)]
    pub pose_stride: Option<usize>,
    /// Integer downscale of the frames for training and testing (default: 4,
    /// i.e. 160×90; quick: 2, i.e. 160×120).
    #[arg(long)]
    pub downscale: Option<u32>,
    /// Skip the COLMAP runs (pose table left empty).
    #[arg(long)]
    pub no_pose: bool,
    /// COLMAP sequential matching overlap (frames matched after each frame).
    #[arg(long, default_value_t = 5)]
    pub pose_overlap: u32,
    /// Most SIFT features per frame for the COLMAP runs.
    #[arg(long, default_value_t = 2048)]
    pub pose_features: u32,
}

/// The four training variants.
const VARIANTS: [(&str, &str); 4] = [
    ("nomask", "(a) no masks"),
    ("romo", "(b) RoMo masks"),
    ("gt", "(c) ground-truth masks"),
    ("oracle", "(d) clean oracle"),
];

/// Symlink `src` at `dst` (replacing what is there).
pub fn link(src: &Path, dst: &Path) -> Result<()> {
    if dst.symlink_metadata().is_ok() {
        if dst.is_dir() && !dst.symlink_metadata()?.file_type().is_symlink() {
            std::fs::remove_dir_all(dst)?;
        } else {
            std::fs::remove_file(dst)?;
        }
    }
    let src =
        std::fs::canonicalize(src).with_context(|| format!("{}: not found", src.display()))?;
    std::os::unix::fs::symlink(&src, dst).with_context(|| format!("linking {}", dst.display()))
}

fn fresh_dir(p: &Path) -> Result<()> {
    if p.exists() {
        std::fs::remove_dir_all(p).with_context(|| format!("clearing {}", p.display()))?;
    }
    std::fs::create_dir_all(p).with_context(|| format!("creating {}", p.display()))
}

/// Names of the training (clutter) and test (extra) frames of a scene.
fn split_names(scene: &loader::scene::Scene) -> Result<(Vec<String>, Vec<String>)> {
    let train: Vec<String> = scene
        .split_indices("clutter")
        .iter()
        .map(|&i| scene.frames[i].name.clone())
        .collect();
    let test: Vec<String> = scene
        .split_indices("extra")
        .iter()
        .map(|&i| scene.frames[i].name.clone())
        .collect();
    if train.is_empty() || test.is_empty() {
        bail!(
            "{}: the demo scene needs a split.json with clutter and extra views",
            scene.root.display()
        );
    }
    Ok((train, test))
}

fn stem(name: &str) -> &str {
    name.rsplit_once('.').map_or(name, |(s, _)| s)
}

/// The video folder: only the training frames, in order, with their ground
/// truth. RoMo and COLMAP run here (held-out views are not part of the video).
fn make_video_dir(scene_dir: &Path, video: &Path, train: &[String]) -> Result<()> {
    fresh_dir(&video.join("images"))?;
    fresh_dir(&video.join("gt_motion"))?;
    for n in train {
        link(
            &scene_dir.join("images").join(n),
            &video.join("images").join(n),
        )?;
        let gt = format!("{}.png", stem(n));
        link(
            &scene_dir.join("gt_motion").join(&gt),
            &video.join("gt_motion").join(&gt),
        )?;
    }
    Ok(())
}

/// A training variant folder: all frames (training ones from `train_src`),
/// the ground-truth model and split, and `masks` when given.
fn make_variant_dir(
    scene_dir: &Path,
    dir: &Path,
    train_src: &Path,
    masks: Option<&Path>,
    names: (&[String], &[String]),
) -> Result<()> {
    fresh_dir(dir)?;
    std::fs::create_dir_all(dir.join("images"))?;
    for n in names.0 {
        link(&train_src.join(n), &dir.join("images").join(n))?;
    }
    for n in names.1 {
        link(
            &scene_dir.join("images").join(n),
            &dir.join("images").join(n),
        )?;
    }
    std::fs::create_dir_all(dir.join("sparse"))?;
    link(&scene_dir.join("sparse/0"), &dir.join("sparse/0"))?;
    link(&scene_dir.join("split.json"), &dir.join("split.json"))?;
    link(&scene_dir.join("gt_motion"), &dir.join("gt_motion"))?;
    if let Some(m) = masks {
        link(m, &dir.join("masks"))?;
    }
    Ok(())
}

struct PoseRow {
    label: String,
    registered: String,
    ate: Option<f64>,
    rpe_rot: Option<f64>,
}

fn run_pose(
    ctx: &Ctx,
    args: &Args,
    video: &Path,
    work: &Path,
    masks: Option<&Path>,
    gt: &[pose::NamedPose],
) -> Result<(serde_json::Value, PoseRow, f64)> {
    let t0 = Instant::now();
    let paths = pose::ColmapPaths {
        scene: video.to_path_buf(),
        images: video.join("images"),
        masks: masks.map_or_else(|| video.join("masks"), Path::to_path_buf),
        work: work.join("colmap"),
        out: work.join("sparse/0"),
        undistorted: work.join("undistorted"),
    };
    let opts = pose::ColmapOptions {
        camera_model: loader::CameraModel::PINHOLE,
        use_masks: masks.is_some(),
        undistort: false,
        overlap: args.pose_overlap,
        max_num_features: args.pose_features,
        ..Default::default()
    };
    let label = if masks.is_some() {
        "masked"
    } else {
        "unmasked"
    };
    let report = match pose::run_colmap(&paths, &opts, &mut |_| {}) {
        Ok(r) => r,
        Err(e) => {
            ctx.info(format!("  COLMAP {label}: failed: {e}"));
            let row = PoseRow {
                label: String::new(),
                registered: format!("0/{}", gt.len()),
                ate: None,
                rpe_rot: None,
            };
            return Ok((
                json!({ "error": e.to_string() }),
                row,
                t0.elapsed().as_secs_f64(),
            ));
        }
    };
    let pred = pose::trajectory::from_colmap(&paths.out)?;
    let metrics = pose::evaluate(&pred, gt, &pose::PoseMetricsOptions::default())?;
    let row = PoseRow {
        label: String::new(),
        registered: format!("{}/{}", report.registered, gt.len()),
        ate: Some(metrics.ate.rmse),
        rpe_rot: metrics.rpe_rot_deg.as_ref().map(|s| s.rmse),
    };
    Ok((
        json!({ "colmap": report, "metrics": metrics }),
        row,
        t0.elapsed().as_secs_f64(),
    ))
}

/// What step 1 made: the scene and its split, and the video folder.
struct DemoScene {
    name: String,
    dir: PathBuf,
    /// Training (clutter) and held-out (extra) frame names.
    train: Vec<String>,
    test: Vec<String>,
    /// Only the training frames: what RoMo and COLMAP see.
    video: PathBuf,
}

/// What step 2 made.
struct DemoMasks {
    metrics: romo::metrics::MaskMetrics,
    /// Ground-truth keep masks (COLMAP convention) of the video frames.
    gt_masks: PathBuf,
}

/// Run the demo: one function per numbered step.
pub fn run(args: &Args, ctx: &Ctx) -> Result<serde_json::Value> {
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut timings: Vec<(String, f64)> = Vec::new();
    let mut summary = serde_json::Map::new();

    let t0 = Instant::now();
    let scene = generate_scene(args, ctx, &mut summary)?;
    timings.push(("generate scene".into(), t0.elapsed().as_secs_f64()));

    let t0 = Instant::now();
    let masks = romo_masks(&scene, &out.join("gt_masks"), ctx, &mut summary)?;
    timings.push(("RoMo masks".into(), t0.elapsed().as_secs_f64()));

    let t0 = Instant::now();
    let pose_rows = colmap_runs(args, &scene, &masks, ctx, &mut summary)?;
    if !args.no_pose {
        timings.push(("COLMAP (3 runs)".into(), t0.elapsed().as_secs_f64()));
    }

    let (steps, views) = train_variants(args, &scene, &masks, ctx, &mut timings)?;

    let tables = result_tables(&scene, &masks, &pose_rows, &views, steps);
    for t in &tables {
        print_table(ctx, t);
    }
    if views.iter().any(|(_, r)| r.lpips.is_none()) {
        ctx.info(splat::lpips_alex::missing_weights_hint(
            splat::lpips_alex::default_weights_path().as_deref(),
        ));
    }
    let report_path = write_report(out, &scene, timings, tables, &views)?;
    ctx.info(format!("report: {}", report_path.display()));
    summary.insert(
        "views".into(),
        views
            .iter()
            .map(|(l, r)| {
                (
                    l.clone(),
                    json!({ "psnr": r.psnr, "ssim": r.ssim, "lpips": r.lpips, "splats": r.splats }),
                )
            })
            .collect::<serde_json::Map<_, _>>()
            .into(),
    );
    summary.insert("report".into(), json!(report_path));
    Ok(summary.into())
}

/// 1. Generate the scene (kept when its spec is unchanged) and the video folder.
fn generate_scene(
    args: &Args,
    ctx: &Ctx,
    summary: &mut serde_json::Map<String, serde_json::Value>,
) -> Result<DemoScene> {
    let out = &args.out;
    let spec_text = if args.quick { SMALL_TOML } else { DEMO_TOML };
    let spec_path = out.join("scene.toml");
    std::fs::write(&spec_path, spec_text)?;
    let spec = loader::synth::load_spec(&spec_path)?;
    let scene_dir = out.join("scene");
    let regenerate = match std::fs::read_to_string(scene_dir.join(".spec.toml")) {
        Ok(prev) => prev != spec_text,
        Err(_) => true,
    };
    if regenerate {
        ctx.info(format!(
            "[1/5] generating the '{}' scene into {}",
            spec.name,
            scene_dir.display()
        ));
        if scene_dir.exists() {
            std::fs::remove_dir_all(&scene_dir)?;
        }
        let rep = loader::synth::generate(&spec, &scene_dir)?;
        std::fs::write(scene_dir.join(".spec.toml"), spec_text)?;
        summary.insert("scene".into(), serde_json::to_value(&rep)?);
    } else {
        ctx.info(format!(
            "[1/5] scene '{}' already generated in {}",
            spec.name,
            scene_dir.display()
        ));
    }
    let scene = loader::scene::Scene::load(&scene_dir, &Default::default())?;
    let (train, test) = split_names(&scene)?;
    let video = out.join("video");
    make_video_dir(&scene_dir, &video, &train)?;
    Ok(DemoScene {
        name: spec.name,
        dir: scene_dir,
        train,
        test,
        video,
    })
}

/// 2. RoMo masks on the video frames, and J against the exact ground truth.
fn romo_masks(
    scene: &DemoScene,
    gt_masks: &Path,
    ctx: &Ctx,
    summary: &mut serde_json::Map<String, serde_json::Value>,
) -> Result<DemoMasks> {
    let t0 = Instant::now();
    ctx.info(format!(
        "[2/5] RoMo motion masks on {} frames",
        scene.train.len()
    ));
    let romo_opts = romo::RomoOptions {
        overlays: true,
        ..Default::default()
    };
    let report = super::mask::segment(&scene.video, 1, &romo_opts, ctx)?;
    let video = &scene.video;
    let metrics = romo::metrics::evaluate_masks(&video.join("masks"), &video.join("gt_motion"))?;
    ctx.info(format!(
        "      J = {:.3}, precision {:.3}, recall {:.3} ({:.1} s)",
        metrics.j_mean,
        metrics.precision,
        metrics.recall,
        t0.elapsed().as_secs_f64()
    ));
    summary.insert("romo".into(), serde_json::to_value(&report)?);
    summary.insert("mask_metrics".into(), serde_json::to_value(&metrics)?);
    fresh_dir(gt_masks)?;
    pose::gt_masks::masks_from_gt_motion(
        &video.join("images"),
        &video.join("gt_motion"),
        gt_masks,
    )?;
    Ok(DemoMasks {
        metrics,
        gt_masks: gt_masks.to_path_buf(),
    })
}

/// Step 3: COLMAP on every `--pose-stride`th video frame: unmasked, RoMo masks,
/// ground-truth masks; ATE against the generator's poses.
fn colmap_runs(
    args: &Args,
    scene: &DemoScene,
    masks: &DemoMasks,
    ctx: &Ctx,
    summary: &mut serde_json::Map<String, serde_json::Value>,
) -> Result<Vec<PoseRow>> {
    let mut pose_rows = Vec::new();
    if args.no_pose {
        ctx.info("[3/5] COLMAP skipped (--no-pose)");
        return Ok(pose_rows);
    }
    let out = &args.out;
    let video = &scene.video;
    let stride = args
        .pose_stride
        .unwrap_or(if args.quick { 2 } else { 3 })
        .max(1);
    let pose_names: Vec<String> = scene.train.iter().step_by(stride).cloned().collect();
    let pose_dir = out.join("pose_frames");
    for sub in ["images", "masks_romo", "masks_gt"] {
        fresh_dir(&pose_dir.join(sub))?;
    }
    for n in &pose_names {
        let m = format!("{n}.png");
        link(
            &video.join("images").join(n),
            &pose_dir.join("images").join(n),
        )?;
        link(
            &video.join("masks").join(&m),
            &pose_dir.join("masks_romo").join(&m),
        )?;
        link(
            &masks.gt_masks.join(&m),
            &pose_dir.join("masks_gt").join(&m),
        )?;
    }
    let gt_traj: Vec<pose::NamedPose> = pose::trajectory::from_colmap(&scene.dir.join("sparse/0"))?
        .into_iter()
        .filter(|p| pose_names.iter().any(|n| n == &p.name))
        .collect();
    let mut pose_json = serde_json::Map::new();
    let runs: [(&str, &str, Option<PathBuf>); 3] = [
        ("nomask", "no masks", None),
        ("romo", "RoMo masks", Some(pose_dir.join("masks_romo"))),
        ("gt", "ground-truth masks", Some(pose_dir.join("masks_gt"))),
    ];
    for (key, label, masks) in runs {
        ctx.info(format!("[3/5] COLMAP with {label}"));
        let (j, mut row, secs) = run_pose(
            ctx,
            args,
            &pose_dir,
            &out.join("pose").join(key),
            masks.as_deref(),
            &gt_traj,
        )?;
        row.label = label.to_string();
        ctx.info(format!(
            "      registered {}, ATE {} ({secs:.1} s)",
            row.registered,
            row.ate.map_or("-".into(), |a| format!("{a:.4}"))
        ));
        pose_json.insert(key.into(), j);
        pose_rows.push(row);
    }
    summary.insert("pose".into(), pose_json.into());
    Ok(pose_rows)
}

/// Steps 4 and 5: train on the ground-truth poses four ways, each scored on the
/// clean held-out views. Returns the step count and one result per variant.
fn train_variants(
    args: &Args,
    scene: &DemoScene,
    masks: &DemoMasks,
    ctx: &Ctx,
    timings: &mut Vec<(String, f64)>,
) -> Result<(u32, Vec<(String, VariantResult)>)> {
    let steps = args.steps.unwrap_or(if args.quick { 200 } else { 800 }) as u32;
    let downscale = args
        .downscale
        .unwrap_or(if args.quick { 2 } else { 4 })
        .max(1);
    let names = (scene.train.as_slice(), scene.test.as_slice());
    let mut views: Vec<(String, VariantResult)> = Vec::new();
    for (i, (key, label)) in VARIANTS.iter().enumerate() {
        let t0 = Instant::now();
        let dir = args.out.join("train").join(key);
        let (src, variant_masks): (PathBuf, Option<PathBuf>) = match *key {
            "nomask" => (scene.dir.join("images"), None),
            "romo" => (scene.dir.join("images"), Some(scene.video.join("masks"))),
            "gt" => (scene.dir.join("images"), Some(masks.gt_masks.clone())),
            _ => (scene.dir.join("clean"), None),
        };
        make_variant_dir(&scene.dir, &dir, &src, variant_masks.as_deref(), names)?;
        ctx.info(format!(
            "[4/5] training {label} ({steps} steps, variant {}/4)",
            i + 1
        ));
        let job = super::train::TrainJob {
            scene: dir.clone(),
            poses: None,
            downscale,
            holdout_every: 0,
            backend: args.backend,
            sparse_adam: false,
            resume: None,
            out: dir.join("out"),
            test_renders: None,
            opts: short_schedule(steps, variant_masks.is_some()),
        };
        let res = train_and_eval(ctx, &job)?;
        ctx.info(format!(
            "      test PSNR {:.2} dB, SSIM {:.4} ({:.1} s)",
            res.psnr,
            res.ssim,
            t0.elapsed().as_secs_f64()
        ));
        timings.push((format!("train {label}"), t0.elapsed().as_secs_f64()));
        views.push((label.to_string(), res));
    }
    Ok((steps, views))
}

/// The result tables: masks, poses, held-out views.
fn result_tables(
    scene: &DemoScene,
    masks: &DemoMasks,
    pose_rows: &[PoseRow],
    views: &[(String, VariantResult)],
    steps: u32,
) -> Vec<Table> {
    let m = &masks.metrics;
    let mut tables = vec![Table {
        caption: "Motion masks (RoMo vs exact ground truth)".into(),
        header: vec![
            "frames".into(),
            "J mean".into(),
            "J recall".into(),
            "precision".into(),
            "recall".into(),
        ],
        rows: vec![vec![
            scene.train.len().to_string(),
            format!("{:.3}", m.j_mean),
            format!("{:.3}", m.j_recall),
            format!("{:.3}", m.precision),
            format!("{:.3}", m.recall),
        ]],
    }];
    if !pose_rows.is_empty() {
        tables.push(Table {
            caption: "Poses (COLMAP vs generator ground truth, Sim(3)-aligned)".into(),
            header: vec![
                "masks".into(),
                "registered".into(),
                "ATE".into(),
                "RPE rot (deg)".into(),
            ],
            rows: pose_rows
                .iter()
                .map(|r| {
                    vec![
                        r.label.clone(),
                        r.registered.clone(),
                        r.ate.map_or("-".into(), |a| format!("{a:.4}")),
                        r.rpe_rot.map_or("-".into(), |a| format!("{a:.3}")),
                    ]
                })
                .collect(),
        });
    }
    tables.push(Table {
        caption: format!(
            "Held-out clean views ({} views, {steps} steps, ground-truth poses)",
            scene.test.len()
        ),
        header: vec![
            "training".into(),
            "PSNR".into(),
            "SSIM".into(),
            "LPIPS".into(),
            "splats".into(),
            "seconds".into(),
        ],
        rows: views
            .iter()
            .map(|(l, r)| {
                vec![
                    l.clone(),
                    format!("{:.2}", r.psnr),
                    format!("{:.4}", r.ssim),
                    r.lpips.map_or("-".into(), |v| format!("{v:.4}")),
                    r.splats.to_string(),
                    format!("{:.0}", r.seconds),
                ]
            })
            .collect(),
    });
    tables
}

/// The report: timings, tables, curves, contact sheet, held-out renders.
fn write_report(
    out: &Path,
    scene: &DemoScene,
    timings: Vec<(String, f64)>,
    tables: Vec<Table>,
    views: &[(String, VariantResult)],
) -> Result<PathBuf> {
    let mut rep = Report {
        title: format!("romosplat demo — {}", scene.name),
        timings,
        tables,
        ..Default::default()
    };
    for (title, y_label, pick) in [("training loss", "loss", 0), ("training PSNR", "dB", 1)] {
        rep.charts.push(Chart {
            title: title.into(),
            x_label: "step".into(),
            y_label: y_label.into(),
            series: views
                .iter()
                .map(|(l, r)| Series {
                    name: l.clone(),
                    points: if pick == 0 {
                        r.loss_curve.clone()
                    } else {
                        r.psnr_curve.clone()
                    },
                })
                .collect(),
        });
    }
    let step = (scene.train.len() / 8).max(1);
    for n in scene.train.iter().step_by(step).take(8) {
        let img = image::open(scene.video.join("images").join(n))
            .with_context(|| format!("{}: cannot read", n))?
            .to_rgb8();
        let mask = image::open(scene.video.join("masks").join(format!("{n}.png")))?.to_luma8();
        let over = report::thumbnail(&report::overlay_mask(&img, &mask), 320);
        rep.contact_sheet.push(Figure {
            caption: n.clone(),
            png: report::png_rgb8(&over)?,
        });
    }
    for (vi, n) in scene.test.iter().enumerate().take(3) {
        let mut row = vec![];
        let gt = image::open(scene.dir.join("images").join(n))?.to_rgb8();
        row.push(Figure {
            caption: format!("{n}: ground truth"),
            png: report::png_rgb8(&report::thumbnail(&gt, 320))?,
        });
        for (l, r) in views {
            if let Some(p) = r.renders.get(vi) {
                let img = image::open(p)?.to_rgb8();
                row.push(Figure {
                    caption: l.clone(),
                    png: report::png_rgb8(&report::thumbnail(&img, 320))?,
                });
            }
        }
        rep.renders.push(row);
    }
    let report_path = out.join("report.html");
    rep.write(&report_path)?;
    Ok(report_path)
}

/// Print a table on stderr with aligned columns.
pub fn print_table(ctx: &Ctx, t: &Table) {
    let mut widths: Vec<usize> = t.header.iter().map(|h| h.chars().count()).collect();
    for r in &t.rows {
        for (i, c) in r.iter().enumerate() {
            if i < widths.len() {
                widths[i] = widths[i].max(c.chars().count());
            }
        }
    }
    let fmt = |cells: &[String]| {
        cells
            .iter()
            .enumerate()
            .map(|(i, c)| format!("{:<w$}", c, w = widths.get(i).copied().unwrap_or(0)))
            .collect::<Vec<_>>()
            .join("  ")
    };
    ctx.info(format!("\n{}", t.caption));
    ctx.info(fmt(&t.header));
    ctx.info(
        widths
            .iter()
            .map(|w| "-".repeat(*w))
            .collect::<Vec<_>>()
            .join("  "),
    );
    for r in &t.rows {
        ctx.info(fmt(r));
    }
}
