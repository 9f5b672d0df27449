//! [`GpuBackend`]: the wgpu implementation of [`TrainBackend`]. Parameters,
//! Adam moments and densification statistics stay on the device across
//! steps; a step reads back only the tile-intersection count (to size the
//! key buffers), the loss partial sums and the visible count. The loss
//! gradient is computed on the device: masked L1 (`loss.wgsl`) plus, with a
//! D-SSIM weight > 0, masked D-SSIM (`ssim.wgsl`, checked against the CPU
//! `train::loss::loss_and_grad`).

use super::adam::{Adam, AdamArgs, AdamUniforms};
use super::backward::{BackwardArgs, BackwardKernels, record_backward};
use super::densify_stats::{DensifyStatsKernel, StatsArgs, StatsBuffers};
use super::forward::{ForwardInput, ForwardKernels, Timings, forward, forward_in, upload_splats};
use super::kernel::{Recorder, Scratch};
use super::loss::{Loss, LossArgs, LossUniforms, blocks};
use super::mcmc::McmcKernels;
use super::project::ParamBuffers;
use super::project_backward::GradBuffers;
use super::project_backward::V_PROJ_FLOATS;
use super::ssim::{Ssim, SsimArgs};
use super::{GpuContext, GpuError, GpuOptions};
use crate::backend::{MeansNoise, Regularization};
use crate::backend::{StepInput, StepStats, TrainBackend, check_step_input};
use crate::error::{Result, SplatError};
use crate::train::adam::AdamConfig;
use crate::types::{AdamState, DensifyStats, RenderCamera, RenderOptions, RenderOutput, Splats};
use std::collections::HashMap;

impl From<GpuError> for SplatError {
    fn from(e: GpuError) -> Self {
        SplatError::Gpu(e.to_string())
    }
}

/// A training view cached on the device.
struct ViewCache {
    target: wgpu::Buffer,
    mask: Option<wgpu::Buffer>,
    /// Σ mask (kept pixels).
    kept: f64,
}

/// Everything resident for training.
struct State {
    params: ParamBuffers,
    m: ParamBuffers,
    v: ParamBuffers,
    grads: GradBuffers,
    stats: StatsBuffers,
    step: u64,
    /// Highest SH degree whose coefficients may have non-zero Adam moments
    /// (from the uploaded moments, then every degree trained since). Adam
    /// skips the coefficients above it: their gradient is zero and so are
    /// their moments, which makes torch's update the identity there.
    sh_moments: u32,
}

/// The wgpu training backend.
pub struct GpuBackend {
    pub ctx: GpuContext,
    fwd: ForwardKernels,
    /// Loss, backward, statistics, regulariser and Adam kernels.
    k: StepKernels,
    /// Every transient buffer of a step (render, loss, D-SSIM maps, sort and
    /// scan scratch, projected gradients), kept across steps.
    scratch: Scratch,
    /// MCMC regularisers added in every step.
    reg: Regularization,
    state: Option<State>,
    views: HashMap<usize, ViewCache>,
    /// Adam hyper-parameters (INRIA defaults).
    pub adam_config: AdamConfig,
    /// Record per-dispatch timestamps in the next steps (see [`GpuBackend::last_timings`]).
    pub profile: bool,
    /// Sparse ("selective") Adam, as gsplat's `SelectiveAdam` / Brush: only
    /// splats visible in the step's view (radius > 0) update their
    /// parameters and moments. Default off = dense torch Adam, which the CPU
    /// reference implements; on, invisible splats keep their moments instead
    /// of decaying them and do not coast on momentum.
    pub sparse_adam: bool,
    timings: Timings,
    /// (tile, splat) pairs of the last step's render.
    intersections: u32,
}

fn unflat<const K: usize>(v: &[f32]) -> Vec<[f32; K]> {
    v.chunks_exact(K)
        .map(|c| std::array::from_fn(|i| c[i]))
        .collect()
}

