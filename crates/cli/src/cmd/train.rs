//! `romosplat train --scene DIR [--no-masks] [--poses PATH] [--steps N]
//! [--backend auto|wgpu|cpu] --out DIR`: masked Gaussian-splatting training.
//! Writes `DIR/splats.ply` (INRIA layout), `DIR/checkpoint.bin` and
//! `DIR/summary.json`; progress on stderr; held-out views (split.json
//! `extra`, or every Nth with `--holdout-every`) are scored at the end.

use crate::Ctx;
use anyhow::{Context, bail};
use loader::{Scene, SceneOptions};
use splat::backend::TrainBackend;
use splat::io::{read_checkpoint, write_ply};
use splat::reference::CpuBackend;
use splat::train::data::{InitReport, initial_splats, load_views, scene_extent};
use splat::train::eval::{EvalReport, evaluate};
use splat::train::{InitMode, TrainData, TrainOptions, TrainReport, Trainer, fresh_start};
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
    /// D-SSIM weight λ (INRIA: 0.2; 0 disables SSIM).
    #[arg(long, default_value_t = TrainOptions::default().ssim_weight)]
    pub ssim_weight: f32,
    /// Highest SH degree (0..=3).
    #[arg(long, default_value_t = TrainOptions::default().sh_degree)]
    pub sh_degree: u32,
    /// Cap on the number of splats (MCMC: its cap is min(1 000 000, this)).
    #[arg(long, default_value_t = splat::strategy::DefaultStrategyOptions::default().max_splats)]
    pub max_splats: usize,
    /// Densification strategy.
    #[arg(long, value_enum, default_value_t = splat::strategy::StrategyKind::Default)]
    pub strategy: splat::strategy::StrategyKind,
    /// Default strategy: first step that densifies (INRIA 500).
    #[arg(long, default_value_t = splat::strategy::DefaultStrategyOptions::default().densify_from)]
    pub densify_from: u32,
    /// Default strategy: last step that densifies (INRIA 15000).
    #[arg(long, default_value_t = splat::strategy::DefaultStrategyOptions::default().densify_until)]
    pub densify_until: u32,
    /// Default strategy: densify every N steps (INRIA 100).
    #[arg(long, default_value_t = splat::strategy::DefaultStrategyOptions::default().densify_every)]
    pub densify_every: u32,
    /// Default strategy: view-space positional gradient threshold (INRIA 2e-4).
    #[arg(long, default_value_t = splat::strategy::DefaultStrategyOptions::default().grad_threshold)]
    pub grad_threshold: f32,
    /// Default strategy: reset opacities every N steps (INRIA 3000; 0 = never).
    #[arg(long, default_value_t = splat::strategy::DefaultStrategyOptions::default().opacity_reset_every)]
    pub opacity_reset_every: u32,
    /// Default strategy: after the first opacity reset, prune splats wider
    /// than this many pixels on screen (INRIA 20; 0 = off, the default, as
    /// gsplat: at low resolution the 20 px rule removes the large splats
    /// that carry the background).
    #[arg(long, default_value_t = splat::strategy::DefaultStrategyOptions::default().prune_screen_px)]
    pub prune_screen_px: f32,
    /// Sparse Adam on the GPU (gsplat's SelectiveAdam, Brush): splats not
    /// visible in a step's view keep their parameters and moments instead
    /// of decaying the moments and moving by momentum as torch's dense Adam
    /// does (INRIA). Off by default; wgpu only.
    #[arg(long)]
    pub sparse_adam: bool,
    /// Raise the active SH degree by one every N steps (INRIA 1000).
    #[arg(long, default_value_t = TrainOptions::default().sh_degree_every)]
    pub sh_degree_every: u32,
    /// Initialisation source.
    #[arg(long, value_enum, default_value_t = InitMode::Auto)]
    pub init: InitMode,
    /// Random background each step.
    #[arg(long)]
    pub random_background: bool,
    /// Antialiased (Mip-Splatting) rendering.
    #[arg(long)]
    pub antialiased: bool,
    /// Write a checkpoint every N steps (0 = only at the end).
    #[arg(long, default_value_t = 0)]
    pub checkpoint_every: u32,
    /// Stop after this many minutes of training (0 = no limit); the summary
    /// reports the steps actually done.
    #[arg(long, default_value_t = 0.0)]
    pub max_minutes: f64,
    /// Resume from this checkpoint.bin.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Random seed.
    #[arg(long, default_value_t = TrainOptions::default().seed)]
    pub seed: u64,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
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
    /// Held-out views that have a mask (the others count all their pixels).
    pub masked_views: usize,
    pub mean_psnr: f64,
    pub mean_ssim: f64,
    /// LPIPS-Alex with the moving pixels copied from the reference.
    pub lpips: Option<f64>,
}

