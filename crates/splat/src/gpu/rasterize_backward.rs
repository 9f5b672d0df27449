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

impl RasterizeBackward {
    /// Record: clear the first `12·n` f32 of `b.grads`
    /// ([`crate::types::ProjectedGrads`] layout), then accumulate dL/d(projected
    /// splat) of the `n` splats into them from `b.v_image` (dL/d image,
    /// `3·w·h` f32) over the `grid` tiles.
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        b: &RasterBackwardBindings,
        grid: (u32, u32),
        n: u32,
    ) -> Result<(), GpuError> {
        let size = n as u64 * GRAD_STRIDE * 4;
        if b.grads.size() < size {
            return Err(GpuError::InvalidInput(format!(
                "projected-gradient buffer of {} bytes, {size} needed",
                b.grads.size()
            )));
        }
        if size > 0 {
            rec.encoder.clear_buffer(b.grads, 0, Some(size));
        }
        self.record(ctx, rec, "rasterize_backward_main", b, [grid.0, grid.1, 1])
    }
}