impl GpuBackend {
    /// Open a device and compile every kernel (`GpuError::NoAdapter` when no
    /// adapter exists, so callers can fall back to the CPU backend).
    pub fn new(opts: &GpuOptions) -> std::result::Result<Self, GpuError> {
        let ctx = GpuContext::new(opts)?;
        Ok(GpuBackend {
            fwd: ForwardKernels::new(&ctx),
            k: StepKernels {
                bwd: BackwardKernels::new(&ctx),
                adam: Adam::new(&ctx),
                loss: Loss::new(&ctx),
                ssim: Ssim::new(&ctx),
                stats: DensifyStatsKernel::new(&ctx),
                mcmc: McmcKernels::new(&ctx),
            },
            scratch: Scratch::default(),
            reg: Regularization::default(),
            ctx,
            state: None,
            views: HashMap::new(),
            adam_config: AdamConfig::default(),
            profile: false,
            sparse_adam: false,
            timings: Vec::new(),
            intersections: 0,
        })
    }

    /// Per-dispatch timings of the last step (empty unless `profile` is set
    /// and the device has timestamp queries).
    pub fn last_timings(&self) -> &Timings {
        &self.timings
    }

    /// Number of (tile, splat) intersections in the last step's render.
    pub fn last_intersections(&self) -> u32 {
        self.intersections
    }

    fn upload_view(&self, input: &StepInput<'_>) -> ViewCache {
        let kept = input
            .mask
            .map_or((input.camera.width * input.camera.height) as f64, |m| {
                m.iter().map(|&v| v as f64).sum()
            });
        ViewCache {
            target: self.ctx.upload("target", input.target),
            mask: input.mask.map(|m| self.ctx.upload("mask", m)),
            kept,
        }
    }

    fn moments(&self, a: &Splats) -> std::result::Result<ParamBuffers, GpuError> {
        upload_splats(&self.ctx, a)
    }
}

/// Highest SH degree with a non-zero coefficient in the moments `m` of
/// `params` (0 when only the DC terms are non-zero).
fn moment_degree(m: &Splats, params: &Splats) -> u32 {
    let k = params.coeffs_per_channel();
    let mut last = 0;
    for row in m.sh.chunks_exact(3 * k.max(1)) {
        if let Some(j) = row.iter().rposition(|&x| x != 0.0) {
            last = last.max(j / 3);
        }
    }
    // Coefficient index c belongs to degree floor(sqrt(c)).
    (last as f64).sqrt().floor() as u32
}

/// Splats → moments container check.
fn same_shape(a: &Splats, b: &Splats) -> bool {
    a.len() == b.len() && a.sh.len() == b.sh.len()
}

/// The kernels a training step records after the forward pass.
struct StepKernels {
    bwd: BackwardKernels,
    adam: Adam,
    loss: Loss,
    ssim: Ssim,
    stats: DensifyStatsKernel,
    /// MCMC position noise and regulariser kernels.
    mcmc: McmcKernels,
}

/// The loss of one step on the device: dL/d image and the partial sums the
/// host reads back for the loss value.
struct LossOutputs {
    v_image: wgpu::Buffer,
    /// (Σ m|d|, Σ m d²) per block of pixels.
    partials: wgpu::Buffer,
    /// Σ g·S per block (mean SSIM); written only when `lambda > 0`.
    ssim_partials: wgpu::Buffer,
    blocks: usize,
    /// Partial sums in `ssim_partials`.
    ssim_blocks: usize,
    /// 1 / (3 · kept pixels), 0 when nothing is kept.
    norm: f64,
    /// D-SSIM weight λ.
    lambda: f64,
}

