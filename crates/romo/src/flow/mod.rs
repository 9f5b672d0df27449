//! Stage 1 of RoMo (`docs/design.md`, "The pipeline"): dense optical flow between frames.
//!
//! [`FlowEstimator`] is the seam: the built-in backend is [`dis::Dis`], a
//! Rust implementation of Dense Inverse Search (Kroeger et al., ECCV 2016)
//! with a variational refinement (Brox et al. 2004 energy, as in DIS); the
//! paper's RAFT can be plugged in through ONNX (feature `onnx`).

pub mod dis;
mod patch;
pub mod pyramid;
pub mod simd;
mod sor;
pub mod variational;

use crate::plane::Plane;
use rayon::prelude::*;

/// A dense flow field: pixel (x, y) of the first frame moves to
/// (x + u, y + v) in the second. Units: pixels of the frames' resolution.
#[derive(Debug, Clone, PartialEq)]
pub struct Flow {
    /// Horizontal displacement (px).
    pub u: Plane,
    /// Vertical displacement (px).
    pub v: Plane,
}

impl Flow {
    /// A zero field.
    pub fn zeros(w: usize, h: usize) -> Self {
        Flow {
            u: Plane::filled(w, h, 0.0),
            v: Plane::filled(w, h, 0.0),
        }
    }

    /// Width.
    pub fn w(&self) -> usize {
        self.u.w
    }

    /// Height.
    pub fn h(&self) -> usize {
        self.u.h
    }

    /// Resample to a new resolution, scaling the vectors accordingly
    /// (bilinear, pixel-centre aligned, clamped borders; box-averaged first
    /// when shrinking by more than 2×, as [`Plane::resize`]).
    pub fn resize(&self, nw: usize, nh: usize) -> Flow {
        let sx = nw as f32 / self.w() as f32;
        let sy = nh as f32 / self.h() as f32;
        if nw == self.w() && nh == self.h() {
            return self.clone();
        }
        if 2 * nw < self.w() || 2 * nh < self.h() {
            return Flow {
                u: self.u.resize(nw, nh).map(|a| a * sx),
                v: self.v.resize(nw, nh).map(|a| a * sy),
            };
        }
        let (w, h) = (self.w(), self.h());
        let (ix, iy) = (w as f32 / nw as f32, h as f32 / nh as f32);
        let mut out = Flow::zeros(nw, nh);
        out.u
            .data
            .par_chunks_mut(nw)
            .zip(out.v.data.par_chunks_mut(nw))
            .enumerate()
            .for_each(|(y, (ru, rv))| {
                let fy = ((y as f32 + 0.5) * iy - 0.5).clamp(0.0, (h - 1) as f32);
                let y0 = fy as usize;
                let ay = fy - y0 as f32;
                let y1 = (y0 + 1).min(h - 1);
                for x in 0..nw {
                    let fx = ((x as f32 + 0.5) * ix - 0.5).clamp(0.0, (w - 1) as f32);
                    let x0 = fx as usize;
                    let ax = fx - x0 as f32;
                    let x1 = (x0 + 1).min(w - 1);
                    let (a, b, c, d) = (y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1);
                    let lerp = |p: &[f32]| {
                        let top = p[a] + ax * (p[b] - p[a]);
                        let bot = p[c] + ax * (p[d] - p[c]);
                        top + ay * (bot - top)
                    };
                    ru[x] = lerp(&self.u.data) * sx;
                    rv[x] = lerp(&self.v.data) * sy;
                }
            });
        out
    }

    /// Flow vector at continuous coordinates (bilinear).
    #[inline]
    pub fn sample(&self, x: f32, y: f32) -> (f32, f32) {
        (self.u.bilinear(x, y), self.v.bilinear(x, y))
    }

    /// Mean vector length (px).
    pub fn mean_magnitude(&self) -> f32 {
        let n = self.u.data.len().max(1);
        let s: f64 = self
            .u
            .data
            .iter()
            .zip(&self.v.data)
            .map(|(a, b)| ((a * a + b * b) as f64).sqrt())
            .sum();
        (s / n as f64) as f32
    }
}

/// Mean end-point error between `est` and `gt` over pixels where `mask`
/// (if given) is true. Returns NaN when no pixel is counted.
pub fn epe(est: &Flow, gt: &Flow, mask: Option<&[bool]>) -> f64 {
    let mut s = 0.0f64;
    let mut n = 0usize;
    for i in 0..est.u.data.len() {
        if mask.is_some_and(|m| !m[i]) {
            continue;
        }
        let du = est.u.data[i] - gt.u.data[i];
        let dv = est.v.data[i] - gt.v.data[i];
        if !(gt.u.data[i].is_finite() && gt.v.data[i].is_finite()) {
            continue;
        }
        s += ((du * du + dv * dv) as f64).sqrt();
        n += 1;
    }
    if n == 0 { f64::NAN } else { s / n as f64 }
}

/// A dense optical flow method. Inputs are grayscale planes with values in
/// [0, 1] of equal size; the result has the same size.
pub trait FlowEstimator: Send + Sync {
    /// Short name for reports.
    fn name(&self) -> &str;
    /// Flow from `i0` to `i1`.
    fn flow(&self, i0: &Plane, i1: &Plane) -> crate::Result<Flow>;
}
