//! The masked photometric loss of romosplat training and its gradient w.r.t.
//! the rendered image: L = (1 − λ)·L1 + λ·(1 − SSIM) (Kerbl et al. 2023 eq. 7,
//! λ = 0.2), where both terms average only over the pixels the mask keeps
//! (RoMo masks: moving pixels contribute nothing; normalised by the kept
//! weight Σ m_p, not by the image size). SSIM uses INRIA's 11×11 Gaussian
//! window (σ = 1.5) with zero padding, whose filter is self-adjoint, so the
//! backward pass is three more filters.

use crate::metrics::{
    Border, SSIM_C1, SSIM_C2, SSIM_RADIUS, SSIM_SIGMA, gaussian_filter, gaussian_kernel, ssim_stats,
};
use rayon::prelude::*;

/// Loss value breakdown.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LossValue {
    /// Total loss.
    pub loss: f64,
    /// Masked mean absolute error.
    pub l1: f64,
    /// Masked mean SSIM (1 when the D-SSIM weight is 0 and it was skipped).
    pub ssim: f64,
    /// Masked mean squared error (for PSNR).
    pub mse: f64,
    /// Σ of mask weights (pixels kept).
    pub kept: f64,
}

/// Loss and dL/d image (`w×h×3`). `mask` holds per-pixel weights in [0, 1]
/// (`w×h`); `None` keeps everything. When nothing is kept the loss and the
/// gradient are zero.
pub fn loss_and_grad(
    image: &[f32],
    target: &[f32],
    mask: Option<&[f32]>,
    (w, h): (usize, usize),
    ssim_weight: f64,
) -> (LossValue, Vec<f32>) {
    let n = w * h;
    let m = |i: usize| mask.map_or(1.0, |m| m[i] as f64);
    let kept: f64 = (0..n).map(m).sum();
    let mut grad = vec![0.0f32; n * 3];
    if kept <= 0.0 {
        return (LossValue::default(), grad);
    }
    let norm = 1.0 / (3.0 * kept);
    let (mut l1, mut se) = (0.0, 0.0);
    let wl1 = 1.0 - ssim_weight;
    for i in 0..n {
        let mi = m(i);
        if mi == 0.0 {
            continue;
        }
        for c in 0..3 {
            let d = image[i * 3 + c] as f64 - target[i * 3 + c] as f64;
            l1 += mi * d.abs();
            se += mi * d * d;
            let s = if d > 0.0 {
                1.0
            } else if d < 0.0 {
                -1.0
            } else {
                0.0
            };
            grad[i * 3 + c] = (wl1 * mi * s * norm) as f32;
        }
    }
    l1 *= norm;
    let mse = se * norm;
    let mut ssim_mean = 1.0;
    if ssim_weight > 0.0 {
        let k = gaussian_kernel(SSIM_SIGMA, SSIM_RADIUS);
        let per_ch: Vec<(f64, Vec<f64>)> = (0..3)
            .into_par_iter()
            .map(|c| {
                let x: Vec<f64> = image.iter().skip(c).step_by(3).map(|&v| v as f64).collect();
                let y: Vec<f64> = target
                    .iter()
                    .skip(c)
                    .step_by(3)
                    .map(|&v| v as f64)
                    .collect();
                ssim_channel_grad(&x, &y, (w, h), &k, &|i| m(i) * norm)
            })
            .collect();
        ssim_mean = 0.0;
        for (c, (s, g)) in per_ch.iter().enumerate() {
            ssim_mean += s;
            for i in 0..n {
                // L ∋ λ(1 − SSIM): dL/dx = −λ dSSIM/dx.
                grad[i * 3 + c] += (-ssim_weight * g[i]) as f32;
            }
        }
    }
    let loss = wl1 * l1 + ssim_weight * (1.0 - ssim_mean);
    (
        LossValue {
            loss,
            l1,
            ssim: ssim_mean,
            mse,
            kept,
        },
        grad,
    )
}

