//! The RoMo pipeline on a sequence of frames (`docs/design.md`, "The pipeline"), on a
//! low-resolution working grid; [`crate::scene`] adds file I/O and
//! full-resolution refinement.
//!
//! Working resolutions: the MLP, labels and features live on a grid whose
//! long side is `grid_max_side` (≈ ¼ of a DAVIS frame); flow is computed on
//! frames at `flow_scale` × that grid and resampled to it.

use crate::exposure::Exposure;
use crate::features::{FeatureExtractor, FeatureMap, standardise};
use crate::flow::dis::DisOptions;
use crate::flow::{Flow, FlowEstimator};
use crate::geometry::robust::{FitReport, ModelSelection};
use crate::labels::{
    FrameLabels, LabelOptions, NoFit, PairResult, Side, apply_three_view, cycle_valid,
    drop_unreliable_fits, fit_pair, frame_labels, occlusion_violations, propagate_u,
    three_view_residuals, u_majority,
};
use crate::mlp::{Label, Mlp, MlpOptions, TrainReport, train, train_restarts};
use crate::objects::{Evidence, ObjectMethod, graph_cut};
use crate::plane::{Plane, Rgb};
use crate::refine::{RefineOptions, temporal_smooth, temporal_smooth_flow};
use crate::regions::{RegionOptions, complete, flow_segments};
use crate::{Result, RomoError};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

/// Which feature extractor the pipeline uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FeatureBackend {
    /// The built-in hand-made descriptor (default).
    Hand,
    /// An ONNX encoder (XFeat layout; needs feature `onnx`), plus the
    /// hand-made descriptor concatenated.
    Onnx {
        /// Path of the `.onnx` model.
        model: PathBuf,
    },
}

impl FeatureBackend {
    /// `--onnx-features MODEL`: the ONNX encoder at `model`.
    pub fn parse_onnx(model: &str) -> std::result::Result<Self, std::convert::Infallible> {
        Ok(Self::Onnx {
            model: model.into(),
        })
    }
}

/// Which optical-flow estimator the pipeline uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum FlowBackend {
    /// The built-in DIS (`RomoOptions::flow`; default).
    #[default]
    Dis,
    /// A RAFT-style ONNX model (needs feature `onnx`; signature in
    /// [`crate::onnx`]; input scale `RomoOptions::onnx_flow_scale`).
    Onnx {
        /// Path of the `.onnx` model.
        model: PathBuf,
    },
}

impl FlowBackend {
    /// `--onnx-flow MODEL`: the ONNX flow model at `model`.
    pub fn parse_onnx(model: &str) -> std::result::Result<Self, std::convert::Infallible> {
        Ok(Self::Onnx {
            model: model.into(),
        })
    }
}

/// All RoMo options. `Default` gives the paper's settings where the paper
/// states them (see each sub-struct).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(default)]
pub struct RomoOptions {
    /// Long side of the working grid in px (default 256). 384 (flow on
    /// 768 px frames) gave DAVIS mean J 0.738 instead of 0.734 (seeds 0–2,
    /// before the cut's colour-weighted flow links) at half the speed
    /// (`docs/results.md`).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub grid_max_side: usize,
    /// Flow is computed on frames of `flow_scale` × the grid (default 2).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub flow_scale: usize,
    /// Built-in flow parameters (DIS; default [`DisOptions::masks`], which
    /// is `DisOptions::default()` and finer than OpenCV's MEDIUM: a partial
    /// `flow` object in JSON overrides fields of that preset).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub flow: DisOptions,
    /// Flow estimator (default: the built-in DIS). `--onnx-flow MODEL`: an
    /// ONNX optical-flow model instead, two [1, 3, H, W] RGB images in, a
    /// [1, 2, h, w] flow (or [1, 4, h, w]: forward, then backward) out, e.g.
    /// GMFlow from `scripts/export_gmflow_onnx.py`; frames are padded (or
    /// shrunk) to its fixed input size. Needs a build with `--features
    /// onnx` and ORT_DYLIB_PATH.
    #[cfg_attr(feature = "cli", arg(long = "onnx-flow", value_name = "MODEL", value_parser = FlowBackend::parse_onnx, required = false))]
    pub flow_backend: FlowBackend,
    /// Pixel values in [0, 1] are multiplied by this for an ONNX flow model
    /// (default 1; 255 for RAFT exports that take 0–255).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub onnx_flow_scale: f32,
    /// Cycle check, robust geometry and U/L thresholds.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub labels: LabelOptions,
    /// MLP training.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub mlp: MlpOptions,
    /// Rounds of (fit → label → train) (paper: 2).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub iterations: usize,
    /// Refinement to full resolution.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub refine: RefineOptions,
    /// Region completion over flow segments (ours; part of refinement).
    #[cfg_attr(feature = "cli", command(flatten))]
    pub regions: RegionOptions,
    /// Content fixed in the image marked moving (ours; [`crate::overlay`]).
    #[cfg_attr(feature = "cli", command(flatten))]
    pub overlay: crate::overlay::OverlayOptions,
    /// Feature extractor (default: the built-in descriptor).
    /// `--onnx-features MODEL`: an ONNX encoder (XFeat layout), concatenated
    /// with the built-in features; needs a build with `--features onnx` and
    /// ORT_DYLIB_PATH.
    #[cfg_attr(feature = "cli", arg(long = "onnx-features", value_name = "MODEL", value_parser = FeatureBackend::parse_onnx, required = false))]
    pub features: FeatureBackend,
    /// The built-in descriptor with its two chromaticity channels (ours;
    /// see `HandFeatures`; default true). DAVIS 8 sequences, mean J: 0.489
    /// without → 0.510 with (seed 1: 0.521); also tried and not kept:
    /// larger-scale texture energy (0.488; with chromaticity 0.515 but the
    /// demo scene fell 0.60 → 0.51).
    #[cfg_attr(feature = "cli", arg(long = "no-chromaticity", action = clap::ArgAction::SetFalse, help = "Leave the two chromaticity channels out of the built-in features"))]
    pub chromaticity_features: bool,
    /// Focal length of the frames divided by their width, for the
    /// cheirality test (`labels.cheirality`). None: the scene's intrinsics
    /// when segmenting a scene folder, else COLMAP's prior 1.2 × the long
    /// side. Only depth signs are read from it, which a rough value gets
    /// right.
    #[cfg_attr(feature = "cli", arg(long))]
    pub focal_ratio: Option<f64>,
    /// Master seed (default 0; sub-stages derive theirs from it).
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub seed: u64,
    /// Longest run of frames segmented at once (default 500; 0: the whole
    /// video). The stage holds 10–13 MB per 854×480 frame (flows,
    /// features, the space–time cut), so a longer video is cut into runs of
    /// at most this many frames, each sharing one frame with the next, each
    /// with its own MLP (`romo::scene::chunks`): 500 frames peak at about
    /// 5 GB, 650 at once at 8.4 GB. The shared frame keeps the earlier
    /// window's mask, made from its backward pair only; the progress line
    /// names the window it counts.
    #[cfg_attr(feature = "cli", arg(long, required = false))]
    pub chunk_frames: usize,
    /// Order of a folder's frames (`romo::order`): `auto` (default)
    /// keeps the file names' order unless it is clearly not the capture
    /// order (its median step between neighbouring thumbnails is over 2
    /// times a similarity path's), `names`, or `similarity`. `run --video`
    /// uses `names`.
    #[cfg_attr(feature = "cli", arg(long, value_enum, required = false))]
    pub frame_order: crate::order::FrameOrder,
    /// Output folder for `masks/` etc. (default: the scene folder).
    #[cfg_attr(feature = "cli", arg(long))]
    pub out: Option<PathBuf>,
    /// Also write `probabilities/<stem>.exr` (moving probability, full res).
    #[cfg_attr(feature = "cli", arg(long))]
    pub save_probabilities: bool,
    /// Also write `motion/<name>.png` overlays for looking at.
    #[cfg_attr(feature = "cli", arg(long))]
    pub overlays: bool,
    /// Keep the grid probabilities after each refinement step in
    /// [`Segmentation::stages`], for diagnosis (default false).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub record_stages: bool,
}

