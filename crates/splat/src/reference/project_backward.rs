//! Reference backward of the projection (INRIA `backward.cu`
//! `computeCov2DCUDA` / `preprocessCUDA`, gsplat `proj_bwd`), generic over
//! f32/f64: from dL/d(mean2d, conic, opacity, colour) of each projected splat
//! to dL/d(means, log-scales, quaternions, opacity logits, SH).
//!
//! It recomputes the forward intermediates with [`project_one`] and applies
//! the chain rule exactly for the forward as written, including: zero
//! gradient through a colour channel clamped at 0, the true derivative of the
//! clamped Jacobian (x/z clamped ⇒ no gradient through x in J, as gsplat),
//! the antialiasing compensation, the quaternion normalisation and the view
//! direction of the SH. Culled splats get zero gradients.

use super::project::{CamT, Inter, ProjectedT, project_one};
use super::rasterize_backward::ProjGradT;
use super::real::Real;
use super::sh;
use crate::types::{ProjectedGrads, RenderCamera, RenderOptions, SplatGrads, Splats};
use rayon::prelude::*;

/// Parameter gradients in precision `T` (layout of [`Splats`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SplatGradsT<T> {
    pub means: Vec<[T; 3]>,
    pub log_scales: Vec<[T; 3]>,
    pub rotations: Vec<[T; 4]>,
    pub opacity_logits: Vec<T>,
    pub sh: Vec<T>,
}

#[derive(Debug, Clone, Copy, Default)]
struct One<T> {
    mean: [T; 3],
    log_scale: [T; 3],
    rot: [T; 4],
    logit: T,
}

type M3<T> = [[T; 3]; 3];

fn backward_one<T: Real>(
    splats: &Splats,
    i: usize,
    cam: &CamT<T>,
    opts: &RenderOptions,
    v: &ProjGradT<T>,
    v_sh: &mut [T],
) -> One<T> {
    let mut o = One::<T>::default();
    let Some((p, it)) = project_one(splats, i, cam, opts) else {
        return o;
    };
    o.mean = colour_backward(splats, i, opts, &it, v.color, v_sh);
    // Opacity.
    let s = it.sigmoid;
    o.logit = v.opacity * it.comp * s * (T::c(1.0) - s);
    let v2 = cov2d_backward(&p, &it, opts, v.conic, v.opacity * s);
    let (v3, v_j) = projection_cov_backward(cam, &it, &v2);
    let v_mean = mean_backward(cam, &it, v.mean2d, &v_j);
    for a in 0..3 {
        o.mean[a] += v_mean[a];
    }
    let v_r;
    (v_r, o.log_scale) = cov3d_backward(&it, &v3);
    o.rot = rotation_backward(&it, &v_r);
    o
}

/// Colour → SH coefficients (into `v_sh`) and view direction; returns the
/// direction's gradient on the mean. A channel clamped at 0 passes none.
fn colour_backward<T: Real>(
    splats: &Splats,
    i: usize,
    opts: &RenderOptions,
    it: &Inter<T>,
    v_color: [T; 3],
    v_sh: &mut [T],
) -> [T; 3] {
    let z0 = T::default();
    let k_stored = splats.coeffs_per_channel();
    let sh_block = &splats.sh[i * k_stored * 3..(i + 1) * k_stored * 3];
    let deg = opts.sh_degree.min(splats.sh_degree);
    let mut vc = v_color;
    for ch in 0..3 {
        if it.color_clamped[ch] {
            vc[ch] = z0;
        }
    }
    let n = sh::sh_count(deg);
    let bg = sh::basis_grad(deg, it.dir);
    let mut v_dir = [z0; 3];
    for k in 0..n {
        for ch in 0..3 {
            v_sh[k * 3 + ch] = it.basis[k] * vc[ch];
            let w = T::f(sh_block[k * 3 + ch]) * vc[ch];
            for a in 0..3 {
                v_dir[a] += w * bg[k][a];
            }
        }
    }
    let mut v_mean = [z0; 3];
    if it.dist > z0 {
        let dd = it.dir[0] * v_dir[0] + it.dir[1] * v_dir[1] + it.dir[2] * v_dir[2];
        for a in 0..3 {
            v_mean[a] = (v_dir[a] - it.dir[a] * dd) / it.dist;
        }
    }
    v_mean
}

