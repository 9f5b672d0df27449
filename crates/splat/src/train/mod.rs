//! Training: the schedule (learning rates, SH degree, view order,
//! background), the masked loss, the optimiser and the loop that drives a
//! [`TrainBackend`] and a densification [`Strategy`] (Kerbl et al. 2023).
//!
//! Every random choice is drawn from a generator seeded by (seed, step), so
//! a run is reproducible on the CPU backend and a resumed run makes the same
//! choices as an uninterrupted one.

pub mod adam;
pub mod data;
pub mod eval;
pub mod loss;
pub mod options;

pub use data::{InitReport, TrainData, View};
pub use options::{InitMode, TrainOptions};

use crate::backend::{LossConfig, TrainBackend};
use crate::error::Result;
use crate::io::{Checkpoint, write_checkpoint};
use crate::strategy::{
    DefaultStrategy, McmcStrategy, ModelState, RefineReport, SceneInfo, Strategy, StrategyKind,
};
use crate::types::{AdamState, DensifyStats, RenderOptions, Splats};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::time::Instant;

/// SplitMix64 finaliser: independent seeds from (seed, a, b).
pub fn mix_seed(seed: u64, a: u64, b: u64) -> u64 {
    let mut z =
        seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Progress reported after each step.
#[derive(Debug, Clone, Serialize)]
pub struct Progress {
    /// Steps completed.
    pub step: u32,
    pub steps: u32,
    pub loss: f32,
    /// PSNR of the last training view over kept pixels (dB).
    pub psnr: f32,
    pub splats: usize,
    /// Steps per second since the start of this run.
    pub steps_per_sec: f32,
}

/// Summary of a training run.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TrainReport {
    pub backend: String,
    pub steps: u32,
    pub start_step: u32,
    pub splats: usize,
    /// Mean loss and training PSNR over the last 100 steps.
    pub final_loss: f32,
    pub final_train_psnr: f32,
    pub seconds: f64,
    pub steps_per_sec: f64,
    /// Σ over refinements.
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
    pub opacity_resets: usize,
    /// Σ dead splats relocated (MCMC).
    #[serde(default)]
    pub relocated: usize,
    /// Σ splats added by MCMC growth.
    #[serde(default)]
    pub added: usize,
}

/// A training run: backend, data, options, where to write checkpoints.
pub struct Trainer<'a> {
    pub backend: &'a mut dyn TrainBackend,
    pub data: &'a TrainData,
    pub opts: TrainOptions,
    /// Directory for `checkpoint.bin` (none: no checkpoints).
    pub checkpoint_dir: Option<PathBuf>,
}

