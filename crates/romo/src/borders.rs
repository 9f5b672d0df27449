//! Bars at the frame's edges (a 4:3 video pillarboxed in 16:9, a film
//! letterboxed, a phone's portrait video padded to landscape): strips of
//! one uniform colour that stay in every frame.
//!
//! They are not part of the scene and they spoil its geometry: their flow
//! is interpolated from the content beside them, near zero, and a pair's
//! fundamental matrix can explain both it and the scene's motion, so it
//! absorbs the movers too (car-roundabout pillarboxed: every pair scored by
//! F, U 0.6% of the frame instead of 3.7%, J 0.27 against 0.86;
//! `docs/results.md`). [`detect`] finds them; the mask stage segments the
//! frames cropped to what lies between them and masks the bars (0, left
//! out of COLMAP's features and of the training loss, as content fixed in
//! the image is). A video without bars is segmented as before.

use crate::plane::{Plane, Rgb};

/// A column or row is uniform when all its values, in all channels, lie
/// within this of each other, and constant when its mean moves less than
/// this between the frames sampled (intensity in [0, 1]: 4 grey levels of
/// 255, above a video codec's ringing in a flat bar).
const TOLERANCE: f32 = 4.0 / 255.0;

/// Bars narrower than this share of the frame's side are ignored (a dark
/// edge of the picture, not padding).
const MIN_SHARE: f32 = 0.02;

/// What is left between the bars must be at least this share of each
/// side: a frame uniform almost everywhere is flat, not padded.
const MIN_CONTENT: f32 = 0.5;

/// Widths of the bars at each edge, in px of the frames given to
/// [`detect`]; all zero when there are none.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Borders {
    /// Columns at the left edge.
    pub left: usize,
    /// Columns at the right edge.
    pub right: usize,
    /// Rows at the top edge.
    pub top: usize,
    /// Rows at the bottom edge.
    pub bottom: usize,
}

impl Borders {
    /// True when there are no bars.
    pub fn is_empty(&self) -> bool {
        *self == Borders::default()
    }

    /// The content's rectangle `(x, y, w, h)` in a `w × h` frame.
    pub fn content(&self, w: usize, h: usize) -> (usize, usize, usize, usize) {
        (
            self.left,
            self.top,
            w.saturating_sub(self.left + self.right),
            h.saturating_sub(self.top + self.bottom),
        )
    }
}

/// Mean and spread (max − min over all channels) of column `x` of `f`,
/// or of row `x` when `row`.
fn line_stats(f: &Rgb, x: usize, row: bool) -> (f32, f32) {
    let (w, h) = (f.w(), f.h());
    let (mut lo, mut hi, mut sum, mut n) = (f32::MAX, f32::MIN, 0.0f64, 0usize);
    let len = if row { w } else { h };
    for c in &f.c {
        for k in 0..len {
            let v = if row {
                c.data[x * w + k]
            } else {
                c.data[k * w + x]
            };
            lo = lo.min(v);
            hi = hi.max(v);
            sum += f64::from(v);
            n += 1;
        }
    }
    ((sum / n.max(1) as f64) as f32, hi - lo)
}

/// How many lines from one edge are bars in every frame: uniform in each
/// frame and at the same mean in all. `lines` yields the line indices from
/// the edge inwards.
fn bar_lines(frames: &[Rgb], lines: impl Iterator<Item = usize>, row: bool) -> usize {
    let mut n = 0;
    for x in lines {
        let stats: Vec<(f32, f32)> = frames.iter().map(|f| line_stats(f, x, row)).collect();
        let (lo, hi) = stats.iter().fold((f32::MAX, f32::MIN), |(a, b), (m, _)| {
            (a.min(*m), b.max(*m))
        });
        if stats.iter().any(|(_, spread)| *spread > TOLERANCE) || hi - lo > TOLERANCE {
            break;
        }
        n += 1;
    }
    n
}