/// Conic → dilated 2D covariance, dL/dΣ' = −C G C with G = [[va, vb/2],
/// [vb/2, vc]], plus the antialiasing compensation comp = sqrt(det0 / det')
/// (whose gradient is `v_comp`): dL/dΣ2.
fn cov2d_backward<T: Real>(
    p: &ProjectedT<T>,
    it: &Inter<T>,
    opts: &RenderOptions,
    v_conic: [T; 3],
    v_comp: T,
) -> [[T; 2]; 2] {
    let z0 = T::default();
    let c = [[p.conic[0], p.conic[1]], [p.conic[1], p.conic[2]]];
    let half = T::c(0.5);
    let g = [
        [v_conic[0], half * v_conic[1]],
        [half * v_conic[1], v_conic[2]],
    ];
    let mut cg = [[z0; 2]; 2];
    let mut v2 = [[z0; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            cg[a][b] = c[a][0] * g[0][b] + c[a][1] * g[1][b];
        }
    }
    for a in 0..2 {
        for b in 0..2 {
            v2[a][b] = -(cg[a][0] * c[0][b] + cg[a][1] * c[1][b]);
        }
    }
    if opts.antialiased && it.comp > z0 {
        let [a0, b0, c0] = it.cov2d;
        let det0 = a0 * c0 - b0 * b0;
        let lp = T::f(opts.low_pass);
        let d1 = it.det;
        let k = v_comp / (T::c(2.0) * it.comp) / (d1 * d1);
        v2[0][0] += k * (c0 * d1 - det0 * (c0 + lp));
        v2[1][1] += k * (a0 * d1 - det0 * (a0 + lp));
        let off = k * (-b0 * d1 + det0 * b0);
        v2[0][1] += off;
        v2[1][0] += off;
    }
    v2
}

/// Σ2 = T Σ3 Tᵀ with T = J W: from dL/dΣ2 to dL/dΣ3 and dL/dJ = dL/dT Wᵀ.
fn projection_cov_backward<T: Real>(
    cam: &CamT<T>,
    it: &Inter<T>,
    v2: &[[T; 2]; 2],
) -> (M3<T>, [[T; 3]; 2]) {
    let z0 = T::default();
    let t = &it.jw;
    let mut t_s = [[z0; 3]; 2]; // T Σ3
    for a in 0..2 {
        for b in 0..3 {
            t_s[a][b] =
                t[a][0] * it.cov3d[0][b] + t[a][1] * it.cov3d[1][b] + t[a][2] * it.cov3d[2][b];
        }
    }
    let mut v_t = [[z0; 3]; 2];
    for a in 0..2 {
        for b in 0..3 {
            v_t[a][b] = (v2[a][0] + v2[0][a]) * t_s[0][b] + (v2[a][1] + v2[1][a]) * t_s[1][b];
        }
    }
    let mut v3: M3<T> = [[z0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            let mut acc = z0;
            for x in 0..2 {
                for y in 0..2 {
                    acc += t[x][a] * v2[x][y] * t[y][b];
                }
            }
            v3[a][b] = acc;
        }
    }
    let w = &cam.rot;
    let mut v_j = [[z0; 3]; 2];
    for a in 0..2 {
        for b in 0..3 {
            v_j[a][b] = v_t[a][0] * w[b][0] + v_t[a][1] * w[b][1] + v_t[a][2] * w[b][2];
        }
    }
    (v3, v_j)
}

/// The mean's gradient through the camera-space point: from the projected
/// centre and from the (clamped) Jacobian J.
fn mean_backward<T: Real>(
    cam: &CamT<T>,
    it: &Inter<T>,
    v_mean2d: [T; 2],
    v_j: &[[T; 3]; 2],
) -> [T; 3] {
    let z0 = T::default();
    let [tx, ty, tz] = it.p_cam;
    let mut v_pc = [z0; 3];
    let (fx, fy) = (cam.fx, cam.fy);
    let tz2 = tz * tz;
    // mean2d = (fx x/z + cx, fy y/z + cy).
    v_pc[0] += fx / tz * v_mean2d[0];
    v_pc[1] += fy / tz * v_mean2d[1];
    v_pc[2] += -(fx * tx * v_mean2d[0] + fy * ty * v_mean2d[1]) / tz2;
    // J00 = fx/z, J11 = fy/z, J02 = −fx·clamp(x/z)/z, J12 = −fy·clamp(y/z)/z.
    v_pc[2] += -(fx * v_j[0][0] + fy * v_j[1][1]) / tz2;
    let cxz = (tx / tz).max(-cam.lim[0]).min(cam.lim[0]);
    let cyz = (ty / tz).max(-cam.lim[1]).min(cam.lim[1]);
    if it.clamped_xy[0] {
        v_pc[2] += fx * cxz / tz2 * v_j[0][2];
    } else {
        v_pc[0] += -fx / tz2 * v_j[0][2];
        v_pc[2] += T::c(2.0) * fx * tx / (tz2 * tz) * v_j[0][2];
    }
    if it.clamped_xy[1] {
        v_pc[2] += fy * cyz / tz2 * v_j[1][2];
    } else {
        v_pc[1] += -fy / tz2 * v_j[1][2];
        v_pc[2] += T::c(2.0) * fy * ty / (tz2 * tz) * v_j[1][2];
    }
    let w = &cam.rot;
    let mut v_mean = [z0; 3];
    for a in 0..3 {
        v_mean[a] = w[0][a] * v_pc[0] + w[1][a] * v_pc[1] + w[2][a] * v_pc[2];
    }
    v_mean
}