impl Default for RomoOptions {
    fn default() -> Self {
        Self {
            grid_max_side: 256,
            flow_scale: 2,
            flow: DisOptions::masks(),
            flow_backend: FlowBackend::Dis,
            onnx_flow_scale: 1.0,
            labels: LabelOptions::default(),
            mlp: MlpOptions::default(),
            iterations: 2,
            refine: RefineOptions::default(),
            regions: RegionOptions::default(),
            overlay: crate::overlay::OverlayOptions::default(),
            features: FeatureBackend::Hand,
            chromaticity_features: true,
            focal_ratio: None,
            seed: 0,
            chunk_frames: 500,
            frame_order: crate::order::FrameOrder::Auto,
            out: None,
            save_probabilities: false,
            overlays: false,
            record_stages: false,
        }
    }
}

impl RomoOptions {
    /// Check every option.
    pub fn validate(&self) -> Result<()> {
        if self.grid_max_side < 16 || self.flow_scale == 0 || self.iterations == 0 {
            return Err(RomoError::Options(
                "romo: grid_max_side >= 16, flow_scale >= 1, iterations >= 1 required".into(),
            ));
        }
        if self
            .focal_ratio
            .is_some_and(|r| !(r.is_finite() && r > 0.0))
        {
            return Err(RomoError::Options("romo: focal_ratio must be > 0".into()));
        }
        if !(self.onnx_flow_scale.is_finite() && self.onnx_flow_scale > 0.0) {
            return Err(RomoError::Options(
                "romo: onnx_flow_scale must be > 0".into(),
            ));
        }
        self.flow.validate()?;
        self.labels.validate()?;
        self.mlp.validate()?;
        self.refine.validate()?;
        self.overlay.validate()?;
        self.regions.validate()
    }

    /// The working grid for frames of `w × h`.
    pub fn grid_size(&self, w: usize, h: usize) -> (usize, usize) {
        let s = (self.grid_max_side as f64 / w.max(h) as f64).min(1.0);
        (
            ((w as f64 * s).round() as usize).max(8),
            ((h as f64 * s).round() as usize).max(8),
        )
    }
}

/// Where frames come from (loaded on demand so a long video never sits in
/// memory at full resolution).
pub trait FrameSource: Sync {
    /// Number of frames.
    fn len(&self) -> usize;
    /// True when there are no frames.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Frame `i` as RGB in [0, 1].
    fn frame(&self, i: usize) -> Result<Rgb>;
    /// Frame `i`'s (width, height); sources that can read it without
    /// decoding the frame do.
    fn size(&self, i: usize) -> Result<(usize, usize)> {
        self.frame(i).map(|f| (f.w(), f.h()))
    }
    /// What to call frame `i` in an error: its file where it has one.
    fn describe(&self, i: usize) -> String {
        format!("frame {i}")
    }
}

impl FrameSource for [Rgb] {
    fn len(&self) -> usize {
        <[Rgb]>::len(self)
    }
    fn frame(&self, i: usize) -> Result<Rgb> {
        self.get(i)
            .cloned()
            .ok_or_else(|| RomoError::Input(format!("frame {i} out of range")))
    }
}

impl FrameSource for Vec<Rgb> {
    fn len(&self) -> usize {
        <[Rgb]>::len(self)
    }
    fn frame(&self, i: usize) -> Result<Rgb> {
        self.as_slice().frame(i)
    }
}

/// Per-frame diagnostics.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct FrameReport {
    /// Frame index.
    pub index: usize,
    /// Image name (filled by the scene driver).
    pub name: String,
    /// Model of the forward pair (t, t+1): "F" or "H" ("" for the last).
    pub model_fwd: String,
    /// Inlier ratio of the frame's correspondences (last round).
    pub inlier_ratio: f32,
    /// Fraction of grid pixels in U (last round).
    pub u_coverage: f32,
    /// Fraction in L.
    pub l_coverage: f32,
    /// Fraction of pixels passing the cycle check on some side.
    pub valid_ratio: f32,
    /// Mean flow magnitude in grid px.
    pub v_px: f32,
    /// Dropped from MLP training (inlier ratio below the minimum).
    pub dropped: bool,
    /// Fraction of the grid called moving (H > threshold).
    pub moving_fraction: f32,
}

/// What a RoMo run did.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RomoReport {
    /// Frames.
    pub frames: Vec<FrameReport>,
    /// Indices of frames dropped from training (last round).
    pub dropped_frames: Vec<usize>,
    /// One report per training round.
    pub rounds: Vec<TrainReport>,
    /// Pair fit reports of the last round (pair p = frames p, p+1).
    pub pairs: Vec<FitReport>,
    /// Wall-clock milliseconds per stage.
    pub timings_ms: BTreeMap<String, f64>,
    /// Working grid (w, h).
    pub grid: (usize, usize),
    /// Flow and feature backends used.
    pub backends: Vec<String>,
    /// Where masks were written (scene driver).
    pub masks_dir: Option<PathBuf>,
    /// split.json `extra` views given all-keep masks (not part of the video).
    pub held_out_views: usize,
    /// Pairs (p = frames p, p+1) left out: a frame without texture, too few
    /// cycle-consistent correspondences, no model could be fitted, or its
    /// fit was unreliable (`LabelOptions::max_sigma_ratio`). Their frames
    /// are labelled from their other neighbour.
    pub skipped_pairs: Vec<SkippedPair>,
    /// Frames whose pairs on both sides failed (unusable or not fitted): no
    /// evidence of motion, so they are kept whole (probability 0).
    pub no_evidence_frames: Vec<usize>,
    /// One line per problem the run worked around (skipped pairs, frames
    /// without evidence), for the user.
    pub warnings: Vec<String>,
    /// Share of the grid marked moving in every frame as content fixed in
    /// the image ([`crate::overlay`]).
    pub image_fixed_fraction: f32,
    /// What the fixed-content test decided, in words.
    pub image_fixed: String,
    /// Median step between neighbouring thumbnails in file-name order over
    /// the similarity order's ([`crate::order`]; None when not measured).
    #[serde(default)]
    pub name_order_ratio: Option<f64>,
    /// True when the frames were segmented in similarity order, not by name.
    #[serde(default)]
    pub reordered: bool,
}

