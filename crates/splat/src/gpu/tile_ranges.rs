//! Host for `shaders/splat/tile_ranges.wgsl`: per-tile `[start, end)` into the
//! tile-sorted key list, which the rasterizers walk. Reference: Kerbl et al.
//! (2023), §6 ("identify the start and end of each tile's range").

use super::kernel::{BindingDecl, BindingKind, Kernel, KernelDecl, Recorder, groups_1d};
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup.
pub const WORKGROUP_SIZE: u32 = 256;

/// Uniforms (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct RangeUniforms {
    /// Number of (tile, splat) keys.
    pub n: u32,
    pub num_tiles: u32,
    pub pad: [u32; 2],
}

pub static DECL: KernelDecl = KernelDecl {
    name: "tile_ranges",
    source: include_str!("../../../../shaders/splat/tile_ranges.wgsl"),
    entry_points: &["ranges_main"],
    bindings: &[
        BindingDecl {
            name: "u",
            binding: 0,
            kind: BindingKind::Uniform,
        },
        BindingDecl {
            name: "tile_keys",
            binding: 1,
            kind: BindingKind::StorageRead,
        },
        BindingDecl {
            name: "ranges",
            binding: 2,
            kind: BindingKind::StorageRw,
        },
    ],
    uniform: Some(("RangeUniforms", std::mem::size_of::<RangeUniforms>())),
    uses_grad_atomics: false,
};

/// Arguments: sorted tile keys in, `2 × num_tiles` u32 ranges out.
pub struct RangeArgs<'a> {
    pub tile_keys: &'a wgpu::Buffer,
    pub ranges: &'a wgpu::Buffer,
    pub n: u32,
    pub num_tiles: u32,
}

/// The compiled kernel.
pub struct TileRanges {
    kernel: Kernel,
}

impl TileRanges {
    pub fn new(ctx: &GpuContext) -> Self {
        TileRanges {
            kernel: Kernel::new(ctx, &DECL),
        }
    }

    /// Record: clear `ranges`, then mark the start and end of every run.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        args: &RangeArgs,
    ) -> Result<(), GpuError> {
        rec.encoder.clear_buffer(args.ranges, 0, None);
        if args.n == 0 {
            return Ok(());
        }
        let u = ctx.uniform(
            "ranges_u",
            &RangeUniforms {
                n: args.n,
                num_tiles: args.num_tiles,
                pad: [0; 2],
            },
        );
        let bind = self.kernel.bind(
            ctx,
            &[
                ("u", &u),
                ("tile_keys", args.tile_keys),
                ("ranges", args.ranges),
            ],
        )?;
        rec.dispatch(
            &self.kernel,
            "ranges_main",
            &bind,
            groups_1d(args.n, WORKGROUP_SIZE),
        )
    }
}
