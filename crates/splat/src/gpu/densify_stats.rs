//! Host for `shaders/splat/densify_stats.wgsl`: per-step densification
//! statistics kept on the GPU (INRIA `add_densification_stats`; the same
//! update as `reference::backend::CpuBackend::step`) and the visible count.

use super::kernel::{Recorder, groups_1d, kernel};
use super::project::CameraUniforms;
use super::{GpuContext, GpuError};

/// Invocations per workgroup.
pub const WORKGROUP_SIZE: u32 = 256;

kernel! {
    /// The compiled kernel.
    pub struct DensifyStatsKernel;
    decl DECL = "densify_stats";
    bindings StatsBindings {
        cam: uniform CameraUniforms,
        projected: read "array<ProjectedSplat>",
        v_proj: read "array<f32>",
        grad_accum: read_write "array<f32>",
        vis_count: read_write "array<u32>",
        max_radius: read_write "array<f32>",
        visible: read_write "atomic<u32>",
    }
    entry_points { densify_stats_main: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE }
}

/// Statistics buffers resident on the GPU.
pub struct StatsBuffers {
    pub grad_accum: wgpu::Buffer,
    pub count: wgpu::Buffer,
    pub max_radius: wgpu::Buffer,
    /// One u32: visible splats in the last step (cleared by `dispatch`).
    pub visible: wgpu::Buffer,
}

impl StatsBuffers {
    /// Zeroed statistics for `n` splats.
    pub fn zeros(ctx: &GpuContext, n: u32) -> Self {
        let z = vec![0u32; n as usize];
        StatsBuffers {
            grad_accum: ctx.upload("grad_accum", &z),
            count: ctx.upload("vis_count", &z),
            max_radius: ctx.upload("max_radius", &z),
            visible: ctx.upload("visible", &[0u32; 4]),
        }
    }
}

/// Buffers of one update.
pub struct StatsArgs<'a> {
    pub cam: &'a wgpu::Buffer,
    pub projected: &'a wgpu::Buffer,
    pub v_proj: &'a wgpu::Buffer,
    pub stats: &'a StatsBuffers,
    pub n: u32,
}

impl DensifyStatsKernel {
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &StatsArgs,
    ) -> Result<(), GpuError> {
        rec.encoder.clear_buffer(&a.stats.visible, 0, None);
        if a.n == 0 {
            return Ok(());
        }
        self.record(
            ctx,
            rec,
            "densify_stats_main",
            &StatsBindings {
                cam: a.cam,
                projected: a.projected,
                v_proj: a.v_proj,
                grad_accum: &a.stats.grad_accum,
                vis_count: &a.stats.count,
                max_radius: &a.stats.max_radius,
                visible: &a.stats.visible,
            },
            groups_1d(a.n, WORKGROUP_SIZE),
        )
    }
}
