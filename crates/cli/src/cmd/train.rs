//! `romosplat train --scene DIR [--no-masks] [--poses PATH] [--steps N]
//! [--backend auto|wgpu|cpu] --out DIR`: masked Gaussian-splatting training.
//! Writes `DIR/splats.ply` (INRIA layout), `DIR/checkpoint.bin` and
//! `DIR/summary.json`; progress on stderr; held-out views (split.json
//! `extra`, or every Nth with `--holdout-every`) are scored at the end.

use crate::Ctx;
use anyhow::{Context, bail};
use loader::{Scene, SceneOptions};
use splat::backend::TrainBackend;
use splat::io::{Checkpoint, read_checkpoint, write_ply};
use splat::reference::CpuBackend;
use splat::train::data::{InitReport, View, initial_splats, load_views, scene_extent};
use splat::train::eval::{EvalReport, evaluate, score_images};
use splat::train::{TrainData, TrainOptions, TrainReport, Trainer, fresh_start};
use splat::types::RenderOptions;
use std::path::{Path, PathBuf};

/// Which training backend.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendKind {
    /// wgpu when an adapter exists, else the CPU reference.
    Auto,
    /// wgpu (error when no adapter).
    Wgpu,
    /// CPU reference (rayon).
    Cpu,
}

/// Make a backend; says which on stderr.
pub fn make_backend(kind: BackendKind, ctx: &Ctx) -> anyhow::Result<Box<dyn TrainBackend>> {
    make_train_backend(kind, false, ctx)
}

/// Make a backend, with sparse Adam on the GPU when asked (an error on the
/// CPU reference, which has only dense Adam); says which on stderr.
pub fn make_train_backend(
    kind: BackendKind,
    sparse_adam: bool,
    ctx: &Ctx,
) -> anyhow::Result<Box<dyn TrainBackend>> {
    let gpu = || {
        splat::gpu::backend::GpuBackend::new(&splat::gpu::context::GpuOptions::default()).map(
            |mut g| {
                g.sparse_adam = sparse_adam;
                g
            },
        )
    };
    let cpu = || {
        if sparse_adam {
            anyhow::bail!(
                "--sparse-adam needs the wgpu backend (the CPU reference has dense Adam only)"
            )
        }
        Ok(CpuBackend::new())
    };
    let b: Box<dyn TrainBackend> = match kind {
        BackendKind::Cpu => Box::new(cpu()?),
        BackendKind::Wgpu => Box::new(gpu().map_err(|e| anyhow::anyhow!("wgpu backend: {e}"))?),
        BackendKind::Auto => match gpu() {
            Ok(g) => Box::new(g),
            Err(e) => {
                ctx.info(format!(
                    "no usable GPU adapter ({e}); using the CPU reference backend"
                ));
                Box::new(cpu()?)
            }
        },
    };
    ctx.info(format!("backend: {}", b.name()));
    Ok(b)
}

/// `romosplat train`
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene folder (images/, masks/, sparse/0 or transforms.json, split.json).
    #[arg(long)]
    pub scene: PathBuf,
    /// Ignore masks/ (every pixel counts in the loss and in init filtering).
    #[arg(long)]
    pub no_masks: bool,
    /// COLMAP model folder whose poses and points replace the scene's.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Training steps (INRIA: 30000).
    #[arg(long, default_value_t = TrainOptions::default().steps)]
    pub steps: u32,
    #[arg(long, value_enum, default_value_t = BackendKind::Auto)]
    pub backend: BackendKind,
    /// Integer image downscale factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Hold out every Nth frame for testing when the scene has no split.json (0 = none).
    #[arg(long, default_value_t = 0)]
    pub holdout_every: usize,
    #[command(flatten)]
    pub flags: TrainFlags,
    /// Stop after this many minutes of training (0 = no limit); the summary
    /// reports the steps actually done.
    #[arg(long, default_value_t = 0.0)]
    pub max_minutes: f64,
    /// Resume from this checkpoint.bin.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
}

