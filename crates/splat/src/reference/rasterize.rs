//! Reference tile rasterizer (Kerbl et al. 2023 §6, INRIA `forward.cu`
//! `renderCUDA`), generic over f32/f64.
//!
//! Binning: a splat with radius > 0, mean m and per-axis tile extents e
//! (opacity-aware, see `reference::project`) is a candidate for the tiles
//! `[floor((m−e)/16), ceil((m+e)/16))` on each axis, clamped to the grid
//! ([`tile_rect`]); extent 0 = none. Of those it touches the tiles whose
//! pixel-centre rectangle meets its ellipse d·conic·d ≤ k², k = min(3,
//! sqrt(2 ln(255 o))) — the ellipse whose bounding box the extents are
//! ([`tile_k2`], [`tile_hit`]: an exact minimum over the rectangle). The GPU binning
//! kernels mirror both in f32. Each tile's list is sorted by (depth, splat
//! index) — what a stable radix sort on the depth bits of index-ordered keys
//! produces.
//!
//! Compositing per pixel centre p = (x+0.5, y+0.5), front to back over the
//! tile list: d = mean2d − p, power = −½(a dx² + c dy²) − b dx dy; skip when
//! power > 0; α = min(0.99, o·exp(power)); skip when α < 1/255; stop
//! (without contributing) when T·(1−α) < 1e-4; C += c·α·T, T ·= 1−α. Finally
//! C += T·background.

use super::project::ProjectedT;
use super::real::Real;
use crate::types::{ProjectedSplat, RasterOutput, RenderCamera, RenderOptions, TILE_SIZE};
use rayon::prelude::*;

/// α is clamped to this from above.
pub const ALPHA_MAX: f64 = 0.99;
/// α below this is skipped.
pub const ALPHA_MIN: f64 = 1.0 / 255.0;
/// Compositing stops when the next transmittance would fall below this.
pub const T_MIN: f64 = 1e-4;

/// Tiles `[x0, y0, x1, y1)` touched by a splat of radius `radius` (0 =
/// culled) and tile extents `extent` (pixels per axis); `None` when empty.
pub fn tile_rect(
    mean2d: [f32; 2],
    radius: f32,
    extent: [f32; 2],
    grid: (u32, u32),
) -> Option<[u32; 4]> {
    if !(radius > 0.0 && extent[0] > 0.0 && extent[1] > 0.0) {
        return None;
    }
    let ts = TILE_SIZE as f32;
    let lo = |v: f32, n: u32| (v / ts).floor().clamp(0.0, n as f32) as u32;
    let hi = |v: f32, n: u32| (v / ts).ceil().clamp(0.0, n as f32) as u32;
    let r = [
        lo(mean2d[0] - extent[0], grid.0),
        lo(mean2d[1] - extent[1], grid.1),
        hi(mean2d[0] + extent[0], grid.0),
        hi(mean2d[1] + extent[1], grid.1),
    ];
    (r[2] > r[0] && r[3] > r[1]).then_some(r)
}

/// The squared Mahalanobis radius k² = min(9, 2 ln(255 o)) within which a
/// splat of opacity `o` reaches α ≥ 1/255 (3σ cap, as the tile extents);
/// −1 (no tile) when 255·o ≤ 1. `tile_k2` in `common.wgsl`.
pub fn tile_k2(o: f32) -> f32 {
    let th = 255.0 * o;
    if !(th > 1.0) {
        return -1.0;
    }
    (2.0 * th.ln()).min(9.0)
}

