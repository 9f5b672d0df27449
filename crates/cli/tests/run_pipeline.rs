//! End to end through the binary: `romosplat run` on a generated scene makes
//! every output, a rerun skips every stage, and `--from` reruns from a stage.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::process::Command;

fn romosplat(args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_romosplat"))
        .args(args)
        .arg("--json")
        .arg("--quiet")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "romosplat {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn run_resumes_and_restarts_from_a_stage() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    let out = dir.path().join("out");
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/small.toml");
    romosplat(&[
        "scene",
        "generate",
        spec.to_str().unwrap(),
        "--out",
        scene.to_str().unwrap(),
    ]);
    let args = [
        "run",
        "--scene",
        scene.to_str().unwrap(),
        "--keep-poses",
        "--steps",
        "20",
        "--backend",
        "cpu",
        "--out",
        out.to_str().unwrap(),
    ];
    let first = romosplat(&args);
    for stage in ["frames", "mask", "train", "export", "report"] {
        assert_eq!(
            first["stages"][stage], true,
            "{stage} should run the first time"
        );
    }
    assert_eq!(
        first["stages"]["pose"], false,
        "--keep-poses keeps the scene's poses"
    );
    for f in [
        "train/splats.ply",
        "splats_clean.ply",
        "report.html",
        "scene/masks/00000.png.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    // The user's folder is never written to.
    assert!(!scene.join("masks").exists());
    let psnr = first["train"]["test"]["mean_psnr"].as_f64().unwrap();
    assert!(psnr.is_finite() && psnr > 10.0, "held-out PSNR {psnr}");

    let second = romosplat(&args);
    for stage in ["frames", "mask", "pose", "train", "export", "report"] {
        assert_eq!(
            second["stages"][stage], false,
            "{stage} should be up to date"
        );
    }
    let mut from = args.to_vec();
    from.extend(["--from", "export"]);
    let third = romosplat(&from);
    assert_eq!(third["stages"]["train"], false);
    assert_eq!(third["stages"]["export"], true);
    assert_eq!(third["stages"]["report"], true);
}
