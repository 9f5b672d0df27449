//! The pose stage resumes from its kept database, retries a failed
//! initialisation once with relaxed settings, and copes with images COLMAP
//! cannot read (16-bit copies, named failures) and of several sizes.
//!
//! `interrupted_run_resumes` and `sixteen_bit_images_are_read_through_8_bit_copies`
//! run real COLMAP 3.8 on frames of the small built-in scene (with `CI` set a
//! missing colmap fails them; otherwise they skip); the others use a
//! stand-in `colmap` script.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use pose::colmap_runner::{
    ColmapOptions, ColmapPaths, Progress, relaxed_init_args, run_colmap, run_colmap_cancellable,
};
use pose::progress::Unit;
use pose::resume::Decision;
use pose::{MapperOptions, PoseError};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

mod common;
use common::colmap_available;

/// The first `n` frames of the small scene in `dir/images`.
fn small_frames(dir: &Path, n: usize) -> PathBuf {
    let full = dir.join("full");
    let spec_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/small.toml");
    let spec = loader::synth::load_spec(&spec_path).unwrap();
    loader::synth::generate(&spec, &full).unwrap();
    let scene = dir.join("scene");
    std::fs::create_dir_all(scene.join("images")).unwrap();
    for i in 0..n {
        let name = format!("{i:05}.png");
        std::fs::copy(
            full.join("images").join(&name),
            scene.join("images").join(&name),
        )
        .unwrap();
    }
    scene
}

/// Real COLMAP on a few small-scene frames: no masks, pinhole, the video
/// mapper preset, overlap 3, no undistortion.
fn small_scene_options() -> ColmapOptions {
    ColmapOptions {
        use_masks: false,
        overlap: 3,
        undistort: false,
        camera_model: loader::CameraModel::PINHOLE,
        mapper: MapperOptions::video(),
        ..ColmapOptions::default()
    }
}

/// `dir/scene/images/{a,b,c,…}.png`, black, of the given sizes.
fn grey_images(dir: &Path, sizes: &[(u32, u32)]) -> PathBuf {
    let scene = dir.join("scene");
    std::fs::create_dir_all(scene.join("images")).unwrap();
    for (i, &(w, h)) in sizes.iter().enumerate() {
        let name = format!("{}.png", char::from(b'a' + i as u8));
        image::GrayImage::new(w, h)
            .save(scene.join("images").join(name))
            .unwrap();
    }
    scene
}

/// `dir/colmap`: a stand-in shell script that says it is COLMAP 3.8, runs
/// the `case` arms in `arms` (e.g. `mapper) exit 1 ;;`) and succeeds at
/// every other step.
fn stand_in_colmap(dir: &Path, arms: &str) -> PathBuf {
    let colmap = dir.join("colmap");
    std::fs::write(
        &colmap,
        format!(
            "#!/bin/sh\ncase \"$1\" in\n  -h) echo 'COLMAP 3.8 -- stand-in' ;;\n  {arms}\n  *) exit 0 ;;\nesac\n"
        ),
    )
    .unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&colmap, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    colmap
}

fn log(work: &Path, step: &str) -> String {
    std::fs::read_to_string(work.join(format!("{step}.log"))).unwrap()
}

