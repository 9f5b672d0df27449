//! Scene-level check: RoMo on the built-in small synthetic scene (generated
//! into a temp folder, 24 of its frames to stay fast in the dev profile) must
//! find the pedestrians: J against `gt_motion/` above a threshold set from
//! measurement, masks in the COLMAP convention, and all-keep masks for the
//! held-out test views.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

/// The first 24 frames of a built-in scene (`scenes/<toml>`), generated
/// without supersampling into a temp folder, and the scene loaded from it.
fn generate(toml: &str) -> (tempfile::TempDir, loader::scene::Scene) {
    let spec_path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes")
        .join(toml);
    let mut spec = loader::synth::load_spec(&spec_path).unwrap();
    spec.frames = 24;
    spec.supersample = 1;
    let dir = tempfile::tempdir().unwrap();
    loader::synth::generate(&spec, dir.path()).unwrap();
    let scene = loader::scene::Scene::load(dir.path(), &Default::default()).unwrap();
    (dir, scene)
}

/// RoMo with `opts` (200 LMedS samples) on a generated scene, masks into
/// `<dir>/out`; the report and the masks scored against `gt_motion/`.
fn segment(
    dir: &Path,
    scene: &loader::scene::Scene,
    mut opts: romo::RomoOptions,
) -> (romo::RomoReport, romo::metrics::SequenceMetrics) {
    opts.labels.robust.iterations = 200;
    opts.out = Some(dir.join("out"));
    let report = romo::segment_scene(scene, &opts, &|_, _, _| {}).unwrap();
    // The video frames only: the held-out `extra` views have empty ground
    // truth and all-keep masks, a perfect J of 1 each.
    let m = romo::evaluate_scene_masks(scene, &dir.join("out/masks")).unwrap();
    assert_eq!(m.frames, 24);
    (report, m)
}

#[test]
fn small_scene_masks_match_ground_truth_motion() {
    let (dir, scene) = generate("small.toml");
    let out = dir.path().join("out");
    let (report, m) = segment(dir.path(), &scene, romo::RomoOptions::default());
    assert_eq!(report.frames.len(), 24);
    let u: f32 = report.frames.iter().map(|f| f.u_coverage).sum::<f32>() / 24.0;
    eprintln!(
        "U coverage {u:.4}, moving samples {:?}",
        report
            .rounds
            .iter()
            .map(|r| r.samples_moving)
            .collect::<Vec<_>>()
    );
    assert!(
        report.rounds.iter().all(|r| !r.collapsed),
        "{:?}",
        report.rounds
    );
    // The first round chose the U weight (`mlp.raised_moving_weight`) and
    // the second round trained with the weight of the network it kept.
    let o = romo::RomoOptions::default().mlp;
    let trial = report.rounds[0]
        .weight_trial
        .as_ref()
        .expect("a weight trial");
    let chosen = if trial.raised_kept {
        o.raised_moving_weight
    } else {
        o.moving_weight
    };
    assert_eq!(
        trial.raised_kept,
        trial.raised_error < trial.base_error && trial.z >= o.trial_significance
    );
    assert!(
        report.rounds.iter().all(|r| r.moving_weight == chosen),
        "{:?}",
        report.rounds
    );
    assert!(report.rounds[1..].iter().all(|r| r.weight_trial.is_none()));
    assert!(m.pred_convention.starts_with("keep"));
    eprintln!(
        "small scene: kept U weight {chosen}, J {:.3} P {:.3} R {:.3}",
        m.j_mean, m.precision, m.recall
    );
    // Over the 24 video frames, default options, seed 0 (bit-reproducible,
    // also across thread counts: training sums in a fixed order): J 0.891,
    // P 0.94, R 0.94 (U weight 0.35 kept). The pedestrians cross sideways
    // while the camera dollies sideways, so much of their motion lies along
    // epipolar lines where the Sampson residual cannot see it; the
    // cheirality and three-view tests recover part of it.
    // Thresholds a bit below the measurement.
    assert!(m.precision >= 0.85, "precision {}", m.precision);
    assert!(
        m.j_mean >= 0.76,
        "J {} (precision {}, recall {})",
        m.j_mean,
        m.precision,
        m.recall
    );
    // Held-out views are written as all-keep masks.
    for k in scene.split_indices("extra") {
        let p = loader::masks::mask_path(&out.join("masks"), &scene.frames[k].name);
        let mask = loader::io::read_gray8(&p).unwrap();
        assert!(mask.as_raw().iter().all(|v| *v == 255));
    }
}

