//! Mask evaluation as in DAVIS (Perazzi et al., CVPR 2016): region
//! similarity J (IoU of the moving region per frame, 1 when both are empty),
//! its mean per sequence, recall (fraction of frames with J > 0.5) and
//! decay (mean J of the first quarter of frames minus the last quarter),
//! plus pixel precision and recall of "moving".
//!
//! Ground truth is 255 = moving, `<stem>.png`. Predictions are accepted in
//! romo's `masks/` convention (`<image name>.png`, 255 = keep) or as
//! 255-is-moving `<stem>.png`; which one was read is reported.

use crate::{Result, RomoError};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Metrics of one sequence.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SequenceMetrics {
    /// Sequence name (folder name, or "" for a flat folder).
    pub name: String,
    /// Frames evaluated.
    pub frames: usize,
    /// J per frame, in GT order.
    pub j_per_frame: Vec<f64>,
    /// Mean J.
    pub j_mean: f64,
    /// Fraction of frames with J > 0.5.
    pub j_recall: f64,
    /// Mean J of the first quarter minus the last quarter.
    pub j_decay: f64,
    /// Pixel precision of "moving" (TP / (TP + FP)); 1 when nothing predicted.
    pub precision: f64,
    /// Pixel recall of "moving" (TP / (TP + FN)); 1 when nothing is moving.
    pub recall: f64,
    /// How predictions were read.
    pub pred_convention: String,
}

/// Metrics over all sequences found.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MaskMetrics {
    /// Per sequence.
    pub sequences: Vec<SequenceMetrics>,
    /// Mean over sequences of the mean J.
    pub j_mean: f64,
    /// Mean of the per-sequence recall.
    pub j_recall: f64,
    /// Mean of the per-sequence decay.
    pub j_decay: f64,
    /// Mean precision.
    pub precision: f64,
    /// Mean recall.
    pub recall: f64,
}

fn pngs(dir: &Path) -> Result<Vec<PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|e| loader::LoaderError::io(dir, e))?;
    let mut v: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
        .collect();
    v.sort();
    Ok(v)
}

