//! Variational flow refinement, the last step of each DIS pyramid level
//! (Kroeger et al. 2016, §2.2), minimising the Brox et al. (ECCV 2004) energy
//!
//! `E(du) = Σ δ·Ψ(E_I) + γ·Ψ(E_G) + α·Ψ(|∇(u+du)|² + |∇(v+dv)|²)`
//!
//! with brightness constancy `E_I`, gradient constancy `E_G` (both linearised
//! around the current flow and normalised by the local gradient strength, as
//! in Zimmer et al. 2011) and the robust `Ψ(s²) = √(s² + ε²)`. As in
//! OpenCV's `VariationalRefinement`, the second image is warped once, its
//! derivatives are taken on the warped image and averaged with the first
//! image's, and the lagged non-linearity runs `fixed_point_iters` outer
//! updates of the robust weights, each followed by `sor_iters` red–black SOR
//! sweeps. The increments are stored split by colour ("packed" red and black
//! arrays, each row padded by one cell) so a colour can be updated in place,
//! row-parallel, while the other is only read.
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

/// `src` sampled at `x + flow(x)` (bilinear, clamped to the image).
fn warp(src: &Plane, flow: &Flow) -> Plane {
    let (w, h) = (src.w, src.h);
    let (xm, ym) = ((w - 1) as f32, (h - 1) as f32);
    let d1 = &src.data;
    Plane::from_fn(w, h, |x, y| {
        let i = y * w + x;
        // Clamped to the image, so the casts floor.
        let fx = (x as f32 + flow.u.data[i]).clamp(0.0, xm);
        let fy = (y as f32 + flow.v.data[i]).clamp(0.0, ym);
        let (x0, y0) = (fx as usize, fy as usize);
        let (ax, ay) = (fx - x0 as f32, fy - y0 as f32);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let top = d1[y0 * w + x0] + ax * (d1[y0 * w + x1] - d1[y0 * w + x0]);
        let bot = d1[y1 * w + x0] + ax * (d1[y1 * w + x1] - d1[y1 * w + x0]);
        top + ay * (bot - top)
    })
}

fn linearise(i0: &Plane, i1: &Plane, flow: &Flow) -> Data {
    // The second image and its derivatives, warped once with the flow.
    let warped = warp(i1, flow);
    let (u1x, u1y) = i1.gradients();
    let (u1xx, u1xy) = u1x.gradients();
    let (_, u1yy) = u1y.gradients();
    let (g1x, g1y) = (warp(&u1x, flow), warp(&u1y, flow));
    let (g1xx, g1xy, g1yy) = (warp(&u1xx, flow), warp(&u1xy, flow), warp(&u1yy, flow));
    let (g0x, g0y) = i0.gradients();
    let (g0xx, g0xy) = g0x.gradients();
    let (_, g0yy) = g0y.gradients();
    let avg = |a: &Plane, b: &Plane| a.zip(b, |p, q| 0.5 * (p + q)).data;
    let diff = |a: &Plane, b: &Plane| a.zip(b, |p, q| p - q).data;
    Data {
        ix: avg(&g1x, &g0x),
        iy: avg(&g1y, &g0y),
        iz: diff(&warped, i0),
        ixx: avg(&g1xx, &g0xx),
        ixy: avg(&g1xy, &g0xy),
        iyy: avg(&g1yy, &g0yy),
        ixz: diff(&g1x, &g0x),
        iyz: diff(&g1y, &g0y),
    }
}

/// Red–black packed layout: colour `c` cell `(y, k)` is pixel
/// `x = 2k + (y + c) % 2`; rows have `wr + 2` cells (one pad cell each
/// side) and there is one pad row above and below.
#[derive(Clone, Copy)]
struct Packing {
    w: usize,
    h: usize,
    wr: usize,
    s: usize,
}

impl Packing {
    fn new(w: usize, h: usize) -> Self {
        let wr = w.div_ceil(2);
        Self {
            w,
            h,
            wr,
            s: wr + 2,
        }
    }
    fn len(&self) -> usize {
        self.s * (self.h + 2)
    }
    /// Pixel x of colour `c`, row `y`, packed index `k`.
    #[inline]
    fn x(&self, c: usize, y: usize, k: usize) -> usize {
        2 * k + (y + c) % 2
    }
    /// `full` packed for colour `c` (row-parallel).
    fn packed(&self, full: &[f32], c: usize) -> Vec<f32> {
        let mut out = vec![0.0f32; self.len()];
        out.par_chunks_mut(self.s)
            .enumerate()
            .for_each(|(py, row)| {
                if py == 0 || py > self.h {
                    return;
                }
                let y = py - 1;
                for k in 0..self.wr {
                    let x = self.x(c, y, k);
                    if x < self.w {
                        row[k + 1] = full[y * self.w + x];
                    }
                }
            });
        out
    }
    fn unpack(&self, packed: &[f32], c: usize, full: &mut [f32]) {
        for y in 0..self.h {
            for k in 0..self.wr {
                let x = self.x(c, y, k);
                if x < self.w {
                    full[y * self.w + x] = packed[(y + 1) * self.s + k + 1];
                }
            }
        }
    }
}

