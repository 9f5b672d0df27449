//! Host for `shaders/splat/rasterize_backward.wgsl`: backward of the tile
//! rasterizer (INRIA `backward.cu` renderCUDA; reference
//! `reference::rasterize_backward`). Per-splat gradients are accumulated with
//! float atomics when the device has `SHADER_FLOAT32_ATOMIC`, else with a
//! compare-and-swap loop (chosen when the pipeline is built, see
//! `kernel::ATOMIC_CAS_WGSL`).

use super::kernel::{BindingDecl, BindingKind, Kernel, KernelDecl, Recorder};
use super::project::CameraUniforms;
use super::{GpuContext, GpuError};

/// Workgroup size: one tile of 16×16 pixels, each invocation owning a
/// column of `PIXELS_PER_THREAD` pixels.
pub const WORKGROUP_SIZE: [u32; 2] = [16, 1];
/// Vertically adjacent pixels per invocation (`PPT` in the shader).
pub const PIXELS_PER_THREAD: u32 = 16;
/// f32 per splat in the gradient buffer (the `ProjectedGrads` layout).
pub const GRAD_STRIDE: u64 = 12;

pub static DECL: KernelDecl = KernelDecl {
    name: "rasterize_backward",
    source: concat!(
        include_str!("../../../../shaders/splat/block_lists.wgsl"),
        include_str!("../../../../shaders/splat/rasterize_backward.wgsl")
    ),
    entry_points: &["rasterize_backward_main"],
    bindings: &[
        BindingDecl {
            name: "cam",
            binding: 0,
            kind: BindingKind::Uniform,
        },
        BindingDecl {
            name: "projected",
            binding: 1,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "tile_values",
            binding: 2,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "ranges",
            binding: 3,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "final_t",
            binding: 4,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "last_contrib",
            binding: 5,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "v_image",
            binding: 6,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "grads",
            binding: 7,
            kind: BindingKind::StorageRw,
        },
    ],
    uniform: Some(("CameraUniforms", std::mem::size_of::<CameraUniforms>())),
    uses_grad_atomics: true,
};

/// Buffers of one backward raster.
pub struct RasterBackwardArgs<'a> {
    pub cam: &'a wgpu::Buffer,
    pub projected: &'a wgpu::Buffer,
    pub tile_values: &'a wgpu::Buffer,
    pub ranges: &'a wgpu::Buffer,
    pub final_t: &'a wgpu::Buffer,
    pub last_contrib: &'a wgpu::Buffer,
    /// dL/d image, `3·w·h` f32.
    pub v_image: &'a wgpu::Buffer,
    /// `12·n` f32 out ([`crate::types::ProjectedGrads`] layout); cleared here.
    pub grads: &'a wgpu::Buffer,
    pub grid: (u32, u32),
}

/// The compiled kernel.
pub struct RasterizeBackward {
    kernel: Kernel,
}

impl RasterizeBackward {
    pub fn new(ctx: &GpuContext) -> Self {
        RasterizeBackward {
            kernel: Kernel::new(ctx, &DECL),
        }
    }

    /// Record: clear `grads`, then accumulate into it.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &RasterBackwardArgs,
    ) -> Result<(), GpuError> {
        rec.encoder.clear_buffer(a.grads, 0, None);
        let bind = self.kernel.bind(
            ctx,
            &[
                ("cam", a.cam),
                ("projected", a.projected),
                ("tile_values", a.tile_values),
                ("ranges", a.ranges),
                ("final_t", a.final_t),
                ("last_contrib", a.last_contrib),
                ("v_image", a.v_image),
                ("grads", a.grads),
            ],
        )?;
        rec.dispatch(
            &self.kernel,
            "rasterize_backward_main",
            &bind,
            [a.grid.0, a.grid.1, 1],
        )
    }
}
