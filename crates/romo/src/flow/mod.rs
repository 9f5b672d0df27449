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

use crate::plane::{Plane, Rgb};
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
    /// The size the pipeline should give frames to [`Self::flow_pair`] at,
    /// for a video of `full` (w, h) whose flow resolution is `working`.
    /// Default: `working`.
    fn frame_size(&self, full: (usize, usize), working: (usize, usize)) -> (usize, usize) {
        let _ = full;
        working
    }
    /// Forward (`a` → `b`) and backward flow between two colour frames of
    /// equal size, in pixels of that size. Default: [`Self::flow`] both
    /// ways on the frames' luma.
    fn flow_pair(&self, a: &Rgb, b: &Rgb) -> crate::Result<(Flow, Flow)> {
        let (ga, gb) = (a.gray(), b.gray());
        Ok((self.flow(&ga, &gb)?, self.flow(&gb, &ga)?))
    }
}

/// Where frames go in a flow network's input: resized (aspect ratio kept)
/// to fit when they are larger than it, never enlarged, then padded at the
/// bottom and right by edge replication; the network's flow is cropped
/// back to the frames' region and rescaled to their size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Placement {
    /// The frames' size (w, h).
    pub frame: (usize, usize),
    /// The size the frames are resized to inside the input (equal to
    /// `frame` when they fit).
    pub content: (usize, usize),
    /// The network's input size (w, h).
    pub input: (usize, usize),
}

impl Placement {
    /// Into a network with a fixed input of `input` (w, h).
    pub fn fixed(frame: (usize, usize), input: (usize, usize)) -> Self {
        let (w, h) = (frame.0.max(1), frame.1.max(1));
        let s = (input.0 as f64 / w as f64)
            .min(input.1 as f64 / h as f64)
            .min(1.0);
        let side = |v: usize, limit: usize| ((v as f64 * s).round() as usize).clamp(1, limit);
        Self {
            frame: (w, h),
            content: (side(w, input.0), side(h, input.1)),
            input,
        }
    }

    /// Into a network with dynamic input sizes that must be multiples of
    /// `multiple`: padded to the next multiple.
    pub fn padded(frame: (usize, usize), multiple: usize) -> Self {
        let (w, h) = (frame.0.max(1), frame.1.max(1));
        let m = multiple.max(1);
        Self {
            frame: (w, h),
            content: (w, h),
            input: (w.div_ceil(m) * m, h.div_ceil(m) * m),
        }
    }

    /// A frame's plane (of size `frame`) as the network's input plane.
    pub fn place(&self, p: &Plane) -> Plane {
        let (cw, ch) = self.content;
        let r;
        let c = if (p.w, p.h) == (cw, ch) {
            p
        } else {
            r = p.resize(cw, ch);
            &r
        };
        if (cw, ch) == self.input {
            return c.clone();
        }
        Plane::from_fn(self.input.0, self.input.1, |x, y| {
            c.at(x.min(cw - 1), y.min(ch - 1))
        })
    }

    /// The network's flow (any size covering the whole input, in pixels
    /// of its own grid) as the flow between the frames, in their pixels.
    pub fn unplace(&self, f: &Flow) -> Flow {
        let full = f.resize(self.input.0, self.input.1);
        let (cw, ch) = self.content;
        let crop = |p: &Plane| Plane::from_fn(cw, ch, |x, y| p.at(x, y));
        Flow {
            u: crop(&full.u),
            v: crop(&full.v),
        }
        .resize(self.frame.0, self.frame.1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_fit_a_fixed_input_without_enlarging() {
        // DAVIS frames in GMFlow's 480×864 export: padded only.
        let p = Placement::fixed((854, 480), (864, 480));
        assert_eq!((p.content, p.input), ((854, 480), (864, 480)));
        // Sintel in a 288×512 export: halved, then padded at the bottom.
        let p = Placement::fixed((1024, 436), (512, 288));
        assert_eq!(p.content, (512, 218));
        // DAVIS at the mask stage's flow resolution: exact.
        assert_eq!(Placement::fixed((854, 480), (512, 288)).content, (512, 288));
        // Smaller frames are padded, never enlarged.
        assert_eq!(Placement::fixed((100, 60), (512, 288)).content, (100, 60));
        let d = Placement::padded((854, 480), 32);
        assert_eq!((d.content, d.input), ((854, 480), (864, 480)));
    }

    #[test]
    fn padding_replicates_the_last_row_and_column() {
        let p = Placement::fixed((5, 3), (8, 4));
        let src = Plane::from_fn(5, 3, |x, y| (10 * y + x) as f32);
        let out = p.place(&src);
        assert_eq!((out.w, out.h), (8, 4));
        assert_eq!(out.at(2, 1), 12.0);
        assert_eq!(out.at(7, 1), 14.0);
        assert_eq!(out.at(3, 3), 23.0);
        assert_eq!(out.at(7, 3), 24.0);
    }

    /// A constant motion of the frames, as the network sees it on its input
    /// grid (scaled with the content), comes back in the frames' pixels;
    /// values the network puts in the padding never reach the frames.
    #[test]
    fn flow_is_cropped_and_rescaled_back_to_the_frames() {
        let (du, dv) = (2.0f32, -1.0f32);
        for (frame, input, out_div) in [
            ((1024, 436), (512, 288), 1),
            ((854, 480), (512, 288), 1),
            ((854, 480), (512, 288), 8),
            ((90, 60), (96, 64), 1),
        ] {
            let p = Placement::fixed(frame, input);
            let (sx, sy) = (
                p.content.0 as f32 / frame.0 as f32,
                p.content.1 as f32 / frame.1 as f32,
            );
            let (ow, oh) = (input.0 / out_div, input.1 / out_div);
            let (cw, ch) = (p.content.0 / out_div, p.content.1 / out_div);
            let field = |d: f32, s: f32| {
                Plane::from_fn(ow, oh, |x, y| {
                    if out_div == 1 && (x >= cw || y >= ch) {
                        1e3
                    } else {
                        d * s / out_div as f32
                    }
                })
            };
            let net = Flow {
                u: field(du, sx),
                v: field(dv, sy),
            };
            let f = p.unplace(&net);
            assert_eq!((f.w(), f.h()), frame);
            for (k, d) in [(&f.u, du), (&f.v, dv)] {
                let worst = k.data.iter().map(|v| (v - d).abs()).fold(0.0f32, f32::max);
                assert!(
                    worst < 1e-3,
                    "{frame:?} in {input:?} /{out_div}: off by {worst}"
                );
            }
        }
    }
}
