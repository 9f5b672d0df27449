//! End to end through the binary, on the small built-in scene: `run --video`
//! on an mp4 made with ffmpeg (no split.json: every 8th frame held out)
//! through the report; `run --scene` without a split.json, and what reruns
//! when nothing, an option, an input file, an options file, the version or
//! the input changes; preflight errors before any stage.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, SystemTime};

mod common;
use common::mtime::set_mtime;
use common::{romosplat, romosplat_raw};

/// The stages a run ran, in order.
fn ran(v: &serde_json::Value) -> Vec<String> {
    v["ran"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect()
}

/// The small scene, generated into `dir/small`; returns it and its
/// training (clutter) frame names in order.
fn small_scene(dir: &Path) -> (PathBuf, Vec<String>) {
    let scene = dir.join("small");
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/small.toml");
    romosplat(&[
        "scene",
        "generate",
        spec.to_str().unwrap(),
        "--out",
        scene.to_str().unwrap(),
    ]);
    let s = loader::scene::Scene::load(&scene, &Default::default()).unwrap();
    let train = s
        .split_indices("clutter")
        .iter()
        .map(|&i| s.frames[i].name.clone())
        .collect();
    (scene, train)
}

/// A scene folder with `names` (from `src`), the model, and no split.json.
fn scene_without_split(src: &Path, dst: &Path, names: &[String]) {
    std::fs::create_dir_all(dst.join("images")).unwrap();
    for n in names {
        std::fs::copy(src.join("images").join(n), dst.join("images").join(n)).unwrap();
    }
    std::fs::create_dir_all(dst.join("sparse/0")).unwrap();
    for e in std::fs::read_dir(src.join("sparse/0")).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dst.join("sparse/0").join(e.file_name())).unwrap();
    }
}

