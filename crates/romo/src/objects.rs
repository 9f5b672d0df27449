//! Object-level refinement (ours; the role SAM2 plays in the paper): the
//! per-pixel evidence of a whole video is turned into object masks by one
//! minimum cut over a space–time graph (Boykov & Jolly 2001; Rother et
//! al.'s GrabCut 2004 for the colour model and the contrast term), solved
//! with [`crate::maxflow`].
//!
//! Nodes are the working grid's pixels in every frame. Each node's unary
//! evidence is a log-odds-like score in units where ±1 is "confident":
//!
//! - **geometry** `g`, on textured pixels with a residual: the Sampson
//!   residual `S` placed between RoMo's own thresholds on a log scale,
//!   `g = clamp(ln(S / (v·√(u·l))) / ln(√(u / l)), −1, 1)`: −1 at the L
//!   threshold `l·v`, +1 at the U threshold `u·v`, 0 at their geometric
//!   mean. A textureless pixel's flow is interpolated from its
//!   surroundings, so its residual is not evidence (see
//!   `LabelOptions::u_min_gradient`);
//! - **MLP** `m = clamp(logit(p), −4, 4) / 4` from the refined probability;
//! - **superpixel vote** `r`: the mean of `g` over the pixel's colour
//!   superpixel (Felzenszwalb & Huttenlocher 2004 on the frame's RGB),
//!   × a gain, clamped to [0, 1]: sparse but consistent motion evidence
//!   inside one image region makes the whole region moving;
//! - **colour** `c`: the log ratio of a foreground and a background colour
//!   histogram (16 bins per channel), ÷ 2, clamped to ±1; local models per
//!   tile and few frames with the video's model as a prior (see
//!   `colour_evidence`).
//!
//! Unary `a = w_g·g + w_m·m + w_r·r + w_c·c` (source capacity `max(a, 0)`, sink
//! capacity `max(−a, 0)`). Neighbouring pixels (4-connected) are joined with
//! `λ_s·exp(−|ΔI|² / (2⟨|ΔI|²⟩))` (colour contrast, the frame's mean
//! squared difference), and each pixel to the pixel its cycle-consistent
//! forward flow lands on in the next frame with
//! `λ_t·exp(−|ΔI|² / (2⟨|ΔI|²⟩))`, the colour difference along the flow
//! over the pair's mean (ours, `temporal_contrast`): an object found
//! confidently in some frames carries its label along the flow to frames
//! where its evidence is weak, forward and backward alike, and a link
//! whose two ends differ in colour (the flow landed on something else: an
//! occlusion, a limb the flow missed) carries little. The pixels of the
//! next frame that no forward link reaches (where the flow spreads or
//! rounds past them) are linked back along their cycle-consistent backward
//! flow the same way (`temporal_backward`).
//!
//! As in GrabCut, the colour models are then learnt again from the cut's
//! own masks and the cut is solved again (`colour_rounds`).

use crate::flow::Flow;
use crate::maxflow::{Edge, Network};
use crate::plane::{Plane, Rgb};
use crate::regions::colour_segments;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Which object refinement runs after the per-pixel refinement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum ObjectMethod {
    /// None: the probabilities are thresholded as they are.
    Off,
    /// One minimum cut over the space–time graph (module doc).
    #[default]
    GraphCut,
}

/// Options of the object refinement.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(default)]
pub struct ObjectOptions {
    /// Object-level refinement: graph-cut (one minimum cut over all frames
    /// from the geometric evidence, the MLP, a colour model, image contrast
    /// and the flow; default) or off.
    #[cfg_attr(feature = "cli", arg(long = "objects", value_enum, required = false))]
    pub method: ObjectMethod,
    /// Weight `w_g` of the geometric evidence (default 1).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub geometry_weight: f32,
    /// Residual over mean flow `S / v` at which the geometric evidence is
    /// 0 (default none: the geometric mean of the thresholds, `√(u·l)`;
    /// 1.0 puts it at the U threshold). The scale is kept: `g` moves by 1
    /// per factor `√(u / l)` of `S`.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub geometry_zero: Option<f32>,
    /// Weight `w_m` of the MLP's probability (default 1).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub mlp_weight: f32,
    /// Weight `w_c` of the colour model (default 1).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub colour_weight: f32,
    /// Weight `λ_s` of the contrast-sensitive spatial smoothness (default 3;
    /// with the colour re-estimation, seed 0: DAVIS mean J 0.712 at 1,
    /// 0.717 at 2, 0.719 at 3, 0.720 at 4; the composite 0.893 at 1, 0.908
    /// at 3).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub smoothness: f32,
    /// Weight `λ_t` of the edges along the flow between frames (default 3,
    /// with `temporal_contrast`; mean J over seeds 0–2 against 1 without
    /// it: DAVIS 0.734 → 0.739, the 33 scene and composite runs 0.844 →
    /// 0.849; 5 gives seed 0 the same).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub temporal: f32,
    /// The edges along the flow weighted by the colour difference of their
    /// two ends, `exp(−|ΔI|² / (2⟨|ΔI|²⟩))` with the pair's mean over its
    /// links, as the spatial edges are by image contrast (ours; default
    /// true; false: every link weighs `λ_t`). Without it a heavier `λ_t`
    /// gains on DAVIS and loses on the scenes (`λ_t` 2, seed 0: DAVIS
    /// 0.738, scenes 0.842 → 0.840): flow that lands on another surface
    /// carries the wrong label.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub temporal_contrast: bool,
    /// Link back along the backward flow the pixels of frame `t + 1` that
    /// no forward link reaches (cycle-consistent ones; ours, default true):
    /// where the forward flow spreads (an object coming closer) or rounds
    /// past a pixel, that pixel would otherwise have no edge to frame `t`.
    /// With `colour_bins` 16, against forward links only and 8 bins, mean J
    /// over seeds 0–2: DAVIS 0.739 → 0.741, the 33 scene and composite runs
    /// 0.852 → 0.858 (`docs/results.md`).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub temporal_backward: bool,
    /// Grey gradient (intensity in [0, 1] per grid px) above which a pixel's
    /// residual counts as geometric evidence (default 0.02).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub texture_gradient: f32,
    /// Side in grid px of the tiles of the local colour model (default 32;
    /// 0: one colour model for the whole video). Each pixel's model counts
    /// the seeds of its tile and the 8 around it, over `colour_frames`
    /// frames either side, with the video's model as a prior.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub colour_tile: usize,
    /// Frames either side of a pixel's own that its local colour model
    /// counts (default 2).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub colour_frames: usize,
    /// Histogram bins per RGB channel of the colour models (default 16,
    /// 2–32; 8 before, see `temporal_backward`; DAVIS seed 0 alone: 8 /
    /// 12 / 16 bins 0.740 / 0.740 / 0.742). Finer bins tell apart the
    /// dark shades that 8 put in one bin (a black swan on dark water).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub colour_bins: usize,
    /// Weight `w_r` of the superpixel vote (default 0 = off: composite J
    /// 0.624 → 0.720 at 1, but DAVIS 0.693 → 0.668, seed 0). Each
    /// colour superpixel averages the geometric evidence `g` over its `n`
    /// pixels (0 where a pixel has none) and all its pixels get
    /// `r = clamp(superpixel_gain · Σg / n, 0, 1)`: a superpixel mostly
    /// inside confident motion is moving as a whole, up to its image edges.
    /// Only positive: the static side already has L and `g` per pixel.
    #[cfg_attr(feature = "cli", arg(long = "superpixel-weight", required = false))]
    pub superpixel_weight: f32,
    /// Gain of the superpixel vote: a mean `g` of `1 / gain` is a
    /// confident vote (default 4).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub superpixel_gain: f32,
    /// Felzenszwalb–Huttenlocher scale `k` of the superpixels (RGB in
    /// [0, 1]; larger gives larger superpixels; default 1).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub superpixel_k: f32,
    /// Smallest superpixel in grid px (default 20).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub superpixel_min_size: usize,
    /// Mask propagation along the flow: frames `K` either side whose cut
    /// masks vote for each pixel (0 = off; see `objects::propagation_prior`).
    /// After the cut, each pixel follows its cycle-consistent flow up to
    /// `K` frames forward and backward; the frames it reaches that call it
    /// moving vote with weight `propagation_decay^(k−1)` at distance `k`,
    /// and the cut is solved again with `w_p·clamp(votes − 1, 0, 1)` added
    /// to the pixel's evidence: one other frame's detection carries
    /// nothing, two agreeing ones a confident vote.
    #[cfg_attr(
        feature = "cli",
        arg(long = "mask-propagation-frames", required = false)
    )]
    pub propagation_frames: usize,
    /// Weight `w_p` of the propagated votes in the cut (default 2: it
    /// outweighs one confident static term of the frame's own).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub propagation_weight: f32,
    /// Decay of a vote per frame of distance (default 0.8).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub propagation_decay: f32,
    /// Rounds of (propagate → cut) (default 2: a vote reaches
    /// `passes × K` frames from where the object was found).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub propagation_passes: usize,
    /// Weight of the static votes: the frames reached that call the pixel
    /// static vote the same way, `− static_weight · clamp(votes − 1, 0,
    /// 1)` (default 1; 0 = only moving is carried).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub propagation_static_weight: f32,
    /// Rounds of GrabCut's re-estimation (default 1; 0 = off): the colour
    /// models are learnt again from the cut's own masks (moving: the cut's
    /// moving pixels, no longer U or positive evidence) and the cut is
    /// solved again. Mean J over seeds 0–2 at `λ_s` 1: DAVIS 0.702 → 0.704, demo
    /// 0.897 → 0.904, fox + DAVIS composite 0.874 → 0.886; two rounds add
    /// nothing (DAVIS seed 0 0.712 → 0.711).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub colour_rounds: usize,
}

