//! Reference tile rasterizer (Kerbl et al. 2023 §6, INRIA `forward.cu`
//! `renderCUDA`), generic over f32/f64.
//!
//! Binning: a splat with radius > 0, mean m and per-axis tile extents e
//! (opacity-aware, see `reference::project`) touches the tiles
//! `[floor((m−e)/16), ceil((m+e)/16))` on each axis, clamped to the grid
//! ([`tile_rect`], which the GPU binning kernel mirrors); extent 0 = none. Each tile's list is
//! sorted by (depth, splat index) — what a stable radix sort on the depth
//! bits of index-ordered keys produces.
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

/// Per-tile depth-sorted lists: (`tile_ranges`, `tile_splats`).
pub fn bin<T: Real>(proj: &[ProjectedT<T>], cam: &RenderCamera) -> (Vec<[u32; 2]>, Vec<u32>) {
    let grid = cam.tile_grid();
    let n_tiles = (grid.0 * grid.1) as usize;
    let rects: Vec<Option<[u32; 4]>> = proj
        .iter()
        .map(|p| {
            tile_rect(
                p.mean2d.map(T::to_f32),
                p.radius.to_f32(),
                p.extent.map(T::to_f32),
                grid,
            )
        })
        .collect();
    let mut counts = vec![0u32; n_tiles + 1];
    for r in rects.iter().flatten() {
        for ty in r[1]..r[3] {
            for tx in r[0]..r[2] {
                counts[(ty * grid.0 + tx) as usize + 1] += 1;
            }
        }
    }
    for t in 0..n_tiles {
        counts[t + 1] += counts[t];
    }
    let mut fill = counts.clone();
    let mut splats = vec![0u32; counts[n_tiles] as usize];
    for (i, r) in rects.iter().enumerate() {
        if let Some(r) = r {
            for ty in r[1]..r[3] {
                for tx in r[0]..r[2] {
                    let t = (ty * grid.0 + tx) as usize;
                    splats[fill[t] as usize] = i as u32;
                    fill[t] += 1;
                }
            }
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