/// Whether a splat with 2D mean `mean` and conic (a, b, c) reaches
/// d·conic·d ≤ `k2` ([`tile_k2`]) at some point of tile `(tx, ty)`'s
/// pixel-centre rectangle. Exact: when the mean lies outside the rectangle
/// the minimum of the (convex) quadratic lies on an edge that faces the mean,
/// and on each such edge it is the clamped 1D minimum. All f32, in the
/// operation order of `tile_hit` in `common.wgsl`.
pub fn tile_hit(mean: [f32; 2], conic: [f32; 3], k2: f32, tile: (u32, u32)) -> bool {
    let ts = TILE_SIZE as f32;
    let lo = [tile.0 as f32 * ts + 0.5, tile.1 as f32 * ts + 0.5];
    let hi = [lo[0] + (ts - 1.0), lo[1] + (ts - 1.0)];
    let [a, b, c] = conic;
    let near = [mean[0].clamp(lo[0], hi[0]), mean[1].clamp(lo[1], hi[1])];
    if near[0] == mean[0] && near[1] == mean[1] {
        return k2 >= 0.0;
    }
    let q = |dx: f32, dy: f32| a * dx * dx + 2.0 * b * dx * dy + c * dy * dy;
    let mut best = f32::MAX;
    if near[0] != mean[0] {
        let dx = near[0] - mean[0];
        let dy = (-b * dx / c).clamp(lo[1] - mean[1], hi[1] - mean[1]);
        best = best.min(q(dx, dy));
    }
    if near[1] != mean[1] {
        let dy = near[1] - mean[1];
        let dx = (-b * dy / a).clamp(lo[0] - mean[0], hi[0] - mean[0]);
        best = best.min(q(dx, dy));
    }
    best <= k2
}

/// Per-tile depth-sorted lists: (`tile_ranges`, `tile_splats`).
pub fn bin<T: Real>(proj: &[ProjectedT<T>], cam: &RenderCamera) -> (Vec<[u32; 2]>, Vec<u32>) {
    let grid = cam.tile_grid();
    let n_tiles = (grid.0 * grid.1) as usize;
    // Each splat's touched tiles, in row-major order.
    let touched: Vec<Vec<u32>> = proj
        .par_iter()
        .map(|p| {
            let mean = p.mean2d.map(T::to_f32);
            let Some(r) = tile_rect(mean, p.radius.to_f32(), p.extent.map(T::to_f32), grid) else {
                return Vec::new();
            };
            let (conic, k2) = (p.conic.map(T::to_f32), tile_k2(p.opacity.to_f32()));
            (r[1]..r[3])
                .flat_map(|ty| (r[0]..r[2]).map(move |tx| (tx, ty)))
                .filter(|&t| tile_hit(mean, conic, k2, t))
                .map(|(tx, ty)| ty * grid.0 + tx)
                .collect()
        })
        .collect();
    let mut counts = vec![0u32; n_tiles + 1];
    for &t in touched.iter().flatten() {
        counts[t as usize + 1] += 1;
    }
    for t in 0..n_tiles {
        counts[t + 1] += counts[t];
    }
    let mut fill = counts.clone();
    let mut splats = vec![0u32; counts[n_tiles] as usize];
    for (i, tiles) in touched.iter().enumerate() {
        for &t in tiles {
            splats[fill[t as usize] as usize] = i as u32;
            fill[t as usize] += 1;
        }
    }
    let ranges: Vec<[u32; 2]> = (0..n_tiles).map(|t| [counts[t], counts[t + 1]]).collect();
    // Stable sort by depth within each tile keeps index order on ties.
    let mut chunks: Vec<&mut [u32]> = Vec::with_capacity(n_tiles);
    let mut rest: &mut [u32] = &mut splats;
    for r in &ranges {
        let (a, b) = rest.split_at_mut((r[1] - r[0]) as usize);
        chunks.push(a);
        rest = b;
    }
    chunks.into_par_iter().for_each(|c| {
        c.sort_by(|&a, &b| {
            proj[a as usize]
                .depth
                .partial_cmp(&proj[b as usize].depth)
                .unwrap_or(std::cmp::Ordering::Equal)
        })
    });
    (ranges, splats)
}

/// One pixel's result: (pixel index, colour, final T, last contributor).
type PixelOut<T> = (usize, [T; 3], T, u32);

/// Raster output in precision `T`.
#[derive(Debug, Clone, Default)]
pub struct RasterT<T> {
    pub image: Vec<T>,
    pub final_transmittance: Vec<T>,
    pub last_contrib: Vec<u32>,
    pub tile_ranges: Vec<[u32; 2]>,
    pub tile_splats: Vec<u32>,
}

