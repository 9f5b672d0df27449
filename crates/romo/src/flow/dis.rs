//! Dense Inverse Search optical flow (Kroeger, Timofte, Dai, Van Gool:
//! "Fast Optical Flow using Dense Inverse Search", ECCV 2016), in Rust with
//! rayon.
//!
//! Per pyramid level, coarse to fine:
//! 1. a grid of square patches (size `patch_size`, step `patch_stride`) is
//!    each aligned to the second frame by inverse-compositional Lucas–Kanade
//!    on mean-normalised intensities, starting from the upsampled flow of
//!    the coarser level;
//! 2. patch flows propagate to neighbours when they explain a patch better;
//! 3. densification: each pixel takes the average of the flows of the
//!    patches covering it, weighted by `1 / max(1, |I1(x+u) − I0(x)|)`;
//! 4. variational refinement ([`super::variational`]).
//!
//! Our additions for large motion (Sintel ambush/market, 30–70 px): the
//! pyramid goes down until the image is about `coarsest_width` pixels wide,
//! and at the coarsest level each patch first searches exhaustively over
//! integer displacements within `coarse_search_radius` before descending.

use super::variational::{self, VariationalOptions};
use super::{Flow, FlowEstimator};
use crate::plane::Plane;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// DIS parameters. Defaults follow OpenCV's MEDIUM preset (finest scale 1,
/// 8-px patches every 3 px, 25 descent iterations, 5 variational
/// iterations) plus the coarse search (radius 4 px at the coarsest level).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct DisOptions {
    /// Finest pyramid level that is computed (0 = full resolution; 1 = half,
    /// then bilinearly upsampled). Default 1.
    pub finest_scale: usize,
    /// Patch side in pixels (default 8).
    pub patch_size: usize,
    /// Distance between patch origins in pixels (default 3).
    pub patch_stride: usize,
    /// Gauss–Newton iterations per patch (default 25).
    pub grad_descent_iters: usize,
    /// Width in pixels below which no coarser level is built (default 32).
    pub coarsest_width: usize,
    /// Exhaustive integer search radius at the coarsest level, px of that
    /// level (default 4; 0 disables).
    pub coarse_search_radius: usize,
    /// Variational refinement (α = 20, δ = 5, γ = 10, 5 iterations).
    pub variational: VariationalOptions,
}

impl Default for DisOptions {
    fn default() -> Self {
        Self {
            finest_scale: 1,
            patch_size: 8,
            patch_stride: 3,
            grad_descent_iters: 25,
            coarsest_width: 32,
            coarse_search_radius: 4,
            variational: VariationalOptions::default(),
        }
    }
}

impl DisOptions {
    /// Check the options are usable.
    pub fn validate(&self) -> crate::Result<()> {
        if self.patch_size < 4 || self.patch_stride == 0 || self.patch_stride > self.patch_size {
            return Err(crate::RomoError::Options(format!(
                "DIS: need patch_size >= 4 and 0 < patch_stride <= patch_size (got {} / {})",
                self.patch_size, self.patch_stride
            )));
        }
        if !(0.0..2.0).contains(&self.variational.omega) || self.variational.alpha < 0.0 {
            return Err(crate::RomoError::Options(
                "DIS: variational omega must be in (0, 2) and alpha >= 0".into(),
            ));
        }
        Ok(())
    }
}

/// The built-in flow backend.
#[derive(Debug, Clone, Default)]
pub struct Dis {
    /// Parameters.
    pub opts: DisOptions,
}

/// Patch origins along one axis covering `[0, len)` completely.
fn grid(len: usize, ps: usize, stride: usize) -> Vec<usize> {
    if len <= ps {
        return vec![0];
    }
    let mut v: Vec<usize> = (0..=len - ps).step_by(stride).collect();
    if v.last().copied() != Some(len - ps) {
        v.push(len - ps);
    }
    v
}

/// One patch: its template and precomputed inverse Hessian.
struct Template {
    x0: usize,
    y0: usize,
    t: Vec<f32>,
    tx: Vec<f32>,
    ty: Vec<f32>,
    hinv: [f32; 3],
}

