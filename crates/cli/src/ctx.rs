//! Shared command context: where human output goes (stderr), whether JSON was
//! requested, and progress bars that stay silent when stderr is not a TTY.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;

/// Passed to every command's `run`.
#[derive(Debug, Clone)]
pub struct Ctx {
    /// `--json` was given: the command's JSON value is printed on stdout.
    pub json: bool,
    /// `--quiet`: suppress human output on stderr.
    pub quiet: bool,
}

impl Ctx {
    /// Print one human line on stderr.
    pub fn info(&self, msg: impl AsRef<str>) {
        if !self.quiet {
            eprintln!("{}", msg.as_ref());
        }
    }

    /// A progress bar on stderr with `len` steps (hidden when quiet or not a TTY).
    pub fn progress(&self, len: u64, what: &str) -> ProgressBar {
        let pb = ProgressBar::new(len);
        if self.quiet || !std::io::stderr().is_terminal() {
            pb.set_draw_target(ProgressDrawTarget::hidden());
        }
        let style = ProgressStyle::with_template(
            "{prefix:>10} [{bar:30}] {pos}/{len} {elapsed_precise} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
        pb.set_style(style);
        pb.set_prefix(what.to_string());
        pb
    }
}