impl Default for ObjectOptions {
    fn default() -> Self {
        Self {
            method: ObjectMethod::GraphCut,
            geometry_weight: 1.0,
            geometry_zero: None,
            mlp_weight: 1.0,
            colour_weight: 1.0,
            smoothness: 3.0,
            temporal: 3.0,
            temporal_contrast: true,
            temporal_backward: true,
            texture_gradient: 0.02,
            colour_tile: 32,
            colour_frames: 2,
            colour_bins: 16,
            superpixel_weight: 0.0,
            superpixel_gain: 4.0,
            superpixel_k: 1.0,
            superpixel_min_size: 20,
            propagation_frames: 0,
            propagation_weight: 2.0,
            propagation_decay: 0.8,
            propagation_passes: 2,
            propagation_static_weight: 1.0,
            colour_rounds: 1,
        }
    }
}

impl ObjectOptions {
    /// Check the options.
    pub fn validate(&self) -> crate::Result<()> {
        let ok = [
            self.geometry_weight,
            self.mlp_weight,
            self.colour_weight,
            self.smoothness,
            self.temporal,
            self.texture_gradient,
            self.superpixel_weight,
            self.superpixel_gain,
            self.superpixel_k,
            self.propagation_weight,
            self.propagation_static_weight,
        ]
        .iter()
        .all(|w| w.is_finite() && *w >= 0.0);
        if !ok {
            return Err(crate::RomoError::Options(
                "objects: weights, superpixel_k and texture_gradient must be finite and >= 0"
                    .into(),
            ));
        }
        if self
            .geometry_zero
            .is_some_and(|z| !(z.is_finite() && z > 0.0))
        {
            return Err(crate::RomoError::Options(
                "objects: geometry_zero must be finite and > 0".into(),
            ));
        }
        if !(2..=32).contains(&self.colour_bins) {
            return Err(crate::RomoError::Options(
                "objects: colour_bins must be in 2..=32".into(),
            ));
        }
        if !(self.propagation_decay.is_finite() && (0.0..=1.0).contains(&self.propagation_decay)) {
            return Err(crate::RomoError::Options(
                "objects: propagation_decay must be in [0, 1]".into(),
            ));
        }
        Ok(())
    }
}

/// Everything the refinement reads, per frame on the working grid.
pub struct Evidence<'a> {
    /// Moving probability per frame.
    pub probs: &'a [Plane],
    /// Sampson residual per frame (px, NaN where none).
    pub s: Vec<&'a [f32]>,
    /// Mean flow magnitude per frame (px).
    pub v: Vec<f32>,
    /// Per frame: textured pixels.
    pub textured: &'a [Vec<bool>],
    /// Per frame: the last round's U (likely moving; also from tests that
    /// do not raise `s`, such as the three-view test).
    pub u: Vec<&'a [bool]>,
    /// Per frame: the last round's L (likely static).
    pub l: Vec<&'a [bool]>,
    /// Frames at the grid's size.
    pub rgb: &'a [Rgb],
    /// Forward flow of pair p (frames p → p + 1).
    pub fwd: &'a [Flow],
    /// Its cycle check.
    pub valid_f: &'a [Vec<bool>],
    /// Backward flow of pair p (frames p + 1 → p, on frame p + 1's grid).
    pub bwd: &'a [Flow],
    /// Its cycle check.
    pub valid_b: &'a [Vec<bool>],
    /// RoMo's U factor `u` (`LabelOptions::u_factor`).
    pub u_factor: f32,
    /// RoMo's L factor `l`.
    pub l_factor: f32,
    /// `ObjectOptions::geometry_zero`.
    pub geometry_zero: Option<f32>,
}

/// Capacity units per unit of evidence.
const SCALE: f32 = 100.0;

/// Pixel `i`'s colour histogram bin, `bins` per channel.
fn colour_bin(rgb: &Rgb, i: usize, bins: usize) -> usize {
    let q = |k: usize| ((rgb.c[k].data[i].clamp(0.0, 1.0) * bins as f32) as usize).min(bins - 1);
    (q(0) * bins + q(1)) * bins + q(2)
}

/// Geometric evidence `g` of one pixel (None: no residual, no texture or
/// no flow); 0 at `S = zero · v` (default `√(u·l)`).
fn geometry(s: f32, v: f32, textured: bool, u: f32, l: f32, zero: Option<f32>) -> Option<f32> {
    if !textured || !s.is_finite() || v <= 0.0 {
        return None;
    }
    let pivot = v * zero.unwrap_or((u * l).sqrt());
    let half = (u / l).sqrt().ln();
    Some(((s.max(1e-6) / pivot).ln() / half).clamp(-1.0, 1.0))
}

/// Geometric evidence `g` of pixel `i` of frame `t` with the labels
/// folded in: U from any test is confident motion (+1); a small residual
/// that a label test took out of L is no evidence (0); no residual, 0.
fn pixel_geometry(e: &Evidence, t: usize, i: usize) -> f32 {
    let g = geometry(
        e.s[t][i],
        e.v[t],
        e.textured[t][i],
        e.u_factor,
        e.l_factor,
        e.geometry_zero,
    )
    .unwrap_or(0.0);
    if e.u[t][i] {
        1.0
    } else if !e.l[t][i] && g <= -1.0 {
        0.0
    } else {
        g
    }
}

