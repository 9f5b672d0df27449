//! `romosplat run (--video FILE | --scene DIR) --out DIR`: what a user runs.
//! frames → RoMo masks → masked COLMAP → masked training → cleaned export →
//! report. Each stage is skipped when its outputs exist and are newer than
//! its inputs (a rerun resumes), `--from STAGE` forces a restart from a stage,
//! and a summary table closes the run. The user's scene folder is never
//! written to: `DIR/scene` links its images and holds our masks and model.

use super::demo::{link, print_table};
use crate::Ctx;
use crate::pipeline::{Stage, should_run};
use crate::report::{self, Chart, Figure, Report, Series, Table};
use anyhow::{Context, Result, bail};
use clap::Parser;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `romosplat run`
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("input").required(true).args(["video", "scene"])))]
pub struct Args {
    /// A video file (frames are extracted with ffmpeg).
    #[arg(long)]
    pub video: Option<PathBuf>,
    /// A scene folder with `images/` (never modified).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Restart from this stage (it and every later stage run again).
    #[arg(long, value_enum)]
    pub from: Option<Stage>,
    /// Frames per second to extract from the video (default: every frame).
    #[arg(long)]
    pub fps: Option<f64>,
    /// RoMo rounds (paper: 2).
    #[arg(long, default_value_t = 2)]
    pub iterations: usize,
    /// COLMAP matcher: sequential for videos, exhaustive for photo collections.
    #[arg(long, default_value = "sequential")]
    pub matcher: String,
    /// COLMAP camera model.
    #[arg(long, default_value = "SIMPLE_RADIAL")]
    pub camera_model: String,
    /// Use the scene's own `sparse/0` (or transforms.json) poses instead of running COLMAP.
    #[arg(long)]
    pub keep_poses: bool,
    /// Do not use masks anywhere (COLMAP and training): the unmasked baseline.
    #[arg(long)]
    pub no_masks: bool,
    /// Training steps.
    #[arg(long, default_value_t = 7000)]
    pub steps: usize,
    /// Training backend: auto, wgpu or cpu.
    #[arg(long, default_value = "auto")]
    pub backend: String,
    /// Integer downscale of the frames for training.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Hold out every Nth frame for testing when there is no split.json (0 = none).
    #[arg(long, default_value_t = 8)]
    pub holdout_every: usize,
    /// Export format of the cleaned splats (ply, splat, glb, spz).
    #[arg(long, default_value = "ply")]
    pub format: String,
}

#[derive(Debug, Parser)]
struct Sub<T: clap::Args> {
    #[command(flatten)]
    args: T,
}

fn parse<T: clap::Args + std::fmt::Debug>(argv: &[String]) -> Result<T> {
    Ok(Sub::<T>::try_parse_from(argv)
        .with_context(|| format!("options for {}", argv[0]))?
        .args)
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// Prepare `out/scene`: frames from the video, or links to the user's scene.
fn prepare_scene(args: &Args, scene: &Path, ctx: &Ctx) -> Result<()> {
    std::fs::create_dir_all(scene)?;
    if let Some(video) = &args.video {
        let images = scene.join("images");
        if images.exists() {
            std::fs::remove_dir_all(&images)?;
        }
        let frames = loader::video::extract_frames(video, scene, args.fps)?;
        ctx.info(format!(
            "  {} frames from {}",
            frames.len(),
            video.display()
        ));
        return Ok(());
    }
    let src = args
        .scene
        .as_deref()
        .context("--scene or --video is required")?;
    if !src.join("images").is_dir() {
        bail!("{}: no images/ folder", src.display());
    }
    for name in ["images", "gt_motion"] {
        if src.join(name).is_dir() {
            link(&src.join(name), &scene.join(name))?;
        }
    }
    for name in ["split.json", "transforms.json"] {
        if src.join(name).is_file() {
            link(&src.join(name), &scene.join(name))?;
        }
    }
    if args.keep_poses && src.join("sparse/0").is_dir() {
        std::fs::create_dir_all(scene.join("sparse"))?;
        link(&src.join("sparse/0"), &scene.join("sparse/0"))?;
    }
    Ok(())
}

fn status(ran: bool) -> &'static str {
    if ran { "ran" } else { "up to date" }
}