impl Template {
    fn new(i0: &Plane, gx: &Plane, gy: &Plane, x0: usize, y0: usize, ps: usize) -> Self {
        let n = ps * ps;
        let (mut t, mut tx, mut ty) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for y in y0..y0 + ps {
            for x in x0..x0 + ps {
                let xx = x.min(i0.w - 1);
                let yy = y.min(i0.h - 1);
                t.push(i0.at(xx, yy));
                tx.push(gx.at(xx, yy));
                ty.push(gy.at(xx, yy));
            }
        }
        let m = t.iter().sum::<f32>() / n as f32;
        t.iter_mut().for_each(|v| *v -= m);
        let (mut a, mut b, mut c) = (1e-2f32, 0.0f32, 1e-2f32);
        for k in 0..n {
            a += tx[k] * tx[k];
            b += tx[k] * ty[k];
            c += ty[k] * ty[k];
        }
        let det = a * c - b * b;
        let hinv = if det.abs() > 1e-9 {
            [c / det, -b / det, a / det]
        } else {
            [0.0; 3]
        };
        Template {
            x0,
            y0,
            t,
            tx,
            ty,
            hinv,
        }
    }

    /// Mean-normalised warped patch of `i1` at displacement (u, v). The
    /// bilinear weights are shared by the whole patch (pure translation), so
    /// patches fully inside the image take a fast path without clamping.
    fn warp(&self, i1: &Plane, ps: usize, u: f32, v: f32, out: &mut [f32]) {
        let fx0 = self.x0 as f32 + u;
        let fy0 = self.y0 as f32 + v;
        let (bx, by) = (fx0.floor(), fy0.floor());
        let inside =
            bx >= 0.0 && by >= 0.0 && (bx as usize + ps) < i1.w && (by as usize + ps) < i1.h;
        let mut s = 0.0;
        if inside {
            let (ax, ay) = (fx0 - bx, fy0 - by);
            let w00 = (1.0 - ax) * (1.0 - ay);
            let w10 = ax * (1.0 - ay);
            let w01 = (1.0 - ax) * ay;
            let w11 = ax * ay;
            let (bx, by) = (bx as usize, by as usize);
            let d = &i1.data;
            for y in 0..ps {
                let r0 = (by + y) * i1.w + bx;
                let r1 = r0 + i1.w;
                let o = &mut out[y * ps..(y + 1) * ps];
                for x in 0..ps {
                    let val = w00 * d[r0 + x]
                        + w10 * d[r0 + x + 1]
                        + w01 * d[r1 + x]
                        + w11 * d[r1 + x + 1];
                    o[x] = val;
                    s += val;
                }
            }
        } else {
            let mut k = 0;
            for y in 0..ps {
                for x in 0..ps {
                    let val = i1.bilinear((self.x0 + x) as f32 + u, (self.y0 + y) as f32 + v);
                    out[k] = val;
                    s += val;
                    k += 1;
                }
            }
        }
        let m = s / (ps * ps) as f32;
        out.iter_mut().for_each(|o| *o -= m);
    }

    /// Mean-normalised SSD at displacement (u, v).
    fn cost(&self, i1: &Plane, ps: usize, u: f32, v: f32, buf: &mut [f32]) -> f32 {
        self.warp(i1, ps, u, v, buf);
        buf.iter()
            .zip(&self.t)
            .map(|(a, b)| (a - b) * (a - b))
            .sum()
    }

    /// Inverse-compositional Gauss–Newton from (u, v); returns the flow and
    /// its cost, never worse than the starting point.
    fn align(&self, i1: &Plane, ps: usize, iters: usize, start: (f32, f32)) -> ((f32, f32), f32) {
        let mut buf = vec![0.0f32; ps * ps];
        let c0 = self.cost(i1, ps, start.0, start.1, &mut buf);
        let (mut u, mut v) = start;
        for _ in 0..iters {
            self.warp(i1, ps, u, v, &mut buf);
            let (mut bx, mut by) = (0.0f32, 0.0f32);
            for (((b, t), gx), gy) in buf.iter().zip(&self.t).zip(&self.tx).zip(&self.ty) {
                let e = b - t;
                bx += gx * e;
                by += gy * e;
            }
            let du = self.hinv[0] * bx + self.hinv[1] * by;
            let dv = self.hinv[1] * bx + self.hinv[2] * by;
            u -= du;
            v -= dv;
            if du * du + dv * dv < 1e-4 {
                break;
            }
        }
        let c1 = self.cost(i1, ps, u, v, &mut buf);
        if c1.is_finite() && c1 <= c0 && (u - start.0).hypot(v - start.1) <= 2.0 * ps as f32 {
            ((u, v), c1)
        } else {
            (start, c0)
        }
    }
}

/// Level context for the patch stage.
struct Level<'a> {
    i0: &'a Plane,
    i1: &'a Plane,
    coarsest: bool,
}

impl Dis {
    /// New DIS with the given options.
    pub fn new(opts: DisOptions) -> Self {
        Self { opts }
    }

