//! CPU reference of the two per-step terms of 3DGS-MCMC (Kheradmand et al.
//! 2024; gsplat `inject_noise_to_position` and the `opacity_reg`/`scale_reg`
//! losses of `simple_trainer.py`), mirrored operation for operation by
//! `shaders/splat/mcmc_noise.wgsl` and `mcmc_reg.wgsl`:
//! - SGLD noise `μ += scale · σ(−k(σ(logit) − t)) · Σ ε`, Σ = R S² Rᵀ, with ε
//!   drawn from a counter-based hash (PCG hash, Jarzynski & Olano 2020) of
//!   (seed, splat, component) and Box–Muller, so GPU and CPU draw the same
//!   numbers without any upload;
//! - the regularisers' gradients added before Adam.

use crate::backend::{MeansNoise, Regularization};
use crate::types::{SplatGrads, Splats};

/// PCG-RXS-M-XS hash of one u32 (identical in `mcmc_noise.wgsl`).
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// The four hashes behind splat `i`'s three normals under `seed`.
pub fn noise_bits(seed: u32, i: u32) -> [u32; 4] {
    let base = pcg_hash(i ^ pcg_hash(seed));
    std::array::from_fn(|c| pcg_hash(base.wrapping_add(c as u32)))
}

/// Uniform in (0, 1] from the top 24 bits.
fn unit(h: u32) -> f32 {
    ((h >> 8) + 1) as f32 * (1.0 / 16_777_216.0)
}

/// Three standard normals for splat `i` (Box–Muller on two uniform pairs).
pub fn noise_normals(seed: u32, i: u32) -> [f32; 3] {
    let h = noise_bits(seed, i);
    let r0 = (-2.0 * unit(h[0]).ln()).sqrt();
    let t0 = std::f32::consts::TAU * unit(h[1]);
    let r1 = (-2.0 * unit(h[2]).ln()).sqrt();
    let t1 = std::f32::consts::TAU * unit(h[3]);
    [r0 * t0.cos(), r0 * t0.sin(), r1 * t1.cos()]
}

/// The opacity gate σ(−k(o − t)) with the exponent clamped to 80 (beyond it
/// the gate is < 2e−35 anyway) so no backend meets an infinite exp.
pub fn noise_gate(opacity: f32, k: f32, t: f32) -> f32 {
    1.0 / (1.0 + (k * (opacity - t)).min(80.0).exp())
}

/// Σ ε for a splat: R (s² ⊙ (Rᵀ ε)), R from the normalised quaternion.
pub fn covariance_times(q: [f32; 4], log_scale: [f32; 3], e: [f32; 3]) -> [f32; 3] {
    let r = crate::strategy::rotation(q);
    let mut local = [0.0f32; 3];
    for (c, l) in local.iter_mut().enumerate() {
        let s = (2.0 * log_scale[c]).exp();
        *l = s * (r[0][c] * e[0] + r[1][c] * e[1] + r[2][c] * e[2]);
    }
    std::array::from_fn(|a| r[a][0] * local[0] + r[a][1] * local[1] + r[a][2] * local[2])
}

/// The noise step of one splat's mean; a non-finite result leaves it unchanged.
pub fn noisy_mean(s: &Splats, i: usize, noise: &MeansNoise) -> [f32; 3] {
    let o = 1.0 / (1.0 + (-s.opacity_logits[i]).exp());
    let g = noise.scale * noise_gate(o, noise.k, noise.t);
    let e = noise_normals(noise.seed, i as u32);
    let d = covariance_times(s.rotations[i], s.log_scales[i], e);
    let m = s.means[i];
    let out = [m[0] + g * d[0], m[1] + g * d[1], m[2] + g * d[2]];
    if out.iter().all(|v| v.is_finite()) {
        out
    } else {
        m
    }
}

/// Apply the position noise to every mean.
pub fn perturb_means(s: &mut Splats, noise: &MeansNoise) {
    let means: Vec<[f32; 3]> = (0..s.len()).map(|i| noisy_mean(s, i, noise)).collect();
    s.means = means;
}

/// Per-element weights of the regulariser gradients, (opacity / N,
/// scale / (3N)), computed once in f32 (the GPU receives these values).
pub fn regularization_weights(reg: &Regularization, n: usize) -> (f32, f32) {
    if n == 0 {
        return (0.0, 0.0);
    }
    (reg.opacity / n as f32, reg.scale / (3 * n) as f32)
}

