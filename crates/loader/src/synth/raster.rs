//! A software triangle rasteriser for the synthetic scenes: pinhole camera in
//! COLMAP conventions (world-to-camera pose, OpenCV axes, pixel centres at
//! +0.5), near-plane clipping (Sutherland–Hodgman), z-buffer depth test,
//! perspective-correct texture coordinates (1/z, u/z, v/z are affine in
//! screen space; Heckbert & Moreton 1991), per-sample mip level from the
//! analytic texture-coordinate derivatives, and antialiasing by `ss`×`ss`
//! supersampling resolved with a box filter. Bands of sample rows are
//! rasterised in parallel with rayon; results do not depend on scheduling.

use super::texture::{Rgb, Texture};
use crate::camera::{Intrinsics, Pose};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Near clipping plane, metres in front of the camera.
pub const NEAR: f64 = 0.05;
/// Sample rows per parallel band.
const BAND: usize = 16;
/// Marker for "no triangle" in a sample.
pub const NONE: u32 = u32::MAX;

/// A vertex: world position and texture coordinates.
#[derive(Debug, Clone, Copy)]
pub struct Vertex {
    pub p: Vector3<f64>,
    pub uv: [f64; 2],
}

/// A world-space triangle with its texture index and a constant light factor.
#[derive(Debug, Clone, Copy)]
pub struct Tri {
    pub v: [Vertex; 3],
    pub material: u32,
    pub shade: f32,
}

/// A camera: pose, intrinsics and the supersampling factor per axis.
#[derive(Debug, Clone, Copy)]
pub struct View {
    pub pose: Pose,
    pub intr: Intrinsics,
    pub ss: u32,
}

impl View {
    /// Supersample grid size (width, height).
    pub fn sample_dims(&self) -> (usize, usize) {
        let s = self.ss as usize;
        (self.intr.width as usize * s, self.intr.height as usize * s)
    }
}

/// One supersample of a render target.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Camera-space depth (z), +inf when empty.
    pub depth: f32,
    /// Index into the setup list of the pass, [`NONE`] when empty.
    pub tri: u32,
    pub u: f32,
    pub v: f32,
}

impl Sample {
    pub const EMPTY: Sample = Sample {
        depth: f32::INFINITY,
        tri: NONE,
        u: 0.0,
        v: 0.0,
    };
}

/// A triangle after clipping and projection to sample coordinates, with
/// its screen-space affine planes `a·x + b·y + c` for 1/z, u/z, v/z and two
/// barycentrics.
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    iz: [f64; 3],
    uz: [f64; 3],
    vz: [f64; 3],
    b1: [f64; 3],
    b2: [f64; 3],
    /// Inclusive sample bounds (x0, x1, y0, y1).
    bounds: [usize; 4],
    pub material: u32,
    pub shade: f32,
    /// Index of the source triangle in the list given to [`setup`].
    pub src: u32,
    tex: [f64; 2],
    /// Nearest depth of the (clipped) triangle, for front-to-back order.
    zmin: f64,
}

fn eval(p: &[f64; 3], x: f64, y: f64) -> f64 {
    p[0] * x + p[1] * y + p[2]
}

