//! `romosplat run (--video FILE | --scene DIR) --out DIR`: what a user runs.
//! frames → RoMo masks → masked COLMAP → masked training → cleaned export →
//! report, as one table of stages ([`stages`]): each names its inputs, its
//! outputs, the resolved options that affect its result, the typed function
//! that runs it, and how its typed result comes back from its manifest when
//! it is up to date (see [`crate::pipeline`] for freshness). `--from STAGE`
//! forces a restart from a stage, and a summary table closes the run. The
//! user's scene folder is never written to: `OUT/scene` links its files and
//! holds our masks and model.

use super::demo::{link, print_table};
use super::export::{ExportJob, ExportOutcome};
use super::train::{BackendKind, TrainJob, TrainOutcome, scores_line};
use super::train_common::short_schedule;
use crate::Ctx;
use crate::keyframes::{KeyframeOptions, link_keyframes, select_keyframes};
use crate::pipeline::{self, Decision, Input, Manifest, Stage};
use crate::plan::Plan as Budget;
use crate::report::Table;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use serde_json::json;
use splat::export::ExportFormat;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The input of `run` and `plan`: exactly one of a video and a scene folder.
#[derive(Debug, Clone, clap::Args)]
#[group(id = "input", required = true, multiple = false)]
pub struct InputArgs {
    /// A video file (frames are extracted with ffmpeg).
    #[arg(long)]
    pub video: Option<PathBuf>,
    /// A scene folder with `images/` (never modified).
    #[arg(long)]
    pub scene: Option<PathBuf>,
}

impl InputArgs {
    /// Where the frames come from.
    pub fn source(&self) -> Result<Source> {
        match (&self.video, &self.scene) {
            (Some(v), None) => Ok(Source::Video(v.clone())),
            (None, Some(s)) => Ok(Source::Scene(s.clone())),
            _ => bail!("give exactly one of --video and --scene"),
        }
    }

    /// Frame count and size of the input: the video's (probed with the
    /// ffprobe beside `ffmpeg`, at `fps` when given) or the scene's images;
    /// and, for a video without `fps`, its own frame rate, which the planner
    /// may lower (`--fps` is the user's choice of frames).
    pub fn probe(&self, ffmpeg: &Path, fps: Option<f64>) -> Result<(usize, u32, u32, Option<f64>)> {
        match self.source()? {
            Source::Video(v) => {
                let info = crate::plan::probe_video(ffmpeg, &v)?;
                let own = info.fps.filter(|_| fps.is_none());
                Ok((info.frames_at(fps), info.width, info.height, own))
            }
            Source::Scene(s) => {
                let (n, w, h) = crate::plan::probe_scene(&s)?;
                Ok((n, w, h, None))
            }
        }
    }

    /// Up to `k` frames spread evenly over the input: a scene's image files,
    /// or a video's frames decoded by ffmpeg into `dir` (the first frame
    /// alone when the video's frame rate is unknown).
    pub fn sample_frames(&self, ffmpeg: &Path, k: usize, dir: &Path) -> Result<Vec<PathBuf>> {
        match self.source()? {
            Source::Scene(s) => {
                let images = s.join("images");
                let names = loader::scene::list_images(&images)?;
                let k = k.min(names.len());
                Ok((0..k)
                    .map(|i| images.join(&names[(2 * i + 1) * names.len() / (2 * k)]))
                    .collect())
            }
            Source::Video(v) => {
                let info = crate::plan::probe_video(ffmpeg, &v)?;
                let duration = (info.fps)
                    .filter(|f| *f > 0.0)
                    .map(|f| info.frames as f64 / f);
                let k = if duration.is_some() {
                    k.min(info.frames)
                } else {
                    1
                };
                let times: Vec<f64> = (0..k)
                    .map(|i| duration.map_or(0.0, |d| d * (i as f64 + 0.5) / k as f64))
                    .collect();
                let program = ffmpeg.to_string_lossy();
                Ok(loader::video::extract_frames_at(&program, &v, &times, dir)?)
            }
        }
    }

    /// COLMAP matches every pair: `--matcher` when given, else for a scene
    /// folder (photos), where a video's frames are matched sequentially.
    pub fn exhaustive(&self, matcher: Option<pose::Matcher>) -> Result<bool> {
        Ok(match matcher {
            Some(m) => m == pose::Matcher::Exhaustive,
            None => matches!(self.source()?, Source::Scene(_)),
        })
    }
}

