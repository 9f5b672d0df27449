//! Procedural textures for the synthetic scenes, baked into mip-mapped RGB
//! images and sampled trilinearly by the renderer.
//!
//! Why: optical flow (patch based) and SIFT need corners and detail at every
//! scale, and matching fails on repeated identical patterns. Every texture is
//! therefore a structured pattern (paving stones, bricks with windows, irregular
//! checkers, posters of random shapes, wood, cloth) mixed with seeded
//! multi-octave value noise (Perlin-style fBm, "Texturing & Modeling: A
//! Procedural Approach", Ebert et al.), evaluated in metric face coordinates so
//! no two faces or cells are alike. Pure functions of the seed: deterministic.

use rayon::prelude::*;

/// An RGB colour, components in [0, 1] (display values).
pub type Rgb = [f32; 3];

/// A 64-bit mix (splitmix64 finaliser).
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hash of a lattice point and a seed, uniform in [0, 1).
pub fn hash01(x: i64, y: i64, seed: u64) -> f64 {
    let k = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64)
            .wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            .rotate_left(29);
    let h = mix64(seed.wrapping_mul(0xD6E8_FEB8_6659_FD93) ^ k);
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Smoothly interpolated lattice value noise in [0, 1].
pub fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (xi, yi) = (xf as i64, yf as i64);
    let (tx, ty) = (x - xf, y - yf);
    let sx = tx * tx * (3.0 - 2.0 * tx);
    let sy = ty * ty * (3.0 - 2.0 * ty);
    let a = hash01(xi, yi, seed);
    let b = hash01(xi + 1, yi, seed);
    let c = hash01(xi, yi + 1, seed);
    let d = hash01(xi + 1, yi + 1, seed);
    let top = a + (b - a) * sx;
    let bot = c + (d - c) * sx;
    top + (bot - top) * sy
}

/// Fractal sum of `octaves` value-noise layers (lacunarity 2, gain 0.5),
/// normalised to [0, 1]. `freq` is the base frequency in cycles per metre.
pub fn fbm(x: f64, y: f64, freq: f64, octaves: u32, seed: u64) -> f64 {
    let (mut sum, mut amp, mut norm, mut f) = (0.0, 1.0, 0.0, freq);
    for o in 0..octaves {
        sum += amp
            * value_noise(
                x * f + o as f64 * 17.3,
                y * f - o as f64 * 9.1,
                seed.wrapping_add(o as u64),
            );
        norm += amp;
        amp *= 0.5;
        f *= 2.0;
    }
    sum / norm
}

fn lerp3(a: Rgb, b: Rgb, t: f64) -> Rgb {
    let t = t as f32;
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

fn scale3(a: Rgb, s: f64) -> Rgb {
    let s = s as f32;
    [a[0] * s, a[1] * s, a[2] * s]
}

/// The pattern family of a texture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pattern {
    /// Irregular paving stones with mortar, dirt and stains (ground).
    Paving,
    /// Bricks with a grid of individually varied windows (façades).
    Brick,
    /// Plaster: multi-octave noise with blotches and painted bands.
    Plaster,
    /// Plaster façade with a grid of individually varied windows.
    Facade,
    /// Irregular checker of per-cell palette colours (boxes, tiles).
    Checker,
    /// Poster: random overlapping discs and bars on a background.
    Poster,
    /// Wood planks with warped grain (crates, benches).
    Wood,
    /// Cloth: stripes / plaid in saturated colours (pedestrians' clothes).
    Cloth,
    /// Skin / hair: smooth, slightly mottled.
    Skin,
}

/// A texture recipe: pattern, palette and seed.
#[derive(Debug, Clone, Copy)]
pub struct Style {
    pub pattern: Pattern,
    pub palette: [Rgb; 4],
    pub seed: u64,
}