/// Unary evidence per frame and pixel (before the colour term), and
/// whether each pixel had geometric evidence.
fn base_evidence(e: &Evidence, o: &ObjectOptions) -> Vec<Vec<f32>> {
    (0..e.probs.len())
        .into_par_iter()
        .map(|t| {
            let p = &e.probs[t].data;
            (0..p.len())
                .map(|i| {
                    let q = p[i].clamp(1e-4, 1.0 - 1e-4);
                    let m = ((q / (1.0 - q)).ln().clamp(-4.0, 4.0)) / 4.0;
                    let g = pixel_geometry(e, t, i);
                    o.mlp_weight * m + o.geometry_weight * g
                })
                .collect()
        })
        .collect()
}

/// Superpixel vote `r` per frame and pixel (see
/// `ObjectOptions::superpixel_weight`).
fn superpixel_votes(e: &Evidence, o: &ObjectOptions) -> Vec<Vec<f32>> {
    (0..e.probs.len())
        .into_par_iter()
        .map(|t| {
            let lab = colour_segments(&e.rgb[t], o.superpixel_k, o.superpixel_min_size);
            let m = lab.iter().map(|r| *r as usize + 1).max().unwrap_or(0);
            let mut sum = vec![0f32; m];
            let mut size = vec![0u32; m];
            for (i, r) in lab.iter().enumerate() {
                sum[*r as usize] += pixel_geometry(e, t, i);
                size[*r as usize] += 1;
            }
            lab.iter()
                .map(|r| {
                    let r = *r as usize;
                    (o.superpixel_gain * sum[r] / size[r].max(1) as f32).clamp(0.0, 1.0)
                })
                .collect()
        })
        .collect()
}

/// Pseudo-samples of the video's colour model in each local model.
const COLOUR_PRIOR: f64 = 32.0;

/// Each frame's colour histogram bin per pixel.
fn colour_bins(e: &Evidence, bins: usize) -> Vec<Vec<u16>> {
    e.rgb[..e.probs.len()]
        .par_iter()
        .map(|rgb| {
            (0..rgb.c[0].data.len())
                .map(|i| colour_bin(rgb, i, bins) as u16)
                .collect()
        })
        .collect()
}

/// Colour evidence `c` per frame and pixel (`bins`: [`colour_bins`]): the
/// log ratio of a foreground and a background colour histogram, ÷ 2,
/// clamped to ±1. A pixel is a foreground seed when `fg_side(frame,
/// pixel)` (first U, or positive evidence and not L; in the re-estimation,
/// the cut's moving pixels), a background seed otherwise. With
/// `colour_tile` > 0 each pixel's histograms count the seeds of its tile and the 8 around it in the
/// frames within `colour_frames` of its own, plus the video's histograms
/// scaled to [`COLOUR_PRIOR`] samples: an object whose colour also occurs
/// elsewhere in the video (a tan animal before a tan wall) is still told
/// apart from what surrounds it, as in GrabCut's per-image models.
fn colour_evidence(
    e: &Evidence,
    bins: &[Vec<u16>],
    fg_side: &(dyn Fn(usize, usize) -> bool + Sync),
    o: &ObjectOptions,
) -> Vec<Vec<f32>> {
    let n = bins.len();
    let (w, h) = (e.probs[0].w, e.probs[0].h);
    let np = w * h;
    let nb = o.colour_bins.pow(3);
    let (mut gf, mut gb) = (vec![0f64; nb], vec![0f64; nb]);
    for (t, bt) in bins.iter().enumerate() {
        for (i, b) in bt.iter().enumerate() {
            if fg_side(t, i) {
                gf[*b as usize] += 1.0;
            } else {
                gb[*b as usize] += 1.0;
            }
        }
    }
    let (nf, nbg): (f64, f64) = (gf.iter().sum(), gb.iter().sum());
    if nf == 0.0 || nbg == 0.0 {
        return vec![vec![0.0; np]; n];
    }
    // The video's models, Laplace-smoothed.
    let pf: Vec<f64> = gf.iter().map(|c| (c + 1.0) / (nf + nb as f64)).collect();
    let pb: Vec<f64> = gb.iter().map(|c| (c + 1.0) / (nbg + nb as f64)).collect();
    let ratio = |f: f64, b: f64| ((f / b).ln() / 2.0).clamp(-1.0, 1.0) as f32;
    if o.colour_tile == 0 {
        let r: Vec<f32> = (0..nb).map(|b| ratio(pf[b], pb[b])).collect();
        return bins
            .par_iter()
            .map(|bt| bt.iter().map(|b| r[*b as usize]).collect())
            .collect();
    }
    let ts = o.colour_tile;
    let (tx, ty) = (w.div_ceil(ts), h.div_ceil(ts));
    let nt = tx * ty;
    let tile = |i: usize| (i / w / ts) * tx + (i % w) / ts;
    let k = o.colour_frames;
    (0..n)
        .into_par_iter()
        .map(|t| {
            // Per tile: foreground then background counts per bin over the
            // frames of the window.
            let mut win = vec![0u32; nt * 2 * nb];
            let first = t.saturating_sub(k);
            for (f, bf) in bins.iter().enumerate().take(t + k + 1).skip(first) {
                for (i, b) in bf.iter().enumerate() {
                    let side = usize::from(!fg_side(f, i));
                    win[(tile(i) * 2 + side) * nb + *b as usize] += 1;
                }
            }
            // Per tile: the histograms of its 3 × 3 neighbourhood, and the
            // ratio of each bin its own pixels use, computed once (most of
            // the bins are empty in a tile).
            let mut out = vec![0f32; np];
            let mut lf = vec![0u32; nb];
            let mut lb = vec![0u32; nb];
            let mut memo = vec![f32::NAN; nb];
            for yt in 0..ty {
                for xt in 0..tx {
                    lf.fill(0);
                    lb.fill(0);
                    for yy in yt.saturating_sub(1)..(yt + 2).min(ty) {
                        for xx in xt.saturating_sub(1)..(xt + 2).min(tx) {
                            let base = (yy * tx + xx) * 2 * nb;
                            for (s, v) in lf.iter_mut().zip(&win[base..base + nb]) {
                                *s += v;
                            }
                            for (s, v) in lb.iter_mut().zip(&win[base + nb..base + 2 * nb]) {
                                *s += v;
                            }
                        }
                    }
                    let total = |c: &[u32]| c.iter().map(|v| *v as f64).sum::<f64>();
                    let (sf, sb) = (total(&lf), total(&lb));
                    memo.fill(f32::NAN);
                    for y in yt * ts..((yt + 1) * ts).min(h) {
                        for x in xt * ts..((xt + 1) * ts).min(w) {
                            let b = bins[t][y * w + x] as usize;
                            if memo[b].is_nan() {
                                let f = (lf[b] as f64 + COLOUR_PRIOR * pf[b]) / (sf + COLOUR_PRIOR);
                                let g = (lb[b] as f64 + COLOUR_PRIOR * pb[b]) / (sb + COLOUR_PRIOR);
                                memo[b] = ratio(f, g);
                            }
                            out[y * w + x] = memo[b];
                        }
                    }
                }
            }
            out
        })
        .collect()
}