impl StepKernels {
    /// Masked L1 gradient and, with λ > 0, the D-SSIM term added to it.
    fn record_loss(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        image: &wgpu::Buffer,
        view: &ViewCache,
        cam: &RenderCamera,
        input: &StepInput<'_>,
    ) -> std::result::Result<LossOutputs, GpuError> {
        let pixels = cam.width * cam.height;
        let v_image = rec.storage("v_image", pixels as u64 * 12);
        let lambda = input.loss.ssim_weight as f64;
        let partials = rec.storage("loss_partials", blocks(pixels) as u64 * 8);
        let scale = if view.kept > 0.0 {
            (1.0 - lambda) / (3.0 * view.kept)
        } else {
            0.0
        };
        let norm = if view.kept > 0.0 {
            1.0 / (3.0 * view.kept)
        } else {
            0.0
        };
        let mask_buf = view.mask.as_ref().unwrap_or(&view.target);
        self.loss.dispatch(
            ctx,
            rec,
            &LossArgs {
                image,
                target: &view.target,
                mask: mask_buf,
                v_image: &v_image,
                partials: &partials,
                uniforms: LossUniforms {
                    n_pixels: pixels,
                    has_mask: view.mask.is_some() as u32,
                    pad: [0; 2],
                    scale: scale as f32,
                    pad2: [0.0; 3],
                },
            },
        )?;
        let ssim_blocks = super::ssim::partial_blocks(cam.width, cam.height);
        let ssim_partials = rec.storage("ssim_partials", ssim_blocks as u64 * 4);
        if lambda > 0.0 {
            // D-SSIM on the device, added to the L1 gradient in v_image.
            let need = super::ssim::SCRATCH_MAPS * pixels as u64 * 4;
            let s0 = rec.storage("ssim_scratch0", need);
            let s1 = rec.storage("ssim_scratch1", need);
            self.ssim.dispatch(
                ctx,
                rec,
                &SsimArgs {
                    image,
                    target: &view.target,
                    mask: mask_buf,
                    has_mask: view.mask.is_some(),
                    v_image: &v_image,
                    partials: &ssim_partials,
                    scratch: [&s0, &s1],
                    width: cam.width,
                    height: cam.height,
                    norm: norm as f32,
                    lambda: lambda as f32,
                },
            )?;
        }
        Ok(LossOutputs {
            v_image,
            partials,
            ssim_partials,
            blocks: blocks(pixels) as usize,
            ssim_blocks: ssim_blocks as usize,
            norm,
            lambda,
        })
    }

    /// Backward of the render into `st.grads`, densification statistics,
    /// and the MCMC regulariser gradients (nothing when `reg` is zero).
    fn record_backward(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        st: &State,
        fs: &super::forward::ForwardState,
        v_image: &wgpu::Buffer,
        reg: &Regularization,
    ) -> std::result::Result<(), GpuError> {
        let v_proj = rec.storage("v_proj", st.params.n as u64 * V_PROJ_FLOATS * 4);
        record_backward(
            ctx,
            &self.bwd,
            rec,
            &BackwardArgs {
                params: &st.params,
                state: fs,
                v_image,
                v_proj: &v_proj,
                grads: &st.grads,
            },
        )?;
        self.stats.dispatch(
            ctx,
            rec,
            &StatsArgs {
                cam: &fs.cam,
                projected: &fs.projected,
                v_proj: &v_proj,
                stats: &st.stats,
                n: st.params.n,
            },
        )?;
        self.mcmc.record_reg(ctx, rec, &st.params, &st.grads, reg)
    }

    /// Adam on every parameter group (dense, as torch, unless `sparse`:
    /// then only splats visible in `projected`).
    #[allow(clippy::too_many_arguments)]
    fn record_adam(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        st: &State,
        projected: &wgpu::Buffer,
        lr: &crate::backend::LearningRates,
        base: AdamUniforms,
        sparse: bool,
    ) -> std::result::Result<(), GpuError> {
        let n = st.params.n;
        let k3 = crate::types::sh_coeffs(st.params.sh_degree) as u32 * 3;
        let k3_live = (crate::types::sh_coeffs(st.sh_moments) as u32 * 3).min(k3);
        let groups = [
            (
                &st.params.means,
                &st.grads.means,
                &st.m.means,
                &st.v.means,
                3,
                lr.means,
                lr.means,
                0,
            ),
            (
                &st.params.log_scales,
                &st.grads.log_scales,
                &st.m.log_scales,
                &st.v.log_scales,
                3,
                lr.scales,
                lr.scales,
                0,
            ),
            (
                &st.params.rotations,
                &st.grads.rotations,
                &st.m.rotations,
                &st.v.rotations,
                4,
                lr.rotations,
                lr.rotations,
                0,
            ),
            (
                &st.params.opacity_logits,
                &st.grads.opacity_logits,
                &st.m.opacity_logits,
                &st.v.opacity_logits,
                1,
                lr.opacity,
                lr.opacity,
                0,
            ),
            (
                &st.params.sh,
                &st.grads.sh,
                &st.m.sh,
                &st.v.sh,
                k3,
                lr.sh_rest,
                lr.sh_dc,
                3,
            ),
        ];
        for (p, g, m, v, row, lr_rest, lr_head, head) in groups {
            let width = if head > 0 { k3_live } else { row };
            let uniforms = AdamUniforms {
                n: width * n,
                width,
                row,
                head,
                sparse: sparse as u32,
                lr: lr_rest,
                lr_head,
                ..base
            };
            self.adam.dispatch(
                ctx,
                rec,
                &AdamArgs {
                    params: p,
                    grads: g,
                    exp_avg: m,
                    exp_avg_sq: v,
                    visible: projected,
                    uniforms,
                },
            )?;
        }
        Ok(())
    }
}

