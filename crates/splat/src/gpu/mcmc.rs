//! Host for `shaders/splat/mcmc_noise.wgsl` and `mcmc_reg.wgsl`: the two
//! per-step terms of 3DGS-MCMC (Kheradmand et al. 2024, as gsplat's
//! `MCMCStrategy`) on the device, so the parameters never leave the GPU —
//! SGLD position noise after the optimiser step and the opacity/scale L1
//! regulariser gradients before it. Both mirror `reference::mcmc` (same PCG
//! hash, same operation order); `tests` checks GPU against CPU.

use super::kernel::{Recorder, groups_1d, kernel};
use super::project::ParamBuffers;
use super::project_backward::GradBuffers;
use super::{GpuContext, GpuError};
use crate::backend::{MeansNoise, Regularization};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup (both kernels).
pub const WORKGROUP_SIZE: u32 = 256;

/// Uniforms of the noise kernel (32 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct McmcNoiseUniforms {
    pub n: u32,
    pub seed: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub scale: f32,
    pub k: f32,
    pub t: f32,
    pub pad2: f32,
}

/// Uniforms of the regulariser kernel (32 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct McmcRegUniforms {
    pub n: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
    /// opacity_reg / N.
    pub w_opacity: f32,
    /// scale_reg / (3N).
    pub w_scale: f32,
    pub pad3: f32,
    pub pad4: f32,
}

kernel! {
    /// The compiled position-noise kernel.
    pub struct McmcNoise;
    decl NOISE_DECL = "mcmc_noise";
    bindings NoiseBindings {
        u: uniform McmcNoiseUniforms,
        means: read_write "array<f32>",
        log_scales: read "array<f32>",
        rotations: read "array<f32>",
        opacity_logits: read "array<f32>",
    }
    entry_points { mcmc_noise_main: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE }
}

kernel! {
    /// The compiled regulariser kernel.
    pub struct McmcReg;
    decl REG_DECL = "mcmc_reg";
    bindings RegBindings {
        u: uniform McmcRegUniforms,
        log_scales: read "array<f32>",
        opacity_logits: read "array<f32>",
        grad_log_scales: read_write "array<f32>",
        grad_opacity_logits: read_write "array<f32>",
    }
    entry_points { mcmc_reg_main: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE }
}

/// Both compiled kernels.
pub struct McmcKernels {
    noise: McmcNoise,
    reg: McmcReg,
}

impl McmcKernels {
    pub fn new(ctx: &GpuContext) -> Self {
        McmcKernels {
            noise: McmcNoise::new(ctx),
            reg: McmcReg::new(ctx),
        }
    }

    /// Record the position noise on `params.means`.
    pub fn record_noise(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        params: &ParamBuffers,
        noise: &MeansNoise,
    ) -> Result<(), GpuError> {
        if params.n == 0 {
            return Ok(());
        }
        let u = ctx.uniform(
            "mcmc_noise_u",
            &McmcNoiseUniforms {
                n: params.n,
                seed: noise.seed,
                pad0: 0,
                pad1: 0,
                scale: noise.scale,
                k: noise.k,
                t: noise.t,
                pad2: 0.0,
            },
        );
        self.noise.record(
            ctx,
            rec,
            "mcmc_noise_main",
            &NoiseBindings {
                u: &u,
                means: &params.means,
                log_scales: &params.log_scales,
                rotations: &params.rotations,
                opacity_logits: &params.opacity_logits,
            },
            groups_1d(params.n, WORKGROUP_SIZE),
        )
    }

