//! Least Median of Squares (Rousseeuw 1984) over minimal samples, for F
//! (7-point) and H (4-point), seeded; then a least-squares refit on the
//! LMedS inliers (residual < `inlier_sigmas`·σ̂ with the robust
//! σ̂ = 1.4826·(1 + 5/(n − p))·√median). Model selection between F and H by
//! Torr's GRIC (Geometric Robust Information Criterion, Torr 1998) or by
//! inlier ratio — the paper's named limitation (low parallax) handled as our
//! addition.
//!
//! Residuals inside LMedS are squared (px²: Sampson² for F, transfer² for
//! H); everything reported is in px.

use super::Pt;
use super::fundamental::{eight_point, sampson_sq, seven_point};
use super::homography::{dlt, transfer_sq};
use crate::flow::simd::multiversion;
use nalgebra::Matrix3;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// How a pair's geometric model is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum ModelSelection {
    /// Always the fundamental matrix (the paper).
    Fundamental,
    /// GRIC: homography when GRIC(H) < GRIC(F). Its capped penalty lets H
    /// treat up to ~35% of the points as outliers, so it picks H for pairs
    /// with real parallax (DAVIS goat: the near rocks then look moving).
    Gric,
    /// Homography when its inlier count reaches `h_inlier_ratio` × F's
    /// (default): H only where it explains nearly everything F does.
    /// DAVIS 8 sequences (with L < 0.15·v), mean J 0.623 / 0.627 (two
    /// runs) against 0.558 / 0.563 with GRIC (goat 0.04 → 0.51); the
    /// pure-rotation scene keeps H for 22 of 23 pairs (test
    /// `pure_rotation_video_is_scored_with_homographies`).
    InlierRatio,
    /// Always the homography (diagnosis; a scene without parallax).
    Homography,
}

/// Options of the robust estimation.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(default)]
pub struct RobustOptions {
    /// LMedS samples drawn per model (default 500: 99% confidence of an
    /// outlier-free 7-sample at 50% outliers needs 588; 500 is near).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub iterations: usize,
    /// Inlier threshold in robust standard deviations (default 2.5).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub inlier_sigmas: f64,
    /// Lower bound of σ̂ in px, so near-perfect data keep a sane threshold
    /// (default 0.25 px).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub min_sigma_px: f64,
    /// Model selection rule (default inlier ratio).
    #[cfg_attr(
        feature = "cli",
        arg(long = "model-selection", value_enum, required = false)
    )]
    pub selection: ModelSelection,
    /// For `InlierRatio`: H is chosen when inliers(H) ≥ this × inliers(F)
    /// (default 0.9).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub h_inlier_ratio: f64,
    /// RNG seed (default 0).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub seed: u64,
}

impl Default for RobustOptions {
    fn default() -> Self {
        Self {
            iterations: 500,
            inlier_sigmas: 2.5,
            min_sigma_px: 0.25,
            selection: ModelSelection::InlierRatio,
            h_inlier_ratio: 0.9,
            seed: 0,
        }
    }
}

impl RobustOptions {
    /// Check the options.
    pub fn validate(&self) -> crate::Result<()> {
        if self.iterations == 0 || self.inlier_sigmas <= 0.0 || self.min_sigma_px < 0.0 {
            return Err(crate::RomoError::Options(
                "robust: iterations > 0, inlier_sigmas > 0, min_sigma_px >= 0 required".into(),
            ));
        }
        if !(self.h_inlier_ratio > 0.0 && self.h_inlier_ratio <= 1.0) {
            return Err(crate::RomoError::Options(format!(
                "robust: h_inlier_ratio must be in (0, 1], got {}",
                self.h_inlier_ratio
            )));
        }
        Ok(())
    }
}

/// A two-view model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TwoView {
    /// Fundamental matrix, scored by Sampson distance.
    Fundamental(Matrix3<f64>),
    /// Homography, scored by transfer error.
    Homography(Matrix3<f64>),
}

