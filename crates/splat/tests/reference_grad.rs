//! The reference backward (rasterize_backward ∘ project_backward) checked
//! against central finite differences of the reference forward, all in f64,
//! on smooth scenes (a few large splats covering the image, so no pixel is
//! near an α cut-off), for a random upstream gradient dL/d image.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::needless_range_loop)]

mod common;

use rand::{Rng, SeedableRng};
use splat::reference::project::project_t;
use splat::reference::project_backward::project_backward_t;
use splat::reference::rasterize::rasterize_t;
use splat::reference::rasterize_backward::{RasterRef, rasterize_backward_t};
use splat::{RenderCamera, RenderOptions, Splats};

fn loss(s: &Splats, cam: &RenderCamera, opts: &RenderOptions, cot: &[f64]) -> f64 {
    let p = project_t::<f64>(s, cam, opts);
    let r = rasterize_t(&p, cam, opts);
    r.image.iter().zip(cot).map(|(a, b)| a * b).sum()
}

/// Central difference of `loss` w.r.t. one f32 parameter reached by `get`.
fn fd(
    s: &Splats,
    cam: &RenderCamera,
    opts: &RenderOptions,
    cot: &[f64],
    get: &dyn Fn(&mut Splats) -> &mut f32,
) -> f64 {
    let mut a = s.clone();
    let mut b = s.clone();
    let x = *get(&mut a);
    let eps = 1e-3f32 * x.abs().max(1.0);
    *get(&mut a) = x + eps;
    *get(&mut b) = x - eps;
    // The step actually taken (exact in f64).
    let h = *get(&mut a) as f64 - *get(&mut b) as f64;
    (loss(&a, cam, opts, cot) - loss(&b, cam, opts, cot)) / h
}

fn compare(name: &str, analytic: &[f64], numeric: &[f64]) {
    assert_eq!(analytic.len(), numeric.len());
    assert!(
        analytic.iter().all(|v| v.is_finite()),
        "{name}: non-finite analytic gradient"
    );
    let dot: f64 = analytic.iter().zip(numeric).map(|(a, b)| a * b).sum();
    let na = analytic.iter().map(|a| a * a).sum::<f64>().sqrt();
    let nn = numeric.iter().map(|a| a * a).sum::<f64>().sqrt();
    let diff = analytic
        .iter()
        .zip(numeric)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    let cos = dot / (na * nn).max(1e-300);
    let rel = diff / nn.max(1e-300);
    eprintln!("{name}: cos {cos:.8} rel {rel:.2e} |g| {nn:.3e}");
    assert!(nn > 1e-8, "{name}: gradient vanishes, test is vacuous");
    assert!(
        cos >= 0.999 && rel <= 1e-3,
        "{name}: cos {cos} rel {rel}\n a {analytic:?}\n n {numeric:?}"
    );
}

fn check(s: &Splats, cam: &RenderCamera, opts: &RenderOptions, seed: u64) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let npx = (cam.width * cam.height * 3) as usize;
    let cot: Vec<f64> = (0..npx).map(|_| rng.random_range(-1.0..1.0)).collect();
    let p = project_t::<f64>(s, cam, opts);
    assert!(
        p.iter().all(|p| p.radius > 0.0),
        "smooth scene lost a splat"
    );
    let r = rasterize_t(&p, cam, opts);
    let rr = RasterRef {
        final_transmittance: &r.final_transmittance,
        last_contrib: &r.last_contrib,
        tile_ranges: &r.tile_ranges,
        tile_splats: &r.tile_splats,
    };
    let vp = rasterize_backward_t(&p, rr, cam, opts, &cot);
    let g = project_backward_t(s, cam, opts, &vp);
    let n = s.len();
    // The analytic gradient of `width` values per splat against central
    // differences of the parameters `param` reaches.
    let group = |name: &str,
                 width: usize,
                 analytic: &dyn Fn(usize, usize) -> f64,
                 param: &dyn Fn(&mut Splats, usize, usize) -> &mut f32| {
        let (mut a, mut num) = (vec![], vec![]);
        for i in 0..n {
            for k in 0..width {
                a.push(analytic(i, k));
                num.push(fd(s, cam, opts, &cot, &|t| param(t, i, k)));
            }
        }
        compare(name, &a, &num);
    };
    group("means", 3, &|i, k| g.means[i][k], &|t, i, k| {
        &mut t.means[i][k]
    });
    group("log_scales", 3, &|i, k| g.log_scales[i][k], &|t, i, k| {
        &mut t.log_scales[i][k]
    });
    group("rotations", 4, &|i, k| g.rotations[i][k], &|t, i, k| {
        &mut t.rotations[i][k]
    });
    group(
        "opacity_logits",
        1,
        &|i, _| g.opacity_logits[i],
        &|t, i, _| &mut t.opacity_logits[i],
    );
    let active = splat::types::sh_coeffs(opts.sh_degree.min(s.sh_degree)) * 3;
    let k3 = s.coeffs_per_channel() * 3;
    for (lo, hi, name) in [(0, 3, "sh_dc"), (3, active, "sh_rest")] {
        if hi > lo {
            group(name, hi - lo, &|i, c| g.sh[i * k3 + lo + c], &|t, i, c| {
                &mut t.sh[i * k3 + lo + c]
            });
        }
    }
    // Inactive SH coefficients get exactly zero gradient.
    for i in 0..n {
        assert!(
            g.sh[i * k3 + active..(i + 1) * k3]
                .iter()
                .all(|&v| v == 0.0)
        );
    }
}

#[test]
fn fd_degree3_plain() {
    let s = common::smooth_splats(3, 1);
    let cam = common::camera(40, 34, 40.0);
    let opts = RenderOptions {
        sh_degree: 3,
        background: [0.2, 0.5, 0.9],
        ..Default::default()
    };
    check(&s, &cam, &opts, 11);
}

#[test]
fn fd_degree1_antialiased_tilted() {
    let s = common::smooth_splats(3, 2);
    let cam = common::tilted_camera(40, 34, 40.0);
    let opts = RenderOptions {
        sh_degree: 1,
        antialiased: true,
        ..Default::default()
    };
    check(&s, &cam, &opts, 12);
}

#[test]
fn fd_clamped_jacobian() {
    // One splat far off-axis (x/z beyond 1.3·tan(fov/2)) but large enough to
    // cover the image: exercises the clamped branch of the Jacobian.
    let mut s = common::smooth_splats(2, 3);
    s.means[3] = [4.0, 0.2, 5.0];
    s.log_scales[3] = [2.5f32.ln(), 2.0f32.ln(), 1.0f32.ln()];
    let cam = common::camera(40, 34, 40.0);
    let opts = RenderOptions {
        sh_degree: 2,
        ..Default::default()
    };
    let p = project_t::<f64>(&s, &cam, &opts);
    let lim = 1.3 * 40.0 / (2.0 * 40.0);
    assert!(4.0 / 5.0 > lim && p[3].radius > 0.0);
    check(&s, &cam, &opts, 13);
}
