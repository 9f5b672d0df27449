//! Reference backward of the tile rasterizer (INRIA `backward.cu`
//! `renderCUDA`), generic over f32/f64: per pixel, walk the tile list in
//! reverse from the last contributor, recovering T_i = T_{i+1}/(1−α_i), and
//!
//! dC/dα_i = T_i·(c_i − C_behind,i) − T_final/(1−α_i)·background,
//! C_behind,i = α_{i+1}·c_{i+1} + (1−α_{i+1})·C_behind,i+1,
//!
//! then through α = o·G, G = exp(power) to mean2d, conic and opacity. Where α
//! was clamped at 0.99 the true derivative w.r.t. o and G is zero and so is
//! the gradient here (as gsplat; INRIA ignores the clamp).
//!
//! Accumulation is deterministic: each tile accumulates into slots parallel
//! to its list, then tiles are summed into the splats in tile order.

use super::project::ProjectedT;
use super::rasterize::{ALPHA_MAX, alpha_at};
use super::real::Real;
use crate::types::{
    ProjectedGrads, ProjectedSplat, RasterOutput, RenderCamera, RenderOptions, TILE_SIZE,
};
use rayon::prelude::*;

/// Gradients of one projected splat in precision `T`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ProjGradT<T> {
    pub mean2d: [T; 2],
    pub conic: [T; 3],
    pub opacity: T,
    pub color: [T; 3],
}

impl<T: Real> ProjGradT<T> {
    fn add(&mut self, o: &Self) {
        for k in 0..2 {
            self.mean2d[k] += o.mean2d[k];
        }
        for k in 0..3 {
            self.conic[k] += o.conic[k];
            self.color[k] += o.color[k];
        }
        self.opacity += o.opacity;
    }
}

impl From<ProjGradT<f32>> for ProjectedGrads {
    fn from(g: ProjGradT<f32>) -> Self {
        ProjectedGrads {
            mean2d: g.mean2d,
            conic: g.conic,
            opacity: g.opacity,
            color: g.color,
            ..Default::default()
        }
    }
}

impl From<&ProjectedGrads> for ProjGradT<f32> {
    fn from(g: &ProjectedGrads) -> Self {
        ProjGradT {
            mean2d: g.mean2d,
            conic: g.conic,
            opacity: g.opacity,
            color: g.color,
        }
    }
}

/// What the backward pass needs from the forward raster.
#[derive(Debug, Clone, Copy)]
pub struct RasterRef<'a, T> {
    pub final_transmittance: &'a [T],
    pub last_contrib: &'a [u32],
    pub tile_ranges: &'a [[u32; 2]],
    pub tile_splats: &'a [u32],
}

/// Backward in precision `T`; `v_image` is dL/d image (RGB, row-major).
pub fn rasterize_backward_t<T: Real>(
    proj: &[ProjectedT<T>],
    raster: RasterRef<'_, T>,
    cam: &RenderCamera,
    opts: &RenderOptions,
    v_image: &[T],
) -> Vec<ProjGradT<T>> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let grid = cam.tile_grid();
    let bg = opts.background.map(T::f);
    let ts = TILE_SIZE as usize;
    let one = T::c(1.0);
    let z0 = T::default();
    let per_tile: Vec<Vec<ProjGradT<T>>> = (0..raster.tile_ranges.len())
        .into_par_iter()
        .map(|t| {
            let (tx, ty) = (t % grid.0 as usize, t / grid.0 as usize);
            let rg = raster.tile_ranges[t];
            let list = &raster.tile_splats[rg[0] as usize..rg[1] as usize];
            let mut acc = vec![ProjGradT::<T>::default(); list.len()];
            if list.is_empty() {
                return acc;
            }
            for y in ty * ts..((ty + 1) * ts).min(h) {
                for x in tx * ts..((tx + 1) * ts).min(w) {
                    let pix = y * w + x;
                    let v_pix = [v_image[pix * 3], v_image[pix * 3 + 1], v_image[pix * 3 + 2]];
                    let t_final = raster.final_transmittance[pix];
                    let bg_dot = bg[0] * v_pix[0] + bg[1] * v_pix[1] + bg[2] * v_pix[2];
                    let (px, py) = (T::c(x as f64 + 0.5), T::c(y as f64 + 0.5));
                    let mut tr = t_final;
                    let mut behind = [z0; 3];
                    let mut last_alpha = z0;
                    let mut last_color = [z0; 3];
                    let last = raster.last_contrib[pix] as usize;
                    for k in (0..last.min(list.len())).rev() {
                        let s = &proj[list[k] as usize];
                        let Some((alpha, g, dx, dy)) = alpha_at(s, px, py) else {
                            continue;
                        };
                        tr /= one - alpha;
                        let a = &mut acc[k];
                        let mut v_alpha = z0;
                        for ch in 0..3 {
                            behind[ch] =
                                last_alpha * last_color[ch] + (one - last_alpha) * behind[ch];
                            last_color[ch] = s.color[ch];
                            v_alpha += (s.color[ch] - behind[ch]) * v_pix[ch];
                            a.color[ch] += alpha * tr * v_pix[ch];
                        }
                        v_alpha *= tr;
                        last_alpha = alpha;
                        v_alpha += -t_final / (one - alpha) * bg_dot;
                        if s.opacity * g >= T::c(ALPHA_MAX) {
                            continue;
                        }
                        a.opacity += g * v_alpha;
                        let v_g = s.opacity * v_alpha;
                        // power = −½(a dx² + c dy²) − b dx dy; G = exp(power).
                        let v_power = g * v_g;
                        let dp_ddx = -(s.conic[0] * dx + s.conic[1] * dy);
                        let dp_ddy = -(s.conic[2] * dy + s.conic[1] * dx);
                        a.mean2d[0] += v_power * dp_ddx;
                        a.mean2d[1] += v_power * dp_ddy;
                        a.conic[0] += v_power * (-T::c(0.5) * dx * dx);
                        a.conic[1] += v_power * (-dx * dy);
                        a.conic[2] += v_power * (-T::c(0.5) * dy * dy);
                    }
                }
            }
            acc
        })
        .collect();
    let mut out = vec![ProjGradT::<T>::default(); proj.len()];
    for (t, acc) in per_tile.iter().enumerate() {
        let rg = raster.tile_ranges[t];
        let list = &raster.tile_splats[rg[0] as usize..rg[1] as usize];
        for (k, g) in acc.iter().enumerate() {
            out[list[k] as usize].add(g);
        }
    }
    out
}

/// Backward of [`super::rasterize::rasterize`] (f32), the reference for the GPU
/// `rasterize_backward` kernel.
pub fn rasterize_backward(
    proj: &[ProjectedSplat],
    raster: &RasterOutput,
    cam: &RenderCamera,
    opts: &RenderOptions,
    v_image: &[f32],
) -> Vec<ProjectedGrads> {
    let p: Vec<ProjectedT<f32>> = proj.iter().map(ProjectedT::from).collect();
    let r = RasterRef {
        final_transmittance: &raster.final_transmittance,
        last_contrib: &raster.last_contrib,
        tile_ranges: &raster.tile_ranges,
        tile_splats: &raster.tile_splats,
    };
    rasterize_backward_t(&p, r, cam, opts, v_image)
        .into_iter()
        .map(ProjectedGrads::from)
        .collect()
}