/// Transform, clip against the near plane, project and set up every triangle.
pub fn setup(view: &View, tris: &[Tri], textures: &[Texture]) -> Vec<Setup> {
    let r: Matrix3<f64> = view.pose.rotation();
    let t = view.pose.translation();
    let s = view.ss as f64;
    let (ws, hs) = view.sample_dims();
    let k = view.intr;
    let mut out = Vec::with_capacity(tris.len());
    for (idx, tri) in tris.iter().enumerate() {
        let cam: Vec<(Vector3<f64>, [f64; 2])> =
            tri.v.iter().map(|v| (r * v.p + t, v.uv)).collect();
        if cam.iter().all(|(p, _)| p.z < NEAR) {
            continue;
        }
        // Sutherland–Hodgman against z = NEAR.
        let mut poly: Vec<(Vector3<f64>, [f64; 2])> = Vec::with_capacity(4);
        for i in 0..3 {
            let (a, b) = (cam[i], cam[(i + 1) % 3]);
            let (ina, inb) = (a.0.z >= NEAR, b.0.z >= NEAR);
            if ina {
                poly.push(a);
            }
            if ina != inb {
                let f = (NEAR - a.0.z) / (b.0.z - a.0.z);
                let p = a.0 + (b.0 - a.0) * f;
                let uv = [
                    a.1[0] + (b.1[0] - a.1[0]) * f,
                    a.1[1] + (b.1[1] - a.1[1]) * f,
                ];
                poly.push((Vector3::new(p.x, p.y, NEAR), uv));
            }
        }
        let proj: Vec<[f64; 5]> = poly
            .iter()
            .map(|(p, uv)| {
                let iz = 1.0 / p.z;
                [
                    (k.fx * p.x * iz + k.cx) * s,
                    (k.fy * p.y * iz + k.cy) * s,
                    iz,
                    uv[0] * iz,
                    uv[1] * iz,
                ]
            })
            .collect();
        let tex = textures
            .get(tri.material as usize)
            .map_or((1, 1), |t| t.size());
        for j in 1..proj.len().saturating_sub(1) {
            let (p0, p1, p2) = (proj[0], proj[j], proj[j + 1]);
            let det = (p1[0] - p0[0]) * (p2[1] - p0[1]) - (p2[0] - p0[0]) * (p1[1] - p0[1]);
            if det.abs() < 1e-12 || !det.is_finite() {
                continue;
            }
            let plane = |a0: f64, a1: f64, a2: f64| {
                let ax = ((a1 - a0) * (p2[1] - p0[1]) - (a2 - a0) * (p1[1] - p0[1])) / det;
                let ay = ((a2 - a0) * (p1[0] - p0[0]) - (a1 - a0) * (p2[0] - p0[0])) / det;
                [ax, ay, a0 - ax * p0[0] - ay * p0[1]]
            };
            let xmin = p0[0].min(p1[0]).min(p2[0]);
            let xmax = p0[0].max(p1[0]).max(p2[0]);
            let ymin = p0[1].min(p1[1]).min(p2[1]);
            let ymax = p0[1].max(p1[1]).max(p2[1]);
            // Sample centres sit at index + 0.5.
            let x0 = (xmin - 0.5).ceil().max(0.0);
            let x1 = (xmax - 0.5).floor().min(ws as f64 - 1.0);
            let y0 = (ymin - 0.5).ceil().max(0.0);
            let y1 = (ymax - 0.5).floor().min(hs as f64 - 1.0);
            if x0 > x1 || y0 > y1 {
                continue;
            }
            out.push(Setup {
                zmin: 1.0 / p0[2].max(p1[2]).max(p2[2]),
                iz: plane(p0[2], p1[2], p2[2]),
                uz: plane(p0[3], p1[3], p2[3]),
                vz: plane(p0[4], p1[4], p2[4]),
                b1: plane(0.0, 1.0, 0.0),
                b2: plane(0.0, 0.0, 1.0),
                bounds: [x0 as usize, x1 as usize, y0 as usize, y1 as usize],
                material: tri.material,
                shade: tri.shade,
                src: idx as u32,
                tex: [tex.0 as f64, tex.1 as f64],
            });
        }
    }
    out
}

