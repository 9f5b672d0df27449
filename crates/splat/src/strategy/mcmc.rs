//! "3D Gaussian Splatting as Markov Chain Monte Carlo" (Kheradmand et al.,
//! NeurIPS 2024) as gsplat's `MCMCStrategy` does it: instead of cloning and
//! splitting by gradient, every `refine_every` steps between
//! `refine_start_iter` and `refine_stop_iter`
//! 1. *relocation*: dead splats (opacity ≤ `min_opacity`) are moved onto live
//!    ones sampled ∝ opacity (with replacement); a source sampled n times and
//!    its n copies all get opacity 1 − (1 − o)^(1/(n+1)) and their scales
//!    multiplied by the paper's binomial-sum ratio ([`relocation`]), so the
//!    rendering is (nearly) unchanged; Adam moments of every touched splat
//!    are reset;
//! 2. *growth*: min(cap, ⌊1.05 · N⌋) − N new splats are added the same way.
//!
//! Every step the trainer also asks for the two per-step terms that run inside
//! the backend (parameters stay on the device): the L1 regularisers on
//! opacity and scale ([`Strategy::regularization`]) and SGLD noise on the
//! means ([`Strategy::means_noise`], gsplat `inject_noise_to_position`).

use super::{ModelState, RefineReport, SceneInfo, Strategy, logit, opacities, push_splat, sigmoid};
use crate::backend::{MeansNoise, Regularization};
use crate::types::Splats;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// Largest copy count the relocation formula distinguishes (gsplat `N_MAX`
/// = 51, the size of its binomial table); larger counts are clamped.
pub const N_MAX: usize = 51;

/// Options of [`McmcStrategy`]; defaults are gsplat's `MCMCStrategy` /
/// `simple_trainer` MCMC config (which follow the paper's code).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default)]
pub struct McmcStrategyOptions {
    /// Maximum number of splats (`cap_max`, 1 000 000). Growth stops here; the
    /// count never exceeds max(initial count, cap).
    pub cap_max: usize,
    /// Scale of the SGLD position noise relative to the means learning rate
    /// (`noise_lr`, 5e5).
    pub noise_lr: f32,
    /// Refinement runs after steps strictly greater than this (500).
    pub refine_start_iter: u32,
    /// ...and strictly smaller than this (25 000).
    pub refine_stop_iter: u32,
    /// Steps between refinements (100).
    pub refine_every: u32,
    /// Splats at or below this opacity are dead and get relocated (0.005);
    /// also the lower clamp of relocated opacities and the noise gate's
    /// threshold t in σ(−k(o − t)).
    pub min_opacity: f32,
    /// Fractional growth per refinement (0.05 = 5 %, gsplat's 1.05 factor).
    pub growth_rate: f32,
    /// Weight of the opacity L1 regulariser, λ · mean σ(logit) (`opacity_reg`, 0.01).
    pub opacity_reg: f32,
    /// Weight of the scale L1 regulariser, λ · mean exp(log-scale) (`scale_reg`, 0.01).
    pub scale_reg: f32,
    /// Steepness k of the noise gate σ(−k(o − t)) (gsplat `op_sigmoid`, 100).
    pub noise_gate_k: f32,
}

impl Default for McmcStrategyOptions {
    fn default() -> Self {
        McmcStrategyOptions {
            cap_max: 1_000_000,
            noise_lr: 5e5,
            refine_start_iter: 500,
            refine_stop_iter: 25_000,
            refine_every: 100,
            min_opacity: 0.005,
            growth_rate: 0.05,
            opacity_reg: 0.01,
            scale_reg: 0.01,
            noise_gate_k: 100.0,
        }
    }
}

impl McmcStrategyOptions {
    /// Check the options.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |m: &str| Err(crate::SplatError::Invalid(format!("mcmc strategy: {m}")));
        if self.cap_max == 0 {
            return bad("cap_max must be > 0");
        }
        if self.refine_every == 0 {
            return bad("refine_every must be > 0");
        }
        if !(self.min_opacity > 0.0 && self.min_opacity < 1.0) {
            return bad("min_opacity must be in (0, 1)");
        }
        let finite_nonneg = [
            self.noise_lr,
            self.growth_rate,
            self.opacity_reg,
            self.scale_reg,
            self.noise_gate_k,
        ];
        if finite_nonneg.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return bad(
                "noise_lr, growth_rate, regularisers and noise_gate_k must be finite and >= 0",
            );
        }
        Ok(())
    }
}

