//! Single-channel f32 images ("planes") and the few image operations every
//! RoMo stage needs: bilinear sampling, resizing, pyramids, separable blur,
//! box filters and gradients. Kept dependency-free so the flow, feature and
//! refinement stages share one definition of border handling (clamp to edge).

use rayon::prelude::*;

/// A row-major single-channel f32 image.
#[derive(Debug, Clone, PartialEq)]
pub struct Plane {
    /// Width in pixels.
    pub w: usize,
    /// Height in pixels.
    pub h: usize,
    /// `w * h` values, row-major.
    pub data: Vec<f32>,
}

impl Plane {
    /// A plane filled with `v`.
    pub fn filled(w: usize, h: usize, v: f32) -> Self {
        Self {
            w,
            h,
            data: vec![v; w * h],
        }
    }

    /// A plane from a function of (x, y).
    pub fn from_fn(w: usize, h: usize, f: impl Fn(usize, usize) -> f32 + Sync) -> Self {
        let mut data = vec![0.0; w * h];
        data.par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                for (x, v) in row.iter_mut().enumerate() {
                    *v = f(x, y);
                }
            });
        Self { w, h, data }
    }

    /// Value at integer coordinates (must be in range).
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.w + x]
    }

    /// Value at integer coordinates clamped to the image.
    #[inline]
    pub fn at_clamped(&self, x: isize, y: isize) -> f32 {
        let x = x.clamp(0, self.w as isize - 1) as usize;
        let y = y.clamp(0, self.h as isize - 1) as usize;
        self.data[y * self.w + x]
    }

    /// The four taps and weights of a bilinear sample at (x, y), clamped to
    /// the border.
    #[inline]
    fn bilinear_taps(&self, x: f32, y: f32) -> Taps {
        Taps::new(axis_tap(x, self.w), axis_tap(y, self.h), self.w)
    }

    /// Bilinear sample at continuous pixel coordinates (pixel centres at
    /// integers), clamped to the border.
    #[inline]
    pub fn bilinear(&self, x: f32, y: f32) -> f32 {
        self.bilinear_taps(x, y).sample(&self.data)
    }

    /// Bilinear samples of four planes of this plane's size at one point
    /// (each exactly [`Plane::bilinear`]'s value).
    #[inline]
    pub fn bilinear4(planes: [&Plane; 4], x: f32, y: f32) -> [f32; 4] {
        let t = planes[0].bilinear_taps(x, y);
        planes.map(|q| t.sample(&q.data))
    }

    /// Resize with bilinear interpolation (pixel-centre aligned). When
    /// shrinking by more than 2×, the source is box-averaged first so the
    /// result is not aliased.
    pub fn resize(&self, nw: usize, nh: usize) -> Plane {
        if nw == self.w && nh == self.h {
            return self.clone();
        }
        let mut src = std::borrow::Cow::Borrowed(self);
        while src.w >= 2 * nw.max(1) * 2 && src.h >= 2 * nh.max(1) * 2 {
            src = std::borrow::Cow::Owned(src.half());
        }
        let cols = resize_taps(nw, src.w);
        let rows = resize_taps(nh, src.h);
        let across = resample_rows(&src.data, src.w, &cols, &rows);
        let mut data = vec![0.0; nw * nh];
        data.par_chunks_mut(nw.max(1))
            .zip(&rows)
            .for_each(|(out, &tap)| lerp_rows(&across, nw, tap, out));
        Plane { w: nw, h: nh, data }
    }

    /// Half resolution by 2×2 box averaging (odd edges clamped).
    pub fn half(&self) -> Plane {
        let nw = self.w.div_ceil(2).max(1);
        let nh = self.h.div_ceil(2).max(1);
        Plane::from_fn(nw, nh, |x, y| {
            let x0 = (2 * x) as isize;
            let y0 = (2 * y) as isize;
            0.25 * (self.at_clamped(x0, y0)
                + self.at_clamped(x0 + 1, y0)
                + self.at_clamped(x0, y0 + 1)
                + self.at_clamped(x0 + 1, y0 + 1))
        })
    }

    /// Separable Gaussian blur with standard deviation `sigma` pixels
    /// (kernel radius 3σ, clamped borders). `sigma <= 0` returns a copy.
    pub fn gaussian(&self, sigma: f32) -> Plane {
        if sigma <= 0.0 {
            return self.clone();
        }
        let k = gaussian_kernel(sigma);
        let (w, h, r) = (self.w, self.h, k.len() / 2);
        if w == 0 || h == 0 {
            return self.clone();
        }
        // Horizontal pass on rows padded by r edge values on both sides.
        let mut tmp = vec![0.0f32; w * h];
        let scratch = || Vec::with_capacity(w + 2 * r);
        tmp.par_chunks_mut(w)
            .enumerate()
            .for_each_init(scratch, |padded, (y, out)| {
                let row = &self.data[y * w..(y + 1) * w];
                padded.clear();
                padded.extend(std::iter::repeat_n(row[0], r));
                padded.extend_from_slice(row);
                padded.extend(std::iter::repeat_n(row[w - 1], r));
                for (j, &kv) in k.iter().enumerate() {
                    axpy(kv, &padded[j..j + w], out);
                }
            });
        // Vertical pass: row y sums the clamped rows y − r ..= y + r.
        let mut data = vec![0.0f32; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
            for (j, &kv) in k.iter().enumerate() {
                let sy = (y + j).saturating_sub(r).min(h - 1);
                axpy(kv, &tmp[sy * w..(sy + 1) * w], out);
            }
        });
        Plane { w, h, data }
    }

    /// Mean over the (2r+1)² window around each pixel, windows clipped to the
    /// image (the mean is over the pixels actually inside). O(1) per pixel.
    pub fn box_mean(&self, r: usize) -> Plane {
        let (w, h) = (self.w, self.h);
        // Horizontal running sums.
        let mut tmp = vec![0.0f32; w * h];
        tmp.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
            let row = &self.data[y * w..(y + 1) * w];
            let mut pre = vec![0.0f64; w + 1];
            for x in 0..w {
                pre[x + 1] = pre[x] + row[x] as f64;
            }
            for (x, o) in out.iter_mut().enumerate() {
                let a = x.saturating_sub(r);
                let b = (x + r + 1).min(w);
                *o = ((pre[b] - pre[a]) / (b - a) as f64) as f32;
            }
        });
        // Vertical running sums, a whole row of columns at a time (each
        // column's sums in the same order as one column alone).
        let mut pre = vec![0.0f64; (h + 1) * w];
        for y in 0..h {
            let (done, next) = pre.split_at_mut((y + 1) * w);
            let prev = &done[y * w..];
            for ((p, q), t) in next[..w].iter_mut().zip(prev).zip(&tmp[y * w..(y + 1) * w]) {
                *p = q + *t as f64;
            }
        }
        let mut out = vec![0.0f32; w * h];
        out.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, o)| {
            let a = y.saturating_sub(r);
            let b = (y + r + 1).min(h);
            let n = (b - a) as f64;
            let (pa, pb) = (&pre[a * w..(a + 1) * w], &pre[b * w..(b + 1) * w]);
            for ((o, hi), lo) in o.iter_mut().zip(pb).zip(pa) {
                *o = ((hi - lo) / n) as f32;
            }
        });
        Plane { w, h, data: out }
    }

    /// Central-difference gradients (half the difference of the clamped
    /// neighbours at the border).
    pub fn gradients(&self) -> (Plane, Plane) {
        let (w, h) = (self.w, self.h);
        let mut gx = vec![0.0f32; w * h];
        let mut gy = vec![0.0f32; w * h];
        gx.par_chunks_mut(w)
            .zip(gy.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (rx, ry))| {
                let row = &self.data[y * w..(y + 1) * w];
                let up = &self.data[y.saturating_sub(1) * w..][..w];
                let dn = &self.data[(y + 1).min(h - 1) * w..][..w];
                for x in 0..w {
                    let l = row[x.saturating_sub(1)];
                    let r = row[(x + 1).min(w - 1)];
                    rx[x] = 0.5 * (r - l);
                    ry[x] = 0.5 * (dn[x] - up[x]);
                }
            });
        (Plane { w, h, data: gx }, Plane { w, h, data: gy })
    }

    /// Element-wise map.
    pub fn map(&self, f: impl Fn(f32) -> f32 + Sync) -> Plane {
        Plane {
            w: self.w,
            h: self.h,
            data: self.data.par_iter().map(|v| f(*v)).collect(),
        }
    }

    /// Element-wise combination of two planes of the same size.
    pub fn zip(&self, o: &Plane, f: impl Fn(f32, f32) -> f32 + Sync) -> Plane {
        self.zip3(o, o, |a, b, _| f(a, b))
    }

    /// Element-wise combination of three planes of the same size.
    pub fn zip3(&self, b: &Plane, c: &Plane, f: impl Fn(f32, f32, f32) -> f32 + Sync) -> Plane {
        Plane {
            w: self.w,
            h: self.h,
            data: self
                .data
                .par_iter()
                .zip(b.data.par_iter())
                .zip(c.data.par_iter())
                .map(|((a, b), c)| f(*a, *b, *c))
                .collect(),
        }
    }
}