#[test]
fn interrupted_run_resumes() {
    if !colmap_available() {
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let scene = small_frames(d.path(), 10);
    let paths = ColmapPaths::for_scene(&scene);
    let opts = small_scene_options();

    // 1. Killed during matching, after the third image's pairs.
    let cancel = AtomicBool::new(false);
    let e = run_colmap_cancellable(
        &paths,
        &opts,
        &mut |p| {
            if let Progress::Count { count, .. } = p
                && count.unit == Unit::Matched
                && count.done >= 3
            {
                cancel.store(true, Ordering::Relaxed);
            }
        },
        &cancel,
    )
    .unwrap_err();
    assert!(matches!(e, PoseError::Cancelled { .. }), "{e}");
    let first = log(&paths.work, "feature_extractor");
    assert_eq!(first.matches("Features:").count(), 10, "{first}");
    assert!(!first.contains("SKIP"));

    // 2. The rerun extracts nothing again and skips the matched pairs.
    let r = run_colmap(&paths, &opts, &mut |_| {}).unwrap();
    assert_eq!(r.database, Decision::KeepAll);
    assert_eq!(r.features_reused, 10);
    let second = log(&paths.work, "feature_extractor");
    assert_eq!(
        second
            .matches("SKIP: Features for image already extracted")
            .count(),
        10
    );
    // COLMAP 3.8 logs no skip per pair: the first image's kept pairs take
    // a fraction of a pair actually matched (times relative, so that load
    // cannot fail the test).
    let matched = log(&paths.work, "sequential_matcher");
    let times: Vec<f64> = matched
        .lines()
        .filter_map(|l| {
            let rest = l.strip_prefix("Matching image [")?;
            rest.split(" in ").nth(1)?.strip_suffix('s')?.parse().ok()
        })
        .collect();
    assert_eq!(times.len(), 10, "{matched}");
    let slowest = times.iter().copied().fold(0.0, f64::max);
    assert!(times[0] * 10.0 < slowest, "{matched}");
    assert!(r.registered >= 9, "registered {}/10", r.registered);

    // 3. Other matching settings keep the features and clear the matches.
    let notes = std::cell::RefCell::new(Vec::new());
    let cancel = AtomicBool::new(false);
    let wider = ColmapOptions {
        overlap: 4,
        ..opts.clone()
    };
    let e = run_colmap_cancellable(
        &paths,
        &wider,
        &mut |p| match p {
            Progress::Note { step, .. } => notes.borrow_mut().push(step),
            Progress::Started { step, .. } if step == "sequential_matcher" => {
                cancel.store(true, Ordering::Relaxed)
            }
            _ => {}
        },
        &cancel,
    )
    .unwrap_err();
    assert!(matches!(e, PoseError::Cancelled { .. }), "{e}");
    assert_eq!(notes.borrow().as_slice(), ["database_cleaner"]);
    let third = log(&paths.work, "feature_extractor");
    assert_eq!(third.matches("SKIP").count(), 10);

    // 4. Other feature settings start a fresh database.
    let cancel = AtomicBool::new(false);
    let fewer = ColmapOptions {
        max_num_features: 500,
        ..opts.clone()
    };
    let _ = run_colmap_cancellable(
        &paths,
        &fewer,
        &mut |p| {
            if let Progress::Started { step, .. } = p
                && step == "sequential_matcher"
            {
                cancel.store(true, Ordering::Relaxed)
            }
        },
        &cancel,
    );
    let fourth = log(&paths.work, "feature_extractor");
    assert!(!fourth.contains("SKIP"), "{fourth}");
}

#[test]
fn failed_init_retries_once_then_says_why() {
    let d = tempfile::tempdir().unwrap();
    let scene = grey_images(d.path(), &[(8, 6); 3]);
    let calls = d.path().join("mapper_calls");
    let colmap = stand_in_colmap(
        d.path(),
        &format!(
            "mapper) echo \"$@\" >> '{}'; echo 'Finding good initial image pair'; echo '  => No good initial image pair found.'; exit 1 ;;",
            calls.display()
        ),
    );
    let opts = ColmapOptions {
        colmap: colmap.clone(),
        use_masks: false,
        ..ColmapOptions::default()
    };
    let e = run_colmap(&ColmapPaths::for_scene(&scene), &opts, &mut |_| {}).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with("COLMAP found no initial image pair from 3 images, also with relaxed"),
        "{msg}"
    );
    assert!(msg.contains("mapper_relaxed.log"), "{msg}");
    assert!(!msg.contains('\n'), "{msg}");
    let calls = std::fs::read_to_string(&calls).unwrap();
    let lines: Vec<&str> = calls.lines().collect();
    assert_eq!(lines.len(), 2, "{calls}");
    assert!(!lines[0].contains("init_max_forward_motion"));
    let relaxed = relaxed_init_args(&opts.mapper).join(" ");
    assert!(lines[1].ends_with(&relaxed), "{}", lines[1]);
    assert!(lines[1].contains("--Mapper.init_min_tri_angle 8"));
    // COLMAP refuses an option given twice.
    let opts_given: Vec<&str> = lines[1]
        .split_whitespace()
        .filter(|w| w.starts_with("--"))
        .collect();
    let unique: std::collections::HashSet<&&str> = opts_given.iter().collect();
    assert_eq!(unique.len(), opts_given.len(), "{}", lines[1]);
}

