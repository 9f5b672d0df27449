//! Stage 9 of RoMo: from the MLP's low-resolution probability `H` to a
//! full-resolution mask. `H` is upsampled bilinearly, then filtered with the
//! guided filter (He, Sun, Tang, "Guided Image Filtering", ECCV 2010 / TPAMI
//! 2013) using the frame's colour (or luma) as guide, so mask edges snap to
//! image edges; optionally smoothed over neighbouring frames first;
//! thresholded at 0.5.
//! The filter's coefficients are computed at a subsampled resolution (He &
//! Sun's fast guided filter) so refinement costs little at 854×480.

use crate::plane::{Plane, Rgb};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Refinement options.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(default)]
pub struct RefineOptions {
    /// Guided-filter window radius in full-resolution px (default 8).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub radius: usize,
    /// Guided-filter regulariser ε (guide in [0, 1]; default 1e-3).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub eps: f32,
    /// Fast guided filter (He & Sun 2015, arXiv:1505.00996): the filter's
    /// linear coefficients are computed on the guide subsampled by this
    /// factor and upsampled bilinearly, then applied at full resolution
    /// (default 4, as in that paper; 1 = the exact filter).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub subsample: usize,
    /// Guide the filter with the frame's colour (He et al.'s colour guided
    /// filter: per window a 3 × 3 covariance, so an edge between two
    /// colours of equal luma still guides) instead of its luma (default
    /// true: demo scene J, seeds 0 / 1 / 2, luma 0.838 / 0.813 / 0.820,
    /// colour 0.858 / 0.834 / 0.841; DAVIS luma 0.648 / 0.653 / 0.673,
    /// colour 0.650 / 0.657 / 0.676).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub colour_guide: bool,
    /// Probability above which a pixel is moving (paper: 0.5).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub threshold: f32,
    /// Static veto (ours): grid pixels whose last-round residual is below
    /// `static_veto_factor`·v (geometrically static with high confidence,
    /// like L with its own factor) get moving probability 0 before
    /// upsampling; 0 disables (the paper thresholds H alone). The MLP, with
    /// 8 units on hand-made features, paints whole regions that are
    /// geometrically static (sky, crowd) as moving. Default 0.02.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub static_veto_factor: f32,
    /// Weight of each neighbouring frame's probability in the temporal
    /// smoothing `(1 − 2w)·H_t + w·(H_{t−1} + H_{t+1})` (ours; default 0.25,
    /// 0 = off; DAVIS mean J +0.002 along the flow).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub temporal_weight: f32,
    /// Temporal smoothing follows the optical flow (ours): the neighbours' probabilities are sampled where each
    /// pixel's forward / backward flow lands, only where that flow passed
    /// the cycle check (elsewhere the frame's own value stands in). False =
    /// the same pixel in the neighbouring frames (default true).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub temporal_along_flow: bool,
    /// Passes of the temporal smoothing (each widens its support by one
    /// frame per side; default 1).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub temporal_passes: usize,
    /// Object-level refinement on the grid after the per-pixel steps
    /// (ours; [`crate::objects`]).
    #[cfg_attr(feature = "cli", command(flatten))]
    pub objects: crate::objects::ObjectOptions,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            radius: 8,
            eps: 1e-3,
            subsample: 4,
            colour_guide: true,
            static_veto_factor: 0.02,
            threshold: 0.5,
            temporal_weight: 0.25,
            temporal_along_flow: true,
            temporal_passes: 1,
            objects: Default::default(),
        }
    }
}

impl RefineOptions {
    /// Check the options.
    pub fn validate(&self) -> crate::Result<()> {
        if !(0.0..=0.5).contains(&self.temporal_weight)
            || self.eps <= 0.0
            || !(0.0..1.0).contains(&self.threshold)
            || self.subsample == 0
            || self.static_veto_factor < 0.0
        {
            return Err(crate::RomoError::Options(
                "refine: temporal_weight in [0, 0.5], eps > 0, threshold in (0, 1), subsample >= 1, static_veto_factor >= 0 required"
                .into(),
            ));
        }
        self.objects.validate()
    }
}

