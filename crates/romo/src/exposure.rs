//! Exposure normalisation: a dark or flat video is stretched to the range
//! a well-exposed one covers before segmentation.
//!
//! Several of RoMo's thresholds are in absolute grey levels of [0, 1]: the
//! texture a pixel needs before its residual counts as motion evidence
//! (`labels.u_min_gradient`, `refine.objects.texture_gradient`), the
//! photo-consistency tolerance, the colour model's histogram bins and the
//! guided filter's ε. They were set on footage whose values span most of
//! [0, 1]. An underexposed video (values in [0, 0.12]) has every gradient
//! eight times smaller: no pixel is textured enough to be U, and the masks
//! come out empty (J 0.015 against 0.86 on car-roundabout darkened so;
//! `docs/results.md`).
//!
//! [`Exposure::measure`] takes the 0.5th and 99.5th percentiles `lo`, `hi`
//! of all channel values of the video's frames. When they span less than
//! half of [0, 1] ([`STRETCH_BELOW`]), [`Exposure::apply`] maps
//! `x ↦ (x − lo)·g`, clamped to [0, 1], with the gain
//! `g = 1 / max(hi − lo, MIN_RANGE)`: one linear map for the whole video (a
//! per-frame map would flicker with content), the same for all three
//! channels. Whether a frame has any texture at all is still judged in the
//! source's grey levels ([`Exposure::gain`] scales that threshold), so a
//! black or near-uniform frame stays "no texture" however much it is
//! stretched.
//!
//! Well-exposed footage is left as it is. Stretching every video (DAVIS's
//! values span 0.71–0.99 of the range: gains 1.0–1.4) was measured and
//! gained nothing: DAVIS seeds 0–4 mean J 0.733 against 0.730, with
//! blackswan lower on every seed (0.384–0.407 against 0.398–0.427); 33
//! scene and composite runs 0.844 against 0.849 (`docs/results.md`).

use crate::plane::Rgb;
use rayon::prelude::*;

/// The smallest value range stretched to [0, 1]: at most ×16. A video whose
/// values span less (fewer than 16 grey levels of 255) is flat, not dark,
/// and stretching it further would only amplify its noise.
pub const MIN_RANGE: f32 = 1.0 / 16.0;

/// A video whose values (between the percentiles below) span less than
/// this is stretched; others are left as they are (stretching those gained
/// nothing, module doc).
pub const STRETCH_BELOW: f32 = 0.5;

/// Percentiles of the values that map to 0 and 1.
const LOW_PERCENTILE: f64 = 0.005;
const HIGH_PERCENTILE: f64 = 0.995;

/// Histogram bins over [0, 1] for the percentiles (a quarter of a grey
/// level of 255 each).
const BINS: usize = 1024;

/// One linear exposure map for a video.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exposure {
    /// The values' 0.5th percentile: mapped to 0 when the video is
    /// stretched.
    pub lo: f32,
    /// The values' 99.5th percentile: mapped to 1 when the video is
    /// stretched and `hi − lo ≥ MIN_RANGE`.
    pub hi: f32,
}

impl Default for Exposure {
    /// The identity map.
    fn default() -> Self {
        Exposure { lo: 0.0, hi: 1.0 }
    }
}

impl Exposure {
    /// The map of `frames`: their values' 0.5th and 99.5th percentiles.
    /// The identity for no frames.
    pub fn measure(frames: &[Rgb]) -> Self {
        let hist = frames
            .par_iter()
            .map(|f| {
                let mut h = vec![0u64; BINS];
                for c in &f.c {
                    for &v in &c.data {
                        let b = (v.clamp(0.0, 1.0) * (BINS - 1) as f32).round() as usize;
                        h[b] += 1;
                    }
                }
                h
            })
            .reduce(
                || vec![0u64; BINS],
                |mut a, b| {
                    a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                    a
                },
            );
        let total: u64 = hist.iter().sum();
        if total == 0 {
            return Self::default();
        }
        let value_at = |q: f64| {
            let rank = (q * total as f64).floor() as u64;
            let mut seen = 0u64;
            for (b, &n) in hist.iter().enumerate() {
                seen += n;
                if seen > rank {
                    return b as f32 / (BINS - 1) as f32;
                }
            }
            1.0
        };
        Exposure {
            lo: value_at(LOW_PERCENTILE),
            hi: value_at(HIGH_PERCENTILE),
        }
    }