/// A pair the pipeline could not use, and why.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SkippedPair {
    /// Pair index p (frames p and p+1).
    pub pair: usize,
    /// Why it was skipped.
    pub reason: String,
}

/// Low-resolution result of [`segment_frames`].
pub struct Segmentation {
    /// Moving probability per frame on the grid.
    pub probs: Vec<Plane>,
    /// Last round's U (likely moving) labels per frame on the grid.
    pub u: Vec<Vec<bool>>,
    /// Last round's L (likely static) labels per frame on the grid.
    pub l: Vec<Vec<bool>>,
    /// Last round's residual per frame on the grid: `max(S_fwd, S_bwd)` in
    /// grid px, NaN where no side is valid.
    pub residual: Vec<Vec<f32>>,
    /// Last round's mean flow magnitude `v` per frame (grid px).
    pub mean_flow: Vec<f32>,
    /// The exposure map the stages saw the frames through; the full-size
    /// frames that guide the masks' upsampling take it too.
    pub exposure: Exposure,
    /// Diagnostics.
    pub report: RomoReport,
    /// With `RomoOptions::record_stages`: the grid probabilities after each
    /// refinement step, by step name (`mlp`, `temporal`, `regions`,
    /// `veto`, `objects`, …), in order.
    pub stages: Vec<(String, Vec<Plane>)>,
}

struct Timer<'a>(&'a mut BTreeMap<String, f64>);

impl Timer<'_> {
    fn time<T>(&mut self, stage: &str, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let r = f();
        *self.0.entry(stage.into()).or_default() += t.elapsed().as_secs_f64() * 1e3;
        r
    }
}

/// Everything computed once per video.
struct Prepared {
    /// The video's exposure map, applied to every frame the stages see.
    exposure: Exposure,
    fwd: Vec<Flow>,
    bwd: Vec<Flow>,
    valid_f: Vec<Vec<bool>>,
    valid_b: Vec<Vec<bool>>,
    feats: Vec<Vec<f32>>,
    c: usize,
    /// Focal length at the working grid (px).
    grid_focal: f64,
    /// Per frame: grid pixels with texture (gradient of the grid's grey
    /// image above `labels.u_min_gradient`; all true when that is 0).
    textured: Vec<Vec<bool>>,
    /// Frames at the grid's size (object refinement).
    grid_rgb: Vec<Rgb>,
    /// Their grey levels (fixed-content test).
    grid_grays: Vec<Plane>,
    /// Per frame: pixels textured enough for the object refinement's
    /// geometric evidence (`refine.objects.texture_gradient`).
    evidence_textured: Vec<Vec<bool>>,
    /// Per pair: why it cannot be used (a textureless frame or too few
    /// cycle-consistent correspondences), None when usable. The fit may
    /// still fail later ([`label_round`]).
    unusable: Vec<Option<String>>,
}

/// A correspondence is photo-consistent when the grey levels (in [0, 1]) at
/// its two ends differ by less than this.
pub const PHOTO_TOLERANCE: f32 = 0.1;

/// A pixel is textured when its central-difference gradient exceeds this
/// (intensity in [0, 1] per px; ≈ 2 grey levels of 255).
pub const TEXTURE_GRADIENT: f32 = 2.0 / 255.0;

/// Fraction of a grey frame's pixels whose gradient exceeds
/// [`TEXTURE_GRADIENT`].
pub fn texture_fraction(g: &Plane) -> f32 {
    texture_fraction_above(g, TEXTURE_GRADIENT)
}

/// Fraction of a grey frame's pixels whose gradient exceeds `thr`.
pub fn texture_fraction_above(g: &Plane, thr: f32) -> f32 {
    let (w, h) = (g.w, g.h);
    if w < 3 || h < 3 {
        return 0.0;
    }
    let mut n = 0usize;
    for y in 1..h - 1 {
        let row = &g.data[y * w..(y + 1) * w];
        let up = &g.data[(y - 1) * w..y * w];
        let dn = &g.data[(y + 1) * w..(y + 2) * w];
        for x in 1..w - 1 {
            let gx = 0.5 * (row[x + 1] - row[x - 1]);
            let gy = 0.5 * (dn[x] - up[x]);
            if gx.abs().max(gy.abs()) > thr {
                n += 1;
            }
        }
    }
    n as f32 / ((w - 2) * (h - 2)) as f32
}

/// Frames at the flow's working size (`fw × fh`), checked to share frame
/// 0's size.
fn load_frames(src: &dyn FrameSource, first: &Rgb, (fw, fh): (usize, usize)) -> Result<Vec<Rgb>> {
    (0..src.len())
        .into_par_iter()
        .map(|i| -> Result<Rgb> {
            let f = src.frame(i)?;
            if f.w() != first.w() || f.h() != first.h() {
                return Err(RomoError::Input(format!(
                    "{} is {}x{}, {} is {}x{}: RoMo needs every frame at one size (one camera's video or sequential capture); resize the images to one size, or do without masks (`--no-masks` in run, pose and train)",
                    src.describe(i),
                    f.w(),
                    f.h(),
                    src.describe(0),
                    first.w(),
                    first.h()
                )));
            }
            Ok(f.resize(fw, fh))
        })
        .collect()
}

