//! PSNR / SSIM against known answers computed with scikit-image 0.26.0:
//! `structural_similarity(a, b, gaussian_weights=True, sigma=1.5,
//! use_sample_covariance=False, data_range=1.0, channel_axis=2)` and
//! `peak_signal_noise_ratio(a, b, data_range=1.0)` on the 37×29 images built
//! below (same formulas, float32 then float64), calibrated 2026-11-22.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use splat::metrics::{psnr, ssim};

fn images() -> (Vec<f32>, Vec<f32>) {
    let (w, h) = (37, 29);
    let (mut a, mut b) = (vec![], vec![]);
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let (xf, yf, cf) = (x as f64, y as f64, c as f64);
                let base = 0.5 + 0.4 * (0.3 * xf + 0.2 * yf + cf).sin();
                a.push(base as f32);
                let v = base + 0.15 * (0.9 * xf - 0.5 * yf * cf + 0.1 * xf * yf).cos();
                b.push(v.clamp(0.0, 1.0) as f32);
            }
        }
    }
    (a, b)
}

#[test]
fn ssim_matches_scikit_image() {
    let (a, b) = images();
    let s = ssim(&a, &b, 37, 29, None).unwrap();
    // scikit-image: 0.7454320295129818 (f64 throughout; ours differs only by
    // summation order).
    assert!((s - 0.745_432_029_512_981_8).abs() < 1e-9, "{s}");
    assert!((ssim(&a, &a, 37, 29, None).unwrap() - 1.0).abs() < 1e-12);
}

#[test]
fn psnr_matches_scikit_image() {
    let (a, b) = images();
    let p = psnr(&a, &b, None).unwrap();
    assert!((p - 19.637_860_558_423_62).abs() < 1e-6, "{p}");
}

#[test]
fn masks_exclude_pixels() {
    let (a, mut b) = images();
    let (w, h) = (37usize, 29usize);
    // Ruin the right part of b; a mask that drops it restores a perfect score.
    let mask: Vec<f32> = (0..w * h)
        .map(|i| if i % w >= 20 { 0.0 } else { 1.0 })
        .collect();
    let mut bb = a.clone();
    for i in 0..w * h {
        if i % w >= 20 {
            for c in 0..3 {
                bb[i * 3 + c] = 1.0 - a[i * 3 + c];
                b[i * 3 + c] = 0.0;
            }
        }
    }
    assert!(psnr(&a, &bb, Some(&mask)).unwrap().is_infinite());
    assert!(psnr(&a, &bb, None).unwrap() < 15.0);
    // SSIM windows near the mask edge still see ruined neighbours, so only
    // strictly-inside pixels are perfect: the masked score is far closer to 1.
    let full = ssim(&a, &bb, w, h, None).unwrap();
    let masked = ssim(&a, &bb, w, h, Some(&mask)).unwrap();
    assert!(masked > full + 0.2, "{masked} vs {full}");
    let all_masked = vec![0.0f32; w * h];
    assert!(psnr(&a, &b, Some(&all_masked)).is_none());
}
