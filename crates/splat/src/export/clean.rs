//! Post-training clean-up of a splat set before export: removes what a
//! distractor (a person walking through the capture) tends to leave behind
//! even after masked training, and the usual 3DGS debris.
//!
//! Four criteria, applied in this order; each removed splat is counted under
//! the first criterion that removes it:
//! 1. **transparent** — sigmoid(opacity) < `min_opacity` (INRIA 3DGS prunes
//!    at 0.005 during densification, `densify_and_prune(..., 0.005, ...)`);
//! 2. **unseen** — fewer than `min_views` training cameras see the splat: its
//!    centre in front of the camera and its projected 3σ footprint overlapping
//!    the image. Needs the cameras; skipped (and reported) without them;
//! 3. **oversized** — largest axis σ above `max_scale_over_median` × the
//!    median largest σ; or, seen from the nearest training camera, a 3σ
//!    radius wider than `max_footprint` × the image's larger side (a blob
//!    that would fill the view, the typical leftover of a person walking
//!    close to the camera); or, when `max_scale_extent_fraction` > 0, above
//!    that fraction of the scene extent (INRIA's `big_points_ws` rule, 0.1 ×
//!    cameras_extent, where the extent is 1.1 × the largest camera distance
//!    from the cameras' mean centre, `getNerfppNorm`). The extent rule is off
//!    by default: on a handheld video the cameras span a small fraction of
//!    the scene, and 0.1 × their extent removed 1365 of 1498 splats of a
//!    trained demo-scene model, walls and ground included;
//! 4. **outside bounds** — floaters outside the static scene's robust box:
//!    the per-axis `bounds_percentile` / (100 − `bounds_percentile`)
//!    percentiles of the static points (the COLMAP points3D of a masked
//!    reconstruction when given, else the splat centres that passed 1), grown
//!    by `bounds_margin` × the box size on each side.

use super::sigmoid;
use crate::error::{Result, SplatError};
use crate::types::{RenderCamera, Splats};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Options of [`clean`]. Every threshold is documented with its unit and
/// where its default comes from.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct CleanOptions {
    /// Remove splats with sigmoid(opacity) below this (unitless, 0..1).
    /// Default 0.005, INRIA 3DGS's prune threshold.
    pub min_opacity: f32,
    /// Remove splats seen by fewer training cameras than this. Default 1
    /// ("no training camera sees it").
    pub min_views: u32,
    /// A splat counts as seen when its centre projects within this many σ
    /// (times its largest σ, in pixels) of the image rectangle. Default 3,
    /// the 3σ cut-off of the rasterizer.
    pub view_margin_sigma: f32,
    /// Remove splats whose largest σ exceeds this multiple of the median
    /// largest σ. Default 50 (our choice; no paper gives one — conservative so
    /// that large background splats survive).
    pub max_scale_over_median: f32,
    /// Remove splats whose 3σ radius, projected in the nearest training
    /// camera (by centre distance), exceeds this fraction of that image's
    /// larger side. Default 1.0 (our choice: the splat alone would cover the
    /// whole view); 0 disables. Needs cameras.
    pub max_footprint: f32,
    /// Remove splats whose largest σ exceeds this fraction of the scene extent
    /// (world units / world units). INRIA's `big_points_ws` uses 0.1; default
    /// 0 = off (see the module header for why).
    pub max_scale_extent_fraction: f32,
    /// Lower percentile (in percent) of the robust static bounds per axis; the
    /// upper one is 100 minus it. Default 1.
    pub bounds_percentile: f32,
    /// Grow the robust box by this fraction of its size on every side before
    /// testing. Default 0.5 (our choice: keeps the sparse edges of a scene).
    pub bounds_margin: f32,
}

impl Default for CleanOptions {
    fn default() -> Self {
        CleanOptions {
            min_opacity: 0.005,
            min_views: 1,
            view_margin_sigma: 3.0,
            max_scale_over_median: 50.0,
            max_footprint: 1.0,
            max_scale_extent_fraction: 0.0,
            bounds_percentile: 1.0,
            bounds_margin: 0.5,
        }
    }
}