/// Per-cell SOR system of one colour: `[1/a11, 1/a22, a12, b1, b2, wl, wr,
/// wu, wd]` (diagonals include the smoothness weights; `b` includes the
/// smoothness of the base flow).
type Coef = [f32; 9];

/// One colour's packed constants: the linearised data terms with their
/// normalisers (fixed during the refinement) and the base flow.
struct PackedData {
    ix: Vec<f32>,
    iy: Vec<f32>,
    iz: Vec<f32>,
    ixx: Vec<f32>,
    ixy: Vec<f32>,
    iyy: Vec<f32>,
    ixz: Vec<f32>,
    iyz: Vec<f32>,
    /// Brightness normaliser `1 / (|∇I|² + ζ²)`.
    ni: Vec<f32>,
    /// Gradient normaliser `1 / (|∇∇I|² + ζ²)`.
    ng: Vec<f32>,
    uu: Vec<f32>,
    vv: Vec<f32>,
}

impl PackedData {
    fn new(p: Packing, c: usize, d: &Data, flow: &Flow, zeta_sq: f32) -> Self {
        let n = d.ix.len();
        let (ni, ng): (Vec<f32>, Vec<f32>) = (0..n)
            .into_par_iter()
            .map(|i| {
                let (ix, iy) = (d.ix[i], d.iy[i]);
                let (ixx, ixy, iyy) = (d.ixx[i], d.ixy[i], d.iyy[i]);
                (
                    1.0 / (ix * ix + iy * iy + zeta_sq),
                    1.0 / (ixx * ixx + 2.0 * ixy * ixy + iyy * iyy + zeta_sq),
                )
            })
            .unzip();
        let pk = |full: &[f32]| p.packed(full, c);
        PackedData {
            ix: pk(&d.ix),
            iy: pk(&d.iy),
            iz: pk(&d.iz),
            ixx: pk(&d.ixx),
            ixy: pk(&d.ixy),
            iyy: pk(&d.iyy),
            ixz: pk(&d.ixz),
            iyz: pk(&d.iyz),
            ni: pk(&ni),
            ng: pk(&ng),
            uu: pk(&flow.u.data),
            vv: pk(&flow.v.data),
        }
    }
}

/// Robust smoothness weight `α Ψ'(|∇(u+du)|² + |∇(v+dv)|²)` (forward
/// differences) of every cell of colour `c`, packed.
fn smoothness(
    p: Packing,
    c: usize,
    me: (&PackedData, &Half),
    other: (&PackedData, &Half),
    o: &VariationalOptions,
) -> Vec<f32> {
    let eps2 = o.epsilon * o.epsilon;
    let (w, h, s) = (p.w, p.h, p.s);
    let (md, mh) = me;
    let (od, oh) = other;
    let mut ws = vec![0.0f32; p.len()];
    ws.par_chunks_mut(s).enumerate().for_each(|(py, row)| {
        if py == 0 || py > h {
            return;
        }
        let y = py - 1;
        let q = (y + c) & 1;
        let base = py * s;
        for (k, out) in row[1..=p.wr].iter_mut().enumerate() {
            let x = p.x(c, y, k);
            if x >= w {
                continue;
            }
            let j = base + k + 1;
            let tu = md.uu[j] + mh.u[j];
            let tv = md.vv[j] + mh.v[j];
            let (mut ux, mut vx, mut uy, mut vy) = (0.0, 0.0, 0.0, 0.0);
            if x + 1 < w {
                let r = j + q;
                ux = od.uu[r] + oh.u[r] - tu;
                vx = od.vv[r] + oh.v[r] - tv;
            }
            if y + 1 < h {
                let dn = j + s;
                uy = od.uu[dn] + oh.u[dn] - tu;
                vy = od.vv[dn] + oh.v[dn] - tv;
            }
            *out = o.alpha / (2.0 * (ux * ux + uy * uy + vx * vx + vy * vy + eps2).sqrt());
        }
    });
    ws
}

