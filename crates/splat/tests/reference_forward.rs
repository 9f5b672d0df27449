//! Reference forward: known-answer projection of an isotropic splat, tile
//! rasterizer vs a brute-force per-pixel compositor (no tiles), and fuzz
//! inputs (NaN / Inf / huge) that must be culled, never a NaN image.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::needless_range_loop)]

mod common;

use splat::reference::rasterize::{tile_hit, tile_k2};
use splat::reference::{project, rasterize, render};
use splat::{ProjectedSplat, RenderCamera, RenderOptions, Splats};

fn one_splat(mean: [f32; 3], sigma: f32, logit: f32, dc: [f32; 3]) -> Splats {
    Splats {
        means: vec![mean],
        log_scales: vec![[sigma.ln(); 3]],
        rotations: vec![[2.0, 0.0, 0.0, 0.0]],
        opacity_logits: vec![logit],
        sh: dc.to_vec(),
        sh_degree: 0,
    }
}

#[test]
fn isotropic_known_answer() {
    let cam = common::camera(64, 48, 50.0);
    let s = one_splat([0.4, -0.2, 4.0], 0.1, 0.0, [0.5, -0.5, 3.0]);
    let opts = RenderOptions::default();
    let p = project(&s, &cam, &opts)[0];
    let sig_px = 50.0 * 0.1 / 4.0;
    let var = sig_px * sig_px + 0.3;
    assert!((p.mean2d[0] - (50.0 * 0.1 + 32.0)).abs() < 1e-4);
    assert!((p.mean2d[1] - (50.0 * -0.05 + 24.0)).abs() < 1e-4);
    assert!((p.depth - 4.0).abs() < 1e-6);
    // The off-axis mean tilts the Jacobian slightly; conic ≈ 1/var on the diagonal.
    assert!(
        (p.conic[0] - 1.0 / var).abs() / (1.0 / var) < 0.02,
        "{:?}",
        p.conic
    );
    let lambda = var + 0.1f32.sqrt();
    assert!((p.radius - (3.0 * lambda.sqrt()).ceil()).abs() <= 1.0);
    let c0 = 0.282_094_8f32;
    assert!((p.color[0] - (0.5 + c0 * 0.5)).abs() < 1e-6);
    assert_eq!(p.color[1], (0.5f32 - c0 * 0.5).max(0.0));
    assert!((p.color[2] - (0.5 + c0 * 3.0)).abs() < 1e-5);
    assert!((p.opacity - 0.5).abs() < 1e-6);
    // Centred splat: the pixel under the mean gets α = 0.5·exp(−½ d² conic).
    let s = one_splat([0.0, 0.0, 4.0], 0.1, 0.0, [1.0, 1.0, 1.0]);
    let opts = RenderOptions {
        background: [0.25, 0.5, 1.0],
        ..Default::default()
    };
    let out = render(&s, &cam, &opts).unwrap();
    let p = out.projected[0];
    let (x, y) = (32usize, 24usize);
    let dx = p.mean2d[0] - (x as f32 + 0.5);
    let dy = p.mean2d[1] - (y as f32 + 0.5);
    let g = (-0.5 * (p.conic[0] * dx * dx + p.conic[2] * dy * dy) - p.conic[1] * dx * dy).exp();
    let alpha = 0.5 * g;
    for ch in 0..3 {
        let want = p.color[ch] * alpha + (1.0 - alpha) * opts.background[ch];
        assert!((out.image[(y * 64 + x) * 3 + ch] - want).abs() < 1e-6);
    }
    assert!((out.final_transmittance[y * 64 + x] - (1.0 - alpha)).abs() < 1e-6);
    // A corner pixel far away sees the background only.
    assert_eq!(out.image[0], 0.25);
}

/// The packed tile extents of a projected splat, checked against an
/// independent derivation: from Σ' = conic⁻¹ and k = min(3, sqrt(2 ln(255 o)))
/// the extents are ceil(k·sqrt(Σ'ₓₓ)), ceil(k·sqrt(Σ'ᵧᵧ)) (0 when 255 o ≤ 1),
/// and never smaller than the 3σ circle's bounding box would allow to be
/// dropped: both ≤ the circular radius.
fn extent_of(s: &ProjectedSplat) -> [f32; 2] {
    let bits = s.tile_extent;
    let e = [(bits & 0xffff) as f32, (bits >> 16) as f32];
    let [a, b, c] = s.conic.map(|v| v as f64);
    let det = a * c - b * b;
    let (sxx, syy) = (c / det, a / det);
    let th = 255.0 * s.opacity as f64;
    if th <= 1.0 {
        assert_eq!(e, [0.0, 0.0], "transparent splat has tiles: {s:?}");
        return e;
    }
    let k = (2.0 * th.ln()).sqrt().min(3.0);
    for (got, var) in e.iter().zip([sxx, syy]) {
        let want = k * var.sqrt();
        // f32 rounding of conic vs covariance: ceil may land one pixel either way.
        assert!(
            (*got as f64 - want.ceil()).abs() <= 1.0 && *got as f64 >= want - 1e-3,
            "extent {got} vs {want}: {s:?}"
        );
        assert!(*got <= s.radius, "extent {got} beyond radius {}", s.radius);
    }
    e
}