/// The step's loss value, PSNR and visible count, read back after the submit.
fn read_step_stats(
    ctx: &GpuContext,
    loss: &LossOutputs,
    kept: f64,
    visible: &wgpu::Buffer,
) -> std::result::Result<StepStats, GpuError> {
    let parts: Vec<f32> = ctx.read(&loss.partials, loss.blocks * 2)?;
    let sums = parts.chunks_exact(2).fold((0.0f64, 0.0f64), |a, c| {
        (a.0 + c[0] as f64, a.1 + c[1] as f64)
    });
    let l1 = sums.0 * loss.norm;
    let mse = sums.1 * loss.norm;
    let lambda = loss.lambda;
    let mut ssim = 1.0f64;
    if lambda > 0.0 {
        let p: Vec<f32> = ctx.read(&loss.ssim_partials, loss.ssim_blocks)?;
        ssim = p.iter().map(|&v| v as f64).sum();
    }
    let value = if kept > 0.0 {
        (1.0 - lambda) * l1 + lambda * (1.0 - ssim)
    } else {
        0.0
    };
    let visible: u32 = ctx.read::<u32>(visible, 1)?[0];
    Ok(StepStats {
        loss: value as f32,
        l1: l1 as f32,
        ssim: ssim as f32,
        psnr: (10.0 * (1.0 / mse.max(1e-20)).log10()) as f32,
        visible,
    })
}

impl TrainBackend for GpuBackend {
    fn name(&self) -> String {
        format!(
            "wgpu ({}, {:?})",
            self.ctx.adapter_info.name, self.ctx.adapter_info.backend
        )
    }

    fn upload(&mut self, params: &Splats, adam: &AdamState) -> Result<()> {
        crate::error::check_splats(params)?;
        if !same_shape(params, &adam.m) || !same_shape(params, &adam.v) {
            return Err(SplatError::Invalid(
                "Adam state does not match the splats".into(),
            ));
        }
        let p = upload_splats(&self.ctx, params)?;
        let sh_moments = moment_degree(&adam.m, params).max(moment_degree(&adam.v, params));
        // Moments may carry a stale sh_degree; give them the params' one.
        let mut m = adam.m.clone();
        let mut v = adam.v.clone();
        m.sh_degree = params.sh_degree;
        v.sh_degree = params.sh_degree;
        let (m, v) = (self.moments(&m)?, self.moments(&v)?);
        let grads = GradBuffers::like(&self.ctx, &p);
        let stats = StatsBuffers::zeros(&self.ctx, p.n);
        self.state = Some(State {
            params: p,
            m,
            v,
            grads,
            stats,
            step: adam.step,
            sh_moments,
        });
        Ok(())
    }

