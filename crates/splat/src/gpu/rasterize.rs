//! Host for `shaders/splat/rasterize.wgsl`: the forward tile rasterizer
//! (Kerbl et al. 2023 §6; reference `reference::rasterize::rasterize_t`).
//! One workgroup per 16×16 tile, several pixels per invocation.

use super::kernel::{BindingDecl, BindingKind, Kernel, KernelDecl, Recorder};
use super::project::CameraUniforms;
use super::{GpuContext, GpuError};

/// Workgroup size: one 16×16 tile, each invocation owning a column of
/// `PIXELS_PER_THREAD` pixels.
pub const WORKGROUP_SIZE: [u32; 2] = [16, 1];
/// Vertically adjacent pixels per invocation (`PPT` in the shader).
pub const PIXELS_PER_THREAD: u32 = 16;

pub static DECL: KernelDecl = KernelDecl {
    name: "rasterize",
    source: concat!(
        include_str!("../../../../shaders/splat/block_lists.wgsl"),
        include_str!("../../../../shaders/splat/rasterize.wgsl")
    ),
    entry_points: &["rasterize_main"],
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
            name: "image",
            binding: 4,
            kind: BindingKind::StorageRw,
        },
        BindingDecl {
            name: "final_t",
            binding: 5,
            kind: BindingKind::StorageRw,
        },
        BindingDecl {
            name: "last_contrib",
            binding: 6,
            kind: BindingKind::StorageRw,
        },
    ],
    uniform: Some(("CameraUniforms", std::mem::size_of::<CameraUniforms>())),
    uses_grad_atomics: false,
};

/// Buffers of one forward raster.
pub struct RasterArgs<'a> {
    pub cam: &'a wgpu::Buffer,
    pub projected: &'a wgpu::Buffer,
    pub tile_values: &'a wgpu::Buffer,
    pub ranges: &'a wgpu::Buffer,
    /// `3·w·h` f32 out.
    pub image: &'a wgpu::Buffer,
    /// `w·h` f32 out.
    pub final_t: &'a wgpu::Buffer,
    /// `w·h` u32 out.
    pub last_contrib: &'a wgpu::Buffer,
    /// Tile grid.
    pub grid: (u32, u32),
}

/// The compiled kernel.
pub struct Rasterize {
    kernel: Kernel,
}

impl Rasterize {
    pub fn new(ctx: &GpuContext) -> Self {
        Rasterize {
            kernel: Kernel::new(ctx, &DECL),
        }
    }

    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &RasterArgs,
    ) -> Result<(), GpuError> {
        let bind = self.kernel.bind(
            ctx,
            &[
                ("cam", a.cam),
                ("projected", a.projected),
                ("tile_values", a.tile_values),
                ("ranges", a.ranges),
                ("image", a.image),
                ("final_t", a.final_t),
                ("last_contrib", a.last_contrib),
            ],
        )?;
        rec.dispatch(
            &self.kernel,
            "rasterize_main",
            &bind,
            [a.grid.0, a.grid.1, 1],
        )
    }
}