impl Style {
    /// A window of a façade's 2.6 m × 3.1 m grid at (x, y) (frame, glass,
    /// per-window curtain and reflections), or None between windows.
    fn window(&self, x: f64, y: f64, fine: f64) -> Option<Rgb> {
        let s = self.seed;
        let (wx, wy) = (x / 2.6, (y - 0.9) / 3.1);
        let (cx, cy) = (wx.floor(), wy.floor());
        let (fx, fy) = (wx - cx, wy - cy);
        if !(y > 0.9 && (0.25..0.75).contains(&fx) && (0.2..0.75).contains(&fy)) {
            return None;
        }
        let hw = hash01(cx as i64, cy as i64, s ^ 0x33);
        let frame =
            !(0.28..0.72).contains(&fx) || !(0.24..0.71).contains(&fy) || (fx - 0.5).abs() < 0.015;
        if frame {
            return Some(scale3([0.9, 0.88, 0.82], 0.8 + 0.2 * fine));
        }
        let curtain = [hw as f32, hash01(cx as i64, 5, s) as f32 * 0.7, 0.3];
        let refl = fbm(x + hw * 10.0, y, 1.5, 4, s ^ 0x44);
        let open = hash01(cx as i64 + 100, cy as i64, s) * 0.7;
        let glass = if fy > open {
            curtain
        } else {
            [0.12, 0.16, 0.22]
        };
        Some(lerp3(
            glass,
            [0.75, 0.82, 0.9],
            (refl - 0.4).clamp(0.0, 0.5),
        ))
    }

    /// Plaster: multi-octave noise, blotches and painted bands.
    fn plaster(&self, x: f64, y: f64, fine: f64) -> Rgb {
        let (s, p) = (self.seed, &self.palette);
        let n = fbm(x, y, 1.2, 6, s);
        let blot = fbm(x, y, 0.4, 3, s ^ 0x12);
        let c = lerp3(p[0], p[1], n);
        let c = lerp3(c, p[2], ((blot - 0.55) * 4.0).clamp(0.0, 1.0));
        let band = ((y * 1.3 + 0.3 * value_noise(x * 0.7, 0.0, s)).fract() < 0.08) as u8 as f64;
        lerp3(scale3(c, 0.85 + 0.3 * fine), p[3], band * 0.8)
    }

