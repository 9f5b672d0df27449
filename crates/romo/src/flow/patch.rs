//! The patch stage of Dense Inverse Search (Kroeger et al. 2016, §2.1),
//! organised like OpenCV's `DISOpticalFlow`: for a grid of square patches
//! (size `P`, a const generic so the loops unroll and vectorise), an
//! inverse-compositional Gauss–Newton alignment of mean-normalised
//! intensities to the second image, with the Hessian precomputed per patch,
//! run in horizontal stripes with two spatial-propagation passes each. The
//! second image is replicate-padded so the hot loops need no bounds
//! handling; kernel sums are cached so no displacement is evaluated twice.

use super::pyramid;
use super::simd::multiversion;
use crate::plane::Plane;

/// Patch origins along one axis covering `[0, len)` completely.
pub(super) fn grid(len: usize, ps: usize, stride: usize) -> Vec<usize> {
    if len <= ps {
        return vec![0];
    }
    let mut v: Vec<usize> = (0..=len - ps).step_by(stride).collect();
    if v.last().copied() != Some(len - ps) {
        v.push(len - ps);
    }
    v
}

/// Replicate-pad a plane by `b` pixels on every side.
pub(super) fn pad(p: &Plane, b: usize, par: bool) -> Vec<f32> {
    let wp = p.w + 2 * b;
    let mut out = vec![0.0f32; wp * (p.h + 2 * b)];
    pyramid::rows_mut(par, &mut out, wp, |yp, row| {
        let y = yp.saturating_sub(b).min(p.h - 1);
        let src = &p.data[y * p.w..(y + 1) * p.w];
        row[..b].fill(src[0]);
        row[b..b + p.w].copy_from_slice(src);
        row[b + p.w..].fill(src[p.w - 1]);
    });
    out
}

/// One pyramid level as the patch stage sees it.
pub(super) struct Img<'a> {
    pub(super) i0: &'a [f32],
    pub(super) gx: &'a [f32],
    pub(super) gy: &'a [f32],
    pub(super) w: usize,
    pub(super) h: usize,
    /// Second image padded by `b`.
    pub(super) i1p: &'a [f32],
    pub(super) wp: usize,
    pub(super) b: usize,
}

/// A patch: origin and precomputed mean-normalised inverse Hessian.
#[derive(Clone, Copy)]
pub(super) struct Patch {
    pub(super) x0: usize,
    pub(super) y0: usize,
    pub(super) hinv: [f32; 3],
    pub(super) sgx: f32,
    pub(super) sgy: f32,
}

/// A displacement.
pub(super) type Cand = (f32, f32);

/// Kernel sums `[Σd, Σd², Σ gx·d, Σ gy·d]` of a patch at a displacement.
pub(super) type Sums = [f32; 4];

