//! Host for `shaders/splat/project.wgsl`: forward projection of every splat
//! to a [`ProjectedSplat`] (EWA splatting, Zwicker et al. 2001; Kerbl et al.
//! 2023 §4), following `reference::project::project_one` exactly. Also owns
//! [`CameraUniforms`], the camera/options block every later kernel reads.

use super::kernel::{Recorder, groups_1d, kernel};
use super::{GpuContext, GpuError};
use crate::reference::project::JACOBIAN_CLAMP;
use crate::types::{RenderCamera, RenderOptions};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup.
pub const WORKGROUP_SIZE: u32 = 256;

/// Camera + render options as the kernels see them (160 bytes; mirrors
/// `CameraUniforms` in `common.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct CameraUniforms {
    pub rot: [[f32; 4]; 3],
    pub trans: [f32; 4],
    pub center: [f32; 4],
    /// fx, fy, cx, cy.
    pub focal: [f32; 4],
    /// near, far, 1.3·tan(fovx/2), 1.3·tan(fovy/2).
    pub clip: [f32; 4],
    /// Background rgb, low-pass dilation (px²) in w.
    pub background: [f32; 4],
    pub width: u32,
    pub height: u32,
    pub grid_x: u32,
    pub grid_y: u32,
    pub n: u32,
    pub sh_degree: u32,
    pub sh_stored: u32,
    pub antialiased: u32,
}

impl CameraUniforms {
    /// Uniforms for `n` splats storing `stored_degree` SH.
    pub fn new(cam: &RenderCamera, opts: &RenderOptions, n: u32, stored_degree: u32) -> Self {
        let r = cam.rotation;
        let c = cam.center();
        let (gx, gy) = cam.tile_grid();
        // Same f32 expression as `reference::project::CamT::new`.
        let clamp = JACOBIAN_CLAMP as f32;
        let lim_x = clamp * cam.width as f32 / (2.0 * cam.fx);
        let lim_y = clamp * cam.height as f32 / (2.0 * cam.fy);
        let bg = opts.background;
        CameraUniforms {
            rot: [
                [r[0][0], r[0][1], r[0][2], 0.0],
                [r[1][0], r[1][1], r[1][2], 0.0],
                [r[2][0], r[2][1], r[2][2], 0.0],
            ],
            trans: [
                cam.translation[0],
                cam.translation[1],
                cam.translation[2],
                0.0,
            ],
            center: [c[0], c[1], c[2], 0.0],
            focal: [cam.fx, cam.fy, cam.cx, cam.cy],
            clip: [cam.near, cam.far, lim_x, lim_y],
            background: [bg[0], bg[1], bg[2], opts.low_pass],
            width: cam.width,
            height: cam.height,
            grid_x: gx,
            grid_y: gy,
            n,
            sh_degree: opts.sh_degree.min(stored_degree),
            sh_stored: crate::types::sh_coeffs(stored_degree) as u32,
            antialiased: opts.antialiased as u32,
        }
    }
}

kernel! {
    /// The compiled kernel.
    pub struct Project;
    decl DECL = "project";
    bindings ProjectBindings {
        cam: uniform CameraUniforms,
        means: read "array<f32>",
        log_scales: read "array<f32>",
        rotations: read "array<f32>",
        opacity_logits: read "array<f32>",
        sh: read "array<f32>",
        projected: read_write "array<ProjectedSplat>",
    }
    entry_points { project_main: [WORKGROUP_SIZE] }
    constants { WORKGROUP_SIZE }
}

/// Splat parameters resident on the GPU (flat f32 arrays, [`crate::Splats`] layout).
pub struct ParamBuffers {
    pub means: wgpu::Buffer,
    pub log_scales: wgpu::Buffer,
    pub rotations: wgpu::Buffer,
    pub opacity_logits: wgpu::Buffer,
    pub sh: wgpu::Buffer,
    /// Number of splats.
    pub n: u32,
    /// Stored SH degree.
    pub sh_degree: u32,
}

/// Arguments of one projection.
pub struct ProjectArgs<'a> {
    pub cam: &'a wgpu::Buffer,
    pub params: &'a ParamBuffers,
    /// `n` [`crate::ProjectedSplat`] out.
    pub projected: &'a wgpu::Buffer,
}

impl Project {
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        rec: &mut Recorder,
        a: &ProjectArgs,
    ) -> Result<(), GpuError> {
        let p = a.params;
        self.record(
            ctx,
            rec,
            "project_main",
            &ProjectBindings {
                cam: a.cam,
                means: &p.means,
                log_scales: &p.log_scales,
                rotations: &p.rotations,
                opacity_logits: &p.opacity_logits,
                sh: &p.sh,
                projected: a.projected,
            },
            groups_1d(p.n, WORKGROUP_SIZE),
        )
    }
}
