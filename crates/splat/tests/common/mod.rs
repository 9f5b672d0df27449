//! Scene builders shared by the splat tests.
#![allow(
    dead_code,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::needless_range_loop
)]

use rand::{Rng, SeedableRng};
use splat::types::sh_coeffs;
use splat::{RenderCamera, Splats};

/// A camera at the origin looking down +z (identity pose).
pub fn camera(w: u32, h: u32, f: f32) -> RenderCamera {
    RenderCamera::at_origin(w, h, f)
}

/// A camera with a generic rotation and translation looking at the origin region.
pub fn tilted_camera(w: u32, h: u32, f: f32) -> RenderCamera {
    let (a, b) = (0.2f32, -0.15f32);
    // R = Rx(a) · Ry(b)
    let rx = [
        [1.0, 0.0, 0.0],
        [0.0, a.cos(), -a.sin()],
        [0.0, a.sin(), a.cos()],
    ];
    let ry = [
        [b.cos(), 0.0, b.sin()],
        [0.0, 1.0, 0.0],
        [-b.sin(), 0.0, b.cos()],
    ];
    let mut r = [[0.0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| rx[i][k] * ry[k][j]).sum();
        }
    }
    let mut c = camera(w, h, f);
    c.rotation = r;
    c.translation = [0.1, -0.05, 0.3];
    c
}

/// Random splats in front of `camera(..)`, within a box at depth 2..6.
pub fn random_splats(n: usize, degree: u32, seed: u64, scale: (f32, f32)) -> Splats {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let k = sh_coeffs(degree);
    let mut s = Splats {
        sh_degree: degree,
        ..Default::default()
    };
    for _ in 0..n {
        let z = rng.random_range(2.0..6.0f32);
        s.means.push([
            rng.random_range(-0.8..0.8) * z * 0.5,
            rng.random_range(-0.6..0.6) * z * 0.5,
            z,
        ]);
        let ls = rng.random_range(scale.0..scale.1);
        s.log_scales.push([
            ls + rng.random_range(-0.5..0.5),
            ls + rng.random_range(-0.5..0.5),
            ls + rng.random_range(-0.5..0.5),
        ]);
        s.rotations.push([
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ]);
        s.opacity_logits.push(rng.random_range(-2.0..2.0));
        for c in 0..k * 3 {
            let amp = if c < 3 { 1.0 } else { 0.3 };
            s.sh.push(rng.random_range(-amp..amp));
        }
    }
    s
}

/// A few large, semi-transparent splats covering a small image completely,
/// so every pixel stays far from the α cut-offs: loss is smooth in every
/// parameter (for finite-difference checks).
pub fn smooth_splats(degree: u32, seed: u64) -> Splats {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let k = sh_coeffs(degree);
    let mut s = Splats {
        sh_degree: degree,
        ..Default::default()
    };
    for i in 0..4 {
        let z = 3.0 + i as f32 * 0.7;
        s.means
            .push([rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1), z]);
        s.log_scales.push([
            (1.5f32 + rng.random_range(-0.2..0.2)).ln() + (z / 3.0).ln(),
            (1.1f32 + rng.random_range(-0.2..0.2)).ln() + (z / 3.0).ln(),
            0.0,
        ]);
        let q: [f32; 4] = [
            1.0,
            rng.random_range(-0.4..0.4),
            rng.random_range(-0.4..0.4),
            rng.random_range(-0.4..0.4),
        ];
        s.rotations.push(q);
        s.opacity_logits.push(rng.random_range(-0.8..0.2));
        for c in 0..k * 3 {
            let amp = if c < 3 { 0.8 } else { 0.25 };
            s.sh.push(rng.random_range(-amp..amp) + if c < 3 { 0.4 } else { 0.0 });
        }
    }
    s
}