impl CleanOptions {
    /// Check ranges.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: &str| Err(SplatError::Invalid(format!("clean options: {m}")));
        if !(0.0..1.0).contains(&self.min_opacity) {
            return bad("min_opacity must be in [0, 1)");
        }
        if !(self.view_margin_sigma >= 0.0 && self.view_margin_sigma.is_finite()) {
            return bad("view_margin_sigma must be ≥ 0");
        }
        if self.max_scale_over_median.is_nan() || self.max_scale_over_median <= 1.0 {
            return bad("max_scale_over_median must be > 1");
        }
        if !(self.max_scale_extent_fraction >= 0.0 && self.max_scale_extent_fraction.is_finite()) {
            return bad("max_scale_extent_fraction must be ≥ 0 (0 = off)");
        }
        if !(self.max_footprint >= 0.0 && self.max_footprint.is_finite()) {
            return bad("max_footprint must be ≥ 0 (0 = off)");
        }
        if !(0.0..50.0).contains(&self.bounds_percentile) {
            return bad("bounds_percentile must be in [0, 50)");
        }
        if !(self.bounds_margin >= 0.0 && self.bounds_margin.is_finite()) {
            return bad("bounds_margin must be ≥ 0");
        }
        Ok(())
    }
}

/// What is known about the capture: training cameras and static 3D points
/// (both optional; empty slices mean unknown).
#[derive(Debug, Clone, Default)]
pub struct SceneGeometry {
    /// Training cameras (world-to-camera, OpenCV axes).
    pub cameras: Vec<RenderCamera>,
    /// Static scene points, e.g. COLMAP points3D of the masked reconstruction.
    pub points: Vec<[f32; 3]>,
}

impl SceneGeometry {
    /// The training cameras of a loaded scene (the `clutter`/train split, or
    /// every frame without split.json; frames without a pose are skipped) and
    /// its COLMAP points3D when it has a model.
    pub fn from_scene(scene: &loader::scene::Scene) -> Self {
        let cameras = scene
            .split_indices("train")
            .into_iter()
            .filter_map(|i| {
                let f = &scene.frames[i];
                Some(RenderCamera::from_loader(&f.intrinsics, f.pose.as_ref()?))
            })
            .collect();
        let points = scene
            .model
            .as_ref()
            .map(|m| {
                m.points3d
                    .values()
                    .map(|p| [p.xyz[0] as f32, p.xyz[1] as f32, p.xyz[2] as f32])
                    .collect()
            })
            .unwrap_or_default();
        SceneGeometry { cameras, points }
    }

    /// Cameras and points of a COLMAP model (every registered image; pinhole
    /// intrinsics at the model's resolution).
    pub fn from_colmap(model: &loader::colmap::ColmapModel) -> Self {
        let cameras = model
            .images
            .values()
            .filter_map(|im| {
                let cam = model.cameras.get(&im.camera_id)?;
                Some(RenderCamera::from_loader(&cam.intrinsics(), &im.pose))
            })
            .collect();
        let points = model
            .points3d
            .values()
            .map(|p| [p.xyz[0] as f32, p.xyz[1] as f32, p.xyz[2] as f32])
            .collect();
        SceneGeometry { cameras, points }
    }
}

/// How many splats each criterion removed, and the statistics used.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct CleanReport {
    pub input: usize,
    pub kept: usize,
    pub removed_transparent: usize,
    pub removed_unseen: usize,
    pub removed_oversized: usize,
    pub removed_outside_bounds: usize,
    /// False when no cameras were given and the "unseen" criterion was skipped.
    pub unseen_checked: bool,
    /// Number of cameras used for the visibility test.
    pub cameras: usize,
    /// "points" (static scene points) or "splats" (splat centres).
    pub bounds_source: String,
    /// The box splats had to lie in (after the margin).
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
    /// Scene extent used by the oversized rule (world units).
    pub scene_extent: f32,
    /// "cameras" (INRIA cameras_extent) or "bounds" (half the robust box diagonal).
    pub extent_source: String,
    /// Median largest σ of the splats that passed the opacity test.
    pub median_scale: f32,
    /// Human-readable notes (e.g. skipped criteria).
    pub notes: Vec<String>,
}

