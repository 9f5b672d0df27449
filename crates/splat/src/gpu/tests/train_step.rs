//! GPU Adam and a whole GPU training step against the CPU backend.

use super::ctx;
use super::scenes::{camera, random_splats};
use crate::backend::{LearningRates, LossConfig, StepInput, TrainBackend};
use crate::gpu::GpuBackend;
use crate::gpu::adam::{Adam, AdamArgs, AdamUniforms};
use crate::gpu::kernel::Recorder;
use crate::reference::backend::CpuBackend;
use crate::train::adam::AdamConfig;
use crate::types::{AdamState, RenderCamera, RenderOptions, Splats};
use rand::{Rng, SeedableRng};

/// The learning rates of these tests: INRIA's, with the position rate given.
fn rates(means: f32) -> LearningRates {
    LearningRates {
        means,
        sh_dc: 2.5e-3,
        sh_rest: 1.25e-4,
        opacity: 0.05,
        scales: 5e-3,
        rotations: 1e-3,
    }
}

/// A random `w×h` RGB target in [0, 1).
fn random_image(r: &mut rand_pcg::Pcg64, w: u32, h: u32) -> Vec<f32> {
    (0..w * h * 3)
        .map(|_| r.random_range(0.0f32..1.0))
        .collect()
}

/// One L1-only step towards `target` without mask or device cache, at
/// `rates(1e-3)`.
fn plain_input<'a>(
    camera: &'a RenderCamera,
    target: &'a [f32],
    render: RenderOptions,
) -> StepInput<'a> {
    StepInput {
        camera,
        target,
        mask: None,
        view_id: None,
        lr: rates(1e-3),
        loss: LossConfig { ssim_weight: 0.0 },
        render,
    }
}

/// Uniforms of one Adam step `t` (1-based) over `splats` rows of `row`
/// floats, the first `width` of each updated; columns < `head` use
/// `lr_head`; `sparse` is sparse mode.
fn adam_uniforms(
    cfg: &AdamConfig,
    t: i32,
    splats: usize,
    (lr, lr_head): (f32, f32),
    (width, row, head): (u32, u32, u32),
    sparse: bool,
) -> AdamUniforms {
    AdamUniforms {
        n: splats as u32 * width,
        width,
        row,
        head,
        sparse: sparse as u32,
        lr,
        lr_head,
        ..AdamUniforms::for_step(cfg, t)
    }
}

/// Record, submit and wait for one Adam dispatch.
fn run_adam(c: &crate::gpu::GpuContext, adam: &Adam, args: &AdamArgs) {
    let mut rec = Recorder::new(c, false);
    adam.dispatch(c, &mut rec, args).unwrap();
    rec.finish().unwrap();
}

/// The CPU formula for one element: new (m, v, p).
fn adam_element(u: &AdamUniforms, lr: f32, (m, v, p, g): (f32, f32, f32, f32)) -> (f32, f32, f32) {
    let g = if g.is_finite() { g } else { 0.0 };
    let m = u.beta1 * m + (1.0 - u.beta1) * g;
    let v = u.beta2 * v + (1.0 - u.beta2) * g * g;
    (m, v, p - lr / u.bc1 * m / (v.sqrt() / u.sbc2 + u.eps))
}