/// One axis of a bilinear sample at `c` on `n` pixels, clamped to the
/// border: the two source indices and the fraction.
#[inline]
fn axis_tap(c: f32, n: usize) -> (usize, usize, f32) {
    let m = n.saturating_sub(1);
    let c = c.clamp(0.0, m as f32);
    let c0 = c.floor();
    let i0 = c0 as usize;
    (i0, (i0 + 1).min(m), c - c0)
}

/// The bilinear taps of a pixel-centre aligned resize along one axis of
/// `src` pixels to `n` pixels: per output index [`axis_tap`] at
/// `(i + 0.5)·src/n − 0.5`, as [`Plane::bilinear`] samples there, computed
/// once per row or column.
pub fn resize_taps(n: usize, src: usize) -> Vec<(usize, usize, f32)> {
    let s = src as f32 / n as f32;
    (0..n)
        .map(|i| axis_tap((i as f32 + 0.5) * s - 0.5, src))
        .collect()
}

/// Horizontal half of a separable bilinear resample of the row-major `d`
/// (`w` wide): every source row that `rows` uses, resampled to
/// `cols.len()` columns by `a + fx·(b − a)` as [`Taps::sample`] does within
/// a row; rows no output needs stay zero. With [`lerp_rows`] this gives the
/// bits of sampling every output pixel with [`Taps`], with each source row
/// resampled once instead of once per output row that reads it.
pub fn resample_rows(
    d: &[f32],
    w: usize,
    cols: &[(usize, usize, f32)],
    rows: &[(usize, usize, f32)],
) -> Vec<f32> {
    let h = d.len() / w.max(1);
    let nw = cols.len();
    let mut used = vec![false; h];
    for &(y0, y1, _) in rows {
        used[y0] = true;
        used[y1] = true;
    }
    let mut out = vec![0.0f32; h * nw];
    out.par_chunks_mut(nw.max(1))
        .zip(d.par_chunks(w.max(1)))
        .zip(&used)
        .filter(|(_, used)| **used)
        .for_each(|((o, row), _)| {
            for (v, &(x0, x1, fx)) in o.iter_mut().zip(cols) {
                *v = row[x0] + fx * (row[x1] - row[x0]);
            }
        });
    out
}