/// The `q`-quantile (0..1) of `v` (nearest rank on the sorted values).
fn quantile(v: &mut [f32], q: f32) -> f32 {
    v.sort_by(f32::total_cmp);
    let idx = ((v.len() - 1) as f32 * q).round() as usize;
    v[idx.min(v.len() - 1)]
}

/// INRIA's cameras_extent: 1.1 × the largest distance of a camera centre from
/// the mean centre.
pub fn cameras_extent(cams: &[RenderCamera]) -> f32 {
    if cams.is_empty() {
        return 0.0;
    }
    let centres: Vec<[f32; 3]> = cams.iter().map(RenderCamera::center).collect();
    let mut mean = [0.0f32; 3];
    for c in &centres {
        for a in 0..3 {
            mean[a] += c[a] / centres.len() as f32;
        }
    }
    let max = centres
        .iter()
        .map(|c| {
            ((c[0] - mean[0]).powi(2) + (c[1] - mean[1]).powi(2) + (c[2] - mean[2]).powi(2)).sqrt()
        })
        .fold(0.0, f32::max);
    1.1 * max
}

/// Number of cameras (up to `need`) whose view the splat reaches.
fn views(p: [f32; 3], sigma: f32, cams: &[RenderCamera], margin_sigma: f32, need: u32) -> u32 {
    let mut n = 0;
    for c in cams {
        let r = &c.rotation;
        let z = r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + c.translation[2];
        if z <= c.near || z >= c.far {
            continue;
        }
        let x = r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + c.translation[0];
        let y = r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + c.translation[1];
        let u = c.fx * x / z + c.cx;
        let v = c.fy * y / z + c.cy;
        let m = margin_sigma * sigma * c.fx.max(c.fy) / z;
        if u >= -m && u <= c.width as f32 + m && v >= -m && v <= c.height as f32 + m {
            n += 1;
            if n >= need {
                break;
            }
        }
    }
    n
}

/// The 3σ radius of a splat (centre `p`, largest σ `sigma`) in pixels, seen
/// from the training camera whose centre is nearest, over that image's larger
/// side. A splat at a camera centre counts as infinitely large.
fn footprint_fraction(p: [f32; 3], sigma: f32, cams: &[RenderCamera], centres: &[[f32; 3]]) -> f32 {
    let mut best = (f32::INFINITY, 0usize);
    for (k, c) in centres.iter().enumerate() {
        let d = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
        if d < best.0 {
            best = (d, k);
        }
    }
    let (d, k) = best;
    let c = &cams[k];
    if d <= 0.0 {
        return f32::INFINITY;
    }
    3.0 * sigma * c.fx.max(c.fy) / d / c.width.max(c.height).max(1) as f32
}