impl TwoView {
    /// Squared residual in px².
    #[inline]
    pub fn residual_sq(&self, a: Pt, b: Pt) -> f64 {
        match self {
            TwoView::Fundamental(f) => sampson_sq(f, a, b),
            TwoView::Homography(h) => transfer_sq(h, a, b),
        }
    }

    /// Residual in px.
    #[inline]
    pub fn residual_px(&self, a: Pt, b: Pt) -> f64 {
        self.residual_sq(a, b).sqrt()
    }
}

/// How a fit went.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FitReport {
    /// "F" or "H".
    pub model: String,
    /// Correspondences the model was fitted on.
    pub points: usize,
    /// Inliers of the chosen model among them.
    pub inliers: usize,
    /// LMedS samples drawn (for the chosen model).
    pub iterations: usize,
    /// Median residual of the chosen model over the fit points (px).
    pub median_residual_px: f64,
    /// Robust σ̂ (px).
    pub sigma_px: f64,
    /// GRIC of F and H (NaN when not computed).
    pub gric_f: f64,
    /// GRIC of H.
    pub gric_h: f64,
    /// Fraction of the fit points the fundamental matrix calls moving
    /// (`S_F > u·v`; filled by [`crate::labels::fit_pair`], NaN otherwise).
    #[serde(default)]
    pub u_fraction_f: f64,
    /// Fraction of the voting fit points in front of both cameras under
    /// the pair's decomposed F (the cheirality test; NaN when undecided or
    /// off).
    #[serde(default)]
    pub cheirality_support: f64,
}

impl FitReport {
    /// The report of a pair that was skipped (model "", no points).
    pub fn skipped() -> Self {
        FitReport {
            model: String::new(),
            points: 0,
            inliers: 0,
            iterations: 0,
            median_residual_px: f64::NAN,
            sigma_px: f64::NAN,
            gric_f: f64::NAN,
            gric_h: f64::NAN,
            u_fraction_f: f64::NAN,
            cheirality_support: f64::NAN,
        }
    }
}

#[derive(Clone)]
struct Fit {
    model: TwoView,
    median_sq: f64,
    sigma: f64,
    inliers: usize,
}

/// Median of `v` (reorders it); infinite when empty.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::INFINITY;
    }
    let k = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *m
}

/// Correspondences split into coordinate arrays, so the residual kernels
/// run over contiguous lanes.
struct Soa {
    ax: Vec<f64>,
    ay: Vec<f64>,
    bx: Vec<f64>,
    by: Vec<f64>,
}

impl Soa {
    fn new(a: &[Pt], b: &[Pt]) -> Self {
        Self {
            ax: a.iter().map(|p| p[0]).collect(),
            ay: a.iter().map(|p| p[1]).collect(),
            bx: b.iter().map(|p| p[0]).collect(),
            by: b.iter().map(|p| p[1]).collect(),
        }
    }

    fn len(&self) -> usize {
        self.ax.len()
    }

    /// Correspondence `i` as (point in the first image, in the second).
    fn pair(&self, i: usize) -> (Pt, Pt) {
        ([self.ax[i], self.ay[i]], [self.bx[i], self.by[i]])
    }

    /// Squared residuals (px²) of `m` for points `lo..lo + out.len()`.
    fn residuals_into(&self, m: &TwoView, lo: usize, out: &mut [f64]) {
        let hi = lo + out.len();
        let (ax, ay) = (&self.ax[lo..hi], &self.ay[lo..hi]);
        let (bx, by) = (&self.bx[lo..hi], &self.by[lo..hi]);
        match m {
            TwoView::Fundamental(f) => sampson_block(&row_major(f), ax, ay, bx, by, out),
            TwoView::Homography(h) => transfer_block(&row_major(h), ax, ay, bx, by, out),
        }
    }

    fn residuals(&self, m: &TwoView) -> Vec<f64> {
        let mut r = vec![0.0; self.len()];
        self.residuals_into(m, 0, &mut r);
        r
    }
}

