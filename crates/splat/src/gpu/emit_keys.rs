//! Host for `shaders/splat/emit_keys.wgsl`: tile binning of projected splats
//! (depth keys for the depth sort, tile counts in depth order, one
//! `(tile id, splat index)` pair per touched 16×16 tile). The tile rectangle
//! comes from `tile_rect` and `tile_hit` in `common.wgsl`, shared by counting
//! and emission.
//! Reference: Kerbl et al., "3D Gaussian Splatting" (2023), §6 (tile binning).

use super::kernel::{Recorder, groups_1d, kernel};
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup.
pub const WORKGROUP_SIZE: u32 = 256;

/// Uniforms (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct BinUniforms {
    /// Number of splats.
    pub n: u32,
    pub grid_x: u32,
    pub grid_y: u32,
    pub pad: u32,
}

kernel! {
    /// The compiled binning kernel.
    pub struct EmitKeys;
    decl DECL = "emit_keys";
    bindings EmitBindings {
        u: uniform BinUniforms,
        projected: read "array<ProjectedSplat>",
        depth_keys_out: read_write "array<u32>",
        order: read_write "array<u32>",
        counts: read_write "array<u32>",
        offsets: read "array<u32>",
        tile_keys: read_write "array<u32>",
        tile_values: read_write "array<u32>",
    }
    entry_points {
        depth_keys: [WORKGROUP_SIZE],
        gather_counts: [WORKGROUP_SIZE],
        emit: [WORKGROUP_SIZE],
    }
    constants { WORKGROUP_SIZE }
}

impl EmitKeys {
    /// Record `entry` ("depth_keys", "gather_counts" or "emit") over `n` splats.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        entry: &'static str,
        b: &EmitBindings,
        n: u32,
    ) -> Result<(), GpuError> {
        self.record(ctx, rec, entry, b, groups_1d(n, WORKGROUP_SIZE))
    }
}