/// The sample columns of row `fy` that can lie inside the triangle: the
/// three barycentric half-planes cut the row to an interval (one sample of
/// margin; the exact test is still made per sample).
fn row_span(st: &Setup, fy: f64, x0: usize, x1: usize) -> Option<(usize, usize)> {
    let (mut lo, mut hi) = (x0 as f64 + 0.5, x1 as f64 + 0.5);
    let b0 = [
        -st.b1[0] - st.b2[0],
        -st.b1[1] - st.b2[1],
        1.0 - st.b1[2] - st.b2[2],
    ];
    for p in [&st.b1, &st.b2, &b0] {
        let (a, c) = (p[0], p[1] * fy + p[2]);
        if a > 1e-12 {
            lo = lo.max(-c / a);
        } else if a < -1e-12 {
            hi = hi.min(-c / a);
        } else if c < -1e-9 {
            return None;
        }
    }
    // Also rejects NaN bounds.
    if lo.is_nan() || hi.is_nan() || lo > hi + 1.0 {
        return None;
    }
    let xa = ((lo - 1.5).ceil().max(x0 as f64)) as usize;
    let xb = ((hi + 0.5).floor().min(x1 as f64)) as usize;
    (xa <= xb).then_some((xa, xb))
}

/// Rasterise `setups` into `buf` (a `ws`×`hs` sample grid, row-major) with a
/// depth test. With `limit`, a sample is only written where it is also
/// nearer than `limit` (used to draw distractors over the static world).
pub fn rasterize(setups: &[Setup], buf: &mut [Sample], ws: usize, limit: Option<&[Sample]>) {
    // Front to back, so the depth test rejects hidden samples early; the
    // result does not depend on the order except for exact depth ties,
    // which the stable sort resolves deterministically.
    let mut order: Vec<usize> = (0..setups.len()).collect();
    order.sort_by(|a, b| setups[*a].zmin.total_cmp(&setups[*b].zmin));
    buf.par_chunks_mut(ws * BAND)
        .enumerate()
        .for_each(|(band, chunk)| {
            let row0 = band * BAND;
            let rows = chunk.len() / ws;
            for &id in &order {
                let st = &setups[id];
                let [x0, x1, y0, y1] = st.bounds;
                let (ya, yb) = (y0.max(row0), y1.min(row0 + rows - 1));
                if ya > yb {
                    continue;
                }
                for y in ya..=yb {
                    let fy = y as f64 + 0.5;
                    let Some((xa, xb)) = row_span(st, fy, x0, x1) else {
                        continue;
                    };
                    for x in xa..=xb {
                        let fx = x as f64 + 0.5;
                        let b1 = eval(&st.b1, fx, fy);
                        let b2 = eval(&st.b2, fx, fy);
                        if b1 < -1e-9 || b2 < -1e-9 || b1 + b2 > 1.0 + 1e-9 {
                            continue;
                        }
                        let iz = eval(&st.iz, fx, fy);
                        if iz <= 0.0 {
                            continue;
                        }
                        let z = (1.0 / iz) as f32;
                        let i = (y - row0) * ws + x;
                        if z >= chunk[i].depth {
                            continue;
                        }
                        if let Some(l) = limit
                            && z >= l[y * ws + x].depth
                        {
                            continue;
                        }
                        let u = eval(&st.uz, fx, fy) / iz;
                        let v = eval(&st.vz, fx, fy) / iz;
                        chunk[i] = Sample {
                            depth: z,
                            tri: id as u32,
                            u: u as f32,
                            v: v as f32,
                        };
                    }
                }
            }
        });
}

/// A fresh, empty sample buffer for `view`.
pub fn new_buffer(view: &View) -> Vec<Sample> {
    let (ws, hs) = view.sample_dims();
    vec![Sample::EMPTY; ws * hs]
}

/// Colour of the sky in the direction of sample (sx, sy): a vertical gradient.
fn sky(view: &View, rt: &Matrix3<f64>, sx: usize, sy: usize) -> Rgb {
    let s = view.ss as f64;
    let k = view.intr;
    let d = Vector3::new(
        ((sx as f64 + 0.5) / s - k.cx) / k.fx,
        ((sy as f64 + 0.5) / s - k.cy) / k.fy,
        1.0,
    );
    let w = rt * d;
    let e = (w.z / w.norm()).clamp(0.0, 1.0) as f32;
    [0.80 - 0.40 * e, 0.85 - 0.28 * e, 0.92 - 0.05 * e]
}

