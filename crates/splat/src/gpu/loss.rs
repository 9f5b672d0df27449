//! Host for `shaders/splat/loss.wgsl`: the masked L1 gradient w.r.t. the
//! rendered image, plus partial sums for the L1 value and PSNR. The D-SSIM
//! term (weight > 0) is computed on the CPU from a readback by the backend
//! (`train::loss::loss_and_grad`), not here.

use super::kernel::{Recorder, groups_1d, kernel};
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup (pixels per partial sum).
pub const WORKGROUP_SIZE: u32 = 256;

/// Uniforms (32 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct LossUniforms {
    pub n_pixels: u32,
    pub has_mask: u32,
    pub pad: [u32; 2],
    /// (1 − λ) / (3 · Σ mask).
    pub scale: f32,
    pub pad2: [f32; 3],
}

kernel! {
    /// The compiled kernel.
    pub struct Loss;
    decl DECL = "loss";
    bindings LossBindings {
        u: uniform LossUniforms,
        image: read "array<f32>",
        target_rgb: read "array<f32>",
        mask: read "array<f32>",
        v_image: read_write "array<f32>",
        partials: read_write "array<f32>",
    }
    entry_points { l1_grad: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE }
}

/// Buffers of one loss evaluation.
pub struct LossArgs<'a> {
    pub image: &'a wgpu::Buffer,
    pub target: &'a wgpu::Buffer,
    /// Per-pixel weights; any buffer when `uniforms.has_mask == 0`.
    pub mask: &'a wgpu::Buffer,
    pub v_image: &'a wgpu::Buffer,
    /// `2 × ceil(pixels / 256)` f32 out: (Σ m|d|, Σ m d²) per block.
    pub partials: &'a wgpu::Buffer,
    pub uniforms: LossUniforms,
}

/// Number of partial-sum blocks for `pixels`.
pub fn blocks(pixels: u32) -> u32 {
    pixels.div_ceil(WORKGROUP_SIZE).max(1)
}

impl Loss {
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &LossArgs,
    ) -> Result<(), GpuError> {
        let u = ctx.uniform("loss_u", &a.uniforms);
        self.record(
            ctx,
            rec,
            "l1_grad",
            &LossBindings {
                u: &u,
                image: a.image,
                target_rgb: a.target,
                mask: a.mask,
                v_image: a.v_image,
                partials: a.partials,
            },
            groups_1d(a.uniforms.n_pixels, WORKGROUP_SIZE),
        )
    }
}