/// A base U weight so low that its network gives up U: the first round
/// keeps the network trained at `raised_moving_weight`, and the second
/// round trains on at that weight. Seed 0: the base network fits none of
/// U (error 0.100 under 0.1), the raised one 0.92 of U and 0.92 of L
/// (error 0.089); J 0.883.
#[test]
fn a_kept_raised_u_weight_trains_the_later_rounds() {
    let (dir, scene) = generate("small.toml");
    let mut opts = romo::RomoOptions::default();
    opts.mlp.moving_weight = 0.1;
    let (report, m) = segment(dir.path(), &scene, opts.clone());
    let trial = report.rounds[0]
        .weight_trial
        .as_ref()
        .expect("a weight trial");
    eprintln!("base U weight 0.1: {trial:?}, J {:.3}", m.j_mean);
    assert!(trial.raised_kept, "{trial:?}");
    assert!(trial.raised_recall.0 > trial.base_recall.0, "{trial:?}");
    assert_eq!(report.rounds.len(), 2);
    for r in &report.rounds {
        assert_eq!(r.moving_weight, opts.mlp.raised_moving_weight);
    }
}

/// (J, precision, recall, homography pairs) of RoMo with `opts` on the
/// first 24 frames of `scenes/<toml>`.
fn run_scene(toml: &str, opts: romo::RomoOptions) -> (f64, f64, f64, usize) {
    let (dir, scene) = generate(toml);
    let (report, m) = segment(dir.path(), &scene, opts);
    let h = report.pairs.iter().filter(|p| p.model == "H").count();
    (m.j_mean, m.precision, m.recall, h)
}

/// The low-parallax case on a video: a camera that only
/// pans (`scenes/rotation.toml`, one pedestrian). The default rule must
/// choose the homography for most pairs and find the pedestrian; forcing
/// the fundamental matrix (the paper) must fit F on every pair.
#[test]
fn pure_rotation_video_is_scored_with_homographies() {
    let (j, p, r, h) = run_scene("rotation.toml", romo::RomoOptions::default());
    eprintln!("rotation, default: J {j:.3} P {p:.3} R {r:.3} H pairs {h}/23");
    let mut f_only = romo::RomoOptions::default();
    f_only.labels.robust.selection = romo::geometry::robust::ModelSelection::Fundamental;
    let (jf, pf, rf, hf) = run_scene("rotation.toml", f_only);
    eprintln!("rotation, F only: J {jf:.3} P {pf:.3} R {rf:.3} H pairs {hf}/23");
    // Over the 24 video frames, seed 0: default J 0.947 (P 0.96, R 0.99),
    // H for 23 of 23 pairs; F only J 0.955. With the mask preset's former
    // 5 fixed-point iterations of the flow refinement F only gave 0.722
    // (the degenerate F absorbed part of the pedestrian's motion); with 3
    // it does not on this clip, also without the object cut (0.824
    // against 0.776), so no J ordering is asserted.
    assert_eq!(hf, 0);
    assert!(h >= 18, "only {h} of 23 pairs chose H");
    assert!(j >= 0.7, "J {j} (precision {p}, recall {r})");
}

/// `mask --downscale N` segments the frames at 1/N but writes the masks at
/// the images' own size: the loader (and so `train` and `pose`) accepts
/// them, and they still find the pedestrians.
#[test]
fn masks_of_a_downscaled_scene_have_the_images_size() {
    let spec_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/small.toml");
    let mut spec = loader::synth::load_spec(&spec_path).unwrap();
    spec.supersample = 1;
    let dir = tempfile::tempdir().unwrap();
    loader::synth::generate(&spec, dir.path()).unwrap();
    let scene =
        loader::scene::Scene::load(dir.path(), &loader::scene::SceneOptions { downscale: 2 })
            .unwrap();
    let mut opts = romo::RomoOptions::default();
    opts.labels.robust.iterations = 200;
    romo::segment_scene(&scene, &opts, &|_, _, _| {}).unwrap();
    // The masks now sit in the scene's masks/: loading checks their size.
    let full = loader::scene::Scene::load(dir.path(), &Default::default()).unwrap();
    for (i, f) in full.frames.iter().enumerate() {
        let p = f.mask_path.as_ref().expect("every frame has a mask");
        let m = loader::io::read_gray8(p).unwrap();
        assert_eq!(
            m.dimensions(),
            (f.intrinsics.width, f.intrinsics.height),
            "{}",
            p.display()
        );
        assert!(full.load_mask(i).unwrap().is_some());
    }
    let m = romo::evaluate_scene_masks(&full, &dir.path().join("masks")).unwrap();
    eprintln!(
        "downscale 2: J {:.3} P {:.3} R {:.3}",
        m.j_mean, m.precision, m.recall
    );
    // Seed 0: J 0.713, P 0.91, R 0.77 (30 frames at half size; with 8
    // frames the pedestrians' motion is small beside the dolly's and the
    // outcome depends on the seed, `docs/results.md`).
    assert!(
        m.j_mean >= 0.5 && m.precision >= 0.8,
        "J {} P {}",
        m.j_mean,
        m.precision
    );
}