    fn step(&mut self, input: &StepInput<'_>) -> Result<StepStats> {
        check_step_input(input)?;
        if self.state.is_none() {
            return Err(SplatError::Invalid("step before upload".into()));
        }
        let cache_new = match input.view_id {
            Some(id) => !self.views.contains_key(&id),
            None => true,
        };
        let fresh = cache_new.then(|| self.upload_view(input));
        if let (Some(id), Some(f)) = (input.view_id, fresh) {
            self.views.insert(id, f);
        }
        let tmp;
        let view = match input.view_id.and_then(|id| self.views.get(&id)) {
            Some(v) => v,
            None => {
                tmp = self.upload_view(input);
                &tmp
            }
        };
        let Some(st) = self.state.as_mut() else {
            return Err(SplatError::Invalid("step before upload".into()));
        };
        let ctx = &self.ctx;
        let cam = input.camera;
        let allocs_before = self.scratch.allocations;
        let (fs, mut timings, mut rec) = forward_in(
            ctx,
            &self.fwd,
            Some(&mut self.scratch),
            &ForwardInput {
                params: &st.params,
                cam,
                opts: &input.render,
                profile: self.profile,
            },
        )?;
        let loss = self
            .k
            .record_loss(ctx, &mut rec, &fs.image, view, cam, input)?;
        self.k
            .record_backward(ctx, &mut rec, st, &fs, &loss.v_image, &self.reg)?;
        st.step += 1;
        st.sh_moments = st
            .sh_moments
            .max(input.render.sh_degree.min(st.params.sh_degree));
        let base = AdamUniforms::for_step(&self.adam_config, st.step.min(i32::MAX as u64) as i32);
        self.k.record_adam(
            ctx,
            &mut rec,
            st,
            &fs.projected,
            &input.lr,
            base,
            self.sparse_adam,
        )?;
        let t_sub = std::time::Instant::now();
        timings.extend(rec.finish()?);
        timings.push(("host:step_submit_wait", t_sub.elapsed().as_secs_f64() * 1e3));
        timings.push((
            "count:buffer_allocations",
            (self.scratch.allocations - allocs_before) as f64,
        ));
        let t_stats = std::time::Instant::now();
        let stats = read_step_stats(ctx, &loss, view.kept, &st.stats.visible)?;
        timings.push(("host:stats_readback", t_stats.elapsed().as_secs_f64() * 1e3));
        self.timings = timings;
        self.intersections = fs.intersections;
        Ok(stats)
    }

    fn set_regularization(&mut self, reg: Regularization) -> Result<()> {
        self.reg = reg;
        Ok(())
    }

    fn perturb_means(&mut self, noise: &MeansNoise) -> Result<()> {
        let Some(st) = self.state.as_ref() else {
            return Err(SplatError::Invalid("perturb_means before upload".into()));
        };
        let mut rec = Recorder::new(&self.ctx, false);
        self.k
            .mcmc
            .record_noise(&self.ctx, &mut rec, &st.params, noise)?;
        rec.finish()?;
        Ok(())
    }

    fn download(&mut self) -> Result<(Splats, AdamState, DensifyStats)> {
        let Some(st) = self.state.as_ref() else {
            return Err(SplatError::Invalid("download before upload".into()));
        };
        let ctx = &self.ctx;
        let n = st.params.n as usize;
        let k3 = crate::types::sh_coeffs(st.params.sh_degree) * 3;
        let read = |p: &ParamBuffers| -> std::result::Result<Splats, GpuError> {
            Ok(Splats {
                means: unflat(&ctx.read::<f32>(&p.means, n * 3)?),
                log_scales: unflat(&ctx.read::<f32>(&p.log_scales, n * 3)?),
                rotations: unflat(&ctx.read::<f32>(&p.rotations, n * 4)?),
                opacity_logits: ctx.read(&p.opacity_logits, n)?,
                sh: ctx.read(&p.sh, n * k3)?,
                sh_degree: st.params.sh_degree,
            })
        };
        let params = read(&st.params)?;
        let adam = AdamState {
            step: st.step,
            m: read(&st.m)?,
            v: read(&st.v)?,
        };
        let stats = DensifyStats {
            grad_accum: ctx.read(&st.stats.grad_accum, n)?,
            count: ctx.read(&st.stats.count, n)?,
            max_radius: ctx.read(&st.stats.max_radius, n)?,
        };
        Ok((params, adam, stats))
    }

    fn render(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
    ) -> Result<RenderOutput> {
        let p = upload_splats(&self.ctx, splats)?;
        let (fs, _) = forward(&self.ctx, &self.fwd, &p, cam, opts, false)?;
        let px = (cam.width * cam.height) as usize;
        Ok(RenderOutput {
            width: cam.width,
            height: cam.height,
            image: self.ctx.read(&fs.image, px * 3)?,
            final_transmittance: self.ctx.read(&fs.final_t, px)?,
            projected: fs.read_projected(&self.ctx)?,
        })
    }
}