    /// Colour at metric face coordinates (x right, y up), in metres.
    pub fn texel(&self, x: f64, y: f64) -> Rgb {
        let s = self.seed;
        let p = &self.palette;
        let grain = fbm(x, y, 6.0, 4, s ^ 0xA1);
        let fine = value_noise(x * 45.0, y * 45.0, s ^ 0xB2);
        let c = match self.pattern {
            Pattern::Paving => {
                let row_h = 0.45;
                let row = (y / row_h).floor();
                let ry = y / row_h - row;
                let off = hash01(row as i64, 7, s) * 2.0;
                let w = 0.35 + 0.5 * hash01(row as i64, 3, s);
                let col = ((x + off) / w).floor();
                let rx = (x + off) / w - col;
                let h = hash01(col as i64, row as i64, s ^ 0x55);
                let base = lerp3(
                    p[(h * 3.0) as usize % 3],
                    p[(h * 7.0) as usize % 3],
                    hash01(col as i64, row as i64, s ^ 9),
                );
                let mortar = rx < 0.05 || ry < 0.07;
                let stone = scale3(base, 0.75 + 0.5 * grain + 0.15 * (fine - 0.5));
                let stain = fbm(x, y, 0.35, 3, s ^ 0x77);
                let c = if mortar {
                    scale3(p[3], 0.6 + 0.4 * fine)
                } else {
                    stone
                };
                lerp3(c, scale3(p[3], 0.5), ((stain - 0.62) * 3.0).clamp(0.0, 0.6))
            }
            Pattern::Brick => {
                if let Some(w) = self.window(x, y, fine) {
                    w
                } else {
                    let bh = 0.16;
                    let row = (y / bh).floor();
                    let bw = 0.42;
                    let bx = x / bw + if row as i64 % 2 == 0 { 0.0 } else { 0.5 };
                    let col = bx.floor();
                    let h = hash01(col as i64, row as i64, s);
                    let mortar = (bx - col) < 0.06 || (y / bh - row) < 0.12;
                    let brick = scale3(
                        lerp3(p[0], p[1], h),
                        0.7 + 0.45 * grain + 0.2 * (fine - 0.5),
                    );
                    let c = if mortar {
                        scale3(p[3], 0.85 + 0.3 * fine)
                    } else {
                        brick
                    };
                    lerp3(
                        c,
                        p[2],
                        ((fbm(x, y, 0.5, 3, s ^ 0x99) - 0.55) * 2.5).clamp(0.0, 0.7),
                    )
                }
            }
            Pattern::Plaster => self.plaster(x, y, fine),
            Pattern::Facade => self
                .window(x, y, fine)
                .unwrap_or_else(|| self.plaster(x, y, fine)),
            Pattern::Checker => {
                let cell = 0.18 + 0.2 * hash01(1, 2, s);
                let (cx, cy) = ((x / cell).floor() as i64, (y / cell).floor() as i64);
                let h = hash01(cx, cy, s);
                let base = p[(h * 4.0) as usize % 4];
                scale3(base, 0.7 + 0.4 * grain + 0.15 * (fine - 0.5))
            }
            Pattern::Poster => {
                let mut c = lerp3(p[0], p[3], grain);
                let tile = 0.5;
                let (tx, ty) = ((x / tile).floor(), (y / tile).floor());
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (ix, iy) = (tx as i64 + dx, ty as i64 + dy);
                        let k = hash01(ix, iy, s ^ 0x5151);
                        let ox = (ix as f64 + hash01(ix, iy, s ^ 1)) * tile;
                        let oy = (iy as f64 + hash01(ix, iy, s ^ 2)) * tile;
                        let r = 0.08 + 0.3 * hash01(ix, iy, s ^ 3);
                        let col = p[1 + (k * 3.0) as usize % 3];
                        let inside = if k < 0.5 {
                            (x - ox).hypot(y - oy) < r
                        } else {
                            (x - ox).abs() < r && (y - oy).abs() < r * 0.35
                        };
                        if inside {
                            c = scale3(col, 0.8 + 0.3 * fine);
                        }
                    }
                }
                c
            }
            Pattern::Wood => {
                let plank = 0.14;
                let row = (y / plank).floor();
                let warp = fbm(x, y, 0.8, 3, s ^ 0x21) * 3.0;
                let ring = ((y * 40.0 + warp * 6.0).sin() * 0.5 + 0.5) * 0.35;
                let h = hash01(row as i64, 1, s);
                let gap = (y / plank - row) < 0.06;
                let c = scale3(lerp3(p[0], p[1], h), 0.75 + ring + 0.2 * (fine - 0.5));
                if gap { scale3(p[3], 0.5) } else { c }
            }
            Pattern::Cloth => {
                let sw = 0.05 + 0.06 * hash01(4, 4, s);
                let plaid = hash01(8, 8, s) < 0.5;
                let a = ((y / sw).floor() as i64).rem_euclid(3) as usize;
                let b = ((x / sw).floor() as i64).rem_euclid(3) as usize;
                let c = if plaid { lerp3(p[a], p[b], 0.5) } else { p[a] };
                scale3(c, 0.8 + 0.3 * fine + 0.2 * (grain - 0.5))
            }
            Pattern::Skin => scale3(lerp3(p[0], p[1], grain), 0.9 + 0.15 * (fine - 0.5)),
        };
        [
            c[0].clamp(0.0, 1.0),
            c[1].clamp(0.0, 1.0),
            c[2].clamp(0.0, 1.0),
        ]
    }
}

/// One mip level.
#[derive(Debug, Clone)]
pub struct Level {
    pub w: usize,
    pub h: usize,
    pub data: Vec<Rgb>,
}

/// A baked, mip-mapped texture covering a face; `u` runs along the face's
/// width, `v` along its height, both in [0, 1] (clamped outside).
#[derive(Debug, Clone)]
pub struct Texture {
    pub levels: Vec<Level>,
}