/// Σ_p g(p)·S(p) for one channel and its gradient w.r.t. x, where g is the
/// per-pixel weight (mask / (3·kept)).
fn ssim_channel_grad(
    x: &[f64],
    y: &[f64],
    (w, h): (usize, usize),
    k: &[f64],
    g: &(dyn Fn(usize) -> f64 + Sync),
) -> (f64, Vec<f64>) {
    let st = ssim_stats(x, y, w, h, Border::Zero);
    let n = w * h;
    let mut total = 0.0;
    let (mut d_mx, mut d_exx, mut d_exy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for i in 0..n {
        let gi = g(i);
        if gi == 0.0 {
            continue;
        }
        let (mx, my) = (st.mx[i], st.my[i]);
        let a1 = 2.0 * mx * my + SSIM_C1;
        let a2 = 2.0 * (st.exy[i] - mx * my) + SSIM_C2;
        let b1 = mx * mx + my * my + SSIM_C1;
        let b2 = (st.exx[i] - mx * mx) + (st.eyy[i] - my * my) + SSIM_C2;
        let s = a1 * a2 / (b1 * b2);
        total += gi * s;
        let ds_dexx = -s / b2;
        let ds_dexy = 2.0 * a1 / (b1 * b2);
        let ds_dmx =
            2.0 * my * a2 / (b1 * b2) - 2.0 * mx * s / b1 - 2.0 * mx * ds_dexx - my * ds_dexy;
        d_mx[i] = gi * ds_dmx;
        d_exx[i] = gi * ds_dexx;
        d_exy[i] = gi * ds_dexy;
    }
    let f_mx = gaussian_filter(&d_mx, w, h, k, Border::Zero);
    let f_exx = gaussian_filter(&d_exx, w, h, k, Border::Zero);
    let f_exy = gaussian_filter(&d_exy, w, h, k, Border::Zero);
    let grad = (0..n)
        .map(|q| f_mx[q] + 2.0 * x[q] * f_exx[q] + y[q] * f_exy[q])
        .collect();
    (total, grad)
}

/// A smooth `w×h` RGB test image (a sinusoid, shifted by `phase`) with a
/// deterministic `noise` texture of that amplitude.
#[cfg(test)]
pub(crate) fn test_image(w: usize, h: usize, phase: f64, noise: f64) -> Vec<f32> {
    let mut v = vec![];
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                v.push(
                    (0.5 + 0.4 * (0.37 * x as f64 + 0.23 * y as f64 + c as f64 + phase).sin()
                        + noise * ((x * 7 + y * 13 + c * 5) % 11) as f64 / 11.0)
                        as f32,
                );
            }
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(w: usize, h: usize, phase: f64) -> Vec<f32> {
        test_image(w, h, phase, 0.0)
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let (w, h) = (19, 14);
        let a = img(w, h, 0.0);
        let b = img(w, h, 0.9);
        let mask: Vec<f32> = (0..w * h)
            .map(|i| if i % 7 == 3 { 0.0 } else { 1.0 })
            .collect();
        let (_, g) = loss_and_grad(&a, &b, Some(&mask), (w, h), 0.2);
        // Masked pixels get no gradient from L1 and (by the mask weights) the
        // SSIM term only reaches them through neighbours' windows.
        let mut worst = 0.0f64;
        for idx in [0usize, 5, 77, 200, 401, 3 * (w * h) - 1] {
            let eps = 1e-3f32;
            let mut p = a.clone();
            p[idx] += eps;
            let mut q = a.clone();
            q[idx] -= eps;
            let h_ = p[idx] as f64 - q[idx] as f64;
            let lp = loss_and_grad(&p, &b, Some(&mask), (w, h), 0.2).0.loss;
            let lq = loss_and_grad(&q, &b, Some(&mask), (w, h), 0.2).0.loss;
            let num = (lp - lq) / h_;
            worst = worst.max((num - g[idx] as f64).abs() / num.abs().max(1e-4));
        }
        // f32 gradient output: relative error of a few 1e-4 expected.
        assert!(worst < 2e-3, "worst rel err {worst}");
    }

    #[test]
    fn masked_pixels_do_not_count() {
        let (w, h) = (16, 16);
        let a = img(w, h, 0.0);
        let mut b = a.clone();
        // Corrupt the left half of the target; mask it out.
        for y in 0..h {
            for x in 0..w / 2 {
                for c in 0..3 {
                    b[(y * w + x) * 3 + c] = 1.0 - b[(y * w + x) * 3 + c];
                }
            }
        }
        let mask: Vec<f32> = (0..w * h)
            .map(|i| if i % w < w / 2 { 0.0 } else { 1.0 })
            .collect();
        let (v, g) = loss_and_grad(&a, &b, Some(&mask), (w, h), 0.0);
        assert_eq!(v.l1, 0.0);
        assert_eq!(v.kept, (w * h / 2) as f64);
        assert!(g.iter().all(|&x| x == 0.0));
        let (v, _) = loss_and_grad(&a, &b, None, (w, h), 0.0);
        assert!(v.l1 > 0.1);
    }
}
