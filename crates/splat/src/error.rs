//! The splat crate's error type: one line naming the file or input and the
//! problem.

use std::path::PathBuf;

/// Errors from rendering, training, metrics and splat I/O.
#[derive(Debug, thiserror::Error)]
pub enum SplatError {
    /// Inconsistent or unusable input (wrong lengths, bad options, ...).
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A file could not be read or written, or has bad contents.
    #[error("{path}: {msg}")]
    File { path: PathBuf, msg: String },
    /// Errors from the loader crate (scene folders, images, PLY).
    #[error(transparent)]
    Loader(#[from] loader::LoaderError),
    /// GPU backend failure.
    #[error("gpu: {0}")]
    Gpu(String),
}

/// Result alias.
pub type Result<T> = std::result::Result<T, SplatError>;

/// Check that a [`crate::Splats`] is internally consistent.
pub fn check_splats(s: &crate::Splats) -> Result<()> {
    let n = s.len();
    if s.sh_degree > crate::types::MAX_SH_DEGREE {
        return Err(SplatError::Invalid(format!(
            "sh_degree {} > 3",
            s.sh_degree
        )));
    }
    let k3 = s.coeffs_per_channel() * 3;
    if s.log_scales.len() != n
        || s.rotations.len() != n
        || s.opacity_logits.len() != n
        || s.sh.len() != n * k3
    {
        return Err(SplatError::Invalid(format!(
            "splat arrays disagree: {} means, {} scales, {} rotations, {} opacities, {} SH values (expected {})",
            n,
            s.log_scales.len(),
            s.rotations.len(),
            s.opacity_logits.len(),
            s.sh.len(),
            n * k3
        )));
    }
    Ok(())
}

/// Check a camera is renderable.
pub fn check_camera(c: &crate::RenderCamera) -> Result<()> {
    let finite = [c.fx, c.fy, c.cx, c.cy, c.near]
        .iter()
        .chain(c.rotation.iter().flatten())
        .chain(&c.translation)
        .all(|v| v.is_finite());
    if c.width == 0
        || c.height == 0
        || !finite
        || c.fx.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        || c.fy.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        || c.far.partial_cmp(&c.near) != Some(std::cmp::Ordering::Greater)
    {
        return Err(SplatError::Invalid(format!(
            "camera {}x{} fx {} fy {} near {} far {} is not renderable",
            c.width, c.height, c.fx, c.fy, c.near, c.far
        )));
    }
    Ok(())
}