/// Vertical half of the separable resample: one output row,
/// `a + fy·(b − a)` of the rows `y0` and `y1` of [`resample_rows`]'s
/// result (`nw` wide).
#[inline]
pub fn lerp_rows(across: &[f32], nw: usize, (y0, y1, fy): (usize, usize, f32), out: &mut [f32]) {
    let a = &across[y0 * nw..(y0 + 1) * nw];
    let b = &across[y1 * nw..(y1 + 1) * nw];
    for ((o, a), b) in out.iter_mut().zip(a).zip(b) {
        *o = a + fy * (b - a);
    }
}

/// The four taps and weights of one bilinear sample in a plane `w` wide:
/// row offsets `r0`, `r1`, columns `x0`, `x1`, fractions `fx`, `fy`.
#[derive(Debug, Clone, Copy)]
pub struct Taps {
    r0: usize,
    r1: usize,
    x0: usize,
    x1: usize,
    fx: f32,
    fy: f32,
}

impl Taps {
    /// From the column and row taps (as [`resize_taps`] gives them).
    #[inline]
    pub fn new(
        (x0, x1, fx): (usize, usize, f32),
        (y0, y1, fy): (usize, usize, f32),
        w: usize,
    ) -> Self {
        Taps {
            r0: y0 * w,
            r1: y1 * w,
            x0,
            x1,
            fx,
            fy,
        }
    }

    /// The sample of the row-major data `d`.
    #[inline]
    pub fn sample(&self, d: &[f32]) -> f32 {
        let a = d[self.r0 + self.x0] + self.fx * (d[self.r0 + self.x1] - d[self.r0 + self.x0]);
        let b = d[self.r1 + self.x0] + self.fx * (d[self.r1 + self.x1] - d[self.r1 + self.x0]);
        a + self.fy * (b - a)
    }
}