    fn level(&self, lv: &Level, init: &Flow) -> Flow {
        let o = &self.opts;
        let (i0, i1) = (lv.i0, lv.i1);
        let ps = o.patch_size.min(i0.w).min(i0.h);
        let (gx, gy) = i0.gradients();
        let xs = grid(i0.w, ps, o.patch_stride);
        let ys = grid(i0.h, ps, o.patch_stride);
        let nx = xs.len();
        let half = ps as f32 / 2.0 - 0.5;
        let templates: Vec<Template> = ys
            .par_iter()
            .flat_map_iter(|&y0| {
                let (gx, gy) = (&gx, &gy);
                xs.iter()
                    .map(move |&x0| Template::new(i0, gx, gy, x0, y0, ps))
            })
            .collect();
        // 1. Inverse search per patch.
        let mut res: Vec<((f32, f32), f32)> = templates
            .par_iter()
            .map(|t| {
                let mut start = init.sample(t.x0 as f32 + half, t.y0 as f32 + half);
                if lv.coarsest && o.coarse_search_radius > 0 {
                    let r = o.coarse_search_radius as isize;
                    let mut buf = vec![0.0f32; ps * ps];
                    let mut best = (t.cost(i1, ps, start.0, start.1, &mut buf), start);
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let c = (start.0 + dx as f32, start.1 + dy as f32);
                            let cost = t.cost(i1, ps, c.0, c.1, &mut buf);
                            if cost < best.0 {
                                best = (cost, c);
                            }
                        }
                    }
                    start = best.1;
                }
                t.align(i1, ps, o.grad_descent_iters, start)
            })
            .collect();
        // 2. Propagation: adopt a neighbour's flow if it fits this patch
        // better (two Jacobi passes).
        for _ in 0..2 {
            res = (0..templates.len())
                .into_par_iter()
                .map(|k| {
                    let (px, py) = (k % nx, k / nx);
                    let mut best = res[k];
                    let mut buf = vec![0.0f32; ps * ps];
                    let mut cand = |j: usize| {
                        let f = res[j].0;
                        let c = templates[k].cost(i1, ps, f.0, f.1, &mut buf);
                        if c < best.1 {
                            best = (f, c);
                        }
                    };
                    if px > 0 {
                        cand(k - 1);
                    }
                    if px + 1 < nx {
                        cand(k + 1);
                    }
                    if py > 0 {
                        cand(k - nx);
                    }
                    if k + nx < templates.len() {
                        cand(k + nx);
                    }
                    best
                })
                .collect();
        }
        // 3. Densification, row-parallel.
        let (w, h) = (i0.w, i0.h);
        let rows: Vec<(Vec<f32>, Vec<f32>)> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut su = vec![0.0f32; w];
                let mut sv = vec![0.0f32; w];
                let mut sw = vec![0.0f32; w];
                for (py, &y0) in ys.iter().enumerate() {
                    if y < y0 || y >= y0 + ps {
                        continue;
                    }
                    for (px, &x0) in xs.iter().enumerate() {
                        let ((u, v), _) = res[py * nx + px];
                        let (fx, fy) = (x0 as f32 + u, y as f32 + v);
                        let (bx, by) = (fx.floor(), fy.floor());
                        let fast = bx >= 0.0
                            && by >= 0.0
                            && (bx as usize + ps) < w
                            && (by as usize + 1) < h;
                        let (ax, ay) = (fx - bx, fy - by);
                        let (bxu, byu) = (bx.max(0.0) as usize, by.max(0.0) as usize);
                        for x in x0..(x0 + ps).min(w) {
                            let warped = if fast {
                                let r0 = byu * w + bxu + (x - x0);
                                let r1 = r0 + w;
                                let d = &i1.data;
                                (1.0 - ay) * ((1.0 - ax) * d[r0] + ax * d[r0 + 1])
                                    + ay * ((1.0 - ax) * d[r1] + ax * d[r1 + 1])
                            } else {
                                i1.bilinear(x as f32 + u, y as f32 + v)
                            };
                            let d = warped - i0.at(x, y);
                            let wt = 1.0 / d.abs().max(1.0);
                            su[x] += wt * u;
                            sv[x] += wt * v;
                            sw[x] += wt;
                        }
                    }
                }
                for x in 0..w {
                    if sw[x] > 0.0 {
                        su[x] /= sw[x];
                        sv[x] /= sw[x];
                    } else {
                        let (u, v) = init.sample(x as f32, y as f32);
                        su[x] = u;
                        sv[x] = v;
                    }
                }
                (su, sv)
            })
            .collect();
        let mut out = Flow::zeros(w, h);
        for (y, (ru, rv)) in rows.into_iter().enumerate() {
            out.u.data[y * w..(y + 1) * w].copy_from_slice(&ru);
            out.v.data[y * w..(y + 1) * w].copy_from_slice(&rv);
        }
        // 4. Variational refinement.
        variational::refine(i0, i1, &mut out, &o.variational);
        out
    }

    /// Flow between two grayscale planes in [0, 1].
    pub fn compute(&self, i0: &Plane, i1: &Plane) -> crate::Result<Flow> {
        self.opts.validate()?;
        if i0.w != i1.w || i0.h != i1.h || i0.w < 2 || i0.h < 2 {
            return Err(crate::RomoError::Input(format!(
                "flow: frames must have equal size of at least 2x2 (got {}x{} and {}x{})",
                i0.w, i0.h, i1.w, i1.h
            )));
        }
        let scale = |p: &Plane| p.map(|v| v * 255.0);
        let mut p0 = vec![scale(i0)];
        let mut p1 = vec![scale(i1)];
        loop {
            let last = &p0[p0.len() - 1];
            if last.w / 2 < self.opts.coarsest_width.max(self.opts.patch_size)
                || last.h / 2 < self.opts.patch_size
            {
                break;
            }
            let (a, b) = (last.half(), p1[p1.len() - 1].half());
            p0.push(a);
            p1.push(b);
        }
        let coarsest = p0.len() - 1;
        let finest = self.opts.finest_scale.min(coarsest);
        let mut flow = Flow::zeros(p0[coarsest].w, p0[coarsest].h);
        for l in (finest..=coarsest).rev() {
            let (a, b) = (&p0[l], &p1[l]);
            if flow.w() != a.w || flow.h() != a.h {
                flow = flow.resize(a.w, a.h);
            }
            let lv = Level {
                i0: a,
                i1: b,
                coarsest: l == coarsest,
            };
            flow = self.level(&lv, &flow);
        }
        if flow.w() != i0.w || flow.h() != i0.h {
            flow = flow.resize(i0.w, i0.h);
        }
        Ok(flow)
    }
}

