//! Densification strategies as separate objects with hooks (gsplat's
//! `Strategy` habit): the trainer asks after every step whether the strategy
//! wants to edit the model; if so it downloads parameters, Adam moments and
//! the accumulated statistics from the backend, calls `refine`, and uploads
//! the result (which resets the statistics). Backends fuse forward, backward
//! and Adam in one `step`, so the hook sits after the optimiser step (where
//! INRIA densifies too).

pub mod default;
pub mod mcmc;

pub use default::{DefaultStrategy, DefaultStrategyOptions};
pub use mcmc::{McmcStrategy, McmcStrategyOptions};

use crate::backend::{MeansNoise, Regularization};
use crate::reference::project::{CamT, project_one};
use crate::types::{AdamState, DensifyStats, RenderCamera, RenderOptions, Splats};
use serde::{Deserialize, Serialize};

/// The model as the strategy sees it.
#[derive(Debug, Clone, Default)]
pub struct ModelState {
    pub splats: Splats,
    pub adam: AdamState,
    pub stats: DensifyStats,
}

/// What a refinement did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RefineReport {
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
    pub relocated: usize,
    pub added: usize,
    pub opacity_reset: bool,
}

/// Scene facts a strategy needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneInfo<'a> {
    /// INRIA `cameras_extent`: 1.1 × the largest distance of a camera centre
    /// from their mean (world units).
    pub extent: f32,
    /// The training cameras (empty: unknown, nothing is pruned as unseen).
    pub cameras: &'a [RenderCamera],
    /// Screen-space low-pass dilation the renders use (px², culling depends on it).
    pub low_pass: f32,
}

impl SceneInfo<'_> {
    /// A scene known only by its extent (no cameras).
    pub fn extent_only(extent: f32) -> SceneInfo<'static> {
        SceneInfo {
            extent,
            cameras: &[],
            low_pass: RenderOptions::default().low_pass,
        }
    }
}

/// Splats among `candidates` that the projection culls in every one of
/// `scene.cameras` (behind / beyond the clip planes, outside the image by
/// their 3σ radius, or degenerate): they get no gradient from any training
/// view, so they never change, yet every per-splat kernel pays for them.
/// Empty when the scene has no cameras.
pub fn unseen(splats: &Splats, candidates: &[usize], scene: &SceneInfo) -> Vec<usize> {
    use rayon::prelude::*;
    if scene.cameras.is_empty() {
        return Vec::new();
    }
    let opts = RenderOptions {
        low_pass: scene.low_pass,
        ..RenderOptions::default()
    };
    let cams: Vec<CamT<f32>> = scene.cameras.iter().map(CamT::new).collect();
    candidates
        .par_iter()
        .copied()
        .filter(|&i| {
            cams.iter()
                .all(|c| project_one(splats, i, c, &opts).is_none())
        })
        .collect()
}

/// A densification strategy.
pub trait Strategy: Send {
    /// Short name for logs.
    fn name(&self) -> &'static str;
    /// Whether `refine` must run after step `step` (1-based count of steps done).
    fn wants_refine(&self, step: u32) -> bool;
    /// Edit the model. `seed` is a per-step seed for any randomness.
    fn refine(
        &mut self,
        step: u32,
        state: &mut ModelState,
        scene: &SceneInfo,
        seed: u64,
    ) -> RefineReport;
    /// Edit the model once before a run's first step (nothing by default).
    fn prepare(&mut self, state: &mut ModelState, scene: &SceneInfo) -> RefineReport {
        let _ = (state, scene);
        RefineReport::default()
    }
    /// Regularisers the backend adds to every step's gradients (none by default).
    fn regularization(&self) -> Regularization {
        Regularization::default()
    }
    /// Position noise to apply after step `step` (1-based count of steps
    /// done, after any refinement) given that step's means learning rate;
    /// `seed` is a per-step seed. None by default.
    fn means_noise(&self, step: u32, lr_means: f32, seed: u64) -> Option<MeansNoise> {
        let _ = (step, lr_means, seed);
        None
    }
}

/// Which densification strategy a run uses.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum StrategyKind {
    /// INRIA adaptive density control: clone, split, prune, opacity reset (`DefaultStrategy`).
    #[default]
    Default,
    /// 3DGS-MCMC (Kheradmand et al. 2024): relocate dead splats, grow 5 % per
    /// refinement up to the cap (`McmcStrategy`).
    Mcmc,
}

/// Keep the splats at `keep` (sorted ascending) in params and both Adam moments.
pub fn retain(state: &mut ModelState, keep: &[usize]) {
    fn sel(s: &Splats, keep: &[usize]) -> Splats {
        let k3 = s.coeffs_per_channel() * 3;
        Splats {
            means: keep.iter().map(|&i| s.means[i]).collect(),
            log_scales: keep.iter().map(|&i| s.log_scales[i]).collect(),
            rotations: keep.iter().map(|&i| s.rotations[i]).collect(),
            opacity_logits: keep.iter().map(|&i| s.opacity_logits[i]).collect(),
            sh: keep
                .iter()
                .flat_map(|&i| s.sh[i * k3..(i + 1) * k3].iter().copied())
                .collect(),
            sh_degree: s.sh_degree,
        }
    }
    state.splats = sel(&state.splats, keep);
    state.adam.m = sel(&state.adam.m, keep);
    state.adam.v = sel(&state.adam.v, keep);
    let st = &state.stats;
    state.stats = DensifyStats {
        grad_accum: keep
            .iter()
            .map(|&i| st.grad_accum.get(i).copied().unwrap_or(0.0))
            .collect(),
        count: keep
            .iter()
            .map(|&i| st.count.get(i).copied().unwrap_or(0))
            .collect(),
        max_radius: keep
            .iter()
            .map(|&i| st.max_radius.get(i).copied().unwrap_or(0.0))
            .collect(),
    };
}

/// Append one splat (copied parameters, zero Adam moments and statistics).
pub fn push_splat(
    state: &mut ModelState,
    src: &Splats,
    i: usize,
    mean: [f32; 3],
    log_scale: [f32; 3],
    logit: f32,
) {
    let k3 = src.coeffs_per_channel() * 3;
    let s = &mut state.splats;
    s.means.push(mean);
    s.log_scales.push(log_scale);
    s.rotations.push(src.rotations[i]);
    s.opacity_logits.push(logit);
    s.sh.extend_from_slice(&src.sh[i * k3..(i + 1) * k3]);
    for m in [&mut state.adam.m, &mut state.adam.v] {
        m.means.push([0.0; 3]);
        m.log_scales.push([0.0; 3]);
        m.rotations.push([0.0; 4]);
        m.opacity_logits.push(0.0);
        m.sh.extend(std::iter::repeat_n(0.0, k3));
    }
    state.stats.grad_accum.push(0.0);
    state.stats.count.push(0);
    state.stats.max_radius.push(0.0);
}

/// log(p / (1 − p)).
pub fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// 1 / (1 + e^−x).
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Every splat's opacity (the sigmoid of its logit).
pub fn opacities(splats: &Splats) -> Vec<f32> {
    splats.opacity_logits.iter().map(|&l| sigmoid(l)).collect()
}

/// Rotation matrix of a (not necessarily unit) quaternion (w, x, y, z).
pub fn rotation(q: [f32; 4]) -> [[f32; 3]; 3] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        .sqrt()
        .max(1e-12);
    crate::reference::project::quat_to_rot(q.map(|v| v / n))
}