/// Gaussian falloff exponent at pixel centre `p`; `None` when skipped.
#[inline]
pub fn alpha_at<T: Real>(s: &ProjectedT<T>, px: T, py: T) -> Option<(T, T, T, T)> {
    let dx = s.mean2d[0] - px;
    let dy = s.mean2d[1] - py;
    let power = -T::c(0.5) * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) - s.conic[1] * dx * dy;
    if power > T::default() {
        return None;
    }
    let g = power.exp();
    let alpha = (s.opacity * g).min(T::c(ALPHA_MAX));
    if alpha < T::c(ALPHA_MIN) {
        return None;
    }
    Some((alpha, g, dx, dy))
}

/// Rasterize in precision `T`.
pub fn rasterize_t<T: Real>(
    proj: &[ProjectedT<T>],
    cam: &RenderCamera,
    opts: &RenderOptions,
) -> RasterT<T> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let grid = cam.tile_grid();
    let (tile_ranges, tile_splats) = bin(proj, cam);
    let bg = opts.background.map(T::f);
    let ts = TILE_SIZE as usize;
    // Each tile returns (pixel index, colour, T, last) for its pixels.
    let tiles: Vec<Vec<PixelOut<T>>> = (0..tile_ranges.len())
        .into_par_iter()
        .map(|t| {
            let (tx, ty) = (t % grid.0 as usize, t / grid.0 as usize);
            let list = &tile_splats[tile_ranges[t][0] as usize..tile_ranges[t][1] as usize];
            let mut out = Vec::with_capacity(ts * ts);
            for y in ty * ts..((ty + 1) * ts).min(h) {
                for x in tx * ts..((tx + 1) * ts).min(w) {
                    let (px, py) = (T::c(x as f64 + 0.5), T::c(y as f64 + 0.5));
                    let mut c = [T::default(); 3];
                    let mut tr = T::c(1.0);
                    let mut last = 0u32;
                    for (k, &si) in list.iter().enumerate() {
                        let s = &proj[si as usize];
                        let Some((alpha, ..)) = alpha_at(s, px, py) else {
                            continue;
                        };
                        let next = tr * (T::c(1.0) - alpha);
                        if next < T::c(T_MIN) {
                            break;
                        }
                        for ch in 0..3 {
                            c[ch] += s.color[ch] * alpha * tr;
                        }
                        tr = next;
                        last = k as u32 + 1;
                    }
                    for ch in 0..3 {
                        c[ch] += tr * bg[ch];
                    }
                    out.push((y * w + x, c, tr, last));
                }
            }
            out
        })
        .collect();
    let mut r = RasterT {
        image: vec![T::default(); w * h * 3],
        final_transmittance: vec![T::default(); w * h],
        last_contrib: vec![0; w * h],
        tile_ranges,
        tile_splats,
    };
    for (pix, c, tr, last) in tiles.into_iter().flatten() {
        r.image[pix * 3..pix * 3 + 3].copy_from_slice(&c);
        r.final_transmittance[pix] = tr;
        r.last_contrib[pix] = last;
    }
    r
}

