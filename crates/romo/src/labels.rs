//! Stages 2–4 of RoMo: forward–backward cycle check, robust two-view model
//! per adjacent pair, Sampson residuals, and the sparse labels
//!
//! `U_t = max(S_fwd, S_bwd) > u_factor·v` (likely moving),
//! `L_t = max(S_fwd, S_bwd) < l_factor·v` (likely static),
//!
//! with `v` the frame's mean flow magnitude. **Units:** `S` is the Sampson
//! distance in px (√ of the squared Sampson error, or the homography
//! transfer error in px for low-parallax pairs) and `v` is in px, both at
//! the working grid; the comparison is unit-consistent and invariant to the
//! working resolution. (With px², `S > 2v` compares px² to px and its
//! meaning changes with image scale.)
//!
//! With `cheirality` on (ours), S of a pair scored by F is
//! `max(Sampson, cheirality violation)` (see [`crate::geometry::oriented`]):
//! motion along the epipolar line that only a point behind the cameras
//! could make counts as motion too.

use crate::flow::Flow;
use crate::geometry::Pt;
use crate::geometry::fundamental::sampson_px;
use crate::geometry::oriented::{Oriented, VoteOptions, intrinsics};
use crate::geometry::robust::{
    FitReport, ModelSelection, RobustOptions, TwoView, fit_two_view_all,
};
use crate::plane::Plane;
use nalgebra::Matrix3;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Options of the labelling stages.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(default)]
pub struct LabelOptions {
    /// Cycle check (Sundaram et al. 2010): a correspondence survives when
    /// `|f + b|² < cycle_rel·(|f|² + |b|²) + cycle_abs_px²` (default 0.01).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub cycle_rel: f32,
    /// Absolute part of the cycle threshold in grid px (default 0.5 px).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub cycle_abs_px: f32,
    /// U threshold factor on v (default 1.0; the paper's 2 assumes px²).
    /// With S in px, 2·v left U empty on DAVIS (0.0% coverage, mean J
    /// 0.17 on blackswan + car-roundabout); 1.0 gave U ≈ 7–15% and the best
    /// J of {1.0, 1.5, 2.0} on four DAVIS sequences.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub u_factor: f32,
    /// L threshold factor on v (default 0.1; the paper's 0.01 assumes
    /// px²: with px it keeps ~0.5% of pixels). Measured on DAVIS (8
    /// sequences × 40 frames, mean J, moving_weight 1, no veto): 0.05 →
    /// 0.345, 0.15 → 0.368, 0.3 → 0.374; L stays ≥ 99% static and covers
    /// 60–95% of the background at 0.15. On the demo scene (pedestrians
    /// moving along epipolar lines) 0.3 puts L on them (J 0.23 vs 0.61),
    /// so not 0.3. With inlier-ratio selection and the cheirality and
    /// three-view tests: DAVIS
    /// mean J 0.15 → 0.629, 0.12 → 0.638, 0.1 → 0.639, 0.08 → 0.595 (parkour
    /// 0.82 → 0.56), 0.05 → 0.569; demo scene (seeds 0 / 1 / 2) 0.15 →
    /// 0.767 mean, 0.12 → 0.773, 0.1 → 0.784, 0.08 → 0.785; small test scene
    /// 0.590 → 0.718 at 0.1. Hence 0.1.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub l_factor: f32,
    /// Frames whose inlier ratio is below this are not used to train the
    /// MLP (paper: 0.5). Inlier: residual below `inlier_sigmas`·σ̂ of the
    /// pair's robust fit.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub min_inlier_ratio: f32,
    /// Correspondences (spread on a grid) used to fit each pair's model; the
    /// residuals are then evaluated on all (default 2000).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub fit_points: usize,
    /// F-informative override (ours) of the F-vs-H selection: when the
    /// selection rule picks the homography but the fundamental matrix still
    /// calls at least this fraction of the fit points moving (`S_F > u·v`),
    /// F is used. Rationale: when F absorbs an object (a panning camera
    /// following it: car-roundabout, scooter-black) it calls almost nothing
    /// moving (< 0.5% of points); when it does separate something, that is
    /// the object at higher precision than H's residual, and H's extra U
    /// is static parallax (parkour, breakdance). 0 disables (default
    /// 0.005).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub f_informative_fraction: f32,
    /// U propagation along the flow (ours): U is spread this many frames
    /// forward and backward along cycle-consistent flow (a pixel becomes U
    /// when its correspondent in the neighbouring frame is U) and removed
    /// from L there. Objects whose motion is visible to the epipolar test
    /// only in some frames (the demo's pedestrians walking along epipolar
    /// lines) then keep U, and lose the wrong L, in the frames between.
    /// 0 disables (default 0: the graph cut's temporal edges carry
    /// objects between frames).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub u_propagation_frames: usize,
    /// Cheirality test (ours): in pairs scored by F, a correspondence whose
    /// triangulation lies behind either camera is scored by its parallax
    /// when that exceeds its Sampson distance (see
    /// [`crate::geometry::oriented`]; needs a focal length, from the scene
    /// or guessed). Default true; `--no-cheirality` turns it off.
    #[cfg_attr(feature = "cli", arg(long = "no-cheirality", action = clap::ArgAction::SetFalse, help = "Turn off the cheirality test (flow along the epipolar line that only a point behind the cameras could make counts as motion)"))]
    pub cheirality: bool,
    /// Three-view depth consistency (ours; see [`three_view_residuals`]):
    /// in frames whose two pairs both have a decided metric geometry (F
    /// pairs with the cheirality test on), an unlabelled pixel whose
    /// forward and backward depths disagree by more than
    /// `three_view_u_px` becomes U, and an L pixel whose depths disagree by
    /// more than `three_view_l_px` leaves L. Default true; `--no-three-view`
    /// turns it off.
    #[cfg_attr(feature = "cli", arg(long = "no-three-view", action = clap::ArgAction::SetFalse, help = "Turn off the three-view depth-consistency test (a pixel whose depths from its forward and backward pairs disagree is moving)"))]
    pub three_view: bool,
    /// U threshold of the three-view residual, working-grid px (default
    /// 0.5).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub three_view_u_px: f32,
    /// L-removal threshold of the three-view residual, working-grid px
    /// (default 1.0).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub three_view_l_px: f32,
    /// Local U threshold (ours): a pixel is U when `S > u·min(v, max(m,
    /// local_u_floor·v))`, `m` its own flow magnitude (mean over its valid
    /// sides), instead of `S > u·v`. Flow noise grows with a pixel's own
    /// motion, not with the frame's mean: when the camera follows an object
    /// (it stays still in the image while the background streams past) the
    /// object's residual is about the background's flow, i.e. about v, and
    /// `S > u·v` splits it at random. 0 = off (the paper's global rule;
    /// default): 0.5 / 0.25 give DAVIS seed 0 J 0.686 / 0.648 against
    /// 0.712, U spreading onto goat's slow near rocks (`docs/results.md`).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub local_u_floor: f32,
    /// U needs texture (ours): a pixel whose grey gradient on the working
    /// grid (central differences, intensity in [0, 1] per grid px) is below
    /// this cannot be U. Its flow is an interpolation from its
    /// surroundings (DIS's propagation, the variational smoothness), so its
    /// residual is no evidence of its own motion: in a textureless sky next
    /// to a moving edge it is large. 0 = off.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub u_min_gradient: f32,
    /// Majority filter on U (ours; see [`u_majority`]): a pixel that is U
    /// by its residual (`S > u·v`) stays U only when more than half of the
    /// `(2r + 1)²` grid pixels around it are U, `r` this radius (default
    /// 4; 0 = off). U from tests that do not raise `S` (three-view) is
    /// kept as it is. DAVIS mean J, seeds 0–4: 0.719–0.720 → 0.703–0.739
    /// (mean of 0–2 0.725; blackswan 0.287 → 0.413); 45 composite and
    /// scene runs 0.845 → 0.849 (`docs/results.md`). Filtering the
    /// three-view U as well (DAVIS seed 0: 0.751) loses the pedestrian of
    /// `scenes/follow.toml` (0.777 → 0.277), whose U is only three-view.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub u_majority_radius: usize,
    /// A frame with fewer than this fraction of textured pixels (gradient
    /// above [`crate::pipeline::TEXTURE_GRADIENT`]) is not used in any pair:
    /// its flow is meaningless (default 0.01).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub min_texture_fraction: f32,
    /// A pair whose forward or backward flow is cycle-consistent and
    /// photo-consistent (grey levels within
    /// [`crate::pipeline::PHOTO_TOLERANCE`]) on less than this fraction of
    /// pixels is skipped (default 0.05).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub min_valid_fraction: f32,
    /// Occlusion order (ours; see [`occlusion_violations`]): in pairs with
    /// a decided metric geometry, a pixel that covers, in the next frame,
    /// a pixel with more parallax than its own cannot be static (a static
    /// occluder is nearer than what it hides) and becomes U. This sees an
    /// object the camera follows: its near-zero flow fits the two-view
    /// geometry as a point at infinity, but it hides background of finite
    /// depth. Default false: DAVIS 8 sequences mean J 0.693 → 0.697 (goat
    /// 0.558 → 0.576), fox + DAVIS composite 0.624 → 0.594; `--occlusion`
    /// turns it on.
    #[cfg_attr(
        feature = "cli",
        arg(
            long,
            help = "Occlusion-order test: a pixel that hides, in the next frame, a pixel with more parallax than its own is moving (an object the camera follows; off by default)"
        )
    )]
    pub occlusion: bool,
    /// U threshold of the occlusion-order test as a factor on v: the
    /// hidden pixel's parallax must exceed the occluder's by this × v
    /// (and by `three_view_u_px`) (default 0.5).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub occlusion_factor: f32,
    /// A pair whose robust σ̂ exceeds this × the video's median σ̂ (itself
    /// at least the σ̂ floor `robust.min_sigma_px`) is not used, as one that
    /// could not be fitted (ours; default 2, 0 = off; see
    /// [`drop_unreliable_fits`]).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub max_sigma_ratio: f64,
    /// Robust estimation and model selection.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub robust: RobustOptions,
}

