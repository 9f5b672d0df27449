//! Variational flow refinement, the last step of each DIS pyramid level
//! (Kroeger et al. 2016, §2.2), minimising the Brox et al. (ECCV 2004) energy
//!
//! `E(du) = Σ δ·Ψ(E_I) + γ·Ψ(E_G) + α·Ψ(|∇(u+du)|² + |∇(v+dv)|²)`
//!
//! with brightness constancy `E_I`, gradient constancy `E_G` (both linearised
//! around the current flow and normalised by the local gradient strength, as
//! in Zimmer et al. 2011) and the robust `Ψ(s²) = √(s² + ε²)`. Lagged
//! non-linearity: `fixed_point_iters` outer updates of the robust weights,
//! each followed by `sor_iters` red–black SOR sweeps (parallel over rows).
//! Images are expected in 0–255 units.

use super::Flow;
use crate::plane::Plane;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Weights of the variational refinement. Defaults are DIS's (OpenCV's
/// `DISOpticalFlow` MEDIUM preset: α = 20, δ = 5, γ = 10, 5 iterations).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct VariationalOptions {
    /// Smoothness weight α (default 20).
    pub alpha: f32,
    /// Brightness-constancy weight δ (default 5).
    pub delta: f32,
    /// Gradient-constancy weight γ (default 10).
    pub gamma: f32,
    /// Outer fixed-point iterations (default 5; 0 disables refinement).
    pub fixed_point_iters: usize,
    /// Inner red–black SOR sweeps per fixed-point iteration (default 5).
    pub sor_iters: usize,
    /// SOR relaxation factor ω in (0, 2) (default 1.6).
    pub omega: f32,
    /// Robust penaliser ε (default 0.001).
    pub epsilon: f32,
    /// Gradient normalisation ζ² in (0–255 intensity units)² (default 0.1).
    pub zeta_sq: f32,
}

impl Default for VariationalOptions {
    fn default() -> Self {
        Self {
            alpha: 20.0,
            delta: 5.0,
            gamma: 10.0,
            fixed_point_iters: 5,
            sor_iters: 5,
            omega: 1.6,
            epsilon: 0.001,
            zeta_sq: 0.1,
        }
    }
}

/// Per-pixel linearised data terms (fixed while the flow increment changes).
struct Data {
    ix: Vec<f32>,
    iy: Vec<f32>,
    iz: Vec<f32>,
    ixx: Vec<f32>,
    ixy: Vec<f32>,
    iyy: Vec<f32>,
    ixz: Vec<f32>,
    iyz: Vec<f32>,
}

fn linearise(i0: &Plane, i1: &Plane, flow: &Flow) -> Data {
    let (g0x, g0y) = i0.gradients();
    let (g1x, g1y) = i1.gradients();
    let (g0xx, g0xy) = g0x.gradients();
    let (_, g0yy) = g0y.gradients();
    let (g1xx, g1xy) = g1x.gradients();
    let (_, g1yy) = g1y.gradients();
    let w = i0.w;
    let n = w * i0.h;
    let mut d = Data {
        ix: vec![0.0; n],
        iy: vec![0.0; n],
        iz: vec![0.0; n],
        ixx: vec![0.0; n],
        ixy: vec![0.0; n],
        iyy: vec![0.0; n],
        ixz: vec![0.0; n],
        iyz: vec![0.0; n],
    };
    let vals: Vec<[f32; 8]> = (0..n)
        .into_par_iter()
        .map(|i| {
            let x = (i % w) as f32 + flow.u.data[i];
            let y = (i / w) as f32 + flow.v.data[i];
            let [w1, w1x, w1y, w1xx, w1xy, w1yy] =
                Plane::bilinear_many([i1, &g1x, &g1y, &g1xx, &g1xy, &g1yy], x, y);
            [
                0.5 * (w1x + g0x.data[i]),
                0.5 * (w1y + g0y.data[i]),
                w1 - i0.data[i],
                0.5 * (w1xx + g0xx.data[i]),
                0.5 * (w1xy + g0xy.data[i]),
                0.5 * (w1yy + g0yy.data[i]),
                w1x - g0x.data[i],
                w1y - g0y.data[i],
            ]
        })
        .collect();
    for (i, v) in vals.iter().enumerate() {
        d.ix[i] = v[0];
        d.iy[i] = v[1];
        d.iz[i] = v[2];
        d.ixx[i] = v[3];
        d.ixy[i] = v[4];
        d.iyy[i] = v[5];
        d.ixz[i] = v[6];
        d.iyz[i] = v[7];
    }
    d
}