#[test]
fn adam_kernel_matches_cpu_formula() {
    let Some(c) = ctx() else { return };
    let adam = Adam::new(c);
    let mut r = rand_pcg::Pcg64::seed_from_u64(9);
    let n = 1000usize;
    let mut p: Vec<f32> = (0..n).map(|_| r.random_range(-1.0f32..1.0)).collect();
    let mut m = vec![0.0f32; n];
    let mut v = vec![0.0f32; n];
    let (pb, mb, vb) = (c.upload("p", &p), c.upload("m", &m), c.upload("v", &v));
    let dummy = c.storage("visible", 48);
    let cfg = AdamConfig::default();
    for t in 1..=4i32 {
        let mut g: Vec<f32> = (0..n).map(|_| r.random_range(-1.0f32..1.0)).collect();
        g[7] = f32::NAN; // non-finite gradients count as 0
        let gb = c.upload("g", &g);
        // Rows of 10, the first 7 updated; columns < 3 use lr_head.
        let (lr, lr_head) = (0.01f32, 0.05f32);
        let u = adam_uniforms(&cfg, t, n / 10, (lr, lr_head), (7, 10, 3), false);
        run_adam(
            c,
            &adam,
            &AdamArgs {
                params: &pb,
                grads: &gb,
                exp_avg: &mb,
                exp_avg_sq: &vb,
                visible: &dummy, // not read when dense
                uniforms: u,
            },
        );
        for k in (0..n).filter(|k| k % 10 < 7) {
            let l = if k % 10 < 3 { lr_head } else { lr };
            (m[k], v[k], p[k]) = adam_element(&u, l, (m[k], v[k], p[k], g[k]));
        }
        let gp: Vec<f32> = c.read(&pb, n).unwrap();
        for k in 0..n {
            assert!(
                (gp[k] - p[k]).abs() <= 1e-6,
                "step {t} element {k}: {} vs {}",
                gp[k],
                p[k]
            );
        }
    }
}

/// Sparse Adam: elements of splats with radius 0 in `visible` keep their
/// parameter and both moments; the others follow the dense formula.
#[test]
fn sparse_adam_updates_only_visible_splats() {
    let Some(c) = ctx() else { return };
    let adam = Adam::new(c);
    let mut r = rand_pcg::Pcg64::seed_from_u64(19);
    let (splats, width) = (700usize, 3usize);
    let n = splats * width;
    let p0: Vec<f32> = (0..n).map(|_| r.random_range(-1.0f32..1.0)).collect();
    let m0: Vec<f32> = (0..n).map(|_| r.random_range(-0.1f32..0.1)).collect();
    let v0: Vec<f32> = (0..n).map(|_| r.random_range(0.0f32..0.1)).collect();
    let g: Vec<f32> = (0..n).map(|_| r.random_range(-1.0f32..1.0)).collect();
    let vis: Vec<bool> = (0..splats).map(|i| i % 3 != 1).collect();
    let proj: Vec<crate::types::ProjectedSplat> = vis
        .iter()
        .map(|&v| crate::types::ProjectedSplat {
            radius: if v { 4.0 } else { 0.0 },
            ..Default::default()
        })
        .collect();
    let (pb, mb, vb) = (c.upload("p", &p0), c.upload("m", &m0), c.upload("v", &v0));
    let (gb, visb) = (c.upload("g", &g), c.upload("proj", &proj));
    let lr = 0.01f32;
    let w = width as u32;
    let u = adam_uniforms(&AdamConfig::default(), 1, splats, (lr, lr), (w, w, 0), true);
    run_adam(
        c,
        &adam,
        &AdamArgs {
            params: &pb,
            grads: &gb,
            exp_avg: &mb,
            exp_avg_sq: &vb,
            visible: &visb,
            uniforms: u,
        },
    );
    let (gp, gm, gv): (Vec<f32>, Vec<f32>, Vec<f32>) = (
        c.read(&pb, n).unwrap(),
        c.read(&mb, n).unwrap(),
        c.read(&vb, n).unwrap(),
    );
    for k in 0..n {
        if vis[k / width] {
            let (m, v, p) = adam_element(&u, lr, (m0[k], v0[k], p0[k], g[k]));
            assert!((gm[k] - m).abs() <= 1e-7, "m[{k}]");
            assert!((gv[k] - v).abs() <= 1e-7, "v[{k}]");
            assert!((gp[k] - p).abs() <= 1e-6, "p[{k}]: {} vs {p}", gp[k]);
        } else {
            assert_eq!((gp[k], gm[k], gv[k]), (p0[k], m0[k], v0[k]), "element {k}");
        }
    }
}

