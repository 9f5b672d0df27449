//! What the measurement examples share: checked environment variables and
//! one error line instead of a panic.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// Any error, printed as one line by [`main`].
pub type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// Run `run`; on error print `name: error` and exit with status 2.
pub fn main(name: &str, run: impl FnOnce() -> Res<()>) -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{name}: {e}");
            std::process::ExitCode::from(2)
        }
    }
}

/// `$DAVIS_DIR`, default `../shared/data/davis2016` beside the repository.
pub fn davis_dir() -> PathBuf {
    std::env::var_os("DAVIS_DIR").map_or_else(
        || {
            PathBuf::from(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../../shared/data/davis2016"
            ))
        },
        PathBuf::from,
    )
}

/// `$ROMO_OPTS`, a partial `RomoOptions` JSON (default: the defaults).
pub fn romo_options() -> Res<romo::RomoOptions> {
    Ok(match std::env::var("ROMO_OPTS") {
        Ok(s) => serde_json::from_str(&s).map_err(|e| format!("ROMO_OPTS: {e}"))?,
        Err(_) => Default::default(),
    })
}

/// `$name` parsed as a `T`, `default` when unset; a value that does not
/// parse is an error naming the variable and the value.
pub fn env_or<T>(name: &str, default: T) -> Res<T>
where
    T: std::str::FromStr,
    T::Err: std::fmt::Display,
{
    match std::env::var(name) {
        Ok(v) => Ok(v.parse().map_err(|e| format!("{name}={v}: {e}"))?),
        Err(_) => Ok(default),
    }
}

/// `$FRAME_STEP`: keep every N-th frame (default 1); 0 is an error.
pub fn frame_step() -> Res<usize> {
    match env_or("FRAME_STEP", 1)? {
        0 => Err("FRAME_STEP=0: need a positive step".into()),
        step => Ok(step),
    }
}

/// `$MAXF`: keep only the first N frames, a short clip (default all);
/// fewer than 2 is an error, as RoMo needs a pair.
pub fn max_frames() -> Res<usize> {
    match env_or("MAXF", usize::MAX)? {
        n @ (0 | 1) => Err(format!("MAXF={n}: need at least 2 frames").into()),
        n => Ok(n),
    }
}

/// `$SEQS`: the comma-separated sequences to run (None: all).
pub fn sequences() -> Option<Vec<String>> {
    std::env::var("SEQS")
        .ok()
        .map(|s| s.split(',').map(String::from).collect())
}

/// The last component of `p` as text ("" for none).
pub fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}