/// Rasterize (f32), the reference for the GPU `rasterize` kernel.
pub fn rasterize(
    proj: &[ProjectedSplat],
    cam: &RenderCamera,
    opts: &RenderOptions,
) -> RasterOutput {
    let p: Vec<ProjectedT<f32>> = proj.iter().map(ProjectedT::from).collect();
    let r = rasterize_t(&p, cam, opts);
    RasterOutput {
        width: cam.width,
        height: cam.height,
        image: r.image,
        final_transmittance: r.final_transmittance,
        last_contrib: r.last_contrib,
        tile_ranges: r.tile_ranges,
        tile_splats: r.tile_splats,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// d·conic·d at `p` for a splat at `mean`.
    fn maha(mean: [f32; 2], conic: [f32; 3], p: [f32; 2]) -> f32 {
        let (dx, dy) = (p[0] - mean[0], p[1] - mean[1]);
        conic[0] * dx * dx + 2.0 * conic[1] * dx * dy + conic[2] * dy * dy
    }

    /// A circle of radius 3σ = 6 px (k = 3 at opacity 1): the tile right of
    /// it is hit only when its first pixel-centre column is within 6 px.
    #[test]
    fn tile_hit_known_circle() {
        let conic = [0.25, 0.0, 0.25]; // σ = 2
        let k2 = tile_k2(1.0);
        assert_eq!(k2, 9.0);
        // Tile (1, 0): pixel centres x ∈ [16.5, 31.5], y ∈ [0.5, 15.5].
        assert!(tile_hit([10.6, 8.0], conic, k2, (1, 0)));
        assert!(!tile_hit([10.4, 8.0], conic, k2, (1, 0)));
        // Diagonal: corner (16.5, 16.5) of tile (1, 1) at distance 6·0.99 / 6·1.01.
        let d = 6.0 / 2f32.sqrt();
        assert!(tile_hit(
            [16.5 - 0.99 * d, 16.5 - 0.99 * d],
            conic,
            k2,
            (1, 1)
        ));
        assert!(!tile_hit(
            [16.5 - 1.01 * d, 16.5 - 1.01 * d],
            conic,
            k2,
            (1, 1)
        ));
        // Low opacity shrinks k; 255·o ≤ 1 touches nothing, not even its own tile.
        assert!(tile_k2(0.1) < 9.0);
        assert!(!tile_hit([8.0, 8.0], conic, tile_k2(1.0 / 255.0), (0, 0)));
        assert!(tile_hit([8.0, 8.0], conic, tile_k2(0.01), (0, 0)));
    }

    /// Against brute force on random anisotropic splats: every tile with a
    /// pixel centre inside the ellipse is hit, and every hit tile has a
    /// point of its pixel-centre rectangle (fine grid) inside it.
    #[test]
    fn tile_hit_matches_brute_force() {
        let mut r = rand_pcg::Pcg64::seed_from_u64(7);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..400 {
            let mean = [
                r.random_range(-10.0..74.0f32),
                r.random_range(-10.0..74.0f32),
            ];
            let (s1, s2) = (r.random_range(0.5..12.0f32), r.random_range(0.5..12.0f32));
            let th = r.random_range(0.0..std::f32::consts::PI);
            let (c, s) = (th.cos(), th.sin());
            // Σ = R diag(s1², s2²) Rᵀ, conic = Σ⁻¹.
            let (sxx, sxy, syy) = (
                c * c * s1 * s1 + s * s * s2 * s2,
                c * s * (s1 * s1 - s2 * s2),
                s * s * s1 * s1 + c * c * s2 * s2,
            );
            let det = sxx * syy - sxy * sxy;
            let conic = [syy / det, -sxy / det, sxx / det];
            let k2 = tile_k2(r.random_range(0.02..1.0f32));
            for ty in 0..4u32 {
                for tx in 0..4u32 {
                    let hit = tile_hit(mean, conic, k2, (tx, ty));
                    let x0 = (tx * 16) as f32 + 0.5;
                    let y0 = (ty * 16) as f32 + 0.5;
                    let pixel_in = (0..16).any(|j| {
                        (0..16).any(|i| maha(mean, conic, [x0 + i as f32, y0 + j as f32]) <= k2)
                    });
                    if pixel_in {
                        assert!(hit, "tile ({tx}, {ty}) mean {mean:?} conic {conic:?}");
                    }
                    if hit {
                        let fine = (0..=150).any(|j| {
                            (0..=150).any(|i| {
                                let p = [x0 + 0.1 * i as f32, y0 + 0.1 * j as f32];
                                maha(mean, conic, p) <= k2 * 1.001 + 1e-3
                            })
                        });
                        assert!(fine, "tile ({tx}, {ty}) hit but no point inside");
                        hits += 1;
                    } else {
                        misses += 1;
                    }
                }
            }
        }
        assert!(hits > 500 && misses > 500, "{hits} hits, {misses} misses");
    }
}