impl Default for LabelOptions {
    fn default() -> Self {
        Self {
            cycle_rel: 0.01,
            cycle_abs_px: 0.5,
            u_factor: 1.0,
            l_factor: 0.1,
            min_inlier_ratio: 0.5,
            fit_points: 2000,
            f_informative_fraction: 0.005,
            u_propagation_frames: 0,
            cheirality: true,
            three_view: true,
            three_view_u_px: 0.5,
            three_view_l_px: 1.0,
            local_u_floor: 0.0,
            u_min_gradient: 0.02,
            u_majority_radius: 4,
            min_texture_fraction: 0.01,
            min_valid_fraction: 0.05,
            occlusion: false,
            occlusion_factor: 0.5,
            max_sigma_ratio: 2.0,
            robust: RobustOptions::default(),
        }
    }
}

impl LabelOptions {
    /// Check the options.
    pub fn validate(&self) -> crate::Result<()> {
        if self.u_factor <= self.l_factor
            || self.l_factor < 0.0
            || self.fit_points < 15
            || !(0.0..=1.0).contains(&self.f_informative_fraction)
            || !(self.three_view_u_px > 0.0 && self.three_view_l_px > 0.0)
            || !(0.0..=1.0).contains(&self.local_u_floor)
            || self.u_min_gradient.is_nan()
            || self.u_min_gradient < 0.0
            || !(0.0..1.0).contains(&self.min_texture_fraction)
            || !(0.0..1.0).contains(&self.min_valid_fraction)
            || !(self.occlusion_factor.is_finite() && self.occlusion_factor >= 0.0)
            || !(self.max_sigma_ratio == 0.0 || self.max_sigma_ratio >= 1.0)
        {
            return Err(crate::RomoError::Options(
                "labels: need u_factor > l_factor >= 0, fit_points >= 15, f_informative_fraction in [0, 1], three_view_u_px and three_view_l_px > 0, min_texture_fraction and min_valid_fraction in [0, 1), u_min_gradient >= 0, occlusion_factor >= 0, max_sigma_ratio 0 or >= 1".into(),
            ));
        }
        self.robust.validate()
    }
}

/// Forward–backward consistency of `f` (a → b) with `b` (b → a): one flag
/// per pixel of frame a.
pub fn cycle_valid(f: &Flow, b: &Flow, o: &LabelOptions) -> Vec<bool> {
    let (w, h) = (f.w(), f.h());
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let (u, v) = (f.u.data[i], f.v.data[i]);
            let (x2, y2) = (x + u, y + v);
            if x2 < 0.0 || y2 < 0.0 || x2 > (w - 1) as f32 || y2 > (h - 1) as f32 {
                return false;
            }
            let (bu, bv) = b.sample(x2, y2);
            let (du, dv) = (u + bu, v + bv);
            du * du + dv * dv
                < o.cycle_rel * (u * u + v * v + bu * bu + bv * bv)
                    + o.cycle_abs_px * o.cycle_abs_px
        })
        .collect()
}

/// Correspondences `x ↔ x + f(x)` at pixels where `usable`, spread over a
/// grid (`fit_points` cells, one random pixel each, seeded).
pub fn fit_points(f: &Flow, usable: &[bool], o: &LabelOptions, seed: u64) -> (Vec<Pt>, Vec<Pt>) {
    let (w, h) = (f.w(), f.h());
    let cell = ((w * h) as f64 / o.fit_points as f64).sqrt().max(1.0) as usize;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let (mut a, mut b): (Vec<Pt>, Vec<Pt>) = (vec![], vec![]);
    for cy in (0..h).step_by(cell) {
        for cx in (0..w).step_by(cell) {
            let (cw, ch) = (cell.min(w - cx), cell.min(h - cy));
            for _ in 0..4 {
                let x = cx + rng.random_range(0..cw);
                let y = cy + rng.random_range(0..ch);
                let i = y * w + x;
                if usable[i] {
                    a.push([x as f64, y as f64]);
                    b.push([
                        (x as f32 + f.u.data[i]) as f64,
                        (y as f32 + f.v.data[i]) as f64,
                    ]);
                    break;
                }
            }
        }
    }
    (a, b)
}