/// The SOR system of every cell of colour `c` for the current increment.
fn coefficients(
    p: Packing,
    c: usize,
    me: (&PackedData, &Half, &[f32]),
    other: (&PackedData, &[f32]),
    o: &VariationalOptions,
) -> Vec<Coef> {
    let mut out = vec![[0.0f32; 9]; p.len()];
    let eps2 = o.epsilon * o.epsilon;
    let (w, h, s) = (p.w, p.h, p.s);
    let (d, mh, wsm) = me;
    let (od, wso) = other;
    out.par_chunks_mut(s).enumerate().for_each(|(py, row)| {
        if py == 0 || py > h {
            return;
        }
        let y = py - 1;
        let q = (y + c) & 1;
        let base = py * s;
        fn sub(v: &[f32], off: usize, s: usize) -> &[f32] {
            &v[off..off + s]
        }
        let r = |v| sub(v, base, s);
        let (ix, iy, iz) = (r(&d.ix), r(&d.iy), r(&d.iz));
        let (ixx, ixy, iyy) = (r(&d.ixx), r(&d.ixy), r(&d.iyy));
        let (ixz, iyz, nis, ngs) = (r(&d.ixz), r(&d.iyz), r(&d.ni), r(&d.ng));
        let (mu, mv, uu, vv, wm) = (r(&mh.u), r(&mh.v), r(&d.uu), r(&d.vv), r(wsm));
        let (ouc, ovc, owc) = (r(&od.uu), r(&od.vv), r(wso));
        let row3 = |v, off| sub(v, off, s);
        let (ouu, ovu, owu) = (
            row3(&od.uu, base - s),
            row3(&od.vv, base - s),
            row3(wso, base - s),
        );
        let (oud, ovd, owd) = (
            row3(&od.uu, base + s),
            row3(&od.vv, base + s),
            row3(wso, base + s),
        );
        let (has_u, has_d) = ((y > 0) as u8 as f32, (y + 1 < h) as u8 as f32);
        for (k, cell) in row[1..s - 1].iter_mut().enumerate() {
            let x = 2 * k + q;
            if x >= w {
                continue;
            }
            let j = k + 1;
            let (du, dv) = (mu[j], mv[j]);
            let ni = nis[j];
            let ri = iz[j] + ix[j] * du + iy[j] * dv;
            let wi = o.delta * ni / (2.0 * (ri * ri * ni + eps2).sqrt());
            let ng = ngs[j];
            let (gxx, gxy, gyy) = (ixx[j], ixy[j], iyy[j]);
            let rx = ixz[j] + gxx * du + gxy * dv;
            let ry = iyz[j] + gxy * du + gyy * dv;
            let wg = o.gamma * ng / (2.0 * ((rx * rx + ry * ry) * ng + eps2).sqrt());
            let (gx, gy, gz) = (ix[j], iy[j], iz[j]);
            let a12 = wi * gx * gy + wg * (gxx * gxy + gxy * gyy);
            let mut a11 = wi * gx * gx + wg * (gxx * gxx + gxy * gxy);
            let mut a22 = wi * gy * gy + wg * (gxy * gxy + gyy * gyy);
            let mut b1 = -wi * gx * gz - wg * (gxx * ixz[j] + gxy * iyz[j]);
            let mut b2 = -wi * gy * gz - wg * (gxy * ixz[j] + gyy * iyz[j]);
            let (l, rr) = (j + q - 1, j + q);
            let wl = ((x > 0) as u8 as f32) * 0.5 * (wm[j] + owc[l]);
            let wr = ((x + 1 < w) as u8 as f32) * 0.5 * (wm[j] + owc[rr]);
            let wu = has_u * 0.5 * (wm[j] + owu[j]);
            let wd = has_d * 0.5 * (wm[j] + owd[j]);
            a11 += wl + wr + wu + wd;
            a22 += wl + wr + wu + wd;
            b1 += wl * (ouc[l] - uu[j])
                + wr * (ouc[rr] - uu[j])
                + wu * (ouu[j] - uu[j])
                + wd * (oud[j] - uu[j]);
            b2 += wl * (ovc[l] - vv[j])
                + wr * (ovc[rr] - vv[j])
                + wu * (ovu[j] - vv[j])
                + wd * (ovd[j] - vv[j]);
            *cell = [
                1.0 / a11.max(1e-12),
                1.0 / a22.max(1e-12),
                a12,
                b1,
                b2,
                wl,
                wr,
                wu,
                wd,
            ];
        }
    });
    out
}

/// One colour of the increment field, packed.
struct Half {
    u: Vec<f32>,
    v: Vec<f32>,
}

