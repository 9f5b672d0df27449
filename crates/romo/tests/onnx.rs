//! ONNX Runtime path (feature `onnx`). A missing runtime must be an error,
//! not a panic; with `ORT_DYLIB_PATH` set and the XFeat model present
//! (`$XFEAT_ONNX`, default `../shared/data/onnx/xfeat.onnx`), the encoder
//! must give a 64-channel 80×80 map that responds to image content. Skips
//! cleanly when the runtime or model is absent and `CI` is unset.
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