impl Img<'_> {
    /// Offset into the padded second image of the (clamped) patch origin
    /// displaced by (u, v), and the bilinear weights.
    #[inline(always)]
    pub(super) fn locate<const P: usize>(
        &self,
        x0: usize,
        y0: usize,
        u: f32,
        v: f32,
    ) -> (usize, [f32; 4]) {
        let (o, ax, ay) = self.locate_frac::<P>(x0, y0, u, v);
        (
            o,
            [
                (1.0 - ax) * (1.0 - ay),
                ax * (1.0 - ay),
                (1.0 - ax) * ay,
                ax * ay,
            ],
        )
    }

    /// Offset into the padded second image of the (clamped) patch origin
    /// displaced by (u, v), and the fractional parts (x, y).
    #[inline(always)]
    fn locate_frac<const P: usize>(
        &self,
        x0: usize,
        y0: usize,
        u: f32,
        v: f32,
    ) -> (usize, f32, f32) {
        // Shift by the padding so coordinates are non-negative: the cast
        // then floors (std's floor is a libm call without SSE4.1).
        let b = self.b as f32;
        let lo = b - P as f32 + 1.0;
        let px = (x0 as f32 + u + b).clamp(lo, (self.w - 1) as f32 + b);
        let py = (y0 as f32 + v + b).clamp(lo, (self.h - 1) as f32 + b);
        let (ix, iy) = (px as usize, py as usize);
        (iy * self.wp + ix, px - ix as f32, py - iy as f32)
    }

    /// Sums over the patch of the difference `d = I1(x+u) − I0(x)`: `[Σd,
    /// Σd², Σ gx·d, Σ gy·d]`. The bilinear interpolation is separable
    /// (each of the `P + 1` rows of the second image is interpolated along
    /// x once, then consecutive rows along y); per-lane accumulators so the
    /// loops vectorise.
    #[inline(always)]
    fn kernel<const P: usize>(&self, p: &Patch, u: f32, v: f32) -> [f32; 4] {
        let (o1, ax, ay) = self.locate_frac::<P>(p.x0, p.y0, u, v);
        let o0 = p.y0 * self.w + p.x0;
        let mut sd = [0.0f32; P];
        let mut sd2 = [0.0f32; P];
        let mut sx = [0.0f32; P];
        let mut sy = [0.0f32; P];
        let lerp_row = |r: usize| {
            let t = &self.i1p[o1 + r * self.wp..][..P + 1];
            let mut out = [0.0f32; P];
            for j in 0..P {
                out[j] = t[j] + ax * (t[j + 1] - t[j]);
            }
            out
        };
        let mut prev = lerp_row(0);
        for r in 0..P {
            let a = &self.i0[o0 + r * self.w..][..P];
            let gx = &self.gx[o0 + r * self.w..][..P];
            let gy = &self.gy[o0 + r * self.w..][..P];
            let next = lerp_row(r + 1);
            for j in 0..P {
                let d = prev[j] + ay * (next[j] - prev[j]) - a[j];
                sd[j] += d;
                sd2[j] += d * d;
                sx[j] += d * gx[j];
                sy[j] += d * gy[j];
            }
            prev = next;
        }
        [
            sd.iter().sum(),
            sd2.iter().sum(),
            sx.iter().sum(),
            sy.iter().sum(),
        ]
    }

    /// Mean-normalised SSD at (u, v).
    #[inline(always)]
    fn cost<const P: usize>(&self, p: &Patch, c: Cand) -> f32 {
        let [s1, s2, _, _] = self.kernel::<P>(p, c.0, c.1);
        s2 - s1 * s1 / (P * P) as f32
    }

    pub(super) fn patch<const P: usize>(&self, x0: usize, y0: usize) -> Patch {
        let (mut xx, mut xy, mut yy, mut sx, mut sy) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for r in 0..P {
            let o = (y0 + r) * self.w + x0;
            for (gx, gy) in self.gx[o..o + P].iter().zip(&self.gy[o..o + P]) {
                xx += gx * gx;
                xy += gx * gy;
                yy += gy * gy;
                sx += gx;
                sy += gy;
            }
        }
        let n = (P * P) as f32;
        xx -= sx * sx / n;
        xy -= sx * sy / n;
        yy -= sy * sy / n;
        let mut det = xx * yy - xy * xy;
        if det.abs() < 1e-3 {
            det = 1e-3;
        }
        Patch {
            x0,
            y0,
            hinv: [yy / det, -xy / det, xx / det],
            sgx: sx,
            sgy: sy,
        }
    }

    /// Inverse-compositional Gauss–Newton from `start` (whose kernel sums
    /// `start_sums` are known) with early stopping when the distance stops
    /// decreasing; a result farther than `P` from the start is rejected.
    /// Returns the result and, when they were computed, its kernel sums.
    #[inline(always)]
    fn align<const P: usize>(
        &self,
        p: &Patch,
        start: Cand,
        start_sums: Sums,
        iters: usize,
        step: f32,
    ) -> (Cand, Option<Sums>) {
        let n = (P * P) as f32;
        let mut cur = start;
        let mut sums = start_sums;
        let mut best = (start, f32::INFINITY, start_sums);
        let mut prev = f32::INFINITY;
        let mut stopped = false;
        for it in 0..iters {
            if it > 0 {
                sums = self.kernel::<P>(p, cur.0, cur.1);
            }
            let [s1, s2, bx, by] = sums;
            let ssd = s2 - s1 * s1 / n;
            if ssd < best.1 {
                best = (cur, ssd, sums);
            }
            if ssd >= prev {
                stopped = true;
                break;
            }
            prev = ssd;
            let bx = step * (bx - s1 * p.sgx / n);
            let by = step * (by - s1 * p.sgy / n);
            cur.0 -= p.hinv[0] * bx + p.hinv[1] * by;
            cur.1 -= p.hinv[1] * bx + p.hinv[2] * by;
        }
        let res = if stopped {
            (best.0, Some(best.2))
        } else {
            (cur, None)
        };
        if res.0.0.is_finite()
            && res.0.1.is_finite()
            && (res.0.0 - start.0).hypot(res.0.1 - start.1) <= P as f32
        {
            res
        } else {
            (start, Some(start_sums))
        }
    }

    /// Exhaustive integer search within `r` around `c`.
    fn search<const P: usize>(&self, p: &Patch, c: Cand, r: usize) -> Cand {
        let r = r as isize;
        let mut best = (self.cost::<P>(p, c), c);
        for dy in -r..=r {
            for dx in -r..=r {
                let cand = (c.0 + dx as f32, c.1 + dy as f32);
                let cost = self.cost::<P>(p, cand);
                if cost < best.0 {
                    best = (cost, cand);
                }
            }
        }
        best.1
    }
}