/// `romosplat run`
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub input: InputArgs,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Restart from this stage (it and every later stage run again).
    #[arg(long, value_enum)]
    pub from: Option<Stage>,
    /// Frames per second to extract from the video (default: every frame).
    #[arg(long)]
    pub fps: Option<f64>,
    /// The ffmpeg program (name on PATH or path).
    #[arg(long, default_value = "ffmpeg")]
    pub ffmpeg: PathBuf,
    /// RoMo rounds (paper: 2).
    #[arg(long, default_value_t = 2)]
    pub iterations: usize,
    /// Full RoMo options as JSON (a partial `RomoOptions`); --iterations overrides.
    #[arg(long)]
    pub mask_options: Option<PathBuf>,
    /// COLMAP options (planned from the budget when not given; the matcher
    /// is sequential for a video and exhaustive for a scene folder).
    #[command(flatten)]
    pub pose: super::pose::PoseOpts,
    /// Use the scene's own `sparse/0` (or transforms.json) poses instead of running COLMAP.
    #[arg(long)]
    pub keep_poses: bool,
    /// Do not use masks anywhere (COLMAP and training): the unmasked baseline.
    #[arg(long)]
    pub no_masks: bool,
    /// Do not train the unmasked baseline (by default a second model is
    /// trained without masks on the same poses and steps, and the report
    /// compares their held-out scores; the budget is shared by both).
    #[arg(long)]
    pub no_baseline: bool,
    /// Wall-time budget for the whole run, minutes: plans the training
    /// resolution and steps and COLMAP's image size, features and frame
    /// stride that are not given explicitly (see `romosplat plan`).
    #[arg(long, default_value_t = 20.0)]
    pub budget_minutes: f64,
    /// Training steps (INRIA's schedule compressed to this many steps) [default: planned].
    #[arg(long)]
    pub steps: Option<u32>,
    /// Training backend.
    #[arg(long, value_enum, default_value_t = BackendKind::Auto)]
    pub backend: BackendKind,
    /// Integer downscale of the frames for training [default: planned].
    #[arg(long)]
    pub downscale: Option<u32>,
    /// Video: keep every extracted frame (no keyframe selection).
    #[arg(long)]
    pub all_frames: bool,
    /// Hold out every Nth frame for testing when there is no split.json (0 = none).
    #[arg(long, default_value_t = 8)]
    pub holdout_every: usize,
    /// Export format of the cleaned splats.
    #[arg(long, value_enum, default_value_t = ExportFormat::Ply)]
    pub format: ExportFormat,
}

/// Where the frames come from.
#[derive(Debug, Clone, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// A video file, extracted with ffmpeg.
    Video(PathBuf),
    /// A scene folder, linked.
    Scene(PathBuf),
}

/// Everything the stages need, resolved from the flags and the budget plan once.
#[derive(Debug, Clone)]
pub struct Plan {
    pub out: PathBuf,
    /// `OUT/scene`: frames (or links), masks.
    pub scene: PathBuf,
    pub source: Source,
    pub fps: Option<f64>,
    pub ffmpeg: PathBuf,
    pub keep_poses: bool,
    pub no_masks: bool,
    /// Also train without masks (on the same poses and steps) to compare.
    pub baseline: bool,
    pub romo: romo::RomoOptions,
    /// The `--mask-options` file (a hashed input of the mask stage).
    pub mask_options: Option<PathBuf>,
    /// Keyframe selection (videos, unless `--all-frames`).
    pub keyframes: Option<KeyframeOptions>,
    pub colmap: pose::ColmapOptions,
    pub train: splat::train::TrainOptions,
    pub downscale: u32,
    pub holdout_every: usize,
    pub backend: BackendKind,
    pub format: ExportFormat,
    pub clean: splat::export::CleanOptions,
    pub from: Option<Stage>,
    /// The time-budget plan the values above follow where no flag set them.
    pub budget: Budget,
}

impl Plan {
    /// Resolve the flags; `budget` supplies what they leave unset.
    pub fn new(args: &Args, budget: &Budget) -> Result<Plan> {
        let source = args.input.source()?;
        let video = matches!(source, Source::Video(_));
        let mut romo = match &args.mask_options {
            Some(p) => super::mask::read_options(p)?,
            None => romo::RomoOptions::default(),
        };
        romo.iterations = args.iterations;
        romo.overlays = true;
        // A video's frames are in capture order by construction.
        if video && romo.frame_order == romo::order::FrameOrder::Auto {
            romo.frame_order = romo::order::FrameOrder::Names;
        }
        // Videos: sequential matching and COLMAP's video mapper bounds;
        // photo collections: every pair. The budget picks image size,
        // features and stride; explicit pose flags override all of it.
        let mut colmap = pose::ColmapOptions {
            matcher: if video {
                pose::Matcher::Sequential
            } else {
                pose::Matcher::Exhaustive
            },
            mapper: if video {
                pose::colmap_runner::MapperOptions::video()
            } else {
                pose::colmap_runner::MapperOptions::default()
            },
            use_masks: !args.no_masks,
            max_image_size: budget.pose_max_image_size,
            max_num_features: budget.pose_features,
            stride: budget.pose_stride,
            ..Default::default()
        };
        args.pose.apply(&mut colmap)?;
        colmap.validate()?;
        let steps = args.steps.unwrap_or(budget.steps as u32);
        let train = short_schedule(steps, !args.no_masks);
        train.validate()?;
        Ok(Plan {
            out: args.out.clone(),
            scene: args.out.join("scene"),
            source,
            fps: args.fps.or(budget.extract_fps),
            ffmpeg: args.ffmpeg.clone(),
            keep_poses: args.keep_poses,
            no_masks: args.no_masks,
            baseline: trainings(args) > 1,
            romo,
            mask_options: args.mask_options.clone(),
            keyframes: (video && !args.all_frames).then(KeyframeOptions::default),
            colmap,
            train,
            downscale: args.downscale.unwrap_or(budget.downscale).max(1),
            holdout_every: args.holdout_every,
            backend: args.backend,
            format: args.format,
            clean: splat::export::CleanOptions::default(),
            from: args.from,
            budget: budget.clone(),
        })
    }