/// Forward and backward flow of every pair, resampled to the grid `gw × gh`.
/// A model with its own input size (ONNX) gets frames at that size, loaded
/// again from the source rather than upsampled from `small`.
fn pair_flows(
    src: &dyn FrameSource,
    small: &[Rgb],
    exposure: Exposure,
    flow: &dyn FlowEstimator,
    full: (usize, usize),
    (gw, gh): (usize, usize),
) -> Result<(Vec<Flow>, Vec<Flow>)> {
    let fsize = small.first().map_or((0, 0), |f| (f.w(), f.h()));
    let (sw, sh) = flow.frame_size(full, fsize);
    let flow_frame = |i: usize| -> Result<std::borrow::Cow<'_, Rgb>> {
        if (sw, sh) == fsize {
            return Ok(std::borrow::Cow::Borrowed(&small[i]));
        }
        let f = exposure.applied(src.frame(i)?);
        Ok(std::borrow::Cow::Owned(if (f.w(), f.h()) == (sw, sh) {
            f
        } else {
            f.resize(sw, sh)
        }))
    };
    let flows = (0..small.len().saturating_sub(1))
        .into_par_iter()
        .map(|p| -> Result<(Flow, Flow)> {
            let (f, b) = flow.flow_pair(&*flow_frame(p)?, &*flow_frame(p + 1)?)?;
            Ok((f.resize(gw, gh), b.resize(gw, gh)))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(flows.into_iter().unzip())
}

/// Per pair: why it cannot be used (a frame without texture, or too few
/// cycle- and photo-consistent correspondences), None when usable.
/// `texture[i]` is frame i's [`texture_fraction`].
fn unusable_pairs(
    texture: &[f32],
    fwd: &[Flow],
    bwd: &[Flow],
    (valid_f, valid_b): (&[Vec<bool>], &[Vec<bool>]),
    grid_grays: &[Plane],
    o: &LabelOptions,
) -> Vec<Option<String>> {
    (0..fwd.len())
        .into_par_iter()
        .map(|p| {
            let flat: Vec<usize> = [p, p + 1]
                .into_iter()
                .filter(|&i| texture[i] < o.min_texture_fraction)
                .collect();
            if !flat.is_empty() {
                let list: Vec<String> = flat.iter().map(|i| format!("frame {i}")).collect();
                return Some(format!(
                    "no texture in {} (< {:.1}% of pixels with a gradient)",
                    list.join(" and "),
                    100.0 * o.min_texture_fraction
                ));
            }
            // Cycle-consistent and photo-consistent: two unrelated frames
            // (noise, a cut) can give a smooth near-zero flow that passes
            // the cycle check everywhere but matches nothing.
            let (a, b) = (&grid_grays[p], &grid_grays[p + 1]);
            let vf = photo_consistent_fraction(&fwd[p], &valid_f[p], a, b)
                .min(photo_consistent_fraction(&bwd[p], &valid_b[p], b, a));
            (vf < o.min_valid_fraction).then(|| {
                format!(
                    "{:.1}% of pixels have a cycle- and photo-consistent flow (< {:.1}%)",
                    100.0 * vf,
                    100.0 * o.min_valid_fraction
                )
            })
        })
        .collect()
}

/// Fraction of the pixels of `a` that are valid in `v` and whose grey level
/// matches `b` at the end of their flow within [`PHOTO_TOLERANCE`].
fn photo_consistent_fraction(fl: &Flow, v: &[bool], a: &Plane, b: &Plane) -> f32 {
    let w = fl.w();
    let k = (0..v.len())
        .filter(|&i| {
            v[i] && {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let q = b.bilinear(x + fl.u.data[i], y + fl.v.data[i]);
                (a.data[i] - q).abs() < PHOTO_TOLERANCE
            }
        })
        .count();
    k as f32 / v.len().max(1) as f32
}

/// Everything computed once per video: frames at the flow's size, flows,
/// cycle checks, usable pairs, features on the grid.
fn prepare(
    src: &dyn FrameSource,
    o: &RomoOptions,
    flow: &dyn FlowEstimator,
    fx: &dyn FeatureExtractor,
    progress: &dyn Fn(&str, usize, usize),
    report: &mut RomoReport,
) -> Result<Prepared> {
    let n = src.len();
    let mut timings = BTreeMap::new();
    let mut t = Timer(&mut timings);
    let first = src.frame(0)?;
    let (gw, gh) = o.grid_size(first.w(), first.h());
    report.grid = (gw, gh);
    let ratio = o
        .focal_ratio
        .unwrap_or(1.2 * first.w().max(first.h()) as f64 / first.w() as f64);
    let grid_focal = ratio * gw as f64;
    let (fw, fh) = (gw * o.flow_scale, gh * o.flow_scale);
    progress("load", 0, n);
    let mut small = t.time("load", || load_frames(src, &first, (fw, fh)))?;
    let exposure = t.time("load", || {
        let e = Exposure::measure(&small);
        small.par_iter_mut().for_each(|f| e.apply(f));
        e
    });
    if exposure.stretches() {
        report.warnings.push(format!(
            "the frames are dark or flat (99% of their values within [{:.3}, {:.3}]): stretched ×{:.1} for segmentation",
            exposure.lo,
            exposure.hi,
            exposure.gain()
        ));
    }
    progress("flow", 0, n - 1);
    let grays: Vec<Plane> = small.iter().map(|f| f.gray()).collect();
    let (fwd, bwd) = t.time("flow", || {
        pair_flows(
            src,
            &small,
            exposure,
            flow,
            (first.w(), first.h()),
            (gw, gh),
        )
    })?;
    progress("flow", n - 1, n - 1);
    // Whether a frame has texture at all is judged in the source's grey
    // levels: stretching does not make a black frame textured.
    let texture_thr = TEXTURE_GRADIENT * exposure.gain();
    let texture: Vec<f32> = grays
        .par_iter()
        .map(|g| texture_fraction_above(g, texture_thr))
        .collect();
    let (mut valid_f, mut valid_b): (Vec<Vec<bool>>, Vec<Vec<bool>>) = t.time("cycle", || {
        (0..n - 1)
            .into_par_iter()
            .map(|p| {
                (
                    cycle_valid(&fwd[p], &bwd[p], &o.labels),
                    cycle_valid(&bwd[p], &fwd[p], &o.labels),
                )
            })
            .unzip()
    });
    let grid_grays: Vec<Plane> = grays.par_iter().map(|g| g.resize(gw, gh)).collect();
    let textured: Vec<Vec<bool>> = grid_grays
        .par_iter()
        .map(|g| gradient_mask(g, o.labels.u_min_gradient))
        .collect();
    let unusable = unusable_pairs(
        &texture,
        &fwd,
        &bwd,
        (&valid_f, &valid_b),
        &grid_grays,
        &o.labels,
    );
    // Unusable pairs carry no correspondences for anything downstream
    // (labels, temporal smoothing).
    for (p, u) in unusable.iter().enumerate() {
        if u.is_some() {
            valid_f[p].fill(false);
            valid_b[p].fill(false);
        }
    }
    progress("features", 0, n);
    let mut maps: Vec<FeatureMap> = t.time("features", || {
        small
            .par_iter()
            .map(|f| fx.extract(f, gw, gh).map(|m| m.resize(gw, gh)))
            .collect::<Result<Vec<_>>>()
    })?;
    let grid_rgb: Vec<Rgb> = small.par_iter().map(|f| f.resize(gw, gh)).collect();
    drop(small);
    let evidence_textured: Vec<Vec<bool>> = grid_grays
        .par_iter()
        .map(|g| gradient_mask(g, o.refine.objects.texture_gradient))
        .collect();
    t.time("features", || standardise(&mut maps));
    let c = maps.first().map_or(0, |m| m.c);
    let feats = maps.iter().map(|m| m.pixel_major()).collect();
    report.timings_ms.extend(timings);
    Ok(Prepared {
        exposure,
        fwd,
        bwd,
        valid_f,
        valid_b,
        feats,
        c,
        grid_focal,
        textured,
        grid_rgb,
        grid_grays,
        evidence_textured,
        unusable,
    })
}

/// Pixels whose central-difference gradient (max of |gx|, |gy|; one-sided
/// at the border) exceeds `thr`; all true for `thr` 0.
pub fn gradient_mask(g: &Plane, thr: f32) -> Vec<bool> {
    let (w, h) = (g.w, g.h);
    if thr <= 0.0 {
        return vec![true; w * h];
    }
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (x0, x1) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (y0, y1) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let gx = (g.data[y * w + x1] - g.data[y * w + x0]) / (x1 - x0).max(1) as f32;
            let gy = (g.data[y1 * w + x] - g.data[y0 * w + x]) / (y1 - y0).max(1) as f32;
            gx.abs().max(gy.abs()) > thr
        })
        .collect()
}

/// Labels of every frame and the fit of every pair in one round (`Err` for
/// a pair that is unusable, could not be fitted or was not trusted, with
/// the reason).
type RoundLabels = (Vec<FrameLabels>, Vec<PairResult>);

