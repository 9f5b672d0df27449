//! Stage bookkeeping for `romosplat run`: a stage is skipped when all of its
//! outputs exist and are newer than all of its inputs (so a rerun resumes
//! where it stopped, like `make`), and `--from STAGE` forces that stage and
//! every later one to run again.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// The stages of `romosplat run`, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Stage {
    /// Video → frames (only with `--video`).
    Frames,
    /// RoMo motion masks.
    Mask,
    /// Masked COLMAP.
    Pose,
    /// Masked splat training.
    Train,
    /// Cleaned export.
    Export,
    /// HTML report.
    Report,
}

impl Stage {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Frames => "frames",
            Stage::Mask => "mask",
            Stage::Pose => "pose",
            Stage::Train => "train",
            Stage::Export => "export",
            Stage::Report => "report",
        }
    }
}

/// Newest modification time of a file, or of every file below a folder.
/// `None` when the path does not exist or a folder holds no file.
pub fn newest_mtime(path: &Path) -> Option<SystemTime> {
    let meta = std::fs::metadata(path).ok()?;
    if meta.is_file() {
        return meta.modified().ok();
    }
    let mut newest: Option<SystemTime> = None;
    for entry in std::fs::read_dir(path).ok()?.flatten() {
        if let Some(t) = newest_mtime(&entry.path()) {
            newest = Some(newest.map_or(t, |n| n.max(t)));
        }
    }
    newest
}

/// Oldest modification time among files (a folder counts by its newest file:
/// an output folder is as old as its last write). `None` if any is missing.
fn oldest_output(paths: &[PathBuf]) -> Option<SystemTime> {
    let mut oldest: Option<SystemTime> = None;
    for p in paths {
        let t = newest_mtime(p)?;
        oldest = Some(oldest.map_or(t, |o| o.min(t)));
    }
    oldest
}

/// True when every output exists and none is older than any input.
pub fn is_fresh(outputs: &[PathBuf], inputs: &[PathBuf]) -> bool {
    if outputs.is_empty() {
        return false;
    }
    let Some(out_t) = oldest_output(outputs) else {
        return false;
    };
    inputs
        .iter()
        .filter_map(|p| newest_mtime(p))
        .all(|t| t <= out_t)
}

/// Decide whether a stage runs: forced by `--from`, or stale.
pub fn should_run(
    stage: Stage,
    from: Option<Stage>,
    outputs: &[PathBuf],
    inputs: &[PathBuf],
) -> bool {
    if from.is_some_and(|f| stage >= f) {
        return true;
    }
    !is_fresh(outputs, inputs)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use std::fs::File;
    use std::time::Duration;

    fn touch(p: &Path, t: SystemTime) {
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        let f = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(p)
            .unwrap();
        f.set_modified(t).unwrap();
    }

    #[test]
    fn freshness_follows_mtimes() {
        let d = tempfile::tempdir().unwrap();
        let t0 = SystemTime::now() - Duration::from_secs(100);
        let input = d.path().join("images/a.png");
        let out = d.path().join("masks/a.png.png");
        touch(&input, t0);
        // Missing output: stale.
        assert!(!is_fresh(
            std::slice::from_ref(&out),
            std::slice::from_ref(&input)
        ));
        touch(&out, t0 + Duration::from_secs(10));
        assert!(is_fresh(
            &[d.path().join("masks")],
            &[d.path().join("images")]
        ));
        // An input newer than the output makes it stale again.
        touch(&d.path().join("images/b.png"), t0 + Duration::from_secs(20));
        assert!(!is_fresh(
            &[d.path().join("masks")],
            &[d.path().join("images")]
        ));
        // An empty output folder is not an output.
        std::fs::create_dir_all(d.path().join("empty")).unwrap();
        assert!(!is_fresh(&[d.path().join("empty")], &[]));
    }

    #[test]
    fn from_forces_this_and_later_stages() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("x");
        touch(&out, SystemTime::now());
        let outs = [out];
        assert!(!should_run(Stage::Mask, None, &outs, &[]));
        assert!(!should_run(Stage::Mask, Some(Stage::Pose), &outs, &[]));
        assert!(should_run(Stage::Pose, Some(Stage::Pose), &outs, &[]));
        assert!(should_run(Stage::Report, Some(Stage::Pose), &outs, &[]));
    }
}