    /// The baseline's training options: the masked model's without masks.
    pub fn baseline_options(&self) -> splat::train::TrainOptions {
        splat::train::TrainOptions {
            use_masks: false,
            ..self.train.clone()
        }
    }

    /// The folder COLMAP and training read: the keyframes when selected, else the scene.
    pub fn posed_scene(&self) -> PathBuf {
        if self.keyframes.is_some() {
            self.out.join("keyframes")
        } else {
            self.scene.clone()
        }
    }
    pub fn images(&self) -> PathBuf {
        self.scene.join("images")
    }
    pub fn masks(&self) -> PathBuf {
        self.scene.join("masks")
    }
    pub fn sparse(&self) -> PathBuf {
        self.posed_scene().join("sparse/0")
    }
    /// COLMAP's undistorted PINHOLE copy when it made one, else the posed scene.
    pub fn train_scene(&self) -> PathBuf {
        let posed = self.posed_scene();
        let u = posed.join("undistorted");
        if u.join("images").is_dir() { u } else { posed }
    }
    pub fn train_dir(&self) -> PathBuf {
        self.out.join("train")
    }
    pub fn splats(&self) -> PathBuf {
        self.train_dir().join("splats.ply")
    }
    /// `OUT/baseline`: the model trained without masks.
    pub fn baseline_dir(&self) -> PathBuf {
        self.out.join("baseline")
    }
    pub fn export_path(&self) -> PathBuf {
        let ext = self.format.name();
        self.out.join(format!("splats_clean.{ext}"))
    }
    pub fn report_path(&self) -> PathBuf {
        self.out.join("report.html")
    }
}

/// What the frames stage made.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FramesOutcome {
    pub frames: usize,
    /// The video or scene folder they came from.
    pub source: PathBuf,
    /// How an HDR video's frames were brought to SDR (one line).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hdr: Option<String>,
}

/// What the mask stage made (the summary of RoMo's report the run keeps).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MaskOutcome {
    pub frames: usize,
    /// Mean fraction of each frame called moving.
    pub moving_fraction: f64,
    /// Frames RoMo left out of its MLP training (too few inliers).
    pub dropped_frames: Vec<String>,
    /// Flow and feature backends used.
    pub backends: Vec<String>,
}

impl MaskOutcome {
    fn new(rep: &romo::RomoReport) -> Self {
        let finite: Vec<f64> = rep
            .frames
            .iter()
            .map(|f| f.moving_fraction as f64)
            .filter(|m| m.is_finite())
            .collect();
        MaskOutcome {
            frames: rep.frames.len(),
            moving_fraction: finite.iter().sum::<f64>() / finite.len().max(1) as f64,
            dropped_frames: rep
                .dropped_frames
                .iter()
                .filter_map(|&i| rep.frames.get(i).map(|f| f.name.clone()))
                .collect(),
            backends: rep.backends.clone(),
        }
    }
}

/// What the keyframes stage kept.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct KeyframesOutcome {
    pub kept: usize,
    pub frames: usize,
    #[serde(flatten)]
    pub dropped: crate::keyframes::Dropped,
}

/// The typed results of the stages (run now, or restored from their manifests).
#[derive(Debug, Default)]
pub struct Results {
    pub frames: Option<FramesOutcome>,
    pub mask: Option<MaskOutcome>,
    pub keyframes: Option<KeyframesOutcome>,
    pub pose: Option<pose::ColmapReport>,
    pub train: Option<TrainOutcome>,
    /// The same training without masks.
    pub baseline: Option<TrainOutcome>,
    pub export: Option<ExportOutcome>,
    /// (stage, seconds) of every stage that has run, now or before.
    pub timings: Vec<(String, f64)>,
}

