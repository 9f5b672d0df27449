//! Training options with INRIA 3DGS defaults (Kerbl et al. 2023,
//! `arguments/__init__.py` `OptimizationParams`), each documented.

use crate::backend::{LearningRates, LossConfig};
use crate::strategy::{DefaultStrategyOptions, McmcStrategyOptions, StrategyKind};
use serde::{Deserialize, Serialize};

/// How to initialise the splats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum InitMode {
    /// COLMAP points3D when the scene has them, else random.
    Auto,
    /// COLMAP points3D (error when missing).
    Points,
    /// Random inside the cameras' bounds.
    Random,
}

/// Every knob of a training run. With the `cli` feature it derives
/// `clap::Args`: the algorithm options a user tunes are flags with these
/// defaults; the run's length, masks and time limit (`steps`, `use_masks`,
/// `time_limit_s`) are set by each command (`train --steps --no-masks
/// --max-minutes`, `run`'s plan, `onthego --steps`), and the learning rates,
/// background, low-pass, MCMC and init details keep their defaults.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct TrainOptions {
    /// Optimisation steps (INRIA: 30 000).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().steps))]
    pub steps: u32,
    /// Initial learning rate of the means, × scene extent (INRIA 1.6e-4).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().lr_means_init))]
    pub lr_means_init: f32,
    /// Final learning rate of the means, × scene extent (1.6e-6); the rate
    /// decays log-linearly from init to final over `steps` (INRIA over
    /// `position_lr_max_steps` = 30 000, its default run length).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().lr_means_final))]
    pub lr_means_final: f32,
    /// SH DC learning rate (`feature_lr`, 2.5e-3).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().lr_sh_dc))]
    pub lr_sh_dc: f32,
    /// Higher SH learning rate (`feature_lr / 20`, 1.25e-4).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().lr_sh_rest))]
    pub lr_sh_rest: f32,
    /// Opacity-logit learning rate (0.05).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().lr_opacity))]
    pub lr_opacity: f32,
    /// Log-scale learning rate (5e-3).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().lr_scales))]
    pub lr_scales: f32,
    /// Quaternion learning rate (1e-3).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().lr_rotations))]
    pub lr_rotations: f32,
    /// Highest SH degree (3).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = TrainOptions::default().sh_degree))]
    pub sh_degree: u32,
    /// Steps between SH degree increments (1000).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = TrainOptions::default().sh_degree_every))]
    pub sh_degree_every: u32,
    /// D-SSIM weight λ (0.2; 0 disables SSIM as SLS does).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = TrainOptions::default().ssim_weight))]
    pub ssim_weight: f32,
    /// Background colour behind the splats (black).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().background))]
    pub background: [f32; 3],
    /// Draw a uniformly random background each step instead (INRIA
    /// `--random_background`; off).
    #[cfg_attr(feature = "cli", arg(long))]
    pub random_background: bool,
    /// Mip-Splatting/gsplat antialiased rendering (off).
    #[cfg_attr(feature = "cli", arg(long))]
    pub antialiased: bool,
    /// Screen-space dilation (px², 0.3).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().low_pass))]
    pub low_pass: f32,
    /// Densification (INRIA adaptive density control).
    #[cfg_attr(feature = "cli", command(flatten))]
    pub strategy: DefaultStrategyOptions,
    /// Which densification strategy runs: `default` (INRIA, the options in
    /// `strategy`) or `mcmc` (3DGS-MCMC, the options in `mcmc`). Default: `default`.
    #[serde(default)]
    #[cfg_attr(feature = "cli", arg(long = "strategy", value_name = "STRATEGY", value_enum, default_value_t = TrainOptions::default().strategy_kind))]
    pub strategy_kind: StrategyKind,
    /// 3DGS-MCMC options (Kheradmand et al. 2024; gsplat defaults), used when
    /// `strategy_kind` is `mcmc`.
    #[serde(default)]
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().mcmc))]
    pub mcmc: McmcStrategyOptions,
    /// Initialisation source.
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = TrainOptions::default().init))]
    pub init: InitMode,
    /// Splats drawn for random initialisation (INRIA synthetic: 100 000).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().random_init_count))]
    pub random_init_count: usize,
    /// Skip COLMAP points with more than this fraction of their
    /// observations on moving (masked) pixels (0.5).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().init_max_moving_fraction))]
    pub init_max_moving_fraction: f32,
    /// Use `masks/` in the loss (true; `--no-masks` sets false).
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().use_masks))]
    pub use_masks: bool,
    /// Write a checkpoint every N steps (0 = only at the end).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = TrainOptions::default().checkpoint_every))]
    pub checkpoint_every: u32,
    /// Wall-clock budget in seconds (0 = none): training stops after the
    /// first step that ends past it, and the report gives the steps done.
    /// The learning-rate schedule stays that of a `steps`-long run.
    #[serde(default)]
    #[cfg_attr(feature = "cli", arg(skip = TrainOptions::default().time_limit_s))]
    pub time_limit_s: f64,
    /// Random seed (view order, split sampling, random init and background).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = TrainOptions::default().seed))]
    pub seed: u64,
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            steps: 30_000,
            lr_means_init: 1.6e-4,
            lr_means_final: 1.6e-6,
            lr_sh_dc: 2.5e-3,
            lr_sh_rest: 2.5e-3 / 20.0,
            lr_opacity: 0.05,
            lr_scales: 5e-3,
            lr_rotations: 1e-3,
            sh_degree: 3,
            sh_degree_every: 1000,
            ssim_weight: LossConfig::default().ssim_weight,
            background: [0.0; 3],
            random_background: false,
            antialiased: false,
            low_pass: 0.3,
            strategy: DefaultStrategyOptions::default(),
            strategy_kind: StrategyKind::Default,
            mcmc: McmcStrategyOptions::default(),
            init: InitMode::Auto,
            random_init_count: 100_000,
            init_max_moving_fraction: 0.5,
            use_masks: true,
            checkpoint_every: 0,
            time_limit_s: 0.0,
            seed: 42,
        }
    }
}

