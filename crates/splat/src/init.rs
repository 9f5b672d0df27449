//! Initial splats (Kerbl et al. 2023 §5.1, INRIA `create_from_pcd`): one
//! isotropic splat per point with scale = sqrt(mean squared distance to its 3
//! nearest neighbours) (≥ sqrt(1e-7)), identity rotation, opacity 0.1 and SH
//! DC from the point colour (higher SH zero).
//!
//! Points come from a COLMAP model's points3D, skipping points whose
//! observations fall mostly on masked (moving) pixels, or are drawn
//! uniformly at random in the box around the camera centres grown by the
//! scene extent.

use crate::reference::sh::SH_C0;
use crate::types::{Splats, sh_coeffs};
use rand::{Rng, SeedableRng};
use std::collections::HashMap;

/// INRIA's initial opacity.
pub const INIT_OPACITY: f32 = 0.1;

/// Mean squared distance to the `k` nearest other points (grid search).
pub fn knn_mean_sq_dist(pts: &[[f32; 3]], k: usize) -> Vec<f32> {
    let n = pts.len();
    if n <= 1 {
        return vec![1e-2; n];
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in pts {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let vol: f32 = (0..3).map(|a| (hi[a] - lo[a]).max(1e-6)).product();
    // About 2 points per cell.
    let maxdim = (0..3).map(|a| hi[a] - lo[a]).fold(0.0f32, f32::max);
    // Not finer than 1/256 of the largest side, so degenerate (flat or
    // linear) point sets cannot make the shell search crawl.
    let cell = (vol * 2.0 / n as f32).cbrt().max(maxdim / 256.0).max(1e-6);
    let max_r = (maxdim / cell).ceil() as i64 + 1;
    let key =
        |p: &[f32; 3]| -> [i64; 3] { [0, 1, 2].map(|a| ((p[a] - lo[a]) / cell).floor() as i64) };
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    for (i, p) in pts.iter().enumerate() {
        grid.entry(key(p)).or_default().push(i as u32);
    }
    use rayon::prelude::*;
    pts.par_iter()
        .enumerate()
        .map(|(i, p)| {
            let c = key(p);
            let mut best: Vec<f32> = Vec::with_capacity(k + 1);
            let mut r = 0i64;
            loop {
                // Visit the shell of cells at Chebyshev distance r.
                for dx in -r..=r {
                    for dy in -r..=r {
                        for dz in -r..=r {
                            if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                                continue;
                            }
                            if let Some(v) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                                for &j in v {
                                    if j as usize == i {
                                        continue;
                                    }
                                    let q = &pts[j as usize];
                                    let d =
                                        (0..3).map(|a| (p[a] - q[a]) * (p[a] - q[a])).sum::<f32>();
                                    if best.len() < k {
                                        best.push(d);
                                        best.sort_by(f32::total_cmp);
                                    } else if d < best[k - 1] {
                                        best[k - 1] = d;
                                        best.sort_by(f32::total_cmp);
                                    }
                                }
                            }
                        }
                    }
                }
                // Everything within r·cell of p has been seen.
                let reach = r as f32 * cell;
                if (best.len() == k && best[k - 1] <= reach * reach)
                    || best.len() == n - 1
                    || r > max_r
                {
                    break;
                }
                r += 1;
            }
            (best.iter().sum::<f32>() / best.len().max(1) as f32).max(1e-7)
        })
        .collect()
}

/// Splats from points with 8-bit colours, INRIA style, at SH `degree`.
pub fn splats_from_points(points: &[[f32; 3]], colors: &[[f32; 3]], degree: u32) -> Splats {
    let d2 = knn_mean_sq_dist(points, 3);
    let k3 = sh_coeffs(degree) * 3;
    let mut sh = vec![0.0f32; points.len() * k3];
    for (i, c) in colors.iter().enumerate() {
        for ch in 0..3 {
            sh[i * k3 + ch] = ((c[ch] as f64 - 0.5) / SH_C0) as f32;
        }
    }
    let l = (INIT_OPACITY / (1.0 - INIT_OPACITY)).ln();
    Splats {
        means: points.to_vec(),
        log_scales: d2.iter().map(|&d| [0.5 * d.ln(); 3]).collect(),
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; points.len()],
        opacity_logits: vec![l; points.len()],
        sh,
        sh_degree: degree,
    }
}