/// One row of the stage table.
pub struct StageDef {
    pub stage: Stage,
    /// `Some(reason)` when the stage does not apply to this run.
    pub skip: fn(&Plan) -> Option<&'static str>,
    pub inputs: fn(&Plan) -> Vec<Input>,
    pub outputs: fn(&Plan) -> Vec<PathBuf>,
    /// The resolved options that affect the result.
    pub options: fn(&Plan) -> Result<serde_json::Value>,
    /// Run the stage; its result is stored in `Results` and returned serialised.
    pub run: fn(&Plan, &mut Results, &Ctx) -> Result<serde_json::Value>,
    /// Put a recorded result back into `Results`.
    pub restore: fn(&mut Results, serde_json::Value) -> Result<()>,
}

/// Keep a stage's result in its `Results` slot and return it serialised.
fn store<T: Serialize>(slot: &mut Option<T>, result: T) -> Result<serde_json::Value> {
    let v = serde_json::to_value(&result)?;
    *slot = Some(result);
    Ok(v)
}

/// Put a recorded result back into its `Results` slot.
fn restore_into<T: serde::de::DeserializeOwned>(
    slot: &mut Option<T>,
    v: serde_json::Value,
) -> Result<()> {
    *slot = Some(serde_json::from_value(v)?);
    Ok(())
}

/// The stages, in order.
pub fn stages() -> [StageDef; 8] {
    [
        StageDef {
            stage: Stage::Frames,
            skip: |_| None,
            inputs: |p| match &p.source {
                Source::Video(v) => vec![Input::Hashed(v.clone())],
                Source::Scene(s) => {
                    let mut v = vec![
                        Input::Stat(s.join("images")),
                        Input::Stat(s.join("gt_motion")),
                        Input::Hashed(s.join("split.json")),
                        Input::Hashed(s.join("transforms.json")),
                    ];
                    if p.keep_poses {
                        v.push(Input::Stat(s.join("sparse/0")));
                    }
                    v
                }
            },
            outputs: |p| vec![p.images()],
            options: |p| {
                Ok(json!({ "source": p.source, "fps": p.fps, "keep_poses": p.keep_poses }))
            },
            run: run_frames,
            restore: |r, v| restore_into(&mut r.frames, v),
        },
        StageDef {
            stage: Stage::Mask,
            skip: |p| p.no_masks.then_some("skipped (--no-masks)"),
            inputs: |p| {
                let mut v = vec![Input::Stat(p.images())];
                v.extend(p.mask_options.iter().cloned().map(Input::Hashed));
                v
            },
            outputs: |p| vec![p.masks()],
            options: |p| Ok(serde_json::to_value(&p.romo)?),
            run: |p, r, ctx| {
                clear(&p.masks())?;
                clear(&p.scene.join("motion"))?;
                let rep = MaskOutcome::new(&super::mask::segment(&p.scene, 1, &p.romo, ctx)?);
                store(&mut r.mask, rep)
            },
            restore: |r, v| restore_into(&mut r.mask, v),
        },
        StageDef {
            stage: Stage::Keyframes,
            skip: |p| {
                p.keyframes
                    .is_none()
                    .then_some("every frame (scene folder or --all-frames)")
            },
            inputs: |p| images_and_masks(p, &p.scene),
            outputs: |p| vec![p.posed_scene().join("images")],
            options: |p| Ok(json!({ "keyframes": p.keyframes, "masks": !p.no_masks })),
            run: run_keyframes,
            restore: |r, v| restore_into(&mut r.keyframes, v),
        },
        StageDef {
            stage: Stage::Pose,
            skip: |p| p.keep_poses.then_some("kept the scene's poses"),
            inputs: |p| images_and_masks(p, &p.posed_scene()),
            outputs: |p| vec![p.sparse()],
            options: |p| Ok(serde_json::to_value(&p.colmap)?),
            run: |p, r, ctx| {
                let posed = p.posed_scene();
                let paths = pose::ColmapPaths::for_scene(&posed);
                let rep = super::pose::colmap(&paths, &p.colmap, ctx)
                    .with_context(|| format!("pose stage on {}", posed.display()))?;
                store(&mut r.pose, rep)
            },
            restore: |r, v| restore_into(&mut r.pose, v),
        },
        StageDef {
            stage: Stage::Train,
            skip: |_| None,
            inputs: |p| train_inputs(p, !p.no_masks),
            outputs: |p| vec![p.splats()],
            options: |p| train_options(p, &p.train),
            run: |p, r, ctx| {
                let o = train_into(p, p.train.clone(), &p.train_dir(), ctx)?;
                store(&mut r.train, o)
            },
            restore: |r, v| restore_into(&mut r.train, v),
        },
        StageDef {
            stage: Stage::Baseline,
            skip: |p| {
                if p.no_masks {
                    Some("skipped (--no-masks: the model is the baseline)")
                } else if !p.baseline {
                    Some("skipped (--no-baseline)")
                } else {
                    None
                }
            },
            inputs: |p| train_inputs(p, false),
            outputs: |p| vec![p.baseline_dir().join("splats.ply")],
            options: |p| train_options(p, &p.baseline_options()),
            run: |p, r, ctx| {
                let o = train_into(p, p.baseline_options(), &p.baseline_dir(), ctx)?;
                store(&mut r.baseline, o)
            },
            restore: |r, v| restore_into(&mut r.baseline, v),
        },
        StageDef {
            stage: Stage::Export,
            skip: |_| None,
            inputs: |p| vec![Input::Stat(p.splats())],
            outputs: |p| vec![p.export_path()],
            options: |p| Ok(json!({ "format": format!("{:?}", p.format), "clean": p.clean })),
            run: |p, r, ctx| {
                let job = ExportJob {
                    splats: p.splats(),
                    format: p.format,
                    out: p.export_path(),
                    clean: Some(p.clean.clone()),
                    scene: Some(p.train_scene()),
                    options: Default::default(),
                };
                let o = super::export::export_splats(&job, ctx)?;
                store(&mut r.export, o)
            },
            restore: |r, v| restore_into(&mut r.export, v),
        },
        StageDef {
            stage: Stage::Report,
            skip: |_| None,
            inputs: |p| {
                let mut v = vec![Input::Stat(p.splats()), Input::Stat(p.export_path())];
                if p.baseline && !p.no_masks {
                    v.push(Input::Stat(p.baseline_dir().join("splats.ply")));
                }
                v
            },
            outputs: |p| vec![p.report_path()],
            options: |_| Ok(serde_json::Value::Null),
            run: |p, r, _| {
                super::run_report::write_report(p, r)?;
                Ok(json!(p.report_path()))
            },
            restore: |_, _| Ok(()),
        },
    ]
}