/// Remove distractor leftovers and debris; returns the kept splats (in their
/// original order) and the report.
pub fn clean(
    s: &Splats,
    scene: &SceneGeometry,
    opts: &CleanOptions,
) -> Result<(Splats, CleanReport)> {
    opts.validate()?;
    crate::error::check_splats(s)?;
    let n = s.len();
    let mut rep = CleanReport {
        input: n,
        cameras: scene.cameras.len(),
        ..Default::default()
    };
    // 0 = keep, 1..=4 = removed by criterion.
    let mut verdict = vec![0u8; n];
    let sigma: Vec<f32> = s
        .log_scales
        .iter()
        .map(|l| l[0].max(l[1]).max(l[2]).exp())
        .collect();
    for (v, &o) in verdict.iter_mut().zip(&s.opacity_logits) {
        let a = sigmoid(o);
        if a.is_nan() || a < opts.min_opacity {
            *v = 1;
        }
    }
    let opaque: Vec<usize> = (0..n).filter(|&i| verdict[i] == 0).collect();

    // 2. unseen
    rep.unseen_checked = !scene.cameras.is_empty() && opts.min_views > 0;
    if rep.unseen_checked {
        let seen: Vec<bool> = opaque
            .par_iter()
            .map(|&i| {
                views(
                    s.means[i],
                    sigma[i],
                    &scene.cameras,
                    opts.view_margin_sigma,
                    opts.min_views,
                ) >= opts.min_views
            })
            .collect();
        for (&i, ok) in opaque.iter().zip(seen) {
            if !ok {
                verdict[i] = 2;
            }
        }
    } else {
        rep.notes
            .push("unseen criterion skipped: no training cameras given (--scene)".into());
    }

    // Robust static bounds.
    let (pts, source): (Vec<[f32; 3]>, &str) = if scene.points.is_empty() {
        (opaque.iter().map(|&i| s.means[i]).collect(), "splats")
    } else {
        (scene.points.clone(), "points")
    };
    rep.bounds_source = source.into();
    let mut lo = [f32::NEG_INFINITY; 3];
    let mut hi = [f32::INFINITY; 3];
    let mut half_diag = 0.0f32;
    if !pts.is_empty() {
        let q = opts.bounds_percentile / 100.0;
        for a in 0..3 {
            let mut v: Vec<f32> = pts.iter().map(|p| p[a]).filter(|x| x.is_finite()).collect();
            if v.is_empty() {
                continue;
            }
            let (l, h) = (quantile(&mut v, q), quantile(&mut v, 1.0 - q));
            let size = h - l;
            half_diag += (size / 2.0).powi(2);
            lo[a] = l - opts.bounds_margin * size;
            hi[a] = h + opts.bounds_margin * size;
        }
    }
    rep.bounds_min = lo;
    rep.bounds_max = hi;

    // 3. oversized
    let mut opaque_sigma: Vec<f32> = opaque.iter().map(|&i| sigma[i]).collect();
    rep.median_scale = if opaque_sigma.is_empty() {
        0.0
    } else {
        quantile(&mut opaque_sigma, 0.5)
    };
    let (extent, extent_source) = if scene.cameras.len() >= 2 {
        (cameras_extent(&scene.cameras), "cameras")
    } else {
        (half_diag.sqrt(), "bounds")
    };
    rep.scene_extent = extent;
    rep.extent_source = extent_source.into();
    let median_limit = opts.max_scale_over_median * rep.median_scale;
    let extent_limit = if extent > 0.0 && opts.max_scale_extent_fraction > 0.0 {
        opts.max_scale_extent_fraction * extent
    } else {
        f32::INFINITY
    };
    let centres: Vec<[f32; 3]> = scene.cameras.iter().map(RenderCamera::center).collect();
    let use_footprint = opts.max_footprint > 0.0 && !centres.is_empty();
    for &i in &opaque {
        if verdict[i] != 0 {
            continue;
        }
        let too_big = sigma[i] > median_limit
            || sigma[i] > extent_limit
            || (use_footprint
                && footprint_fraction(s.means[i], sigma[i], &scene.cameras, &centres)
                    > opts.max_footprint);
        if too_big {
            verdict[i] = 3;
        }
    }
    // 4. outside bounds
    for &i in &opaque {
        let p = s.means[i];
        if verdict[i] == 0 && (0..3).any(|a| !(p[a] >= lo[a] && p[a] <= hi[a])) {
            verdict[i] = 4;
        }
    }

    let keep: Vec<usize> = (0..n).filter(|&i| verdict[i] == 0).collect();
    for v in &verdict {
        match v {
            1 => rep.removed_transparent += 1,
            2 => rep.removed_unseen += 1,
            3 => rep.removed_oversized += 1,
            4 => rep.removed_outside_bounds += 1,
            _ => {}
        }
    }
    rep.kept = keep.len();
    Ok((select(s, &keep), rep))
}

/// The splats at `idx`, in that order.
pub fn select(s: &Splats, idx: &[usize]) -> Splats {
    let k3 = s.coeffs_per_channel() * 3;
    Splats {
        means: idx.iter().map(|&i| s.means[i]).collect(),
        log_scales: idx.iter().map(|&i| s.log_scales[i]).collect(),
        rotations: idx.iter().map(|&i| s.rotations[i]).collect(),
        opacity_logits: idx.iter().map(|&i| s.opacity_logits[i]).collect(),
        sh: idx
            .iter()
            .flat_map(|&i| s.sh[i * k3..(i + 1) * k3].iter().copied())
            .collect(),
        sh_degree: s.sh_degree,
    }
}

#[cfg(test)]
#[path = "clean_tests.rs"]
mod tests;