fn row_major(m: &Matrix3<f64>) -> [f64; 9] {
    std::array::from_fn(|k| m[(k / 3, k % 3)])
}

multiversion! {
    /// [`sampson_sq`] of F (row-major `f`) for each point, with the same
    /// operations in the same order (bit-identical; tested).
    fn sampson_block(f: &[f64; 9], ax: &[f64], ay: &[f64], bx: &[f64], by: &[f64], out: &mut [f64]) {
        let pts = ax.iter().zip(ay).zip(bx.iter().zip(by));
        for (r, ((&x, &y), (&u, &v))) in out.iter_mut().zip(pts) {
            let fa = [
                f[0] * x + f[1] * y + f[2],
                f[3] * x + f[4] * y + f[5],
                f[6] * x + f[7] * y + f[8],
            ];
            let ftb = [f[0] * u + f[3] * v + f[6], f[1] * u + f[4] * v + f[7]];
            let num = u * fa[0] + v * fa[1] + fa[2];
            let den = fa[0] * fa[0] + fa[1] * fa[1] + ftb[0] * ftb[0] + ftb[1] * ftb[1];
            *r = if den <= 1e-300 {
                f64::INFINITY
            } else {
                num * num / den
            };
        }
    }
}

multiversion! {
    /// [`transfer_sq`] of H (row-major `h`) for each point, with the same
    /// operations in the same order (bit-identical; tested).
    fn transfer_block(h: &[f64; 9], ax: &[f64], ay: &[f64], bx: &[f64], by: &[f64], out: &mut [f64]) {
        let pts = ax.iter().zip(ay).zip(bx.iter().zip(by));
        for (r, ((&x, &y), (&u, &v))) in out.iter_mut().zip(pts) {
            let p0 = h[0] * x + h[1] * y + h[2];
            let p1 = h[3] * x + h[4] * y + h[5];
            let p2 = h[6] * x + h[7] * y + h[8];
            let (dx, dy) = (p0 / p2 - u, p1 / p2 - v);
            *r = if p2.abs() < 1e-12 {
                f64::INFINITY
            } else {
                dx * dx + dy * dy
            };
        }
    }
}

/// Points per block of [`residuals_may_beat`] between its early-exit checks.
const BLOCK: usize = 64;

/// Fills `buf` with the residuals of `m` unless its median cannot be below
/// `best` (false then; `buf` is left partly filled). The median is the
/// `n/2`-th smallest residual in `f64::total_cmp` order, so it lies below
/// `best` only when at least `n/2 + 1` residuals do: the fill stops, at the
/// end of a block of points, once more than `n − n/2 − 1` residuals are not
/// below it.
fn residuals_may_beat(m: &TwoView, pts: &Soa, buf: &mut [f64], best: Option<f64>) -> bool {
    let Some(best) = best else {
        pts.residuals_into(m, 0, buf);
        return true;
    };
    let allowed = buf.len() - (buf.len() / 2 + 1);
    let mut not_below = 0;
    for (k, block) in buf.chunks_mut(BLOCK).enumerate() {
        pts.residuals_into(m, k * BLOCK, block);
        not_below += block
            .iter()
            .filter(|r| r.total_cmp(&best) != std::cmp::Ordering::Less)
            .count();
        if not_below > allowed {
            return false;
        }
    }
    true
}