/// `dir/images`, and `dir/masks` when the run uses masks.
fn images_and_masks(p: &Plan, dir: &Path) -> Vec<Input> {
    let mut v = vec![Input::Stat(dir.join("images"))];
    if !p.no_masks {
        v.push(Input::Stat(dir.join("masks")));
    }
    v
}

/// What a training stage reads: the posed (undistorted) scene, and the
/// masks when it uses them.
fn train_inputs(p: &Plan, masks: bool) -> Vec<Input> {
    let t = p.train_scene();
    let mut v = vec![
        Input::Stat(t.join("images")),
        Input::Stat(t.join("sparse/0")),
        Input::Hashed(t.join("split.json")),
        Input::Hashed(t.join("transforms.json")),
    ];
    if masks {
        v.push(Input::Stat(t.join("masks")));
    }
    v
}

/// The options a training stage's result depends on.
fn train_options(p: &Plan, train: &splat::train::TrainOptions) -> Result<serde_json::Value> {
    Ok(json!({
        "train": train,
        "downscale": p.downscale,
        "holdout_every": p.holdout_every,
        "backend": format!("{:?}", p.backend),
    }))
}

/// Train on the posed scene into a fresh `dir` (held-out renders in `dir/renders`).
fn train_into(
    p: &Plan,
    opts: splat::train::TrainOptions,
    dir: &Path,
    ctx: &Ctx,
) -> Result<TrainOutcome> {
    clear(dir)?;
    let job = TrainJob {
        scene: p.train_scene(),
        poses: None,
        downscale: p.downscale,
        holdout_every: p.holdout_every,
        backend: p.backend,
        sparse_adam: false,
        resume: None,
        out: dir.to_path_buf(),
        test_renders: Some(dir.join("renders")),
        opts,
    };
    super::train::train(&job, ctx)
}

/// Remove a folder or file we own (stale outputs of an earlier run).
fn clear(p: &Path) -> Result<()> {
    let Ok(meta) = p.symlink_metadata() else {
        return Ok(());
    };
    if meta.is_dir() {
        std::fs::remove_dir_all(p)
    } else {
        std::fs::remove_file(p)
    }
    .with_context(|| format!("clearing {}", p.display()))
}