/// Fit every usable pair (excluding pixels in `moving`, per frame) and
/// label every frame from the pairs on either side that were fitted.
fn label_round(
    pr: &Prepared,
    moving: Option<&[Vec<bool>]>,
    prev: Option<&[PairResult]>,
    o: &RomoOptions,
    round: usize,
) -> RoundLabels {
    let np = pr.fwd.len();
    let mut fits: Vec<PairResult> = (0..np)
        .into_par_iter()
        .map(|p| {
            if let Some(why) = &pr.unusable[p] {
                return Err(NoFit::Failed(why.clone()));
            }
            let usable: Vec<bool> = match moving {
                Some(m) => pr.valid_f[p]
                    .iter()
                    .zip(&m[p])
                    .map(|(v, mv)| *v && !mv)
                    .collect(),
                None => pr.valid_f[p].clone(),
            };
            let seed = o.seed ^ ((round as u64) << 32) ^ p as u64;
            let mut lo = o.labels.clone();
            lo.robust.seed = seed;
            // A pair where F was informative in the first round keeps F:
            // with the object excluded from the fit, F would call nothing
            // moving and the override would not fire again.
            if let Some(Some(Ok(prev))) = prev.map(|v| v.get(p))
                && o.labels.f_informative_fraction > 0.0
                && prev.report.model == "F"
                && prev.report.u_fraction_f >= o.labels.f_informative_fraction as f64
            {
                lo.robust.selection = ModelSelection::Fundamental;
            }
            let focal = Some(pr.grid_focal);
            fit_pair(&pr.fwd[p], &usable, &lo, seed, focal)
                .or_else(|_| fit_pair(&pr.fwd[p], &pr.valid_f[p], &lo, seed, focal))
                .map_err(|e| NoFit::Failed(format!("no model could be fitted ({e})")))
        })
        .collect();
    drop_unreliable_fits(
        &mut fits,
        o.labels.max_sigma_ratio,
        o.labels.robust.min_sigma_px,
    );
    let (gw, gh) = (pr.fwd[0].w(), pr.fwd[0].h());
    let labels = (0..=np)
        .into_par_iter()
        .map(|t| {
            let mut sides = Vec::with_capacity(2);
            if t < np
                && let Ok(fit) = &fits[t]
            {
                sides.push(Side {
                    flow: &pr.fwd[t],
                    valid: &pr.valid_f[t],
                    model: fit.model,
                    report: &fit.report,
                    second: false,
                    oriented: fit.oriented.as_ref(),
                });
            }
            if t > 0
                && let Ok(fit) = &fits[t - 1]
            {
                sides.push(Side {
                    flow: &pr.bwd[t - 1],
                    valid: &pr.valid_b[t - 1],
                    model: fit.model,
                    report: &fit.report,
                    second: true,
                    oriented: fit.oriented.as_ref(),
                });
            }
            if sides.is_empty() {
                return FrameLabels::no_evidence(gw * gh);
            }
            let mut fl = frame_labels(&sides, &o.labels);
            if o.labels.three_view
                && t > 0
                && t < np
                && let (Ok(ff), Ok(fb)) = (&fits[t], &fits[t - 1])
                && let (Some(of), Some(ob)) = (&ff.oriented, &fb.oriented)
                && let Some(e) = three_view_residuals(
                    &pr.fwd[t],
                    &pr.valid_f[t],
                    of,
                    &pr.bwd[t - 1],
                    &pr.valid_b[t - 1],
                    ob,
                    &fl.l,
                )
            {
                apply_three_view(&mut fl, &e, &o.labels);
            }
            if o.labels.occlusion {
                apply_occlusion(&mut fl, pr, &fits, t, &o.labels);
            }
            if o.labels.u_min_gradient > 0.0 {
                for (u, t) in fl.u.iter_mut().zip(&pr.textured[t]) {
                    *u &= *t;
                }
                fl.recount_coverage();
            }
            u_majority(&mut fl, gw, o.labels.u_majority_radius, o.labels.u_factor);
            fl
        })
        .collect();
    (labels, fits)
}

/// The occlusion-order test (`LabelOptions::occlusion`) on frame `t`
/// against each neighbour whose pair has a metric geometry: pixels that
/// hide more parallax than their own by more than `occlusion_factor`·v
/// (and `three_view_u_px`) become U and leave L.
fn apply_occlusion(
    fl: &mut FrameLabels,
    pr: &Prepared,
    fits: &[PairResult],
    t: usize,
    o: &LabelOptions,
) {
    let np = pr.fwd.len();
    let mut viol: Option<Vec<f32>> = None;
    let mut add = |v: Vec<f32>| match &mut viol {
        Some(m) => m.iter_mut().zip(v).for_each(|(a, b)| *a = a.max(b)),
        None => viol = Some(v),
    };
    if t < np
        && let Ok(fit) = &fits[t]
        && let Some(of) = &fit.oriented
    {
        add(occlusion_violations(
            &pr.fwd[t],
            &pr.valid_f[t],
            &pr.bwd[t],
            &pr.valid_b[t],
            of,
            false,
        ));
    }
    if t > 0
        && let Ok(fit) = &fits[t - 1]
        && let Some(ob) = &fit.oriented
    {
        add(occlusion_violations(
            &pr.bwd[t - 1],
            &pr.valid_b[t - 1],
            &pr.fwd[t - 1],
            &pr.valid_f[t - 1],
            ob,
            true,
        ));
    }
    let Some(viol) = viol else { return };
    if viol.len() != fl.u.len() {
        return;
    }
    let thr = (o.occlusion_factor * fl.v).max(o.three_view_u_px);
    for (i, d) in viol.iter().enumerate() {
        if *d > thr {
            fl.u[i] = true;
            fl.l[i] = false;
        }
    }
    fl.recount_coverage();
}

/// A frame's unlabelled pixels (neither U nor L) at least `fraction` of
/// the grid's longer side from the nearest pixel of `near_u` (all of them
/// when it is empty), in pixel order.
fn far_unlabelled(fl: &FrameLabels, near_u: &[bool], w: usize, fraction: f32) -> Vec<usize> {
    let h = fl.u.len() / w.max(1);
    let min = fraction * w.max(h) as f32;
    let d = chamfer_distance(near_u, w);
    (0..fl.u.len())
        .filter(|&i| !fl.u[i] && !fl.l[i] && d[i] >= min)
        .collect()
}

/// Pixels that are U in frame `t` or in any frame up to `k` either side.
fn u_within(labels: &[FrameLabels], t: usize, k: usize) -> Vec<bool> {
    let near = &labels[t.saturating_sub(k)..(t + k + 1).min(labels.len())];
    (0..labels[t].u.len())
        .map(|i| near.iter().any(|m| m.u.get(i).copied().unwrap_or(false)))
        .collect()
}