#[test]
fn run_video_end_to_end_without_a_split() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, train) = small_scene(dir.path());
    // The training frames, renumbered, as an mp4 (MPEG-4 part 2 at high
    // quality: every ffmpeg build has the encoder).
    let frames = dir.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    for (i, n) in train.iter().enumerate() {
        std::fs::copy(
            scene.join("images").join(n),
            frames.join(format!("{:05}.png", i + 1)),
        )
        .unwrap();
    }
    let video = dir.path().join("walk.mp4");
    let st = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "10", "-i"])
        .arg(frames.join("%05d.png"))
        .args(["-c:v", "mpeg4", "-q:v", "2", "-pix_fmt", "yuv420p"])
        .arg(&video)
        .status()
        .unwrap();
    assert!(st.success(), "ffmpeg could not make the test video");

    let romo_json = dir.path().join("romo.json");
    std::fs::write(&romo_json, r#"{"seed": 0}"#).unwrap();
    let out = dir.path().join("out");
    let args = [
        "run",
        "--video",
        video.to_str().unwrap(),
        "--mask-options",
        romo_json.to_str().unwrap(),
        "--steps",
        "30",
        "--downscale",
        "2",
        "--backend",
        "cpu",
        "--out",
        out.to_str().unwrap(),
    ];
    let first = romosplat(&args);
    assert_eq!(
        ran(&first),
        [
            "frames",
            "mask",
            "keyframes",
            "pose",
            "train",
            "baseline",
            "export",
            "report"
        ]
    );
    assert_eq!(first["frames"]["frames"], train.len());
    // A video's frames are in capture order: the mask stage keeps it.
    let mask: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("manifests/mask.json")).unwrap()).unwrap();
    assert_eq!(mask["options"]["frame_order"], "names", "{mask}");
    // Keyframes: the frames COLMAP and training see, with masks of the same names.
    let n = first["keyframes"]["kept"].as_u64().unwrap() as usize;
    assert!(n >= train.len() / 4 && n <= train.len(), "kept {n}");
    let kept = loader::scene::list_images(&out.join("keyframes/images")).unwrap();
    assert_eq!(kept.len(), n);
    for k in &kept {
        assert!(
            out.join("keyframes/masks")
                .join(format!("{k}.png"))
                .is_file()
        );
    }
    // The plan is printed into the report and kept for reruns.
    assert_eq!(first["plan"]["steps"], 30);
    assert!(out.join("plan.json").is_file());
    let registered = first["pose"]["registered"].as_u64().unwrap() as usize;
    assert!(
        registered * 10 >= n * 8,
        "COLMAP registered {registered} of {n} frames"
    );
    // No split.json: every 8th posed frame is held out, scored and rendered.
    let test = &first["train"]["test"];
    let views = test["views"].as_array().unwrap();
    assert!(!views.is_empty() && views.len() <= n.div_ceil(8));
    let psnr = test["mean_psnr"].as_f64().unwrap();
    assert!(psnr.is_finite() && psnr > 10.0, "held-out PSNR {psnr}");
    let renders = first["train"]["test_renders"].as_array().unwrap();
    assert_eq!(renders.len(), views.len());
    for r in renders {
        assert!(Path::new(r.as_str().unwrap()).is_file());
    }
    for f in ["splats_clean.ply", "report.html", "manifests/report.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    // The unmasked baseline: same poses, steps and held-out views, no masks.
    let base = &first["baseline"];
    assert_eq!(base["options"]["steps"], 30);
    assert_eq!(base["options"]["use_masks"], false);
    assert_eq!(first["train"]["options"]["use_masks"], true);
    assert_eq!(base["masked_views"], 0);
    assert_eq!(base["test"]["views"].as_array().unwrap().len(), views.len());
    assert!(base["test"]["mean_psnr"].as_f64().unwrap().is_finite());
    // Both are also scored on the held-out frames' static pixels (RoMo's
    // masks), over the frames in which the masks leave out pixels.
    for o in [&first["train"], base] {
        let m = o["test_static"]["masked_views"].as_u64().unwrap() as usize;
        assert!(m >= 1 && m <= views.len(), "{m} of {}", views.len());
        assert!(o["test_static"]["mean_psnr"].as_f64().unwrap().is_finite());
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("COLMAP") && html.contains("Held-out") && html.contains("Plan for the"));
    assert!(html.contains("RoMo masks") && html.contains("no masks (baseline)"));
    assert!(html.contains("static PSNR"));

    // Touching the video and the options file without changing them reruns
    // nothing (they are hashed); the recorded results come back from the
    // manifests.
    set_mtime(&video, SystemTime::now() + Duration::from_secs(30));
    set_mtime(&romo_json, SystemTime::now() + Duration::from_secs(30));
    let again = romosplat(&args);
    assert!(ran(&again).is_empty(), "{:?}", ran(&again));
    assert_eq!(again["pose"]["registered"], first["pose"]["registered"]);
    assert!(again["seconds"].as_f64().unwrap() < 5.0);
}