fn one_step(
    b: &mut dyn TrainBackend,
    s: &Splats,
    input: &StepInput,
) -> (
    crate::backend::StepStats,
    Splats,
    crate::types::DensifyStats,
) {
    b.upload(s, &AdamState::zeros_like(s)).unwrap();
    let st = b.step(input).unwrap();
    let (p, _, d) = b.download().unwrap();
    (st, p, d)
}

#[test]
fn gpu_step_matches_cpu_step() {
    if ctx().is_none() {
        return;
    }
    let mut gpu = GpuBackend::new(&crate::gpu::GpuOptions::default()).unwrap();
    let mut cpu = CpuBackend::new();
    let (w, h) = (64u32, 48u32);
    let cam = camera(w, h);
    let s = random_splats(300, 1, 55, false);
    let mut r = rand_pcg::Pcg64::seed_from_u64(56);
    let target = random_image(&mut r, w, h);
    // Mask out a block of "moving" pixels.
    let mask: Vec<f32> = (0..w * h)
        .map(|i| {
            if (i % w) < 20 && (i / w) < 20 {
                0.0
            } else {
                1.0
            }
        })
        .collect();
    let lr = rates(1.6e-4);
    for ssim_weight in [0.0f32, 0.2] {
        let input = StepInput {
            camera: &cam,
            target: &target,
            mask: Some(&mask),
            view_id: Some(0),
            lr,
            loss: LossConfig { ssim_weight },
            render: RenderOptions {
                background: [0.1, 0.1, 0.1],
                sh_degree: 1,
                low_pass: 0.3,
                antialiased: false,
            },
        };
        let (gs, gp, gd) = one_step(&mut gpu, &s, &input);
        let (cs, cp, cd) = one_step(&mut cpu, &s, &input);
        assert_eq!(gs.visible, cs.visible, "visible");
        for (a, b, name) in [
            (gs.loss, cs.loss, "loss"),
            (gs.l1, cs.l1, "l1"),
            (gs.psnr, cs.psnr, "psnr"),
            (gs.ssim, cs.ssim, "ssim"),
        ] {
            assert!(
                (a - b).abs() <= 1e-4 * b.abs().max(1.0),
                "λ={ssim_weight} {name}: {a} vs {b}"
            );
        }
        // After one Adam step an element moves by ≈ ±lr (sign of its gradient), so
        // elements whose gradient is ~0 may differ by up to 2·lr; nearly all agree.
        let groups: [(&str, Vec<f32>, Vec<f32>, f32); 4] = [
            (
                "means",
                gp.means.iter().flatten().copied().collect(),
                cp.means.iter().flatten().copied().collect(),
                lr.means,
            ),
            (
                "log_scales",
                gp.log_scales.iter().flatten().copied().collect(),
                cp.log_scales.iter().flatten().copied().collect(),
                lr.scales,
            ),
            (
                "opacity",
                gp.opacity_logits.clone(),
                cp.opacity_logits.clone(),
                lr.opacity,
            ),
            ("sh", gp.sh.clone(), cp.sh.clone(), lr.sh_dc),
        ];
        for (name, a, b, l) in groups {
            let mut off = 0;
            for (x, y) in a.iter().zip(&b) {
                assert!(
                    (x - y).abs() <= 2.0 * l + 1e-6,
                    "λ={ssim_weight} {name}: {x} vs {y}"
                );
                if (x - y).abs() > 0.01 * l + 1e-6 {
                    off += 1;
                }
            }
            assert!(
                off * 50 <= a.len(),
                "λ={ssim_weight} {name}: {off} of {} elements differ",
                a.len()
            );
        }
        assert_eq!(gd.count, cd.count, "densify counts");
        assert_eq!(gd.max_radius, cd.max_radius, "max radii");
        let (cos, rel) =
            super::backward::compare_grads("grad_accum", &gd.grad_accum, &cd.grad_accum);
        assert!(
            cos >= 0.999 && rel <= 1e-3,
            "grad_accum cos {cos} rel {rel}"
        );
    }
}

