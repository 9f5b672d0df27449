//! Host for `shaders/splat/adam.wgsl`: Adam on the GPU, one dispatch per
//! parameter group, matching `train::adam::adam_step` (torch.optim.Adam,
//! INRIA ε = 1e-15) so the parameters and moments never leave the device.

use super::kernel::{Recorder, groups_1d, kernel};
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup.
pub const WORKGROUP_SIZE: u32 = 256;

/// Uniforms of one group update (48 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct AdamUniforms {
    /// Elements updated: splats × `width`.
    pub n: u32,
    /// Leading elements of each splat's row that are updated.
    pub width: u32,
    /// Elements per splat in the buffers (≥ `width`).
    pub row: u32,
    /// Leading elements of each row using `lr_head` (3 = the SH DC of r, g, b).
    pub head: u32,
    /// 1: only splats with radius > 0 in `AdamArgs::visible` are updated
    /// (parameter and moments); 0 = dense.
    pub sparse: u32,
    pub lr: f32,
    pub lr_head: f32,
    pub beta1: f32,
    pub beta2: f32,
    /// 1 − β1ᵗ.
    pub bc1: f32,
    /// sqrt(1 − β2ᵗ).
    pub sbc2: f32,
    pub eps: f32,
}

impl AdamUniforms {
    /// Step `t` (1-based) of `cfg`: its betas, ε and bias corrections, with
    /// the group fields (sizes, rates) zero for the caller to fill in.
    pub fn for_step(cfg: &crate::train::adam::AdamConfig, t: i32) -> Self {
        AdamUniforms {
            n: 0,
            width: 1,
            row: 1,
            head: 0,
            sparse: 0,
            lr: 0.0,
            lr_head: 0.0,
            beta1: cfg.beta1,
            beta2: cfg.beta2,
            bc1: 1.0 - cfg.beta1.powi(t),
            sbc2: (1.0 - cfg.beta2.powi(t)).sqrt(),
            eps: cfg.eps,
        }
    }
}

kernel! {
    /// The compiled kernel.
    pub struct Adam;
    decl DECL = "adam";
    bindings AdamBindings {
        u: uniform AdamUniforms,
        params: read_write "array<f32>",
        grads: read "array<f32>",
        exp_avg: read_write "array<f32>",
        exp_avg_sq: read_write "array<f32>",
        projected: read "array<ProjectedSplat>",
    }
    entry_points { adam_main: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE }
}

/// One group's buffers.
pub struct AdamArgs<'a> {
    pub params: &'a wgpu::Buffer,
    pub grads: &'a wgpu::Buffer,
    pub exp_avg: &'a wgpu::Buffer,
    pub exp_avg_sq: &'a wgpu::Buffer,
    /// This step's projected splats (radius > 0 = visible); read only when
    /// `uniforms.sparse_width > 0`.
    pub visible: &'a wgpu::Buffer,
    pub uniforms: AdamUniforms,
}

impl Adam {
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &AdamArgs,
    ) -> Result<(), GpuError> {
        if a.uniforms.n == 0 {
            return Ok(());
        }
        let u = ctx.uniform("adam_u", &a.uniforms);
        self.record(
            ctx,
            rec,
            "adam_main",
            &AdamBindings {
                u: &u,
                params: a.params,
                grads: a.grads,
                exp_avg: a.exp_avg,
                exp_avg_sq: a.exp_avg_sq,
                projected: a.visible,
            },
            groups_1d(a.uniforms.n, WORKGROUP_SIZE),
        )
    }
}