/// LMedS for one model kind, then a least-squares refit on the inliers.
fn lmeds(pts: &Soa, homography: bool, o: &RobustOptions, seed: u64) -> Option<Fit> {
    let s = if homography { 4 } else { 7 };
    let n = pts.len();
    if n < s + 1 {
        return None;
    }
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut best: Option<(TwoView, f64)> = None;
    let mut idx = [0usize; 7];
    let mut buf = vec![0.0f64; n];
    for _ in 0..o.iterations {
        let mut k = 0;
        while k < s {
            let c = rng.random_range(0..n);
            if !idx[..k].contains(&c) {
                idx[k] = c;
                k += 1;
            }
        }
        let (sa, sb): (Vec<Pt>, Vec<Pt>) = idx[..s].iter().map(|&i| pts.pair(i)).unzip();
        let models: Vec<TwoView> = if homography {
            dlt(&sa, &sb).map(TwoView::Homography).into_iter().collect()
        } else {
            seven_point(&sa, &sb)
                .into_iter()
                .map(TwoView::Fundamental)
                .collect()
        };
        for m in models {
            if !residuals_may_beat(&m, pts, &mut buf, best.as_ref().map(|(_, bm)| *bm)) {
                continue;
            }
            let med = median(&mut buf);
            if med.is_finite() && best.as_ref().is_none_or(|(_, bm)| med < *bm) {
                best = Some((m, med));
            }
        }
    }
    let (mut model, mut med) = best?;
    let sigma_of =
        |med: f64| (1.4826 * (1.0 + 5.0 / (n - s) as f64) * med.sqrt()).max(o.min_sigma_px);
    // Least-squares refit on the inliers; kept when it does not worsen the
    // median.
    let thr = (o.inlier_sigmas * sigma_of(med)).powi(2);
    let r = pts.residuals(&model);
    let (ia, ib): (Vec<Pt>, Vec<Pt>) = r
        .iter()
        .enumerate()
        .filter(|(_, r)| **r < thr)
        .map(|(i, _)| pts.pair(i))
        .unzip();
    let refit = if homography {
        dlt(&ia, &ib).map(TwoView::Homography)
    } else {
        eight_point(&ia, &ib).map(TwoView::Fundamental)
    };
    // The chosen model's residuals (in any order: only counted below).
    let mut chosen = r;
    if let Some(m2) = refit {
        let mut r2 = pts.residuals(&m2);
        let med2 = median(&mut r2);
        if med2 <= med {
            model = m2;
            med = med2;
            chosen = r2;
        }
    }
    let sigma = sigma_of(med);
    let thr = (o.inlier_sigmas * sigma).powi(2);
    let inliers = chosen.iter().filter(|r| **r < thr).count();
    Some(Fit {
        model,
        median_sq: med,
        sigma,
        inliers,
    })
}

/// Torr's GRIC for residuals `r2` (px²) with noise σ (px), model dimension
/// `d` (F: 3, H: 2) and `k` parameters (F: 7, H: 8); data dimension r = 4.
pub fn gric(r2: &[f64], sigma: f64, d: f64, k: f64) -> f64 {
    let n = r2.len() as f64;
    let (r, l3) = (4.0, 2.0);
    let rho: f64 = r2
        .iter()
        .map(|e| (e / (sigma * sigma)).min(l3 * (r - d)))
        .sum();
    rho + r.ln() * d * n + (r * n).ln() * k
}

/// Both fits of a pair: the chosen model and the fundamental matrix (which
/// is always estimated; [`crate::labels::fit_pair`] uses it to overrule a
/// homography choice when F is informative).
#[derive(Debug, Clone)]
pub struct TwoViewFits {
    /// The model chosen by the selection rule.
    pub chosen: TwoView,
    /// Its report.
    pub report: FitReport,
    /// The fundamental matrix.
    pub fundamental: TwoView,
    /// Its report (GRIC fields as in `report`).
    pub fundamental_report: FitReport,
}

fn report_of(fit: &Fit, n: usize, o: &RobustOptions, gf: f64, gh: f64) -> FitReport {
    FitReport {
        model: match fit.model {
            TwoView::Fundamental(_) => "F".into(),
            TwoView::Homography(_) => "H".into(),
        },
        points: n,
        inliers: fit.inliers,
        iterations: o.iterations,
        median_residual_px: fit.median_sq.sqrt(),
        sigma_px: fit.sigma,
        gric_f: gf,
        gric_h: gh,
        u_fraction_f: f64::NAN,
        cheirality_support: f64::NAN,
    }
}