/// A backend whose persistent buffers were sized and filled by earlier steps
/// (more splats, a larger view) gives the same step as a fresh backend.
#[test]
fn reused_buffers_give_the_same_step() {
    if ctx().is_none() {
        return;
    }
    let lr = rates(1.6e-4);
    let render = RenderOptions {
        background: [0.2, 0.1, 0.0],
        sh_degree: 1,
        low_pass: 0.3,
        antialiased: false,
    };
    let mut r = rand_pcg::Pcg64::seed_from_u64(71);
    let (big_cam, small_cam) = (camera(96, 80), camera(64, 48));
    let (big_t, small_t) = (random_image(&mut r, 96, 80), random_image(&mut r, 64, 48));
    let input = |cam, t| StepInput {
        camera: cam,
        target: t,
        mask: None,
        view_id: None,
        lr,
        loss: LossConfig { ssim_weight: 0.2 },
        render,
    };
    let big = random_splats(600, 1, 72, true);
    let small = random_splats(250, 1, 73, true);
    let mut used = GpuBackend::new(&crate::gpu::GpuOptions::default()).unwrap();
    one_step(&mut used, &big, &input(&big_cam, &big_t));
    let (us, up, ud) = one_step(&mut used, &small, &input(&small_cam, &small_t));
    let mut fresh = GpuBackend::new(&crate::gpu::GpuOptions::default()).unwrap();
    let (fs, fp, fd) = one_step(&mut fresh, &small, &input(&small_cam, &small_t));
    assert_eq!(us.visible, fs.visible);
    // Same kernels on the same data; only atomic summation order may differ.
    for (a, b) in [(us.loss, fs.loss), (us.l1, fs.l1), (us.ssim, fs.ssim)] {
        assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{a} vs {b}");
    }
    assert_eq!(ud.count, fd.count);
    assert_eq!(ud.max_radius, fd.max_radius);
    let flat = |s: &Splats| -> Vec<f32> {
        let mut v: Vec<f32> = s.means.iter().flatten().copied().collect();
        v.extend(s.log_scales.iter().flatten());
        v.extend(s.rotations.iter().flatten());
        v.extend(&s.opacity_logits);
        v.extend(&s.sh);
        v
    };
    let (a, b) = (flat(&up), flat(&fp));
    assert_eq!(a.len(), b.len());
    let moved = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| (*x - *y).abs() > 1e-5)
        .count();
    // Adam's first step is ±lr·sign(g): a gradient summed in another order
    // can flip sign only where it is ~0, so nearly every element agrees.
    assert!(moved * 100 <= a.len(), "{moved} of {} differ", a.len());
}

/// `GpuBackend::sparse_adam`: a splat outside the view keeps its parameters
/// and moments (every group, SH included); dense Adam moves it on momentum.
#[test]
fn sparse_adam_backend_leaves_invisible_splats() {
    if ctx().is_none() {
        return;
    }
    let cam = camera(64, 48);
    let mut s = random_splats(200, 1, 81, false);
    s.means[5] = [500.0, 0.0, 3.0]; // far off-screen: culled
    let mut adam = AdamState::zeros_like(&s);
    let mut r = rand_pcg::Pcg64::seed_from_u64(82);
    for m in [&mut adam.m, &mut adam.v] {
        for x in m.means.iter_mut().flatten() {
            *x = r.random_range(0.01f32..0.1);
        }
        for x in m.sh.iter_mut() {
            *x = r.random_range(0.01f32..0.1);
        }
        for x in m.opacity_logits.iter_mut() {
            *x = r.random_range(0.01f32..0.1);
        }
    }
    adam.step = 3;
    let target = random_image(&mut r, 64, 48);
    let input = plain_input(
        &cam,
        &target,
        RenderOptions {
            sh_degree: 1,
            ..Default::default()
        },
    );
    let k3 = s.sh.len() / s.len();
    let run = |sparse: bool| {
        let mut b = GpuBackend::new(&crate::gpu::GpuOptions::default()).unwrap();
        b.sparse_adam = sparse;
        b.upload(&s, &adam).unwrap();
        b.step(&input).unwrap();
        let (p, a, _) = b.download().unwrap();
        (p, a)
    };
    let (sp, sa) = run(true);
    assert_eq!(sp.means[5], s.means[5]);
    assert_eq!(sp.sh[5 * k3..6 * k3], s.sh[5 * k3..6 * k3]);
    assert_eq!(sp.opacity_logits[5], s.opacity_logits[5]);
    assert_eq!(sa.m.means[5], adam.m.means[5]);
    assert_eq!(sa.v.sh[5 * k3..6 * k3], adam.v.sh[5 * k3..6 * k3]);
    let (dp, da) = run(false);
    assert_ne!(dp.means[5], s.means[5], "dense Adam coasts on momentum");
    assert_ne!(da.m.means[5], adam.m.means[5], "dense Adam decays moments");
    // Visible splats get the same update either way.
    let visible_same = (0..s.len())
        .filter(|&i| i != 5)
        .filter(|&i| sp.opacity_logits[i] == dp.opacity_logits[i])
        .count();
    assert!(visible_same * 10 >= (s.len() - 1) * 7, "{visible_same}");
}

