//! Reference projection of 3D Gaussians to 2D EWA splats (Zwicker et al.
//! 2001; Kerbl et al. 2023 §4 and INRIA `forward.cu` `preprocessCUDA` /
//! `computeCov2D`), in plain Rust, generic over f32/f64.
//!
//! Per splat: Σ = R S² Rᵀ from the normalised quaternion and exp(log-scale);
//! camera-space mean t = W·μ + t_cam; Jacobian J of the perspective projection
//! at t with t.x/t.z and t.y/t.z clamped to ±1.3·tan(fov/2) (INRIA), where
//! tan(fovx/2) = width / (2 fx); Σ' = J W Σ Wᵀ Jᵀ + low_pass·I; conic = Σ'⁻¹;
//! radius = ceil(3·sqrt(λ_max)) with λ_max = mid + sqrt(max(0.1, mid² − det));
//! tile extents (gsplat's opacity-aware per-axis bounds, used only for tile
//! binning): with o the final opacity, a Gaussian reaches α ≥ 1/255 only
//! within Mahalanobis distance sqrt(2·ln(255·o)), so with
//! k = min(3, sqrt(2·ln(255·o))) the extents are ceil(k·sqrt(Σ'ₓₓ)) and
//! ceil(k·sqrt(Σ'ᵧᵧ)) pixels (0, no tiles, when 255·o ≤ 1), at most
//! [`MAX_EXTENT`]; they travel packed in `ProjectedSplat::tile_extent` ([`pack_extent`]);
//! colour from SH (+0.5, clamped at 0); opacity = sigmoid(logit), times
//! sqrt(max(0, det(Σ'−low_pass·I)/det(Σ'))) in antialiased mode (Mip-Splatting
//! / gsplat). Pixel centres are at integer + 0.5, so mean2d = f·x/z + c.
//!
//! A splat is culled (every output field zero, radius 0) when any input is
//! not finite, its quaternion is zero, depth < near or > far, the 2D
//! covariance is not positive definite, it lies entirely off-screen, or any
//! output is not finite. The GPU kernel follows the same rules.

use super::real::{Real, sigmoid};
use super::sh;
use crate::types::{ProjectedSplat, RenderCamera, RenderOptions, Splats};
use rayon::prelude::*;

/// INRIA's frustum factor for clamping the Jacobian's x/z and y/z.
pub const JACOBIAN_CLAMP: f64 = 1.3;

/// A projected splat in precision `T` (same fields as [`ProjectedSplat`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ProjectedT<T> {
    pub mean2d: [T; 2],
    pub depth: T,
    pub radius: T,
    pub conic: [T; 3],
    pub opacity: T,
    pub color: [T; 3],
    /// Tile-binning half extents in pixels (x, y), integers ≤ [`MAX_EXTENT`];
    /// 0 = no tiles.
    pub extent: [T; 2],
}

/// Largest tile extent in pixels (far beyond any image; the packed pair
/// also stays a finite f32 bit pattern, as it was when the field was f32).
pub const MAX_EXTENT: u32 = 0x7f7f;

/// Pack per-axis tile extents into `ProjectedSplat::tile_extent`
/// (x in the low 16 bits, y in the high 16 bits), as `common.wgsl` reads them.
pub fn pack_extent(e: [f32; 2]) -> u32 {
    let c = |v: f32| (v.max(0.0) as u32).min(MAX_EXTENT);
    c(e[0]) | (c(e[1]) << 16)
}

/// Inverse of [`pack_extent`].
pub fn unpack_extent(b: u32) -> [f32; 2] {
    [(b & 0xffff) as f32, (b >> 16) as f32]
}

/// Opacity-aware per-axis tile extents of a splat with dilated 2D covariance
/// diagonal (`sxx`, `syy`) and final opacity `o` (see the module header).
pub fn tile_extent<T: Real>(sxx: T, syy: T, o: T) -> [T; 2] {
    let z0 = T::default();
    let th = T::c(255.0) * o;
    if !(th > T::c(1.0)) {
        return [z0, z0];
    }
    let k = (T::c(2.0) * th.ln()).sqrt().min(T::c(3.0));
    let cap = T::c(MAX_EXTENT as f64);
    let e = |s: T| (k * s.max(z0).sqrt()).ceil().min(cap);
    [e(sxx), e(syy)]
}

impl From<ProjectedT<f32>> for ProjectedSplat {
    fn from(p: ProjectedT<f32>) -> Self {
        ProjectedSplat {
            mean2d: p.mean2d,
            depth: p.depth,
            radius: p.radius,
            conic: p.conic,
            opacity: p.opacity,
            color: p.color,
            tile_extent: pack_extent(p.extent),
        }
    }
}

impl From<&ProjectedSplat> for ProjectedT<f32> {
    fn from(p: &ProjectedSplat) -> Self {
        ProjectedT {
            mean2d: p.mean2d,
            depth: p.depth,
            radius: p.radius,
            conic: p.conic,
            opacity: p.opacity,
            color: p.color,
            extent: unpack_extent(p.tile_extent),
        }
    }
}