/// Frames: extract the video, or link the user's scene files, into a fresh `OUT/scene`.
fn run_frames(p: &Plan, r: &mut Results, ctx: &Ctx) -> Result<serde_json::Value> {
    // New frames invalidate everything made from the old ones (masks, the
    // COLMAP database and model).
    clear(&p.scene)?;
    std::fs::create_dir_all(&p.scene).with_context(|| format!("creating {}", p.scene.display()))?;
    let outcome = match &p.source {
        Source::Video(video) => {
            let program = p.ffmpeg.to_string_lossy();
            let extraction = loader::video::extract_frames_with(&program, video, &p.scene, p.fps)?;
            ctx.info(format!(
                "  {} frames from {}",
                extraction.frames.len(),
                video.display()
            ));
            let hdr = extraction.hdr.as_ref().map(loader::video::Hdr::describe);
            if let Some(line) = &hdr {
                ctx.info(format!("  {line}"));
            }
            FramesOutcome {
                frames: extraction.frames.len(),
                source: video.clone(),
                hdr,
            }
        }
        Source::Scene(src) => {
            if !src.join("images").is_dir() {
                bail!("{}: no images/ folder", src.display());
            }
            for name in ["images", "gt_motion", "split.json", "transforms.json"] {
                if src.join(name).exists() {
                    link(&src.join(name), &p.scene.join(name))?;
                }
            }
            if p.keep_poses && src.join("sparse/0").is_dir() {
                std::fs::create_dir_all(p.scene.join("sparse"))?;
                link(&src.join("sparse/0"), &p.sparse())?;
            }
            let frames = loader::scene::list_images(&src.join("images"))?.len();
            ctx.info(format!("  {frames} frames linked from {}", src.display()));
            FramesOutcome {
                frames,
                source: src.clone(),
                hdr: None,
            }
        }
    };
    store(&mut r.frames, outcome)
}

/// Keyframes: link the sharp, non-duplicate frames (and their masks) into `OUT/keyframes`.
fn run_keyframes(p: &Plan, r: &mut Results, ctx: &Ctx) -> Result<serde_json::Value> {
    let opts = p.keyframes.unwrap_or_default();
    let dir = p.posed_scene();
    // New keyframes invalidate the COLMAP database and model made from the old ones.
    clear(&dir)?;
    let names = loader::scene::list_images(&p.images())?;
    let masks = (!p.no_masks).then(|| p.masks());
    let k = select_keyframes(&p.images(), masks.as_deref(), &names, &opts)?;
    link_keyframes(&p.scene, &k.kept, &dir)?;
    let outcome = KeyframesOutcome {
        kept: k.kept.len(),
        frames: names.len(),
        dropped: k.dropped(),
    };
    ctx.info(format!(
        "  kept {} of {} frames ({} dropped)",
        outcome.kept, outcome.frames, outcome.dropped
    ));
    store(&mut r.keyframes, outcome)
}

/// The time-budget plan for this run. It is kept in `OUT/plan.json` with
/// what it was made from (budget, input size, the flags it respects), and
/// reused while those stay the same: a rerun neither probes the adapter
/// again nor sees a slightly different probe change its stages' options.
fn budget(args: &Args, ctx: &Ctx) -> Result<Budget> {
    let (frames, width, height, fps) = args.input.probe(&args.ffmpeg, args.fps)?;
    let input = crate::plan::Input {
        frames,
        width,
        height,
        overlap: args
            .pose
            .pose_overlap
            .unwrap_or(pose::ColmapOptions::default().overlap),
        exhaustive: args.input.exhaustive(args.pose.matcher)?,
        trainings: trainings(args),
        masks: !args.no_masks,
        fps,
    };
    let fixed = crate::plan::Fixed {
        steps: args.steps.map(|s| s as usize),
        downscale: args.downscale,
        pose_stride: args.pose.pose_stride,
        pose_features: args.pose.pose_features,
        pose_max_image_size: args.pose.pose_max_image_size,
    };
    let key = json!({
        "version": pipeline::VERSION,
        "budget_minutes": args.budget_minutes,
        "input": input,
        "fixed": fixed,
        "backend": format!("{:?}", args.backend),
    });
    let path = args.out.join("plan.json");
    let recorded = std::fs::read(&path)
        .ok()
        .and_then(|b| serde_json::from_slice::<RecordedPlan>(&b).ok())
        .filter(|r| r.key == key);
    let budget = match recorded {
        Some(r) => r.plan,
        None => {
            let colmap =
                (args.pose.colmap.clone()).unwrap_or_else(|| pose::ColmapOptions::default().colmap);
            // With the scene's own poses COLMAP does not run: nothing to probe.
            let sift = (!args.keep_poses).then(|| super::plan::SiftProbe {
                input: &args.input,
                ffmpeg: &args.ffmpeg,
                colmap: &colmap,
            });
            let b = super::plan::plan_for(
                &input,
                args.budget_minutes,
                &fixed,
                args.backend,
                sift,
                ctx,
            )?;
            let rec = RecordedPlan {
                key,
                plan: b.clone(),
            };
            loader::io::write_bytes_atomic(&path, serde_json::to_string_pretty(&rec)?.as_bytes())?;
            b
        }
    };
    ctx.info(format!(
        "plan for {frames} frames of {width}×{height} ({:.0}-minute budget; flags given override it):",
        args.budget_minutes
    ));
    for l in budget.lines() {
        ctx.info(format!("  {l}"));
    }
    Ok(budget)
}