impl FlowEstimator for Dis {
    fn name(&self) -> &str {
        "dis"
    }

    fn flow(&self, i0: &Plane, i1: &Plane) -> crate::Result<Flow> {
        self.compute(i0, i1)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::flow::epe;

    /// A smooth random texture (sum of sinusoids), values in [0, 1].
    fn texture(x: f32, y: f32) -> f32 {
        let mut s = 0.5;
        let waves = [
            (0.21, 0.13, 0.0, 0.12),
            (-0.11, 0.27, 1.0, 0.1),
            (0.05, -0.07, 2.0, 0.12),
            (0.37, 0.31, 0.5, 0.06),
            (-0.3, 0.17, 3.0, 0.05),
        ];
        for (a, b, p, amp) in waves {
            s += amp * (a * x + b * y + p).sin();
        }
        s
    }

    fn check(map: impl Fn(f32, f32) -> (f32, f32) + Sync, max_epe: f64) {
        let (w, h) = (160, 120);
        // i1(x + flow(x)) = i0(x): i0 samples the texture at the mapped point.
        let i1 = Plane::from_fn(w, h, |x, y| texture(x as f32, y as f32));
        let i0 = Plane::from_fn(w, h, |x, y| {
            let (u, v) = map(x as f32, y as f32);
            texture(x as f32 + u, y as f32 + v)
        });
        let gt = Flow {
            u: Plane::from_fn(w, h, |x, y| map(x as f32, y as f32).0),
            v: Plane::from_fn(w, h, |x, y| map(x as f32, y as f32).1),
        };
        let est = Dis::default().compute(&i0, &i1).unwrap();
        // Ignore a 10-px border where content leaves the frame.
        let mask: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                x >= 10 && y >= 10 && x < w - 10 && y < h - 10
            })
            .collect();
        let e = epe(&est, &gt, Some(&mask));
        assert!(e < max_epe, "EPE {e} >= {max_epe}");
    }

    // Tolerances: measured 2026-11 on these textures (translation ~0.05 px,
    // affine ~0.1 px); the bounds leave a margin of several times that.
    #[test]
    fn recovers_a_translation() {
        check(|_, _| (3.4, -1.7), 0.25);
    }

    #[test]
    fn recovers_an_affine_warp() {
        check(
            |x, y| {
                let (cx, cy) = (x - 80.0, y - 60.0);
                (1.5 + 0.03 * cx - 0.02 * cy, -0.8 + 0.02 * cx + 0.025 * cy)
            },
            0.4,
        );
    }

    #[test]
    fn grid_covers_everything() {
        assert_eq!(grid(20, 8, 3), vec![0, 3, 6, 9, 12]);
        assert_eq!(grid(21, 8, 3), vec![0, 3, 6, 9, 12, 13]);
        assert_eq!(grid(5, 8, 3), vec![0]);
    }
}
