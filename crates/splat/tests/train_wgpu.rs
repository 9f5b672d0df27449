//! CI training test on the wgpu backend (lavapipe in CI): generate the small
//! built-in scene (`scenes/small.toml` through `loader::synth`), train on its
//! `clutter` views with ground-truth masks for a fixed number of steps and
//! score the held-out `extra` views. Asserts a PSNR floor set from
//! measurement (see `PSNR_FLOOR`) and a gain over the initial splats, so a
//! broken kernel, loss or optimiser fails it.
//!
//! Without an adapter the test skips with a message, unless `CI` is set: then
//! it fails, so CI cannot silently stop testing the GPU path.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use loader::{Scene, SceneOptions};
use splat::backend::TrainBackend;
use splat::gpu::{GpuBackend, GpuError, GpuOptions};
use splat::train::data::{initial_splats, load_views, scene_extent};
use splat::train::eval::evaluate;
use splat::train::{TrainData, TrainOptions, Trainer, fresh_start};
use splat::types::RenderOptions;

/// Training steps (no densification yet: it starts at step 500).
const STEPS: u32 = 200;
/// Held-out PSNR floor (dB) after `STEPS` steps at 160×120 (4 `extra`
/// views). Measured on lavapipe (llvmpipe 256-bit, Mesa 22.3.6): 22.89 dB
/// from 13.00 dB for the initial splats (same with the CPU and the GPU
/// D-SSIM; 29 s, 8 steps/s in `cargo test --release` on a loaded 2-core
/// machine); the floor leaves 1.4 dB for driver and rounding differences.
const PSNR_FLOOR: f64 = 21.5;
/// Required gain over the initial splats (dB; measured 9.9).
const MIN_GAIN: f64 = 6.0;

fn gpu_backend() -> Option<GpuBackend> {
    match GpuBackend::new(&GpuOptions::default()) {
        Ok(b) => Some(b),
        Err(GpuError::NoAdapter) if std::env::var_os("CI").is_none() => {
            eprintln!("skipping wgpu training test: no adapter (set CI=1 to make this fail)");
            None
        }
        Err(e) => panic!("wgpu backend unavailable under CI: {e}"),
    }
}

#[test]
fn wgpu_training_on_small_scene_reaches_psnr_floor() {
    let Some(mut backend) = gpu_backend() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let spec_path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/small.toml");
    let spec = loader::synth::spec::load_spec(spec_path).unwrap();
    loader::synth::generate(&spec, dir.path()).unwrap();
    let scene = Scene::load(dir.path(), &SceneOptions { downscale: 2 }).unwrap();
    let train_idx = scene.split_indices("clutter");
    let test_idx = scene.split_indices("extra");
    assert!(train_idx.len() >= 10 && !test_idx.is_empty());
    let views = load_views(&scene, &train_idx, true).unwrap();
    let test_views = load_views(&scene, &test_idx, false).unwrap();
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let extent = scene_extent(&cams);
    let opts = TrainOptions {
        steps: STEPS,
        ..Default::default()
    };
    let (init, _) = initial_splats(&scene, &cams, extent, &opts).unwrap();
    let data = TrainData { views, extent };
    let ropts = RenderOptions::default();
    let (before, _) = evaluate(&mut backend, &init, &test_views, &ropts).unwrap();
    let mut trainer = Trainer {
        backend: &mut backend,
        data: &data,
        opts,
        checkpoint_dir: None,
    };
    let (end, rep) = trainer.run(fresh_start(init), &mut |_| {}).unwrap();
    assert_eq!(rep.steps, STEPS);
    let ropts = RenderOptions {
        sh_degree: end.splats.sh_degree,
        ..Default::default()
    };
    let (after, _) = evaluate(&mut backend, &end.splats, &test_views, &ropts).unwrap();
    eprintln!(
        "wgpu small scene: held-out PSNR {:.2} -> {:.2} dB, SSIM {:.4}, {:.2} steps/s ({})",
        before.mean_psnr,
        after.mean_psnr,
        after.mean_ssim,
        rep.steps_per_sec,
        backend.name()
    );
    assert!(after.mean_psnr.is_finite());
    assert!(
        after.mean_psnr >= PSNR_FLOOR,
        "held-out PSNR {:.2} dB < floor {PSNR_FLOOR}",
        after.mean_psnr
    );
    assert!(
        after.mean_psnr - before.mean_psnr >= MIN_GAIN,
        "held-out PSNR gain {:.2} dB < {MIN_GAIN}",
        after.mean_psnr - before.mean_psnr
    );
}