/// Distance of every pixel of a `w`-wide mask to its nearest set pixel
/// (3-4 chamfer, in px; infinite without any).
fn chamfer_distance(mask: &[bool], w: usize) -> Vec<f32> {
    let h = mask.len() / w.max(1);
    let mut d: Vec<f32> = mask
        .iter()
        .map(|m| if *m { 0.0 } else { f32::INFINITY })
        .collect();
    let (a, b) = (1.0f32, 4.0 / 3.0);
    // Forward pass: left, up-left, up, up-right; the backward pass mirrors it.
    let ahead = [(-1, 0, a), (-1, -1, b), (0, -1, a), (1, -1, b)];
    for forward in [true, false] {
        let sign = if forward { 1 } else { -1 };
        for k in 0..w * h {
            let i = if forward { k } else { w * h - 1 - k };
            let (x, y) = ((i % w) as isize, (i / w) as isize);
            for &(dx, dy, c) in &ahead {
                let (nx, ny) = (x + sign * dx, y + sign * dy);
                if (0..w as isize).contains(&nx) && (0..h as isize).contains(&ny) {
                    let v = d[ny as usize * w + nx as usize] + c;
                    if v < d[i] {
                        d[i] = v;
                    }
                }
            }
        }
    }
    d
}

/// Draw training samples: per kept frame up to `samples_per_frame`, half
/// from U when it has that many.
fn samples(
    pr: &Prepared,
    labels: &[FrameLabels],
    keep: &[bool],
    o: &RomoOptions,
    round: usize,
) -> (Vec<f32>, Vec<Label>) {
    let c = pr.c;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(o.seed ^ 0x5a5a ^ round as u64);
    let (mut x, mut y) = (Vec::new(), Vec::new());
    for (t, fl) in labels.iter().enumerate() {
        if !keep[t] {
            continue;
        }
        let mut u: Vec<usize> = (0..fl.u.len()).filter(|&i| fl.u[i]).collect();
        let mut l: Vec<usize> = (0..fl.l.len()).filter(|&i| fl.l[i]).collect();
        let share = o.mlp.unlabelled_share;
        let mut free = if share > 0.0 {
            let near_u = u_within(labels, t, o.mlp.unlabelled_frames);
            far_unlabelled(
                fl,
                &near_u,
                pr.grid_rgb[t].c[0].w,
                o.mlp.unlabelled_distance,
            )
        } else {
            Vec::new()
        };
        let cap = o.mlp.samples_per_frame;
        let (nu, nl, nf) = if cap > 0 {
            let nu = u.len().min(cap / 2);
            let nf = free.len().min(((cap - nu) as f64 * share).round() as usize);
            (nu, l.len().min(cap - nu - nf), nf)
        } else {
            // All labelled pixels, and unlabelled ones in the same share.
            let nf = (l.len() as f64 * share / (1.0 - share)).round() as usize;
            (u.len(), l.len(), free.len().min(nf))
        };
        let mut draw = |v: &mut Vec<usize>, k: usize| {
            for i in 0..k {
                let j = rng.random_range(i..v.len());
                v.swap(i, j);
            }
            v.truncate(k);
        };
        if cap > 0 {
            draw(&mut u, nu);
            draw(&mut l, nl);
        }
        if nf < free.len() {
            draw(&mut free, nf);
        }
        for (set, lab) in [
            (&u, Label::Moving),
            (&l, Label::Static),
            (&free, Label::Static),
        ] {
            for &i in set {
                x.extend_from_slice(&pr.feats[t][i * c..(i + 1) * c]);
                y.push(lab);
            }
        }
    }
    (x, y)
}

/// Run RoMo on `src` with the given backends; returns grid-resolution
/// moving probabilities and the report. `progress(stage, done, total)` is
/// called as stages advance.
pub fn segment_frames(
    src: &dyn FrameSource,
    o: &RomoOptions,
    flow: &dyn FlowEstimator,
    fx: &dyn FeatureExtractor,
    progress: &dyn Fn(&str, usize, usize),
) -> Result<Segmentation> {
    o.validate()?;
    let n = src.len();
    if n == 0 {
        return Err(RomoError::Input(
            "no frames: RoMo needs at least 2 (a video or a photo sequence)".into(),
        ));
    }
    if n == 1 {
        return Err(RomoError::Input(format!(
            "{} is the only frame: RoMo needs at least 2 (a video or a photo sequence)",
            src.describe(0)
        )));
    }
    let mut report = RomoReport {
        backends: vec![flow.name().to_string(), fx.name().to_string()],
        ..Default::default()
    };
    let pr = prepare(src, o, flow, fx, progress, &mut report)?;
    let mut timings = BTreeMap::new();
    let mut tm = Timer(&mut timings);
    let (probs, (labels, fits)) = train_rounds(&pr, o, progress, &mut report, &mut tm)?;
    let (gw, gh) = report.grid;
    let planes: Vec<Plane> = probs
        .into_iter()
        .map(|d| Plane {
            w: gw,
            h: gh,
            data: d,
        })
        .collect();
    let mut stages = Vec::new();
    let mut planes = refine_grid(planes, &pr, &labels, o, &mut tm, &mut stages);
    keep_frames_without_evidence(&mut planes, &fits, &mut report);
    if o.overlay.enabled {
        tm.time("refine", || {
            mark_image_fixed(&mut planes, &pr, o, &mut report)
        });
    }
    report_frames(&labels, &fits, &planes, o, &mut report);
    for (k, v) in timings {
        *report.timings_ms.entry(k).or_default() += v;
    }
    Ok(Segmentation {
        probs: planes,
        u: labels.iter().map(|l| l.u.clone()).collect(),
        l: labels.iter().map(|l| l.l.clone()).collect(),
        residual: labels.iter().map(|l| l.s.clone()).collect(),
        mean_flow: labels.iter().map(|l| l.v).collect(),
        exposure: pr.exposure,
        report,
        stages,
    })
}

