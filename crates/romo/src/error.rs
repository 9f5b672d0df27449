//! The romo error type: every failure is one line naming what went wrong
//! (and the file, when there is one).

/// Errors from motion segmentation.
#[derive(Debug, thiserror::Error)]
pub enum RomoError {
    /// Reading or writing a file failed (the loader's message names it).
    #[error(transparent)]
    Loader(#[from] loader::LoaderError),
    /// An options struct failed `validate()`.
    #[error("invalid options: {0}")]
    Options(String),
    /// Input data is unusable (sizes, too few frames, ...).
    #[error("{0}")]
    Input(String),
    /// A geometric estimate could not be made (too few correspondences).
    #[error("geometry: {0}")]
    Geometry(String),
    /// The ONNX runtime or a model failed.
    #[error("onnx: {0}")]
    Onnx(String),
}

/// Result alias.
pub type Result<T> = std::result::Result<T, RomoError>;
