//! Stage 6 of RoMo: per-pixel features for the MLP. The paper uses SAM2's
//! image encoder; romo's built-in [`HandFeatures`] is a hand-made
//! multi-scale descriptor (colour, smoothed colour at two scales, texture,
//! position), which our prototype found about as good as XFeat's and best
//! combined with it. Neural encoders plug in through [`FeatureExtractor`]
//! (see `onnx` for XFeat / SAM2 through ONNX Runtime).

use crate::plane::{Plane, Rgb};
use rayon::prelude::*;

/// A C × h × w feature map (channel-major).
#[derive(Debug, Clone)]
pub struct FeatureMap {
    /// Channels.
    pub c: usize,
    /// Width.
    pub w: usize,
    /// Height.
    pub h: usize,
    /// `c * h * w` values, channel-major.
    pub data: Vec<f32>,
}

impl FeatureMap {
    /// Resample every channel to `w × h` (bilinear).
    pub fn resize(&self, w: usize, h: usize) -> FeatureMap {
        if w == self.w && h == self.h {
            return self.clone();
        }
        let mut data = Vec::with_capacity(self.c * w * h);
        for k in 0..self.c {
            let p = Plane {
                w: self.w,
                h: self.h,
                data: self.data[k * self.w * self.h..(k + 1) * self.w * self.h].to_vec(),
            };
            data.extend(p.resize(w, h).data);
        }
        FeatureMap {
            c: self.c,
            w,
            h,
            data,
        }
    }

    /// Pixel-major copy (`h * w` rows of `c` values), the MLP's layout.
    pub fn pixel_major(&self) -> Vec<f32> {
        let n = self.w * self.h;
        let mut out = vec![0.0; n * self.c];
        out.par_chunks_mut(self.c.max(1))
            .enumerate()
            .for_each(|(i, row)| {
                for (k, v) in row.iter_mut().enumerate() {
                    *v = self.data[k * n + i];
                }
            });
        out
    }

    /// Concatenate channels of maps of equal size.
    pub fn concat(maps: &[FeatureMap]) -> Option<FeatureMap> {
        let first = maps.first()?;
        if maps.iter().any(|m| m.w != first.w || m.h != first.h) {
            return None;
        }
        Some(FeatureMap {
            c: maps.iter().map(|m| m.c).sum(),
            w: first.w,
            h: first.h,
            data: maps.iter().flat_map(|m| m.data.iter().copied()).collect(),
        })
    }
}

/// Something that turns a frame into a feature map. The output may have any
/// resolution; the pipeline resamples it to its working grid.
pub trait FeatureExtractor: Send + Sync {
    /// Short name for reports.
    fn name(&self) -> &str;
    /// Features of one frame (RGB in [0, 1]) for a working grid of
    /// `w × h`.
    fn extract(&self, frame: &Rgb, w: usize, h: usize) -> crate::Result<FeatureMap>;
}

/// The built-in descriptor, 14 (16) channels at the working grid:
/// RGB (3), RGB Gaussian-smoothed with σ = 2 and σ = 6 grid px (6),
/// gradient magnitude of luma at the grid and at twice its resolution (2),
/// local standard deviation of luma in a 5 × 5 window (1), and normalised
/// position x/w, y/h (2).
///
/// With `chromaticity` (the pipeline's default) two more channels, 16 in
/// all, placed before the position: r/(r+g+b) and g/(r+g+b) smoothed with
/// σ = 1 grid px (colour independent of shading; see README for the DAVIS
/// measurement).
#[derive(Debug, Clone, Default)]
pub struct HandFeatures {
    /// Add the two chromaticity channels.
    pub chromaticity: bool,
}

impl FeatureExtractor for HandFeatures {
    fn name(&self) -> &str {
        "hand"
    }

    fn extract(&self, frame: &Rgb, w: usize, h: usize) -> crate::Result<FeatureMap> {
        let small = frame.resize(w, h);
        let fine = frame.resize(2 * w, 2 * h).gray();
        let gray = small.gray();
        let mut planes: Vec<Plane> = Vec::with_capacity(14);
        planes.extend(small.c.iter().cloned());
        for s in [2.0, 6.0] {
            planes.extend(small.c.iter().map(|p| p.gaussian(s)));
        }
        let gmag = |p: &Plane| {
            let (gx, gy) = p.gradients();
            gx.zip(&gy, |a, b| (a * a + b * b).sqrt())
        };
        planes.push(gmag(&gray).gaussian(1.0));
        planes.push(gmag(&fine).resize(w, h));
        let mean = gray.box_mean(2);
        let sq = gray.map(|v| v * v).box_mean(2);
        planes.push(sq.zip(&mean, |s, m| (s - m * m).max(0.0).sqrt()));
        if self.chromaticity {
            // Shading-invariant colour: r/(r+g+b), g/(r+g+b), smoothed σ = 1.
            let sum = small.c[0]
                .zip(&small.c[1], |a, b| a + b)
                .zip(&small.c[2], |a, b| a + b + 1e-3);
            planes.push(small.c[0].zip(&sum, |a, s| a / s).gaussian(1.0));
            planes.push(small.c[1].zip(&sum, |a, s| a / s).gaussian(1.0));
        }
        planes.push(Plane::from_fn(w, h, |x, _| (x as f32 + 0.5) / w as f32));
        planes.push(Plane::from_fn(w, h, |_, y| (y as f32 + 0.5) / h as f32));
        Ok(FeatureMap {
            c: planes.len(),
            w,
            h,
            data: planes.into_iter().flat_map(|p| p.data).collect(),
        })
    }
}

/// Standardise each channel to zero mean and unit variance over all maps
/// (the whole video), in place.
pub fn standardise(maps: &mut [FeatureMap]) {
    let Some(c) = maps.first().map(|m| m.c) else {
        return;
    };
    for k in 0..c {
        let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for m in maps.iter() {
            let np = m.w * m.h;
            for v in &m.data[k * np..(k + 1) * np] {
                s += *v as f64;
                s2 += (*v as f64) * (*v as f64);
                n += 1.0;
            }
        }
        let mean = s / n.max(1.0);
        let sd = (s2 / n.max(1.0) - mean * mean).max(0.0).sqrt().max(1e-6);
        for m in maps.iter_mut() {
            let np = m.w * m.h;
            for v in &mut m.data[k * np..(k + 1) * np] {
                *v = ((*v as f64 - mean) / sd) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_features_shape_and_standardisation() {
        let img = Rgb {
            c: [
                Plane::from_fn(40, 30, |x, _| x as f32 / 40.0),
                Plane::from_fn(40, 30, |_, y| y as f32 / 30.0),
                Plane::filled(40, 30, 0.5),
            ],
        };
        let f = HandFeatures::default().extract(&img, 20, 15).unwrap();
        assert_eq!((f.c, f.w, f.h), (14, 20, 15));
        let mut v = vec![f.clone(), f];
        standardise(&mut v);
        let n = 20 * 15;
        // Channel 0 (red = x ramp) now has mean 0 and unit variance.
        let ch = &v[0].data[..n];
        let m: f32 = ch.iter().sum::<f32>() / n as f32;
        let var: f32 = ch.iter().map(|x| (x - m) * (x - m)).sum::<f32>() / n as f32;
        assert!(m.abs() < 1e-4 && (var - 1.0).abs() < 1e-3);
        // Constant blue channel stays finite.
        assert!(v[0].data[2 * n..3 * n].iter().all(|x| x.is_finite()));
        let pm = v[0].pixel_major();
        assert_eq!(pm[14 * 7 + 12], v[0].data[12 * n + 7]);
    }
}