/// The rounds of (fit → label → train): each round fits the pairs without
/// the pixels the previous round called moving, labels the frames and
/// trains the MLP on them. Returns the last round's probabilities per frame
/// (grid, pixel-major) and its labels and fits.
fn train_rounds(
    pr: &Prepared,
    o: &RomoOptions,
    progress: &dyn Fn(&str, usize, usize),
    report: &mut RomoReport,
    tm: &mut Timer<'_>,
) -> Result<(Vec<Vec<f32>>, RoundLabels)> {
    let n = pr.feats.len();
    // Trained from fresh starts in the first round, continued after.
    let mut mlp: Option<Mlp> = None;
    let mut probs: Vec<Vec<f32>> = Vec::new();
    let mut last: Option<RoundLabels> = None;
    // The first round's choice ([`MlpOptions::raised_moving_weight`]).
    let mut moving_weight = o.mlp.moving_weight;
    for round in 0..o.iterations {
        progress("geometry", round, o.iterations);
        let moving: Option<Vec<Vec<bool>>> = (round > 0).then(|| {
            probs
                .iter()
                .map(|p| p.iter().map(|h| *h > o.refine.threshold).collect())
                .collect()
        });
        let prev = last.as_ref().map(|l| l.1.as_slice());
        let (mut labels, fits) = tm.time("geometry", || {
            label_round(pr, moving.as_deref(), prev, o, round)
        });
        if o.labels.u_propagation_frames > 0 {
            tm.time("geometry", || {
                propagate_u(
                    &mut labels,
                    &pr.fwd,
                    &pr.bwd,
                    &pr.valid_f,
                    &pr.valid_b,
                    o.labels.u_propagation_frames,
                )
            });
        }
        let keep: Vec<bool> = labels
            .iter()
            .map(|l| l.inlier_ratio >= o.labels.min_inlier_ratio)
            .collect();
        // If every frame would be dropped, train on all rather than nothing.
        let keep = if keep.iter().any(|k| *k) {
            keep
        } else {
            vec![true; n]
        };
        progress("mlp", round, o.iterations);
        let (m, rep) = tm.time("mlp", || {
            let (x, y) = samples(pr, &labels, &keep, o, round);
            match mlp.take() {
                Some(mut m) => {
                    let r = train(
                        &mut m,
                        &x,
                        &y,
                        o.mlp.epochs_per_round,
                        false,
                        &MlpOptions {
                            moving_weight,
                            ..o.mlp.clone()
                        },
                        o.seed ^ round as u64,
                    );
                    (m, r)
                }
                None => train_restarts(
                    pr.c,
                    &x,
                    &y,
                    o.mlp.epochs_per_round,
                    &o.mlp,
                    o.seed ^ 0x11,
                    o.seed,
                ),
            }
        });
        moving_weight = rep.moving_weight;
        report.rounds.push(rep);
        let m = mlp.insert(m);
        probs = tm.time("mlp", || pr.feats.iter().map(|f| m.predict(f)).collect());
        last = Some((labels, fits));
    }
    let last = last.ok_or_else(|| RomoError::Options("romo: iterations >= 1 required".into()))?;
    Ok((probs, last))
}

/// Refinement on the grid, in order: temporal smoothing along the flow,
/// region completion, the static veto, the object-level graph cut, and
/// temporal smoothing in place when not along the flow.
fn refine_grid(
    planes: Vec<Plane>,
    pr: &Prepared,
    labels: &[FrameLabels],
    o: &RomoOptions,
    tm: &mut Timer<'_>,
    stages: &mut Vec<(String, Vec<Plane>)>,
) -> Vec<Plane> {
    let mut record = |name: &str, p: &[Plane]| {
        if o.record_stages {
            stages.push((name.to_string(), p.to_vec()));
        }
    };
    record("mlp", &planes);
    let mut planes = if o.refine.temporal_along_flow {
        tm.time("refine", || {
            temporal_smooth_flow(
                &planes,
                &pr.fwd,
                &pr.bwd,
                &pr.valid_f,
                &pr.valid_b,
                o.refine.temporal_weight,
                o.refine.temporal_passes,
            )
        })
    } else {
        planes
    };
    record("temporal", &planes);
    if o.regions.enabled {
        tm.time("regions", || {
            planes.par_iter_mut().enumerate().for_each(|(t, p)| {
                let f = if t < pr.fwd.len() {
                    &pr.fwd[t]
                } else {
                    &pr.bwd[t - 1]
                };
                let lab = flow_segments(f, f.mean_magnitude(), o.regions.k, o.regions.min_size);
                complete(
                    &mut p.data,
                    &lab,
                    o.regions.threshold,
                    Some(labels[t].l.as_slice()),
                );
            })
        });
        record("regions", &planes);
    }
    if o.refine.static_veto_factor > 0.0 {
        for (p, l) in planes.iter_mut().zip(labels) {
            let thr = o.refine.static_veto_factor * l.v;
            for (v, s) in p.data.iter_mut().zip(&l.s) {
                if *s < thr {
                    *v = 0.0;
                }
            }
        }
        record("veto", &planes);
    }
    if o.refine.objects.method == ObjectMethod::GraphCut {
        let ev = Evidence {
            probs: &planes,
            s: labels.iter().map(|l| l.s.as_slice()).collect(),
            v: labels.iter().map(|l| l.v).collect(),
            textured: &pr.evidence_textured,
            u: labels.iter().map(|l| l.u.as_slice()).collect(),
            l: labels.iter().map(|l| l.l.as_slice()).collect(),
            rgb: &pr.grid_rgb,
            fwd: &pr.fwd,
            valid_f: &pr.valid_f,
            bwd: &pr.bwd,
            valid_b: &pr.valid_b,
            u_factor: o.labels.u_factor,
            l_factor: o.labels.l_factor,
            geometry_zero: o.refine.objects.geometry_zero,
        };
        let moving = tm.time("objects", || graph_cut(&ev, &o.refine.objects));
        for (p, m) in planes.iter_mut().zip(moving) {
            for (v, b) in p.data.iter_mut().zip(m) {
                *v = if b { 1.0 } else { 0.0 };
            }
        }
        record("objects", &planes);
    }
    if !o.refine.temporal_along_flow {
        for _ in 0..o.refine.temporal_passes {
            planes = temporal_smooth(&planes, o.refine.temporal_weight);
        }
    }
    planes
}

/// Content fixed in the image ([`crate::overlay`]) becomes moving in every
/// frame; the report says what was decided.
fn mark_image_fixed(planes: &mut [Plane], pr: &Prepared, o: &RomoOptions, report: &mut RomoReport) {
    use crate::overlay::{Overlay, image_fixed};
    match image_fixed(
        &pr.fwd,
        &pr.bwd,
        &pr.valid_f,
        &pr.textured,
        &pr.grid_grays,
        &o.overlay,
    ) {
        Overlay::Found(m) => {
            let k = m.iter().filter(|b| **b).count();
            report.image_fixed_fraction = k as f32 / m.len().max(1) as f32;
            report.image_fixed = format!(
                "{:.2}% of the frame fixed in the image, marked moving",
                100.0 * report.image_fixed_fraction
            );
            for p in planes.iter_mut() {
                for (v, f) in p.data.iter_mut().zip(&m) {
                    if *f {
                        *v = 1.0;
                    }
                }
            }
        }
        Overlay::TooLittleMotion { pairs } => {
            report.image_fixed = format!(
                "not tested: {pairs} pairs show camera motion, {} needed",
                o.overlay.min_pairs
            );
        }
        Overlay::TooLarge { fraction } => {
            report.image_fixed = format!(
                "nothing marked: {:.0}% of the frame is still, more than an overlay ({:.0}%): taken for distant scene",
                100.0 * fraction,
                100.0 * o.overlay.max_area
            );
        }
    }
}

/// Report the skipped pairs, and keep whole (probability 0) the frames
/// whose pairs on both sides failed ([`NoFit::Failed`]): they carry no
/// evidence of motion, so the MLP's guess on them is not trusted.
fn keep_frames_without_evidence(
    planes: &mut [Plane],
    fits: &[PairResult],
    report: &mut RomoReport,
) {
    let np = fits.len();
    for (p, f) in fits.iter().enumerate() {
        if let Err(reason) = f {
            report.warnings.push(skipped_pair_warning(p, reason));
            report.skipped_pairs.push(SkippedPair {
                pair: p,
                reason: reason.to_string(),
            });
        }
    }
    for (t, plane) in planes.iter_mut().enumerate() {
        // A pair with a fit it does not trust still leaves the frame's
        // appearance to the MLP; only failed pairs leave nothing.
        let evidence = |f: &PairResult| !matches!(f, Err(NoFit::Failed(_)));
        let fwd_ok = t < np && evidence(&fits[t]);
        let bwd_ok = t > 0 && evidence(&fits[t - 1]);
        if !fwd_ok && !bwd_ok {
            plane.data.fill(0.0);
            report.no_evidence_frames.push(t);
        }
    }
    if !report.no_evidence_frames.is_empty() {
        report
            .warnings
            .push(no_evidence_warning(&report.no_evidence_frames));
    }
}