/// Camera in precision `T`.
#[derive(Debug, Clone, Copy)]
pub struct CamT<T> {
    pub width: u32,
    pub height: u32,
    pub fx: T,
    pub fy: T,
    pub cx: T,
    pub cy: T,
    pub rot: [[T; 3]; 3],
    pub trans: [T; 3],
    pub center: [T; 3],
    pub near: T,
    pub far: T,
    /// 1.3·tan(fovx/2) and 1.3·tan(fovy/2).
    pub lim: [T; 2],
}

impl<T: Real> CamT<T> {
    pub fn new(c: &RenderCamera) -> Self {
        let rot = c.rotation.map(|r| r.map(T::f));
        let trans = c.translation.map(T::f);
        let mut center = [T::default(); 3];
        for (j, cj) in center.iter_mut().enumerate() {
            *cj = -(rot[0][j] * trans[0] + rot[1][j] * trans[1] + rot[2][j] * trans[2]);
        }
        let clamp = T::c(JACOBIAN_CLAMP);
        CamT {
            width: c.width,
            height: c.height,
            fx: T::f(c.fx),
            fy: T::f(c.fy),
            cx: T::f(c.cx),
            cy: T::f(c.cy),
            rot,
            trans,
            center,
            near: T::f(c.near),
            far: T::f(c.far),
            lim: [
                clamp * T::c(c.width as f64) / (T::c(2.0) * T::f(c.fx)),
                clamp * T::c(c.height as f64) / (T::c(2.0) * T::f(c.fy)),
            ],
        }
    }
}

/// Everything the forward computes for one splat that the backward reuses.
#[derive(Debug, Clone, Copy, Default)]
pub struct Inter<T> {
    pub p_cam: [T; 3],
    /// Normalised quaternion (w, x, y, z) and the norm of the raw one.
    pub qn: [T; 4],
    pub qnorm: T,
    pub rot: [[T; 3]; 3],
    pub scale: [T; 3],
    pub cov3d: [[T; 3]; 3],
    /// T = J·W (2×3).
    pub jw: [[T; 3]; 2],
    /// Whether t.x/t.z, t.y/t.z were clamped.
    pub clamped_xy: [bool; 2],
    /// Undilated 2D covariance (a, b, c).
    pub cov2d: [T; 3],
    /// Dilated determinant.
    pub det: T,
    /// Antialiasing compensation (1 when off).
    pub comp: T,
    pub sigmoid: T,
    /// Unit view direction and the distance it was normalised by.
    pub dir: [T; 3],
    pub dist: T,
    pub basis: [T; 16],
    /// Colour channels clamped at 0 (zero gradient).
    pub color_clamped: [bool; 3],
}

/// Rotation matrix of a unit quaternion (w, x, y, z).
pub fn quat_to_rot<T: Real>(q: [T; 4]) -> [[T; 3]; 3] {
    let [w, x, y, z] = q;
    let one = T::c(1.0);
    let two = T::c(2.0);
    [
        [
            one - two * (y * y + z * z),
            two * (x * y - w * z),
            two * (x * z + w * y),
        ],
        [
            two * (x * y + w * z),
            one - two * (x * x + z * z),
            two * (y * z - w * x),
        ],
        [
            two * (x * z - w * y),
            two * (y * z + w * x),
            one - two * (x * x + y * y),
        ],
    ]
}

fn all_finite(xs: &[f32]) -> bool {
    xs.iter().all(|x| x.is_finite())
}