/// Guided filter of `p` with guide `i` (same size), window radius `r`.
pub fn guided_filter(i: &Plane, p: &Plane, r: usize, eps: f32) -> Plane {
    let (ma, mb) = guided_coefficients(i, p, r, eps);
    apply_coefficients(&ma, &mb, i)
}

/// `q = a·I + b` with window-averaged coefficients `a`, `b` (same size as
/// the guide `i`).
fn apply_coefficients(ma: &Plane, mb: &Plane, i: &Plane) -> Plane {
    ma.zip3(mb, i, |a, b, g| a * g + b)
}

/// Window means of the guided filter's linear coefficients (ā, b̄).
fn guided_coefficients(i: &Plane, p: &Plane, r: usize, eps: f32) -> (Plane, Plane) {
    let mi = i.box_mean(r);
    let mp = p.box_mean(r);
    let cip = i.zip(p, |a, b| a * b).box_mean(r);
    let ii = i.map(|a| a * a).box_mean(r);
    let var = ii.zip(&mi, |s, m| s - m * m);
    let cov = cip.zip3(&mi, &mp, |c, a, b| c - a * b);
    let a = cov.zip(&var, |c, v| c / (v + eps));
    let b = mp.zip3(&a, &mi, |p, a, m| p - a * m);
    (a.box_mean(r), b.box_mean(r))
}

/// Fast guided filter (He & Sun 2015): coefficients on `i` and `p`
/// subsampled by `s` (radius `r / s`), upsampled, applied to the full `i`.
pub fn fast_guided_filter(i: &Plane, p: &Plane, r: usize, eps: f32, s: usize) -> Plane {
    if s <= 1 {
        return guided_filter(i, p, r, eps);
    }
    let (w, h) = (i.w.div_ceil(s).max(1), i.h.div_ceil(s).max(1));
    let (ma, mb) = guided_coefficients(&i.resize(w, h), &p.resize(w, h), (r / s).max(1), eps);
    apply_coefficients(&ma.resize(i.w, i.h), &mb.resize(i.w, i.h), i)
}

/// Window means of the colour guided filter's coefficients (ā per
/// channel, b̄): per window `a = (Σ + εI)⁻¹ cov(I, p)`, `b = p̄ − a·Ī`,
/// with Σ the 3 × 3 covariance of the guide's channels (He et al. 2013,
/// eq. 14–15).
fn guided_coefficients_rgb(i: &Rgb, p: &Plane, r: usize, eps: f32) -> ([Plane; 3], Plane) {
    let m: [Plane; 3] = std::array::from_fn(|k| i.c[k].box_mean(r));
    let mp = p.box_mean(r);
    let cov_p: [Plane; 3] = std::array::from_fn(|k| {
        i.c[k]
            .zip(p, |a, b| a * b)
            .box_mean(r)
            .zip(&m[k].zip(&mp, |a, b| a * b), |c, ab| c - ab)
    });
    // Covariances of channel pairs (0,0) (0,1) (0,2) (1,1) (1,2) (2,2).
    let pairs = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
    let var: Vec<Plane> = pairs
        .iter()
        .map(|&(k, l)| {
            i.c[k]
                .zip(&i.c[l], |a, b| a * b)
                .box_mean(r)
                .zip(&m[k].zip(&m[l], |a, b| a * b), |c, ab| c - ab)
        })
        .collect();
    let n = p.data.len();
    let mut a: [Vec<f32>; 3] = std::array::from_fn(|_| vec![0.0; n]);
    let mut b = vec![0.0; n];
    for x in 0..n {
        let e = eps as f64;
        let s00 = var[0].data[x] as f64 + e;
        let s01 = var[1].data[x] as f64;
        let s02 = var[2].data[x] as f64;
        let s11 = var[3].data[x] as f64 + e;
        let s12 = var[4].data[x] as f64;
        let s22 = var[5].data[x] as f64 + e;
        // Inverse of the symmetric positive-definite Σ + εI by cofactors.
        let c00 = s11 * s22 - s12 * s12;
        let c01 = s02 * s12 - s01 * s22;
        let c02 = s01 * s12 - s02 * s11;
        let c11 = s00 * s22 - s02 * s02;
        let c12 = s01 * s02 - s00 * s12;
        let c22 = s00 * s11 - s01 * s01;
        let det = s00 * c00 + s01 * c01 + s02 * c02;
        let q = [
            cov_p[0].data[x] as f64,
            cov_p[1].data[x] as f64,
            cov_p[2].data[x] as f64,
        ];
        let ak = [
            (c00 * q[0] + c01 * q[1] + c02 * q[2]) / det,
            (c01 * q[0] + c11 * q[1] + c12 * q[2]) / det,
            (c02 * q[0] + c12 * q[1] + c22 * q[2]) / det,
        ];
        let mut bx = mp.data[x] as f64;
        for k in 0..3 {
            a[k][x] = ak[k] as f32;
            bx -= ak[k] * m[k].data[x] as f64;
        }
        b[x] = bx as f32;
    }
    let plane = |data: Vec<f32>| Plane {
        w: p.w,
        h: p.h,
        data,
    };
    let [a0, a1, a2] = a;
    (
        [
            plane(a0).box_mean(r),
            plane(a1).box_mean(r),
            plane(a2).box_mean(r),
        ],
        plane(b).box_mean(r),
    )
}

