//! Training on the CPU backend: targets rendered from known splats, training
//! from a perturbed start must fit held-out views, be bit-identical across
//! runs with the same seed, and ignore masked (moving) pixels.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::needless_range_loop)]

mod common;

use rand::{Rng, SeedableRng};
use splat::metrics::psnr;
use splat::reference::{CpuBackend, render};
use splat::strategy::DefaultStrategyOptions;
use splat::train::{TrainData, TrainOptions, Trainer, View, fresh_start};
use splat::{RenderCamera, RenderOptions, Splats};

fn cams(n: usize) -> Vec<RenderCamera> {
    (0..n)
        .map(|i| {
            let mut c = common::camera(48, 40, 44.0);
            let a = i as f32 * 0.7;
            c.translation = [0.4 * a.cos(), 0.3 * a.sin(), 0.1 * (i % 3) as f32];
            c
        })
        .collect()
}

fn views(gt: &Splats, cams: &[RenderCamera]) -> Vec<View> {
    cams.iter()
        .enumerate()
        .map(|(i, c)| {
            let opts = RenderOptions {
                sh_degree: 1,
                ..Default::default()
            };
            View {
                index: i,
                name: format!("{i}"),
                camera: *c,
                image: render(gt, c, &opts).unwrap().image,
                mask: None,
            }
        })
        .collect()
}

fn perturbed(gt: &Splats, seed: u64) -> Splats {
    let mut s = gt.clone();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    for m in &mut s.means {
        for v in m.iter_mut() {
            *v += rng.random_range(-0.08..0.08);
        }
    }
    for v in &mut s.sh {
        *v = 0.5 * *v + rng.random_range(-0.2..0.2);
    }
    for l in &mut s.opacity_logits {
        *l = 0.0;
    }
    s
}

fn options(steps: u32) -> TrainOptions {
    TrainOptions {
        steps,
        sh_degree: 1,
        sh_degree_every: 40,
        strategy: DefaultStrategyOptions {
            densify_from: 30,
            densify_every: 30,
            densify_until: 100,
            grad_threshold: 1e-4,
            opacity_reset_every: 0,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn train(data: &TrainData, start: Splats, opts: TrainOptions) -> Splats {
    let mut b = CpuBackend::new();
    let mut t = Trainer {
        backend: &mut b,
        data,
        opts,
        checkpoint_dir: None,
    };
    t.run(fresh_start(start), &mut |_| {}).unwrap().0.splats
}

fn test_psnr(s: &Splats, v: &[View]) -> f64 {
    let opts = RenderOptions {
        sh_degree: 1,
        ..Default::default()
    };
    v.iter()
        .map(|v| psnr(&render(s, &v.camera, &opts).unwrap().image, &v.image, None).unwrap())
        .sum::<f64>()
        / v.len() as f64
}

#[test]
fn fits_held_out_views_deterministically() {
    let gt = common::random_splats(80, 1, 21, (-3.0, -1.8));
    let all = cams(7);
    let train_v = views(&gt, &all[..6]);
    let test_v = views(&gt, &all[6..]);
    let data = TrainData {
        views: train_v,
        extent: 1.0,
    };
    let start = perturbed(&gt, 3);
    let before = test_psnr(&start, &test_v);
    let a = train(&data, start.clone(), options(150));
    let after = test_psnr(&a, &test_v);
    eprintln!(
        "held-out PSNR {before:.2} → {after:.2} dB, {} splats",
        a.len()
    );
    // Calibrated 2026-11-22 (CPU backend): 22.35 → 25.65 dB; thresholds leave margin.
    assert!(after > before + 2.0 && after > 24.5, "{before} → {after}");
    let b = train(&data, start, options(150));
    assert_eq!(a, b, "two runs with the same seed differ");
}

#[test]
fn masked_pixels_are_ignored() {
    let gt = common::random_splats(80, 1, 22, (-3.0, -1.8));
    let all = cams(6);
    let clean = views(&gt, &all);
    // A "pedestrian": a magenta block in the middle of every training image.
    let mut dirty = clean.clone();
    for v in &mut dirty {
        let w = v.camera.width as usize;
        let mut mask = vec![1.0f32; (v.camera.width * v.camera.height) as usize];
        for y in 12..28 {
            for x in 16..32 {
                v.image[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[1.0, 0.0, 1.0]);
                mask[y * w + x] = 0.0;
            }
        }
        v.mask = Some(mask);
    }
    let start = perturbed(&gt, 4);
    let masked = train(
        &TrainData {
            views: dirty.clone(),
            extent: 1.0,
        },
        start.clone(),
        options(120),
    );
    for v in &mut dirty {
        v.mask = None;
    }
    let unmasked = train(
        &TrainData {
            views: dirty,
            extent: 1.0,
        },
        start,
        options(120),
    );
    let (pm, pu) = (test_psnr(&masked, &clean), test_psnr(&unmasked, &clean));
    eprintln!("clean-view PSNR: masked {pm:.2} dB, unmasked {pu:.2} dB");
    // Calibrated 2026-11-22: masked 22.87 dB vs unmasked 20.74 dB.
    assert!(pm > pu + 1.0, "masked {pm} vs unmasked {pu}");
}
