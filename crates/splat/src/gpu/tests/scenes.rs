//! Random test scenes: splats in front of a small camera, with the awkward
//! cases the issue lists (overlapping, near-plane, off-screen, tiny and
//! degenerate splats).

use crate::types::{RenderCamera, Splats, sh_coeffs};
use rand::{Rng, SeedableRng};

pub fn camera(width: u32, height: u32) -> RenderCamera {
    // A slightly rotated camera looking down +z.
    let (a, b) = (0.1f32, -0.05f32);
    let (ca, sa, cb, sb) = (a.cos(), a.sin(), b.cos(), b.sin());
    // R = Rx(a) · Ry(b)
    let rotation = [
        [cb, 0.0, sb],
        [sa * sb, ca, -sa * cb],
        [-ca * sb, sa, ca * cb],
    ];
    RenderCamera {
        width,
        height,
        fx: width as f32 * 0.9,
        fy: width as f32 * 0.9,
        cx: width as f32 * 0.5 + 0.3,
        cy: height as f32 * 0.5 - 0.2,
        rotation,
        translation: [0.1, -0.05, 0.2],
        near: 0.2,
        far: 100.0,
    }
}

/// `n` random splats of SH degree `deg`, world positions mostly in view.
pub fn random_splats(n: usize, deg: u32, seed: u64, awkward: bool) -> Splats {
    let mut r = rand_pcg::Pcg64::seed_from_u64(seed);
    let k = sh_coeffs(deg);
    let mut s = Splats {
        sh_degree: deg,
        ..Default::default()
    };
    for i in 0..n {
        let z = r.random_range(1.5f32..6.0);
        let mut mean = [
            r.random_range(-0.7f32..0.7) * z,
            r.random_range(-0.5f32..0.5) * z,
            z,
        ];
        let mut ls = [
            r.random_range(-3.5f32..-1.5),
            r.random_range(-3.5f32..-1.5),
            r.random_range(-3.5f32..-1.5),
        ];
        let mut q = [
            r.random_range(-1.0f32..1.0),
            r.random_range(-1.0f32..1.0),
            r.random_range(-1.0f32..1.0),
            r.random_range(-1.0f32..1.0),
        ];
        if awkward {
            match i % 12 {
                0 => mean[2] = r.random_range(0.0f32..0.35), // around the near plane
                1 => {
                    mean[0] =
                        r.random_range(4.0f32..30.0) * if r.random::<bool>() { 1.0 } else { -1.0 }
                } // off-screen
                2 => ls = [-9.0, -9.0, -9.0],                // tiny
                3 => ls = [-1.0, -12.0, -2.0],               // degenerate (flat)
                4 => q = [0.0, 0.0, 0.0, 0.0],               // zero quaternion: culled
                5 => mean = [0.0, 0.0, 3.0],                 // heavy overlap at one point
                6 => ls = [-0.3, -0.4, -0.5],                // large
                _ => {}
            }
        }
        s.means.push(mean);
        s.log_scales.push(ls);
        s.rotations.push(q);
        s.opacity_logits.push(r.random_range(-2.0f32..4.0));
        for c in 0..k * 3 {
            s.sh.push(if c < 3 {
                r.random_range(-1.5f32..1.5)
            } else {
                r.random_range(-0.4f32..0.4)
            });
        }
    }
    s
}