/// log2 to about 0.01 from the float's exponent and a quadratic in the mantissa.
fn fast_log2(x: f32) -> f32 {
    let b = x.max(1e-30).to_bits();
    let e = ((b >> 23) & 0xFF) as f32 - 127.0;
    let m = f32::from_bits((b & 0x007F_FFFF) | 0x3F80_0000);
    e + (-0.344_848_43 * m + 2.024_665_8) * m - 1.674_877_6
}

/// Mip level of a sample at sample coordinates (fx, fy): log2 of the larger
/// texel footprint, from d(u)/dx = (d(u/z)/dx − u · d(1/z)/dx) / (1/z).
fn lod(st: &Setup, s: &Sample) -> f32 {
    let iz = 1.0 / s.depth as f64;
    let (u, v) = (s.u as f64, s.v as f64);
    let dudx = (st.uz[0] - u * st.iz[0]) / iz * st.tex[0];
    let dvdx = (st.vz[0] - v * st.iz[0]) / iz * st.tex[1];
    let dudy = (st.uz[1] - u * st.iz[1]) / iz * st.tex[0];
    let dvdy = (st.vz[1] - v * st.iz[1]) / iz * st.tex[1];
    let rho2 = (dudx * dudx + dvdx * dvdx).max(dudy * dudy + dvdy * dvdy);
    0.5 * fast_log2(rho2 as f32)
}

fn shade(s: &Sample, setups: &[Setup], textures: &[Texture]) -> Option<Rgb> {
    let st = setups.get(s.tri as usize)?;
    let tex = textures.get(st.material as usize)?;
    let c = tex.sample(s.u, s.v, lod(st, s));
    Some([c[0] * st.shade, c[1] * st.shade, c[2] * st.shade])
}

/// One rendered frame at output resolution.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// The static world only (RGB8, row-major).
    pub clean: Vec<u8>,
    /// The static world with the distractors composited over it.
    pub frame: Vec<u8>,
    /// Per pixel, how many of the `ss²` samples show a distractor.
    pub coverage: Vec<u16>,
}

/// The two passes of a frame: the static world and the distractors.
pub struct Passes<'a> {
    pub static_buf: &'a [Sample],
    pub static_setups: &'a [Setup],
    pub dyn_buf: &'a [Sample],
    pub dyn_setups: &'a [Setup],
    pub textures: &'a [Texture],
}

fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Shade every sample and box-filter each `ss`×`ss` block to a pixel.
pub fn resolve(view: &View, p: &Passes) -> Resolved {
    let (w, h) = (view.intr.width as usize, view.intr.height as usize);
    let s = view.ss as usize;
    let ws = w * s;
    let rt = view.pose.rotation().transpose();
    let mut clean = vec![0u8; w * h * 3];
    let mut frame = vec![0u8; w * h * 3];
    let mut coverage = vec![0u16; w * h];
    let norm = 1.0 / (s * s) as f32;
    clean
        .par_chunks_mut(w * 3)
        .zip(frame.par_chunks_mut(w * 3))
        .zip(coverage.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, ((crow, frow), cov))| {
            for x in 0..w {
                let (mut c, mut f, mut n) = ([0.0f32; 3], [0.0f32; 3], 0u16);
                for sy in y * s..(y + 1) * s {
                    for sx in x * s..(x + 1) * s {
                        let i = sy * ws + sx;
                        let sc = shade(&p.static_buf[i], p.static_setups, p.textures)
                            .unwrap_or_else(|| sky(view, &rt, sx, sy));
                        let fc = match shade(&p.dyn_buf[i], p.dyn_setups, p.textures) {
                            Some(d) => {
                                n += 1;
                                d
                            }
                            None => sc,
                        };
                        for k in 0..3 {
                            c[k] += sc[k];
                            f[k] += fc[k];
                        }
                    }
                }
                for k in 0..3 {
                    crow[x * 3 + k] = to_u8(c[k] * norm);
                    frow[x * 3 + k] = to_u8(f[k] * norm);
                }
                cov[x] = n;
            }
        });
    Resolved {
        clean,
        frame,
        coverage,
    }
}
