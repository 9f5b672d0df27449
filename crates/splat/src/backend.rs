//! The training backend interface. Two implementations: the CPU reference
//! ([`crate::reference::backend::CpuBackend`]) and the wgpu one in
//! `gpu/`. The trainer (`train/`) owns the schedule, densification and I/O
//! and talks to a backend only through this trait, so both train alike and a
//! test can run the same steps on both.
//!
//! A backend holds the parameters, their Adam moments and the densification
//! statistics between calls; `step` does forward + masked loss + backward +
//! Adam + statistics accumulation; `download` reads everything back (for
//! densification, logging, checkpoints and export), `upload` replaces it.

use crate::error::Result;
use crate::types::{AdamState, DensifyStats, RenderCamera, RenderOptions, RenderOutput, Splats};
use serde::{Deserialize, Serialize};

/// Learning rates for one step, per parameter group, already scheduled
/// (the means rate includes the exponential decay and × scene extent).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LearningRates {
    pub means: f32,
    /// SH coefficient 0 (DC) of each channel.
    pub sh_dc: f32,
    /// SH coefficients 1.. of each channel.
    pub sh_rest: f32,
    pub opacity: f32,
    pub scales: f32,
    pub rotations: f32,
}

/// Loss configuration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LossConfig {
    /// Weight λ of D-SSIM in (1−λ)·L1 + λ·(1−SSIM). INRIA: 0.2; 0 disables
    /// SSIM (as SLS does).
    pub ssim_weight: f32,
}

impl Default for LossConfig {
    fn default() -> Self {
        LossConfig { ssim_weight: 0.2 }
    }
}

/// One training step's input.
#[derive(Debug, Clone, Copy)]
pub struct StepInput<'a> {
    pub camera: &'a RenderCamera,
    /// Target RGB, row-major, `width*height*3`, in [0, 1].
    pub target: &'a [f32],
    /// Per-pixel loss weights (`width*height`): 1 keep, 0 moving (ignored).
    /// `None` keeps every pixel.
    pub mask: Option<&'a [f32]>,
    /// Stable id of this training view, so a backend may cache the target
    /// and mask on the device; `None` disables caching.
    pub view_id: Option<usize>,
    pub lr: LearningRates,
    pub loss: LossConfig,
    /// Background, active SH degree, low-pass, antialiasing for this step.
    pub render: RenderOptions,
}

/// What one step reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StepStats {
    /// Total loss.
    pub loss: f32,
    /// Masked L1.
    pub l1: f32,
    /// Masked SSIM (1 when not computed).
    pub ssim: f32,
    /// PSNR (dB) over kept pixels of the rendered training view.
    pub psnr: f32,
    /// Splats with radius > 0 in this view.
    pub visible: u32,
}

/// L1 regularisers of the MCMC strategy (Kheradmand et al. 2024; gsplat
/// `opacity_reg`, `scale_reg`): the loss gains
/// `opacity · mean_i σ(logit_i) + scale · mean_{i,c} exp(log_scale_ic)`.
/// Backends add the gradients (`opacity/N · σ(1−σ)` per logit,
/// `scale/(3N) · exp(s)` per log-scale) to the image-loss gradients before
/// Adam in every `step`; the reported loss stays the image loss.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Regularization {
    pub opacity: f32,
    pub scale: f32,
}

/// SGLD noise on the means of the MCMC strategy (gsplat
/// `inject_noise_to_position`): `μ += scale · σ(−k(σ(logit) − t)) · Σ ε`
/// with Σ = R S² Rᵀ the splat's covariance and ε ~ N(0, I) drawn from a
/// counter-based hash of (seed, splat, component) identical on every backend
/// (`reference::mcmc`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MeansNoise {
    /// noise_lr × the current means learning rate.
    pub scale: f32,
    /// Gate steepness k (100).
    pub k: f32,
    /// Gate threshold t (0.005).
    pub t: f32,
    pub seed: u32,
}

/// A training backend (CPU reference or wgpu).
pub trait TrainBackend {
    /// Human-readable name, e.g. `cpu` or `wgpu (llvmpipe, Vulkan)`.
    fn name(&self) -> String;
    /// Replace parameters and optimiser state; densification statistics are
    /// reset to zero for every splat.
    fn upload(&mut self, params: &Splats, adam: &AdamState) -> Result<()>;
    /// Forward + masked loss + backward + Adam + statistics accumulation.
    fn step(&mut self, input: &StepInput<'_>) -> Result<StepStats>;
    /// Read back parameters, optimiser state and accumulated statistics.
    fn download(&mut self) -> Result<(Splats, AdamState, DensifyStats)>;
    /// Set the regularisers added in every later `step` (zero, the initial
    /// setting, disables them). Backends without support refuse non-zero ones.
    fn set_regularization(&mut self, reg: Regularization) -> Result<()> {
        if reg == Regularization::default() {
            return Ok(());
        }
        Err(crate::SplatError::Invalid(format!(
            "backend {} has no MCMC regularisers",
            self.name()
        )))
    }
    /// Add SGLD noise to the means of the training state in place (MCMC).
    fn perturb_means(&mut self, noise: &MeansNoise) -> Result<()> {
        let _ = noise;
        Err(crate::SplatError::Invalid(format!(
            "backend {} has no MCMC position noise",
            self.name()
        )))
    }
    /// Render arbitrary splats (not the training state) from a camera.
    fn render(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
    ) -> Result<RenderOutput>;
}

/// Check a step input's buffer sizes.
pub fn check_step_input(input: &StepInput<'_>) -> Result<()> {
    crate::error::check_camera(input.camera)?;
    let n = (input.camera.width * input.camera.height) as usize;
    if input.target.len() != n * 3 {
        return Err(crate::SplatError::Invalid(format!(
            "target has {} values, camera needs {}",
            input.target.len(),
            n * 3
        )));
    }
    if let Some(m) = input.mask
        && m.len() != n
    {
        return Err(crate::SplatError::Invalid(format!(
            "mask has {} values, camera needs {n}",
            m.len()
        )));
    }
    Ok(())
}