    /// Record the regulariser gradients into `grads` (after the backward
    /// pass, before Adam). Nothing is recorded for a zero regulariser.
    pub fn record_reg(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        params: &ParamBuffers,
        grads: &GradBuffers,
        reg: &Regularization,
    ) -> Result<(), GpuError> {
        if params.n == 0 || *reg == Regularization::default() {
            return Ok(());
        }
        let (w_opacity, w_scale) =
            crate::reference::mcmc::regularization_weights(reg, params.n as usize);
        let u = ctx.uniform(
            "mcmc_reg_u",
            &McmcRegUniforms {
                n: params.n,
                pad0: 0,
                pad1: 0,
                pad2: 0,
                w_opacity,
                w_scale,
                pad3: 0.0,
                pad4: 0.0,
            },
        );
        self.reg.record(
            ctx,
            rec,
            "mcmc_reg_main",
            &RegBindings {
                u: &u,
                log_scales: &params.log_scales,
                opacity_logits: &params.opacity_logits,
                grad_log_scales: &grads.log_scales,
                grad_opacity_logits: &grads.opacity_logits,
            },
            groups_1d(params.n, WORKGROUP_SIZE),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::TrainBackend;
    use crate::gpu::forward::upload_splats;
    use crate::reference::CpuBackend;
    use crate::types::{AdamState, Splats};
    use rand::{Rng, SeedableRng};

    fn splats(n: usize, seed: u64) -> Splats {
        let mut r = rand_pcg::Pcg64::seed_from_u64(seed);
        Splats {
            means: (0..n)
                .map(|_| std::array::from_fn(|_| r.random_range(-1.0..1.0)))
                .collect(),
            log_scales: (0..n)
                .map(|_| std::array::from_fn(|_| r.random_range(-4.0..-1.0)))
                .collect(),
            rotations: (0..n)
                .map(|_| std::array::from_fn(|_| r.random_range(-1.0..1.0)))
                .collect(),
            // Mostly near-dead opacities so the noise gate is open.
            opacity_logits: (0..n).map(|_| r.random_range(-8.0..-2.0)).collect(),
            sh: (0..n * 3).map(|_| r.random_range(-1.0..1.0)).collect(),
            sh_degree: 0,
        }
    }

    /// The GPU noise kernel draws the same numbers as the CPU reference and
    /// moves every mean the same way.
    #[test]
    fn noise_matches_cpu_reference() {
        let Some(ctx) = crate::gpu::tests::ctx() else {
            return;
        };
        let s = splats(3000, 4);
        let noise = MeansNoise {
            scale: 5e5 * 1.6e-4,
            k: 100.0,
            t: 0.005,
            seed: 0xDEAD_BEEF,
        };
        let mut want = s.clone();
        crate::reference::mcmc::perturb_means(&mut want, &noise);
        let p = upload_splats(ctx, &s).unwrap();
        let k = McmcKernels::new(ctx);
        let mut rec = Recorder::new(ctx, false);
        k.record_noise(ctx, &mut rec, &p, &noise).unwrap();
        rec.finish().unwrap();
        let got: Vec<f32> = ctx.read(&p.means, 3 * s.len()).unwrap();
        let mut max_delta = 0.0f32;
        let mut max_err = 0.0f32;
        for i in 0..s.len() {
            for c in 0..3 {
                let dw = want.means[i][c] - s.means[i][c];
                let dg = got[3 * i + c] - s.means[i][c];
                max_delta = max_delta.max(dw.abs());
                max_err = max_err.max((dw - dg).abs());
            }
        }
        eprintln!("noise: max |Δμ| {max_delta:e}, max GPU−CPU {max_err:e}");
        assert!(max_delta > 1e-4, "noise too small to test: {max_delta}");
        assert!(
            max_err <= 1e-4 * max_delta + 1e-7,
            "{max_err} vs {max_delta}"
        );
    }

    /// One training step with regularisers on the GPU backend equals the CPU
    /// backend's (and differs from a step without them), and
    /// `perturb_means` agrees between the backends.
    #[test]
    fn backend_regularised_step_and_noise_match_cpu() {
        use crate::backend::{LossConfig, StepInput};
        use crate::types::RenderOptions;
        if crate::gpu::tests::ctx().is_none() {
            return;
        }
        let mut s = splats(400, 9);
        for l in &mut s.opacity_logits {
            *l += 4.0;
        }
        // Odd splats sit behind the camera: no image gradient, so only the
        // regulariser moves them (Adam's first step: −lr · sign(g)).
        for (i, m) in s.means.iter_mut().enumerate() {
            m[2] += if i % 2 == 0 { 4.0 } else { -6.0 };
        }
        let cam = crate::types::RenderCamera::at_origin(64, 48, 60.0);
        let target: Vec<f32> = (0..64 * 48 * 3).map(|k| (k % 7) as f32 / 7.0).collect();
        let input = StepInput {
            camera: &cam,
            target: &target,
            mask: None,
            view_id: None,
            lr: crate::train::TrainOptions::default().learning_rates(0, 1.0),
            loss: LossConfig { ssim_weight: 0.0 },
            render: RenderOptions::default(),
        };
        let reg = Regularization {
            opacity: 0.5,
            scale: 0.5,
        };
        let adam = AdamState::zeros_like(&s);
        let mut gpu = crate::gpu::GpuBackend::new(&crate::gpu::GpuOptions::default()).unwrap();
        let mut cpu = CpuBackend::new();
        let mut plain = CpuBackend::new();
        for b in [&mut gpu as &mut dyn TrainBackend, &mut cpu, &mut plain] {
            b.upload(&s, &adam).unwrap();
        }
        gpu.set_regularization(reg).unwrap();
        cpu.set_regularization(reg).unwrap();
        let noise = MeansNoise {
            scale: 80.0,
            k: 100.0,
            t: 0.005,
            seed: 3,
        };
        for b in [&mut gpu as &mut dyn TrainBackend, &mut cpu, &mut plain] {
            b.step(&input).unwrap();
            b.perturb_means(&noise).unwrap();
        }
        let (g, _, _) = gpu.download().unwrap();
        let (c, _, _) = cpu.download().unwrap();
        let (p, _, _) = plain.download().unwrap();
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-5 * (1.0 + a.abs());
        for i in (1..s.len()).step_by(2) {
            assert_eq!(p.opacity_logits[i], s.opacity_logits[i]);
            assert!((c.opacity_logits[i] - (s.opacity_logits[i] - 0.05)).abs() < 1e-4);
            assert!((c.log_scales[i][0] - (s.log_scales[i][0] - 5e-3)).abs() < 1e-5);
        }
        for i in 0..s.len() {
            assert!(close(g.opacity_logits[i], c.opacity_logits[i]), "{i}");
            for k in 0..3 {
                assert!(close(g.log_scales[i][k], c.log_scales[i][k]), "{i}");
                assert!(close(g.means[i][k], c.means[i][k]), "{i}");
            }
        }
    }
}
