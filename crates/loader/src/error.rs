//! The loader's error type. Every variant names the file it is about, so a
//! user sees `<path>: <problem>` on one line.

use std::path::{Path, PathBuf};

/// Errors from reading or writing anything on disk.
#[derive(Debug, thiserror::Error)]
pub enum LoaderError {
    /// An operating-system I/O error on a file.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file exists but its content is not what the format requires.
    #[error("{}: {msg}", path.display())]
    Format { path: PathBuf, msg: String },
    /// A file the scene refers to does not exist.
    #[error("{}: file not found{}", path.display(), if context.is_empty() { String::new() } else { format!(" ({context})") })]
    Missing { path: PathBuf, context: String },
    /// An image could not be decoded or encoded.
    #[error("{}: image error: {source}", path.display())]
    Image {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    /// An external program (ffmpeg, ...) is missing or failed.
    #[error("{0}")]
    External(String),
    /// Invalid option or argument value.
    #[error("invalid argument: {0}")]
    Invalid(String),
}

/// Result alias for the loader.
pub type Result<T> = std::result::Result<T, LoaderError>;

impl LoaderError {
    /// Build an I/O error for `path`.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        LoaderError::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
    /// Build a format error for `path`.
    pub fn format(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        LoaderError::Format {
            path: path.as_ref().to_path_buf(),
            msg: msg.into(),
        }
    }
    /// Build an image error for `path`.
    pub fn image(path: impl AsRef<Path>, source: image::ImageError) -> Self {
        LoaderError::Image {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
}

/// A TOML parse error as one line: `path: line L, column C: message`
/// (toml's own text quotes the source over several lines).
pub fn toml_error(path: &Path, text: &str, e: &toml::de::Error) -> LoaderError {
    let msg = e.message().split_whitespace().collect::<Vec<_>>().join(" ");
    let msg = match e.span() {
        Some(span) => {
            let before = &text.as_bytes()[..span.start.min(text.len())];
            let line = before.iter().filter(|b| **b == b'\n').count() + 1;
            let col = before.iter().rev().take_while(|b| **b != b'\n').count() + 1;
            format!("line {line}, column {col}: {msg}")
        }
        None => msg,
    };
    LoaderError::format(path, msg)
}