fn subdirs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_dir())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn stem_of(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Boolean "moving" map of a prediction, resized (nearest) to `w × h`.
fn read_moving(p: &Path, keep: bool, w: u32, h: u32) -> Result<Vec<bool>> {
    let m = loader::io::read_gray8(p)?;
    let m = if m.dimensions() == (w, h) {
        m
    } else {
        image::imageops::resize(&m, w, h, image::imageops::FilterType::Nearest)
    };
    Ok(m.as_raw()
        .iter()
        .map(|v| if keep { *v < 128 } else { *v >= 128 })
        .collect())
}

/// Evaluate one sequence: `gt` holds `<stem>.png`; `pred` holds predictions.
pub fn evaluate_sequence(pred: &Path, gt: &Path, name: &str) -> Result<SequenceMetrics> {
    evaluate_sequence_excluding(pred, gt, name, &[])
}

/// [`evaluate_sequence`] leaving out the ground-truth frames whose stem is
/// in `exclude` (e.g. a scene's held-out `extra` views: empty ground truth
/// and all-keep masks would each score a perfect J of 1).
pub fn evaluate_sequence_excluding(
    pred: &Path,
    gt: &Path,
    name: &str,
    exclude: &[String],
) -> Result<SequenceMetrics> {
    let pred = if pngs(pred)?.is_empty() && pred.join("masks").is_dir() {
        pred.join("masks")
    } else {
        pred.to_path_buf()
    };
    let mut gts = pngs(gt)?;
    gts.retain(|p| !exclude.contains(&stem_of(p)));
    if gts.is_empty() {
        return Err(RomoError::Input(format!(
            "{}: no ground-truth PNGs",
            gt.display()
        )));
    }
    let preds = pngs(&pred)?;
    // Match GT stem "00000" to "00000.png" or "00000.<ext>.png".
    let find = |stem: &str| -> Option<(PathBuf, bool)> {
        preds.iter().find_map(|p| {
            let s = stem_of(p);
            if s == stem {
                Some((p.clone(), false))
            } else if Path::new(&s)
                .file_stem()
                .is_some_and(|x| x.to_string_lossy() == stem)
                && Path::new(&s).extension().is_some()
            {
                Some((p.clone(), true))
            } else {
                None
            }
        })
    };
    let matched: Vec<(PathBuf, PathBuf, bool)> = gts
        .iter()
        .filter_map(|g| {
            find(&stem_of(g)).map(|(p, named_like_masks)| (g.clone(), p, named_like_masks))
        })
        .collect();
    if matched.is_empty() {
        return Err(RomoError::Input(format!(
            "{}: no prediction matches a ground-truth name in {}",
            pred.display(),
            gt.display()
        )));
    }
    // Convention: `<name>.<ext>.png` files are masks/ (keep); plain
    // `<stem>.png` files are keep when mostly white, else moving.
    let named = matched.iter().filter(|m| m.2).count() * 2 > matched.len();
    let keep = if named {
        true
    } else {
        let (mut s, mut n) = (0u64, 0u64);
        for (_, p, _) in matched.iter().take(10) {
            let m = loader::io::read_gray8(p)?;
            s += m.as_raw().iter().map(|v| *v as u64).sum::<u64>();
            n += m.as_raw().len() as u64;
        }
        s > 127 * n.max(1)
    };
    let convention = if keep {
        "keep (masks/ convention, 255 = static)"
    } else {
        "moving (255 = moving)"
    };
    let (mut tp, mut fp, mut fnn) = (0u64, 0u64, 0u64);
    let mut js = Vec::with_capacity(matched.len());
    for (g, p, _) in &matched {
        let gm = loader::masks::read_moving(g)?;
        let (w, h) = gm.dimensions();
        let gv: Vec<bool> = gm.as_raw().iter().map(|v| *v >= 128).collect();
        let pv = read_moving(p, keep, w, h)?;
        let (mut i, mut u) = (0u64, 0u64);
        for (a, b) in gv.iter().zip(&pv) {
            i += (*a && *b) as u64;
            u += (*a || *b) as u64;
            fp += (!*a && *b) as u64;
            fnn += (*a && !*b) as u64;
        }
        tp += i;
        js.push(if u == 0 { 1.0 } else { i as f64 / u as f64 });
    }
    let n = js.len();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let q = (n / 4).max(1);
    Ok(SequenceMetrics {
        name: name.to_string(),
        frames: n,
        j_mean: mean(&js),
        j_recall: js.iter().filter(|j| **j > 0.5).count() as f64 / n as f64,
        j_decay: mean(&js[..q]) - mean(&js[n - q..]),
        precision: if tp + fp == 0 {
            1.0
        } else {
            tp as f64 / (tp + fp) as f64
        },
        recall: if tp + fnn == 0 {
            1.0
        } else {
            tp as f64 / (tp + fnn) as f64
        },
        j_per_frame: js,
        pred_convention: convention.into(),
    })
}

/// Evaluate predictions against ground truth. When `gt_dir` holds PNGs it is
/// one sequence; when it holds sub-folders (DAVIS `Annotations/480p/`), each
/// sub-folder with a same-named prediction folder is a sequence.
pub fn evaluate_masks(pred_dir: &Path, gt_dir: &Path) -> Result<MaskMetrics> {
    evaluate_masks_excluding(pred_dir, gt_dir, &[])
}

/// [`evaluate_masks`] leaving out, in every sequence, the ground-truth
/// frames whose stem is in `exclude` (see [`evaluate_sequence_excluding`]).
pub fn evaluate_masks_excluding(
    pred_dir: &Path,
    gt_dir: &Path,
    exclude: &[String],
) -> Result<MaskMetrics> {
    if !gt_dir.is_dir() {
        return Err(RomoError::Input(format!(
            "{}: ground-truth folder not found",
            gt_dir.display()
        )));
    }
    if !pred_dir.is_dir() {
        return Err(RomoError::Input(format!(
            "{}: prediction folder not found",
            pred_dir.display()
        )));
    }
    let sequences = if !pngs(gt_dir)?.is_empty() {
        vec![evaluate_sequence_excluding(pred_dir, gt_dir, "", exclude)?]
    } else {
        let mut v = Vec::new();
        for g in subdirs(gt_dir) {
            let name = g
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            let p = pred_dir.join(&name);
            if p.is_dir() {
                v.push(evaluate_sequence_excluding(&p, &g, &name, exclude)?);
            }
        }
        if v.is_empty() {
            return Err(RomoError::Input(format!(
                "{}: no PNGs and no sequence folder matching one in {}",
                gt_dir.display(),
                pred_dir.display()
            )));
        }
        v
    };
    let m = |f: fn(&SequenceMetrics) -> f64| {
        sequences.iter().map(f).sum::<f64>() / sequences.len() as f64
    };
    Ok(MaskMetrics {
        j_mean: m(|s| s.j_mean),
        j_recall: m(|s| s.j_recall),
        j_decay: m(|s| s.j_decay),
        precision: m(|s| s.precision),
        recall: m(|s| s.recall),
        sequences,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::GrayImage;

    #[test]
    fn j_precision_recall_and_conventions() {
        let d = tempfile::tempdir().unwrap();
        let (gt, pk, pm) = (
            d.path().join("gt"),
            d.path().join("pk"),
            d.path().join("pm"),
        );
        // GT: left half moving in frame 0, nothing moving in frame 1.
        let g0 = GrayImage::from_fn(10, 4, |x, _| image::Luma([if x < 5 { 255 } else { 0 }]));
        let g1 = GrayImage::new(10, 4);
        loader::io::write_png_gray8(gt.join("00000.png"), &g0).unwrap();
        loader::io::write_png_gray8(gt.join("00001.png"), &g1).unwrap();
        // Prediction: moving x < 4 in frame 0 (IoU 16/20 = 0.8), empty in 1 (J = 1).
        let p0 = GrayImage::from_fn(10, 4, |x, _| image::Luma([if x < 4 { 255 } else { 0 }]));
        let inv = |m: &GrayImage| {
            GrayImage::from_fn(10, 4, |x, y| image::Luma([255 - m.get_pixel(x, y).0[0]]))
        };
        loader::io::write_png_gray8(pm.join("00000.png"), &p0).unwrap();
        loader::io::write_png_gray8(pm.join("00001.png"), &g1).unwrap();
        loader::io::write_png_gray8(pk.join("00000.jpg.png"), &inv(&p0)).unwrap();
        loader::io::write_png_gray8(pk.join("00001.jpg.png"), &inv(&g1)).unwrap();
        for (p, conv) in [(&pm, "moving"), (&pk, "keep")] {
            let m = evaluate_masks(p, &gt).unwrap();
            let s = &m.sequences[0];
            assert!(s.pred_convention.starts_with(conv), "{}", s.pred_convention);
            assert!((s.j_per_frame[0] - 0.8).abs() < 1e-12 && s.j_per_frame[1] == 1.0);
            assert!((m.j_mean - 0.9).abs() < 1e-12);
            assert_eq!(s.j_recall, 1.0);
            assert!((s.precision - 1.0).abs() < 1e-12 && (s.recall - 0.8).abs() < 1e-12);
            assert!((s.j_decay - (0.8 - 1.0)).abs() < 1e-12);
        }
        assert!(evaluate_masks(&d.path().join("nope"), &gt).is_err());
        // Leaving out frame 1 (an empty "held-out" frame scoring J = 1).
        let s = evaluate_sequence_excluding(&pk, &gt, "", &["00001".to_string()]).unwrap();
        assert_eq!(s.frames, 1);
        assert!((s.j_mean - 0.8).abs() < 1e-12);
        // Leaving out everything is an error, not a J of nothing.
        let all = ["00000".to_string(), "00001".to_string()];
        assert!(evaluate_sequence_excluding(&pk, &gt, "", &all).is_err());
    }
}
