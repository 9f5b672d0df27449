//! Setting a file's modification time, for the freshness tests (the unit
//! tests of `pipeline` include this file too).
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::time::SystemTime;

/// Set `p`'s modification time to `t`.
pub fn set_mtime(p: &Path, t: SystemTime) {
    std::fs::File::options()
        .write(true)
        .open(p)
        .unwrap()
        .set_modified(t)
        .unwrap();
}