/// Σ3 = M Mᵀ with M = R S: dL/dR and dL/d(log-scales).
fn cov3d_backward<T: Real>(it: &Inter<T>, v3: &M3<T>) -> (M3<T>, [T; 3]) {
    let z0 = T::default();
    let r = &it.rot;
    let mut m: M3<T> = *r;
    for row in m.iter_mut() {
        for (j, x) in row.iter_mut().enumerate() {
            *x *= it.scale[j];
        }
    }
    let mut v_m: M3<T> = [[z0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            for k in 0..3 {
                v_m[a][b] += (v3[a][k] + v3[k][a]) * m[k][b];
            }
        }
    }
    let mut v_r: M3<T> = [[z0; 3]; 3];
    let mut v_log_scale = [z0; 3];
    for a in 0..3 {
        for j in 0..3 {
            v_r[a][j] = v_m[a][j] * it.scale[j];
            v_log_scale[j] += v_m[a][j] * r[a][j] * it.scale[j];
        }
    }
    (v_r, v_log_scale)
}

/// R(q̂) → q̂ → q (through the normalisation).
fn rotation_backward<T: Real>(it: &Inter<T>, vr: &M3<T>) -> [T; 4] {
    let [qw, qx, qy, qz] = it.qn;
    let two = T::c(2.0);
    let vq = [
        two * (-qz * vr[0][1] + qy * vr[0][2] + qz * vr[1][0] - qx * vr[1][2] - qy * vr[2][0]
            + qx * vr[2][1]),
        two * (qy * vr[0][1] + qz * vr[0][2] + qy * vr[1][0] - two * qx * vr[1][1] - qw * vr[1][2]
            + qz * vr[2][0]
            + qw * vr[2][1]
            - two * qx * vr[2][2]),
        two * (-two * qy * vr[0][0]
            + qx * vr[0][1]
            + qw * vr[0][2]
            + qx * vr[1][0]
            + qz * vr[1][2]
            - qw * vr[2][0]
            + qz * vr[2][1]
            - two * qy * vr[2][2]),
        two * (-two * qz * vr[0][0] - qw * vr[0][1] + qx * vr[0][2] + qw * vr[1][0]
            - two * qz * vr[1][1]
            + qy * vr[1][2]
            + qx * vr[2][0]
            + qy * vr[2][1]),
    ];
    let dq = qw * vq[0] + qx * vq[1] + qy * vq[2] + qz * vq[3];
    let mut rot = [T::default(); 4];
    for a in 0..4 {
        rot[a] = (vq[a] - it.qn[a] * dq) / it.qnorm;
    }
    rot
}

/// Backward in precision `T`.
pub fn project_backward_t<T: Real>(
    splats: &Splats,
    cam: &RenderCamera,
    opts: &RenderOptions,
    v_proj: &[ProjGradT<T>],
) -> SplatGradsT<T> {
    let c = CamT::<T>::new(cam);
    let k3 = splats.coeffs_per_channel() * 3;
    let mut sh = vec![T::default(); splats.sh.len()];
    let ones: Vec<One<T>> = sh
        .par_chunks_mut(k3.max(1))
        .enumerate()
        .map(|(i, v_sh)| backward_one(splats, i, &c, opts, &v_proj[i], v_sh))
        .collect();
    SplatGradsT {
        means: ones.iter().map(|o| o.mean).collect(),
        log_scales: ones.iter().map(|o| o.log_scale).collect(),
        rotations: ones.iter().map(|o| o.rot).collect(),
        opacity_logits: ones.iter().map(|o| o.logit).collect(),
        sh,
    }
}

/// Backward of [`super::project::project`] (f32), the reference for the GPU
/// `project_backward` kernel. `mean2d_abs` holds ‖dL/d mean2d‖ (pixels).
pub fn project_backward(
    splats: &Splats,
    cam: &RenderCamera,
    opts: &RenderOptions,
    v_proj: &[ProjectedGrads],
) -> SplatGrads {
    let v: Vec<ProjGradT<f32>> = v_proj.iter().map(ProjGradT::from).collect();
    let g = project_backward_t(splats, cam, opts, &v);
    SplatGrads {
        means: g.means,
        log_scales: g.log_scales,
        rotations: g.rotations,
        opacity_logits: g.opacity_logits,
        sh: g.sh,
        mean2d_abs: v_proj
            .iter()
            .map(|p| p.mean2d[0].hypot(p.mean2d[1]))
            .collect(),
    }
}