/// A pair's fitted model, its report and (for F with `cheirality` on) its
/// metric geometry.
#[derive(Debug, Clone)]
pub struct PairFit {
    pub model: TwoView,
    pub report: FitReport,
    /// The decomposed F for the cheirality test, when decided.
    pub oriented: Option<Oriented>,
}

/// Why a pair has no model.
#[derive(Debug, Clone, PartialEq)]
pub enum NoFit {
    /// No texture, too few consistent correspondences, or no model could
    /// be fitted: the pair carries no evidence at all.
    Failed(String),
    /// A model was fitted but [`drop_unreliable_fits`] does not trust it:
    /// its frames still have appearance for the MLP to label.
    Unreliable(String),
}

impl std::fmt::Display for NoFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NoFit::Failed(r) | NoFit::Unreliable(r) => f.write_str(r),
        }
    }
}

/// A pair's fit, or why it has none.
pub type PairResult = std::result::Result<PairFit, NoFit>;

/// Pairs whose fit is unreliable become [`NoFit::Unreliable`].
/// LMedS assumes the model explains at least half of the points; its σ̂ is
/// then the flow's noise, about the same in every pair of a video (on the
/// built-in scenes and the 8 DAVIS sequences every pair sits at the
/// 0.25 px floor). When moving objects cover more than half of a frame
/// the median lands on a compromise between the background and the movers:
/// σ̂ rises several-fold, the model absorbs the movers (they become L) and
/// calls background moving (U), and these inverted labels can make the MLP
/// collapse for the whole video (fox + DAVIS composite with five objects
/// per frame, 29–63% of each frame moving: J 0.03 / 0.57 / 0.02 for seeds
/// 0–2 without this, 0.02 / 0.63 / 0.72 with it). A pair whose
/// σ̂ exceeds `ratio` × max(the median σ̂ of the fitted pairs, `floor`) is
/// therefore left out like one that could not be fitted (its frames are
/// labelled from their other neighbour), except that a frame between two
/// such pairs is still predicted by the MLP rather than kept whole.
/// `ratio` 0 disables.
pub fn drop_unreliable_fits(fits: &mut [PairResult], ratio: f64, floor: f64) {
    if ratio <= 0.0 {
        return;
    }
    let mut sigmas: Vec<f64> = fits
        .iter()
        .filter_map(|f| f.as_ref().ok())
        .map(|f| f.report.sigma_px)
        .filter(|s| s.is_finite())
        .collect();
    if sigmas.is_empty() {
        return;
    }
    let typical = crate::geometry::robust::median(&mut sigmas).max(floor);
    let limit = ratio * typical;
    for f in fits.iter_mut() {
        if let Ok(p) = f
            // A NaN σ̂ is not trusted either.
            && (p.report.sigma_px > limit || p.report.sigma_px.is_nan())
        {
            *f = Err(NoFit::Unreliable(format!(
                "unreliable fit: robust sigma {:.2} px is over {ratio}x the video's {typical:.2} px \
                 (moving objects over half of the frame?)",
                p.report.sigma_px
            )));
        }
    }
}

/// Fit one pair's model on the [`fit_points`] of `f` where `usable`.
/// `focal_px` is the focal length at the flow's grid (principal point at
/// the grid centre), for the cheirality test; None skips it.
pub fn fit_pair(
    f: &Flow,
    usable: &[bool],
    o: &LabelOptions,
    seed: u64,
    focal_px: Option<f64>,
) -> crate::Result<PairFit> {
    let (a, b) = fit_points(f, usable, o, seed);
    let fits = fit_two_view_all(&a, &b, &o.robust)?;
    let v = f.mean_magnitude() as f64;
    let oriented = match (focal_px, &fits.fundamental) {
        (Some(fp), TwoView::Fundamental(fm)) if o.cheirality => {
            orient(fm, fp, (f.w(), f.h()), &a, &b, o, v)
        }
        _ => None,
    };
    // Moving according to F: Sampson, and the cheirality violation.
    let residual_f = |p: Pt, q: Pt| {
        let r = fits.fundamental.residual_px(p, q);
        oriented.map_or(r, |or| r.max(or.violation_px(p, q)))
    };
    let thr = o.u_factor as f64 * v;
    let nu = a
        .iter()
        .zip(&b)
        .filter(|(p, q)| residual_f(**p, **q) > thr)
        .count();
    let frac = nu as f64 / a.len().max(1) as f64;
    let overrule = o.f_informative_fraction > 0.0
        && matches!(fits.chosen, TwoView::Homography(_))
        && matches!(
            o.robust.selection,
            ModelSelection::Gric | ModelSelection::InlierRatio
        )
        && frac >= o.f_informative_fraction as f64;
    let (model, mut report) = if overrule {
        (fits.fundamental, fits.fundamental_report)
    } else {
        (fits.chosen, fits.report)
    };
    report.u_fraction_f = frac;
    let oriented = oriented.filter(|_| matches!(model, TwoView::Fundamental(_)));
    report.cheirality_support = oriented.map_or(f64::NAN, |o| o.support);
    Ok(PairFit {
        model,
        report,
        oriented,
    })
}

/// Decompose `F` with focal `focal_px` for the cheirality test, decided by
/// the votes of the fit points whose Sampson distance is below
/// max(l, u/2)·v (those F does not call moving). None when the votes do
/// not decide (little translation).
fn orient(
    fm: &Matrix3<f64>,
    focal_px: f64,
    (w, h): (usize, usize),
    a: &[Pt],
    b: &[Pt],
    o: &LabelOptions,
    v: f64,
) -> Option<Oriented> {
    if !(focal_px.is_finite() && focal_px > 0.0) {
        return None;
    }
    let k = intrinsics(focal_px, 0.5 * (w as f64 - 1.0), 0.5 * (h as f64 - 1.0));
    let thr = o.l_factor.max(0.5 * o.u_factor) as f64 * v;
    let (a, b): (Vec<Pt>, Vec<Pt>) = a
        .iter()
        .zip(b)
        .filter(|(p, q)| sampson_px(fm, **p, **q) < thr)
        .map(|(p, q)| (*p, *q))
        .unzip();
    Oriented::from_fundamental(fm, &k, &a, &b, &VoteOptions::default())
}

/// One side (forward or backward) of a frame's evidence.
pub struct Side<'a> {
    /// Flow from this frame to the neighbour.
    pub flow: &'a Flow,
    /// Cycle-consistent pixels of this frame.
    pub valid: &'a [bool],
    /// The pair's model.
    pub model: TwoView,
    /// Its fit report.
    pub report: &'a FitReport,
    /// True when this frame is the pair's second frame (backward side).
    pub second: bool,
    /// The pair's metric geometry for the cheirality test, if decided.
    pub oriented: Option<&'a Oriented>,
}

/// Labels of one frame.
#[derive(Debug, Clone)]
pub struct FrameLabels {
    /// max(S_fwd, S_bwd) in px per pixel, NaN where no side is valid.
    pub s: Vec<f32>,
    /// Likely moving.
    pub u: Vec<bool>,
    /// Likely static.
    pub l: Vec<bool>,
    /// Mean flow magnitude (px).
    pub v: f32,
    /// Fraction of pixels with a valid residual that are inliers.
    pub inlier_ratio: f32,
    /// Fraction of all pixels in U.
    pub u_coverage: f32,
    /// Fraction of all pixels in L.
    pub l_coverage: f32,
    /// Fraction of pixels with a valid residual.
    pub valid_ratio: f32,
}