/// Refine `flow` (from `i0` to `i1`, images in 0–255) in place.
pub fn refine(i0: &Plane, i1: &Plane, flow: &mut Flow, o: &VariationalOptions) {
    if o.fixed_point_iters == 0 || i0.w < 3 || i0.h < 3 {
        return;
    }
    let (w, h) = (i0.w, i0.h);
    let n = w * h;
    let d = linearise(i0, i1, flow);
    let mut du = vec![0.0f32; n];
    let mut dv = vec![0.0f32; n];
    let eps2 = o.epsilon * o.epsilon;
    for _ in 0..o.fixed_point_iters {
        // Robust weights for the data terms (lagged).
        let coef: Vec<[f32; 5]> = (0..n)
            .into_par_iter()
            .map(|i| {
                let (ix, iy, iz) = (d.ix[i], d.iy[i], d.iz[i]);
                let (ixx, ixy, iyy) = (d.ixx[i], d.ixy[i], d.iyy[i]);
                let ni = 1.0 / (ix * ix + iy * iy + o.zeta_sq);
                let ri = iz + ix * du[i] + iy * dv[i];
                let wi = o.delta * ni / (2.0 * (ri * ri * ni + eps2).sqrt());
                let ng = 1.0 / (ixx * ixx + 2.0 * ixy * ixy + iyy * iyy + o.zeta_sq);
                let rx = d.ixz[i] + ixx * du[i] + ixy * dv[i];
                let ry = d.iyz[i] + ixy * du[i] + iyy * dv[i];
                let wg = o.gamma * ng / (2.0 * ((rx * rx + ry * ry) * ng + eps2).sqrt());
                [
                    wi * ix * ix + wg * (ixx * ixx + ixy * ixy),
                    wi * ix * iy + wg * (ixx * ixy + ixy * iyy),
                    wi * iy * iy + wg * (ixy * ixy + iyy * iyy),
                    -wi * ix * iz - wg * (ixx * d.ixz[i] + ixy * d.iyz[i]),
                    -wi * iy * iz - wg * (ixy * d.ixz[i] + iyy * d.iyz[i]),
                ]
            })
            .collect();
        // Robust smoothness weight per pixel, on the total flow.
        let uu = &flow.u.data;
        let vv = &flow.v.data;
        let ws: Vec<f32> = (0..n)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let xn = if x + 1 < w { i + 1 } else { i };
                let yn = if y + 1 < h { i + w } else { i };
                let ux = uu[xn] + du[xn] - uu[i] - du[i];
                let uy = uu[yn] + du[yn] - uu[i] - du[i];
                let vx = vv[xn] + dv[xn] - vv[i] - dv[i];
                let vy = vv[yn] + dv[yn] - vv[i] - dv[i];
                o.alpha / (2.0 * (ux * ux + uy * uy + vx * vx + vy * vy + eps2).sqrt())
            })
            .collect();
        for _ in 0..o.sor_iters {
            for colour in 0..2 {
                let su = du.clone();
                let sv = dv.clone();
                du.par_chunks_mut(w)
                    .zip(dv.par_chunks_mut(w))
                    .enumerate()
                    .for_each(|(y, (ru, rv))| {
                        let start = (colour + y) % 2;
                        for x in (start..w).step_by(2) {
                            let i = y * w + x;
                            let c = &coef[i];
                            let (mut a11, mut a22) = (c[0], c[2]);
                            let (mut b1, mut b2) = (c[3], c[4]);
                            let mut nb = |j: usize| {
                                let wgt = 0.5 * (ws[i] + ws[j]);
                                a11 += wgt;
                                a22 += wgt;
                                b1 += wgt * (uu[j] + su[j] - uu[i]);
                                b2 += wgt * (vv[j] + sv[j] - vv[i]);
                            };
                            if x > 0 {
                                nb(i - 1);
                            }
                            if x + 1 < w {
                                nb(i + 1);
                            }
                            if y > 0 {
                                nb(i - w);
                            }
                            if y + 1 < h {
                                nb(i + w);
                            }
                            let nu = (b1 - c[1] * rv[x]) / a11.max(1e-12);
                            ru[x] = (1.0 - o.omega) * ru[x] + o.omega * nu;
                            let nv = (b2 - c[1] * ru[x]) / a22.max(1e-12);
                            rv[x] = (1.0 - o.omega) * rv[x] + o.omega * nv;
                        }
                    });
            }
        }
    }
    for i in 0..n {
        flow.u.data[i] += du[i];
        flow.v.data[i] += dv[i];
    }
}
