//! Host for `shaders/splat/project_backward.wgsl`: from dL/d(projected splat)
//! to dL/d(every splat parameter), one invocation per splat (INRIA
//! `backward.cu` computeCov2DCUDA / preprocessCUDA; reference
//! `reference::project_backward`). Also writes ‖dL/d mean2d‖ per splat for
//! densification statistics.

use super::kernel::{Recorder, groups_1d, kernel};
use super::project::{CameraUniforms, ParamBuffers};
use super::rasterize_backward::GRAD_STRIDE;
use super::{GpuContext, GpuError};

/// Invocations per workgroup.
pub const WORKGROUP_SIZE: u32 = 256;
/// f32 per splat in the planar geometry-gradient segment (means 3,
/// log-scales 3, rotations 4, opacity 1, ‖dL/d mean2d‖ 1) that follows the
/// projected gradients in the kernel's `io` buffer.
pub const GEOM_FLOATS: u64 = 12;
/// f32 per splat of a projected-gradient buffer as this kernel binds it:
/// dL/d projected splat ([`GRAD_STRIDE`], `[0, 12n)`) then the planar
/// geometry gradients (`[12n, 24n)`). One buffer for both keeps the kernel
/// at 7 storage bindings plus the camera, which then also goes in storage
/// like every other kernel's uniforms (`KernelDecl::uniform_in_storage`).
pub const V_PROJ_FLOATS: u64 = GRAD_STRIDE + GEOM_FLOATS;

kernel! {
    /// The compiled kernel.
    pub struct ProjectBackward;
    decl DECL = "project_backward";
    bindings ProjectBackwardBindings {
        cam: uniform CameraUniforms,
        means: read "array<f32>",
        log_scales: read "array<f32>",
        rotations: read "array<f32>",
        opacity_logits: read "array<f32>",
        sh: read "array<f32>",
        io: read_write "array<f32>",
        g_sh: read_write "array<f32>",
    }
    entry_points { project_backward_main: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE }
}

/// Parameter gradients resident on the GPU (same layout as [`ParamBuffers`]).
pub struct GradBuffers {
    pub means: wgpu::Buffer,
    pub log_scales: wgpu::Buffer,
    pub rotations: wgpu::Buffer,
    pub opacity_logits: wgpu::Buffer,
    pub sh: wgpu::Buffer,
    /// ‖dL/d mean2d‖ per splat (pixels).
    pub mean2d_abs: wgpu::Buffer,
}

impl GradBuffers {
    /// Buffers shaped like `p`.
    pub fn like(ctx: &GpuContext, p: &ParamBuffers) -> Self {
        let n = p.n as u64;
        let k3 = crate::types::sh_coeffs(p.sh_degree) as u64 * 3;
        GradBuffers {
            means: ctx.storage("g_means", n * 12),
            log_scales: ctx.storage("g_log_scales", n * 12),
            rotations: ctx.storage("g_rotations", n * 16),
            opacity_logits: ctx.storage("g_opacity_logits", n * 4),
            sh: ctx.storage("g_sh", n * k3 * 4),
            mean2d_abs: ctx.storage("mean2d_abs", n * 4),
        }
    }
}

/// Arguments of one backward projection.
pub struct ProjectBackwardArgs<'a> {
    pub cam: &'a wgpu::Buffer,
    pub params: &'a ParamBuffers,
    /// At least [`V_PROJ_FLOATS`]`·n` f32: dL/d projected splats
    /// ([`crate::types::ProjectedGrads`] layout) in the first `12·n`, the
    /// rest scratch.
    pub v_proj: &'a wgpu::Buffer,
    pub grads: &'a GradBuffers,
}

impl ProjectBackward {
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &ProjectBackwardArgs,
    ) -> Result<(), GpuError> {
        let (p, g) = (a.params, a.grads);
        let need = p.n as u64 * V_PROJ_FLOATS * 4;
        if a.v_proj.size() < need {
            return Err(GpuError::InvalidInput(format!(
                "projected-gradient buffer of {} bytes, {need} needed",
                a.v_proj.size()
            )));
        }
        self.record(
            ctx,
            rec,
            "project_backward_main",
            &ProjectBackwardBindings {
                cam: a.cam,
                means: &p.means,
                log_scales: &p.log_scales,
                rotations: &p.rotations,
                opacity_logits: &p.opacity_logits,
                sh: &p.sh,
                io: a.v_proj,
                g_sh: &g.sh,
            },
            groups_1d(p.n, WORKGROUP_SIZE),
        )?;
        // Planar segments after the projected gradients → the per-group
        // gradient buffers.
        let n = p.n as u64 * 4;
        let geom = GRAD_STRIDE * n;
        for (seg, dst, floats) in [
            (0, &g.means, 3),
            (3, &g.log_scales, 3),
            (6, &g.rotations, 4),
            (10, &g.opacity_logits, 1),
            (11, &g.mean2d_abs, 1),
        ] {
            if n > 0 {
                rec.encoder
                    .copy_buffer_to_buffer(a.v_proj, geom + seg * n, dst, 0, floats * n);
            }
        }
        Ok(())
    }
}
