//! Stage 9 of RoMo: from the MLP's low-resolution probability `H` to a
//! full-resolution mask. `H` is upsampled bilinearly, then filtered with the
//! guided filter (He, Sun, Tang, "Guided Image Filtering", ECCV 2010 / TPAMI
//! 2013) using the frame's luma as guide, so mask edges snap to image edges;
//! optionally smoothed over neighbouring frames first; thresholded at 0.5.
//! The filter's coefficients are computed at a subsampled resolution (He &
//! Sun's fast guided filter) so refinement costs little at 854×480.

use crate::plane::Plane;
use serde::{Deserialize, Serialize};

/// Refinement options.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct RefineOptions {
    /// Guided-filter window radius in full-resolution px (default 8).
    pub radius: usize,
    /// Guided-filter regulariser ε (guide in [0, 1]; default 1e-3).
    pub eps: f32,
    /// Fast guided filter (He & Sun 2015, arXiv:1505.00996): the filter's
    /// linear coefficients are computed on the guide subsampled by this
    /// factor and upsampled bilinearly, then applied at full resolution
    /// (default 4, as in that paper; 1 = the exact filter).
    pub subsample: usize,
    /// Probability above which a pixel is moving (paper: 0.5).
    pub threshold: f32,
    /// Static veto (ours): grid pixels whose last-round residual is below
    /// `static_veto_factor`·v (geometrically static with high confidence,
    /// like L with its own factor) get moving probability 0 before
    /// upsampling; 0 disables (the paper thresholds H alone). The MLP, with
    /// 8 units on hand-made features, paints whole regions that are
    /// geometrically static (sky, crowd) as moving. Default: see README.
    pub static_veto_factor: f32,
    /// Weight of each neighbouring frame's probability in the temporal
    /// smoothing `(1 − 2w)·H_t + w·(H_{t−1} + H_{t+1})` (ours; default 0.25,
    /// 0 = off; DAVIS mean J +0.002 along the flow, see README).
    pub temporal_weight: f32,
    /// Temporal smoothing follows the optical flow (ours; the issue's
    /// optional item): the neighbours' probabilities are sampled where each
    /// pixel's forward / backward flow lands, only where that flow passed
    /// the cycle check (elsewhere the frame's own value stands in). False =
    /// the same pixel in the neighbouring frames (default true).
    pub temporal_along_flow: bool,
    /// Passes of the temporal smoothing (each widens its support by one
    /// frame per side; default 1).
    pub temporal_passes: usize,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            radius: 8,
            eps: 1e-3,
            subsample: 4,
            static_veto_factor: 0.02,
            threshold: 0.5,
            temporal_weight: 0.25,
            temporal_along_flow: true,
            temporal_passes: 1,
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
        Ok(())
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
    Plane {
        w: i.w,
        h: i.h,
        data: ma
            .data
            .iter()
            .zip(&mb.data)
            .zip(&i.data)
            .map(|((a, b), g)| a * g + b)
            .collect(),
    }
}

/// Window means of the guided filter's linear coefficients (ā, b̄).
fn guided_coefficients(i: &Plane, p: &Plane, r: usize, eps: f32) -> (Plane, Plane) {
    let mi = i.box_mean(r);
    let mp = p.box_mean(r);
    let cip = i.zip(p, |a, b| a * b).box_mean(r);
    let ii = i.map(|a| a * a).box_mean(r);
    let var = ii.zip(&mi, |s, m| s - m * m);
    let cov = Plane {
        w: i.w,
        h: i.h,
        data: cip
            .data
            .iter()
            .zip(&mi.data)
            .zip(&mp.data)
            .map(|((c, a), b)| c - a * b)
            .collect(),
    };
    let a = cov.zip(&var, |c, v| c / (v + eps));
    let b = Plane {
        w: i.w,
        h: i.h,
        data: mp
            .data
            .iter()
            .zip(&a.data)
            .zip(&mi.data)
            .map(|((p, a), m)| p - a * m)
            .collect(),
    };
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
/// the frame's luma `guide` (values in [0, 1]).
pub fn upsample_probability(prob: &Plane, guide: &Plane, o: &RefineOptions) -> Plane {
    let up = prob.resize(guide.w, guide.h);
    if o.radius == 0 {
        return up;
    }
    fast_guided_filter(guide, &up, o.radius, o.eps, o.subsample).map(|v| v.clamp(0.0, 1.0))
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
    #![allow(clippy::unwrap_used, clippy::expect_used)]
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
