//! Summaries of COLMAP models (registered images, points, reprojection error,
//! camera) used to pick the mapper's best model and to report on it, and
//! installing a chosen model into the scene. Reading goes through
//! `loader::colmap`, the one place that knows the file formats.

use crate::error::{PoseError, Result};
use loader::colmap::{ColmapModel, read_model};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A model's points and first camera, as the pose stage reports them
/// (also flattened into [`crate::colmap_runner::ColmapReport`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelStats {
    /// Number of 3D points.
    pub points: usize,
    /// Mean of the points' reprojection errors, pixels (COLMAP's
    /// `ComputeMeanReprojectionError`; points with unknown error skipped).
    pub mean_reprojection_error: f64,
    /// Mean track length (observations per point).
    pub mean_track_length: f64,
    /// Model name of the first camera.
    pub camera_model: String,
    /// Parameters of the first camera.
    pub camera_params: Vec<f64>,
}

/// What the pose stage knows about a model.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelInfo {
    /// Registered image names, sorted.
    pub image_names: Vec<String>,
    pub stats: ModelStats,
    /// Whether any camera has non-zero distortion.
    pub has_distortion: bool,
}

impl ModelInfo {
    /// Number of registered images.
    pub fn registered(&self) -> usize {
        self.image_names.len()
    }
}

/// Summarise a model.
pub fn model_info(model: &ColmapModel) -> ModelInfo {
    let mut image_names: Vec<String> = model.images.values().map(|i| i.name.clone()).collect();
    image_names.sort();
    let errs: Vec<f64> = model
        .points3d
        .values()
        .map(|p| p.error)
        .filter(|e| e.is_finite() && *e >= 0.0)
        .collect();
    let mean_reprojection_error = if errs.is_empty() {
        0.0
    } else {
        errs.iter().sum::<f64>() / errs.len() as f64
    };
    let mean_track_length = if model.points3d.is_empty() {
        0.0
    } else {
        model
            .points3d
            .values()
            .map(|p| p.track.len() as f64)
            .sum::<f64>()
            / model.points3d.len() as f64
    };
    let first = model.cameras.values().next();
    ModelInfo {
        image_names,
        stats: ModelStats {
            points: model.points3d.len(),
            mean_reprojection_error,
            mean_track_length,
            camera_model: first
                .map(|c| c.model.name().to_string())
                .unwrap_or_default(),
            camera_params: first.map(|c| c.params.clone()).unwrap_or_default(),
        },
        has_distortion: model.cameras.values().any(|c| !c.is_pinhole()),
    }
}

/// Read and summarise the model in `dir`.
pub fn read_model_info(dir: &Path) -> Result<ModelInfo> {
    Ok(model_info(&read_model(dir)?))
}

/// Model files a folder may hold; all are replaced when a model is installed
/// so no stale text model (e.g. a generated scene's ground truth) survives
/// beside the new binary one.
const MODEL_FILES: [&str; 10] = [
    "cameras.bin",
    "images.bin",
    "points3D.bin",
    "cameras.txt",
    "images.txt",
    "points3D.txt",
    "rigs.bin",
    "frames.bin",
    "rigs.txt",
    "frames.txt",
];

/// Copy the binary model in `src` to `out` byte for byte (atomic writes),
/// removing any other model files in `out` first.
pub fn install_model(src: &Path, out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).map_err(|e| PoseError::io(out, e))?;
    let mut bytes = Vec::new();
    for name in ["cameras.bin", "images.bin", "points3D.bin"] {
        bytes.push((name, loader::io::read_bytes(src.join(name))?));
    }
    for name in MODEL_FILES {
        let p = out.join(name);
        if p.is_file() {
            std::fs::remove_file(&p).map_err(|e| PoseError::io(&p, e))?;
        }
    }
    for (name, b) in bytes {
        loader::io::write_bytes_atomic(out.join(name), &b)?;
    }
    Ok(())
}
