//! The low-parallax case through the CLI's default path: a camera that only
//! pans (`scenes/rotation.toml`, one pedestrian walking the way the camera
//! turns), `romosplat scene generate` → `romosplat mask` → `romosplat eval
//! masks`, default flags, must find the pedestrian.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

mod common;
use common::romosplat;

#[test]
fn pure_rotation_masks_through_the_cli() {
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/rotation.toml");
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("rotation");
    let s = scene.to_str().unwrap();
    romosplat(&["scene", "generate", spec.to_str().unwrap(), "--out", s]);
    romosplat(&["mask", "--scene", s]);
    let m = romosplat(&[
        "eval",
        "masks",
        "--pred",
        scene.join("masks").to_str().unwrap(),
        "--gt",
        scene.join("gt_motion").to_str().unwrap(),
    ]);
    let j = m["j_mean"].as_f64().unwrap();
    let (p, r) = (
        m["precision"].as_f64().unwrap(),
        m["recall"].as_f64().unwrap(),
    );
    eprintln!("rotation through the CLI: J {j:.3} P {p:.3} R {r:.3}");
    // Measured 2026-11-26 (16 frames + 2 held-out views, seed 0): J 0.843,
    // P 0.84, R 0.96; 0.000 before U needed texture (the MLP learnt the
    // textureless sky, whose interpolated flow had put it in U).
    assert!(j >= 0.7, "J {j} (precision {p}, recall {r})");
}