/// Fit F (and H, per the selection rule) robustly to correspondences
/// `a[i] ↔ b[i]` and choose the model. Errors when there are too few points.
pub fn fit_two_view(a: &[Pt], b: &[Pt], o: &RobustOptions) -> crate::Result<(TwoView, FitReport)> {
    let f = fit_two_view_all(a, b, o)?;
    Ok((f.chosen, f.report))
}

/// As [`fit_two_view`], also returning the fundamental matrix's fit.
pub fn fit_two_view_all(a: &[Pt], b: &[Pt], o: &RobustOptions) -> crate::Result<TwoViewFits> {
    o.validate()?;
    if a.len() != b.len() || a.len() < 15 {
        return Err(crate::RomoError::Geometry(format!(
            "need at least 15 correspondences, got {}",
            a.len().min(b.len())
        )));
    }
    let pts = Soa::new(a, b);
    let f = lmeds(&pts, false, o, o.seed)
        .ok_or_else(|| crate::RomoError::Geometry("fundamental matrix: degenerate".into()))?;
    let h = match o.selection {
        ModelSelection::Fundamental => None,
        _ => lmeds(&pts, true, o, o.seed ^ 0x9e37_79b9),
    };
    let (mut gf, mut gh) = (f64::NAN, f64::NAN);
    let use_h = match (&h, o.selection) {
        (Some(h), ModelSelection::Gric) => {
            let sigma = f.sigma;
            gf = gric(&pts.residuals(&f.model), sigma, 3.0, 7.0);
            gh = gric(&pts.residuals(&h.model), sigma, 2.0, 8.0);
            gh < gf
        }
        (Some(h), ModelSelection::InlierRatio) => {
            let thr = (o.inlier_sigmas * f.sigma).powi(2);
            let hin = pts.residuals(&h.model).iter().filter(|r| **r < thr).count();
            hin as f64 >= o.h_inlier_ratio * f.inliers as f64
        }
        (Some(_), ModelSelection::Homography) => true,
        _ => false,
    };
    let chosen = match (use_h, h) {
        (true, Some(h)) => h,
        _ => f.clone(),
    };
    Ok(TwoViewFits {
        chosen: chosen.model,
        report: report_of(&chosen, a.len(), o, gf, gh),
        fundamental: f.model,
        fundamental_report: report_of(&f, a.len(), o, gf, gh),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use rand::Rng;

    /// The block kernels give exactly the scalar residuals, on both
    /// instruction-set paths, including the degenerate (infinite) ones.
    #[test]
    fn block_residuals_equal_the_scalar_ones_bit_for_bit() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let mut pt = || {
            [
                rng.random_range(-50.0..900.0),
                rng.random_range(-50.0..500.0),
            ]
        };
        let n = 1000;
        let a: Vec<Pt> = (0..n).map(|_| pt()).collect();
        let b: Vec<Pt> = (0..n).map(|_| pt()).collect();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(8);
        let mut models = Vec::new();
        for _ in 0..20 {
            let m = Matrix3::from_fn(|_, _| rng.random_range(-1.0..1.0));
            models.push(TwoView::Fundamental(m));
            models.push(TwoView::Homography(m));
        }
        // Degenerate: a zero F and an H mapping every point to infinity.
        models.push(TwoView::Fundamental(Matrix3::zeros()));
        models.push(TwoView::Homography(Matrix3::new(
            1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0,
        )));
        let pts = Soa::new(&a, &b);
        for baseline in [false, true] {
            crate::flow::simd::force_baseline(baseline);
            for m in &models {
                let block = pts.residuals(m);
                for (i, r) in block.iter().enumerate() {
                    assert_eq!(
                        r.to_bits(),
                        m.residual_sq(a[i], b[i]).to_bits(),
                        "{m:?} point {i}"
                    );
                }
            }
        }
        crate::flow::simd::force_baseline(false);
    }
}