/// A point observed by images: world position, colour in [0, 1], and for
/// each observation whether it falls on a masked (moving) pixel.
#[derive(Debug, Clone)]
pub struct ObservedPoint {
    pub xyz: [f32; 3],
    pub rgb: [f32; 3],
    /// Observations that were checked against a mask.
    pub checked: u32,
    /// Of those, how many were on moving pixels.
    pub on_moving: u32,
}

/// Keep the points whose checked observations are not mostly (more than
/// `max_moving_fraction`) on moving pixels; returns (kept, skipped).
pub fn filter_points(
    points: &[ObservedPoint],
    max_moving_fraction: f32,
) -> (Vec<&ObservedPoint>, usize) {
    let kept: Vec<&ObservedPoint> = points
        .iter()
        .filter(|p| {
            p.checked == 0 || (p.on_moving as f32) <= max_moving_fraction * p.checked as f32
        })
        .collect();
    let skipped = points.len() - kept.len();
    (kept, skipped)
}

/// `n` random splats uniformly in the axis-aligned box around `centers`
/// grown by `extent` on every side, random colours, seeded.
pub fn random_splats(
    centers: &[[f32; 3]],
    extent: f32,
    n: usize,
    degree: u32,
    seed: u64,
) -> Splats {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for c in centers {
        for a in 0..3 {
            lo[a] = lo[a].min(c[a] - extent);
            hi[a] = hi[a].max(c[a] + extent);
        }
    }
    if centers.is_empty() {
        lo = [-extent; 3];
        hi = [extent; 3];
    }
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let pts: Vec<[f32; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|a| rng.random_range(lo[a]..=hi[a])))
        .collect();
    let cols: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            [
                rng.random::<f32>(),
                rng.random::<f32>(),
                rng.random::<f32>(),
            ]
        })
        .collect();
    splats_from_points(&pts, &cols, degree)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knn_matches_brute_force() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let pts: Vec<[f32; 3]> = (0..400)
            .map(|i| {
                let s = if i % 3 == 0 { 10.0 } else { 1.0 };
                [
                    rng.random::<f32>() * s,
                    rng.random::<f32>(),
                    rng.random::<f32>() * 0.1,
                ]
            })
            .collect();
        let fast = knn_mean_sq_dist(&pts, 3);
        for i in 0..pts.len() {
            let mut d: Vec<f32> = (0..pts.len())
                .filter(|&j| j != i)
                .map(|j| (0..3).map(|a| (pts[i][a] - pts[j][a]).powi(2)).sum())
                .collect();
            d.sort_by(f32::total_cmp);
            let want = ((d[0] + d[1] + d[2]) / 3.0).max(1e-7);
            assert!(
                (fast[i] - want).abs() <= 1e-6 * want.max(1e-3),
                "{i}: {} vs {want}",
                fast[i]
            );
        }
    }

    #[test]
    fn init_colours_and_masked_points() {
        let s = splats_from_points(
            &[[0.0; 3], [1.0, 0.0, 0.0]],
            &[[1.0, 0.5, 0.0], [0.2, 0.2, 0.2]],
            1,
        );
        assert_eq!(s.sh.len(), 2 * 12);
        // colour = 0.5 + C0·dc reproduces the point colour.
        assert!(((0.5 + SH_C0 as f32 * s.sh[0]) - 1.0).abs() < 1e-6);
        assert!((0.5 + SH_C0 as f32 * s.sh[2]).abs() < 1e-6);
        assert!((s.log_scales[0][0] - 0.0).abs() < 1e-6);
        let pts = vec![
            ObservedPoint {
                xyz: [0.0; 3],
                rgb: [0.0; 3],
                checked: 4,
                on_moving: 3,
            },
            ObservedPoint {
                xyz: [0.0; 3],
                rgb: [0.0; 3],
                checked: 4,
                on_moving: 2,
            },
            ObservedPoint {
                xyz: [0.0; 3],
                rgb: [0.0; 3],
                checked: 0,
                on_moving: 0,
            },
        ];
        let (kept, skipped) = filter_points(&pts, 0.5);
        assert_eq!((kept.len(), skipped), (2, 1));
    }
}
