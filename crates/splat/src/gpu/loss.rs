//! Host for `shaders/splat/loss.wgsl`: the masked L1 gradient w.r.t. the
//! rendered image, plus partial sums for the L1 value and PSNR. The D-SSIM
//! term (weight > 0) is computed on the CPU from a readback by the backend
//! (`train::loss::loss_and_grad`), not here.

use super::kernel::{BindingDecl, BindingKind, Kernel, KernelDecl, Recorder, groups_1d};
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

pub static DECL: KernelDecl = KernelDecl {
    name: "loss",
    source: include_str!("../../../../shaders/splat/loss.wgsl"),
    entry_points: &["l1_grad"],
    bindings: &[
        BindingDecl {
            name: "u",
            binding: 0,
            kind: BindingKind::Uniform,
        },
        BindingDecl {
            name: "image",
            binding: 1,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "target_rgb",
            binding: 2,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "mask",
            binding: 3,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "v_image",
            binding: 4,
            kind: BindingKind::StorageRw,
        },
        BindingDecl {
            name: "partials",
            binding: 5,
            kind: BindingKind::StorageRw,
        },
    ],
    uniform: Some(("LossUniforms", std::mem::size_of::<LossUniforms>())),
    uses_grad_atomics: false,
};

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

/// The compiled kernel.
pub struct Loss {
    kernel: Kernel,
}

impl Loss {
    pub fn new(ctx: &GpuContext) -> Self {
        Loss {
            kernel: Kernel::new(ctx, &DECL),
        }
    }

    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &LossArgs,
    ) -> Result<(), GpuError> {
        let u = ctx.uniform("loss_u", &a.uniforms);
        let bind = self.kernel.bind(
            ctx,
            &[
                ("u", &u),
                ("image", a.image),
                ("target_rgb", a.target),
                ("mask", a.mask),
                ("v_image", a.v_image),
                ("partials", a.partials),
            ],
        )?;
        rec.dispatch(
            &self.kernel,
            "l1_grad",
            &bind,
            groups_1d(a.uniforms.n_pixels, WORKGROUP_SIZE),
        )
    }
}