/// Moving (true) / static per frame and grid pixel: the minimum cut of the
/// space–time graph (module doc), then with `propagation_frames` > 0 the
/// rounds of mask propagation ([`propagation_prior`]), each re-solving the
/// cut with the propagated votes added to the evidence.
pub fn graph_cut(e: &Evidence, o: &ObjectOptions) -> Vec<Vec<bool>> {
    if e.probs.is_empty() {
        return Vec::new();
    }
    // The pairwise edges are the same in every cut; only terminals change.
    // Building them (partly serial) runs beside the unary evidence.
    let (mut net, (base, bins)) = rayon::join(
        || pairwise(e, o),
        || {
            let bins = if o.colour_weight > 0.0 {
                colour_bins(e, o.colour_bins)
            } else {
                Vec::new()
            };
            (evidence_without_colour(e, o), bins)
        },
    );
    // The colour term from seeds (`seeds(t, i)`: moving), added to `base`.
    let with_colour = |seeds: &(dyn Fn(usize, usize) -> bool + Sync)| {
        let mut a = base.clone();
        if o.colour_weight > 0.0 {
            add_scaled(
                &mut a,
                o.colour_weight,
                &colour_evidence(e, &bins, seeds, o),
            );
        }
        a
    };
    let mut a = with_colour(&|t, i| e.u[t][i] || (base[t][i] > 0.0 && !e.l[t][i]));
    let mut masks = solve(&mut net, &a);
    // GrabCut's re-estimation: the colour models learnt from the cut.
    if o.colour_weight > 0.0 {
        for _ in 0..o.colour_rounds {
            a = with_colour(&|t, i| masks[t][i]);
            masks = solve(&mut net, &a);
        }
    }
    if o.propagation_frames == 0 || o.propagation_weight <= 0.0 {
        return masks;
    }
    for _ in 0..o.propagation_passes {
        let mut with = a.clone();
        add_scaled(
            &mut with,
            o.propagation_weight,
            &propagation_prior(&masks, e, o),
        );
        masks = solve(&mut net, &with);
    }
    masks
}

/// Propagated votes per frame and pixel, in [0, 1]: the pixel follows its
/// flow from frame `t` up to `propagation_frames` frames forward (`fwd`)
/// and backward (`bwd`), one pair at a time, and stops where a step fails
/// the pair's cycle check (occluded or unreliable flow) or leaves the
/// frame. Each frame it reaches at distance `k` whose mask calls the
/// landing pixel moving adds `propagation_decay^(k−1)`; the vote is
/// `clamp(sum − 1, 0, 1)`, so a detection in one other frame alone never
/// spreads, and a frame's own mask is not counted.
pub fn propagation_prior(masks: &[Vec<bool>], e: &Evidence, o: &ObjectOptions) -> Vec<Vec<f32>> {
    let n = masks.len();
    let (w, h) = (e.probs[0].w, e.probs[0].h);
    let np = w * h;
    let k_max = o.propagation_frames;
    (0..n)
        .into_par_iter()
        .map(|t| {
            (0..np)
                .map(|i| {
                    let (mut votes, mut against) = (0f32, 0f32);
                    for forward in [true, false] {
                        let (mut x, mut y) = ((i % w) as f32, (i / w) as f32);
                        let mut j = i;
                        let mut weight = 1f32;
                        for k in 1..=k_max {
                            // Pair and flow from frame `from` to `to`.
                            let (flow, valid, to) = if forward {
                                let from = t + k - 1;
                                if from + 1 >= n || from >= e.fwd.len() {
                                    break;
                                }
                                (&e.fwd[from], &e.valid_f[from], from + 1)
                            } else {
                                let Some(to) = t.checked_sub(k) else { break };
                                if to >= e.bwd.len() {
                                    break;
                                }
                                (&e.bwd[to], &e.valid_b[to], to)
                            };
                            if !valid[j] {
                                break;
                            }
                            let (du, dv) = (flow.u.bilinear(x, y), flow.v.bilinear(x, y));
                            x += du;
                            y += dv;
                            let Some(next) = nearest_pixel(x, y, w, h) else {
                                break;
                            };
                            j = next;
                            if masks[to][j] {
                                votes += weight;
                            } else {
                                against += weight;
                            }
                            weight *= o.propagation_decay;
                        }
                    }
                    (votes - 1.0).clamp(0.0, 1.0)
                        - o.propagation_static_weight * (against - 1.0).clamp(0.0, 1.0)
                })
                .collect()
        })
        .collect()
}

/// The index of the pixel nearest to `(x, y)` on a `w × h` grid, if inside.
fn nearest_pixel(x: f32, y: f32, w: usize, h: usize) -> Option<usize> {
    let (xr, yr) = (x.round(), y.round());
    (xr >= 0.0 && yr >= 0.0 && xr < w as f32 && yr < h as f32)
        .then(|| yr as usize * w + xr as usize)
}

/// `a += w · b`, per frame and pixel.
fn add_scaled(a: &mut [Vec<f32>], w: f32, b: &[Vec<f32>]) {
    a.par_iter_mut().zip(b).for_each(|(at, bt)| {
        for (ai, bi) in at.iter_mut().zip(bt) {
            *ai += w * bi;
        }
    });
}

/// The geometric, MLP and superpixel terms of the unary evidence.
fn evidence_without_colour(e: &Evidence, o: &ObjectOptions) -> Vec<Vec<f32>> {
    let mut a = base_evidence(e, o);
    if o.superpixel_weight > 0.0 {
        add_scaled(&mut a, o.superpixel_weight, &superpixel_votes(e, o));
    }
    a
}

/// The minimum cut of the space–time graph `net` ([`pairwise`]) with
/// unary evidence `a` (the network keeps the flow for the next cut).
fn solve(net: &mut Network, a: &[Vec<f32>]) -> Vec<Vec<bool>> {
    let np = a.first().map_or(1, Vec::len).max(1);
    let terminals: Vec<i64> = a
        .par_iter()
        .flat_map_iter(|at| {
            at.iter().map(|ai| {
                let c = i64::from((ai.abs() * SCALE).round() as i32);
                if *ai > 0.0 { c } else { -c }
            })
        })
        .collect();
    net.solve(&terminals)
        .chunks(np)
        .map(|c| c.to_vec())
        .collect()
}

/// Squared RGB distance between pixel `i` of `a` and pixel `j` of `b`.
fn colour_d2(a: &Rgb, i: usize, b: &Rgb, j: usize) -> f32 {
    a.c.iter()
        .zip(&b.c)
        .map(|(pa, pb)| {
            let d = pa.data[i] - pb.data[j];
            d * d
        })
        .sum()
}

/// GrabCut's contrast factor `β = 1 / (2⟨|ΔI|²⟩)` from a sum of squared
/// colour differences over `count` edges.
fn contrast_beta(sum: f64, count: usize) -> f32 {
    1.0 / (2.0 * (sum / count.max(1) as f64).max(1e-8)) as f32
}

