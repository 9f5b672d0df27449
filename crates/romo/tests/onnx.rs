//! ONNX Runtime path (feature `onnx`). A missing runtime must be an error,
//! not a panic; with `ORT_DYLIB_PATH` set and the XFeat model present
//! (`$XFEAT_ONNX`, default `../shared/data/onnx/xfeat.onnx`), the encoder
//! must give a 64-channel 80×80 map that responds to image content. The
//! flow path runs the Lucas–Kanade model `scripts/make_lk_flow_onnx.py`
//! writes (needs python3 with `onnx`) against a known translation. Skips
//! cleanly when the runtime, model or python is absent and `CI` is unset.
#![cfg(feature = "onnx")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use romo::features::FeatureExtractor;
use romo::plane::{Plane, Rgb};
use std::path::PathBuf;

#[test]
fn missing_model_is_an_error() {
    let r = romo::onnx::OnnxFeatures::load(std::path::Path::new("/nonexistent/model.onnx"));
    assert!(r.is_err());
}

#[test]
fn xfeat_encoder_runs() {
    let Some(_) = std::env::var_os("ORT_DYLIB_PATH") else {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI set but ORT_DYLIB_PATH missing"
        );
        eprintln!("skipped: ORT_DYLIB_PATH not set");
        return;
    };
    let model = std::env::var_os("XFEAT_ONNX")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/onnx/xfeat.onnx")
        });
    if !model.exists() {
        eprintln!("skipped: {} not found", model.display());
        return;
    }
    let enc = romo::onnx::OnnxFeatures::load(&model).unwrap();
    let img = |phase: f32| Rgb {
        c: [0, 1, 2].map(|k| {
            Plane::from_fn(96, 64, |x, y| {
                0.5 + 0.4 * ((x as f32 * 0.3 + phase + k as f32).sin() * (y as f32 * 0.2).cos())
            })
        }),
    };
    let a = enc.encode(&img(0.0)).unwrap();
    assert_eq!((a.c, a.w, a.h), (64, 80, 80));
    assert!(a.data.iter().all(|v| v.is_finite()));
    let b = enc.encode(&img(1.5)).unwrap();
    let diff: f32 = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .sum::<f32>()
        / a.data.len() as f32;
    assert!(diff > 1e-4, "descriptors do not depend on the image");
    let m = enc.extract(&img(0.0), 24, 16).unwrap();
    assert_eq!((m.c, m.w, m.h), (64, 24, 16));
}

/// The Lucas–Kanade flow model `scripts/make_lk_flow_onnx.py` writes, in a
/// temp folder; None (skip) when the runtime, python3 or its `onnx` package
/// is missing and `CI` is unset.
fn lk_flow_model(dir: &std::path::Path) -> Option<PathBuf> {
    lk_model(dir, false)
}

/// As [`lk_flow_model`]; `bidirectional`: the [1, 4, H, W] output
/// (forward, then backward flow).
fn lk_model(dir: &std::path::Path, bidirectional: bool) -> Option<PathBuf> {
    let ci = std::env::var_os("CI").is_some();
    if std::env::var_os("ORT_DYLIB_PATH").is_none() {
        assert!(!ci, "CI set but ORT_DYLIB_PATH missing");
        eprintln!("skipped: ORT_DYLIB_PATH not set");
        return None;
    }
    let script =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scripts/make_lk_flow_onnx.py");
    let out = dir.join(if bidirectional {
        "lk_flow_both.onnx"
    } else {
        "lk_flow.onnx"
    });
    let ok = std::process::Command::new("python3")
        .arg(&script)
        .args(bidirectional.then_some("--bidirectional"))
        .arg(&out)
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            !ci,
            "CI set but {} failed (pip install onnx)",
            script.display()
        );
        eprintln!("skipped: could not run {}", script.display());
        return None;
    }
    Some(out)
}

/// A smooth texture shifted by (dx, dy) px.
fn textured(w: usize, h: usize, dx: f32, dy: f32) -> Plane {
    Plane::from_fn(w, h, |x, y| {
        let (x, y) = (x as f32 - dx, y as f32 - dy);
        0.5 + 0.2 * (x * 0.35).sin() * (y * 0.3).cos() + 0.15 * (x * 0.13 + y * 0.21).sin()
    })
}