/// Models the run trains: the masked one, and the unmasked baseline unless
/// `--no-baseline` (or `--no-masks`, where the model is the baseline).
fn trainings(args: &Args) -> usize {
    if args.no_masks || args.no_baseline {
        1
    } else {
        2
    }
}

/// `OUT/plan.json`: a plan and what it was made from.
#[derive(Debug, Serialize, Deserialize)]
struct RecordedPlan {
    key: serde_json::Value,
    plan: Budget,
}

/// How one stage went in this run.
#[derive(Debug, Clone, Serialize)]
pub struct StageRow {
    pub stage: Stage,
    /// "ran", "up to date", or why it does not apply.
    pub status: String,
    pub ran: bool,
    /// Why it ran (empty when it did not).
    pub reason: String,
    /// Seconds spent in this run.
    pub seconds: f64,
}

/// Run the pipeline.
pub fn run(args: &Args, ctx: &Ctx) -> Result<serde_json::Value> {
    let t_all = Instant::now();
    crate::preflight::for_run(args, ctx)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let budget = budget(args, ctx)?;
    let plan = Plan::new(args, &budget)?;
    let mut results = Results::default();
    let rows = run_stages(&plan, &mut results, ctx)?;
    print_summary(ctx, &plan, &rows, &results, t_all.elapsed().as_secs_f64());
    let mut summary = serde_json::Map::new();
    summary.insert(
        "stages".into(),
        rows.iter()
            .map(|r| (r.stage.name().to_string(), json!(r)))
            .collect::<serde_json::Map<_, _>>()
            .into(),
    );
    summary.insert(
        "ran".into(),
        json!(
            rows.iter()
                .filter(|r| r.ran)
                .map(|r| r.stage.name())
                .collect::<Vec<_>>()
        ),
    );
    summary.insert("seconds".into(), json!(t_all.elapsed().as_secs_f64()));
    summary.insert("frames".into(), json!(results.frames));
    summary.insert("mask".into(), json!(results.mask));
    summary.insert("keyframes".into(), json!(results.keyframes));
    summary.insert("plan".into(), json!(plan.budget));
    summary.insert("pose".into(), json!(results.pose));
    summary.insert("train".into(), json!(results.train));
    summary.insert("baseline".into(), json!(results.baseline));
    summary.insert("export".into(), json!(results.export));
    summary.insert("splats".into(), json!(plan.splats()));
    summary.insert("export_path".into(), json!(plan.export_path()));
    summary.insert("report".into(), json!(plan.report_path()));
    Ok(summary.into())
}

/// The stage loop: decide each stage by its fingerprint, run it or restore
/// its recorded result, and record what ran.
fn run_stages(plan: &Plan, results: &mut Results, ctx: &Ctx) -> Result<Vec<StageRow>> {
    let mut rows = Vec::new();
    let mut earlier_ran: Option<Stage> = None;
    for def in stages() {
        let t0 = Instant::now();
        let stage = def.stage;
        if let Some(why) = (def.skip)(plan) {
            rows.push(StageRow {
                stage,
                status: why.into(),
                ran: false,
                reason: String::new(),
                seconds: 0.0,
            });
            continue;
        }
        let recorded = pipeline::read_manifest(&plan.out, stage);
        let now = pipeline::fingerprint(
            &(def.inputs)(plan),
            (def.options)(plan)?,
            recorded.as_ref().map(|m| &m.fingerprint),
        )?;
        let forced = match (plan.from, earlier_ran) {
            (Some(f), _) if stage >= f => Some(format!("--from {}", f.name())),
            (_, Some(e)) => Some(format!("{} ran", e.name())),
            _ => None,
        };
        let mut decision = pipeline::decide(
            recorded.as_ref(),
            &now,
            &(def.outputs)(plan),
            forced.as_deref(),
        );
        if let (Decision::Fresh, Some(m)) = (&decision, &recorded) {
            match (def.restore)(results, m.result.clone()) {
                Ok(()) => results.timings.push((stage.name().into(), m.seconds)),
                Err(e) => decision = Decision::Run(format!("its record is unreadable ({e})")),
            }
        }
        let Decision::Run(reason) = decision else {
            rows.push(StageRow {
                stage,
                status: "up to date".into(),
                ran: false,
                reason: String::new(),
                seconds: t0.elapsed().as_secs_f64(),
            });
            continue;
        };
        ctx.info(format!("[{}] {reason}", stage.name()));
        pipeline::remove_manifest(&plan.out, stage)?;
        // The report lists this stage's time, so record it before the report runs.
        let value = (def.run)(plan, results, ctx)?;
        let seconds = t0.elapsed().as_secs_f64();
        if stage != Stage::Report {
            results.timings.push((stage.name().into(), seconds));
        }
        pipeline::write_manifest(
            &plan.out,
            &Manifest {
                stage,
                fingerprint: now,
                seconds,
                result: value,
            },
        )?;
        earlier_ran = Some(stage);
        rows.push(StageRow {
            stage,
            status: "ran".into(),
            ran: true,
            reason,
            seconds,
        });
    }
    Ok(rows)
}

