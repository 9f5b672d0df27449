//! The pose crate's error type. Every message is one line that names the file,
//! the COLMAP step or the option at fault, and — where there is one — the fix.

use std::path::PathBuf;

/// Errors from running COLMAP, reading trajectories or computing pose metrics.
#[derive(Debug, thiserror::Error)]
pub enum PoseError {
    /// Reading or writing a file through the loader failed.
    #[error(transparent)]
    Loader(#[from] loader::LoaderError),
    /// A plain I/O error on a path.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A COLMAP database could not be read.
    #[error("{}: cannot read the COLMAP database: {reason}", path.display())]
    Database { path: PathBuf, reason: String },
    /// The `colmap` executable could not be started.
    #[error(
        "colmap not found (tried `{binary}`: {reason}); install it with `apt-get install -y colmap` or pass its path"
    )]
    ColmapMissing { binary: String, reason: String },
    /// A COLMAP step exited with a non-zero status.
    #[error("colmap {step} failed ({status}); log {}: {tail}", log.display())]
    StepFailed {
        step: String,
        status: String,
        log: PathBuf,
        tail: String,
    },
    /// The run was cancelled while `step` ran (its process was killed; the
    /// database keeps what was done, so a rerun resumes).
    #[error("colmap {step} cancelled; rerun to resume")]
    Cancelled { step: String },
    /// COLMAP ran but produced no usable reconstruction.
    #[error("{0}")]
    NoModel(String),
    /// An option or argument is invalid.
    #[error("invalid argument: {0}")]
    Invalid(String),
    /// The data cannot support the requested computation (too few frames,
    /// collinear camera centres, ...).
    #[error("{0}")]
    Degenerate(String),
}

/// Result alias for the pose crate.
pub type Result<T> = std::result::Result<T, PoseError>;

impl PoseError {
    /// Build an I/O error for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        PoseError::Io {
            path: path.into(),
            source,
        }
    }
}