#[test]
fn images_of_several_sizes_get_one_camera_each() {
    // A photo collection: COLMAP's shared camera would skip every image
    // whose size differs from the first one's.
    let d = tempfile::tempdir().unwrap();
    let scene = grey_images(d.path(), &[(8, 6), (6, 8), (8, 6)]);
    let calls = d.path().join("extractor_calls");
    let colmap = stand_in_colmap(
        d.path(),
        &format!(
            "feature_extractor) echo \"$@\" >> '{}' ;;\n  mapper) exit 1 ;;",
            calls.display()
        ),
    );
    let opts = ColmapOptions {
        colmap,
        use_masks: false,
        ..ColmapOptions::default()
    };
    assert!(opts.single_camera);
    let mut notes = vec![];
    let _ = run_colmap(&ColmapPaths::for_scene(&scene), &opts, &mut |p| {
        if let Progress::Note { message, .. } = p {
            notes.push(message);
        }
    });
    let calls = std::fs::read_to_string(&calls).unwrap();
    assert!(calls.contains("--ImageReader.single_camera 0"), "{calls}");
    assert!(
        notes
            .iter()
            .any(|n| n.contains("2 sizes (8×6, 6×8): one camera per image")),
        "{notes:?}"
    );
}

/// Frames of a 10-bit video or 16-bit scans: COLMAP 3.8 cannot read
/// 16-bit PNGs, so the stage gives it 8-bit copies under the same names.
#[test]
fn sixteen_bit_images_are_read_through_8_bit_copies() {
    if !colmap_available() {
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let scene = small_frames(d.path(), 8);
    let images = scene.join("images");
    for i in 0..8 {
        let p = images.join(format!("{i:05}.png"));
        let deep: image::ImageBuffer<image::Rgb<u16>, Vec<u16>> =
            image::DynamicImage::ImageRgb8(image::open(&p).unwrap().to_rgb8()).into_rgb16();
        deep.save(&p).unwrap();
    }
    assert_eq!(
        image::open(images.join("00000.png")).unwrap().color(),
        image::ColorType::Rgb16
    );
    let paths = ColmapPaths::for_scene(&scene);
    let opts = small_scene_options();
    let mut notes = Vec::new();
    let r = run_colmap(&paths, &opts, &mut |p| {
        if let Progress::Note { message, .. } = p {
            notes.push(message);
        }
    })
    .unwrap();
    assert!(r.registered >= 6, "{} of 8 registered", r.registered);
    assert!(
        notes
            .iter()
            .any(|n| n.starts_with("8 of 8 images have more than 8 bits")),
        "{notes:?}"
    );
    let copy = paths.work.join("images_8bit/00003.png");
    assert_eq!(image::open(&copy).unwrap().color(), image::ColorType::Rgb8);
    // The originals are untouched.
    assert_eq!(
        image::open(images.join("00003.png")).unwrap().color(),
        image::ColorType::Rgb16
    );
}

/// COLMAP exits 0 when it cannot read an image; the stage names the image
/// instead of letting the matcher abort on an empty database.
#[test]
fn images_colmap_cannot_read_are_named() {
    let d = tempfile::tempdir().unwrap();
    let scene = grey_images(d.path(), &[(8, 6); 3]);
    let colmap = stand_in_colmap(
        d.path(),
        "feature_extractor) for n in a b c; do echo \"Processed file [1/3]\"; echo \"  Name:            $n.png\"; echo \"  ERROR: Failed to read image file format.\"; done ;;\n  sequential_matcher) exit 134 ;;",
    );
    let opts = ColmapOptions {
        colmap,
        use_masks: false,
        ..ColmapOptions::default()
    };
    let e = run_colmap(&ColmapPaths::for_scene(&scene), &opts, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("COLMAP could not read 3 of 3 images in ")
            && e.contains("(first a.png: Failed to read image file format.)")
            && e.contains("feature_extractor.log"),
        "{e}"
    );
    assert!(!e.contains('\n'), "{e}");
}
