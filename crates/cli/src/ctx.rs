//! Shared command context: where human output goes (stderr), whether JSON was
//! requested, and the progress reporter every stage calls.
//!
//! Progress has one typed API ([`Progress`]: length, position, message) and
//! three renderings chosen once per process: an indicatif bar when stderr is
//! a TTY; one plain line at least every [`LINE_INTERVAL`] otherwise (piped,
//! under nohup, in CI), with the same fields as the bar (stage, done/total,
//! rate, ETA); nothing with `--quiet`.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::{IsTerminal, Write};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// Without a TTY, a progress line is printed this often while a stage runs
/// (and once when it finishes).
pub const LINE_INTERVAL: Duration = Duration::from_secs(5);

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

    /// A progress reporter on stderr for `stage` with `total` units of work
    /// (0 = not known yet; `set_length` later).
    pub fn progress(&self, total: u64, stage: &str) -> Progress {
        if self.quiet {
            Progress::hidden(total, stage)
        } else if std::io::stderr().is_terminal() {
            Progress::bar(total, stage)
        } else {
            Progress::lines(total, stage, LINE_INTERVAL, Box::new(std::io::stderr()))
        }
    }
}

/// What a progress line shows.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgressState {
    pub stage: String,
    pub done: u64,
    /// 0 = unknown.
    pub total: u64,
    pub message: String,
    /// Seconds since the reporter started.
    pub elapsed: f64,
    /// Units per second since the rate base (see [`Progress::reset_rate`]).
    pub rate: Option<f64>,
}

/// `m:ss`, or `h:mm:ss` from an hour on.
pub fn format_duration(secs: f64) -> String {
    let s = secs.max(0.0).round() as u64;
    if s >= 3600 {
        format!("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
    } else {
        format!("{}:{:02}", s / 60, s % 60)
    }
}

/// The line printed without a TTY:
/// `mask: 12/40 (30%), 1.25/s, ETA 0:22, 0:10 elapsed, flow`.
pub fn format_line(p: &ProgressState) -> String {
    let mut s = format!("{}: {}", p.stage, p.done);
    if p.total > 0 {
        let pct = 100.0 * p.done.min(p.total) as f64 / p.total as f64;
        s.push_str(&format!("/{} ({pct:.0}%)", p.total));
    }
    match p.rate {
        Some(r) if r > 0.0 => {
            let rate = if r >= 10.0 {
                format!("{r:.0}")
            } else {
                format!("{r:.2}")
            };
            s.push_str(&format!(", {rate}/s"));
            if p.total > p.done {
                let eta = (p.total - p.done) as f64 / r;
                s.push_str(&format!(", ETA {}", format_duration(eta)));
            }
        }
        _ => {}
    }
    s.push_str(&format!(", {} elapsed", format_duration(p.elapsed)));
    if !p.message.is_empty() {
        s.push_str(", ");
        s.push_str(&p.message);
    }
    s
}

struct State {
    done: u64,
    total: u64,
    message: String,
    base_done: u64,
    base_time: Instant,
    finished: bool,
}

struct Shared {
    stage: String,
    start: Instant,
    state: Mutex<State>,
    wake: Condvar,
    out: Mutex<Box<dyn Write + Send>>,
}

impl Shared {
    fn snapshot(&self) -> ProgressState {
        let st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let dt = st.base_time.elapsed().as_secs_f64();
        let rate =
            (dt > 0.05 && st.done > st.base_done).then(|| (st.done - st.base_done) as f64 / dt);
        ProgressState {
            stage: self.stage.clone(),
            done: st.done,
            total: st.total,
            message: st.message.clone(),
            elapsed: self.start.elapsed().as_secs_f64(),
            rate,
        }
    }

    fn print_line(&self) {
        let line = format_line(&self.snapshot());
        let mut out = self.out.lock().unwrap_or_else(|e| e.into_inner());
        // A failed write to stderr is not worth failing a stage for.
        let _ = writeln!(out, "{line}");
        let _ = out.flush();
    }
}

enum Mode {
    Hidden,
    Bar(ProgressBar),
    Lines(Option<std::thread::JoinHandle<()>>),
}

/// A progress reporter (see the module docs). Cheap to update from any
/// thread; dropping it stops its line printer.
pub struct Progress {
    shared: Arc<Shared>,
    mode: Mode,
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("stage", &self.shared.stage)
            .finish()
    }
}

impl Progress {
    fn new_shared(total: u64, stage: &str, out: Box<dyn Write + Send>) -> Arc<Shared> {
        let now = Instant::now();
        Arc::new(Shared {
            stage: stage.to_string(),
            start: now,
            state: Mutex::new(State {
                done: 0,
                total,
                message: String::new(),
                base_done: 0,
                base_time: now,
                finished: false,
            }),
            wake: Condvar::new(),
            out: Mutex::new(out),
        })
    }

    /// A reporter that shows nothing (still tracks its state).
    pub fn hidden(total: u64, stage: &str) -> Self {
        Progress {
            shared: Self::new_shared(total, stage, Box::new(std::io::sink())),
            mode: Mode::Hidden,
        }
    }

