//! Shared helpers: a per-process scratch folder in /dev/shm (or the temp
//! folder) for the readers that take paths, and splitting one input into
//! several files written there.
#![allow(dead_code)]

use std::path::PathBuf;

/// A scratch folder unique to this process.
pub fn scratch() -> PathBuf {
    let base = if std::path::Path::new("/dev/shm").is_dir() {
        PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    let d = base.join(format!("romosplat-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&d);
    d
}

/// Split `data` into `n` parts at the byte sequence `\n--8<--\n` (the seed
/// script joins files the same way); missing parts are empty.
pub fn split_parts(data: &[u8], n: usize) -> Vec<&[u8]> {
    const SEP: &[u8] = b"\n--8<--\n";
    let mut parts = Vec::with_capacity(n);
    let mut rest = data;
    while parts.len() + 1 < n {
        match rest.windows(SEP.len()).position(|w| w == SEP) {
            Some(i) => {
                parts.push(&rest[..i]);
                rest = &rest[i + SEP.len()..];
            }
            None => break,
        }
    }
    parts.push(rest);
    while parts.len() < n {
        parts.push(&[]);
    }
    parts
}

/// Split `data` as [`split_parts`] does into one part per name and write
/// each as `scratch()/sub/<name>`; returns that folder.
pub fn write_parts(data: &[u8], sub: &str, names: &[&str]) -> PathBuf {
    let dir = scratch().join(sub);
    let _ = std::fs::create_dir_all(&dir);
    for (name, bytes) in names.iter().zip(split_parts(data, names.len())) {
        std::fs::write(dir.join(name), bytes).expect("scratch write");
    }
    dir
}