impl Texture {
    /// Bake `style` over a face of `width_m` × `height_m` metres at
    /// `texels_per_meter` (texel counts clamped to [4, 2048]).
    pub fn bake(style: &Style, width_m: f64, height_m: f64, texels_per_meter: f64) -> Texture {
        let w = ((width_m * texels_per_meter).round() as usize).clamp(4, 2048);
        let h = ((height_m * texels_per_meter).round() as usize).clamp(4, 2048);
        let mut data = vec![[0.0f32; 3]; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            // Row 0 is the top of the face (v = 0 ↔ top).
            let y = (h - j) as f64 - 0.5;
            for (i, px) in row.iter_mut().enumerate() {
                let x = i as f64 + 0.5;
                *px = style.texel(x * width_m / w as f64, y * height_m / h as f64);
            }
        });
        let mut levels = vec![Level { w, h, data }];
        while let Some(last) = levels.last() {
            if last.w == 1 && last.h == 1 {
                break;
            }
            let (nw, nh) = (last.w.div_ceil(2), last.h.div_ceil(2));
            let mut nd = vec![[0.0f32; 3]; nw * nh];
            for j in 0..nh {
                for i in 0..nw {
                    let mut acc = [0.0f32; 3];
                    for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let (x, y) = ((2 * i + di).min(last.w - 1), (2 * j + dj).min(last.h - 1));
                        let t = last.data[y * last.w + x];
                        acc = [acc[0] + t[0], acc[1] + t[1], acc[2] + t[2]];
                    }
                    nd[j * nw + i] = [acc[0] * 0.25, acc[1] * 0.25, acc[2] * 0.25];
                }
            }
            levels.push(Level {
                w: nw,
                h: nh,
                data: nd,
            });
        }
        Texture { levels }
    }

    /// Texel size of the base level.
    pub fn size(&self) -> (usize, usize) {
        self.levels.first().map_or((1, 1), |l| (l.w, l.h))
    }

    fn bilinear(&self, level: usize, u: f32, v: f32) -> Rgb {
        let l = &self.levels[level.min(self.levels.len() - 1)];
        let x = (u * l.w as f32 - 0.5).clamp(0.0, (l.w - 1) as f32);
        let y = (v * l.h as f32 - 0.5).clamp(0.0, (l.h - 1) as f32);
        let (x0, y0) = (x as usize, y as usize);
        let (x1, y1) = ((x0 + 1).min(l.w - 1), (y0 + 1).min(l.h - 1));
        let (tx, ty) = (x - x0 as f32, y - y0 as f32);
        let a = l.data[y0 * l.w + x0];
        let b = l.data[y0 * l.w + x1];
        let c = l.data[y1 * l.w + x0];
        let d = l.data[y1 * l.w + x1];
        let mut out = [0.0; 3];
        for k in 0..3 {
            let top = a[k] + (b[k] - a[k]) * tx;
            let bot = c[k] + (d[k] - c[k]) * tx;
            out[k] = top + (bot - top) * ty;
        }
        out
    }

    /// Trilinear sample at (u, v) with level of detail `lod` (log2 of the
    /// footprint in base texels; ≤ 0 samples the base level).
    pub fn sample(&self, u: f32, v: f32, lod: f32) -> Rgb {
        let max = (self.levels.len() - 1) as f32;
        let lod = lod.clamp(0.0, max);
        let l0 = lod.floor();
        let t = lod - l0;
        // Blend two levels only near the middle of a level (cheaper than
        // full trilinear; the supersampling box filter hides the rest).
        if t <= 0.25 {
            return self.bilinear(l0 as usize, u, v);
        }
        if t >= 0.75 {
            return self.bilinear(l0 as usize + 1, u, v);
        }
        let t = (t - 0.25) * 2.0;
        let a = self.bilinear(l0 as usize, u, v);
        let b = self.bilinear(l0 as usize + 1, u, v);
        [
            a[0] + (b[0] - a[0]) * t,
            a[1] + (b[1] - a[1]) * t,
            a[2] + (b[2] - a[2]) * t,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_deterministic_and_seed_dependent() {
        assert_eq!(fbm(1.3, 2.7, 1.0, 5, 9), fbm(1.3, 2.7, 1.0, 5, 9));
        assert_ne!(fbm(1.3, 2.7, 1.0, 5, 9), fbm(1.3, 2.7, 1.0, 5, 10));
        for i in 0..200 {
            let v = value_noise(i as f64 * 0.37, i as f64 * -0.11, 3);
            assert!((0.0..=1.0).contains(&v));
        }
    }

    #[test]
    fn mips_preserve_mean_and_sampling_is_clamped() {
        let style = Style {
            pattern: Pattern::Checker,
            palette: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.5; 3]],
            seed: 1,
        };
        let t = Texture::bake(&style, 1.0, 1.0, 64.0);
        let base = &t.levels[0];
        let mean: f32 = base.data.iter().map(|c| c[1]).sum::<f32>() / base.data.len() as f32;
        let top = t.levels.last().map(|l| l.data[0][1]).unwrap_or(-1.0);
        assert!((mean - top).abs() < 1e-3, "{mean} vs {top}");
        assert_eq!(t.levels.last().map(|l| (l.w, l.h)), Some((1, 1)));
        // Sampling far outside [0,1] clamps to the edge texel.
        assert_eq!(t.sample(-5.0, -5.0, 0.0), base.data[0]);
    }
}