/// A video longer than `chunk_frames` is segmented in windows sharing one
/// frame, each with its own MLP: every frame gets one mask, the report is
/// indexed over the whole video, and J stays near the whole-video run's.
#[test]
fn a_video_longer_than_chunk_frames_is_segmented_in_windows() {
    let (dir, scene) = generate("small.toml");
    let (_, whole) = segment(dir.path(), &scene, romo::RomoOptions::default());
    let windowed = romo::RomoOptions {
        chunk_frames: 13,
        ..Default::default()
    };
    // 24 frames, 23 pairs, at most 13 frames a window: 0–12, 12–23.
    assert_eq!(romo::scene::chunks(24, 13), [(0, 13), (12, 24)]);
    let (report, m) = segment(dir.path(), &scene, windowed);
    let idx: Vec<usize> = report.frames.iter().map(|f| f.index).collect();
    assert_eq!(idx, (0..24).collect::<Vec<_>>());
    assert_eq!(report.frames[23].name, scene.frames[23].name);
    assert_eq!(report.pairs.len(), 23);
    assert_eq!(report.rounds.len(), 4, "two rounds per window");
    eprintln!("J whole {:.3}, in windows {:.3}", whole.j_mean, m.j_mean);
    assert!(
        m.j_mean >= whole.j_mean - 0.1,
        "J whole {}, in windows {}",
        whole.j_mean,
        m.j_mean
    );
}

#[test]
fn windows_cover_every_pair_once() {
    for n in [2, 5, 6, 499, 500, 501, 1201, 3640] {
        let w = romo::scene::chunks(n, 500);
        assert_eq!(w.first().map(|c| c.0), Some(0));
        assert_eq!(w.last().map(|c| c.1), Some(n));
        for c in &w {
            assert!(c.1 - c.0 <= 500 && c.1 - c.0 >= 2, "{n}: {w:?}");
        }
        for p in w.windows(2) {
            assert_eq!(p[1].0 + 1, p[0].1, "{n}: {w:?}");
        }
    }
    assert_eq!(romo::scene::chunks(3640, 0), [(0, 3640)]);
}

/// Photos whose file names do not sort in capture order (renamed, merged
/// from two phones) are segmented in similarity order: the small scene's
/// 24 frames under shuffled names recover the capture order up to
/// direction, and their masks score as the ordered run's. In their own
/// order the names are kept (`name_order_ratio` 1).
#[test]
fn photos_named_out_of_order_are_segmented_in_capture_order() {
    let (dir, scene) = generate("small.toml");
    let (ordered, m_ordered) = segment(dir.path(), &scene, romo::RomoOptions::default());
    assert!(!ordered.reordered);
    let ratio = ordered.name_order_ratio.unwrap();
    assert!((ratio - 1.0).abs() < 0.05, "{ratio}");
    let extra = scene.split_indices("extra");
    let video: Vec<usize> = (0..scene.frames.len())
        .filter(|i| !extra.contains(i))
        .collect();
    // A fixed shuffle of the 24 video frames, named by their new position.
    let perm: Vec<usize> = (0..24).map(|k| video[(k * 7 + 5) % 24]).collect();
    let paths: Vec<_> = perm
        .iter()
        .map(|&i| scene.frames[i].image_path.clone())
        .collect();
    let names: Vec<String> = (0..24).map(|k| format!("s{k:02}.png")).collect();
    let gt = dir.path().join("gt_shuffled");
    std::fs::create_dir_all(&gt).unwrap();
    for (k, &i) in perm.iter().enumerate() {
        let src =
            loader::masks::gt_motion_path(&scene.root.join("gt_motion"), &scene.frames[i].name);
        std::fs::copy(src, gt.join(format!("s{k:02}.png"))).unwrap();
    }
    let out = dir.path().join("shuffled");
    let mut opts = romo::RomoOptions::default();
    opts.labels.robust.iterations = 200;
    let report = romo::segment_paths(&paths, &names, &out, &opts, &|_, _, _| {}).unwrap();
    assert!(report.reordered, "ratio {:?}", report.name_order_ratio);
    assert!(
        report.warnings[0].contains("not in capture order"),
        "{:?}",
        report.warnings
    );
    // The order segmented, as capture indices: consecutive or reversed.
    let capture: Vec<usize> = report
        .frames
        .iter()
        .map(|f| {
            let k: usize = f.name[1..3].parse().unwrap();
            video.iter().position(|&v| v == perm[k]).unwrap()
        })
        .collect();
    let forward: Vec<usize> = (0..24).collect();
    let backward: Vec<usize> = (0..24).rev().collect();
    assert!(capture == forward || capture == backward, "{capture:?}");
    let m = romo::metrics::evaluate_sequence(&out.join("masks"), &gt, "").unwrap();
    eprintln!(
        "J ordered {:.3}, shuffled {:.3}",
        m_ordered.j_mean, m.j_mean
    );
    assert!(
        m.j_mean >= m_ordered.j_mean - 0.05,
        "J {} vs {}",
        m.j_mean,
        m_ordered.j_mean
    );
}
