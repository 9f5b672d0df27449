//! Running one COLMAP step as a subprocess: both output streams go to a log
//! file in the work folder (COLMAP's own logs are kept for the user), lines
//! that show progress are forwarded to a callback, and a failure comes back as
//! an error carrying the exit status and the last lines of the log.

use crate::error::{PoseError, Result};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Number of log lines quoted in a failure message.
pub const TAIL_LINES: usize = 12;

/// What one finished step produced.
#[derive(Debug, Clone)]
pub struct StepOutcome {
    /// Wall time of the step in seconds.
    pub seconds: f64,
    /// The log file (stdout and stderr interleaved).
    pub log: PathBuf,
    /// Whether the process exited with status 0.
    pub success: bool,
    /// Exit status as text (`exit status: 1`, `signal: 9`, ...).
    pub status: String,
}

/// Check that `colmap` can be started; returns its version line
/// (e.g. `COLMAP 3.8 -- Structure-from-Motion and Multi-View Stereo`).
pub fn colmap_version(colmap: &Path) -> Result<String> {
    let out = Command::new(colmap)
        .arg("-h")
        .stdin(Stdio::null())
        .output()
        .map_err(|e| PoseError::ColmapMissing {
            binary: colmap.display().to_string(),
            reason: e.to_string(),
        })?;
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find(|l| l.contains("COLMAP"))
        .unwrap_or("COLMAP (unknown version)")
        .trim()
        .to_string();
    Ok(line)
}

/// The last `n` lines of a log file, joined with ` | ` for a one-line error.
pub fn log_tail(log: &Path, n: usize) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    let start = lines.len().saturating_sub(n);
    lines[start..].join(" | ")
}

/// Run `colmap <step> <args>`, logging to `log`. `on_line` receives every
/// stdout line (trimmed). Returns the outcome; a non-zero exit is *not* an
/// error here (the caller decides, e.g. the mapper's "no model" case), but a
/// process that cannot be started is.
pub fn run_step(
    colmap: &Path,
    step: &str,
    args: &[String],
    log: &Path,
    on_line: &mut dyn FnMut(&str),
) -> Result<StepOutcome> {
    run_step_cancellable(colmap, step, args, log, on_line, &AtomicBool::new(false))
}

/// [`run_step`] that kills the process (and returns [`PoseError::Cancelled`])
/// once `cancel` is set.
pub fn run_step_cancellable(
    colmap: &Path,
    step: &str,
    args: &[String],
    log: &Path,
    on_line: &mut dyn FnMut(&str),
    cancel: &AtomicBool,
) -> Result<StepOutcome> {
    let file = std::fs::File::create(log).map_err(|e| PoseError::io(log, e))?;
    let sink = Arc::new(Mutex::new(file));
    if let Ok(mut f) = sink.lock() {
        let _ = writeln!(f, "$ {} {} {}", colmap.display(), step, args.join(" "));
    }
    let start = Instant::now();
    let mut child = Command::new(colmap)
        .arg(step)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| PoseError::ColmapMissing {
            binary: colmap.display().to_string(),
            reason: e.to_string(),
        })?;
    let err_thread = child.stderr.take().map(|mut stderr| {
        let sink = Arc::clone(&sink);
        std::thread::spawn(move || {
            let mut buf = [0u8; 8192];
            while let Ok(n) = stderr.read(&mut buf) {
                if n == 0 {
                    break;
                }
                if let Ok(mut f) = sink.lock() {
                    let _ = f.write_all(&buf[..n]);
                }
            }
        })
    });
    let stdout = child.stdout.take();
    let child = Arc::new(Mutex::new(child));
    let done = Arc::new(AtomicBool::new(false));
    let cancelled = Arc::new(AtomicBool::new(false));
    // The watcher kills the process when `cancel` is set; it polls because
    // the reading below blocks. `cancel` is borrowed, so the watcher runs in
    // a scope.
    let status = std::thread::scope(|scope| {
        let watcher = {
            let child = Arc::clone(&child);
            let done = Arc::clone(&done);
            let cancelled = Arc::clone(&cancelled);
            scope.spawn(move || {
                while !done.load(Ordering::Relaxed) {
                    if cancel.load(Ordering::Relaxed) {
                        if let Ok(mut c) = child.lock() {
                            let _ = c.kill();
                        }
                        cancelled.store(true, Ordering::Relaxed);
                        break;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(50));
                }
            })
        };
        if let Some(stdout) = stdout {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if let Ok(mut f) = sink.lock() {
                    let _ = writeln!(f, "{line}");
                }
                on_line(line.trim());
            }
        }
        if let Some(t) = err_thread {
            let _ = t.join();
        }
        done.store(true, Ordering::Relaxed);
        let _ = watcher.join();
        let mut c = child
            .lock()
            .map_err(|_| PoseError::Invalid(format!("colmap {step}: process handle poisoned")))?;
        c.wait().map_err(|e| PoseError::io(log, e))
    })?;
    let seconds = start.elapsed().as_secs_f64();
    if let Ok(mut f) = sink.lock() {
        let _ = writeln!(f, "# {status} after {seconds:.2} s");
        let _ = f.flush();
    }
    if cancelled.load(Ordering::Relaxed) {
        return Err(PoseError::Cancelled {
            step: step.to_string(),
        });
    }
    Ok(StepOutcome {
        seconds,
        log: log.to_path_buf(),
        success: status.success(),
        status: status.to_string(),
    })
}

