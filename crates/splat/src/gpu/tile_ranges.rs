//! Host for `shaders/splat/tile_ranges.wgsl`: per-tile `[start, end)` into the
//! tile-sorted key list, which the rasterizers walk. Reference: Kerbl et al.
//! (2023), §6 ("identify the start and end of each tile's range").

use super::kernel::{Recorder, groups_1d, kernel};
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

kernel! {
    /// The compiled kernel.
    pub struct TileRanges;
    decl DECL = "tile_ranges";
    bindings RangeBindings {
        u: uniform RangeUniforms,
        tile_keys: read "array<u32>",
        ranges: read_write "array<u32>",
    }
    entry_points { ranges_main: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE }
}

/// Arguments: sorted tile keys in, `2 × num_tiles` u32 ranges out.
pub struct RangeArgs<'a> {
    pub tile_keys: &'a wgpu::Buffer,
    pub ranges: &'a wgpu::Buffer,
    pub n: u32,
    pub num_tiles: u32,
}

impl TileRanges {
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
        self.record(
            ctx,
            rec,
            "ranges_main",
            &RangeBindings {
                u: &u,
                tile_keys: args.tile_keys,
                ranges: args.ranges,
            },
            groups_1d(args.n, WORKGROUP_SIZE),
        )
    }
}