/// The normalised taps of a Gaussian with standard deviation `sigma` px,
/// radius ⌈3σ⌉ (`2r + 1` taps).
fn gaussian_kernel(sigma: f32) -> Vec<f32> {
    let r = (3.0 * sigma).ceil() as isize;
    let mut k: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f32 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

crate::flow::simd::multiversion! {
    /// `out[x] += k · src[x]`: one tap of [`Plane::gaussian`], added in
    /// tap order per pixel (the order of a per-pixel loop over the taps).
    fn axpy(k: f32, src: &[f32], out: &mut [f32]) {
        for (o, s) in out.iter_mut().zip(src) {
            *o += k * s;
        }
    }
}

/// An RGB image as three planes (values in [0, 1]).
#[derive(Debug, Clone)]
pub struct Rgb {
    /// Red, green, blue planes.
    pub c: [Plane; 3],
}

impl Rgb {
    /// From interleaved RGB f32 data.
    pub fn from_interleaved(w: usize, h: usize, data: &[f32]) -> Self {
        Self::from_samples(w, h, |i| data[i])
    }

    /// The planes of interleaved RGB samples, `sample(i)` the value at
    /// index `i = (y·w + x)·3 + channel`.
    fn from_samples(w: usize, h: usize, sample: impl Fn(usize) -> f32 + Sync) -> Self {
        let ch = |k: usize| Plane::from_fn(w, h, |x, y| sample((y * w + x) * 3 + k));
        Rgb {
            c: [ch(0), ch(1), ch(2)],
        }
    }

    /// From an `image` crate f32 RGB image.
    pub fn from_image(img: &image::Rgb32FImage) -> Self {
        Self::from_interleaved(img.width() as usize, img.height() as usize, img.as_raw())
    }

    /// From a decoded image of any pixel format: 8-bit RGB (JPEG frames)
    /// straight into the planes, the same values as through
    /// `DynamicImage::to_rgb32f` (`v / 255`) without its interleaved f32
    /// copy; other formats through that conversion.
    pub fn from_dynamic(img: image::DynamicImage) -> Self {
        match img {
            image::DynamicImage::ImageRgb8(rgb) => {
                let (w, h) = (rgb.width() as usize, rgb.height() as usize);
                let data = rgb.as_raw();
                Self::from_samples(w, h, |i| f32::from(data[i]) / f32::from(u8::MAX))
            }
            other => Self::from_image(&other.to_rgb32f()),
        }
    }

    /// Width.
    pub fn w(&self) -> usize {
        self.c[0].w
    }

    /// Height.
    pub fn h(&self) -> usize {
        self.c[0].h
    }

    /// Rec. 601 luma in [0, 1].
    pub fn gray(&self) -> Plane {
        let [r, g, b] = &self.c;
        Plane::from_fn(r.w, r.h, |x, y| {
            0.299 * r.at(x, y) + 0.587 * g.at(x, y) + 0.114 * b.at(x, y)
        })
    }

    /// Resize every channel.
    pub fn resize(&self, nw: usize, nh: usize) -> Rgb {
        Rgb {
            c: [
                self.c[0].resize(nw, nh),
                self.c[1].resize(nw, nh),
                self.c[2].resize(nw, nh),
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An 8-bit RGB image's planes hold the bits `to_rgb32f` gives, for
    /// every value in every channel; a 16-bit image keeps its precision.
    #[test]
    fn eight_bit_frames_convert_as_the_image_crate_does() {
        let img = image::RgbImage::from_fn(256, 3, |x, y| {
            let v = x as u8;
            match y {
                0 => image::Rgb([v, 255 - v, v / 2]),
                1 => image::Rgb([v / 3, v, 255 - v]),
                _ => image::Rgb([255 - v, v / 5, v]),
            }
        });
        let dynamic = image::DynamicImage::ImageRgb8(img);
        let want = Rgb::from_image(&dynamic.to_rgb32f());
        let got = Rgb::from_dynamic(dynamic);
        for k in 0..3 {
            let bits = |p: &Plane| p.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got.c[k]), bits(&want.c[k]), "channel {k}");
        }
        let deep = image::DynamicImage::ImageRgb16(image::ImageBuffer::from_pixel(
            2,
            2,
            image::Rgb([1u16, 32768, 65535]),
        ));
        let planes = Rgb::from_dynamic(deep);
        assert_eq!(planes.c[0].data[0], 1.0 / 65535.0);
        assert_eq!(planes.c[2].data[3], 1.0);
    }

    /// The tabulated resize gives the same bits as sampling every output
    /// pixel with [`Plane::bilinear`], growing, shrinking and across the
    /// box-averaging step.
    #[test]
    fn resize_equals_per_pixel_bilinear() {
        let src = Plane::from_fn(37, 23, |x, y| {
            ((x * 29 + y * 13) % 11) as f32 * 0.37 + 0.01 * x as f32
        });
        for (nw, nh) in [(90, 51), (12, 7), (37, 9), (8, 23), (1, 1), (150, 5)] {
            let mut s = std::borrow::Cow::Borrowed(&src);
            while s.w >= 4 * nw && s.h >= 4 * nh {
                s = std::borrow::Cow::Owned(s.half());
            }
            let (sx, sy) = (s.w as f32 / nw as f32, s.h as f32 / nh as f32);
            let want = Plane::from_fn(nw, nh, |x, y| {
                s.bilinear((x as f32 + 0.5) * sx - 0.5, (y as f32 + 0.5) * sy - 0.5)
            });
            let got = src.resize(nw, nh);
            assert_eq!((got.w, got.h), (nw, nh));
            for (a, b) in got.data.iter().zip(&want.data) {
                assert_eq!(a.to_bits(), b.to_bits(), "{nw}x{nh}");
            }
        }
    }

    /// The row-vectorised blur gives the same bits as the per-pixel
    /// definition (taps in order, clamped to the edge), also when the
    /// kernel is wider than the image, on both instruction-set paths.
    #[test]
    fn gaussian_equals_per_pixel_clamped_convolution() {
        let src = Plane::from_fn(41, 17, |x, y| {
            ((x * 29 + y * 13) % 11) as f32 * 0.37 - 0.02 * y as f32
        });
        for baseline in [false, true] {
            crate::flow::simd::force_baseline(baseline);
            for sigma in [0.8f32, 1.0, 2.0, 6.0] {
                let k = gaussian_kernel(sigma);
                let r = (k.len() / 2) as isize;
                let conv = |p: &Plane, dx: isize, dy: isize| {
                    Plane::from_fn(p.w, p.h, |x, y| {
                        let mut acc = 0.0;
                        for (j, kv) in k.iter().enumerate() {
                            let o = j as isize - r;
                            acc += kv * p.at_clamped(x as isize + o * dx, y as isize + o * dy);
                        }
                        acc
                    })
                };
                let want = conv(&conv(&src, 1, 0), 0, 1);
                let got = src.gaussian(sigma);
                for (a, b) in got.data.iter().zip(&want.data) {
                    assert_eq!(a.to_bits(), b.to_bits(), "sigma {sigma}");
                }
            }
        }
        crate::flow::simd::force_baseline(false);
    }

    #[test]
    fn bilinear4_equals_bilinear_per_plane() {
        let planes: Vec<Plane> = (0..4)
            .map(|k| Plane::from_fn(7, 5, move |x, y| ((x * 31 + y * 17 + k * 7) % 13) as f32))
            .collect();
        let refs = [&planes[0], &planes[1], &planes[2], &planes[3]];
        for (x, y) in [
            (0.0, 0.0),
            (2.3, 1.7),
            (6.0, 4.0),
            (-1.5, 9.0),
            (5.99, 0.01),
        ] {
            let four = Plane::bilinear4(refs, x, y);
            for (k, p) in planes.iter().enumerate() {
                assert_eq!(
                    four[k].to_bits(),
                    p.bilinear(x, y).to_bits(),
                    "({x}, {y}) plane {k}"
                );
            }
        }
        // Known answer: halfway between 0 and 10 in x.
        let ramp = Plane::from_fn(2, 1, |x, _| 10.0 * x as f32);
        assert_eq!(ramp.bilinear(0.5, 0.0), 5.0);
    }

    #[test]
    fn bilinear_is_exact_on_a_linear_ramp() {
        let p = Plane::from_fn(10, 8, |x, y| 2.0 * x as f32 + 3.0 * y as f32);
        assert!((p.bilinear(3.25, 4.5) - (6.5 + 13.5)).abs() < 1e-5);
        // Clamped beyond the border.
        assert_eq!(p.bilinear(-5.0, 0.0), 0.0);
    }

    #[test]
    fn box_mean_matches_brute_force() {
        let p = Plane::from_fn(13, 9, |x, y| ((x * 7 + y * 3) % 11) as f32);
        let b = p.box_mean(2);
        for y in 0..9usize {
            for x in 0..13usize {
                let (mut s, mut n) = (0.0, 0.0);
                for yy in y.saturating_sub(2)..(y + 3).min(9) {
                    for xx in x.saturating_sub(2)..(x + 3).min(13) {
                        s += p.at(xx, yy);
                        n += 1.0;
                    }
                }
                assert!((b.at(x, y) - s / n).abs() < 1e-4, "{x},{y}");
            }
        }
    }

    #[test]
    fn gradients_of_a_ramp() {
        let p = Plane::from_fn(6, 6, |x, y| x as f32 - 2.0 * y as f32);
        let (gx, gy) = p.gradients();
        assert!((gx.at(3, 3) - 1.0).abs() < 1e-6);
        assert!((gy.at(3, 3) + 2.0).abs() < 1e-6);
    }
}