fn print_summary(ctx: &Ctx, plan: &Plan, rows: &[StageRow], results: &Results, total: f64) {
    let table = Table {
        caption: format!("romosplat run → {} ({total:.1} s)", plan.out.display()),
        header: vec![
            "stage".into(),
            "status".into(),
            "seconds".into(),
            "why".into(),
        ],
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    r.stage.name().into(),
                    r.status.clone(),
                    format!("{:.1}", r.seconds),
                    r.reason.clone(),
                ]
            })
            .collect(),
    };
    print_table(ctx, &table);
    if !rows.iter().any(|r| r.ran) {
        ctx.info("nothing to do: every stage is up to date");
    }
    let Some(train) = &results.train else { return };
    let Some(t) = &train.test else { return };
    ctx.info(format!(
        "held-out views: {} ({} views)",
        scores_line(t.mean_psnr, t.mean_ssim, train.test_lpips),
        t.views.len()
    ));
    for (name, o) in [("masks", &results.train), ("no masks", &results.baseline)] {
        if let Some(st) = o.as_ref().and_then(|o| o.test_static.as_ref()) {
            ctx.info(format!(
                "  static pixels, {name}: {}",
                scores_line(st.mean_psnr, st.mean_ssim, st.lpips)
            ));
        }
    }
    if let Some(b) = &results.baseline
        && let Some(bt) = &b.test
    {
        ctx.info(format!(
            "  all pixels, no masks (baseline): {}",
            scores_line(bt.mean_psnr, bt.mean_ssim, b.test_lpips)
        ));
    }
    if train.test_lpips.is_none() {
        ctx.info(splat::lpips_alex::missing_weights_hint(
            splat::lpips_alex::default_weights_path().as_deref(),
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(video: Option<PathBuf>, scene: Option<PathBuf>) -> InputArgs {
        InputArgs { video, scene }
    }

    /// A scene's samples are its images at the middles of equal parts of
    /// the name order; a video's are decoded at the middles of equal parts
    /// of its duration, at the frames' size.
    #[test]
    fn probe_frames_are_spread_over_the_input() {
        let dir = tempfile::tempdir().unwrap();
        let images = dir.path().join("scene/images");
        std::fs::create_dir_all(&images).unwrap();
        for i in 0..10 {
            image::RgbImage::new(8, 6)
                .save(images.join(format!("{i:02}.png")))
                .unwrap();
        }
        let scene = input(None, Some(dir.path().join("scene")));
        let got = scene
            .sample_frames(Path::new("ffmpeg"), 3, dir.path())
            .unwrap();
        let names: Vec<_> = got.iter().map(|p| p.file_name().unwrap()).collect();
        assert_eq!(names, ["01.png", "05.png", "08.png"]);
        assert_eq!(
            scene
                .sample_frames(Path::new("ffmpeg"), 30, dir.path())
                .unwrap()
                .len(),
            10
        );
        if !loader::video::ffmpeg_available() {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI is set but ffmpeg is missing"
            );
            return;
        }
        // 3 s at 10 fps whose frame number is drawn as text: frames decoded
        // at 0.5, 1.5 and 2.5 s differ.
        let v = dir.path().join("clip.mp4");
        let st = std::process::Command::new("ffmpeg")
            .args(["-hide_banner", "-loglevel", "error", "-nostdin", "-y"])
            .args(["-f", "lavfi", "-i", "testsrc=size=64x48:rate=10:duration=3"])
            .args(["-c:v", "mpeg4"])
            .arg(&v)
            .status()
            .unwrap();
        assert!(st.success());
        let out = dir.path().join("frames");
        std::fs::create_dir_all(&out).unwrap();
        let got = input(Some(v.clone()), None)
            .sample_frames(Path::new("ffmpeg"), 3, &out)
            .unwrap();
        assert_eq!(got.len(), 3);
        let pixels: Vec<Vec<u8>> = got
            .iter()
            .map(|p| {
                let img = image::open(p).unwrap().to_rgb8();
                assert_eq!(img.dimensions(), (64, 48));
                img.into_raw()
            })
            .collect();
        assert!(pixels[0] != pixels[1] && pixels[1] != pixels[2]);
        // Not a video: a one-line error naming the file.
        let bad = dir.path().join("bad.mp4");
        std::fs::write(&bad, b"nothing").unwrap();
        let e = input(Some(bad), None)
            .sample_frames(Path::new("ffmpeg"), 3, &out)
            .unwrap_err();
        assert!(format!("{e:#}").contains("bad.mp4"), "{e:#}");
    }
}
