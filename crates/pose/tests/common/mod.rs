//! Helpers shared by the tests that run the real COLMAP (`pose/tests` and,
//! through `#[path]`, the workspace `tests/tests/colmap_real.rs`).

/// True when colmap runs; panics under CI when it does not.
pub fn colmap_available() -> bool {
    let ok = std::process::Command::new("colmap")
        .arg("-h")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("COLMAP"));
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but `colmap` cannot be run: apt-get install -y colmap"
        );
        eprintln!("colmap not found: skipping (set CI to make this a failure)");
    }
    ok
}