/// Turn an unsuccessful outcome into [`PoseError::StepFailed`].
pub fn require_success(step: &str, outcome: &StepOutcome) -> Result<()> {
    if outcome.success {
        return Ok(());
    }
    Err(PoseError::StepFailed {
        step: step.to_string(),
        status: outcome.status.clone(),
        log: outcome.log.clone(),
        tail: log_tail(&outcome.log, TAIL_LINES),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_binary_says_how_to_install() {
        let e = colmap_version(Path::new("/nonexistent/colmap-xyz")).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("apt-get install -y colmap"), "{msg}");
        assert!(msg.contains("/nonexistent/colmap-xyz"), "{msg}");
    }

    #[test]
    fn failing_step_reports_status_and_log_tail() {
        // `sh -c` stands in for colmap: the "step" is the -c flag.
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("x.log");
        let mut lines = Vec::new();
        let out = run_step(
            Path::new("sh"),
            "-c",
            &["echo 'Processed file [1/2]'; echo boom-cause >&2; exit 3".to_string()],
            &log,
            &mut |l| lines.push(l.to_string()),
        )
        .unwrap();
        assert!(!out.success);
        assert_eq!(lines, vec!["Processed file [1/2]"]);
        assert!(
            std::fs::read_to_string(&log)
                .unwrap()
                .contains("boom-cause")
        );
        let e = require_success("feature_extractor", &out)
            .unwrap_err()
            .to_string();
        assert!(e.contains("feature_extractor") && e.contains('3'), "{e}");
        assert!(e.contains("boom-cause"), "{e}");
        assert!(e.contains("x.log"), "{e}");
    }

    #[test]
    fn cancel_kills_the_step() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("y.log");
        let cancel = AtomicBool::new(false);
        let t = Instant::now();
        let e = run_step_cancellable(
            Path::new("sh"),
            "-c",
            &["echo 'Matching image [1/9]'; exec sleep 30".to_string()],
            &log,
            &mut |_| cancel.store(true, Ordering::Relaxed),
            &cancel,
        )
        .unwrap_err();
        assert!(matches!(e, PoseError::Cancelled { .. }), "{e}");
        assert!(t.elapsed().as_secs_f64() < 10.0);
        assert!(!std::fs::read_to_string(&log).unwrap().contains("never"));
    }
}
