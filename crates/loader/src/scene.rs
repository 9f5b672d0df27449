//! The scene folder (see DESIGN.md): frames in capture order, cameras and
//! poses, masks, split and ground-truth motion.

use crate::camera::{Camera, Intrinsics, Pose};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// One frame of a scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Frame {
    /// Image file name relative to `images/` (e.g. `0001.jpg`); this is the
    /// key used by COLMAP, masks (`masks/<name>.png`) and split.json.
    pub name: String,
    /// Full path of the image file actually read (may be in `images_N/`).
    pub image_path: PathBuf,
    /// Pinhole intrinsics at the loaded resolution (after downscale).
    pub intrinsics: Intrinsics,
    /// The full COLMAP camera at the original resolution, when known.
    pub camera: Option<Camera>,
    /// World-to-camera pose (COLMAP convention), when known.
    pub pose: Option<Pose>,
    /// `masks/<name>.png` when present (255 keep, 0 moving).
    pub mask_path: Option<PathBuf>,
    /// `gt_motion/<stem>.png` when present (255 moving).
    pub gt_motion_path: Option<PathBuf>,
}