/// Composite every pixel over all splats sorted by depth, no tiles.
fn brute_force(p: &[ProjectedSplat], cam: &RenderCamera, bg: [f32; 3]) -> Vec<f32> {
    let mut order: Vec<usize> = (0..p.len()).filter(|&i| p[i].radius > 0.0).collect();
    order.sort_by(|&a, &b| p[a].depth.total_cmp(&p[b].depth).then(a.cmp(&b)));
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut img = vec![0.0; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
            let mut t = 1.0f32;
            let mut c = [0.0f32; 3];
            for &i in &order {
                let s = &p[i];
                // Splats only reach the tiles of their per-axis extents
                // (opacity-aware, gsplat style; checked in `extent_of`).
                let [ex, ey] = extent_of(s);
                if ex == 0.0 || ey == 0.0 {
                    continue;
                }
                let tx0 = ((s.mean2d[0] - ex) / 16.0).floor().max(0.0) as usize;
                let tx1 = ((s.mean2d[0] + ex) / 16.0).ceil() as usize;
                let ty0 = ((s.mean2d[1] - ey) / 16.0).floor().max(0.0) as usize;
                let ty1 = ((s.mean2d[1] + ey) / 16.0).ceil() as usize;
                if !(tx0..tx1).contains(&(x / 16)) || !(ty0..ty1).contains(&(y / 16)) {
                    continue;
                }
                // ... of those, only the tiles their 3σ-capped ellipse meets.
                let k2 = tile_k2(s.opacity);
                if !tile_hit(s.mean2d, s.conic, k2, ((x / 16) as u32, (y / 16) as u32)) {
                    continue;
                }
                let (dx, dy) = (s.mean2d[0] - px, s.mean2d[1] - py);
                let pw =
                    -0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) - s.conic[1] * dx * dy;
                if pw > 0.0 {
                    continue;
                }
                let a = (s.opacity * pw.exp()).min(0.99);
                if a < 1.0 / 255.0 {
                    continue;
                }
                let nt = t * (1.0 - a);
                if nt < 1e-4 {
                    break;
                }
                for ch in 0..3 {
                    c[ch] += s.color[ch] * a * t;
                }
                t = nt;
            }
            for ch in 0..3 {
                img[(y * w + x) * 3 + ch] = c[ch] + t * bg[ch];
            }
        }
    }
    img
}

#[test]
fn tiles_match_brute_force() {
    for (seed, scale) in [(1u64, (-4.0, -2.0)), (2, (-3.0, -1.0)), (3, (-5.0, -3.5))] {
        let s = common::random_splats(300, 2, seed, scale);
        let cam = common::tilted_camera(83, 61, 70.0);
        let opts = RenderOptions {
            sh_degree: 2,
            background: [0.1, 0.2, 0.3],
            ..Default::default()
        };
        let p = project(&s, &cam, &opts);
        let visible = p.iter().filter(|p| p.radius > 0.0).count();
        assert!(visible > 100, "only {visible} visible");
        let r = rasterize(&p, &cam, &opts);
        let b = brute_force(&p, &cam, opts.background);
        let max = r
            .image
            .iter()
            .zip(&b)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(max < 1e-5, "seed {seed}: max diff {max}");
        // Tile lists are sorted by depth.
        for rg in &r.tile_ranges {
            let l = &r.tile_splats[rg[0] as usize..rg[1] as usize];
            assert!(
                l.windows(2)
                    .all(|w| p[w[0] as usize].depth <= p[w[1] as usize].depth)
            );
        }
    }
}

#[test]
fn fuzz_never_nan() {
    let cam = common::camera(48, 40, 40.0);
    let mut s = common::random_splats(64, 1, 9, (-3.0, -1.0));
    let bad = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e30,
        -1e30,
        0.0,
        1e-30,
    ];
    for (i, &v) in bad.iter().enumerate() {
        s.means[i * 7][i % 3] = v;
        s.log_scales[i * 7 + 1][i % 3] = v;
        s.rotations[i * 7 + 2] = [v, 0.0, 0.0, 0.0];
        s.opacity_logits[i * 7 + 3] = v;
        s.sh[(i * 7 + 4) * 12] = v;
        s.log_scales[i * 7 + 5] = [80.0, 80.0, 80.0];
        s.means[i * 7 + 6] = [0.0, 0.0, 0.011];
    }
    for aa in [false, true] {
        let opts = RenderOptions {
            sh_degree: 1,
            antialiased: aa,
            ..Default::default()
        };
        let out = render(&s, &cam, &opts).unwrap();
        assert!(out.image.iter().all(|v| v.is_finite()), "NaN/Inf pixel");
        assert!(out.final_transmittance.iter().all(|v| v.is_finite()));
        for p in &out.projected {
            let vals = [
                p.mean2d[0],
                p.mean2d[1],
                p.depth,
                p.radius,
                p.opacity,
                p.conic[0],
                p.color[0],
            ];
            assert!(vals.iter().all(|v| v.is_finite()));
            if p.radius == 0.0 {
                assert_eq!(*p, ProjectedSplat::default(), "culled splat not zeroed");
            }
        }
        // The NaN-mean and NaN-scale splats are culled.
        assert_eq!(out.projected[0].radius, 0.0);
        assert_eq!(out.projected[1].radius, 0.0);
    }
    // Inconsistent arrays are a clear error, not a panic.
    let mut broken = s.clone();
    broken.sh.pop();
    assert!(render(&broken, &cam, &RenderOptions::default()).is_err());
    let mut badcam = cam;
    badcam.fx = f32::NAN;
    assert!(render(&s, &badcam, &RenderOptions::default()).is_err());
}