/// The bars of frames of one size (a sample of a video's frames is
/// enough); none when the frames disagree in size, the bars are too
/// narrow, or too little is left between them.
pub fn detect(frames: &[Rgb]) -> Borders {
    let Some(first) = frames.first() else {
        return Borders::default();
    };
    let (w, h) = (first.w(), first.h());
    if w < 8 || h < 8 || frames.iter().any(|f| f.w() != w || f.h() != h) {
        return Borders::default();
    }
    let keep = |n: usize, side: usize| {
        if (n as f32) < MIN_SHARE * side as f32 {
            0
        } else {
            n
        }
    };
    let b = Borders {
        left: keep(bar_lines(frames, 0..w, false), w),
        right: keep(bar_lines(frames, (0..w).rev(), false), w),
        top: keep(bar_lines(frames, 0..h, true), h),
        bottom: keep(bar_lines(frames, (0..h).rev(), true), h),
    };
    let (_, _, cw, ch) = b.content(w, h);
    if (cw as f32) < MIN_CONTENT * w as f32 || (ch as f32) < MIN_CONTENT * h as f32 {
        return Borders::default();
    }
    b
}

/// `f` cropped to the content's rectangle of `b`.
pub fn crop(f: &Rgb, b: &Borders) -> Rgb {
    let (x0, y0, cw, ch) = b.content(f.w(), f.h());
    let w = f.w();
    Rgb {
        c: [0, 1, 2].map(|k| Plane::from_fn(cw, ch, |x, y| f.c[k].data[(y0 + y) * w + x0 + x])),
    }
}

/// `p` (the content's size) placed in a `w × h` plane whose bars are
/// `fill`.
pub fn paste(p: &Plane, b: &Borders, (w, h): (usize, usize), fill: f32) -> Plane {
    let (x0, y0, cw, ch) = b.content(w, h);
    Plane::from_fn(w, h, |x, y| {
        if x >= x0 && x < x0 + cw && y >= y0 && y < y0 + ch {
            p.at(
                (x - x0).min(p.w.saturating_sub(1)),
                (y - y0).min(p.h.saturating_sub(1)),
            )
        } else {
            fill
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A textured 100 × 60 frame with black bars of 12 px at left and
    /// right and of 4 px at the top.
    fn padded(t: usize) -> Rgb {
        let v = |x: usize, y: usize| {
            if !(12..88).contains(&x) || y < 4 {
                0.0
            } else {
                0.3 + 0.4 * (((x * 7 + y * 13 + t * 5) % 17) as f32 / 16.0)
            }
        };
        Rgb {
            c: [
                Plane::from_fn(100, 60, v),
                Plane::from_fn(100, 60, v),
                Plane::from_fn(100, 60, v),
            ],
        }
    }

    #[test]
    fn pillarbox_and_letterbox_bars_are_found_and_cropped() {
        let frames: Vec<Rgb> = (0..4).map(padded).collect();
        let b = detect(&frames);
        assert_eq!(
            b,
            Borders {
                left: 12,
                right: 12,
                top: 4,
                bottom: 0
            }
        );
        let c = crop(&frames[1], &b);
        assert_eq!((c.w(), c.h()), (76, 56));
        assert_eq!(c.c[0].at(0, 0), frames[1].c[0].at(12, 4));
        let p = paste(&c.c[0], &b, (100, 60), 1.0);
        assert_eq!(p.at(5, 30), 1.0);
        assert_eq!(p.at(50, 2), 1.0);
        assert_eq!(p.at(50, 30), frames[1].c[0].at(50, 30));
    }

    /// Textured edges, a dark edge that changes between frames, and a frame
    /// uniform almost everywhere have no bars.
    #[test]
    fn no_bars_in_textured_changing_or_flat_frames() {
        let textured = |t: usize| {
            let p = Plane::from_fn(100, 60, move |x, y| {
                ((x * 3 + y * 5 + t) % 11) as f32 / 10.0
            });
            Rgb {
                c: [p.clone(), p.clone(), p],
            }
        };
        assert!(detect(&(0..3).map(textured).collect::<Vec<_>>()).is_empty());
        // A uniform left strip whose level changes from frame to frame is
        // picture (a dark wall as the light changes), not a bar.
        let changing = |t: usize| {
            let p = Plane::from_fn(100, 60, move |x, y| {
                if x < 10 {
                    0.05 * t as f32
                } else {
                    ((x + y) % 7) as f32 / 6.0
                }
            });
            Rgb {
                c: [p.clone(), p.clone(), p],
            }
        };
        assert!(detect(&(0..3).map(changing).collect::<Vec<_>>()).is_empty());
        let flat = Rgb {
            c: [0, 1, 2].map(|_| Plane::filled(100, 60, 0.2)),
        };
        assert!(detect(&[flat.clone(), flat]).is_empty());
        assert!(detect(&[]).is_empty());
    }
}
