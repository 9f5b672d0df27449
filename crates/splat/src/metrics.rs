//! Image metrics for evaluation: PSNR and SSIM, optionally restricted to the
//! pixels a mask keeps (e.g. excluding ground-truth moving pixels).
//!
//! SSIM follows scikit-image `structural_similarity(gaussian_weights=True,
//! sigma=1.5, use_sample_covariance=False, data_range=1, channel_axis=-1)`:
//! an 11×11 Gaussian window (σ = 1.5, truncate 3.5 ⇒ radius 5) applied
//! separably with scipy's `reflect` boundary, C1 = (0.01)², C2 = (0.03)², the
//! map averaged over the image cropped by 5 pixels on each side and over
//! channels. This is also INRIA's SSIM up to its zero-padded border.

use rayon::prelude::*;

/// SSIM window standard deviation (pixels).
pub const SSIM_SIGMA: f64 = 1.5;
/// SSIM window radius (11×11 window).
pub const SSIM_RADIUS: usize = 5;
/// SSIM stabilisers for data range 1.
pub const SSIM_C1: f64 = 0.01 * 0.01;
pub const SSIM_C2: f64 = 0.03 * 0.03;

/// How the Gaussian filter treats samples outside the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Border {
    /// scipy `reflect` (d c b a | a b c d), as scikit-image.
    Reflect,
    /// Zeros outside, as INRIA's `F.conv2d(padding=5)`; self-adjoint.
    Zero,
}

/// Normalised 1D Gaussian weights, length 2·radius+1.
pub fn gaussian_kernel(sigma: f64, radius: usize) -> Vec<f64> {
    let mut k: Vec<f64> = (0..=2 * radius)
        .map(|i| {
            let x = i as f64 - radius as f64;
            (-0.5 * x * x / (sigma * sigma)).exp()
        })
        .collect();
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

fn reflect(i: isize, n: usize) -> Option<usize> {
    let n = n as isize;
    let period = 2 * n;
    let mut m = i.rem_euclid(period);
    if m >= n {
        m = period - 1 - m;
    }
    Some(m as usize)
}

fn sample(i: isize, n: usize, border: Border) -> Option<usize> {
    match border {
        Border::Reflect => reflect(i, n),
        Border::Zero => (i >= 0 && (i as usize) < n).then_some(i as usize),
    }
}

/// Separable Gaussian filter of a single-channel `w×h` image: a pass along
/// the rows, then one along the columns.
pub fn gaussian_filter(img: &[f64], w: usize, h: usize, k: &[f64], border: Border) -> Vec<f64> {
    let rows = filter_pass(img, w, h, k, border, Axis::X);
    filter_pass(&rows, w, h, k, border, Axis::Y)
}

/// The image axis a 1D filter pass runs along.
#[derive(Clone, Copy, PartialEq)]
enum Axis {
    X,
    Y,
}

/// One 1D pass of the kernel `k` (centred) over a `w×h` image along `axis`.
fn filter_pass(img: &[f64], w: usize, h: usize, k: &[f64], border: Border, axis: Axis) -> Vec<f64> {
    let r = (k.len() / 2) as isize;
    let n = if axis == Axis::X { w } else { h };
    let mut out = vec![0.0; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let i = if axis == Axis::X { x } else { y };
            let mut acc = 0.0;
            for (t, &kv) in k.iter().enumerate() {
                if let Some(j) = sample(i as isize + t as isize - r, n, border) {
                    acc += kv
                        * img[if axis == Axis::X {
                            y * w + j
                        } else {
                            j * w + x
                        }];
                }
            }
            *o = acc;
        }
    });
    out
}

/// One channel of an interleaved RGB image as f64.
pub fn channel(img: &[f32], ch: usize) -> Vec<f64> {
    img.iter().skip(ch).step_by(3).map(|&v| v as f64).collect()
}

/// The SSIM statistics of one channel: (μx, μy, E[x²], E[y²], E[xy]).
pub struct SsimStats {
    pub mx: Vec<f64>,
    pub my: Vec<f64>,
    pub exx: Vec<f64>,
    pub eyy: Vec<f64>,
    pub exy: Vec<f64>,
}

/// Filtered moments of two single-channel images.
pub fn ssim_stats(x: &[f64], y: &[f64], w: usize, h: usize, border: Border) -> SsimStats {
    let k = gaussian_kernel(SSIM_SIGMA, SSIM_RADIUS);
    let prod = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).collect::<Vec<_>>();
    SsimStats {
        mx: gaussian_filter(x, w, h, &k, border),
        my: gaussian_filter(y, w, h, &k, border),
        exx: gaussian_filter(&prod(x, x), w, h, &k, border),
        eyy: gaussian_filter(&prod(y, y), w, h, &k, border),
        exy: gaussian_filter(&prod(x, y), w, h, &k, border),
    }
}

/// SSIM at one pixel from the filtered moments.
#[inline]
pub fn ssim_at(s: &SsimStats, i: usize) -> f64 {
    let (mx, my) = (s.mx[i], s.my[i]);
    let vx = s.exx[i] - mx * mx;
    let vy = s.eyy[i] - my * my;
    let vxy = s.exy[i] - mx * my;
    ((2.0 * mx * my + SSIM_C1) * (2.0 * vxy + SSIM_C2))
        / ((mx * mx + my * my + SSIM_C1) * (vx + vy + SSIM_C2))
}

/// Mean SSIM of two RGB images (`w×h×3`, values in [0, 1]) as scikit-image
/// computes it; with `mask` (`w×h`, > 0.5 = keep) only kept pixels inside the
/// cropped region count. `None` when no pixel counts (image smaller than
/// 11×11 or everything masked).
pub fn ssim(a: &[f32], b: &[f32], w: usize, h: usize, mask: Option<&[f32]>) -> Option<f64> {
    if a.len() != w * h * 3 || b.len() != w * h * 3 || w <= 2 * SSIM_RADIUS || h <= 2 * SSIM_RADIUS
    {
        return None;
    }
    let p = SSIM_RADIUS;
    let mut total = 0.0;
    let mut count = 0usize;
    for ch in 0..3 {
        let s = ssim_stats(&channel(a, ch), &channel(b, ch), w, h, Border::Reflect);
        for y in p..h - p {
            for x in p..w - p {
                let i = y * w + x;
                if mask.is_none_or(|m| m[i] > 0.5) {
                    total += ssim_at(&s, i);
                    count += 1;
                }
            }
        }
    }
    (count > 0).then(|| total / count as f64)
}

/// PSNR (dB, data range 1) over the kept pixels (`mask` > 0.5) or all;
/// `None` when nothing is kept. Identical images give +∞.
pub fn psnr(a: &[f32], b: &[f32], mask: Option<&[f32]>) -> Option<f64> {
    if a.len() != b.len() || !a.len().is_multiple_of(3) {
        return None;
    }
    let mut se = 0.0f64;
    let mut n = 0usize;
    for (i, (pa, pb)) in a.chunks_exact(3).zip(b.chunks_exact(3)).enumerate() {
        if mask.is_none_or(|m| m.get(i).is_some_and(|&v| v > 0.5)) {
            for c in 0..3 {
                let d = pa[c] as f64 - pb[c] as f64;
                se += d * d;
            }
            n += 3;
        }
    }
    (n > 0).then(|| 10.0 * (1.0 / (se / n as f64)).log10())
}