#[test]
fn run_scene_without_a_split_reruns_what_changed() {
    let dir = tempfile::tempdir().unwrap();
    let (small, train) = small_scene(dir.path());
    // 12 frames, no masks (the video test runs the mask stage): frames 0
    // and 8 are held out.
    let scene = dir.path().join("scene");
    scene_without_split(&small, &scene, &train[..12]);
    let out = dir.path().join("out");
    let run_on = |scene: &Path, extra: &[&str]| {
        let mut a = vec![
            "run",
            "--scene",
            scene.to_str().unwrap(),
            "--keep-poses",
            "--no-masks",
            "--backend",
            "cpu",
            "--out",
            out.to_str().unwrap(),
        ];
        if !extra.contains(&"--steps") {
            a.extend(["--steps", "20"]);
        }
        a.extend_from_slice(extra);
        romosplat(&a)
    };
    let run = |extra: &[&str]| run_on(&scene, extra);
    let all = ["frames", "train", "export", "report"];

    let first = run(&[]);
    assert_eq!(ran(&first), all);
    assert_eq!(first["stages"]["pose"]["status"], "kept the scene's poses");
    assert_eq!(first["stages"]["mask"]["status"], "skipped (--no-masks)");
    assert_eq!(
        first["stages"]["baseline"]["status"],
        "skipped (--no-masks: the model is the baseline)"
    );
    assert_eq!(first["train"]["test"]["views"].as_array().unwrap().len(), 2);
    assert_eq!(first["train"]["train_views"], 10);
    // The user's folder is never written to.
    assert!(!scene.join("masks").exists() && !scene.join("split.json").exists());

    // Nothing changed: no stage runs, and it says so quickly.
    let same = run(&[]);
    assert!(ran(&same).is_empty(), "{:?}", ran(&same));
    assert_eq!(same["stages"]["train"]["status"], "up to date");
    assert!(same["seconds"].as_f64().unwrap() < 5.0);
    assert_eq!(
        same["train"]["test"]["mean_psnr"],
        first["train"]["test"]["mean_psnr"]
    );

    // An option: train, export and report only.
    assert_eq!(ran(&run(&["--steps", "30"])), ["train", "export", "report"]);
    // --from.
    assert_eq!(
        ran(&run(&["--steps", "30", "--from", "export"])),
        ["export", "report"]
    );

    // The version recorded in a manifest.
    let m = out.join("manifests/export.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&m).unwrap()).unwrap();
    v["version"] = "0.0.0-older".into();
    std::fs::write(&m, v.to_string()).unwrap();
    assert_eq!(ran(&run(&["--steps", "30"])), ["export", "report"]);

    // An input file (a frame rewritten): everything.
    let frame = scene.join("images").join(&train[3]);
    set_mtime(&frame, SystemTime::now() + Duration::from_secs(60));
    assert_eq!(ran(&run(&["--steps", "30"])), all);

    // A different scene in the same --out: everything, on its frames.
    let other = dir.path().join("other");
    scene_without_split(&small, &other, &train[4..20]);
    let o = run_on(&other, &["--steps", "30"]);
    assert_eq!(ran(&o), all);
    assert_eq!(o["frames"]["frames"], 16);
    assert_eq!(o["train"]["train_views"], 14);
}

#[test]
fn preflight_rejects_before_any_stage() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let video = dir.path().join("v.mp4");
    std::fs::write(&video, b"not a video").unwrap();
    let r = romosplat_raw(&[
        "run",
        "--video",
        video.to_str().unwrap(),
        "--keep-poses",
        "--colmap",
        "/nonexistent/colmap",
        "--ffmpeg",
        "/nonexistent/ffmpeg",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("--keep-poses needs --scene"), "{err}");
    assert!(
        err.contains("ffmpeg (`/nonexistent/ffmpeg`) does not run"),
        "{err}"
    );
    // --keep-poses (wrongly) given: colmap is not needed, so not named.
    assert!(!err.contains("colmap (`"), "{err}");
    assert!(!out.join("scene").exists(), "a stage ran");

    let r = romosplat_raw(&[
        "run",
        "--video",
        video.to_str().unwrap(),
        "--colmap",
        "/nonexistent/colmap",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success());
    assert!(
        err.contains("colmap (`/nonexistent/colmap`) does not run"),
        "{err}"
    );
    assert!(!out.join("scene").exists(), "a stage ran");

    // A sound file named .mp4: one line saying it has no video stream.
    let audio = dir.path().join("sound.mp4");
    let st = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-f", "lavfi", "-i", "sine=d=1"])
        .arg(&audio)
        .status()
        .unwrap();
    assert!(st.success(), "ffmpeg could not make the test sound");
    let r = romosplat_raw(&["plan", "--video", audio.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success());
    let want = format!("{}: the file has no video stream", audio.display());
    assert_eq!(err.trim_end(), format!("error: {want}"), "{err}");
}
