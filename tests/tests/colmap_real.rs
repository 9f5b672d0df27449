//! Real COLMAP 3.8 on the small built-in scene (generated into a scratch
//! folder): the pose stage registers every frame with and without masks, the
//! masks are honoured (no keypoint on a masked pixel), and a model written by
//! real COLMAP round-trips through the loader byte for byte.
//!
//! With `CI` set, a missing `colmap` fails these tests; without it they skip.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use loader::colmap::{
    ColmapModel, read_model_binary, read_model_text, write_model_binary, write_model_text,
};
use pose::colmap_runner::{ColmapOptions, ColmapPaths, ColmapReport, run_colmap};
use pose::metrics::{NamedPose, PoseMetricsOptions, evaluate};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

#[path = "../../crates/pose/tests/common/mod.rs"]
mod common;
use common::colmap_available;

/// This process's scratch root under cargo's integration-test tmp dir; roots
/// left by earlier (dead) test processes are removed on first use.
fn root() -> &'static Path {
    static ROOT: OnceLock<PathBuf> = OnceLock::new();
    ROOT.get_or_init(|| {
        let base = Path::new(env!("CARGO_TARGET_TMPDIR"));
        if let Ok(rd) = std::fs::read_dir(base) {
            for e in rd.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                if let Some(pid) = name.strip_prefix("colmap_real-")
                    && !Path::new("/proc").join(pid).exists()
                {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
        }
        let d = base.join(format!("colmap_real-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    })
}

fn scratch(name: &str) -> PathBuf {
    let d = root().join(name);
    if d.exists() {
        std::fs::remove_dir_all(&d).unwrap();
    }
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The small scene (generated once per process) with masks from ground truth.
fn scene() -> &'static Path {
    static SCENE: OnceLock<PathBuf> = OnceLock::new();
    SCENE.get_or_init(|| {
        let dir = scratch("scene");
        let t = std::time::Instant::now();
        let spec_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/small.toml");
        let spec = loader::synth::load_spec(&spec_path).unwrap();
        loader::synth::generate(&spec, &dir).unwrap();
        pose::gt_masks::masks_from_gt_motion(
            &dir.join("images"),
            &dir.join("gt_motion"),
            &dir.join("masks"),
        )
        .unwrap();
        eprintln!("scene generated in {:.1} s", t.elapsed().as_secs_f64());
        dir
    })
}

struct Run {
    scene: PathBuf,
    paths: ColmapPaths,
    report: ColmapReport,
}

/// Run the pose stage on the shared scene into `root/name`. Overlap 6
/// instead of 10 keeps the test cheap; registration does not need more.
fn run(name: &str, opts: ColmapOptions) -> Run {
    let scene = scene().to_path_buf();
    let out = scratch(name);
    let mut paths = ColmapPaths::for_scene(&scene);
    paths.work = out.join("colmap");
    paths.out = out.join("sparse/0");
    paths.undistorted = out.join("undistorted");
    let opts = ColmapOptions {
        overlap: 6,
        seed: 1,
        ..opts
    };
    let mut steps = Vec::new();
    let report = run_colmap(&paths, &opts, &mut |p| steps.push(format!("{p:?}"))).unwrap();
    eprintln!(
        "{name}: {}",
        serde_json::to_string(&report.timings).unwrap()
    );
    assert!(steps.iter().any(|s| s.contains("mapper")), "{steps:?}");
    Run {
        scene,
        paths,
        report,
    }
}

fn masked_run() -> Option<&'static Run> {
    static RUN: OnceLock<Option<Run>> = OnceLock::new();
    RUN.get_or_init(|| colmap_available().then(|| run("masked", ColmapOptions::default())))
        .as_ref()
}

fn trajectory(model: &ColmapModel) -> Vec<NamedPose> {
    model
        .images
        .values()
        .map(|im| NamedPose {
            name: im.name.clone(),
            pose: im.pose,
        })
        .collect()
}

/// Registered every frame and recovered the trajectory: ATE after Sim(3)
/// alignment below 1 % of the ground-truth path length.
fn check_registration(r: &Run) {
    let rep = &r.report;
    assert_eq!(rep.registered, rep.total, "left out: {:?}", rep.left_out);
    assert!(rep.left_out.is_empty());
    assert!(rep.total >= 30, "{}", rep.total);
    assert!(rep.model.points > 500, "{} points", rep.model.points);
    assert!(
        rep.model.mean_reprojection_error < 1.5,
        "{}",
        rep.model.mean_reprojection_error
    );
    let pred = read_model_binary(&r.paths.out).unwrap();
    let gt = loader::colmap::read_model(r.scene.join("sparse/0")).unwrap();
    let m = evaluate(
        &trajectory(&pred),
        &trajectory(&gt),
        &PoseMetricsOptions::default(),
    )
    .unwrap();
    assert_eq!(m.registered, m.total);
    assert!(
        m.ate.rmse < 0.01 * m.gt_path_length,
        "ATE {} vs path length {}",
        m.ate.rmse,
        m.gt_path_length
    );
}

/// Count keypoints of `model` lying on a masked (0) pixel of `masks`, using
/// COLMAP's rule (`MaskKeypoints`: the pixel at (⌊x⌋, ⌊y⌋)).
fn keypoints_on_masked_pixels(model: &ColmapModel, masks: &Path) -> (usize, usize) {
    let (mut on, mut total) = (0, 0);
    for im in model.images.values() {
        let mask = loader::io::read_gray8(masks.join(format!("{}.png", im.name))).unwrap();
        for p in &im.points2d {
            let (x, y) = (p.xy[0].floor() as u32, p.xy[1].floor() as u32);
            total += 1;
            if mask.get_pixel(x, y).0[0] == 0 {
                on += 1;
            }
        }
    }
    (on, total)
}

#[test]
fn masked_run_registers_every_frame_and_honours_masks() {
    let Some(r) = masked_run() else { return };
    check_registration(r);
    let model = read_model_binary(&r.paths.out).unwrap();
    let (on, total) = keypoints_on_masked_pixels(&model, &r.paths.masks);
    assert!(total > 1000, "{total} keypoints");
    assert_eq!(on, 0, "{on} of {total} keypoints lie on masked pixels");
    // The undistorted copy has a PINHOLE model and a mask of the right size
    // for every registered image.
    let und = r
        .report
        .undistorted_dir
        .as_ref()
        .expect("SIMPLE_RADIAL is undistorted");
    let um = loader::colmap::read_model(und.join("sparse/0")).unwrap();
    assert_eq!(um.images.len(), r.report.registered);
    for im in um.images.values() {
        let cam = &um.cameras[&im.camera_id];
        assert_eq!(cam.model, loader::CameraModel::PINHOLE);
        let (w, h) = image::image_dimensions(und.join("images").join(&im.name)).unwrap();
        let mask =
            loader::io::read_gray8(und.join("masks").join(format!("{}.png", im.name))).unwrap();
        assert_eq!((mask.width(), mask.height()), (w, h));
        assert_eq!((w as u64, h as u64), (cam.width, cam.height));
    }
}

#[test]
fn unmasked_run_registers_every_frame_and_sees_the_pedestrians() {
    if !colmap_available() {
        return;
    }
    let r = run(
        "unmasked",
        ColmapOptions {
            use_masks: false,
            camera_model: loader::CameraModel::PINHOLE,
            ..Default::default()
        },
    );
    check_registration(&r);
    assert!(
        r.report.undistorted_dir.is_none(),
        "PINHOLE needs no undistortion"
    );
    // Without masks COLMAP does extract keypoints on the moving people, so the
    // masked test above is not vacuous.
    let model = read_model_binary(&r.paths.out).unwrap();
    let (on, total) = keypoints_on_masked_pixels(&model, &r.paths.masks);
    assert!(on > 20, "only {on} of {total} keypoints on moving pixels");
}

fn assert_models_close(a: &ColmapModel, b: &ColmapModel, rel: f64) {
    let close = |x: f64, y: f64| (x - y).abs() <= rel * x.abs().max(y.abs()).max(1.0);
    let all_close =
        |a: &[f64], b: &[f64]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| close(*x, *y));
    assert_eq!(a.cameras.len(), b.cameras.len());
    for (id, ca) in &a.cameras {
        let cb = &b.cameras[id];
        assert_eq!(
            (ca.model, ca.width, ca.height),
            (cb.model, cb.width, cb.height)
        );
        assert!(all_close(&ca.params, &cb.params));
    }
    assert_eq!(a.images.len(), b.images.len());
    for (id, ia) in &a.images {
        let ib = &b.images[id];
        assert_eq!((&ia.name, ia.camera_id), (&ib.name, ib.camera_id));
        assert!(all_close(&ia.pose.qvec, &ib.pose.qvec));
        assert!(all_close(&ia.pose.tvec, &ib.pose.tvec));
        assert_eq!(ia.points2d.len(), ib.points2d.len());
        for (pa, pb) in ia.points2d.iter().zip(&ib.points2d) {
            assert_eq!(pa.point3d_id, pb.point3d_id);
            assert!(all_close(&pa.xy, &pb.xy));
        }
    }
    assert_eq!(a.points3d.len(), b.points3d.len());
    for (id, pa) in &a.points3d {
        let pb = &b.points3d[id];
        assert_eq!((pa.rgb, &pa.track), (pb.rgb, &pb.track));
        assert!(all_close(&pa.xyz, &pb.xyz));
        assert!(close(pa.error, pb.error));
    }
}

#[test]
fn colmap_written_model_round_trips_byte_exact() {
    let Some(r) = masked_run() else { return };
    let model = read_model_binary(&r.paths.out).unwrap();
    assert!(!model.images.is_empty() && !model.points3d.is_empty());
    let dir = scratch("roundtrip");
    // Binary → binary: the same bytes as COLMAP wrote.
    write_model_binary(&model, dir.join("bin")).unwrap();
    for f in ["cameras.bin", "images.bin", "points3D.bin"] {
        let a = std::fs::read(r.paths.out.join(f)).unwrap();
        let b = std::fs::read(dir.join("bin").join(f)).unwrap();
        assert!(
            a == b,
            "{f}: {} vs {} bytes, contents differ",
            a.len(),
            b.len()
        );
    }
    // Binary → our text → read back: the same model.
    write_model_text(&model, dir.join("txt")).unwrap();
    let back = read_model_text(dir.join("txt")).unwrap();
    assert_models_close(&model, &back, 0.0);
    // COLMAP's own text export of the same model reads as the same model.
    std::fs::create_dir_all(dir.join("colmap_txt")).unwrap();
    let out = std::process::Command::new("colmap")
        .args(["model_converter", "--output_type", "TXT", "--input_path"])
        .arg(&r.paths.out)
        .arg("--output_path")
        .arg(dir.join("colmap_txt"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let colmap_txt = read_model_text(dir.join("colmap_txt")).unwrap();
    // COLMAP writes text with limited digits; calibrated: 1e-6 relative.
    assert_models_close(&model, &colmap_txt, 1e-6);
    std::fs::remove_dir_all(&dir).unwrap();
}