/// The training flags `train` shares with `onthego --train-args`: the
/// algorithm's options (`splat::train::TrainOptions`, whose `Default` gives
/// every flag's default) and sparse Adam.
#[derive(Debug, Clone, clap::Args)]
pub struct TrainFlags {
    #[command(flatten)]
    pub opts: TrainOptions,
    /// Sparse Adam on the GPU (gsplat's SelectiveAdam, Brush): splats not
    /// visible in a step's view keep their parameters and moments instead
    /// of decaying the moments and moving by momentum as torch's dense Adam
    /// does (INRIA). Off by default; wgpu only.
    #[arg(long)]
    pub sparse_adam: bool,
}

impl TrainFlags {
    /// The options of a `steps`-long run, with or without masks: `--max-splats`
    /// caps both strategies.
    pub fn train_options(&self, steps: u32, use_masks: bool) -> TrainOptions {
        let mut o = TrainOptions {
            steps,
            use_masks,
            ..self.opts.clone()
        };
        o.cap_mcmc_at_max_splats();
        o
    }
}

/// Replace frame poses (and the model used for init) with a COLMAP model's.
pub fn apply_poses(scene: &mut Scene, path: &Path) -> anyhow::Result<()> {
    let dir = loader::colmap::find_model_dir(path)
        .with_context(|| format!("{}: no COLMAP model", path.display()))?;
    let model = loader::colmap::read_model(&dir)?;
    let mut matched = 0;
    for f in &mut scene.frames {
        f.pose = None;
        if let Some(im) = model.image_by_name(&f.name) {
            f.pose = Some(im.pose);
            if let Some(cam) = model.cameras.get(&im.camera_id) {
                f.intrinsics = cam
                    .intrinsics()
                    .scaled_to(f.intrinsics.width, f.intrinsics.height);
            }
            matched += 1;
        }
    }
    if matched == 0 {
        bail!(
            "{}: no image of the model matches a scene frame",
            dir.display()
        );
    }
    scene.model = Some(model);
    Ok(())
}

/// Train and test frame indices: split.json, else every Nth held out, else all train.
pub fn split_views(scene: &Scene, holdout_every: usize) -> (Vec<usize>, Vec<usize>) {
    let posed = |i: &usize| scene.frames[*i].pose.is_some();
    if scene.split.is_some() {
        let tr: Vec<usize> = scene
            .split_indices("clutter")
            .into_iter()
            .filter(posed)
            .collect();
        let te: Vec<usize> = scene
            .split_indices("extra")
            .into_iter()
            .filter(posed)
            .collect();
        return (tr, te);
    }
    let all: Vec<usize> = (0..scene.len()).filter(posed).collect();
    if holdout_every > 0 {
        let (te, tr): (Vec<usize>, Vec<usize>) = all.iter().partition(|&&i| i % holdout_every == 0);
        (tr, te)
    } else {
        (all, Vec::new())
    }
}

/// A training run, typed: what [`train`] needs.
#[derive(Debug, Clone)]
pub struct TrainJob {
    /// Scene folder (images/, masks/, sparse/0 or transforms.json, split.json).
    pub scene: PathBuf,
    /// COLMAP model folder whose poses replace the scene's.
    pub poses: Option<PathBuf>,
    /// Integer image downscale factor.
    pub downscale: u32,
    /// Hold out every Nth frame when the scene has no split.json (0 = none).
    pub holdout_every: usize,
    pub backend: BackendKind,
    /// Sparse Adam (wgpu only).
    pub sparse_adam: bool,
    /// Resume from this checkpoint.bin.
    pub resume: Option<PathBuf>,
    /// Output folder (splats.ply, checkpoint.bin, summary.json).
    pub out: PathBuf,
    /// Write the held-out renders here as `<stem>.png`.
    pub test_renders: Option<PathBuf>,
    pub opts: TrainOptions,
}