/// The space–time graph's pairwise edges (module doc), without terminals:
/// the edges of each frame and of each pair are made in parallel.
fn pairwise(e: &Evidence, o: &ObjectOptions) -> Network {
    let n = e.probs.len();
    let (w, h) = (e.probs[0].w, e.probs[0].h);
    let np = w * h;
    let mut parts: Vec<Vec<Edge>> = Vec::new();
    if o.smoothness > 0.0 {
        parts.par_extend(e.rgb.par_iter().take(n).enumerate().map(|(t, rgb)| {
            let d2 = |i: usize, j: usize| colour_d2(rgb, i, rgb, j);
            let mut sum = 0f64;
            let mut cnt = 0usize;
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    if x + 1 < w {
                        sum += d2(i, i + 1) as f64;
                        cnt += 1;
                    }
                    if y + 1 < h {
                        sum += d2(i, i + w) as f64;
                        cnt += 1;
                    }
                }
            }
            let beta = contrast_beta(sum, cnt);
            let cap = |i: usize, j: usize| -> i32 {
                (o.smoothness * SCALE * (-beta * d2(i, j)).exp()).round() as i32
            };
            let node = |i: usize| (t * np + i) as u32;
            let mut edges = Vec::with_capacity(2 * np);
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    if x + 1 < w {
                        let c = cap(i, i + 1);
                        edges.push((node(i), node(i + 1), c, c));
                    }
                    if y + 1 < h {
                        let c = cap(i, i + w);
                        edges.push((node(i), node(i + w), c, c));
                    }
                }
            }
            edges
        }));
    }
    if o.temporal > 0.0 {
        let pairs = e.fwd.len().min(n - 1).min(e.rgb.len().saturating_sub(1));
        parts.par_extend((0..pairs).into_par_iter().map(|p| {
            let (a, b) = (&e.rgb[p], &e.rgb[p + 1]);
            // Where pixel i's flow lands (nearest pixel), if in the frame.
            let land = |f: &Flow, i: usize| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                nearest_pixel(x + f.u.data[i], y + f.v.data[i], w, h)
            };
            // Each link (pixel of p, pixel of p + 1) with its squared
            // colour change (0 without the contrast term, where it is not
            // needed).
            let d2 = |i: usize, j: usize| {
                if o.temporal_contrast {
                    colour_d2(a, i, b, j)
                } else {
                    0.0
                }
            };
            let mut links: Vec<(usize, usize, f32)> = (0..np)
                .filter(|&i| e.valid_f[p][i])
                .filter_map(|i| land(&e.fwd[p], i).map(|j| (i, j, d2(i, j))))
                .collect();
            if o.temporal_backward && p < e.bwd.len() {
                let mut reached = vec![false; np];
                for l in &links {
                    reached[l.1] = true;
                }
                links.extend(
                    (0..np)
                        .filter(|&j| !reached[j] && e.valid_b[p][j])
                        .filter_map(|j| land(&e.bwd[p], j).map(|i| (i, j, d2(i, j)))),
                );
            }
            let beta = if o.temporal_contrast {
                contrast_beta(links.iter().map(|l| l.2 as f64).sum(), links.len())
            } else {
                0.0
            };
            links
                .into_iter()
                .map(|(i, j, d2)| {
                    let c = (o.temporal * SCALE * (-beta * d2).exp()).round() as i32;
                    ((p * np + i) as u32, ((p + 1) * np + j) as u32, c, c)
                })
                .collect()
        }));
    }
    Network::new(n * np, &parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The evidence of a single frame (no flow), RoMo's default factors.
    fn one_frame<'a>(
        probs: &'a [Plane],
        s: &'a [f32],
        v: f32,
        textured: &'a [Vec<bool>],
        u: &'a [bool],
        l: &'a [bool],
        rgb: &'a [Rgb],
    ) -> Evidence<'a> {
        Evidence {
            probs,
            s: vec![s],
            v: vec![v],
            textured,
            u: vec![u],
            l: vec![l],
            rgb,
            fwd: &[],
            valid_f: &[],
            bwd: &[],
            valid_b: &[],
            u_factor: 1.0,
            l_factor: 0.1,
            geometry_zero: None,
        }
    }

    /// The evidence of a video with forward flow only (each pair's flow and
    /// its cycle-valid pixels), `v` = 1 in every frame, no U and RoMo's
    /// default factors.
    fn forward_only<'a>(
        probs: &'a [Plane],
        s: Vec<&'a [f32]>,
        textured: &'a [Vec<bool>],
        no_u: &'a [bool],
        l: Vec<&'a [bool]>,
        rgb: &'a [Rgb],
        (fwd, valid_f): (&'a [Flow], &'a [Vec<bool>]),
    ) -> Evidence<'a> {
        Evidence {
            probs,
            v: vec![1.0; s.len()],
            u: vec![no_u; s.len()],
            s,
            textured,
            l,
            rgb,
            fwd,
            valid_f,
            bwd: &[],
            valid_b: &[],
            u_factor: 1.0,
            l_factor: 0.1,
            geometry_zero: None,
        }
    }

    /// Two frames' evidence: frame 0's residual is over the U threshold
    /// and its MLP sure that `obj` moves, with small residuals elsewhere
    /// (L); frame 1's residual is 0.28·v everywhere (between the
    /// thresholds, a little on the static side), its MLP static.
    struct SureThenUnsure {
        probs: Vec<Plane>,
        s0: Vec<f32>,
        s1: Vec<f32>,
        textured: Vec<Vec<bool>>,
        no: Vec<bool>,
        l0: Vec<bool>,
    }

    impl SureThenUnsure {
        fn new(w: usize, h: usize, obj: impl Fn(usize) -> bool + Sync) -> Self {
            let s0: Vec<f32> = (0..w * h)
                .map(|i| if obj(i) { 3.0 } else { 0.01 })
                .collect();
            Self {
                probs: vec![
                    Plane::from_fn(w, h, |x, y| if obj(y * w + x) { 0.98 } else { 0.1 }),
                    Plane::filled(w, h, 0.1),
                ],
                l0: s0.iter().map(|r| *r < 0.1).collect(),
                s0,
                s1: vec![0.28; w * h],
                textured: vec![vec![true; w * h]; 2],
                no: vec![false; w * h],
            }
        }

        /// With frames `rgb` and forward flow `fwd`.
        fn evidence<'a>(
            &'a self,
            rgb: &'a [Rgb],
            fwd: (&'a [Flow], &'a [Vec<bool>]),
        ) -> Evidence<'a> {
            forward_only(
                &self.probs,
                vec![&self.s0, &self.s1],
                &self.textured,
                &self.no,
                vec![&self.l0, &self.no],
                rgb,
                fwd,
            )
        }
    }

    fn flat_rgb(w: usize, h: usize, f: impl Fn(usize, usize) -> f32 + Sync) -> Rgb {
        let p = Plane::from_fn(w, h, f);
        Rgb {
            c: [p.clone(), p.clone(), p],
        }
    }

    /// A square moves right by 2 px per frame over a static textured
    /// background. Its residual is large in the last frames and weak in
    /// the first; the MLP saw nothing. The cut finds the square in every
    /// frame (the temporal edges carry it back to the first frames) and no
    /// background.
    #[test]
    fn evidence_of_later_frames_carries_to_the_first() {
        let (w, h, n) = (40, 30, 6);
        let sq = |t: usize, x: usize, y: usize| {
            let x0 = 8 + 2 * t;
            (x0..x0 + 10).contains(&x) && (10..20).contains(&y)
        };
        let rgb: Vec<Rgb> = (0..n)
            .map(|t| {
                flat_rgb(w, h, |x, y| {
                    if sq(t, x, y) {
                        0.8 + 0.1 * ((x + y) % 2) as f32
                    } else {
                        0.2 + 0.1 * ((x * 3 + y) % 4) as f32
                    }
                })
            })
            .collect();
        let fwd: Vec<Flow> = (0..n - 1)
            .map(|t| {
                let mut f = Flow::zeros(w, h);
                for y in 0..h {
                    for x in 0..w {
                        if sq(t, x, y) {
                            f.u.data[y * w + x] = 2.0;
                        }
                    }
                }
                f
            })
            .collect();
        // Background the square covers in the next frame fails the cycle
        // check (occluded).
        let valid_f: Vec<Vec<bool>> = (0..n - 1)
            .map(|t| {
                (0..w * h)
                    .map(|i| sq(t, i % w, i / w) || !sq(t + 1, i % w, i / w))
                    .collect()
            })
            .collect();
        // Residual inside the square (v = 1): weak (between L and U) in
        // frames 0–2, strong after; background at 0.01·v.
        let s: Vec<Vec<f32>> = (0..n)
            .map(|t| {
                (0..w * h)
                    .map(|i| {
                        if sq(t, i % w, i / w) {
                            if t < 3 { 0.25 } else { 3.0 }
                        } else {
                            0.01
                        }
                    })
                    .collect()
            })
            .collect();
        let probs = vec![Plane::filled(w, h, 0.1); n];
        let textured = vec![vec![true; w * h]; n];
        let no = vec![false; w * h];
        // L: the background (residual below l·v).
        let l: Vec<Vec<bool>> = s
            .iter()
            .map(|f| f.iter().map(|r| *r < 0.1).collect())
            .collect();
        let e = forward_only(
            &probs,
            s.iter().map(|v| v.as_slice()).collect(),
            &textured,
            &no,
            l.iter().map(|v| v.as_slice()).collect(),
            &rgb,
            (&fwd, &valid_f),
        );
        let o = ObjectOptions::default();
        let m = graph_cut(&e, &o);
        for (t, mt) in m.iter().enumerate() {
            for (i, mi) in mt.iter().enumerate() {
                assert_eq!(*mi, sq(t, i % w, i / w), "frame {t} pixel {i}");
            }
        }
        // Without the temporal edges and the colour model, the first
        // frames' weak evidence alone loses against the MLP.
        let off = ObjectOptions {
            temporal: 0.0,
            colour_weight: 0.0,
            ..o
        };
        let m = graph_cut(&e, &off);
        assert!(m[0].iter().all(|b| !b));
        assert!((0..w * h).filter(|&i| m[5][i]).count() == 100);
    }

    /// A flow link whose two ends differ in colour carries little
    /// (`temporal_contrast`). A bright square moves confidently in frame 0
    /// and is gone in frame 1, but the flow (zero, cycle-consistent, as a
    /// flow that missed the motion) links its pixels to the background it
    /// uncovered, whose own evidence is mildly static. Links of weight
    /// `λ_t` pull that background into the mask; weighted by the colour
    /// difference along them they do not, and the square stays found.
    #[test]
    fn a_flow_link_onto_another_colour_carries_little() {
        let (w, h) = (40, 30);
        let sq = |i: usize| (8..18).contains(&(i % w)) && (10..20).contains(&(i / w));
        let bg = |x: usize, y: usize| 0.2 + 0.1 * ((x * 3 + y) % 4) as f32;
        let rgb = vec![
            flat_rgb(w, h, |x, y| if sq(y * w + x) { 0.8 } else { bg(x, y) }),
            flat_rgb(w, h, bg),
        ];
        let fwd = vec![Flow::zeros(w, h)];
        let valid_f = vec![vec![true; w * h]];
        let d = SureThenUnsure::new(w, h, sq);
        let e = d.evidence(&rgb, (&fwd, &valid_f));
        let o = ObjectOptions {
            colour_weight: 0.0,
            ..ObjectOptions::default()
        };
        let m = graph_cut(&e, &o);
        assert!(
            (0..w * h).all(|i| m[0][i] == sq(i)),
            "frame 0 is the square"
        );
        assert!(m[1].iter().all(|b| !b), "frame 1 has no square");
        let plain = ObjectOptions {
            temporal_contrast: false,
            ..o
        };
        let m = graph_cut(&e, &plain);
        let dragged = (0..w * h).filter(|&i| sq(i) && m[1][i]).count();
        assert_eq!(
            dragged, 100,
            "without the contrast the links drag the background along"
        );
    }

    /// A moving square doubles its width from frame 0 to frame 1 (it comes
    /// closer). Frame 0 is sure it moves; frame 1 leans static. The forward
    /// flow spreads the square's 10 columns over every other one of the 20
    /// it covers in frame 1, so half of frame 1's square has no link to
    /// frame 0; the backward flow links every one of them back.
    #[test]
    fn backward_links_reach_what_the_forward_flow_spreads_past() {
        let (w, h) = (40, 30);
        let rows = |y: usize| (10..20).contains(&y);
        let sq0 = |x: usize, y: usize| (8..18).contains(&x) && rows(y);
        let sq1 = |x: usize, y: usize| (8..28).contains(&x) && rows(y);
        let bg = |x: usize, y: usize| 0.2 + 0.1 * ((x * 3 + y) % 4) as f32;
        let rgb = vec![
            flat_rgb(w, h, |x, y| if sq0(x, y) { 0.8 } else { bg(x, y) }),
            flat_rgb(w, h, |x, y| if sq1(x, y) { 0.8 } else { bg(x, y) }),
        ];
        // Forward: column 8 + k of the square lands on 8 + 2k; the
        // background the grown square covers in frame 1 fails the cycle
        // check. Backward: column 8 + k of frame 1's square lands on
        // 8 + k / 2.
        let fwd = vec![Flow {
            u: Plane::from_fn(w, h, |x, y| if sq0(x, y) { (x - 8) as f32 } else { 0.0 }),
            v: Plane::filled(w, h, 0.0),
        }];
        let valid_f = vec![
            (0..w * h)
                .map(|i| !sq1(i % w, i / w) || sq0(i % w, i / w))
                .collect(),
        ];
        let bwd = vec![Flow {
            u: Plane::from_fn(w, h, |x, y| {
                if sq1(x, y) {
                    (8 + (x - 8) / 2) as f32 - x as f32
                } else {
                    0.0
                }
            }),
            v: Plane::filled(w, h, 0.0),
        }];
        let valid_b = vec![vec![true; w * h]];
        let d = SureThenUnsure::new(w, h, |i| sq0(i % w, i / w));
        let e = Evidence {
            bwd: &bwd,
            valid_b: &valid_b,
            ..d.evidence(&rgb, (&fwd, &valid_f))
        };
        // No spatial edges: only the links can carry the square.
        let both = ObjectOptions {
            colour_weight: 0.0,
            smoothness: 0.0,
            ..ObjectOptions::default()
        };
        let forward = ObjectOptions {
            temporal_backward: false,
            ..both
        };
        let moving = |o: &ObjectOptions| {
            let m = graph_cut(&e, o);
            assert!((0..w * h).all(|i| m[0][i] == sq0(i % w, i / w)));
            assert!((0..w * h).all(|i| !m[1][i] || sq1(i % w, i / w)));
            m[1].iter().filter(|b| **b).count()
        };
        assert_eq!(moving(&forward), 100, "every other column");
        assert_eq!(moving(&both), 200, "the whole grown square");
    }

    /// GrabCut's re-estimation (`colour_rounds`): the MLP paints a ring of
    /// background colour around a moving square and a small island of the
    /// same colour inside a static patch of another colour. The first
    /// colour model takes both as moving seeds, so background colour looks
    /// half moving and the island is cut as moving. The cut drops the ring
    /// (it is tied to the static background around it); the model learnt
    /// again from the cut is purer and the second cut drops the island too.
    #[test]
    fn colour_models_learnt_from_the_cut_drop_a_false_island() {
        let (w, h) = (48, 40);
        let obj = |x: usize, y: usize| (6..18).contains(&x) && (6..18).contains(&y);
        let ring = |x: usize, y: usize| (4..20).contains(&x) && (4..20).contains(&y) && !obj(x, y);
        let patch = |x: usize, y: usize| (28..44).contains(&x) && (20..36).contains(&y);
        let island = |x: usize, y: usize| (34..39).contains(&x) && (26..31).contains(&y);
        let rgb = vec![flat_rgb(w, h, |x, y| {
            if obj(x, y) {
                0.8
            } else if patch(x, y) && !island(x, y) {
                0.5
            } else {
                0.2
            }
        })];
        let at = |i: usize| (i % w, i / w);
        let s: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = at(i);
                if obj(x, y) {
                    3.0
                } else if ring(x, y) || island(x, y) {
                    f32::NAN
                } else {
                    0.01
                }
            })
            .collect();
        let probs = vec![Plane::from_fn(w, h, |x, y| {
            if obj(x, y) || island(x, y) {
                0.88
            } else if ring(x, y) {
                0.8
            } else {
                0.1
            }
        })];
        let u: Vec<bool> = (0..w * h).map(|i| obj(at(i).0, at(i).1)).collect();
        let l: Vec<bool> = s.iter().map(|r| *r < 0.1).collect();
        let textured = vec![vec![true; w * h]];
        let e = one_frame(&probs, &s, 1.0, &textured, &u, &l, &rgb);
        let count = |m: &[bool], f: &dyn Fn(usize, usize) -> bool| {
            (0..w * h).filter(|&i| m[i] && f(at(i).0, at(i).1)).count()
        };
        let once = ObjectOptions {
            colour_rounds: 0,
            ..Default::default()
        };
        let m = graph_cut(&e, &once);
        assert_eq!(count(&m[0], &obj), 144);
        assert_eq!(count(&m[0], &ring), 0);
        assert_eq!(count(&m[0], &island), 25);
        let again = ObjectOptions {
            colour_rounds: 1,
            ..once
        };
        let m = graph_cut(&e, &again);
        let wrong: Vec<(usize, usize)> = (0..w * h)
            .filter(|&i| m[0][i] != obj(at(i).0, at(i).1))
            .map(at)
            .collect();
        assert!(wrong.is_empty(), "{wrong:?}");
    }

    /// An object with sparse confident motion (every 10th pixel U, the
    /// rest with residuals exactly between the L and U thresholds) that the
    /// MLP calls static: without the superpixel vote the cut finds less
    /// than a third of it; with it the whole object and no background.
    #[test]
    fn superpixel_vote_completes_an_object_with_sparse_evidence() {
        let (w, h) = (40, 30);
        let obj = |i: usize| (10..22).contains(&(i % w)) && (8..20).contains(&(i / w));
        let tex = |x: usize, y: usize| 0.02 * ((x * 7 + y * 3) % 3) as f32;
        let rgb = vec![flat_rgb(w, h, |x, y| {
            (if obj(y * w + x) { 0.8 } else { 0.2 }) + tex(x, y)
        })];
        let v = 1.0f32;
        let mid = v * 0.1f32.sqrt();
        let s: Vec<f32> = (0..w * h)
            .map(|i| if obj(i) { mid } else { 0.01 })
            .collect();
        let u: Vec<bool> = (0..w * h).map(|i| obj(i) && i % 10 == 0).collect();
        let l: Vec<bool> = (0..w * h).map(|i| !obj(i)).collect();
        let probs = vec![Plane::filled(w, h, 0.3)];
        let textured = vec![vec![true; w * h]];
        let e = one_frame(&probs, &s, v, &textured, &u, &l, &rgb);
        let o = ObjectOptions {
            colour_weight: 0.0,
            temporal: 0.0,
            superpixel_weight: 1.0,
            ..Default::default()
        };
        let m = graph_cut(&e, &o);
        let bad: Vec<(usize, usize)> = (0..w * h)
            .filter(|&i| m[0][i] != obj(i))
            .map(|i| (i % w, i / w))
            .collect();
        assert!(bad.is_empty(), "{bad:?}");
        let off = ObjectOptions {
            superpixel_weight: 0.0,
            ..o
        };
        let m = graph_cut(&e, &off);
        let found = (0..w * h).filter(|&i| m[0][i] && obj(i)).count();
        assert!(found < 144 / 3, "{found}");
        assert!((0..w * h).all(|i| !m[0][i] || obj(i)));
    }

    /// A video of `n` frames `w × h` on a static camera: one object
    /// square of side 10 at `x0(t)`, rows 10..20, and owned copies of
    /// everything [`Evidence`] borrows. The square's flow is `x0(t+1) −
    /// x0(t)` forward (and its negative backward); background that the
    /// square covers or uncovers fails the cycle check.
    struct Video {
        probs: Vec<Plane>,
        s: Vec<Vec<f32>>,
        textured: Vec<Vec<bool>>,
        u: Vec<Vec<bool>>,
        l: Vec<Vec<bool>>,
        rgb: Vec<Rgb>,
        fwd: Vec<Flow>,
        valid_f: Vec<Vec<bool>>,
        bwd: Vec<Flow>,
        valid_b: Vec<Vec<bool>>,
    }

    impl Video {
        fn new(w: usize, h: usize, x0: &[usize]) -> Self {
            let n = x0.len();
            let sq = |t: usize, i: usize| {
                (x0[t]..x0[t] + 10).contains(&(i % w)) && (10..20).contains(&(i / w))
            };
            let rgb = (0..n)
                .map(|t| {
                    flat_rgb(w, h, |x, y| {
                        if sq(t, y * w + x) {
                            0.8 + 0.1 * ((x + y) % 2) as f32
                        } else {
                            0.2 + 0.1 * ((x * 3 + y) % 4) as f32
                        }
                    })
                })
                .collect();
            let pair = |t: usize, from: usize, d: f32| {
                let mut f = Flow::zeros(w, h);
                let mut valid = vec![true; w * h];
                for (i, ok) in valid.iter_mut().enumerate() {
                    if sq(from, i) {
                        f.u.data[i] = d;
                    } else if sq(t, i) || sq(t + 1, i) {
                        *ok = false;
                    }
                }
                (f, valid)
            };
            let (fwd, valid_f) = (0..n - 1)
                .map(|t| pair(t, t, x0[t + 1] as f32 - x0[t] as f32))
                .unzip();
            let (bwd, valid_b) = (0..n - 1)
                .map(|t| pair(t, t + 1, x0[t] as f32 - x0[t + 1] as f32))
                .unzip();
            Video {
                probs: vec![Plane::filled(w, h, 0.1); n],
                s: vec![vec![0.01; w * h]; n],
                textured: vec![vec![true; w * h]; n],
                u: vec![vec![false; w * h]; n],
                l: vec![vec![true; w * h]; n],
                rgb,
                fwd,
                valid_f,
                bwd,
                valid_b,
            }
        }

        fn evidence(&self) -> Evidence<'_> {
            Evidence {
                probs: &self.probs,
                s: self.s.iter().map(|v| v.as_slice()).collect(),
                v: vec![1.0; self.probs.len()],
                textured: &self.textured,
                u: self.u.iter().map(|v| v.as_slice()).collect(),
                l: self.l.iter().map(|v| v.as_slice()).collect(),
                rgb: &self.rgb,
                fwd: &self.fwd,
                valid_f: &self.valid_f,
                bwd: &self.bwd,
                valid_b: &self.valid_b,
                u_factor: 1.0,
                l_factor: 0.1,
                geometry_zero: None,
            }
        }
    }

    /// The object stands still in frames 0–2 (the MLP calls it static and
    /// its residual is just above L's threshold) and moves 2 px per frame
    /// in frames 3–9 (U). The cut alone finds it in frames 3–9 only; with
    /// mask propagation of the moving votes the later frames carry it back
    /// to frames 0–2, with no background.
    #[test]
    fn propagation_finds_an_object_in_the_frames_where_it_stands_still() {
        let (w, h, n) = (48, 30, 10);
        let x0: Vec<usize> = (0..n).map(|t: usize| 4 + 2 * t.saturating_sub(2)).collect();
        let mut vid = Video::new(w, h, &x0);
        let sq = |t: usize, i: usize| {
            (x0[t]..x0[t] + 10).contains(&(i % w)) && (10..20).contains(&(i / w))
        };
        for t in 0..n {
            for i in 0..w * h {
                if !sq(t, i) {
                    continue;
                }
                vid.l[t][i] = false;
                if t >= 3 {
                    vid.s[t][i] = 3.0;
                    vid.u[t][i] = true;
                } else {
                    vid.s[t][i] = 0.15;
                    vid.probs[t].data[i] = 0.05;
                }
            }
        }
        let e = vid.evidence();
        // The temporal weight this test was built for: heavier links carry
        // frames 0–2's static evidence into frame 3 without propagation.
        let off = ObjectOptions {
            colour_weight: 0.0,
            temporal: 1.0,
            ..Default::default()
        };
        let found = |m: &[Vec<bool>], t: usize| (0..w * h).filter(|&i| m[t][i] && sq(t, i)).count();
        let wrong = |m: &[Vec<bool>], t: usize| (0..w * h).filter(|&i| m[t][i] != sq(t, i)).count();
        let m = graph_cut(&e, &off);
        for t in 3..n {
            assert_eq!(wrong(&m, t), 0, "frame {t}");
        }
        for t in 0..3 {
            assert!(found(&m, t) < 20, "frame {t}: {}", found(&m, t));
        }
        let on = ObjectOptions {
            propagation_frames: 4,
            propagation_static_weight: 0.0,
            ..off
        };
        let m = graph_cut(&e, &on);
        for t in 0..n {
            assert_eq!(wrong(&m, t), 0, "frame {t}");
        }
        // The votes themselves: frame 2 sees the object moving in frames
        // 3–6 of the first cut (1 + 0.8 + 0.64 + 0.51 − 1, clamped to 1);
        // frame 0 only in frames 3 and 4 (0.64 + 0.51 − 1).
        let first = graph_cut(&e, &off);
        let prior = propagation_prior(&first, &e, &on);
        let centre = |t: usize| 15 * w + x0[t] + 5;
        assert_eq!(prior[2][centre(2)], 1.0);
        assert!(
            (prior[0][centre(0)] - 0.152).abs() < 1e-3,
            "{}",
            prior[0][centre(0)]
        );
        assert_eq!(prior[0][15 * w + 30], 0.0);
    }

    /// A static patch with confident motion evidence and a colour of its
    /// own in frame 5 only (a false positive) stays in frame 5 and does not
    /// spread to the other frames: no other frame agrees with it.
    #[test]
    fn propagation_does_not_spread_a_single_frame_detection() {
        let (w, h, n) = (48, 30, 10);
        let x0 = vec![4; n];
        let mut vid = Video::new(w, h, &x0);
        let patch = |i: usize| (30..38).contains(&(i % w)) && (4..12).contains(&(i / w));
        for i in (0..w * h).filter(|&i| patch(i)) {
            for c in &mut vid.rgb[5].c {
                c.data[i] = 0.7;
            }
            vid.s[5][i] = 3.0;
            vid.u[5][i] = true;
            vid.l[5][i] = false;
            vid.probs[5].data[i] = 0.99;
        }
        // The square is a true object found in every frame.
        for t in 0..n {
            for i in 0..w * h {
                if (4..14).contains(&(i % w)) && (10..20).contains(&(i / w)) {
                    vid.s[t][i] = 3.0;
                    vid.u[t][i] = true;
                    vid.l[t][i] = false;
                }
            }
        }
        let e = vid.evidence();
        for static_weight in [0.0, 1.0] {
            let o = ObjectOptions {
                propagation_frames: 4,
                propagation_static_weight: static_weight,
                ..Default::default()
            };
            let m = graph_cut(&e, &o);
            let count = |t: usize| (0..w * h).filter(|&i| m[t][i] && patch(i)).count();
            if static_weight == 0.0 {
                assert_eq!(count(5), 64);
            }
            for t in (0..n).filter(|t| *t != 5) {
                assert_eq!(count(t), 0, "frame {t}");
                assert!((0..w * h).filter(|&i| m[t][i]).count() == 100, "frame {t}");
            }
            let first = graph_cut(
                &e,
                &ObjectOptions {
                    propagation_frames: 0,
                    ..o.clone()
                },
            );
            assert_eq!((0..w * h).filter(|&i| first[5][i] && patch(i)).count(), 64);
            let prior = propagation_prior(&first, &e, &o);
            for t in (0..n).filter(|t| *t != 5) {
                assert!(
                    (0..w * h).all(|i| !patch(i) || prior[t][i] <= 0.0),
                    "frame {t}"
                );
            }
        }
    }

    #[test]
    fn a_geometry_zero_that_is_not_positive_is_refused() {
        for z in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            let o = ObjectOptions {
                geometry_zero: Some(z),
                ..Default::default()
            };
            assert!(o.validate().is_err(), "{z}");
        }
        let o = ObjectOptions {
            geometry_zero: Some(1.0),
            ..Default::default()
        };
        assert!(o.validate().is_ok());
    }

    /// A near-black object (0.05) on dark ground (0.10), each side its
    /// own seeds: 8 bins per channel put both in bin 0 and the colour term
    /// cannot tell them apart; 16 bins give the object a positive and the
    /// ground a negative term.
    #[test]
    fn finer_colour_bins_tell_dark_shades_apart() {
        let (w, h) = (20, 10);
        let obj = |i: usize| i % w < 5;
        let rgb = vec![flat_rgb(w, h, |x, _| if x < 5 { 0.05 } else { 0.10 })];
        let probs = vec![Plane::filled(w, h, 0.5)];
        let s = vec![f32::NAN; w * h];
        let textured = vec![vec![true; w * h]];
        let no = vec![false; w * h];
        let e = one_frame(&probs, &s, 1.0, &textured, &no, &no, &rgb);
        let term = |bins: usize, tile: usize| {
            let o = ObjectOptions {
                colour_bins: bins,
                colour_tile: tile,
                ..ObjectOptions::default()
            };
            colour_evidence(&e, &colour_bins(&e, bins), &|_, i| obj(i), &o).remove(0)
        };
        let coarse = term(8, 0);
        assert!(coarse.iter().all(|c| *c == coarse[0]), "one bin, one value");
        // The video's model, and local models on 8-px tiles.
        for tile in [0, 8] {
            let fine = term(16, tile);
            assert!(
                (0..w * h).all(|i| (fine[i] > 0.5) == obj(i) && (fine[i] < -0.5) != obj(i)),
                "tile {tile}: {fine:?}"
            );
        }
        let refused = ObjectOptions {
            colour_bins: 33,
            ..ObjectOptions::default()
        };
        assert!(refused.validate().is_err());
    }

    /// A textureless pixel's residual is no evidence.
    #[test]
    fn geometry_needs_texture_and_sits_between_the_thresholds() {
        assert_eq!(geometry(5.0, 1.0, false, 1.0, 0.1, None), None);
        assert_eq!(geometry(f32::NAN, 1.0, true, 1.0, 0.1, None), None);
        let g = |s| geometry(s, 2.0, true, 1.0, 0.1, None).unwrap();
        assert!((g(2.0) - 1.0).abs() < 1e-5);
        assert!((g(0.2) + 1.0).abs() < 1e-5);
        assert!(g(2.0 * 0.1f32.sqrt()).abs() < 1e-5);
        assert_eq!(g(100.0), 1.0);
        // Zero at the U threshold: the same scale, shifted.
        let z = |s| geometry(s, 2.0, true, 1.0, 0.1, Some(1.0)).unwrap();
        assert!(z(2.0).abs() < 1e-5);
        assert!((z(2.0 * 0.1f32.sqrt()) + 1.0).abs() < 1e-5);
        assert!((z(2.0 * 10f32.sqrt()) - 1.0).abs() < 1e-5);
    }
}
