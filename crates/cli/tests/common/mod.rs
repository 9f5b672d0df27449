//! Helpers shared by the CLI's integration tests.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

pub mod mtime;

use std::process::{Command, Output};

/// Run the binary with `--json --quiet`.
pub fn romosplat_raw(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_romosplat"))
        .args(args)
        .arg("--json")
        .arg("--quiet")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap()
}

/// Run the binary, expect success, return its JSON summary.
pub fn romosplat(args: &[&str]) -> serde_json::Value {
    let out = romosplat_raw(args);
    assert!(
        out.status.success(),
        "romosplat {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}