/// Held-out scores with the moving pixels of the held-out frames (their
/// `masks/`) left out, as `eval views --mask-gt` does with ground truth: on
/// a video the held-out frames have people in them that a masked model
/// rightly does not reconstruct, so this is where models trained with and
/// without masks compare on the same pixels.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct StaticScores {
    /// Held-out views whose mask leaves out some pixels (the others count
    /// all their pixels).
    pub masked_views: usize,
    pub mean_psnr: f64,
    pub mean_ssim: f64,
    /// LPIPS-Alex with the moving pixels copied from the reference.
    pub lpips: Option<f64>,
}

/// "PSNR 25.52 dB, SSIM 0.8690, LPIPS 0.0790" (LPIPS when it was scored):
/// how held-out scores are printed.
pub fn scores_line(psnr: f64, ssim: f64, lpips: Option<f64>) -> String {
    format!(
        "PSNR {psnr:.2} dB, SSIM {ssim:.4}{}",
        lpips.map_or(String::new(), |l| format!(", LPIPS {l:.4}"))
    )
}

/// [`StaticScores`] of the held-out `images` (rendered for the all-pixel
/// scores) against `views` with their masks; `None` when no view's mask
/// leaves out a pixel.
fn score_static_pixels(
    views: &[View],
    images: &[Vec<f32>],
    lpips: Option<&mut super::eval_views::Lpips>,
    ctx: &Ctx,
) -> anyhow::Result<Option<StaticScores>> {
    // Views whose mask leaves out no pixel score the same as over all
    // pixels: without any, there is nothing static-only to report.
    let masked_views = views
        .iter()
        .filter(|v| v.mask.as_ref().is_some_and(|m| m.iter().any(|k| *k < 1.0)))
        .count();
    if masked_views == 0 {
        return Ok(None);
    }
    let ev = score_images(views, images);
    let lpips = match lpips {
        Some(net) => Some(super::eval_views::mean_std(&net.score_views(views, images)?).0),
        None => None,
    };
    ctx.info(format!(
        "test views, static pixels ({masked_views} with masks): {}",
        scores_line(ev.mean_psnr, ev.mean_ssim, lpips)
    ));
    Ok(Some(StaticScores {
        masked_views,
        mean_psnr: ev.mean_psnr,
        mean_ssim: ev.mean_ssim,
        lpips,
    }))
}

/// One sample of the training curves.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct HistoryPoint {
    pub step: u32,
    pub loss: f32,
    pub psnr: f32,
    pub splats: usize,
}

/// What [`train`] did (also written as `summary.json`).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct TrainOutcome {
    pub splats_ply: PathBuf,
    pub checkpoint: PathBuf,
    pub backend: String,
    pub train_views: usize,
    pub masked_views: usize,
    pub extent: f32,
    pub init: Option<InitReport>,
    pub report: TrainReport,
    /// Held-out scores (none when nothing is held out).
    pub test: Option<EvalReport>,
    /// Held-out renders (PNG), in the order of `test.views`.
    #[serde(default)]
    pub test_renders: Vec<PathBuf>,
    /// Mean held-out LPIPS-Alex (when its weights are found).
    #[serde(default)]
    pub test_lpips: Option<f64>,
    /// Held-out scores over static pixels only, when held-out frames have masks.
    #[serde(default)]
    pub test_static: Option<StaticScores>,
    /// About 100 samples of the loss / PSNR curves.
    pub history: Vec<HistoryPoint>,
    pub options: TrainOptions,
}

impl Args {
    /// The training options these flags select.
    pub fn train_options(&self) -> TrainOptions {
        TrainOptions {
            time_limit_s: self.max_minutes * 60.0,
            ..self.flags.train_options(self.steps, !self.no_masks)
        }
    }

    /// The typed job these flags describe.
    pub fn job(&self) -> TrainJob {
        TrainJob {
            scene: self.scene.clone(),
            poses: self.poses.clone(),
            downscale: self.downscale,
            holdout_every: self.holdout_every,
            backend: self.backend,
            sparse_adam: self.flags.sparse_adam,
            resume: self.resume.clone(),
            out: self.out.clone(),
            test_renders: None,
            opts: self.train_options(),
        }
    }
}