/// `q = Σ_k ā_k·I_k + b̄` at the guide's resolution.
fn apply_coefficients_rgb(a: &[Plane; 3], b: &Plane, i: &Rgb) -> Plane {
    Plane::from_fn(i.w(), i.h(), |x, y| {
        let j = y * i.w() + x;
        a[0].data[j] * i.c[0].data[j]
            + a[1].data[j] * i.c[1].data[j]
            + a[2].data[j] * i.c[2].data[j]
            + b.data[j]
    })
}

/// Guided filter of `p` with the colour guide `i` (same size), window
/// radius `r`.
pub fn guided_filter_rgb(i: &Rgb, p: &Plane, r: usize, eps: f32) -> Plane {
    let (a, b) = guided_coefficients_rgb(i, p, r, eps);
    apply_coefficients_rgb(&a, &b, i)
}

/// [`fast_guided_filter`] with a colour guide.
pub fn fast_guided_filter_rgb(i: &Rgb, p: &Plane, r: usize, eps: f32, s: usize) -> Plane {
    if s <= 1 {
        return guided_filter_rgb(i, p, r, eps);
    }
    let (w, h) = (i.w().div_ceil(s).max(1), i.h().div_ceil(s).max(1));
    let (a, b) = guided_coefficients_rgb(&i.resize(w, h), &p.resize(w, h), (r / s).max(1), eps);
    // The coefficients upsampled as `Plane::resize` does (pixel-centre
    // aligned bilinear, separably: each coarse row once across, then each
    // output row down) and applied to the full-resolution guide row by row.
    let (fw, fh) = (i.w(), i.h());
    let cols = crate::plane::resize_taps(fw, w);
    let rows = crate::plane::resize_taps(fh, h);
    let across =
        [&a[0], &a[1], &a[2], &b].map(|q| crate::plane::resample_rows(&q.data, w, &cols, &rows));
    let mut data = vec![0.0; fw * fh];
    data.par_chunks_mut(fw.max(1))
        .zip(&rows)
        .enumerate()
        .for_each_init(
            || vec![0.0f32; 4 * fw],
            |co, (y, (out, &tap))| {
                for (k, c) in co.chunks_mut(fw.max(1)).enumerate() {
                    crate::plane::lerp_rows(&across[k], fw, tap, c);
                }
                let (a0, rest) = co.split_at(fw);
                let (a1, rest) = rest.split_at(fw);
                let (a2, bb) = rest.split_at(fw);
                let px = |k: usize| &i.c[k].data[y * fw..(y + 1) * fw];
                let (i0, i1, i2) = (px(0), px(1), px(2));
                for x in 0..fw {
                    out[x] = a0[x] * i0[x] + a1[x] * i1[x] + a2[x] * i2[x] + bb[x];
                }
            },
        );
    Plane { w: fw, h: fh, data }
}