/// Project splat `i`; `None` when culled.
pub fn project_one<T: Real>(
    splats: &Splats,
    i: usize,
    cam: &CamT<T>,
    opts: &RenderOptions,
) -> Option<(ProjectedT<T>, Inter<T>)> {
    let k_stored = splats.coeffs_per_channel();
    let sh_block = splats.sh.get(i * k_stored * 3..(i + 1) * k_stored * 3)?;
    let (m, ls, q) = (splats.means[i], splats.log_scales[i], splats.rotations[i]);
    let logit = splats.opacity_logits[i];
    if !(all_finite(&m) && all_finite(&ls) && all_finite(&q) && logit.is_finite()) {
        return None;
    }
    let mut it = Inter::<T>::default();
    let mw = m.map(T::f);
    let r = &cam.rot;
    for (a, pa) in it.p_cam.iter_mut().enumerate() {
        *pa = r[a][0] * mw[0] + r[a][1] * mw[1] + r[a][2] * mw[2] + cam.trans[a];
    }
    let [tx, ty, tz] = it.p_cam;
    if !tz.is_finite() || tz < cam.near || tz > cam.far {
        return None;
    }
    // 3D covariance.
    let qt = q.map(T::f);
    let n2 = qt[0] * qt[0] + qt[1] * qt[1] + qt[2] * qt[2] + qt[3] * qt[3];
    if !(n2 > T::default()) || !n2.is_finite() {
        return None;
    }
    it.qnorm = n2.sqrt();
    it.qn = qt.map(|v| v / it.qnorm);
    it.rot = quat_to_rot(it.qn);
    it.scale = ls.map(|v| T::f(v).exp());
    let mut rs = it.rot;
    for row in rs.iter_mut() {
        for (j, v) in row.iter_mut().enumerate() {
            *v *= it.scale[j];
        }
    }
    for a in 0..3 {
        for b in 0..3 {
            it.cov3d[a][b] = rs[a][0] * rs[b][0] + rs[a][1] * rs[b][1] + rs[a][2] * rs[b][2];
        }
    }
    // Jacobian with INRIA clamping.
    let (xz, yz) = (tx / tz, ty / tz);
    let cx_ = xz.max(-cam.lim[0]).min(cam.lim[0]);
    let cy_ = yz.max(-cam.lim[1]).min(cam.lim[1]);
    it.clamped_xy = [cx_ != xz, cy_ != yz];
    let z0 = T::default();
    let j = [
        [cam.fx / tz, z0, -cam.fx * cx_ / tz],
        [z0, cam.fy / tz, -cam.fy * cy_ / tz],
    ];
    for a in 0..2 {
        for b in 0..3 {
            it.jw[a][b] = j[a][0] * r[0][b] + j[a][1] * r[1][b] + j[a][2] * r[2][b];
        }
    }
    let mut tmp = [[z0; 3]; 2];
    for a in 0..2 {
        for b in 0..3 {
            tmp[a][b] = it.jw[a][0] * it.cov3d[0][b]
                + it.jw[a][1] * it.cov3d[1][b]
                + it.jw[a][2] * it.cov3d[2][b];
        }
    }
    let dot = |u: &[T; 3], v: &[T; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    it.cov2d = [
        dot(&tmp[0], &it.jw[0]),
        dot(&tmp[0], &it.jw[1]),
        dot(&tmp[1], &it.jw[1]),
    ];
    let lp = T::f(opts.low_pass);
    let (a, b, c) = (it.cov2d[0] + lp, it.cov2d[1], it.cov2d[2] + lp);
    it.det = a * c - b * b;
    if !(it.det > z0) || !it.det.is_finite() {
        return None;
    }
    let conic = [c / it.det, -b / it.det, a / it.det];
    let mid = T::c(0.5) * (a + c);
    let lambda = mid + (mid * mid - it.det).max(T::c(0.1)).sqrt();
    let radius = (T::c(3.0) * lambda.sqrt()).ceil();
    let mean2d = [cam.fx * xz + cam.cx, cam.fy * yz + cam.cy];
    let (w, h) = (T::c(cam.width as f64), T::c(cam.height as f64));
    if !(radius > z0)
        || mean2d[0] + radius <= z0
        || mean2d[0] - radius >= w
        || mean2d[1] + radius <= z0
        || mean2d[1] - radius >= h
    {
        return None;
    }
    it.comp = if opts.antialiased {
        let det0 = it.cov2d[0] * it.cov2d[2] - it.cov2d[1] * it.cov2d[1];
        (det0 / it.det).max(z0).sqrt()
    } else {
        T::c(1.0)
    };
    it.sigmoid = sigmoid(T::f(logit));
    // Colour.
    let mut d = [z0; 3];
    for (a, da) in d.iter_mut().enumerate() {
        *da = mw[a] - cam.center[a];
    }
    it.dist = dot(&d, &d).sqrt();
    it.dir = if it.dist > z0 {
        d.map(|v| v / it.dist)
    } else {
        [z0, z0, T::c(1.0)]
    };
    let deg = opts.sh_degree.min(splats.sh_degree);
    it.basis = sh::basis(deg, it.dir);
    let raw = sh::eval(deg, &it.basis, sh_block);
    let mut color = [z0; 3];
    for ch in 0..3 {
        let v = raw[ch] + T::c(0.5);
        it.color_clamped[ch] = v < z0;
        color[ch] = v.max(z0);
    }
    let opacity = it.sigmoid * it.comp;
    let p = ProjectedT {
        mean2d,
        depth: tz,
        radius,
        conic,
        opacity,
        color,
        extent: tile_extent(a, c, opacity),
    };
    let ok = p
        .mean2d
        .iter()
        .chain(&p.conic)
        .chain(&p.color)
        .all(|v| v.is_finite())
        && p.opacity.is_finite()
        && p.radius.is_finite();
    ok.then_some((p, it))
}

/// Project every splat in precision `T` (culled splats are all-zero).
pub fn project_t<T: Real>(
    splats: &Splats,
    cam: &RenderCamera,
    opts: &RenderOptions,
) -> Vec<ProjectedT<T>> {
    let c = CamT::<T>::new(cam);
    (0..splats.len())
        .into_par_iter()
        .map(|i| {
            project_one(splats, i, &c, opts)
                .map(|(p, _)| p)
                .unwrap_or_default()
        })
        .collect()
}

/// Project every splat (f32), the reference for the GPU `project` kernel.
pub fn project(splats: &Splats, cam: &RenderCamera, opts: &RenderOptions) -> Vec<ProjectedSplat> {
    project_t::<f32>(splats, cam, opts)
        .into_iter()
        .map(ProjectedSplat::from)
        .collect()
}