impl TrainOutcome {
    /// (step, loss) samples of the training curve.
    pub fn loss_curve(&self) -> Vec<(f64, f64)> {
        self.history
            .iter()
            .map(|h| (h.step as f64, h.loss as f64))
            .collect()
    }

    /// (step, training PSNR) samples of the training curve.
    pub fn psnr_curve(&self) -> Vec<(f64, f64)> {
        self.history
            .iter()
            .map(|h| (h.step as f64, h.psnr as f64))
            .collect()
    }
}

/// `romosplat train`: run the job, write `summary.json`, return it.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    Ok(serde_json::to_value(train(&args.job(), ctx)?)?)
}

/// Train a scene: load, initialise, train, write `splats.ply` and
/// `summary.json`, score (and optionally render) the held-out views.
pub fn train(job: &TrainJob, ctx: &Ctx) -> anyhow::Result<TrainOutcome> {
    let (run, start) = prepare(job, ctx)?;
    // Outputs (checkpoints, splats.ply, summary.json) are staged and moved
    // into --out together at the end: a failed run leaves --out untouched.
    let stage = loader::io::Staging::new(&job.out)?;
    // Errors name the output folder, not the hidden staging folder.
    let staged = (|| -> anyhow::Result<TrainOutcome> {
        let mut backend = make_train_backend(job.backend, job.sparse_adam, ctx)?;
        let (end, report, history) = run_trainer(backend.as_mut(), &run, start, stage.path(), ctx)?;
        let ply = job.out.join("splats.ply");
        write_ply(stage.path().join("splats.ply"), &end.splats)?;
        ctx.info(format!(
            "trained {} steps in {:.1} s ({:.2} steps/s), {} splats, train PSNR {:.2} → {}",
            report.steps - report.start_step,
            report.seconds,
            report.steps_per_sec,
            report.splats,
            report.final_train_psnr,
            ply.display()
        ));
        let held_out = if run.test_idx.is_empty() {
            HeldOut::default()
        } else {
            score_held_out(backend.as_mut(), &end.splats, &run, job, ctx)?
        };
        let outcome = TrainOutcome {
            splats_ply: ply,
            checkpoint: job.out.join("checkpoint.bin"),
            backend: report.backend.clone(),
            train_views: run.train_idx.len(),
            masked_views: run.masked,
            extent: run.data.extent,
            init: run.init,
            report,
            test: held_out.test,
            test_renders: held_out.renders,
            test_lpips: held_out.lpips,
            test_static: held_out.static_scores,
            history,
            options: run.opts,
        };
        loader::io::write_bytes_atomic(
            stage.path().join("summary.json"),
            serde_json::to_string_pretty(&outcome)?.as_bytes(),
        )?;
        Ok(outcome)
    })();
    let outcome = staged.map_err(|e| anyhow::anyhow!(stage.public(&format!("{e:#}"))))?;
    stage.commit()?;
    Ok(outcome)
}

/// A loaded training run: the scene, its split and the training views.
struct Prepared {
    scene: Scene,
    opts: TrainOptions,
    train_idx: Vec<usize>,
    test_idx: Vec<usize>,
    data: TrainData,
    /// Training views with a mask.
    masked: usize,
    init: Option<InitReport>,
}

/// Load the scene (with `--poses` applied), split it, load the training
/// views and initialise the splats (or read the checkpoint to resume): the
/// run and its starting point.
fn prepare(job: &TrainJob, ctx: &Ctx) -> anyhow::Result<(Prepared, Checkpoint)> {
    let mut scene = Scene::load(
        &job.scene,
        &SceneOptions {
            downscale: job.downscale,
        },
    )?;
    if let Some(p) = &job.poses {
        apply_poses(&mut scene, p)?;
    }
    let opts = job.opts.clone();
    opts.validate()?;
    let (train_idx, test_idx) = split_views(&scene, job.holdout_every);
    if train_idx.is_empty() {
        bail!("{}: no posed training frames", job.scene.display());
    }
    ctx.info(format!(
        "loading {} training and {} test views",
        train_idx.len(),
        test_idx.len()
    ));
    let views = load_views(&scene, &train_idx, opts.use_masks)?;
    let masked = views.iter().filter(|v| v.mask.is_some()).count();
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let extent = scene_extent(&cams);
    let (start, init) = match &job.resume {
        Some(p) => (read_checkpoint(p)?, None),
        None => {
            let (s, rep) = initial_splats(&scene, &cams, extent, &opts)?;
            ctx.info(format!(
                "init: {} splats from {} ({} points skipped as moving)",
                rep.splats, rep.source, rep.skipped_moving
            ));
            (fresh_start(s), Some(rep))
        }
    };
    let run = Prepared {
        scene,
        opts,
        train_idx,
        test_idx,
        data: TrainData { views, extent },
        masked,
        init,
    };
    Ok((run, start))
}