/// Temporal smoothing of a sequence of probability maps (same size).
pub fn temporal_smooth(probs: &[Plane], w: f32) -> Vec<Plane> {
    if w <= 0.0 || probs.len() < 2 {
        return probs.to_vec();
    }
    (0..probs.len())
        .map(|t| {
            let prev = &probs[t.saturating_sub(1)];
            let next = &probs[(t + 1).min(probs.len() - 1)];
            Plane {
                w: probs[t].w,
                h: probs[t].h,
                data: (0..probs[t].data.len())
                    .map(|i| (1.0 - 2.0 * w) * probs[t].data[i] + w * (prev.data[i] + next.data[i]))
                    .collect(),
            }
        })
        .collect()
}

/// Temporal smoothing along the flow: `(1 − 2w)·H_t + w·(H_{t−1}(x + b_t(x))
/// + H_{t+1}(x + f_t(x)))`, where `f_t` (frame t → t+1, `fwd[t]`) and `b_t`
/// (t → t−1, `bwd[t−1]`) are the pair flows on the probability grid and a
/// neighbour whose flow failed the cycle check (`valid_*` false) is replaced
/// by `H_t`. `passes` repeats it.
pub fn temporal_smooth_flow(
    probs: &[Plane],
    fwd: &[crate::flow::Flow],
    bwd: &[crate::flow::Flow],
    valid_f: &[Vec<bool>],
    valid_b: &[Vec<bool>],
    w: f32,
    passes: usize,
) -> Vec<Plane> {
    use rayon::prelude::*;
    let n = probs.len();
    if w <= 0.0 || n < 2 || fwd.len() + 1 != n || bwd.len() + 1 != n {
        return probs.to_vec();
    }
    let mut cur = probs.to_vec();
    for _ in 0..passes {
        cur = (0..n)
            .into_par_iter()
            .map(|t| {
                let p = &cur[t];
                let data = (0..p.data.len())
                    .map(|i| {
                        let (x, y) = ((i % p.w) as f32, (i / p.w) as f32);
                        let own = p.data[i];
                        let prev = if t > 0 && valid_b[t - 1][i] {
                            let f = &bwd[t - 1];
                            cur[t - 1].bilinear(x + f.u.data[i], y + f.v.data[i])
                        } else {
                            own
                        };
                        let next = if t + 1 < n && valid_f[t][i] {
                            let f = &fwd[t];
                            cur[t + 1].bilinear(x + f.u.data[i], y + f.v.data[i])
                        } else {
                            own
                        };
                        (1.0 - 2.0 * w) * own + w * (prev + next)
                    })
                    .collect();
                Plane {
                    w: p.w,
                    h: p.h,
                    data,
                }
            })
            .collect();
    }
    cur
}

/// Full-resolution moving probability from a low-resolution one, guided by
/// the frame (RGB in [0, 1]): its luma, or its colour with
/// `colour_guide`.
pub fn upsample_probability(prob: &Plane, frame: &Rgb, o: &RefineOptions) -> Plane {
    let up = prob.resize(frame.w(), frame.h());
    if o.radius == 0 {
        return up;
    }
    let mut q = if o.colour_guide {
        fast_guided_filter_rgb(frame, &up, o.radius, o.eps, o.subsample)
    } else {
        fast_guided_filter(&frame.gray(), &up, o.radius, o.eps, o.subsample)
    };
    q.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    q
}

