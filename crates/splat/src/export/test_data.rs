//! Deterministic random splat sets for the export tests.

use crate::types::{Splats, sh_coeffs};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// `n` splats with centres in [-3, 3]³, log scales in [-5, 0], random
/// rotations (not normalised), opacity logits in [-6, 6], DC in [-1.5, 1.5]
/// and higher SH in [-0.8, 0.8] (inside SPZ's representable range).
pub fn random_splats(n: usize, sh_degree: u32, seed: u64) -> Splats {
    let mut rng = Pcg64::seed_from_u64(seed);
    let k = sh_coeffs(sh_degree);
    let mut s = Splats {
        sh_degree,
        ..Default::default()
    };
    for _ in 0..n {
        s.means.push([0; 3].map(|_| rng.random_range(-3.0f32..3.0)));
        s.log_scales
            .push([0; 3].map(|_| rng.random_range(-5.0f32..0.0)));
        s.rotations
            .push([0; 4].map(|_| rng.random_range(-2.0f32..2.0)));
        s.opacity_logits.push(rng.random_range(-6.0f32..6.0));
        for j in 0..k {
            let r = if j == 0 { 1.5f32 } else { 0.8 };
            for _ in 0..3 {
                s.sh.push(rng.random_range(-r..r));
            }
        }
    }
    s
}