/// Run the trainer with a progress bar (checkpoints into `checkpoint_dir`);
/// returns the end state, the report and about 100 curve samples.
fn run_trainer(
    backend: &mut dyn TrainBackend,
    run: &Prepared,
    start: Checkpoint,
    checkpoint_dir: &Path,
    ctx: &Ctx,
) -> anyhow::Result<(Checkpoint, TrainReport, Vec<HistoryPoint>)> {
    let opts = &run.opts;
    let pb = ctx.progress(opts.steps as u64, "train");
    pb.set_position(start.step as u64);
    pb.reset_rate();
    let mut trainer = Trainer {
        backend,
        data: &run.data,
        opts: opts.clone(),
        checkpoint_dir: Some(checkpoint_dir.to_path_buf()),
    };
    let every = (opts.steps / 100).max(1);
    let mut history: Vec<HistoryPoint> = Vec::new();
    let (end, rep) = trainer.run(start, &mut |p| {
        if p.step.is_multiple_of(every) || p.step == p.steps {
            history.push(HistoryPoint {
                step: p.step,
                loss: p.loss,
                psnr: p.psnr,
                splats: p.splats,
            });
        }
        pb.set_position(p.step as u64);
        if p.step.is_multiple_of(10) || p.step == p.steps {
            pb.set_message(format!(
                "loss {:.4} psnr {:.2} splats {}",
                p.loss, p.psnr, p.splats
            ));
        }
    })?;
    pb.finish_and_clear();
    Ok((end, rep, history))
}

/// The held-out scores of a trained model.
#[derive(Default)]
struct HeldOut {
    test: Option<EvalReport>,
    renders: Vec<PathBuf>,
    lpips: Option<f64>,
    static_scores: Option<StaticScores>,
}

