//! Scene-level check: RoMo on the built-in small synthetic scene (generated
//! into a temp folder, fewer frames to stay fast in the dev profile) must
//! find the pedestrians: J against `gt_motion/` above a threshold set from
//! measurement, masks in the COLMAP convention, and all-keep masks for the
//! held-out test views.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

#[test]
fn small_scene_masks_match_ground_truth_motion() {
    let spec_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/small.toml");
    let mut spec = loader::synth::load_spec(&spec_path).unwrap();
    spec.frames = 16;
    spec.supersample = 1;
    let dir = tempfile::tempdir().unwrap();
    loader::synth::generate(&spec, dir.path()).unwrap();
    let scene = loader::scene::Scene::load(dir.path(), &Default::default()).unwrap();
    let mut opts = romo::RomoOptions::default();
    opts.labels.robust.iterations = 200;
    opts.grid_max_side = 192;
    let out = dir.path().join("out");
    opts.out = Some(out.clone());
    let report = romo::segment_scene(&scene, &opts, &|_, _, _| {}).unwrap();
    assert_eq!(report.frames.len(), 16);
    assert!(
        report.rounds.iter().all(|r| !r.collapsed),
        "{:?}",
        report.rounds
    );
    let m =
        romo::metrics::evaluate_masks(&out.join("masks"), &dir.path().join("gt_motion")).unwrap();
    let s = &m.sequences[0];
    assert!(s.pred_convention.starts_with("keep"));
    eprintln!(
        "small scene: J {:.3} P {:.3} R {:.3}",
        m.j_mean, m.precision, m.recall
    );
    // Measured 2026-11-22 (dev profile, 16 frames + 4 held-out views): J
    // 0.283, precision 0.77, recall 0.12. The pedestrians cross sideways
    // while the camera dollies sideways, so most of their motion lies along
    // epipolar lines and the Sampson residual cannot see it.
    assert!(m.precision >= 0.5, "precision {}", m.precision);
    assert!(
        m.j_mean >= 0.2,
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