/// Opacity and scale factor for each of `copies` splats replacing one splat of
/// opacity `opacity` at the same place (Kheradmand et al. 2024 eq. 9; gsplat
/// `compute_relocation`): α' = 1 − (1 − o)^(1/N) so that N copies composited
/// at the centre give back o, and the scales are multiplied by
/// o / Σ_{i=1..N} Σ_{k=0..i−1} C(i−1, k) (−1)^k α'^(k+1) / √(k+1), which
/// keeps the integral of the composited 1-D profile. `copies` is clamped to
/// 1..=[`N_MAX`] as gsplat does. Evaluated in f64 (binomials up to C(50, 25)
/// are exact there). The opacity is *not* clamped here.
pub fn relocation(opacity: f64, copies: usize) -> (f64, f64) {
    let n = copies.clamp(1, N_MAX);
    let a = 1.0 - (1.0 - opacity).powf(1.0 / n as f64);
    let mut denom = 0.0;
    for i in 1..=n {
        // C(i−1, k) by the multiplicative recurrence (exact in f64 here).
        let mut c = 1.0f64;
        for k in 0..i {
            if k > 0 {
                c = c * (i - k) as f64 / k as f64;
            }
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            denom += c * sign * a.powi(k as i32 + 1) / ((k + 1) as f64).sqrt();
        }
    }
    let ratio = if denom > 0.0 { opacity / denom } else { 1.0 };
    (a, ratio)
}

/// Draw `count` indices from `cands` with probability ∝ `weight[cand]`, with
/// replacement (torch.multinomial). Empty when the weights sum to 0.
fn sample_weighted<R: Rng>(
    cands: &[usize],
    weight: &[f32],
    count: usize,
    rng: &mut R,
) -> Vec<usize> {
    let mut cdf = Vec::with_capacity(cands.len());
    let mut total = 0.0f64;
    for &c in cands {
        let w = weight[c] as f64;
        total += if w.is_finite() && w > 0.0 { w } else { 0.0 };
        cdf.push(total);
    }
    if total <= 0.0 {
        return Vec::new();
    }
    (0..count)
        .map(|_| {
            let u = rng.random::<f64>() * total;
            let j = cdf.partition_point(|&c| c <= u).min(cands.len() - 1);
            cands[j]
        })
        .collect()
}

fn zero_moments(state: &mut ModelState, i: usize) {
    let k3 = state.splats.coeffs_per_channel() * 3;
    for m in [&mut state.adam.m, &mut state.adam.v] {
        m.means[i] = [0.0; 3];
        m.log_scales[i] = [0.0; 3];
        m.rotations[i] = [0.0; 4];
        m.opacity_logits[i] = 0.0;
        m.sh[i * k3..(i + 1) * k3].fill(0.0);
    }
}

/// Give each sampled source its corrected opacity and scale (one correction
/// per distinct source, from how often it was drawn) and reset its moments.
fn correct_sources(state: &mut ModelState, sampled: &[usize], min_opacity: f32) {
    let mut count = std::collections::BTreeMap::<usize, usize>::new();
    for &s in sampled {
        *count.entry(s).or_default() += 1;
    }
    for (&s, &n) in &count {
        let o = sigmoid(state.splats.opacity_logits[s]) as f64;
        let (a, ratio) = relocation(o, n + 1);
        // gsplat clamps the new opacity to [min_opacity, 1 − ε_f32].
        let a = (a as f32).clamp(min_opacity, 1.0 - f32::EPSILON);
        state.splats.opacity_logits[s] = logit(a);
        let lr = (ratio as f32).ln();
        for v in state.splats.log_scales[s].iter_mut() {
            *v += lr;
        }
        zero_moments(state, s);
    }
}

