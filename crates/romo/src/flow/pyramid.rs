//! Image pyramids and flow resampling for [`super::dis`], written for speed:
//! the 2×2 box reduction is fused with the intensity scaling (so the full
//! resolution level is never materialised when DIS starts at level 1, as
//! OpenCV's MEDIUM preset does), and bilinear flow resizing interpolates
//! rows first (contiguous, vectorised) and then columns through a
//! precomputed table. Both keep the conventions of [`crate::plane::Plane`]
//! (pixel-centre alignment, clamped borders, odd edges replicated). Small
//! images run on the calling thread (below [`PAR_MIN_PIXELS`]).

use super::Flow;
use super::simd::multiversion;
use crate::plane::Plane;
use rayon::prelude::*;

/// Images with fewer pixels are processed single-threaded: rayon's
/// fork–join costs more than the work there.
pub const PAR_MIN_PIXELS: usize = 20_000;

/// Run `f(row_index, row)` over the `chunk`-sized rows of `data`, in
/// parallel when `par`.
pub fn rows_mut<F>(par: bool, data: &mut [f32], chunk: usize, f: F)
where
    F: Fn(usize, &mut [f32]) + Sync + Send,
{
    if par {
        data.par_chunks_mut(chunk)
            .enumerate()
            .for_each(|(i, r)| f(i, r));
    } else {
        data.chunks_mut(chunk)
            .enumerate()
            .for_each(|(i, r)| f(i, r));
    }
}

/// As [`rows_mut`] over two arrays with the same row count.
pub fn rows2_mut<F>(par: bool, a: &mut [f32], ca: usize, b: &mut [f32], cb: usize, f: F)
where
    F: Fn(usize, &mut [f32], &mut [f32]) + Sync + Send,
{
    if par {
        a.par_chunks_mut(ca)
            .zip(b.par_chunks_mut(cb))
            .enumerate()
            .for_each(|(i, (x, y))| f(i, x, y));
    } else {
        a.chunks_mut(ca)
            .zip(b.chunks_mut(cb))
            .enumerate()
            .for_each(|(i, (x, y))| f(i, x, y));
    }
}

multiversion! {
    /// `scale` × the 2×2 box mean of `src` (size rounded up; an odd last
    /// column or row is replicated, as [`Plane::half`]).
    pub fn half(src: &Plane, scale: f32) -> Plane {
        let (w, h) = (src.w, src.h);
        let (nw, nh) = (w.div_ceil(2).max(1), h.div_ceil(2).max(1));
        let mut out = vec![0.0f32; nw * nh];
        let k = 0.25 * scale;
        rows_mut(nw * nh >= PAR_MIN_PIXELS, &mut out, nw, |y, row| {
            let r0 = &src.data[(2 * y).min(h - 1) * w..][..w];
            let r1 = &src.data[(2 * y + 1).min(h - 1) * w..][..w];
            let pairs = w / 2;
            for (x, o) in row[..pairs].iter_mut().enumerate() {
                *o = k * (r0[2 * x] + r0[2 * x + 1] + r1[2 * x] + r1[2 * x + 1]);
            }
            if pairs < nw {
                row[pairs] = k * 2.0 * (r0[w - 1] + r1[w - 1]);
            }
        });
        Plane {
            w: nw,
            h: nh,
            data: out,
        }
    }
}

multiversion! {
    /// `scale` × `src` (a copy when `scale` is 1).
    pub fn scaled(src: &Plane, scale: f32) -> Plane {
        let mut out = src.clone();
        rows_mut(
            src.w * src.h >= PAR_MIN_PIXELS,
            &mut out.data,
            src.w.max(1),
            |_, r| r.iter_mut().for_each(|v| *v *= scale),
        );
        out
    }
}

/// Source index pair and weight of each output coordinate when resampling
/// `n` pixels to `m` (pixel-centre aligned, clamped).
fn taps(n: usize, m: usize) -> Vec<(usize, usize, f32)> {
    let r = n as f32 / m as f32;
    (0..m)
        .map(|x| {
            let f = ((x as f32 + 0.5) * r - 0.5).clamp(0.0, (n - 1) as f32);
            let i = f as usize;
            (i, (i + 1).min(n - 1), f - i as f32)
        })
        .collect()
}

multiversion! {
    /// Bilinear resize of a flow to `nw`×`nh`, vectors scaled by the size
    /// ratio. For enlarging or shrinking by at most 2× (more is delegated to
    /// [`Flow::resize`], which box-averages first).
    pub fn resize_flow(f: &Flow, nw: usize, nh: usize) -> Flow {
        let (w, h) = (f.w(), f.h());
        if (nw, nh) == (w, h) {
            return f.clone();
        }
        if 2 * nw < w || 2 * nh < h {
            return f.resize(nw, nh);
        }
        let (sx, sy) = (nw as f32 / w as f32, nh as f32 / h as f32);
        let (cols, rows) = (taps(w, nw), taps(h, nh));
        let mut out = Flow::zeros(nw, nh);
        let body = |y: usize, ru: &mut [f32], rv: &mut [f32]| {
            let (y0, y1, ay) = rows[y];
            // Rows first (contiguous, vectorised), then columns via the table.
            let mut tu = vec![0.0f32; w];
            let mut tv = vec![0.0f32; w];
            for (src, dst, s) in [(&f.u, &mut tu, sx), (&f.v, &mut tv, sy)] {
                let (a, b) = (&src.data[y0 * w..][..w], &src.data[y1 * w..][..w]);
                for ((d, p), q) in dst.iter_mut().zip(a).zip(b) {
                    *d = s * (p + ay * (q - p));
                }
            }
            for (x, &(x0, x1, ax)) in cols.iter().enumerate() {
                ru[x] = tu[x0] + ax * (tu[x1] - tu[x0]);
                rv[x] = tv[x0] + ax * (tv[x1] - tv[x0]);
            }
        };
        rows2_mut(
            nw * nh >= PAR_MIN_PIXELS,
            &mut out.u.data,
            nw,
            &mut out.v.data,
            nw,
            body,
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> Plane {
        Plane::from_fn(w, h, |x, y| {
            (x * 7 + y * 13 % 5) as f32 * 0.01 + (x * y) as f32 * 1e-3
        })
    }

    #[test]
    fn half_matches_plane_half() {
        for (w, h) in [(9, 7), (8, 6), (1, 3), (64, 65)] {
            let p = ramp(w, h);
            let a = half(&p, 255.0);
            let b = p.half().map(|v| v * 255.0);
            assert_eq!((a.w, a.h), (b.w, b.h));
            for (x, y) in a.data.iter().zip(&b.data) {
                assert!((x - y).abs() < 1e-4 * y.abs().max(1.0), "{x} vs {y}");
            }
        }
    }

    #[test]
    fn resize_flow_matches_flow_resize() {
        for (w, h, nw, nh) in [
            (8, 6, 16, 12),
            (9, 7, 17, 13),
            (50, 40, 31, 27),
            (5, 5, 5, 9),
        ] {
            let f = Flow {
                u: ramp(w, h),
                v: ramp(h, w).resize(w, h).map(|v| -v),
            };
            let a = resize_flow(&f, nw, nh);
            let b = f.resize(nw, nh);
            for (x, y) in a.u.data.iter().zip(&b.u.data) {
                assert!((x - y).abs() < 1e-5, "{x} vs {y}");
            }
            for (x, y) in a.v.data.iter().zip(&b.v.data) {
                assert!((x - y).abs() < 1e-5, "{x} vs {y}");
            }
        }
    }
}
