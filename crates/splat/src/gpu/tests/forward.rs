//! GPU forward (projection, binning, rasterization) against the CPU reference.

use super::scenes::{camera, random_splats};
use super::{ctx, ctx_cas};
use crate::gpu::GpuContext;
use crate::gpu::forward::{ForwardKernels, forward, upload_splats};
use crate::reference;
use crate::types::RenderOptions;

/// Largest |a − b| with NaN check first, naming the index (Brush's `compare`).
pub fn max_abs_diff(name: &str, a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "{name}: lengths");
    let mut worst = 0.0f32;
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(!x.is_nan() && !y.is_nan(), "{name}[{i}]: NaN ({x} vs {y})");
        worst = worst.max((x - y).abs());
    }
    worst
}

#[test]
fn forward_matches_reference_on_random_scenes() {
    let Some(c) = ctx() else { return };
    run(c);
}

/// The same on the no-subgroup context, whose rasterizer walks its lists
/// one entry per invocation (`lanes` = 1, the path of adapters without
/// 8-lane subgroups).
#[test]
fn forward_matches_reference_one_lane() {
    let Some(c) = ctx_cas() else { return };
    assert_eq!(c.lanes, 1);
    run(c);
}

fn run(c: &GpuContext) {
    let k = ForwardKernels::new(c);
    let cases = [
        (64u32, 48u32, 300usize, 0u32, false, [0.0f32, 0.0, 0.0]),
        (96, 80, 400, 1, true, [0.2, 0.5, 0.9]),
        (128, 96, 500, 3, true, [1.0, 1.0, 1.0]),
        (70, 45, 200, 2, true, [0.0, 0.3, 0.0]),
    ];
    for (ci, &(w, h, n, deg, antialiased, bg)) in cases.iter().enumerate() {
        let splats = random_splats(n, deg, 100 + ci as u64, true);
        let cam = camera(w, h);
        let opts = RenderOptions {
            background: bg,
            sh_degree: deg,
            low_pass: 0.3,
            antialiased,
        };
        let params = upload_splats(c, &splats).unwrap();
        let (state, _) = forward(c, &k, &params, &cam, &opts, false).unwrap();
        let gp = state.read_projected(c).unwrap();
        let rp = reference::project(&splats, &cam, &opts);
        let visible = rp.iter().filter(|p| p.radius > 0.0).count();
        assert!(
            visible > n / 3,
            "case {ci}: only {visible} visible splats, scene too sparse to test"
        );
        for (i, (g, r)) in gp.iter().zip(&rp).enumerate() {
            assert_eq!(
                g.radius > 0.0,
                r.radius > 0.0,
                "case {ci} splat {i} culling: {g:?} vs {r:?}"
            );
            let tol = |v: f32| 1e-4 * v.abs().max(1.0);
            for (a, b) in [
                g.mean2d[0],
                g.mean2d[1],
                g.depth,
                g.opacity,
                g.color[0],
                g.color[1],
                g.color[2],
            ]
            .iter()
            .zip([
                r.mean2d[0],
                r.mean2d[1],
                r.depth,
                r.opacity,
                r.color[0],
                r.color[1],
                r.color[2],
            ]) {
                assert!(
                    (a - b).abs() <= tol(b),
                    "case {ci} splat {i}: {g:?} vs {r:?}"
                );
            }
            for (a, b) in g.conic.iter().zip(r.conic) {
                assert!(
                    (a - b).abs() <= 1e-3 * b.abs().max(1e-3),
                    "case {ci} splat {i} conic: {g:?} vs {r:?}"
                );
            }
        }
        // Rasterize the reference's own projection so the comparison tests the
        // rasterizer and binning, then compare the full GPU pipeline too.
        let rr = reference::rasterize(&gp, &cam, &opts);
        let gr = state.read_raster(c).unwrap();
        assert_eq!(gr.tile_ranges, rr.tile_ranges, "case {ci}: tile ranges");
        assert_eq!(gr.tile_splats, rr.tile_splats, "case {ci}: tile lists");
        // Tolerance 1e-4: the bound (GPU exp/fma differ from Rust's by a few ulp).
        let e = max_abs_diff("image", &gr.image, &rr.image);
        assert!(e <= 1e-4, "case {ci}: max pixel error {e}");
        let e = max_abs_diff("final_t", &gr.final_transmittance, &rr.final_transmittance);
        assert!(e <= 1e-4, "case {ci}: max transmittance error {e}");
        let differ = gr
            .last_contrib
            .iter()
            .zip(&rr.last_contrib)
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(
            differ, 0,
            "case {ci}: last_contrib differs at {differ} pixels"
        );
        let full = reference::render(&splats, &cam, &opts).unwrap();
        let e = max_abs_diff("image vs full reference", &gr.image, &full.image);
        assert!(
            e <= 1e-4,
            "case {ci}: max pixel error vs full reference {e}"
        );
        let lit = gr
            .image
            .iter()
            .zip(bg.iter().cycle())
            .filter(|(v, b)| (*v - *b).abs() > 0.05)
            .count();
        assert!(
            lit > gr.image.len() / 10,
            "case {ci}: image nearly empty, test too weak"
        );
    }
}