impl FrameLabels {
    /// Count `u_coverage` and `l_coverage` again after U or L changed.
    pub fn recount_coverage(&mut self) {
        let m = self.u.len().max(1) as f32;
        self.u_coverage = self.u.iter().filter(|b| **b).count() as f32 / m;
        self.l_coverage = self.l.iter().filter(|b| **b).count() as f32 / m;
    }

    /// Labels of a frame with no usable pair on either side: no residuals,
    /// nothing in U or L.
    pub fn no_evidence(n: usize) -> Self {
        FrameLabels {
            s: vec![f32::NAN; n],
            u: vec![false; n],
            l: vec![false; n],
            v: 0.0,
            inlier_ratio: 0.0,
            u_coverage: 0.0,
            l_coverage: 0.0,
            valid_ratio: 0.0,
        }
    }
}

/// Residuals, U and L for a frame from its forward and/or backward sides.
pub fn frame_labels(sides: &[Side], o: &LabelOptions) -> FrameLabels {
    let Some(first) = sides.first() else {
        return FrameLabels {
            s: vec![],
            u: vec![],
            l: vec![],
            v: 0.0,
            inlier_ratio: 0.0,
            u_coverage: 0.0,
            l_coverage: 0.0,
            valid_ratio: 0.0,
        };
    };
    let (w, h) = (first.flow.w(), first.flow.h());
    let n = w * h;
    let v = sides.iter().map(|s| s.flow.mean_magnitude()).sum::<f32>() / sides.len() as f32;
    let s: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let mut best = f32::NAN;
            for sd in sides {
                if !sd.valid[i] {
                    continue;
                }
                let q = [x + sd.flow.u.data[i] as f64, y + sd.flow.v.data[i] as f64];
                let (p1, p2) = if sd.second { (q, [x, y]) } else { ([x, y], q) };
                let mut r = sd.model.residual_px(p1, p2);
                if let Some(or) = sd.oriented {
                    r = r.max(or.violation_px(p1, p2));
                }
                let r = r as f32;
                if best.is_nan() || r > best {
                    best = r;
                }
            }
            best
        })
        .collect();
    let inlier_thr = sides
        .iter()
        .map(|sd| (o.robust.inlier_sigmas * sd.report.sigma_px) as f32)
        .fold(0.0f32, f32::max);
    let (ut, lt) = (o.u_factor * v, o.l_factor * v);
    let u: Vec<bool> = if o.local_u_floor > 0.0 {
        (0..n)
            .into_par_iter()
            .map(|i| {
                let (mut m, mut k) = (0.0f32, 0u32);
                for sd in sides {
                    if sd.valid[i] {
                        m += sd.flow.u.data[i].hypot(sd.flow.v.data[i]);
                        k += 1;
                    }
                }
                let m = m / k.max(1) as f32;
                let t = o.u_factor * v.min(m.max(o.local_u_floor * v));
                !s[i].is_nan() && s[i] > t
            })
            .collect()
    } else {
        s.iter().map(|x| !x.is_nan() && *x > ut).collect()
    };
    let l: Vec<bool> = s.iter().map(|x| !x.is_nan() && *x < lt).collect();
    let nv = s.iter().filter(|x| !x.is_nan()).count();
    let ni = s.iter().filter(|x| !x.is_nan() && **x < inlier_thr).count();
    FrameLabels {
        inlier_ratio: ni as f32 / nv.max(1) as f32,
        u_coverage: u.iter().filter(|b| **b).count() as f32 / n as f32,
        l_coverage: l.iter().filter(|b| **b).count() as f32 / n as f32,
        valid_ratio: nv as f32 / n as f32,
        s,
        u,
        l,
        v,
    }
}

/// The majority filter on U (`LabelOptions::u_majority_radius` `r`): a
/// pixel that is U because its residual exceeds `u_factor·v` leaves U
/// unless more than half of the `(2r + 1)²` window around it (clipped at
/// the frame's edges) is U. A residual near the threshold in a noisy region
/// (rippling water, a swan's wake) crosses it in scattered pixels, while a
/// moving object's residual exceeds it over an area. Isolated U costs the
/// MLP most: trained on U from the pond around blackswan's swan, it paints
/// the whole pond. U from other tests (the three-view test, which finds
/// pedestrians walking along the epipolar lines in few pixels) is kept.
pub fn u_majority(fl: &mut FrameLabels, w: usize, radius: usize, u_factor: f32) {
    if radius == 0 || w == 0 || !fl.u.len().is_multiple_of(w) {
        return;
    }
    let density = Plane {
        w,
        h: fl.u.len() / w,
        data: fl.u.iter().map(|b| f32::from(u8::from(*b))).collect(),
    }
    .box_mean(radius);
    let thr = u_factor * fl.v;
    for ((u, d), s) in fl.u.iter_mut().zip(&density.data).zip(&fl.s) {
        if *u && *s > thr && *d <= 0.5 {
            *u = false;
        }
    }
    fl.recount_coverage();
}

/// Pixels with less parallax in either pair than this are not tested by
/// [`three_view_residuals`] (working-grid px).
pub const THREE_VIEW_MIN_PARALLAX_PX: f64 = 0.5;

/// Three-view depth consistency of frame t (ours). Each pixel is
/// triangulated twice, with the pair (t, t+1) through `fwd` and `of`, and
/// with the pair (t−1, t) through `bwd` (t → t−1) and `ob`; each pair's
/// depths are in units of its own baseline, so for a static point their
/// ratio is the same everywhere: the ratio of the two baselines, taken as
/// the median over the `reference` pixels (L). A pedestrian walking along
/// the epipolar lines passes Sampson and cheirality in both pairs (it
/// looks like a static point at another depth), but the depth it mimics
/// depends on the camera's displacement relative to its own, so unless the
/// camera moves at a constant velocity the two depths disagree. The
/// residual is that disagreement as a change of the forward parallax:
/// `parallax_f · |1 − ρ(x) / ρ̂|` px. NaN where a flow failed the cycle
/// check, the parallax is below [`THREE_VIEW_MIN_PARALLAX_PX`] or a depth
/// is not positive; None when fewer than 50 reference pixels qualify.
pub fn three_view_residuals(
    fwd: &Flow,
    valid_f: &[bool],
    of: &Oriented,
    bwd: &Flow,
    valid_b: &[bool],
    ob: &Oriented,
    reference: &[bool],
) -> Option<Vec<f32>> {
    let w = fwd.w();
    let n = w * fwd.h();
    if bwd.w() != w
        || bwd.h() != fwd.h()
        || [valid_f, valid_b, reference].iter().any(|v| v.len() != n)
    {
        return None;
    }
    // (depth ratio z_f / z_b, forward parallax) per pixel.
    let per: Vec<Option<(f64, f64)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if !valid_f[i] || !valid_b[i] {
                return None;
            }
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let a = [x + fwd.u.data[i] as f64, y + fwd.v.data[i] as f64];
            let b = [x + bwd.u.data[i] as f64, y + bwd.v.data[i] as f64];
            let df = of.depths([x, y], a);
            let db = ob.depths(b, [x, y]);
            let ok = df.parallax_px >= THREE_VIEW_MIN_PARALLAX_PX
                && db.parallax_px >= THREE_VIEW_MIN_PARALLAX_PX
                && df.z1 > 0.0
                && db.z2 > 0.0
                && (df.z1 / db.z2).is_finite();
            ok.then_some((df.z1 / db.z2, df.parallax_px))
        })
        .collect();
    let mut ratios: Vec<f64> = per
        .iter()
        .zip(reference)
        .filter_map(|(p, r)| p.filter(|_| *r).map(|(q, _)| q))
        .collect();
    if ratios.len() < 50 {
        return None;
    }
    let mid = ratios.len() / 2;
    let (_, med, _) = ratios.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    let med = *med;
    Some(
        per.iter()
            .map(|p| p.map_or(f32::NAN, |(q, par)| (par * (1.0 - q / med).abs()) as f32))
            .collect(),
    )
}

