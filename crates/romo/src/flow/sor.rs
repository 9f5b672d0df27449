//! The linear solver of the variational refinement
//! ([`super::variational`]): red–black SOR on the colour-packed system,
//! run as a wavefront (all `sor_iters` sweeps in one pass over the rows, so
//! the rows in flight stay in cache) and split into two exact bands with
//! ghost zones on large levels. Both schedules reproduce plain red–black
//! SOR bit for bit (tests).

use super::simd::multiversion;
use super::variational::{A12, B1, B2, Ctx, EH, EV, IA11, IA22, L, NC, fld, ld, st};

/// SOR update of colour `c`, padded row `py` (`own`: that row, `[u | v]`)
/// reading the other colour's rows above, at and below (`nb`).
#[inline(always)]
fn sor_row(cx: &Ctx, co: &[Vec<f32>; 2], c: usize, py: usize, own: &mut [f32], nb: [&[f32]; 3]) {
    let (s, wr) = (cx.p.s, cx.p.wr);
    let omega = cx.o.omega;
    let (coef, oco) = (&co[c], &co[1 - c]);
    let q = (py - 1 + c) & 1;
    let cf = |k| fld(coef, NC, s, py, k);
    let (ia11, ia22, a12, b1, b2) = (cf(IA11), cf(IA22), cf(A12), cf(B1), cf(B2));
    let (eh, ev) = (cf(EH), cf(EV));
    let (oeh, oev) = (fld(oco, NC, s, py, EH), fld(oco, NC, s, py - 1, EV));
    let [up, cur, dn] = nb;
    let (ouc, ovc) = cur.split_at(s);
    let (ouu, ovu) = up.split_at(s);
    let (oud, ovd) = dn.split_at(s);
    let (ru, rv) = own.split_at_mut(s);
    for j in (1..=wr).step_by(L) {
        let (wl, wrr, wu, wd) = (ld(oeh, j + q - 1), ld(eh, j), ld(oev, j), ld(ev, j));
        let (ul, ur, uu, ud) = (ld(ouc, j + q - 1), ld(ouc, j + q), ld(ouu, j), ld(oud, j));
        let (vl, vr, vu, vd) = (ld(ovc, j + q - 1), ld(ovc, j + q), ld(ovu, j), ld(ovd, j));
        let (ia11, ia22, a12) = (ld(ia11, j), ld(ia22, j), ld(a12, j));
        let (b1, b2) = (ld(b1, j), ld(b2, j));
        let (mut cu, mut cv) = (ld(ru, j), ld(rv, j));
        for l in 0..L {
            let su = wl[l] * ul[l] + wrr[l] * ur[l] + wu[l] * uu[l] + wd[l] * ud[l];
            let sv = wl[l] * vl[l] + wrr[l] * vr[l] + wu[l] * vu[l] + wd[l] * vd[l];
            let nu = (b1[l] + su - a12[l] * cv[l]) * ia11[l];
            cu[l] += omega * (nu - cu[l]);
            let nv = (b2[l] + sv - a12[l] * cu[l]) * ia22[l];
            cv[l] += omega * (nv - cv[l]);
        }
        st(ru, j, cu);
        st(rv, j, cv);
    }
}

/// A horizontal band of padded rows `[r0, r0 + n)` of both colours' flow
/// (rows of `[u | v]`), with copies of the rows just above and below.
struct Band<'a> {
    r0: usize,
    rows: [&'a mut [f32]; 2],
    /// `[colour][above, below]`.
    halo: [[Vec<f32>; 2]; 2],
}

/// `sor_iters` red–black SOR sweeps over a band as one wavefront: at step
/// `t`, sweep `k` updates red row `t − 2k` then black row `t − 2k − 1`, so
/// every update reads exactly the values plain red–black SOR would (each
/// red row after the previous sweep's black rows around it, each black row
/// after this sweep's red rows), while the ~`4k` rows in flight stay in
/// cache. Rows outside the band are read from `halo`.
#[inline(always)]
fn sor_band(cx: &Ctx, co: &[Vec<f32>; 2], band: Band) {
    let s2 = 2 * cx.p.s;
    let Band { r0, rows, halo } = band;
    let n = rows[0].len() / s2;
    let k_max = cx.o.sor_iters;
    let [rows0, rows1] = rows;
    let mut rows = [rows0, rows1];
    for t in 0..n + 2 * k_max {
        for k in 0..k_max {
            for c in 0..2 {
                let lag = 2 * k + c;
                if t < lag || t - lag >= n {
                    continue;
                }
                let i = t - lag;
                let (mine, other) = if c == 0 {
                    let [a, b] = &mut rows;
                    (a, &**b)
                } else {
                    let [a, b] = &mut rows;
                    (b, &**a)
                };
                let row = |i: isize| -> &[f32] {
                    if i < 0 {
                        &halo[1 - c][0]
                    } else if i as usize >= n {
                        &halo[1 - c][1]
                    } else {
                        &other[i as usize * s2..][..s2]
                    }
                };
                let ii = i as isize;
                let nb = [row(ii - 1), row(ii), row(ii + 1)];
                sor_row(cx, co, c, r0 + i, &mut mine[i * s2..][..s2], nb);
            }
        }
    }
}