impl Trainer<'_> {
    /// Train from `start` (step 0 with fresh Adam state, or a checkpoint) to
    /// `opts.steps`, calling `progress` after every step.
    pub fn run(
        &mut self,
        start: Checkpoint,
        progress: &mut dyn FnMut(&Progress),
    ) -> Result<(Checkpoint, TrainReport)> {
        let o = self.opts.clone();
        o.validate()?;
        let nv = self.data.views.len();
        if nv == 0 {
            return Err(crate::SplatError::Invalid("no training views".into()));
        }
        let mut strategy: Box<dyn Strategy> = match o.strategy_kind {
            StrategyKind::Default => Box::new(DefaultStrategy::new(o.strategy.clone())),
            StrategyKind::Mcmc => Box::new(McmcStrategy::new(o.mcmc.clone())),
        };
        self.backend.set_regularization(strategy.regularization())?;
        let cameras: Vec<_> = self.data.views.iter().map(|v| v.camera).collect();
        let scene = SceneInfo {
            extent: self.data.extent,
            cameras: &cameras,
            low_pass: o.low_pass,
        };
        let (start, prepared) = prepare_start(strategy.as_mut(), start, &scene);
        self.backend.upload(&start.splats, &start.adam)?;
        let mut n_splats = start.splats.len();
        let t0 = Instant::now();
        let mut rep = TrainReport {
            backend: self.backend.name(),
            start_step: start.step,
            pruned: prepared.pruned,
            ..Default::default()
        };
        let mut recent: Vec<(f32, f32)> = Vec::new();
        let mut order = ViewOrder::default();
        let mut last_step = start.step;
        for s in start.step..o.steps {
            let view = &self.data.views[order.view(s, nv, o.seed)];
            let input = view.step_input(
                o.learning_rates(s, self.data.extent),
                LossConfig {
                    ssim_weight: o.ssim_weight,
                },
                RenderOptions {
                    background: step_background(&o, s),
                    sh_degree: o.active_sh_degree(s),
                    low_pass: o.low_pass,
                    antialiased: o.antialiased,
                },
            );
            let st = self.backend.step(&input)?;
            let done = s + 1;
            if strategy.wants_refine(done) {
                n_splats = self.refine(strategy.as_mut(), done, &scene, &mut rep)?;
            }
            if let Some(noise) =
                strategy.means_noise(done, input.lr.means, mix_seed(o.seed, done as u64, 4))
            {
                self.backend.perturb_means(&noise)?;
            }
            recent.push((st.loss, st.psnr));
            if recent.len() > 100 {
                recent.remove(0);
            }
            let el = t0.elapsed().as_secs_f64().max(1e-9);
            progress(&Progress {
                step: done,
                steps: o.steps,
                loss: st.loss,
                psnr: st.psnr,
                splats: n_splats,
                steps_per_sec: ((done - start.step) as f64 / el) as f32,
            });
            if o.checkpoint_every > 0 && done.is_multiple_of(o.checkpoint_every) && done < o.steps {
                self.write_checkpoint(done)?;
            }
            last_step = done;
            if o.time_limit_s > 0.0 && t0.elapsed().as_secs_f64() >= o.time_limit_s {
                break;
            }
        }
        let (splats, adam, _) = self.backend.download()?;
        let end = Checkpoint {
            step: last_step.max(start.step),
            splats,
            adam,
        };
        if let Some(dir) = &self.checkpoint_dir {
            write_checkpoint(dir.join("checkpoint.bin"), &end)?;
        }
        rep.seconds = t0.elapsed().as_secs_f64();
        rep.steps = end.step;
        rep.splats = end.splats.len();
        rep.steps_per_sec = (end.step - start.step) as f64 / rep.seconds.max(1e-9);
        if !recent.is_empty() {
            rep.final_loss = recent.iter().map(|r| r.0).sum::<f32>() / recent.len() as f32;
            rep.final_train_psnr = recent.iter().map(|r| r.1).sum::<f32>() / recent.len() as f32;
        }
        Ok((end, rep))
    }

    /// Refine the model after step `done` (download, strategy, upload), add
    /// what it did to `rep`; returns the new splat count.
    fn refine(
        &mut self,
        strategy: &mut dyn Strategy,
        done: u32,
        scene: &SceneInfo,
        rep: &mut TrainReport,
    ) -> Result<usize> {
        let (splats, adam, stats) = self.backend.download()?;
        let mut ms = ModelState {
            splats,
            adam,
            stats,
        };
        let r: RefineReport = strategy.refine(
            done,
            &mut ms,
            scene,
            mix_seed(self.opts.seed, done as u64, 3),
        );
        rep.cloned += r.cloned;
        rep.split += r.split;
        rep.pruned += r.pruned;
        rep.opacity_resets += r.opacity_reset as usize;
        rep.relocated += r.relocated;
        rep.added += r.added;
        self.backend.upload(&ms.splats, &ms.adam)?;
        Ok(ms.splats.len())
    }

    /// Write `checkpoint.bin` at step `done` (when there is a checkpoint folder).
    fn write_checkpoint(&mut self, done: u32) -> Result<()> {
        if let Some(dir) = &self.checkpoint_dir {
            let (splats, adam, _) = self.backend.download()?;
            write_checkpoint(
                dir.join("checkpoint.bin"),
                &Checkpoint {
                    step: done,
                    splats,
                    adam,
                },
            )?;
        }
        Ok(())
    }
}

/// The strategy's one edit before the first step, applied to `start`.
fn prepare_start(
    strategy: &mut dyn Strategy,
    start: Checkpoint,
    scene: &SceneInfo,
) -> (Checkpoint, RefineReport) {
    let mut pre = ModelState {
        stats: DensifyStats::zeros(start.splats.len()),
        splats: start.splats,
        adam: start.adam,
    };
    let prepared = strategy.prepare(&mut pre, scene);
    let start = Checkpoint {
        step: start.step,
        splats: pre.splats,
        adam: pre.adam,
    };
    (start, prepared)
}

/// The order training visits the views in: a seeded permutation per epoch.
struct ViewOrder {
    perm: Vec<usize>,
    epoch: u64,
}

impl Default for ViewOrder {
    fn default() -> Self {
        ViewOrder {
            perm: Vec::new(),
            epoch: u64::MAX,
        }
    }
}

impl ViewOrder {
    /// The view of (0-based) step `s` among `nv`.
    fn view(&mut self, s: u32, nv: usize, seed: u64) -> usize {
        let epoch = s as u64 / nv as u64;
        if epoch != self.epoch {
            self.perm = (0..nv).collect();
            self.perm
                .shuffle(&mut rand_pcg::Pcg64::seed_from_u64(mix_seed(
                    seed, epoch, 1,
                )));
            self.epoch = epoch;
        }
        self.perm[s as usize % nv]
    }
}

/// The background of (0-based) step `s`: uniformly random per step with
/// `random_background`, else the fixed one.
fn step_background(o: &TrainOptions, s: u32) -> [f32; 3] {
    if o.random_background {
        let mut r = rand_pcg::Pcg64::seed_from_u64(mix_seed(o.seed, s as u64, 2));
        [r.random::<f32>(), r.random::<f32>(), r.random::<f32>()]
    } else {
        o.background
    }
}

/// A fresh start: step 0, zero Adam moments.
pub fn fresh_start(splats: Splats) -> Checkpoint {
    let adam = AdamState::zeros_like(&splats);
    Checkpoint {
        step: 0,
        splats,
        adam,
    }
}
