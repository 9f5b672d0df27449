//! GPU backward stages against the CPU reference for a random upstream
//! gradient, on both the float-atomic and the compare-and-swap paths.

use super::scenes::{camera, random_splats};
use super::{ctx, ctx_cas, ctx_wide_lists};
use crate::gpu::GpuContext;
use crate::gpu::backward::{
    BackwardArgs, BackwardKernels, projected_grads_buffer, read_grads, read_projected_grads,
    record_backward,
};
use crate::gpu::forward::{ForwardKernels, forward, upload_splats};
use crate::gpu::kernel::Recorder;
use crate::gpu::project_backward::{GradBuffers, ProjectBackwardArgs, V_PROJ_FLOATS};
use crate::reference;
use crate::types::{ProjectedGrads, RenderOptions};
use rand::{Rng, SeedableRng};

/// Cosine similarity and relative L2 error of `a` against reference `b`.
pub fn compare_grads(name: &str, a: &[f32], b: &[f32]) -> (f64, f64) {
    assert_eq!(a.len(), b.len(), "{name}: lengths");
    let (mut ab, mut aa, mut bb, mut dd) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        assert!(
            x.is_finite() && y.is_finite(),
            "{name}[{i}]: non-finite ({x} vs {y})"
        );
        let (x, y) = (x as f64, y as f64);
        ab += x * y;
        aa += x * x;
        bb += y * y;
        dd += (x - y) * (x - y);
    }
    assert!(
        bb > 0.0,
        "{name}: reference gradient is all zero, test too weak"
    );
    (
        ab / (aa.sqrt() * bb.sqrt()).max(1e-300),
        dd.sqrt() / bb.sqrt(),
    )
}

fn check(name: &str, a: &[f32], b: &[f32]) {
    let (cos, rel) = compare_grads(name, a, b);
    eprintln!("{name}: cos {cos:.7} rel {rel:.2e}");
    // Bounds from the issue; float-atomic summation order is the main source
    // of difference (measured rel ≈ 1e-6 on lavapipe).
    assert!(
        cos >= 0.999 && rel <= 1e-3,
        "{name}: cosine {cos}, relative L2 {rel}"
    );
}

fn flat_proj(g: &[ProjectedGrads]) -> [Vec<f32>; 4] {
    [
        g.iter().flat_map(|p| p.mean2d).collect(),
        g.iter().flat_map(|p| p.conic).collect(),
        g.iter().map(|p| p.opacity).collect(),
        g.iter().flat_map(|p| p.color).collect(),
    ]
}

fn run(c: &GpuContext) {
    let fk = ForwardKernels::new(c);
    let bk = BackwardKernels::new(c);
    for (ci, &(w, h, n, deg, antialiased)) in [
        (64u32, 48u32, 300usize, 1u32, false),
        (96, 72, 400, 3, true),
    ]
    .iter()
    .enumerate()
    {
        let splats = random_splats(n, deg, 200 + ci as u64, true);
        let cam = camera(w, h);
        let opts = RenderOptions {
            background: [0.3, 0.2, 0.7],
            sh_degree: deg,
            low_pass: 0.3,
            antialiased,
        };
        let params = upload_splats(c, &splats).unwrap();
        let (state, _) = forward(c, &fk, &params, &cam, &opts, false).unwrap();
        let mut r = rand_pcg::Pcg64::seed_from_u64(300 + ci as u64);
        let v_image: Vec<f32> = (0..w * h * 3)
            .map(|_| r.random_range(-1.0f32..1.0))
            .collect();
        let v_buf = c.upload("v_image", &v_image);
        let v_proj = projected_grads_buffer(c, params.n);
        let grads = GradBuffers::like(c, &params);
        let mut rec = Recorder::new(c, false);
        record_backward(
            c,
            &bk,
            &mut rec,
            &BackwardArgs {
                params: &params,
                state: &state,
                v_image: &v_buf,
                v_proj: &v_proj,
                grads: &grads,
            },
        )
        .unwrap();
        rec.finish().unwrap();
        // Stage 1: rasterize backward on identical projected splats and lists.
        let proj = state.read_projected(c).unwrap();
        let raster = state.read_raster(c).unwrap();
        let ref_vp = reference::rasterize_backward(&proj, &raster, &cam, &opts, &v_image);
        let gpu_vp = read_projected_grads(c, &v_proj, params.n).unwrap();
        let (a, b) = (flat_proj(&gpu_vp), flat_proj(&ref_vp));
        for (k, name) in ["v_mean2d", "v_conic", "v_opacity", "v_color"]
            .iter()
            .enumerate()
        {
            check(&format!("case {ci} {name}"), &a[k], &b[k]);
        }
        // Stage 2: project backward fed the reference's projected gradients.
        let mut vp_ref: Vec<f32> = bytemuck::cast_slice(&ref_vp).to_vec();
        vp_ref.resize(params.n as usize * V_PROJ_FLOATS as usize, f32::NAN);
        let vp_buf = c.upload("v_proj_ref", &vp_ref);
        let mut rec = Recorder::new(c, false);
        bk.project_backward
            .dispatch(
                c,
                &mut rec,
                &ProjectBackwardArgs {
                    cam: &state.cam,
                    params: &params,
                    v_proj: &vp_buf,
                    grads: &grads,
                },
            )
            .unwrap();
        rec.finish().unwrap();
        let g = read_grads(c, &grads, &params).unwrap();
        let rg = reference::project_backward(&splats, &cam, &opts, &ref_vp);
        let flat3 = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let flat4 = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        for (name, gpu, cpu) in [
            ("means", flat3(&g.means), flat3(&rg.means)),
            ("log_scales", flat3(&g.log_scales), flat3(&rg.log_scales)),
            ("rotations", flat4(&g.rotations), flat4(&rg.rotations)),
            (
                "opacity",
                g.opacity_logits.clone(),
                rg.opacity_logits.clone(),
            ),
            ("sh", g.sh.clone(), rg.sh.clone()),
            ("mean2d_abs", g.mean2d_abs.clone(), rg.mean2d_abs.clone()),
        ] {
            check(&format!("case {ci} {name}"), &gpu, &cpu);
        }
    }
}

#[test]
fn backward_matches_reference_float_atomics() {
    let Some(c) = ctx() else { return };
    run(c);
}

#[test]
fn backward_matches_reference_cas_atomics() {
    let Some(c) = ctx_cas() else { return };
    assert!(!c.float_atomics);
    run(c);
}

#[test]
fn backward_matches_reference_wide_lists() {
    let Some(c) = ctx_wide_lists() else { return };
    assert_eq!(c.list_cols, 16);
    run(c);
}