fn copy_splat(s: &mut Splats, from: usize, to: usize) {
    let k3 = s.coeffs_per_channel() * 3;
    s.means[to] = s.means[from];
    s.log_scales[to] = s.log_scales[from];
    s.rotations[to] = s.rotations[from];
    s.opacity_logits[to] = s.opacity_logits[from];
    s.sh.copy_within(from * k3..(from + 1) * k3, to * k3);
}

/// Move dead splats onto live ones (gsplat `relocate`). Returns how many moved.
pub fn relocate<R: Rng>(state: &mut ModelState, min_opacity: f32, rng: &mut R) -> usize {
    let op = opacities(&state.splats);
    // NaN opacities count as dead too.
    let (dead, alive): (Vec<usize>, Vec<usize>) =
        (0..op.len()).partition(|&i| op[i].is_nan() || op[i] <= min_opacity);
    if dead.is_empty() || alive.is_empty() {
        return 0;
    }
    let sampled = sample_weighted(&alive, &op, dead.len(), rng);
    if sampled.is_empty() {
        return 0;
    }
    correct_sources(state, &sampled, min_opacity);
    for (&d, &s) in dead.iter().zip(&sampled) {
        copy_splat(&mut state.splats, s, d);
        zero_moments(state, d);
    }
    dead.len()
}

/// Add min(cap, ⌊(1 + growth) · N⌋) − N splats as copies of ones sampled ∝
/// opacity (gsplat `sample_add`). Returns how many were added.
pub fn grow<R: Rng>(
    state: &mut ModelState,
    cap: usize,
    growth: f32,
    min_opacity: f32,
    rng: &mut R,
) -> usize {
    let n = state.splats.len();
    let target = (((1.0 + growth as f64) * n as f64).floor() as usize).min(cap);
    let add = target.saturating_sub(n);
    if add == 0 {
        return 0;
    }
    let op = opacities(&state.splats);
    let all: Vec<usize> = (0..n).collect();
    let sampled = sample_weighted(&all, &op, add, rng);
    if sampled.is_empty() {
        return 0;
    }
    correct_sources(state, &sampled, min_opacity);
    let src = state.splats.clone();
    for &s in &sampled {
        push_splat(
            state,
            &src,
            s,
            src.means[s],
            src.log_scales[s],
            src.opacity_logits[s],
        );
    }
    sampled.len()
}

/// The MCMC strategy.
#[derive(Debug, Clone, Default)]
pub struct McmcStrategy {
    pub opts: McmcStrategyOptions,
}

impl McmcStrategy {
    pub fn new(opts: McmcStrategyOptions) -> Self {
        McmcStrategy { opts }
    }
}

impl Strategy for McmcStrategy {
    fn name(&self) -> &'static str {
        "mcmc"
    }

    fn wants_refine(&self, step: u32) -> bool {
        let o = &self.opts;
        step > o.refine_start_iter
            && step < o.refine_stop_iter
            && step.is_multiple_of(o.refine_every)
    }

    fn refine(
        &mut self,
        _step: u32,
        state: &mut ModelState,
        _scene: &SceneInfo,
        seed: u64,
    ) -> RefineReport {
        let o = &self.opts;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let relocated = relocate(state, o.min_opacity, &mut rng);
        let added = grow(state, o.cap_max, o.growth_rate, o.min_opacity, &mut rng);
        RefineReport {
            relocated,
            added,
            ..Default::default()
        }
    }

    fn regularization(&self) -> Regularization {
        Regularization {
            opacity: self.opts.opacity_reg,
            scale: self.opts.scale_reg,
        }
    }

    fn means_noise(&self, _step: u32, lr_means: f32, seed: u64) -> Option<MeansNoise> {
        let scale = self.opts.noise_lr * lr_means;
        (scale > 0.0).then_some(MeansNoise {
            scale,
            k: self.opts.noise_gate_k,
            t: self.opts.min_opacity,
            seed: (seed ^ (seed >> 32)) as u32,
        })
    }
}

#[cfg(test)]
#[path = "mcmc_tests.rs"]
mod tests;