/// The COLMAP-convention mask: 255 where static (keep), 0 where moving.
pub fn to_keep_mask(prob: &Plane, threshold: f32) -> image::GrayImage {
    let data = prob
        .data
        .iter()
        .map(|p| if *p > threshold { 0u8 } else { 255u8 })
        .collect();
    image::GrayImage::from_raw(prob.w as u32, prob.h as u32, data)
        .unwrap_or_else(|| image::GrayImage::new(prob.w as u32, prob.h as u32))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guided_filter_snaps_a_blurry_mask_to_the_guide_edge() {
        // Guide: a sharp vertical edge at x = 20; input: a blurred step at
        // x = 17 (misaligned). Output should cross 0.5 close to x = 20.
        let g = Plane::from_fn(40, 20, |x, _| if x >= 20 { 1.0 } else { 0.0 });
        let p = Plane::from_fn(40, 20, |x, _| {
            1.0 / (1.0 + (-(x as f32 - 17.0) / 2.0).exp())
        });
        let q = guided_filter(&g, &p, 4, 1e-3);
        let row: Vec<f32> = (0..40).map(|x| q.at(x, 10)).collect();
        assert!(row[15] < 0.35 && row[24] > 0.9, "{row:?}");
        // Constant input stays constant.
        let c = guided_filter(&g, &Plane::filled(40, 20, 0.3), 4, 1e-3);
        assert!(c.data.iter().all(|v| (v - 0.3).abs() < 1e-4));
    }

    /// Two colours of equal luma meet at x = 20: the luma guide is flat
    /// there and cannot move a misaligned mask edge, the colour guide snaps
    /// it to the colour edge (exact and fast filters alike).
    #[test]
    fn colour_guide_snaps_to_an_edge_the_luma_cannot_see() {
        let left = [0.8f32, 0.2, 0.5];
        let luma = 0.299 * left[0] + 0.587 * left[1] + 0.114 * left[2];
        let right = [0.1f32, 0.6, (luma - 0.299 * 0.1 - 0.587 * 0.6) / 0.114];
        let g = Rgb {
            c: std::array::from_fn(|k| {
                Plane::from_fn(40, 20, |x, _| if x >= 20 { right[k] } else { left[k] })
            }),
        };
        let gray = g.gray();
        assert!(gray.data.iter().all(|v| (v - luma).abs() < 1e-5));
        let p = Plane::from_fn(40, 20, |x, _| {
            1.0 / (1.0 + (-(x as f32 - 17.0) / 2.0).exp())
        });
        let snapped = |q: &Plane| {
            let row: Vec<f32> = (0..40).map(|x| q.at(x, 10)).collect();
            row[15] < 0.35 && row[18] < 0.5 && row[24] > 0.9
        };
        let colour = guided_filter_rgb(&g, &p, 4, 1e-3);
        assert!(snapped(&colour), "{:?}", &colour.data[400..440]);
        assert!(!snapped(&guided_filter(&gray, &p, 4, 1e-3)));
        // The fast filter at s = 1 is the exact one; at s = 2 it still snaps.
        assert_eq!(fast_guided_filter_rgb(&g, &p, 4, 1e-3, 1), colour);
        assert!(snapped(&fast_guided_filter_rgb(&g, &p, 4, 1e-3, 2)));
        // A constant input stays constant.
        let c = guided_filter_rgb(&g, &Plane::filled(40, 20, 0.3), 4, 1e-3);
        assert!(c.data.iter().all(|v| (v - 0.3).abs() < 1e-4));
    }

    /// The separable application of the coarse colour coefficients gives
    /// the bits of sampling them per pixel with bilinear taps.
    #[test]
    fn colour_coefficients_applied_separably_equal_per_pixel_taps() {
        use crate::plane::{Taps, resize_taps};
        let (fw, fh, r, eps, s) = (37, 29, 8, 1e-3, 4);
        let img = Rgb {
            c: std::array::from_fn(|k| {
                Plane::from_fn(fw, fh, |x, y| ((x * (3 + k) + y * 7) % 13) as f32 / 13.0)
            }),
        };
        let p = Plane::from_fn(fw, fh, |x, y| if (x + 2 * y) % 9 < 4 { 0.9 } else { 0.1 });
        let got = fast_guided_filter_rgb(&img, &p, r, eps, s);
        let (w, h) = (fw.div_ceil(s), fh.div_ceil(s));
        let (a, b) = guided_coefficients_rgb(&img.resize(w, h), &p.resize(w, h), r / s, eps);
        let (cols, rows) = (resize_taps(fw, w), resize_taps(fh, h));
        for (y, &row) in rows.iter().enumerate() {
            for (x, &col) in cols.iter().enumerate() {
                let t = Taps::new(col, row, w);
                let j = y * fw + x;
                let want = t.sample(&a[0].data) * img.c[0].data[j]
                    + t.sample(&a[1].data) * img.c[1].data[j]
                    + t.sample(&a[2].data) * img.c[2].data[j]
                    + t.sample(&b.data);
                assert_eq!(got.data[j].to_bits(), want.to_bits(), "({x}, {y})");
            }
        }
    }

    #[test]
    fn fast_guided_filter_approximates_the_exact_one() {
        // A textured guide and a blurry probability: the subsampled filter
        // stays within 0.1 of the exact one at every pixel away from the
        // border and agrees on the thresholded mask almost everywhere.
        let g = Plane::from_fn(96, 64, |x, y| {
            let base = if x >= 48 { 0.8 } else { 0.2 };
            base + 0.05 * ((x as f32 * 0.7).sin() * (y as f32 * 0.3).cos())
        });
        let p = Plane::from_fn(96, 64, |x, _| {
            1.0 / (1.0 + (-(x as f32 - 45.0) / 4.0).exp())
        });
        let exact = guided_filter(&g, &p, 8, 1e-3);
        let fast = fast_guided_filter(&g, &p, 8, 1e-3, 4);
        let mut disagree = 0;
        for y in 8..56 {
            for x in 8..88 {
                let (a, b) = (exact.at(x, y), fast.at(x, y));
                assert!((a - b).abs() < 0.1, "{x},{y}: {a} vs {b}");
                disagree += ((a > 0.5) != (b > 0.5)) as usize;
            }
        }
        assert!(disagree < 48, "{disagree}");
        // s = 1 is the exact filter.
        assert_eq!(fast_guided_filter(&g, &p, 8, 1e-3, 1), exact);
    }

    #[test]
    fn smoothing_along_the_flow_keeps_a_moving_square_sharp() {
        // A square moving 3 px right per frame: along the flow the
        // neighbours agree, so the interior stays 1 and the outside 0;
        // smoothing at fixed pixels blurs its leading and trailing edges.
        use crate::flow::Flow;
        let (w, h, n) = (40, 20, 4);
        let sq = |t: usize| {
            Plane::from_fn(w, h, move |x, y| {
                let x0 = 5 + 3 * t;
                ((x0..x0 + 8).contains(&x) && (6..14).contains(&y)) as u8 as f32
            })
        };
        let probs: Vec<Plane> = (0..n).map(sq).collect();
        let fwd = vec![
            Flow {
                u: Plane::filled(w, h, 3.0),
                v: Plane::filled(w, h, 0.0)
            };
            n - 1
        ];
        let bwd = vec![
            Flow {
                u: Plane::filled(w, h, -3.0),
                v: Plane::filled(w, h, 0.0)
            };
            n - 1
        ];
        let valid = vec![vec![true; w * h]; n - 1];
        let s = temporal_smooth_flow(&probs, &fwd, &bwd, &valid, &valid, 0.25, 2);
        for t in 1..n - 1 {
            for i in 0..w * h {
                assert!((s[t].data[i] - probs[t].data[i]).abs() < 1e-5, "{t} {i}");
            }
        }
        let fixed = temporal_smooth(&probs, 0.25);
        assert!((fixed[1].at(8, 10) - 0.75).abs() < 1e-5); // trailing edge blurred
        // Invalid flow: the frame's own value stands in (no change at all).
        let none = vec![vec![false; w * h]; n - 1];
        let s = temporal_smooth_flow(&probs, &fwd, &bwd, &none, &none, 0.25, 1);
        assert_eq!(s, probs);
    }

    #[test]
    fn keep_mask_convention() {
        let p = Plane::from_fn(3, 1, |x, _| x as f32 * 0.4);
        let m = to_keep_mask(&p, 0.5);
        assert_eq!(m.as_raw(), &vec![255, 255, 0]);
        let s = temporal_smooth(&[Plane::filled(1, 1, 0.0), Plane::filled(1, 1, 1.0)], 0.25);
        assert!((s[0].data[0] - 0.25).abs() < 1e-6 && (s[1].data[0] - 0.75).abs() < 1e-6);
    }
}
