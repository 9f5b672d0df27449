//! Host for `shaders/splat/rasterize.wgsl`: the forward tile rasterizer
//! (Kerbl et al. 2023 §6; reference `reference::rasterize::rasterize_t`).
//! One workgroup per 16×16 tile, several pixels per invocation.

use super::kernel::{Recorder, kernel};
use super::project::CameraUniforms;
use super::{GpuContext, GpuError};

/// Invocations per workgroup (`THREADS` in the shader): one per column of
/// the 16×16 tile, each owning the column's 16 pixels (`PPT` in the shader).
pub const THREADS: u32 = 16;

kernel! {
    /// The compiled kernel.
    pub struct Rasterize;
    decl DECL = "rasterize" after ["block_lists"];
    bindings RasterBindings {
        cam: uniform CameraUniforms,
        projected: read "array<ProjectedSplat>",
        tile_values: read "array<u32>",
        ranges: read "array<u32>",
        image: read_write "array<f32>",
        final_t: read_write "array<f32>",
        last_contrib: read_write "array<u32>",
    }
    entry_points { rasterize_main: [THREADS, 1] }
    constants { THREADS }
}

impl Rasterize {
    /// Record the raster of the `grid` tiles into `b.image`, `b.final_t`
    /// (`w·h` f32) and `b.last_contrib` (`w·h` u32).
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        b: &RasterBindings,
        grid: (u32, u32),
    ) -> Result<(), GpuError> {
        self.record(ctx, rec, "rasterize_main", b, [grid.0, grid.1, 1])
    }
}