multiversion! {
    /// `sor_iters` SOR sweeps over the whole flow, exactly red–black SOR. On
    /// large levels the rows are cut into two bands processed in parallel;
    /// each band also sweeps a ghost zone of `2·sor_iters + 1` rows beyond its
    /// boundaries (the rows its own rows depend on within the sweeps: each
    /// sweep propagates two rows) starting from the same state, and keeps only
    /// its own rows, so the result does not depend on the banding.
    pub(super) fn sor(cx: &Ctx, co: &[Vec<f32>; 2], fl: &mut [Vec<f32>; 2]) {
        let (h, s2) = (cx.p.h, 2 * cx.p.s);
        if !cx.par || h < 4 {
            let [f0, f1] = fl;
            let halo = [
                [f0[..s2].to_vec(), f0[(h + 1) * s2..].to_vec()],
                [f1[..s2].to_vec(), f1[(h + 1) * s2..].to_vec()],
            ];
            let band = Band {
                r0: 1,
                rows: [&mut f0[s2..(h + 1) * s2], &mut f1[s2..(h + 1) * s2]],
                halo,
            };
            sor_band(cx, co, band);
            return;
        }
        let ghost = 2 * cx.o.sor_iters + 1;
        let mid = 1 + h / 2;
        let state: &[Vec<f32>; 2] = fl;
        let run = |(r0, r1): (usize, usize)| {
            let (a, b) = (r0.saturating_sub(ghost).max(1), (r1 + ghost).min(h + 1));
            let mut bufs = [
                state[0][a * s2..b * s2].to_vec(),
                state[1][a * s2..b * s2].to_vec(),
            ];
            let row = |c: usize, r: usize| state[c][r * s2..][..s2].to_vec();
            let halo = [[row(0, a - 1), row(0, b)], [row(1, a - 1), row(1, b)]];
            {
                let [b0, b1] = &mut bufs;
                let band = Band {
                    r0: a,
                    rows: [b0, b1],
                    halo,
                };
                sor_band(cx, co, band);
            }
            let keep = |v: &Vec<f32>| v[(r0 - a) * s2..(r1 - a) * s2].to_vec();
            (r0, r1, [keep(&bufs[0]), keep(&bufs[1])])
        };
        let (top, bottom) = rayon::join(|| run((1, mid)), || run((mid, h + 1)));
        for (r0, r1, rows) in [top, bottom] {
            for (c, r) in rows.iter().enumerate() {
                fl[c][r0 * s2..r1 * s2].copy_from_slice(r);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::variational::{NS, Packing, VariationalOptions};

    /// Plain red–black SOR, row by row, for comparison with the wavefront.
    fn sor_reference(cx: &Ctx, co: &[Vec<f32>; 2], fl: &mut [Vec<f32>; 2]) {
        let s2 = 2 * cx.p.s;
        for _ in 0..cx.o.sor_iters {
            for c in 0..2 {
                let [f0, f1] = &mut *fl;
                let (mine, other) = if c == 0 { (f0, &*f1) } else { (f1, &*f0) };
                for py in 1..=cx.p.h {
                    let nb = [
                        &other[(py - 1) * s2..][..s2],
                        &other[py * s2..][..s2],
                        &other[(py + 1) * s2..][..s2],
                    ];
                    sor_row(cx, co, c, py, &mut mine[py * s2..][..s2], nb);
                }
            }
        }
    }

    /// The wavefront schedule reproduces plain red–black SOR bit for bit,
    /// in one band and in two bands with ghost zones.
    #[test]
    fn wavefront_sor_equals_red_black_sor() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg32::seed_from_u64(5);
        let (w, h) = (37, 61);
        let p = Packing::new(w, h);
        let o = VariationalOptions::default();
        let masks = p.masks();
        let st = [
            vec![0.0f32; (h + 2) * NS * p.s],
            vec![0.0f32; (h + 2) * NS * p.s],
        ];
        let n = (h + 2) * p.s;
        let mut rand_vec = |len: usize, lo: f32, hi: f32| -> Vec<f32> {
            (0..len)
                .map(|_| lo + (hi - lo) * rng.random::<f32>())
                .collect()
        };
        let mut co = [rand_vec(NC * n, 0.0, 0.2), rand_vec(NC * n, 0.0, 0.2)];
        // Pad rows and cells hold zeros, as in `refine`.
        for c in &mut co {
            c[..NC * p.s].fill(0.0);
            c[(h + 1) * NC * p.s..].fill(0.0);
        }
        let mut fl0 = [rand_vec(2 * n, -1.0, 1.0), rand_vec(2 * n, -1.0, 1.0)];
        for f in &mut fl0 {
            f[..2 * p.s].fill(0.0);
            f[(h + 1) * 2 * p.s..].fill(0.0);
        }
        let mut cx = Ctx {
            p,
            o: &o,
            st: &st,
            masks: &masks,
            par: false,
        };
        let mut a = fl0.clone();
        sor_reference(&cx, &co, &mut a);
        let mut b = fl0.clone();
        sor(&cx, &co, &mut b);
        assert_eq!(a, b);
        cx.par = true;
        let mut c = fl0.clone();
        sor(&cx, &co, &mut c);
        assert_eq!(a, c);
    }
}
