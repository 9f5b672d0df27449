//! Adam (Kingma & Ba 2015) exactly as torch.optim.Adam, which INRIA 3DGS uses
//! with ε = 1e-15 and β = (0.9, 0.999): m ← β1 m + (1−β1) g,
//! v ← β2 v + (1−β2) g², p ← p − lr/(1−β1ᵗ) · m / (sqrt(v)/sqrt(1−β2ᵗ) + ε).
//! Dense: every splat's moments decay each step, visible or not (as torch).

use crate::backend::LearningRates;
use crate::types::{AdamState, SplatGrads, Splats};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Adam hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdamConfig {
    /// First-moment decay (0.9).
    pub beta1: f32,
    /// Second-moment decay (0.999).
    pub beta2: f32,
    /// Denominator stabiliser (INRIA: 1e-15).
    pub eps: f32,
}

impl Default for AdamConfig {
    fn default() -> Self {
        AdamConfig {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        }
    }
}

struct Upd {
    lr: f32,
    b1: f32,
    b2: f32,
    bc1: f32,
    sbc2: f32,
    eps: f32,
}

#[inline]
fn upd(p: &mut [f32], m: &mut [f32], v: &mut [f32], g: &[f32], u: &Upd) {
    for k in 0..p.len() {
        let gk = if g[k].is_finite() { g[k] } else { 0.0 };
        m[k] = u.b1 * m[k] + (1.0 - u.b1) * gk;
        v[k] = u.b2 * v[k] + (1.0 - u.b2) * gk * gk;
        p[k] -= u.lr / u.bc1 * m[k] / (v[k].sqrt() / u.sbc2 + u.eps);
    }
}

/// One Adam step over every parameter group. Non-finite gradients are
/// treated as 0 so one bad pixel cannot poison the model.
pub fn adam_step(
    params: &mut Splats,
    grads: &SplatGrads,
    state: &mut AdamState,
    lr: &LearningRates,
    cfg: &AdamConfig,
) {
    state.step += 1;
    let t = state.step as i32;
    let bc1 = 1.0 - cfg.beta1.powi(t);
    let sbc2 = (1.0 - cfg.beta2.powi(t)).sqrt();
    let mk = |lr: f32| Upd {
        lr,
        b1: cfg.beta1,
        b2: cfg.beta2,
        bc1,
        sbc2,
        eps: cfg.eps,
    };
    let (m, v) = (&mut state.m, &mut state.v);
    let u = mk(lr.means);
    params
        .means
        .par_iter_mut()
        .zip(&mut m.means)
        .zip(&mut v.means)
        .zip(&grads.means)
        .for_each(|(((p, m), v), g)| upd(p, m, v, g, &u));
    let u = mk(lr.scales);
    params
        .log_scales
        .par_iter_mut()
        .zip(&mut m.log_scales)
        .zip(&mut v.log_scales)
        .zip(&grads.log_scales)
        .for_each(|(((p, m), v), g)| upd(p, m, v, g, &u));
    let u = mk(lr.rotations);
    params
        .rotations
        .par_iter_mut()
        .zip(&mut m.rotations)
        .zip(&mut v.rotations)
        .zip(&grads.rotations)
        .for_each(|(((p, m), v), g)| upd(p, m, v, g, &u));
    let u = mk(lr.opacity);
    upd(
        &mut params.opacity_logits,
        &mut m.opacity_logits,
        &mut v.opacity_logits,
        &grads.opacity_logits,
        &u,
    );
    let k3 = params.coeffs_per_channel() * 3;
    let (ud, ur) = (mk(lr.sh_dc), mk(lr.sh_rest));
    params
        .sh
        .par_chunks_mut(k3)
        .zip(m.sh.par_chunks_mut(k3))
        .zip(v.sh.par_chunks_mut(k3))
        .zip(grads.sh.par_chunks(k3))
        .for_each(|(((p, m), v), g)| {
            upd(&mut p[..3], &mut m[..3], &mut v[..3], &g[..3], &ud);
            upd(&mut p[3..], &mut m[3..], &mut v[3..], &g[3..], &ur);
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_torch_formula_on_scalar() {
        // Hand-iterated torch Adam on f(p) = p² from p = 1, lr 0.1.
        let mut s = Splats {
            means: vec![[1.0, 0.0, 0.0]],
            log_scales: vec![[0.0; 3]],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]],
            opacity_logits: vec![0.0],
            sh: vec![0.0; 3],
            sh_degree: 0,
        };
        let mut st = AdamState::zeros_like(&s);
        let lr = LearningRates {
            means: 0.1,
            ..Default::default()
        };
        let (mut p, mut m, mut v) = (1.0f64, 0.0f64, 0.0f64);
        for t in 1..=5 {
            let g = SplatGrads {
                means: vec![[2.0 * s.means[0][0], 0.0, 0.0]],
                log_scales: vec![[0.0; 3]],
                rotations: vec![[0.0; 4]],
                opacity_logits: vec![0.0],
                sh: vec![0.0; 3],
                mean2d_abs: vec![],
            };
            adam_step(&mut s, &g, &mut st, &lr, &AdamConfig::default());
            let gg = 2.0 * p;
            m = 0.9 * m + 0.1 * gg;
            v = 0.999 * v + 0.001 * gg * gg;
            let bc1 = 1.0 - 0.9f64.powi(t);
            let bc2 = 1.0 - 0.999f64.powi(t);
            p -= 0.1 / bc1 * m / (v.sqrt() / bc2.sqrt() + 1e-15);
            assert!(
                (s.means[0][0] as f64 - p).abs() < 1e-5,
                "step {t}: {} vs {p}",
                s.means[0][0]
            );
        }
    }
}