/// Occlusion-order violations of one frame against one neighbour (ours).
/// `out` is the flow from this frame to the neighbour and `valid_out` its
/// cycle check; `back` the flow from the neighbour to this frame and
/// `valid_back` its cycle check (per pixel of the neighbour); `second`:
/// the neighbour is the earlier frame of the pair that `of` describes.
///
/// A pixel `i` whose flow fails the cycle check, and whose target `q` in
/// the neighbour is a cycle-consistent pixel that came from elsewhere
/// (`q + back(q)` more than 1 px from `i`), is hidden there by the pixel
/// `j` it came from: `j` is in front of `i`. For static points seen by a
/// camera that translates, the nearer point has the larger parallax
/// (parallax ∝ baseline / depth), so `j` is static only if its parallax is
/// at least `i`'s. Returns per pixel the largest `parallax(i) −
/// parallax(j)` over the pixels `i` that `j` hides (px, 0 where none),
/// counting only `i` whose flow differs from `j`'s by more than 1 px (a
/// flow dragged across the boundary carries no depth of its own).
pub fn occlusion_violations(
    out: &Flow,
    valid_out: &[bool],
    back: &Flow,
    valid_back: &[bool],
    of: &Oriented,
    second: bool,
) -> Vec<f32> {
    let (w, h) = (out.w(), out.h());
    let n = w * h;
    let mut viol = vec![0f32; n];
    if valid_out.len() != n || valid_back.len() != n || back.w() != w || back.h() != h {
        return viol;
    }
    let parallax = |i: usize| -> f64 {
        let (x, y) = ((i % w) as f64, (i / w) as f64);
        let q = [x + out.u.data[i] as f64, y + out.v.data[i] as f64];
        let d = if second {
            of.depths(q, [x, y])
        } else {
            of.depths([x, y], q)
        };
        d.parallax_px
    };
    let at = |x: f32, y: f32| -> Option<usize> {
        let (xr, yr) = (x.round(), y.round());
        (xr >= 0.0 && yr >= 0.0 && xr < w as f32 && yr < h as f32)
            .then(|| yr as usize * w + xr as usize)
    };
    let hits: Vec<(usize, f32)> = (0..n)
        .into_par_iter()
        .filter_map(|i| {
            if valid_out[i] {
                return None;
            }
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let (qx, qy) = (x + out.u.data[i], y + out.v.data[i]);
            let q = at(qx, qy)?;
            if !valid_back[q] {
                return None;
            }
            let (jx, jy) = (qx + back.u.data[q], qy + back.v.data[q]);
            if (jx - x).hypot(jy - y) <= 1.0 {
                return None;
            }
            let j = at(jx, jy)?;
            if !valid_out[j] {
                return None;
            }
            let df = (out.u.data[i] - out.u.data[j]).hypot(out.v.data[i] - out.v.data[j]);
            if df <= 1.0 {
                return None;
            }
            let d = (parallax(i) - parallax(j)) as f32;
            (d > 0.0).then_some((j, d))
        })
        .collect();
    for (j, d) in hits {
        viol[j] = viol[j].max(d);
    }
    viol
}

/// Apply [`three_view_residuals`] to a frame's labels (see
/// [`LabelOptions::three_view`]) and update its coverage fractions.
pub fn apply_three_view(fl: &mut FrameLabels, residual: &[f32], o: &LabelOptions) {
    if fl.u.len() != residual.len() || fl.l.len() != residual.len() {
        return;
    }
    for (i, e) in residual.iter().enumerate() {
        if e.is_nan() {
            continue;
        }
        if !fl.u[i] && !fl.l[i] && *e > o.three_view_u_px {
            fl.u[i] = true;
        }
        if fl.l[i] && *e > o.three_view_l_px {
            fl.l[i] = false;
        }
    }
    fl.recount_coverage();
}