/// Render the held-out views once and score them on all pixels and, where
/// they have masks, on their static pixels; write the renders when the job
/// asks for them.
fn score_held_out(
    backend: &mut dyn TrainBackend,
    splats: &splat::Splats,
    run: &Prepared,
    job: &TrainJob,
    ctx: &Ctx,
) -> anyhow::Result<HeldOut> {
    let mut views = load_views(&run.scene, &run.test_idx, true)?;
    let masks: Vec<Option<Vec<f32>>> = views.iter_mut().map(|v| v.mask.take()).collect();
    let ropts = RenderOptions {
        background: run.opts.background,
        sh_degree: splats.sh_degree,
        low_pass: run.opts.low_pass,
        antialiased: run.opts.antialiased,
    };
    let (ev, images) = evaluate(backend, splats, &views, &ropts)?;
    ctx.info(format!(
        "test views: PSNR {:.2} dB, SSIM {:.4} ({} views)",
        ev.mean_psnr,
        ev.mean_ssim,
        ev.views.len()
    ));
    let mut net = super::eval_views::builtin_lpips()?;
    let mut lpips = None;
    if let Some(net) = net.as_mut() {
        let mean = super::eval_views::mean_std(&net.score_views(&views, &images)?).0;
        ctx.info(format!("test views: LPIPS {mean:.4}"));
        lpips = Some(mean);
    }
    let mut renders = Vec::new();
    if let Some(dir) = &job.test_renders {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for (v, img) in views.iter().zip(&images) {
            let path = dir.join(format!("{}.png", super::render::stem(&v.name)));
            let img = image::Rgb32FImage::from_raw(v.camera.width, v.camera.height, img.clone())
                .ok_or_else(|| anyhow::anyhow!("{}: render size mismatch", v.name))?;
            loader::io::write_png_rgb32f(&path, &img)?;
            renders.push(path);
        }
    }
    for (v, m) in views.iter_mut().zip(masks) {
        v.mask = m;
    }
    let static_scores = score_static_pixels(&views, &images, net.as_mut(), ctx)?;
    Ok(HeldOut {
        test: Some(ev),
        renders,
        lpips,
        static_scores,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Train {
        #[command(flatten)]
        args: Args,
    }

    fn parse(extra: &[&str]) -> Args {
        let base = ["train", "--scene", "s", "--out", "o"];
        Train::try_parse_from(base.iter().chain(extra))
            .unwrap()
            .args
    }

    #[test]
    fn static_scores_need_a_mask_that_leaves_out_pixels() {
        let ctx = Ctx {
            json: false,
            quiet: true,
        };
        let view = |mask: Option<Vec<f32>>| View {
            index: 0,
            name: "v".into(),
            camera: splat::RenderCamera::at_origin(2, 1, 1.0),
            image: vec![0.5; 6],
            mask,
        };
        // Rendered: one pixel right, one off by 0.1 in every channel.
        let images = vec![vec![0.5, 0.5, 0.5, 0.6, 0.6, 0.6]];
        let score = |v: View| score_static_pixels(&[v], &images, None, &ctx).unwrap();
        assert!(score(view(None)).is_none());
        assert!(score(view(Some(vec![1.0, 1.0]))).is_none());
        // The wrong pixel left out: the static pixels are rendered exactly.
        let s = score(view(Some(vec![1.0, 0.0]))).unwrap();
        assert_eq!(s.masked_views, 1);
        assert!(s.mean_psnr > 60.0, "{}", s.mean_psnr);
    }

    #[test]
    fn no_flags_give_the_library_defaults() {
        let a = parse(&[]);
        assert_eq!(a.train_options(), TrainOptions::default());
        assert!(!a.flags.sparse_adam);
    }

    #[test]
    fn every_training_flag_reaches_its_option() {
        let a = parse(&[
            "--steps",
            "300",
            "--no-masks",
            "--max-minutes",
            "2",
            "--ssim-weight",
            "0.1",
            "--sh-degree",
            "1",
            "--sh-degree-every",
            "50",
            "--max-splats",
            "5000",
            "--strategy",
            "mcmc",
            "--densify-from",
            "7",
            "--densify-until",
            "90",
            "--densify-every",
            "11",
            "--grad-threshold",
            "0.001",
            "--opacity-reset-every",
            "0",
            "--prune-screen-px",
            "20",
            "--init",
            "random",
            "--random-background",
            "--antialiased",
            "--checkpoint-every",
            "100",
            "--seed",
            "3",
            "--sparse-adam",
        ]);
        let o = a.train_options();
        let d = TrainOptions::default();
        let expected = TrainOptions {
            steps: 300,
            use_masks: false,
            time_limit_s: 120.0,
            ssim_weight: 0.1,
            sh_degree: 1,
            sh_degree_every: 50,
            strategy: splat::strategy::DefaultStrategyOptions {
                max_splats: 5000,
                densify_from: 7,
                densify_until: 90,
                densify_every: 11,
                grad_threshold: 0.001,
                opacity_reset_every: 0,
                prune_screen_px: 20.0,
                ..d.strategy.clone()
            },
            strategy_kind: splat::strategy::StrategyKind::Mcmc,
            mcmc: splat::strategy::McmcStrategyOptions {
                cap_max: 5000,
                ..d.mcmc.clone()
            },
            init: splat::train::InitMode::Random,
            random_background: true,
            antialiased: true,
            checkpoint_every: 100,
            seed: 3,
            ..d
        };
        assert_eq!(o, expected);
        assert!(a.job().sparse_adam);
    }
}
