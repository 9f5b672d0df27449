//! The GPU backward pass: rasterize-backward (per-splat dL/d projected splat,
//! atomics) then project-backward (dL/d parameters). Stage by stage the same
//! as `reference::rasterize_backward` and `reference::project_backward`.

use super::forward::ForwardState;
use super::kernel::Recorder;
use super::project::ParamBuffers;
use super::project_backward::{GradBuffers, ProjectBackward, ProjectBackwardArgs, V_PROJ_FLOATS};
use super::rasterize_backward::{RasterBackwardBindings, RasterizeBackward};
use super::{GpuContext, GpuError};
use crate::types::{ProjectedGrads, SplatGrads};

/// The backward kernels, compiled once.
pub struct BackwardKernels {
    pub rasterize_backward: RasterizeBackward,
    pub project_backward: ProjectBackward,
}

impl BackwardKernels {
    pub fn new(ctx: &GpuContext) -> Self {
        BackwardKernels {
            rasterize_backward: RasterizeBackward::new(ctx),
            project_backward: ProjectBackward::new(ctx),
        }
    }
}

/// A buffer for per-splat projected gradients (`12·n` f32) and the
/// backward projection's scratch ([`V_PROJ_FLOATS`]`·n` f32 in all).
pub fn projected_grads_buffer(ctx: &GpuContext, n: u32) -> wgpu::Buffer {
    ctx.storage("v_proj", n as u64 * V_PROJ_FLOATS * 4)
}

/// Buffers of one backward pass.
pub struct BackwardArgs<'a> {
    pub params: &'a ParamBuffers,
    pub state: &'a ForwardState,
    /// dL/d image (`3·w·h` f32).
    pub v_image: &'a wgpu::Buffer,
    /// Scratch / output: dL/d projected splats in the first `12·n` f32
    /// ([`projected_grads_buffer`]).
    pub v_proj: &'a wgpu::Buffer,
    pub grads: &'a GradBuffers,
}

/// Record the backward pass.
pub fn record_backward(
    ctx: &GpuContext,
    k: &BackwardKernels,
    rec: &mut Recorder,
    a: &BackwardArgs,
) -> Result<(), GpuError> {
    let s = a.state;
    k.rasterize_backward.dispatch(
        ctx,
        rec,
        &RasterBackwardBindings {
            cam: &s.cam,
            projected: &s.projected,
            tile_values: &s.tile_values,
            ranges: &s.ranges,
            final_t: &s.final_t,
            last_contrib: &s.last_contrib,
            v_image: a.v_image,
            grads: a.v_proj,
        },
        s.grid,
        s.n,
    )?;
    k.project_backward.dispatch(
        ctx,
        rec,
        &ProjectBackwardArgs {
            cam: &s.cam,
            params: a.params,
            v_proj: a.v_proj,
            grads: a.grads,
        },
    )
}

/// Read projected gradients back.
pub fn read_projected_grads(
    ctx: &GpuContext,
    v_proj: &wgpu::Buffer,
    n: u32,
) -> Result<Vec<ProjectedGrads>, GpuError> {
    ctx.read(v_proj, n as usize)
}

/// Read parameter gradients back in the [`SplatGrads`] layout.
pub fn read_grads(
    ctx: &GpuContext,
    g: &GradBuffers,
    params: &ParamBuffers,
) -> Result<SplatGrads, GpuError> {
    let n = params.n as usize;
    let k3 = crate::types::sh_coeffs(params.sh_degree) * 3;
    Ok(SplatGrads {
        means: ctx.read(&g.means, n)?,
        log_scales: ctx.read(&g.log_scales, n)?,
        rotations: ctx.read(&g.rotations, n)?,
        opacity_logits: ctx.read(&g.opacity_logits, n)?,
        sh: ctx.read(&g.sh, n * k3)?,
        mean2d_abs: ctx.read(&g.mean2d_abs, n)?,
    })
}