/// Run the pipeline.
pub fn run(args: &Args, ctx: &Ctx) -> Result<serde_json::Value> {
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let scene = out.join("scene");
    let mut timings: Vec<(String, f64)> = Vec::new();
    let mut ran: Vec<(Stage, &str)> = Vec::new();
    let mut summary = serde_json::Map::new();
    let from = args.from;
    let input: PathBuf = args
        .video
        .clone()
        .or_else(|| args.scene.as_ref().map(|d| d.join("images")))
        .context("no input")?;

    // frames
    let t0 = Instant::now();
    let images = scene.join("images");
    let go = should_run(
        Stage::Frames,
        from,
        std::slice::from_ref(&images),
        std::slice::from_ref(&input),
    );
    if go {
        ctx.info("[frames]");
        prepare_scene(args, &scene, ctx)?;
    }
    ran.push((Stage::Frames, status(go)));
    timings.push(("frames".into(), t0.elapsed().as_secs_f64()));

    // mask
    let t0 = Instant::now();
    let masks = scene.join("masks");
    let go = !args.no_masks
        && should_run(
            Stage::Mask,
            from,
            std::slice::from_ref(&masks),
            std::slice::from_ref(&images),
        );
    if go {
        ctx.info("[mask] RoMo motion masks");
        let m = super::mask::run(
            &parse::<super::mask::Args>(&[
                "mask".into(),
                "--scene".into(),
                s(&scene),
                "--iterations".into(),
                args.iterations.to_string(),
                "--overlays".into(),
            ])?,
            ctx,
        )?;
        summary.insert("mask".into(), m);
    }
    ran.push((
        Stage::Mask,
        if args.no_masks {
            "skipped (--no-masks)"
        } else {
            status(go)
        },
    ));
    timings.push(("mask".into(), t0.elapsed().as_secs_f64()));

    // pose
    let t0 = Instant::now();
    let sparse = scene.join("sparse/0");
    let pose_inputs = if args.no_masks {
        vec![images.clone()]
    } else {
        vec![images.clone(), masks.clone()]
    };
    let go = !args.keep_poses
        && should_run(
            Stage::Pose,
            from,
            std::slice::from_ref(&sparse),
            &pose_inputs,
        );
    if go {
        ctx.info("[pose] COLMAP");
        let mut argv = vec![
            "pose".into(),
            "--scene".into(),
            s(&scene),
            "--matcher".into(),
            args.matcher.clone(),
            "--camera-model".into(),
            args.camera_model.clone(),
        ];
        if args.no_masks {
            argv.push("--no-masks".into());
        }
        let p = super::pose::run(&parse::<super::pose::Args>(&argv)?, ctx)?;
        summary.insert("pose".into(), p);
    }
    ran.push((
        Stage::Pose,
        if args.keep_poses {
            "kept the scene's poses"
        } else {
            status(go)
        },
    ));
    timings.push(("pose".into(), t0.elapsed().as_secs_f64()));

    // train (on the undistorted copy when COLMAP made one)
    let t0 = Instant::now();
    let train_scene = if scene.join("undistorted/images").is_dir() {
        scene.join("undistorted")
    } else {
        scene.clone()
    };
    let train_out = out.join("train");
    let ply = train_out.join("splats.ply");
    let go = should_run(
        Stage::Train,
        from,
        std::slice::from_ref(&ply),
        &[sparse.clone(), masks.clone(), images.clone()],
    );
    let mut result = None;
    if go {
        ctx.info(format!("[train] {} steps", args.steps));
        let mut extra = vec![
            "--downscale".to_string(),
            args.downscale.to_string(),
            "--holdout-every".into(),
            args.holdout_every.to_string(),
        ];
        if args.no_masks {
            extra.push("--no-masks".into());
        }
        let r = super::train_common::train_and_eval(
            ctx,
            &train_scene,
            &train_out,
            args.steps,
            &args.backend,
            &extra,
        )?;
        summary.insert("train".into(), r.summary.clone());
        result = Some(r);
    }
    ran.push((Stage::Train, status(go)));
    timings.push(("train".into(), t0.elapsed().as_secs_f64()));

    // export (cleaned)
    let t0 = Instant::now();
    let export = out.join(format!("splats_clean.{}", args.format));
    let go = should_run(
        Stage::Export,
        from,
        std::slice::from_ref(&export),
        std::slice::from_ref(&ply),
    );
    if go {
        ctx.info(format!("[export] cleaned {}", export.display()));
        let e = super::export::run(
            &parse::<super::export::Args>(&[
                "export".into(),
                "--splats".into(),
                s(&ply),
                "--format".into(),
                args.format.clone(),
                "--clean".into(),
                "--scene".into(),
                s(&train_scene),
                "--out".into(),
                s(&export),
            ])?,
            ctx,
        )?;
        summary.insert("export".into(), e);
    }
    ran.push((Stage::Export, status(go)));
    timings.push(("export".into(), t0.elapsed().as_secs_f64()));

    // report
    let t0 = Instant::now();
    let report_path = out.join("report.html");
    let go = should_run(
        Stage::Report,
        from,
        std::slice::from_ref(&report_path),
        &[ply.clone(), export.clone()],
    );
    if go {
        write_report(&report_path, &scene, &timings, result.as_ref(), &summary)?;
        ctx.info(format!("[report] {}", report_path.display()));
    }
    ran.push((Stage::Report, status(go)));
    timings.push(("report".into(), t0.elapsed().as_secs_f64()));

    let table = Table {
        caption: format!("romosplat run → {}", out.display()),
        header: vec!["stage".into(), "status".into(), "seconds".into()],
        rows: ran
            .iter()
            .zip(&timings)
            .map(|((st, go), (_, secs))| {
                vec![st.name().into(), (*go).to_string(), format!("{secs:.1}")]
            })
            .collect(),
    };
    print_table(ctx, &table);
    if let Some(r) = &result {
        ctx.info(format!(
            "held-out views: PSNR {:.2} dB, SSIM {:.4}; {} splats",
            r.psnr, r.ssim, r.splats
        ));
    }
    summary.insert(
        "stages".into(),
        ran.iter()
            .map(|(st, go)| (st.name().to_string(), json!(*go == "ran")))
            .collect::<serde_json::Map<_, _>>()
            .into(),
    );
    summary.insert("splats".into(), json!(ply));
    summary.insert("export_path".into(), json!(export));
    summary.insert("report".into(), json!(report_path));
    Ok(summary.into())
}