    /// An indicatif bar on stderr.
    pub fn bar(total: u64, stage: &str) -> Self {
        let pb = ProgressBar::new(total);
        let style = ProgressStyle::with_template(
            "{prefix:>10} [{bar:30}] {pos}/{len} {per_sec} ETA {eta} {elapsed} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
        pb.set_style(style);
        pb.set_prefix(stage.to_string());
        pb.set_draw_target(ProgressDrawTarget::stderr());
        Progress {
            shared: Self::new_shared(total, stage, Box::new(std::io::sink())),
            mode: Mode::Bar(pb),
        }
    }

    /// Plain lines on `out`: one every `interval` while running, one at the end.
    pub fn lines(total: u64, stage: &str, interval: Duration, out: Box<dyn Write + Send>) -> Self {
        let shared = Self::new_shared(total, stage, out);
        let s = Arc::clone(&shared);
        let ticker = std::thread::Builder::new()
            .name(format!("progress-{stage}"))
            .spawn(move || {
                let mut st = s.state.lock().unwrap_or_else(|e| e.into_inner());
                loop {
                    let (guard, timeout) = s
                        .wake
                        .wait_timeout(st, interval)
                        .unwrap_or_else(|e| e.into_inner());
                    st = guard;
                    if st.finished {
                        return;
                    }
                    if timeout.timed_out() {
                        drop(st);
                        s.print_line();
                        st = s.state.lock().unwrap_or_else(|e| e.into_inner());
                    }
                }
            })
            .ok();
        Progress {
            shared,
            mode: Mode::Lines(ticker),
        }
    }

    fn update(&self, f: impl FnOnce(&mut State)) {
        let mut st = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
        f(&mut st);
    }

    /// Total units of work (0 = unknown).
    pub fn set_length(&self, total: u64) {
        self.update(|s| s.total = total);
        if let Mode::Bar(pb) = &self.mode {
            pb.set_length(total);
        }
    }

    /// Units done so far.
    pub fn set_position(&self, done: u64) {
        self.update(|s| s.done = done);
        if let Mode::Bar(pb) = &self.mode {
            pb.set_position(done);
        }
    }

    /// `delta` more units done.
    pub fn inc(&self, delta: u64) {
        self.update(|s| s.done += delta);
        if let Mode::Bar(pb) = &self.mode {
            pb.inc(delta);
        }
    }

    /// What is happening now (a sub-step, a loss value).
    pub fn set_message(&self, msg: impl Into<String>) {
        let msg = msg.into();
        if let Mode::Bar(pb) = &self.mode {
            pb.set_message(msg.clone());
        }
        self.update(|s| s.message = msg);
    }

    /// Measure the rate from the current position on (e.g. after resuming
    /// at step N, so the rate counts only this run's steps).
    pub fn reset_rate(&self) {
        self.update(|s| {
            s.base_done = s.done;
            s.base_time = Instant::now();
        });
        if let Mode::Bar(pb) = &self.mode {
            pb.reset_eta();
        }
    }

    /// The current state.
    pub fn state(&self) -> ProgressState {
        self.shared.snapshot()
    }

    /// Stop: clear the bar, or print the final line.
    pub fn finish_and_clear(&self) {
        let first = {
            let mut st = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
            let first = !st.finished;
            st.finished = true;
            first
        };
        self.shared.wake.notify_all();
        match &self.mode {
            Mode::Bar(pb) => pb.finish_and_clear(),
            Mode::Lines(_) if first => self.shared.print_line(),
            _ => {}
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish_and_clear();
        if let Mode::Lines(t) = &mut self.mode
            && let Some(t) = t.take()
        {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_has_stage_done_total_rate_eta() {
        let p = ProgressState {
            stage: "mask".into(),
            done: 12,
            total: 40,
            message: "flow".into(),
            elapsed: 10.2,
            rate: Some(1.25),
        };
        // 28 left at 1.25/s = 22.4 s.
        assert_eq!(
            format_line(&p),
            "mask: 12/40 (30%), 1.25/s, ETA 0:22, 0:10 elapsed, flow"
        );
        let unknown = ProgressState {
            stage: "colmap".into(),
            done: 0,
            total: 0,
            message: String::new(),
            elapsed: 3725.0,
            rate: None,
        };
        assert_eq!(format_line(&unknown), "colmap: 0, 1:02:05 elapsed");
        let fast = ProgressState {
            rate: Some(250.0),
            done: 40,
            ..p
        };
        assert_eq!(
            format_line(&fast),
            "mask: 40/40 (100%), 250/s, 0:10 elapsed, flow"
        );
    }

    #[derive(Clone, Default)]
    struct Buf(Arc<Mutex<Vec<u8>>>);
    impl Write for Buf {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn lines_are_printed_while_running_and_at_the_end() {
        let buf = Buf::default();
        let p = Progress::lines(
            10,
            "train",
            Duration::from_millis(40),
            Box::new(buf.clone()),
        );
        p.set_position(3);
        p.set_message("loss 0.1");
        std::thread::sleep(Duration::from_millis(150));
        let while_running = String::from_utf8(buf.0.lock().unwrap().clone()).unwrap();
        let n = while_running.lines().count();
        assert!(n >= 2, "expected ≥ 2 lines in 150 ms at 40 ms, got {n}");
        assert!(
            while_running
                .lines()
                .all(|l| l.starts_with("train: 3/10 (30%)") && l.ends_with("loss 0.1")),
            "{while_running}"
        );
        p.set_position(10);
        p.finish_and_clear();
        drop(p);
        let all = String::from_utf8(buf.0.lock().unwrap().clone()).unwrap();
        let last = all.lines().last().unwrap();
        assert!(last.starts_with("train: 10/10 (100%)"), "{last}");
        // The ticker stopped: nothing more is printed.
        let len = all.len();
        std::thread::sleep(Duration::from_millis(100));
        assert_eq!(buf.0.lock().unwrap().len(), len);
    }
}