/// Adam skips SH coefficients above every degree trained since the upload
/// only while their moments are zero (torch's update is then the identity):
/// a degree-3 model rendered at degree 0 leaves them bit-identical to the
/// CPU's dense Adam, and with non-zero uploaded moments there it still
/// updates them (momentum) exactly as the CPU does.
#[test]
fn adam_skips_untrained_sh_only_when_its_moments_are_zero() {
    if ctx().is_none() {
        return;
    }
    let cam = camera(64, 48);
    let s = random_splats(150, 3, 91, false);
    let k3 = s.sh.len() / s.len();
    let mut r = rand_pcg::Pcg64::seed_from_u64(92);
    let target = random_image(&mut r, 64, 48);
    let input = plain_input(&cam, &target, RenderOptions::default()); // SH degree 0
    let mut moving = AdamState::zeros_like(&s);
    moving.step = 4;
    for (k, (m, v)) in moving
        .m
        .sh
        .iter_mut()
        .zip(moving.v.sh.iter_mut())
        .enumerate()
    {
        if k % k3 >= 3 {
            *m = r.random_range(0.01f32..0.1);
            *v = r.random_range(0.01f32..0.1);
        }
    }
    for adam in [AdamState::zeros_like(&s), moving] {
        let mut gpu = GpuBackend::new(&crate::gpu::GpuOptions::default()).unwrap();
        let mut cpu = CpuBackend::new();
        let mut out = Vec::new();
        for b in [&mut gpu as &mut dyn TrainBackend, &mut cpu] {
            b.upload(&s, &adam).unwrap();
            b.step(&input).unwrap();
            out.push(b.download().unwrap());
        }
        let rest = |v: &[f32]| -> Vec<f32> {
            v.iter()
                .enumerate()
                .filter(|(k, _)| k % k3 >= 3)
                .map(|(_, x)| *x)
                .collect()
        };
        let (g, c) = (&out[0], &out[1]);
        let zero = adam.m.sh.iter().all(|&x| x == 0.0);
        if zero {
            assert_eq!(rest(&g.0.sh), rest(&s.sh), "untouched");
        } else {
            assert_ne!(rest(&g.0.sh), rest(&s.sh), "momentum moves them");
        }
        for (a, b, name) in [
            (rest(&g.0.sh), rest(&c.0.sh), "params"),
            (rest(&g.1.m.sh), rest(&c.1.m.sh), "m"),
            (rest(&g.1.v.sh), rest(&c.1.v.sh), "v"),
        ] {
            for (x, y) in a.iter().zip(&b) {
                assert!(
                    (x - y).abs() <= 1e-6 * y.abs().max(1.0),
                    "{name}: {x} vs {y}"
                );
            }
        }
    }
}
