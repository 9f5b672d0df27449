//! Benchmark: per-kernel GPU times of a training step on a real scene's
//! first view with its initial splats (no densification), for tuning the
//! kernels on a shared machine: prints, per kernel, the median and the
//! minimum ms over the steps (the minimum is the least load-sensitive).
//! Scene: `STEP_BENCH_SCENE` (default `../shared/data/fox` from the repo
//! root), `STEP_BENCH_DOWNSCALE` (default 4), `STEP_BENCH_STEPS` (default 5);
//! `STEP_BENCH_PLY` trains splats from a PLY (e.g. a trained scene) instead
//! of the scene's initial ones.
//! Run: `cargo bench -p splat --bench step_profile`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use loader::scene::{Scene, SceneOptions};
use splat::backend::{LossConfig, StepInput, TrainBackend};
use splat::gpu::{GpuBackend, GpuOptions};
use splat::train::TrainOptions;
use splat::train::data::{initial_splats, load_views, scene_extent};
use splat::types::{AdamState, RenderOptions};
use std::collections::BTreeMap;

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
    let mut b = GpuBackend::new(&GpuOptions {
        timestamps: true,
        ..Default::default()
    })
    .unwrap();
    b.upload(&splats, &AdamState::zeros_like(&splats)).unwrap();
    let v = &views[0];
    let input = StepInput {
        camera: &v.camera,
        target: &v.image,
        mask: v.mask.as_deref(),
        view_id: Some(v.index),
        lr: opts.learning_rates(0, extent),
        loss: LossConfig::default(),
        render: RenderOptions {
            sh_degree: 3,
            ..Default::default()
        },
    };
    b.step(&input).unwrap();
    b.profile = true;
    let mut per: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    for _ in 0..steps {
        let t0 = std::time::Instant::now();
        b.step(&input).unwrap();
        let wall = t0.elapsed().as_secs_f64() * 1e3;
        let mut this: BTreeMap<&'static str, f64> = BTreeMap::new();
        for (name, ms) in b.last_timings() {
            *this.entry(name).or_insert(0.0) += ms;
        }
        this.insert("step_wall", wall);
        for (k, ms) in this {
            per.entry(k).or_default().push(ms);
        }
    }
    let mut out = serde_json::Map::new();
    for (k, mut v) in per {
        v.sort_by(f64::total_cmp);
        let r = |x: f64| (x * 10.0).round() / 10.0;
        out.insert(
            k.to_string(),
            serde_json::json!({ "median": r(v[v.len() / 2]), "min": r(v[0]) }),
        );
    }
    println!(
        "{}",
        serde_json::json!({
            "scene": root,
            "splats": splats.len(),
            "intersections": b.last_intersections(),
            "ms": out,
        })
    );
}
