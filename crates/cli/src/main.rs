//! `romosplat`: the command-line front end. Thin: argument parsing, progress
//! and output; the work is done by the library crates.

mod cmd;
mod ctx;
mod keyframes;
mod memory;
mod pipeline;
mod plan;
mod preflight;
mod report;
#[cfg(test)]
#[path = "../tests/common/mtime.rs"]
mod test_mtime;

use clap::Parser;
pub use ctx::Ctx;

/// romosplat: clean 3D Gaussian splats from casual videos with people walking through.
#[derive(Debug, Parser)]
#[command(name = "romosplat", version, about)]
struct Cli {
    /// Print one machine-readable JSON object on stdout (human output stays on stderr).
    #[arg(long, global = true)]
    json: bool,
    /// No human output on stderr.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: cmd::Command,
}

fn main() {
    #[cfg(target_os = "linux")]
    ensure_runtime_dir();
    // Without glibc there is nothing to tune; the defaults stay.
    let _ = memory::keep_freed_memory();
    let cli = Cli::parse();
    let ctx = Ctx {
        json: cli.json,
        quiet: cli.quiet,
    };
    match cmd::dispatch(&cli.command, &ctx) {
        Ok(value) => {
            if ctx.json {
                println!(
                    "{}",
                    serde_json::to_string(&value).unwrap_or_else(|_| "{}".into())
                );
            }
        }
        Err(err) => {
            let msg = one_line(&err);
            if ctx.json {
                println!("{}", serde_json::json!({ "error": msg }));
            }
            eprintln!("error: {msg}");
            std::process::exit(1);
        }
    }
}

/// Without `XDG_RUNTIME_DIR` (a root shell, a container, a cron job), the
/// Vulkan loader's Wayland support prints "error: XDG_RUNTIME_DIR is invalid
/// or not set in the environment." twice whenever wgpu starts, which reads as
/// romosplat's own error although training then runs normally. When the
/// variable is unset or names no directory, point it at a private 0700
/// folder of this user in the temporary directory (kept only when it is a
/// directory owned by this user with no group or other access).
#[cfg(target_os = "linux")]
fn ensure_runtime_dir() {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    let usable = std::env::var_os("XDG_RUNTIME_DIR")
        .is_some_and(|d| std::fs::metadata(d).is_ok_and(|m| m.is_dir()));
    if usable {
        return;
    }
    // The owner of /proc/self is this process's effective user.
    let Ok(uid) = std::fs::metadata("/proc/self").map(|m| m.uid()) else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("romosplat-runtime-{uid}"));
    let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
    let private = std::fs::symlink_metadata(&dir)
        .is_ok_and(|m| m.is_dir() && m.uid() == uid && m.permissions().mode() & 0o077 == 0);
    if private {
        // SAFETY: called first thing in `main`, before any thread exists, so
        // no other thread can read the environment concurrently.
        #[allow(unsafe_code)]
        unsafe {
            std::env::set_var("XDG_RUNTIME_DIR", &dir)
        };
    }
}

/// The error as one line: the chain of causes joined with ": ", each cause
/// once (errors that already print their source, such as the loader's
/// `path: os error`, are not repeated by their source), whitespace and
/// newlines collapsed.
fn one_line(err: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        let text = text.split_whitespace().collect::<Vec<_>>().join(" ");
        if text.is_empty() || msg.contains(&text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&text);
    }
    msg
}

#[cfg(test)]
mod tests {
    use super::{Cli, one_line};
    use clap::CommandFactory;

    /// clap's own consistency checks over every subcommand: no two flags
    /// share a name or short form, defaults parse with their value parsers,
    /// `requires` / `conflicts_with` name existing arguments.
    ///
    /// clap runs those checks only in a debug build of clap, so ids are
    /// also checked here: two flattened fields of one name (`enabled` in the
    /// overlay and region options) would share an id, and one flag would
    /// set both.
    #[test]
    fn command_line_definition_is_consistent() {
        Cli::command().debug_assert();
        fn unique_ids(cmd: &clap::Command) {
            let mut ids: Vec<&str> = cmd.get_arguments().map(|a| a.get_id().as_str()).collect();
            let n = ids.len();
            ids.sort_unstable();
            ids.dedup();
            assert_eq!(ids.len(), n, "{}: a flag id is used twice", cmd.get_name());
            cmd.get_subcommands().for_each(unique_ids);
        }
        unique_ids(&Cli::command());
    }

    #[test]
    fn causes_are_printed_once_on_one_line() {
        let os = std::io::Error::from_raw_os_error(17);
        let e = loader::LoaderError::io("out/tr", os);
        let line = one_line(&anyhow::Error::new(e).context("train"));
        assert_eq!(line.matches("os error 17").count(), 1, "{line}");
        assert!(line.starts_with("train: out/tr: "), "{line}");
        let multi = anyhow::anyhow!("a\n  b\n\tc");
        assert_eq!(one_line(&multi), "a b c");
    }
}