    /// True when the values span less than [`STRETCH_BELOW`]: the video is
    /// stretched.
    pub fn stretches(&self) -> bool {
        self.hi - self.lo < STRETCH_BELOW
    }

    /// The map's gain: `1 / max(hi − lo, MIN_RANGE)` (2 to 16) when it
    /// [`stretches`](Self::stretches), else 1.
    pub fn gain(&self) -> f32 {
        if self.stretches() {
            1.0 / (self.hi - self.lo).max(MIN_RANGE)
        } else {
            1.0
        }
    }

    /// Map `frame` in place.
    pub fn apply(&self, frame: &mut Rgb) {
        if !self.stretches() {
            return;
        }
        let (lo, g) = (self.lo, self.gain());
        for c in &mut frame.c {
            for v in &mut c.data {
                *v = ((*v - lo) * g).clamp(0.0, 1.0);
            }
        }
    }

    /// `frame` mapped.
    pub fn applied(&self, mut frame: Rgb) -> Rgb {
        self.apply(&mut frame);
        frame
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::Plane;

    fn frame(w: usize, h: usize, f: impl Fn(usize, usize) -> f32 + Sync + Copy) -> Rgb {
        Rgb {
            c: [
                Plane::from_fn(w, h, f),
                Plane::from_fn(w, h, move |x, y| 0.5 * f(x, y)),
                Plane::from_fn(w, h, f),
            ],
        }
    }

    /// A ramp over [0.02, 0.12] is stretched to about [0, 1], its gradient
    /// ten times steeper, all channels by the same map.
    #[test]
    fn a_dark_ramp_is_stretched_to_the_full_range() {
        let dark = frame(200, 10, |x, _| 0.02 + 0.1 * x as f32 / 199.0);
        let e = Exposure::measure(std::slice::from_ref(&dark));
        // Green spans [0.01, 0.06]: the lowest values of all channels.
        assert!((e.lo - 0.01).abs() < 0.003, "{e:?}");
        assert!((e.hi - 0.12).abs() < 0.003, "{e:?}");
        let out = e.applied(dark.clone());
        let r = &out.c[0].data;
        assert!(r[0] < 0.12 && r[199] > 0.98, "{} {}", r[0], r[199]);
        let step = r[101] - r[100];
        assert!((step - 0.1 / 199.0 * e.gain()).abs() < 1e-5, "{step}");
        // One map for all channels: green over red is (0.5·r − lo) / (r − lo).
        let (gs, rs) = (&out.c[1].data, &out.c[0].data);
        for x in [50, 120, 180] {
            let want = (0.5 * dark.c[0].data[x] - e.lo) / (dark.c[0].data[x] - e.lo);
            let got = gs[x] / rs[x];
            assert!((got - want).abs() < 1e-4, "x {x}: {got} vs {want}");
        }
    }

    /// Frames spanning [0, 1], or [0.1, 0.9], are left as they are; a
    /// black frame and a flat one are stretched at most ×16.
    #[test]
    fn well_exposed_frames_are_kept_and_flat_ones_capped() {
        let full = frame(256, 4, |x, _| x as f32 / 255.0);
        let e = Exposure::measure(std::slice::from_ref(&full));
        assert!(e.lo < 0.01 && e.hi > 0.99, "{e:?}");
        assert!(!e.stretches() && e.gain() == 1.0);
        // Red and blue span [0.2, 0.9], green (half of red) [0.1, 0.45].
        let mid = frame(256, 4, |x, _| 0.2 + 0.7 * x as f32 / 255.0);
        let e = Exposure::measure(std::slice::from_ref(&mid));
        assert!(!e.stretches(), "{e:?}");
        assert_eq!(e.applied(mid.clone()).c, mid.c);
        let black = frame(16, 16, |_, _| 0.0);
        let e = Exposure::measure(std::slice::from_ref(&black));
        assert_eq!(e.gain(), 16.0);
        let out = e.applied(black.clone());
        assert!(out.c.iter().all(|c| c.data.iter().all(|v| *v == 0.0)));
        let plane = Plane::from_fn(16, 16, |x, y| 0.5 + 0.002 * ((x + y) % 2) as f32);
        let flat = Rgb {
            c: [plane.clone(), plane.clone(), plane],
        };
        assert_eq!(Exposure::measure(std::slice::from_ref(&flat)).gain(), 16.0);
        assert!(!Exposure::measure(&[]).stretches());
    }
}