/// Add the regularisers' gradients to `g`.
pub fn add_regularization_grads(s: &Splats, g: &mut SplatGrads, reg: &Regularization) {
    let (wo, ws) = regularization_weights(reg, s.len());
    for (gl, &l) in g.opacity_logits.iter_mut().zip(&s.opacity_logits) {
        let o = 1.0 / (1.0 + (-l).exp());
        *gl += wo * o * (1.0 - o);
    }
    for (gs, ls) in g.log_scales.iter_mut().zip(&s.log_scales) {
        for (gc, lc) in gs.iter_mut().zip(ls) {
            *gc += ws * lc.exp();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pcg_hash_known_values_and_normals_are_standard() {
        // Reference values of the PCG hash, computed independently (Python,
        // arbitrary-precision ints masked to 32 bits).
        assert_eq!(pcg_hash(0), 129_708_002);
        assert_eq!(pcg_hash(1), 2_831_084_092);
        assert_eq!(pcg_hash(12_345), 4_099_845_390);
        let n = 20_000u32;
        let (mut sum, mut sq) = ([0.0f64; 3], [0.0f64; 3]);
        for i in 0..n {
            let z = noise_normals(7, i);
            for c in 0..3 {
                sum[c] += z[c] as f64;
                sq[c] += (z[c] as f64).powi(2);
            }
        }
        for c in 0..3 {
            let mean = sum[c] / n as f64;
            let var = sq[c] / n as f64 - mean * mean;
            assert!(mean.abs() < 0.03, "component {c}: mean {mean}");
            assert!((var - 1.0).abs() < 0.05, "component {c}: var {var}");
        }
        assert_ne!(noise_normals(7, 3), noise_normals(8, 3));
    }

    #[test]
    fn covariance_product_matches_explicit_matrix() {
        let q = [0.8f32, 0.3, -0.2, 0.5];
        let ls = [-1.0f32, -0.5, 0.2];
        let r = crate::strategy::rotation(q);
        let s2 = ls.map(|v| (2.0 * v).exp());
        let e = [0.3f32, -1.2, 0.7];
        let got = covariance_times(q, ls, e);
        for a in 0..3 {
            let mut want = 0.0f32;
            for b in 0..3 {
                let sig: f32 = (0..3).map(|c| r[a][c] * s2[c] * r[b][c]).sum();
                want += sig * e[b];
            }
            assert!((got[a] - want).abs() < 1e-5, "{a}: {} vs {want}", got[a]);
        }
    }

    #[test]
    fn gate_and_regularisers_known_answers() {
        assert!((noise_gate(0.005, 100.0, 0.005) - 0.5).abs() < 1e-7);
        assert!(noise_gate(1.0, 100.0, 0.005) < 1e-30);
        assert!((noise_gate(0.0, 100.0, 0.005) - 1.0 / (1.0 + (-0.5f32).exp())).abs() < 1e-6);
        let s = Splats {
            means: vec![[0.0; 3]; 2],
            log_scales: vec![[0.0, 1.0, -1.0], [0.5; 3]],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; 2],
            opacity_logits: vec![0.0, 2.0],
            sh: vec![0.0; 6],
            sh_degree: 0,
        };
        let mut g = SplatGrads {
            means: vec![[0.0; 3]; 2],
            log_scales: vec![[1.0; 3]; 2],
            rotations: vec![[0.0; 4]; 2],
            opacity_logits: vec![1.0; 2],
            sh: vec![0.0; 6],
            mean2d_abs: Vec::new(),
        };
        let reg = Regularization {
            opacity: 0.01,
            scale: 0.03,
        };
        add_regularization_grads(&s, &mut g, &reg);
        // d/dx [0.01 · mean σ] at x = 0: 0.01/2 · 0.25.
        assert!((g.opacity_logits[0] - (1.0 + 0.00125)).abs() < 1e-7);
        // d/ds [0.03 · mean exp] = 0.03/6 · e^s.
        assert!((g.log_scales[0][1] - (1.0 + 0.005 * 1f32.exp())).abs() < 1e-6);
    }
}