/// One SOR half-sweep: update colour `c` (`mine`) in place reading `other`.
fn sor_half(p: Packing, c: usize, coef: &[Coef], mine: &mut Half, other: &Half, omega: f32) {
    let s = p.s;
    let h = p.h;
    mine.u
        .par_chunks_mut(s)
        .zip(mine.v.par_chunks_mut(s))
        .enumerate()
        .with_min_len(8)
        .for_each(|(py, (ru, rv))| {
            if py == 0 || py > h {
                return;
            }
            let q = (py - 1 + c) & 1;
            let base = py * s;
            let co = &coef[base..base + s];
            let (ou, ov) = (&other.u, &other.v);
            let (uc, uup, udn) = (
                &ou[base..base + s],
                &ou[base - s..base],
                &ou[base + s..][..s],
            );
            let (vc, vup, vdn) = (
                &ov[base..base + s],
                &ov[base - s..base],
                &ov[base + s..][..s],
            );
            let (ru, rv) = (&mut ru[..s], &mut rv[..s]);
            for j in 1..s - 1 {
                let cf = &co[j];
                let (l, r) = (j + q - 1, j + q);
                let su = cf[5] * uc[l] + cf[6] * uc[r] + cf[7] * uup[j] + cf[8] * udn[j];
                let sv = cf[5] * vc[l] + cf[6] * vc[r] + cf[7] * vup[j] + cf[8] * vdn[j];
                let nu = (cf[3] + su - cf[2] * rv[j]) * cf[0];
                ru[j] += omega * (nu - ru[j]);
                let nv = (cf[4] + sv - cf[2] * ru[j]) * cf[1];
                rv[j] += omega * (nv - rv[j]);
            }
        });
}

/// Refine `flow` (from `i0` to `i1`, images in 0–255) in place.
pub fn refine(i0: &Plane, i1: &Plane, flow: &mut Flow, o: &VariationalOptions) {
    if o.fixed_point_iters == 0 || i0.w < 3 || i0.h < 3 {
        return;
    }
    let (w, h) = (i0.w, i0.h);
    let p = Packing::new(w, h);
    let d = linearise(i0, i1, flow);
    let (dr, db) = rayon::join(
        || PackedData::new(p, 0, &d, flow, o.zeta_sq),
        || PackedData::new(p, 1, &d, flow, o.zeta_sq),
    );
    drop(d);
    let zero = || Half {
        u: vec![0.0; p.len()],
        v: vec![0.0; p.len()],
    };
    let (mut red, mut black) = (zero(), zero());
    for _ in 0..o.fixed_point_iters {
        let (wsr, wsb) = rayon::join(
            || smoothness(p, 0, (&dr, &red), (&db, &black), o),
            || smoothness(p, 1, (&db, &black), (&dr, &red), o),
        );
        let (cr, cb) = rayon::join(
            || coefficients(p, 0, (&dr, &red, &wsr), (&db, &wsb), o),
            || coefficients(p, 1, (&db, &black, &wsb), (&dr, &wsr), o),
        );
        for _ in 0..o.sor_iters {
            sor_half(p, 0, &cr, &mut red, &black, o.omega);
            sor_half(p, 1, &cb, &mut black, &red, o.omega);
        }
    }
    let n = w * h;
    let (mut du, mut dv) = (vec![0.0f32; n], vec![0.0f32; n]);
    p.unpack(&red.u, 0, &mut du);
    p.unpack(&red.v, 0, &mut dv);
    p.unpack(&black.u, 1, &mut du);
    p.unpack(&black.v, 1, &mut dv);
    for i in 0..n {
        flow.u.data[i] += du[i];
        flow.v.data[i] += dv[i];
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn packing_round_trips() {
        for (w, h) in [(5, 3), (6, 4), (1, 1), (7, 2)] {
            let p = Packing::new(w, h);
            let full: Vec<f32> = (0..w * h).map(|i| i as f32 + 1.0).collect();
            let (r, b) = (p.packed(&full, 0), p.packed(&full, 1));
            let mut back = vec![0.0; w * h];
            p.unpack(&r, 0, &mut back);
            p.unpack(&b, 1, &mut back);
            assert_eq!(back, full);
        }
    }

    /// The packed neighbour indices (left `j + q - 1`, right `j + q`, up and
    /// down `j`) address the true 4-neighbours of the other colour.
    #[test]
    fn packed_neighbours_are_the_pixel_neighbours() {
        let (w, h) = (7, 5);
        let p = Packing::new(w, h);
        let full: Vec<f32> = (0..w * h).map(|i| i as f32 + 1.0).collect();
        let packed = [p.packed(&full, 0), p.packed(&full, 1)];
        for c in 0..2 {
            let other = &packed[1 - c];
            for y in 1..h - 1 {
                let q = (y + c) & 1;
                for k in 0..p.wr {
                    let x = p.x(c, y, k);
                    if x == 0 || x + 1 >= w {
                        continue;
                    }
                    let j = k + 1;
                    let row = (y + 1) * p.s;
                    assert_eq!(other[row + j + q - 1], full[y * w + x - 1]);
                    assert_eq!(other[row + j + q], full[y * w + x + 1]);
                    assert_eq!(other[row - p.s + j], full[(y - 1) * w + x]);
                    assert_eq!(other[row + p.s + j], full[(y + 1) * w + x]);
                }
            }
        }
    }
}
