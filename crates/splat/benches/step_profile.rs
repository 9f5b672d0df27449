//! Benchmark: per-kernel GPU times of a training step on a real scene's
//! first view with its initial splats (no densification), for tuning the
//! kernels on a shared machine: prints, per kernel, the median ms over the
//! steps (`splat::gpu::profile_step`, as `romosplat bench train --profile`,
//! which this adds a trained-PLY input to; `count:intersections` included).
//! Scene: `STEP_BENCH_SCENE` (default `../shared/data/fox` from the repo
//! root), `STEP_BENCH_DOWNSCALE` (default 4), `STEP_BENCH_STEPS` (default 5);
//! `STEP_BENCH_PLY` trains splats from a PLY (e.g. a trained scene) instead
//! of the scene's initial ones; `STEP_BENCH_SH` the SH degree rendered
//! (default 3).
//! Run: `cargo bench -p splat --bench step_profile`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use loader::scene::{Scene, SceneOptions};
use splat::backend::LossConfig;
use splat::gpu::profile_step;
use splat::train::TrainOptions;
use splat::train::data::{initial_splats, load_views, scene_extent};
use splat::types::RenderOptions;

fn env_or<T: std::str::FromStr>(k: &str, d: T) -> T {
    std::env::var(k)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(d)
}

fn main() {
    let root = std::env::var("STEP_BENCH_SCENE").unwrap_or_else(|_| {
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/fox").into()
    });
    let downscale: u32 = env_or("STEP_BENCH_DOWNSCALE", 4);
    let steps: usize = env_or("STEP_BENCH_STEPS", 5);
    let scene = Scene::load(std::path::Path::new(&root), &SceneOptions { downscale }).unwrap();
    let views = load_views(&scene, &[0], true).unwrap();
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let extent = scene_extent(&cams);
    let opts = TrainOptions::default();
    let splats = match std::env::var("STEP_BENCH_PLY") {
        Ok(p) => splat::io::read_ply(p).unwrap(),
        Err(_) => initial_splats(&scene, &cams, extent, &opts).unwrap().0,
    };
    let sh_degree: u32 = env_or("STEP_BENCH_SH", 3);
    let v = &views[0];
    let input = v.step_input(
        opts.learning_rates(0, extent),
        LossConfig::default(),
        RenderOptions {
            sh_degree,
            ..Default::default()
        },
    );
    let prof = profile_step(&splats, &input, 1, steps).unwrap();
    let r = |x: f64| (x * 10.0).round() / 10.0;
    let ms: serde_json::Map<String, serde_json::Value> =
        prof.into_iter().map(|(k, v)| (k, r(v).into())).collect();
    println!(
        "{}",
        serde_json::json!({ "scene": root, "splats": splats.len(), "ms": ms })
    );
}