#[test]
fn onnx_flow_recovers_a_known_translation() {
    use romo::flow::FlowEstimator;
    let dir = tempfile::tempdir().unwrap();
    let Some(model) = lk_flow_model(dir.path()) else {
        return;
    };
    let net = romo::onnx::OnnxFlow::load(&model, 1.0).unwrap();
    assert_eq!(net.input_size, None, "the LK model has dynamic H, W");
    // 96×64 goes in as is; 90×60 and 50×34 are padded to multiples of 32
    // (96×64, 64×64) and their flow cropped back.
    for (w, h, tol_mean) in [(96usize, 64usize, 0.02f32), (90, 60, 0.02), (50, 34, 0.02)] {
        let (dx, dy) = (0.7f32, -0.4f32);
        let f = net
            .flow(&textured(w, h, 0.0, 0.0), &textured(w, h, dx, dy))
            .unwrap();
        assert_eq!((f.w(), f.h()), (w, h));
        let (mu, mv) = mean_flow(&f);
        assert!(
            (mu - dx).abs() < tol_mean && (mv - dy).abs() < tol_mean,
            "{w}x{h}: mean flow ({mu}, {mv}), truth ({dx}, {dy})"
        );
    }
    // The pipeline's backend switch builds it.
    let opts = romo::RomoOptions {
        flow_backend: romo::FlowBackend::Onnx {
            model: model.clone(),
        },
        ..Default::default()
    };
    assert_eq!(romo::scene::make_flow(&opts).unwrap().name(), "onnx-flow");
}

/// Mean flow over the frame less a 10-pixel border.
fn mean_flow(f: &romo::flow::Flow) -> (f32, f32) {
    let (w, h) = (f.w(), f.h());
    let (mut su, mut sv, mut n) = (0.0f32, 0.0f32, 0.0f32);
    for y in 10..h - 10 {
        for x in 10..w - 10 {
            su += f.u.data[y * w + x];
            sv += f.v.data[y * w + x];
            n += 1.0;
        }
    }
    (su / n, sv / n)
}

/// Forward and backward flow from a [1, 2, h, w] model (two runs) and from
/// a [1, 4, h, w] one (one run), on RGB frames.
#[test]
fn onnx_flow_pair_gives_both_directions() {
    use romo::flow::FlowEstimator;
    let dir = tempfile::tempdir().unwrap();
    let (Some(one_way), Some(both)) = (lk_model(dir.path(), false), lk_model(dir.path(), true))
    else {
        return;
    };
    let (dx, dy) = (0.6f32, 0.3f32);
    let rgb = |p: Plane| Rgb {
        c: [p.clone(), p.clone(), p],
    };
    let (a, b) = (
        rgb(textured(80, 56, 0.0, 0.0)),
        rgb(textured(80, 56, dx, dy)),
    );
    for model in [one_way, both] {
        let net = romo::onnx::OnnxFlow::load(&model, 1.0).unwrap();
        let (f, bw) = net.flow_pair(&a, &b).unwrap();
        let ((fu, fv), (bu, bv)) = (mean_flow(&f), mean_flow(&bw));
        for (got, want) in [(fu, dx), (fv, dy), (bu, -dx), (bv, -dy)] {
            assert!(
                (got - want).abs() < 0.02,
                "{}: forward ({fu}, {fv}), backward ({bu}, {bv}); truth ({dx}, {dy})",
                model.display()
            );
        }
        // A single direction from the two-way model is its forward flow.
        let single = net.flow(&a.gray(), &b.gray()).unwrap();
        assert!((mean_flow(&single).0 - dx).abs() < 0.02);
    }
}

#[test]
fn onnx_flow_rejects_bad_models_and_inputs() {
    use romo::flow::FlowEstimator;
    let r = romo::onnx::OnnxFlow::load(std::path::Path::new("/nonexistent/flow.onnx"), 1.0);
    assert!(r.is_err());
    let dir = tempfile::tempdir().unwrap();
    let Some(model) = lk_flow_model(dir.path()) else {
        return;
    };
    assert!(romo::onnx::OnnxFlow::load(&model, 0.0).is_err());
    let net = romo::onnx::OnnxFlow::load(&model, 1.0).unwrap();
    let e = net
        .flow(&textured(32, 24, 0.0, 0.0), &textured(24, 32, 0.0, 0.0))
        .unwrap_err();
    assert!(e.to_string().contains("32x24"), "{e}");
}
