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

impl Rasterize {
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &RasterArgs,
    ) -> Result<(), GpuError> {
        let bind = self.bind(
            ctx,
            &RasterBindings {
                cam: a.cam,
                projected: a.projected,
                tile_values: a.tile_values,
                ranges: a.ranges,
                image: a.image,
                final_t: a.final_t,
                last_contrib: a.last_contrib,
            },
        )?;
        rec.dispatch(
            &self.kernel,
            "rasterize_main",
            &bind,
            [a.grid.0, a.grid.1, 1],
        )
    }
}
