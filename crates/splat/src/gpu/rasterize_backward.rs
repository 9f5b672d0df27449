//! Host for `shaders/splat/rasterize_backward.wgsl`: backward of the tile
//! rasterizer (INRIA `backward.cu` renderCUDA; reference
//! `reference::rasterize_backward`). Per-splat gradients are accumulated with
//! float atomics when the device has `SHADER_FLOAT32_ATOMIC`, else with a
//! compare-and-swap loop (chosen when the pipeline is built, see
//! `kernel::ATOMIC_CAS_WGSL`).

use super::kernel::{Recorder, kernel};
use super::project::CameraUniforms;
use super::rasterize::THREADS;
use super::{GpuContext, GpuError};

/// f32 per splat in the gradient buffer (the `ProjectedGrads` layout).
pub const GRAD_STRIDE: u64 = 12;

kernel! {
    /// The compiled kernel.
    pub struct RasterizeBackward;
    decl DECL = "rasterize_backward" after ["block_lists"];
    bindings RasterBackwardBindings {
        cam: uniform CameraUniforms,
        projected: read "array<ProjectedSplat>",
        tile_values: read "array<u32>",
        ranges: read "array<u32>",
        final_t: read "array<f32>",
        last_contrib: read "array<u32>",
        v_image: read "array<f32>",
        grads: read_write "array<GradAtomic>",
    }
    entry_points { rasterize_backward_main: [THREADS, 1] }
    constants { THREADS }
    grad_atomics
}

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

impl RasterizeBackward {
    /// Record: clear `grads`, then accumulate into it.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &RasterBackwardArgs,
    ) -> Result<(), GpuError> {
        rec.encoder.clear_buffer(a.grads, 0, None);
        let bind = self.bind(
            ctx,
            &RasterBackwardBindings {
                cam: a.cam,
                projected: a.projected,
                tile_values: a.tile_values,
                ranges: a.ranges,
                final_t: a.final_t,
                last_contrib: a.last_contrib,
                v_image: a.v_image,
                grads: a.grads,
            },
        )?;
        rec.dispatch(
            &self.kernel,
            "rasterize_backward_main",
            &bind,
            [a.grid.0, a.grid.1, 1],
        )
    }
}