impl TrainOptions {
    /// Check the options.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |m: String| Err(crate::SplatError::Invalid(format!("train options: {m}")));
        let lrs = [
            self.lr_means_init,
            self.lr_means_final,
            self.lr_sh_dc,
            self.lr_sh_rest,
            self.lr_opacity,
            self.lr_scales,
            self.lr_rotations,
        ];
        if lrs.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return bad(format!("learning rates must be finite and >= 0: {lrs:?}"));
        }
        if self.lr_means_init > 0.0 && self.lr_means_final <= 0.0 {
            return bad("lr_means_final must be > 0 for the log-linear decay".into());
        }
        if self.sh_degree > crate::types::MAX_SH_DEGREE {
            return bad(format!("sh_degree {} > 3", self.sh_degree));
        }
        if !(self.time_limit_s.is_finite() && self.time_limit_s >= 0.0) {
            return bad(format!("time_limit_s {} must be >= 0", self.time_limit_s));
        }
        if self.sh_degree_every == 0 {
            return bad("sh_degree_every must be > 0".into());
        }
        if !(0.0..=1.0).contains(&self.ssim_weight) {
            return bad(format!("ssim_weight {} not in [0, 1]", self.ssim_weight));
        }
        if !(self.low_pass.is_finite() && self.low_pass >= 0.0) {
            return bad("low_pass must be >= 0".into());
        }
        if !(0.0..=1.0).contains(&self.init_max_moving_fraction) {
            return bad("init_max_moving_fraction not in [0, 1]".into());
        }
        if self.strategy_kind == StrategyKind::Mcmc {
            self.mcmc.validate()?;
        }
        self.strategy.validate()
    }

    /// Learning rates at (0-based) step `step` for a scene of `extent`.
    pub fn learning_rates(&self, step: u32, extent: f32) -> LearningRates {
        let t = if self.steps <= 1 {
            0.0
        } else {
            (step as f64 / self.steps as f64).clamp(0.0, 1.0)
        };
        let means = if self.lr_means_init > 0.0 {
            let (a, b) = (self.lr_means_init as f64, self.lr_means_final as f64);
            (a.ln() * (1.0 - t) + b.ln() * t).exp() as f32
        } else {
            0.0
        };
        LearningRates {
            means: means * extent,
            sh_dc: self.lr_sh_dc,
            sh_rest: self.lr_sh_rest,
            opacity: self.lr_opacity,
            scales: self.lr_scales,
            rotations: self.lr_rotations,
        }
    }

    /// Cap the MCMC strategy's splat count at `strategy.max_splats` too, as
    /// the command line's `--max-splats` does for both strategies.
    pub fn cap_mcmc_at_max_splats(&mut self) {
        self.mcmc.cap_max = self.mcmc.cap_max.min(self.strategy.max_splats);
    }

    /// Active SH degree at (0-based) step `step`: +1 every `sh_degree_every`.
    pub fn active_sh_degree(&self, step: u32) -> u32 {
        (step / self.sh_degree_every).min(self.sh_degree)
    }
}