/// The warning for skipped pair `p` (frames p, p+1).
pub(crate) fn skipped_pair_warning(p: usize, reason: &dyn std::fmt::Display) -> String {
    format!(
        "pair {p}–{} skipped: {reason}; its frames are labelled from their other neighbour",
        p + 1
    )
}

/// The warning for frames without evidence.
pub(crate) fn no_evidence_warning(frames: &[usize]) -> String {
    let list: Vec<String> = frames.iter().map(|t| t.to_string()).collect();
    format!(
        "no evidence of motion in frame(s) {} (no usable pair on either side): kept whole",
        list.join(", ")
    )
}

/// Per-frame and per-pair diagnostics of the last round.
fn report_frames(
    labels: &[FrameLabels],
    fits: &[PairResult],
    planes: &[Plane],
    o: &RomoOptions,
    report: &mut RomoReport,
) {
    for (t, l) in labels.iter().enumerate() {
        let dropped = l.inlier_ratio < o.labels.min_inlier_ratio;
        if dropped {
            report.dropped_frames.push(t);
        }
        let grid = planes[t].data.len().max(1);
        report.frames.push(FrameReport {
            index: t,
            name: String::new(),
            model_fwd: match fits.get(t) {
                Some(Ok(f)) => f.report.model.clone(),
                _ => String::new(),
            },
            inlier_ratio: l.inlier_ratio,
            u_coverage: l.u_coverage,
            l_coverage: l.l_coverage,
            valid_ratio: l.valid_ratio,
            v_px: l.v,
            dropped,
            moving_fraction: planes[t]
                .data
                .iter()
                .filter(|h| **h > o.refine.threshold)
                .count() as f32
                / grid as f32,
        });
    }
    report.pairs = fits
        .iter()
        .map(|f| match f {
            Ok(f) => f.report.clone(),
            Err(_) => FitReport::skipped(),
        })
        .collect();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Chamfer distances from one set pixel: k along an axis, 4k/3 along a
    /// diagonal; infinite without any set pixel.
    #[test]
    fn chamfer_distance_known_answers() {
        let (w, h) = (9, 7);
        let mut m = vec![false; w * h];
        m[3 * w + 2] = true;
        let d = chamfer_distance(&m, w);
        assert_eq!(d[3 * w + 2], 0.0);
        assert_eq!(d[3 * w + 8], 6.0);
        assert_eq!(d[6 * w + 2], 3.0);
        assert!((d[w + 4] - 8.0 / 3.0).abs() < 1e-6);
        assert!((d[6 * w + 8] - (3.0 + 4.0)).abs() < 1e-6);
        assert!(
            chamfer_distance(&[false; 12], 4)
                .iter()
                .all(|v| v.is_infinite())
        );
    }

    /// Static samples from unlabelled pixels: never U or L, never within
    /// the distance of U; a frame without U gives all its unlabelled pixels.
    #[test]
    fn far_unlabelled_pixels_keep_away_from_u() {
        let (w, h) = (20, 10);
        let mut fl = FrameLabels::no_evidence(w * h);
        for y in 0..h {
            fl.l[y * w + 19] = true;
        }
        assert_eq!(far_unlabelled(&fl, &fl.u, w, 0.25).len(), w * h - h);
        fl.u[5 * w + 3] = true;
        // 0.25 of the longer side (20): 5 px.
        let far = far_unlabelled(&fl, &fl.u, w, 0.25);
        let d = chamfer_distance(&fl.u, w);
        assert!(!far.is_empty());
        for (i, di) in d.iter().enumerate() {
            let expect = !fl.u[i] && !fl.l[i] && *di >= 5.0;
            assert_eq!(far.contains(&i), expect, "pixel {i}");
        }
        assert!(!far.contains(&(5 * w + 7)) && far.contains(&(5 * w + 8)));
    }

    /// U of the frames within k either side counts, and no further: an
    /// object with U only in frame 1 keeps frame 4's pixels at k = 3, not
    /// at k = 2.
    #[test]
    fn u_of_neighbouring_frames_keeps_static_samples_away() {
        let (w, h) = (20, 10);
        let mut labels: Vec<FrameLabels> =
            (0..6).map(|_| FrameLabels::no_evidence(w * h)).collect();
        labels[1].u[5 * w + 3] = true;
        assert!(u_within(&labels, 4, 3)[5 * w + 3]);
        assert!(u_within(&labels, 4, 2).iter().all(|b| !b));
        assert_eq!(u_within(&labels, 1, 0), labels[1].u);
        let far = far_unlabelled(&labels[4], &u_within(&labels, 4, 3), w, 0.25);
        assert!(!far.contains(&(5 * w + 3)) && !far.contains(&(5 * w + 7)));
        assert!(far.contains(&(5 * w + 8)));
        assert_eq!(
            far_unlabelled(&labels[4], &u_within(&labels, 4, 2), w, 0.25).len(),
            w * h
        );
    }

    /// A partial `flow` object changes only the fields it names: the rest
    /// stay at the mask stage's preset, not at OpenCV's MEDIUM.
    #[test]
    fn partial_flow_options_override_the_mask_preset() {
        let preset = DisOptions::masks();
        assert_ne!(
            preset.finest_scale,
            DisOptions::opencv_medium().finest_scale
        );
        let o: RomoOptions = serde_json::from_str("{}").unwrap();
        assert_eq!(o.flow.finest_scale, preset.finest_scale);
        assert_eq!(o.flow.patch_stride, preset.patch_stride);
        let o: RomoOptions =
            serde_json::from_str(r#"{"flow":{"patch_size":6,"variational":{"sor_iters":7}}}"#)
                .unwrap();
        assert_eq!(o.flow.patch_size, 6);
        assert_eq!(o.flow.variational.sor_iters, 7);
        assert_eq!(o.flow.finest_scale, preset.finest_scale);
        assert_eq!(o.flow.patch_stride, preset.patch_stride);
        assert_eq!(o.flow.variational.alpha, preset.variational.alpha);
        // The preset's refinement differs from MEDIUM's, and a partial
        // `variational` object keeps the preset's.
        assert_ne!(
            preset.variational.fixed_point_iters,
            DisOptions::opencv_medium().variational.fixed_point_iters
        );
        assert_eq!(
            o.flow.variational.fixed_point_iters,
            preset.variational.fixed_point_iters
        );
        let o: RomoOptions = serde_json::from_str(r#"{"flow":{"finest_scale":1}}"#).unwrap();
        assert_eq!(o.flow.finest_scale, 1);
        assert!(serde_json::from_str::<RomoOptions>(r#"{"flow":{"patch_size":"big"}}"#).is_err());
    }
}
