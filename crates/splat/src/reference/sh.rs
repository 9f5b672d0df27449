//! Real spherical harmonics up to degree 3 for view-dependent colour, with the
//! constants and sign conventions of INRIA 3DGS (`forward.cu`
//! `computeColorFromSH`, `backward.cu` `computeColorFromSH`): colour =
//! Σ_k basis_k(dir) · sh_k + 0.5, clamped at 0 from below.

use super::real::Real;

pub const SH_C0: f64 = 0.282_094_791_773_878_14;
pub const SH_C1: f64 = 0.488_602_511_902_919_9;
pub const SH_C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
pub const SH_C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// The SH basis values for a unit direction, `(degree+1)²` entries (rest 0).
pub fn basis<T: Real>(degree: u32, d: [T; 3]) -> [T; 16] {
    let mut b = [T::default(); 16];
    b[0] = T::c(SH_C0);
    if degree == 0 {
        return b;
    }
    let [x, y, z] = d;
    let c1 = T::c(SH_C1);
    b[1] = -c1 * y;
    b[2] = c1 * z;
    b[3] = -c1 * x;
    if degree == 1 {
        return b;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    b[4] = T::c(SH_C2[0]) * xy;
    b[5] = T::c(SH_C2[1]) * yz;
    b[6] = T::c(SH_C2[2]) * (T::c(2.0) * zz - xx - yy);
    b[7] = T::c(SH_C2[3]) * xz;
    b[8] = T::c(SH_C2[4]) * (xx - yy);
    if degree == 2 {
        return b;
    }
    b[9] = T::c(SH_C3[0]) * y * (T::c(3.0) * xx - yy);
    b[10] = T::c(SH_C3[1]) * xy * z;
    b[11] = T::c(SH_C3[2]) * y * (T::c(4.0) * zz - xx - yy);
    b[12] = T::c(SH_C3[3]) * z * (T::c(2.0) * zz - T::c(3.0) * xx - T::c(3.0) * yy);
    b[13] = T::c(SH_C3[4]) * x * (T::c(4.0) * zz - xx - yy);
    b[14] = T::c(SH_C3[5]) * z * (xx - yy);
    b[15] = T::c(SH_C3[6]) * x * (xx - T::c(3.0) * yy);
    b
}

/// Jacobian of [`basis`] w.r.t. the direction: `out[k] = d basis_k / d(x,y,z)`.
pub fn basis_grad<T: Real>(degree: u32, d: [T; 3]) -> [[T; 3]; 16] {
    let z0 = T::default();
    let mut g = [[z0; 3]; 16];
    if degree == 0 {
        return g;
    }
    let [x, y, z] = d;
    let c1 = T::c(SH_C1);
    g[1] = [z0, -c1, z0];
    g[2] = [z0, z0, c1];
    g[3] = [-c1, z0, z0];
    if degree == 1 {
        return g;
    }
    let two = T::c(2.0);
    let c2 = SH_C2.map(T::c);
    g[4] = [c2[0] * y, c2[0] * x, z0];
    g[5] = [z0, c2[1] * z, c2[1] * y];
    g[6] = [-two * c2[2] * x, -two * c2[2] * y, T::c(4.0) * c2[2] * z];
    g[7] = [c2[3] * z, z0, c2[3] * x];
    g[8] = [two * c2[4] * x, -two * c2[4] * y, z0];
    if degree == 2 {
        return g;
    }
    let c3 = SH_C3.map(T::c);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let three = T::c(3.0);
    let four = T::c(4.0);
    // b9 = c·y(3x² − y²)
    g[9] = [
        c3[0] * T::c(6.0) * x * y,
        c3[0] * (three * xx - three * yy),
        z0,
    ];
    // b10 = c·xyz
    g[10] = [c3[1] * y * z, c3[1] * x * z, c3[1] * x * y];
    // b11 = c·y(4z² − x² − y²)
    g[11] = [
        c3[2] * (-two * x * y),
        c3[2] * (four * zz - xx - three * yy),
        c3[2] * (T::c(8.0) * y * z),
    ];
    // b12 = c·z(2z² − 3x² − 3y²)
    g[12] = [
        c3[3] * (-T::c(6.0) * x * z),
        c3[3] * (-T::c(6.0) * y * z),
        c3[3] * (T::c(6.0) * zz - three * xx - three * yy),
    ];
    // b13 = c·x(4z² − x² − y²)
    g[13] = [
        c3[4] * (four * zz - three * xx - yy),
        c3[4] * (-two * x * y),
        c3[4] * (T::c(8.0) * x * z),
    ];
    // b14 = c·z(x² − y²)
    g[14] = [c3[5] * two * x * z, -c3[5] * two * y * z, c3[5] * (xx - yy)];
    // b15 = c·x(x² − 3y²)
    g[15] = [
        c3[6] * (three * xx - three * yy),
        -c3[6] * T::c(6.0) * x * y,
        z0,
    ];
    g
}

/// Evaluate colour (before the +0.5 and clamp) from one splat's SH block
/// (`stored` coefficients per channel, `[coeff][rgb]`) at `degree`.
pub fn eval<T: Real>(degree: u32, basis: &[T; 16], sh: &[f32]) -> [T; 3] {
    let n = ((degree + 1) * (degree + 1)) as usize;
    let mut c = [T::default(); 3];
    for (k, &bk) in basis.iter().enumerate().take(n) {
        for (ch, cv) in c.iter_mut().enumerate() {
            *cv += bk * T::f(sh[k * 3 + ch]);
        }
    }
    c
}

/// Number of SH basis functions for a degree.
pub const fn sh_count(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}