fn write_report(
    path: &Path,
    scene: &Path,
    timings: &[(String, f64)],
    result: Option<&super::train_common::VariantResult>,
    summary: &serde_json::Map<String, serde_json::Value>,
) -> Result<()> {
    let mut rep = Report {
        title: format!("romosplat run — {}", scene.display()),
        timings: timings.to_vec(),
        ..Default::default()
    };
    if let Some(p) = summary.get("pose") {
        rep.tables.push(Table {
            caption: "COLMAP".into(),
            header: vec![
                "registered".into(),
                "total".into(),
                "points".into(),
                "mean reprojection error (px)".into(),
            ],
            rows: vec![vec![
                p["registered"].to_string(),
                p["total"].to_string(),
                p["points"].to_string(),
                p["mean_reprojection_error"]
                    .as_f64()
                    .map_or("-".into(), |v| format!("{v:.3}")),
            ]],
        });
    }
    if let Some(r) = result {
        rep.tables.push(Table {
            caption: "Held-out views".into(),
            header: vec!["PSNR".into(), "SSIM".into(), "splats".into()],
            rows: vec![vec![
                format!("{:.2}", r.psnr),
                format!("{:.4}", r.ssim),
                r.splats.to_string(),
            ]],
        });
        rep.charts.push(Chart {
            title: "training loss".into(),
            x_label: "step".into(),
            y_label: "loss".into(),
            series: vec![Series {
                name: "loss".into(),
                points: r.loss_curve.clone(),
            }],
        });
        rep.charts.push(Chart {
            title: "training PSNR".into(),
            x_label: "step".into(),
            y_label: "dB".into(),
            series: vec![Series {
                name: "PSNR".into(),
                points: r.psnr_curve.clone(),
            }],
        });
        for p in r.renders.iter().take(4) {
            let img = image::open(p)
                .with_context(|| format!("{}: cannot read", p.display()))?
                .to_rgb8();
            rep.renders.push(vec![Figure {
                caption: s(p),
                png: report::png_rgb8(&report::thumbnail(&img, 320))?,
            }]);
        }
    }
    let names = loader::scene::list_images(&scene.join("images"))?;
    let step = (names.len() / 8).max(1);
    for n in names.iter().step_by(step).take(8) {
        let img = image::open(scene.join("images").join(n))
            .with_context(|| format!("{n}: cannot read"))?
            .to_rgb8();
        let over = match image::open(scene.join("masks").join(format!("{n}.png"))) {
            Ok(m) => report::overlay_mask(&img, &m.to_luma8()),
            Err(_) => img,
        };
        rep.contact_sheet.push(Figure {
            caption: n.clone(),
            png: report::png_rgb8(&report::thumbnail(&over, 320))?,
        });
    }
    rep.write(path)
}