/// Everything one stripe needs besides its own flows.
pub(super) struct StripeCtx<'a> {
    pub(super) img: &'a Img<'a>,
    pub(super) patches: &'a [Patch],
    pub(super) nx: usize,
    pub(super) iters: usize,
    pub(super) search_radius: usize,
    pub(super) step: f32,
    /// A whole-image displacement tried as one more start for every patch
    /// in the first pass (see `DisOptions::global_search`).
    pub(super) global: Option<Cand>,
}

multiversion! {
    /// Two propagation + descent passes over one stripe of patch rows
    /// (`s` holds the stripe's flows, row-major, `nx` per row).
    pub(super) fn stripe<const P: usize>(ctx: &StripeCtx, first_row: usize, s: &mut [Cand]) {
        let nx = ctx.nx;
        let rows = s.len() / nx;
        let img = ctx.img;
        let pat = |k: usize| &ctx.patches[first_row * nx + k];
        if ctx.search_radius > 0 {
            for (k, c) in s.iter_mut().enumerate() {
                *c = img.search::<P>(pat(k), *c, ctx.search_radius);
            }
        }
        let per_pass = (ctx.iters / 2).max(1);
        let n = (P * P) as f32;
        let cost = |m: &Sums| m[1] - m[0] * m[0] / n;
        // Kernel sums at each patch's current flow, when known.
        let mut known: Vec<Option<Sums>> = vec![None; s.len()];
        for pass in 0..2 {
            for ri in 0..rows {
                for ci in 0..nx {
                    let (r, c) = if pass == 0 {
                        (ri, ci)
                    } else {
                        (rows - 1 - ri, nx - 1 - ci)
                    };
                    let k = r * nx + c;
                    let p = pat(k);
                    let own = known[k].unwrap_or_else(|| img.kernel::<P>(p, s[k].0, s[k].1));
                    let mut best = (cost(&own), s[k], own);
                    let mut try_flow = |f: Cand| {
                        // Equal flows have equal costs: skip the evaluation.
                        if f != best.1 {
                            let m = img.kernel::<P>(p, f.0, f.1);
                            let cf = cost(&m);
                            if cf < best.0 {
                                best = (cf, f, m);
                            }
                        }
                    };
                    if pass == 0 {
                        if let Some(g) = ctx.global {
                            try_flow(g);
                        }
                        if c > 0 {
                            try_flow(s[k - 1]);
                        }
                        if r > 0 {
                            try_flow(s[k - nx]);
                        }
                    } else {
                        if c + 1 < nx {
                            try_flow(s[k + 1]);
                        }
                        if r + 1 < rows {
                            try_flow(s[k + nx]);
                        }
                    }
                    (s[k], known[k]) = img.align::<P>(p, best.1, best.2, per_pass, ctx.step);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_covers_everything() {
        assert_eq!(grid(20, 8, 3), vec![0, 3, 6, 9, 12]);
        assert_eq!(grid(21, 8, 3), vec![0, 3, 6, 9, 12, 13]);
        assert_eq!(grid(5, 8, 3), vec![0]);
    }
}