/// [`StaticScores`] of `splats` on held-out frames `idx`; `None` when none
/// of them has a mask.
fn score_static_pixels(
    backend: &mut dyn TrainBackend,
    splats: &splat::Splats,
    scene: &Scene,
    idx: &[usize],
    ropts: &RenderOptions,
    ctx: &Ctx,
) -> anyhow::Result<Option<StaticScores>> {
    let views = load_views(scene, idx, true)?;
    let masked_views = views.iter().filter(|v| v.mask.is_some()).count();
    if masked_views == 0 {
        return Ok(None);
    }
    let (ev, images) = evaluate(backend, splats, &views, ropts)?;
    let lpips = match super::eval_views::builtin_lpips()? {
        Some(mut net) => Some(super::eval_views::mean_std(&net.score_views(&views, &images)?).0),
        None => None,
    };
    ctx.info(format!(
        "test views, static pixels ({masked_views} with masks): PSNR {:.2} dB, SSIM {:.4}{}",
        ev.mean_psnr,
        ev.mean_ssim,
        lpips.map_or(String::new(), |l| format!(", LPIPS {l:.4}"))
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
            steps: self.steps,
            ssim_weight: self.ssim_weight,
            sh_degree: self.sh_degree,
            random_background: self.random_background,
            antialiased: self.antialiased,
            use_masks: !self.no_masks,
            checkpoint_every: self.checkpoint_every,
            time_limit_s: self.max_minutes * 60.0,
            seed: self.seed,
            init: self.init,
            sh_degree_every: self.sh_degree_every,
            strategy: splat::strategy::DefaultStrategyOptions {
                max_splats: self.max_splats,
                densify_from: self.densify_from,
                densify_until: self.densify_until,
                densify_every: self.densify_every,
                grad_threshold: self.grad_threshold,
                opacity_reset_every: self.opacity_reset_every,
                prune_screen_px: self.prune_screen_px,
                ..Default::default()
            },
            strategy_kind: self.strategy,
            mcmc: {
                let d = splat::strategy::McmcStrategyOptions::default();
                splat::strategy::McmcStrategyOptions {
                    cap_max: d.cap_max.min(self.max_splats),
                    ..d
                }
            },
            ..Default::default()
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
            sparse_adam: self.sparse_adam,
            resume: self.resume.clone(),
            out: self.out.clone(),
            test_renders: None,
            opts: self.train_options(),
        }
    }
}

/// `romosplat train`: run the job, write `summary.json`, return it.
pub fn run(args: &Args, ctx: &Ctx) -> anyhow::Result<serde_json::Value> {
    Ok(serde_json::to_value(train(&args.job(), ctx)?)?)
}

/// Train a scene: load, initialise, train, write `splats.ply` and
/// `summary.json`, score (and optionally render) the held-out views.
pub fn train(job: &TrainJob, ctx: &Ctx) -> anyhow::Result<TrainOutcome> {
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
    let data = TrainData { views, extent };
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
    // Outputs (checkpoints, splats.ply, summary.json) are staged and moved
    // into --out together at the end: a failed run leaves --out untouched.
    let stage = loader::io::Staging::new(&job.out)?;
    // Errors name the output folder, not the hidden staging folder.
    let staged = (|| -> anyhow::Result<TrainOutcome> {
        let mut backend = make_train_backend(job.backend, job.sparse_adam, ctx)?;
        let pb = ctx.progress(opts.steps as u64, "train");
        pb.set_position(start.step as u64);
        pb.reset_rate();
        let mut trainer = Trainer {
            backend: backend.as_mut(),
            data: &data,
            opts: opts.clone(),
            checkpoint_dir: Some(stage.path().to_path_buf()),
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
        let ply = job.out.join("splats.ply");
        write_ply(stage.path().join("splats.ply"), &end.splats)?;
        ctx.info(format!(
            "trained {} steps in {:.1} s ({:.2} steps/s), {} splats, train PSNR {:.2} → {}",
            rep.steps - rep.start_step,
            rep.seconds,
            rep.steps_per_sec,
            rep.splats,
            rep.final_train_psnr,
            ply.display()
        ));
        let mut test = None;
        let mut test_renders = Vec::new();
        let mut test_lpips = None;
        let mut test_static = None;
        if !test_idx.is_empty() {
            let tviews = load_views(&scene, &test_idx, false)?;
            let ropts = RenderOptions {
                background: opts.background,
                sh_degree: end.splats.sh_degree,
                low_pass: opts.low_pass,
                antialiased: opts.antialiased,
            };
            let (ev, images) = evaluate(backend.as_mut(), &end.splats, &tviews, &ropts)?;
            ctx.info(format!(
                "test views: PSNR {:.2} dB, SSIM {:.4} ({} views)",
                ev.mean_psnr,
                ev.mean_ssim,
                ev.views.len()
            ));
            if let Some(mut net) = super::eval_views::builtin_lpips()? {
                let l = net.score_views(&tviews, &images)?;
                let mean = super::eval_views::mean_std(&l).0;
                ctx.info(format!("test views: LPIPS {mean:.4}"));
                test_lpips = Some(mean);
            }
            if let Some(dir) = &job.test_renders {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
                for (v, img) in tviews.iter().zip(images) {
                    let path = dir.join(format!("{}.png", super::render::stem(&v.name)));
                    let img = image::Rgb32FImage::from_raw(v.camera.width, v.camera.height, img)
                        .ok_or_else(|| anyhow::anyhow!("{}: render size mismatch", v.name))?;
                    loader::io::write_png_rgb32f(&path, &img)?;
                    test_renders.push(path);
                }
            }
            test_static = score_static_pixels(
                backend.as_mut(),
                &end.splats,
                &scene,
                &test_idx,
                &ropts,
                ctx,
            )?;
            test = Some(ev);
        }
        let outcome = TrainOutcome {
            splats_ply: ply,
            checkpoint: job.out.join("checkpoint.bin"),
            backend: rep.backend.clone(),
            train_views: train_idx.len(),
            masked_views: masked,
            extent,
            init,
            report: rep,
            test,
            test_renders,
            test_lpips,
            test_static,
            history,
            options: opts,
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