/// Spread U along the flow `passes` times (see
/// [`LabelOptions::u_propagation_frames`]): frame t gains U where
/// `fwd[t]` (t → t+1) lands in U of frame t+1 or `bwd[t−1]` (t → t−1) lands
/// in U of frame t−1, both only where the flow passed the cycle check; L
/// and the coverage fractions are updated.
pub fn propagate_u(
    labels: &mut [FrameLabels],
    fwd: &[Flow],
    bwd: &[Flow],
    valid_f: &[Vec<bool>],
    valid_b: &[Vec<bool>],
    passes: usize,
) {
    let n = labels.len();
    if n < 2 || fwd.len() + 1 != n || bwd.len() + 1 != n {
        return;
    }
    let (w, h) = (fwd[0].w(), fwd[0].h());
    let hit = |u: &[bool], f: &Flow, i: usize| {
        let x = ((i % w) as f32 + f.u.data[i]).round();
        let y = ((i / w) as f32 + f.v.data[i]).round();
        x >= 0.0
            && y >= 0.0
            && (x as usize) < w
            && (y as usize) < h
            && u[y as usize * w + x as usize]
    };
    for _ in 0..passes {
        let us: Vec<Vec<bool>> = labels.iter().map(|l| l.u.clone()).collect();
        labels.par_iter_mut().enumerate().for_each(|(t, fl)| {
            if fl.u.len() != w * h {
                return;
            }
            for i in 0..w * h {
                if fl.u[i] {
                    continue;
                }
                let from_next = t + 1 < n && valid_f[t][i] && hit(&us[t + 1], &fwd[t], i);
                let from_prev = t > 0 && valid_b[t - 1][i] && hit(&us[t - 1], &bwd[t - 1], i);
                if from_next || from_prev {
                    fl.u[i] = true;
                    fl.l[i] = false;
                }
            }
        });
    }
    for fl in labels.iter_mut() {
        fl.recount_coverage();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::Plane;

    #[test]
    fn u_majority_keeps_areas_and_drops_scattered_pixels() {
        // A 12 × 12 square of U with a residual of 3·v, and single U
        // pixels (residual 2·v) every 6 px elsewhere: at r = 4 a square's
        // pixel stays U when more than half of its 9 × 9 window is in the
        // square (its middle and the middles of its sides; not its corners,
        // 25 of 81), and every single pixel leaves. A single U pixel whose
        // residual is below u·v (U from the three-view test) stays.
        let (w, h) = (40, 30);
        let in_square = |x: usize, y: usize| (4..16).contains(&x) && (4..16).contains(&y);
        let mut s = vec![0.05f32; w * h];
        let mut u = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if in_square(x, y) {
                    s[i] = 3.0;
                    u[i] = true;
                } else if x >= 20 && x % 6 == 0 && y % 6 == 0 {
                    s[i] = 2.0;
                    u[i] = true;
                }
            }
        }
        let three_view = 25 * w + 10;
        u[three_view] = true;
        let mut fl = FrameLabels {
            s,
            u,
            l: vec![false; w * h],
            v: 1.0,
            inlier_ratio: 1.0,
            u_coverage: 0.0,
            l_coverage: 0.0,
            valid_ratio: 1.0,
        };
        u_majority(&mut fl, w, 4, 1.0);
        assert!(fl.u[three_view]);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if i == three_view {
                    continue;
                }
                let (xs, ys) = (
                    x.saturating_sub(4)..(x + 5).min(w),
                    y.saturating_sub(4)..(y + 5).min(h),
                );
                let window = xs.len() * ys.len();
                let inside = ys
                    .flat_map(|yy| xs.clone().map(move |xx| (xx, yy)))
                    .filter(|(xx, yy)| in_square(*xx, *yy))
                    .count();
                let expect = in_square(x, y) && 2 * inside > window;
                assert_eq!(fl.u[i], expect, "pixel ({x}, {y})");
            }
        }
        for (x, y) in [(9, 9), (10, 4), (4, 10), (15, 9), (9, 15)] {
            assert!(fl.u[y * w + x], "({x}, {y}) should stay U");
        }
        for (x, y) in [(4, 4), (15, 15), (24, 6), (36, 24)] {
            assert!(!fl.u[y * w + x], "({x}, {y}) should leave U");
        }
        let n = fl.u.iter().filter(|b| **b).count();
        assert!((fl.u_coverage - n as f32 / (w * h) as f32).abs() < 1e-6);
        // r = 0 leaves U as it is.
        let before = fl.u.clone();
        u_majority(&mut fl, w, 0, 1.0);
        assert_eq!(fl.u, before);
    }

    #[test]
    fn u_propagates_along_the_flow_and_clears_l() {
        // U only in frame 0 (a 4×4 square); the scene moves 2 px right per
        // frame. After 2 passes frames 1 and 2 have U on the moved square,
        // L is cleared there, and frame 3 (3 frames away) has none.
        let (w, h, n) = (30, 12, 4);
        let mut labels: Vec<FrameLabels> = (0..n)
            .map(|t| FrameLabels {
                s: vec![0.0; w * h],
                u: (0..w * h)
                    .map(|i| t == 0 && (4..8).contains(&(i % w)) && (4..8).contains(&(i / w)))
                    .collect(),
                l: vec![t != 0; w * h],
                v: 2.0,
                inlier_ratio: 1.0,
                u_coverage: 0.0,
                l_coverage: 0.0,
                valid_ratio: 1.0,
            })
            .collect();
        let flow = |d: f32| Flow {
            u: Plane::filled(w, h, d),
            v: Plane::filled(w, h, 0.0),
        };
        let fwd = vec![flow(2.0); n - 1];
        let bwd = vec![flow(-2.0); n - 1];
        let valid = vec![vec![true; w * h]; n - 1];
        propagate_u(&mut labels, &fwd, &bwd, &valid, &valid, 2);
        for (t, lab) in labels.iter().enumerate().take(3).skip(1) {
            for i in 0..w * h {
                let (x, y) = (i % w, i / w);
                let inside = (4 + 2 * t..8 + 2 * t).contains(&x) && (4..8).contains(&y);
                assert_eq!(lab.u[i], inside, "frame {t} ({x}, {y})");
                assert_eq!(lab.l[i], !inside);
            }
            assert!((lab.u_coverage - 16.0 / (w * h) as f32).abs() < 1e-6);
        }
        assert!(labels[3].u.iter().all(|u| !u));
    }

    /// Correspondences on a 256 × 144 grid: a camera translating along x
    /// over static points at depths 2–10 (parallax along x, ±0.05 px
    /// noise), and a share `moving` of the points on deforming objects
    /// (each point displaced up to 6 px its own way).
    fn pair_points(moving: f64, seed: u64) -> (Vec<Pt>, Vec<Pt>) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        (0..1500)
            .map(|_| {
                let a = [rng.random_range(0.0..256.0), rng.random_range(0.0..144.0)];
                let noise = [rng.random_range(-0.05..0.05), rng.random_range(-0.05..0.05)];
                let d = if rng.random_bool(moving) {
                    [rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0)]
                } else {
                    [8.0 / rng.random_range(2.0..10.0), 0.0]
                };
                (a, [a[0] + d[0] + noise[0], a[1] + d[1] + noise[1]])
            })
            .unzip()
    }

    fn pair_fit(moving: f64, seed: u64) -> PairFit {
        let (a, b) = pair_points(moving, seed);
        let fits = fit_two_view_all(&a, &b, &RobustOptions::default()).unwrap();
        PairFit {
            model: fits.chosen,
            report: fits.report,
            oriented: None,
        }
    }

    /// LMedS σ̂ stays at its floor while the static points are the
    /// majority and rises when movers cover 60% of the points; only that
    /// pair is dropped, and failed pairs keep their reason.
    #[test]
    fn a_fit_with_movers_over_half_the_points_is_dropped() {
        let floor = RobustOptions::default().min_sigma_px;
        let mut fits: Vec<PairResult> = vec![
            Ok(pair_fit(0.2, 1)),
            Ok(pair_fit(0.3, 2)),
            Err(NoFit::Failed("no texture".into())),
            Ok(pair_fit(0.6, 3)),
            Ok(pair_fit(0.1, 4)),
        ];
        let sigma = |f: &PairResult| f.as_ref().map(|p| p.report.sigma_px).unwrap_or(f64::NAN);
        for k in [0, 1, 4] {
            assert!(
                sigma(&fits[k]) <= floor * 1.01,
                "pair {k}: {}",
                sigma(&fits[k])
            );
        }
        assert!(sigma(&fits[3]) > 2.0 * floor, "{}", sigma(&fits[3]));
        let before = fits.clone();
        drop_unreliable_fits(&mut fits, 0.0, floor);
        assert_eq!(
            fits.iter().map(|f| f.is_ok()).collect::<Vec<_>>(),
            before.iter().map(|f| f.is_ok()).collect::<Vec<_>>(),
            "ratio 0 disables"
        );
        drop_unreliable_fits(&mut fits, 2.0, floor);
        assert!(fits[0].is_ok() && fits[1].is_ok() && fits[4].is_ok());
        assert!(matches!(&fits[2], Err(NoFit::Failed(r)) if r == "no texture"));
        assert!(matches!(&fits[3], Err(NoFit::Unreliable(r)) if r.contains("unreliable fit")));
    }

    #[test]
    fn cycle_check_flags_inconsistent_flow() {
        let f = Flow {
            u: Plane::filled(20, 10, 2.0),
            v: Plane::filled(20, 10, 0.0),
        };
        let mut b = Flow {
            u: Plane::filled(20, 10, -2.0),
            v: Plane::filled(20, 10, 0.0),
        };
        // Backward flow wrong in a region: those pixels (mapped into it) fail.
        for y in 0..10 {
            for x in 10..14 {
                b.v.data[y * 20 + x] = 3.0;
            }
        }
        let ok = cycle_valid(&f, &b, &LabelOptions::default());
        assert!(ok[5 * 20 + 3]);
        assert!(!ok[5 * 20 + 10]); // 10 + 2 = 12 lands in the bad region
        assert!(!ok[5 * 20 + 19]); // leaves the frame
    }

    /// A sideways dolly with a little yaw over a static scene at 3–15 m,
    /// and a block of pixels on a walker moving the camera's way, faster:
    /// its flow stays on the epipolar lines. Sampson alone calls it static;
    /// with the cheirality test it is U, and the static scene stays clear.
    /// Intrinsics (and inverse) of a `w × h` grid with focal `f`, principal
    /// point at the centre, as `orient` builds them.
    fn grid_camera(w: usize, h: usize, f: f64) -> (Matrix3<f64>, Matrix3<f64>) {
        let k = crate::geometry::oriented::intrinsics(
            f,
            0.5 * (w as f64 - 1.0),
            0.5 * (h as f64 - 1.0),
        );
        (k, k.try_inverse().unwrap())
    }

    /// Rotation by `a` rad about the y axis.
    fn yaw(a: f64) -> Matrix3<f64> {
        Matrix3::new(a.cos(), 0.0, a.sin(), 0.0, 1.0, 0.0, -a.sin(), 0.0, a.cos())
    }

    /// Frames t−1, t, t+1 of a sideways dolly whose speed changes (camera
    /// at x = −0.06, 0, +0.10, small yaws) and a pedestrian walking against
    /// it (−0.1 per frame, depth 3): in both pairs its flow lies on the
    /// epipolar lines and triangulates in front of the cameras, so Sampson
    /// and cheirality are blind to it, but its two depths disagree. At
    /// constant camera velocity they agree (the stated limit).
    fn three_view_scene(cb_x: f64) -> (Flow, Flow, Oriented, Oriented, Vec<bool>, Matrix3<f64>) {
        use nalgebra::Vector3;
        let (w, h) = (96usize, 64usize);
        let (k, ki) = grid_camera(w, h, 120.0);
        let (rf, rb) = (yaw(0.004), yaw(-0.003));
        let (cf, cb) = (Vector3::new(0.10, 0.0, 0.0), Vector3::new(cb_x, 0.0, 0.0));
        let step = Vector3::new(-0.1, 0.0, 0.0);
        let walker = |x: usize, y: usize| (40..56).contains(&x) && (20..44).contains(&y);
        let zero = || Flow {
            u: Plane::filled(w, h, 0.0),
            v: Plane::filled(w, h, 0.0),
        };
        let (mut fwd, mut bwd) = (zero(), zero());
        let (mut va, mut vb, mut wa, mut wb) = (vec![], vec![], vec![], vec![]);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let wk = walker(x, y);
                let z = if wk {
                    3.0
                } else {
                    4.0 + 8.0 * (((x * 7 + y * 13) % 17) as f64 / 16.0)
                };
                let p = ki * Vector3::new(x as f64, y as f64, 1.0) * z;
                let (pn, pp) = if wk { (p + step, p - step) } else { (p, p) };
                let qf = k * (rf * (pn - cf));
                let qb = k * (rb * (pp - cb));
                let (xf, yf) = (qf[0] / qf[2], qf[1] / qf[2]);
                let (xb, yb) = (qb[0] / qb[2], qb[1] / qb[2]);
                fwd.u.data[i] = (xf - x as f64) as f32;
                fwd.v.data[i] = (yf - y as f64) as f32;
                bwd.u.data[i] = (xb - x as f64) as f32;
                bwd.v.data[i] = (yb - y as f64) as f32;
                if !wk {
                    va.push([x as f64, y as f64]);
                    vb.push([xf, yf]);
                    wa.push([xb, yb]);
                    wb.push([x as f64, y as f64]);
                }
            }
        }
        // p_{t+1} = R_f p_t − R_f c_f; p_t = R_bᵀ p_{t−1} + c_b.
        let fm = |r: Matrix3<f64>, t: Vector3<f64>| {
            let tx = Matrix3::new(0.0, -t[2], t[1], t[2], 0.0, -t[0], -t[1], t[0], 0.0);
            ki.transpose() * tx * r * ki
        };
        let vote = VoteOptions::default();
        let of = Oriented::from_fundamental(&fm(rf, -(rf * cf)), &k, &va, &vb, &vote).unwrap();
        let ob = Oriented::from_fundamental(&fm(rb.transpose(), cb), &k, &wa, &wb, &vote).unwrap();
        let wmask = (0..w * h).map(|i| walker(i % w, i / w)).collect();
        (fwd, bwd, of, ob, wmask, fm(rf, -(rf * cf)))
    }

    /// A sideways dolly (0.1 per frame, no rotation) over a static
    /// background whose depth grows with the row (4 + 0.1·y), and a block
    /// of pixels at columns 40–55, rows 20–43 whose own depth is
    /// `block_depth` (None: it moves with the camera, zero flow, a point at
    /// infinity to two-view geometry). Returns the occlusion violations of
    /// frame t against t+1 and of t+1 against t, and the block's columns
    /// in t and t+1.
    fn occlusion_scene(block_depth: Option<f64>) -> (Vec<f32>, Vec<f32>, usize) {
        use nalgebra::Vector3;
        let (w, h) = (96usize, 64usize);
        let f = 120.0;
        let (k, ki) = grid_camera(w, h, f);
        let c = 0.1;
        let bg = |y: usize| (f * c / (4.0 + 0.1 * y as f64)) as f32;
        let db = block_depth.map_or(0.0, |z| (f * c / z) as f32);
        let shift = db.round() as usize;
        let rows = 20..44;
        let zero = || Flow {
            u: Plane::filled(w, h, 0.0),
            v: Plane::filled(w, h, 0.0),
        };
        let (mut fwd, mut bwd) = (zero(), zero());
        let (mut a, mut b) = (vec![], vec![]);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let in_t = rows.contains(&y) && (40..56).contains(&x);
                let in_t1 = rows.contains(&y) && (40 - shift..56 - shift).contains(&x);
                fwd.u.data[i] = if in_t { -db } else { -bg(y) };
                bwd.u.data[i] = if in_t1 { db } else { bg(y) };
                if !in_t {
                    a.push([x as f64, y as f64]);
                    b.push([x as f64 - bg(y) as f64, y as f64]);
                }
            }
        }
        let t = Vector3::new(-c, 0.0, 0.0);
        let fm = ki.transpose() * t.cross_matrix() * ki;
        let of = Oriented::from_fundamental(&fm, &k, &a, &b, &VoteOptions::default()).unwrap();
        let o = LabelOptions::default();
        let (vf, vb) = (cycle_valid(&fwd, &bwd, &o), cycle_valid(&bwd, &fwd, &o));
        (
            occlusion_violations(&fwd, &vf, &bwd, &vb, &of, false),
            occlusion_violations(&bwd, &vb, &fwd, &vf, &of, true),
            shift,
        )
    }

    /// The camera follows the block: it hides background with 2–3 px of
    /// parallax while having none itself, so its leading columns violate
    /// the occlusion order by about the background's parallax, and no
    /// background pixel does. A static block nearer than the background
    /// (depth 2, 6 px of parallax) hides it too, without a violation.
    #[test]
    fn occlusion_order_flags_an_object_the_camera_follows() {
        let w = 96;
        let (vf, vb, _) = occlusion_scene(None);
        let block = |i: usize| (20..44).contains(&(i / w)) && (40..56).contains(&(i % w));
        let flagged: Vec<usize> = (0..vf.len()).filter(|&i| vf[i] > 1.0).collect();
        assert!(
            flagged.len() >= 24,
            "{} block pixels flagged",
            flagged.len()
        );
        assert!(flagged.iter().all(|&i| block(i) && i % w >= 53));
        assert!((0..vf.len()).all(|i| block(i) || vf[i] == 0.0));
        // Seen from t+1 backwards the block hides what it uncovers.
        assert!((0..vb.len()).filter(|&i| vb[i] > 1.0).count() >= 24);
        assert!((0..vb.len()).all(|i| block(i) || vb[i] == 0.0));
        let (vf, vb, shift) = occlusion_scene(Some(2.0));
        assert_eq!(shift, 6);
        let worst = vf.iter().chain(&vb).fold(0.0f32, |a, b| a.max(*b));
        assert!(worst < 0.5, "static occluder violates by {worst} px");
    }

    #[test]
    fn three_view_test_flags_a_walker_along_the_epipolar_lines() {
        let (fwd, bwd, of, ob, walker, f_f) = three_view_scene(-0.06);
        let (w, n) = (fwd.w(), walker.len());
        let valid = vec![true; n];
        let reference: Vec<bool> = walker.iter().map(|b| !b).collect();
        let e = three_view_residuals(&fwd, &valid, &of, &bwd, &valid, &ob, &reference).unwrap();
        let (mut hit, mut nw, mut worst_static) = (0, 0, 0.0f32);
        for i in 0..n {
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let q = [x + fwd.u.data[i] as f64, y + fwd.v.data[i] as f64];
            if walker[i] {
                // Two-view tests are blind to it ...
                assert!(crate::geometry::fundamental::sampson_px(&f_f, [x, y], q) < 0.05);
                assert_eq!(of.violation_px([x, y], q), 0.0);
                // ... the three-view residual is not (expected 2.7 px).
                nw += 1;
                hit += usize::from(e[i] > 1.5);
            } else if !e[i].is_nan() {
                worst_static = worst_static.max(e[i]);
            }
        }
        assert!(
            hit * 100 >= nw * 95,
            "{hit} of {nw} walker pixels over 1.5 px"
        );
        assert!(
            worst_static < 0.05,
            "static residual up to {worst_static} px"
        );
        // Labels: the walker's left half unlabelled becomes U, its right half
        // leaves L; the static scene keeps L.
        let mut fl = FrameLabels {
            s: vec![0.0; n],
            u: vec![false; n],
            l: (0..n).map(|i| !(walker[i] && i % w < 48)).collect(),
            v: 1.0,
            inlier_ratio: 1.0,
            u_coverage: 0.0,
            l_coverage: 1.0,
            valid_ratio: 1.0,
        };
        apply_three_view(&mut fl, &e, &LabelOptions::default());
        for i in 0..n {
            if walker[i] && !e[i].is_nan() && e[i] > 1.0 {
                assert!(!fl.l[i]);
                assert_eq!(fl.u[i], i % w < 48);
            } else if !walker[i] {
                assert!(fl.l[i] && !fl.u[i]);
            }
        }
        assert!(fl.u_coverage > 0.0 && fl.l_coverage < 1.0);
        // Constant camera velocity: the walker is a static point at another
        // depth in all three views, and the residual vanishes.
        let (fwd, bwd, of, ob, walker, _) = three_view_scene(-0.10);
        let e = three_view_residuals(&fwd, &valid, &of, &bwd, &valid, &ob, &reference).unwrap();
        let worst = (0..n)
            .filter(|i| walker[*i] && !e[*i].is_nan())
            .map(|i| e[i])
            .fold(0.0f32, f32::max);
        assert!(
            worst < 0.2,
            "constant velocity: walker residual up to {worst} px"
        );
    }

    #[test]
    fn cheirality_flags_motion_along_epipolar_lines() {
        use nalgebra::Vector3;
        let (w, h) = (96usize, 64usize);
        let focal = 80.0;
        let (k, ki) = grid_camera(w, h, focal);
        let r = yaw(0.004);
        let t = Vector3::new(-0.08, 0.0, 0.0);
        let walker = |x: usize, y: usize| (40..56).contains(&x) && (20..50).contains(&y);
        let mut flow = Flow {
            u: Plane::filled(w, h, 0.0),
            v: Plane::filled(w, h, 0.0),
        };
        for y in 0..h {
            for x in 0..w {
                let z = if walker(x, y) {
                    4.0
                } else {
                    3.0 + 12.0 * (((x * 7 + y * 13) % 17) as f64 / 16.0)
                };
                let p = ki * Vector3::new(x as f64, y as f64, 1.0) * z;
                let p = if walker(x, y) {
                    p + Vector3::new(0.16, 0.0, 0.0)
                } else {
                    p
                };
                let q = k * (r * p + t);
                flow.u.data[y * w + x] = (q[0] / q[2] - x as f64) as f32;
                flow.v.data[y * w + x] = (q[1] / q[2] - y as f64) as f32;
            }
        }
        let valid = vec![true; w * h];
        let o = LabelOptions::default();
        let count = |fit: &PairFit| {
            let side = Side {
                flow: &flow,
                valid: &valid,
                model: fit.model,
                report: &fit.report,
                second: false,
                oriented: fit.oriented.as_ref(),
            };
            let lab = frame_labels(&[side], &o);
            let (mut inside, mut outside) = (0, 0);
            for i in 0..w * h {
                if lab.u[i] {
                    if walker(i % w, i / w) {
                        inside += 1;
                    } else {
                        outside += 1;
                    }
                }
            }
            (inside, outside)
        };
        let plain = fit_pair(&flow, &valid, &o, 3, None).unwrap();
        assert!(plain.oriented.is_none());
        let (inside, _) = count(&plain);
        assert!(
            inside < 16 * 30 / 10,
            "Sampson alone: {inside} of 480 walker px in U"
        );
        let fit = fit_pair(&flow, &valid, &o, 3, Some(focal)).unwrap();
        assert_eq!(fit.report.model, "F");
        let or = fit.oriented.expect("decided");
        // The walker (8% of the pixels, on its epipolar lines) votes against.
        assert!(or.support > 0.85, "{}", or.support);
        let (inside, outside) = count(&fit);
        assert!(inside > 16 * 30 * 9 / 10, "{inside} of 480 walker px in U");
        assert!(outside < 60, "{outside} static px in U");
        let off = LabelOptions {
            cheirality: false,
            ..Default::default()
        };
        assert!(
            fit_pair(&flow, &valid, &off, 3, Some(focal))
                .unwrap()
                .oriented
                .is_none()
        );
    }
}
