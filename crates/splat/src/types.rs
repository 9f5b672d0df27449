//! Data types shared by the CPU reference (`reference/`) and the wgpu kernels
//! (`gpu/`). Both sides take and return exactly these, so a test can feed the
//! same upstream values to both and compare one stage at a time.
//!
//! Conventions: cameras are COLMAP world-to-camera with OpenCV axes; pixel
//! centres at integer + 0.5; images row-major RGB f32 in [0, 1].

use bytemuck::{Pod, Zeroable};

/// Tile edge in pixels for binning and rasterization (16×16 tiles).
pub const TILE_SIZE: u32 = 16;
/// Number of SH coefficients per colour channel for a degree.
pub const fn sh_coeffs(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}
/// Largest supported SH degree.
pub const MAX_SH_DEGREE: u32 = 3;

/// A set of 3D Gaussians, structure of arrays, in the INRIA parameterisation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Splats {
    /// World-space centres.
    pub means: Vec<[f32; 3]>,
    /// Per-axis log standard deviations.
    pub log_scales: Vec<[f32; 3]>,
    /// Rotation quaternions (w, x, y, z), not necessarily normalised.
    pub rotations: Vec<[f32; 4]>,
    /// Opacity logits (opacity = sigmoid(logit)).
    pub opacity_logits: Vec<f32>,
    /// SH coefficients, `[splat][coeff][rgb]`, `sh_coeffs(sh_degree)` per splat.
    /// Coefficient 0 is the DC term (colour = 0.5 + SH_C0 · dc).
    pub sh: Vec<f32>,
    /// SH degree stored (0..=3).
    pub sh_degree: u32,
}

impl Splats {
    /// No splats yet, with room for `n` and the SH coefficients of `n`
    /// splats of `sh_degree` already zeroed (the per-splat vectors are
    /// pushed to; `sh` is written in place).
    pub fn with_capacity(n: usize, sh_degree: u32) -> Self {
        Self {
            means: Vec::with_capacity(n),
            log_scales: Vec::with_capacity(n),
            rotations: Vec::with_capacity(n),
            opacity_logits: Vec::with_capacity(n),
            sh: vec![0.0; n * sh_coeffs(sh_degree) * 3],
            sh_degree,
        }
    }
    /// Number of splats.
    pub fn len(&self) -> usize {
        self.means.len()
    }
    /// True when there are no splats.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }
    /// SH coefficients per channel.
    pub fn coeffs_per_channel(&self) -> usize {
        sh_coeffs(self.sh_degree)
    }
}

/// A pinhole camera to render from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderCamera {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// World-to-camera rotation, row-major.
    pub rotation: [[f32; 3]; 3],
    /// World-to-camera translation.
    pub translation: [f32; 3],
    /// Near clip distance (camera z); splats closer are culled.
    pub near: f32,
    /// Far clip distance.
    pub far: f32,
}

impl RenderCamera {
    /// A `width × height` pinhole camera with focal length `f` px and the
    /// principal point at the image centre, at the origin looking down +z
    /// (identity pose), clipping at 0.01 and 100.
    pub fn at_origin(width: u32, height: u32, f: f32) -> Self {
        RenderCamera {
            width,
            height,
            fx: f,
            fy: f,
            cx: width as f32 / 2.0,
            cy: height as f32 / 2.0,
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [0.0; 3],
            near: 0.01,
            far: 100.0,
        }
    }

    /// Camera centre in world coordinates.
    pub fn center(&self) -> [f32; 3] {
        let r = &self.rotation;
        let t = &self.translation;
        let mut c = [0.0f32; 3];
        for (j, cj) in c.iter_mut().enumerate() {
            *cj = -(r[0][j] * t[0] + r[1][j] * t[1] + r[2][j] * t[2]);
        }
        c
    }

    /// Build from loader intrinsics and pose.
    pub fn from_loader(k: &loader::Intrinsics, pose: &loader::Pose) -> Self {
        let r = pose.rotation();
        let mut rotation = [[0.0f32; 3]; 3];
        for (i, row) in rotation.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = r[(i, j)] as f32;
            }
        }
        RenderCamera {
            width: k.width,
            height: k.height,
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
            rotation,
            translation: [
                pose.tvec[0] as f32,
                pose.tvec[1] as f32,
                pose.tvec[2] as f32,
            ],
            near: 0.01,
            far: 1e10,
        }
    }

    /// Number of tiles along x and y.
    pub fn tile_grid(&self) -> (u32, u32) {
        (
            self.width.div_ceil(TILE_SIZE),
            self.height.div_ceil(TILE_SIZE),
        )
    }
}

/// Options for a render (forward) pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Background colour composited behind the splats.
    pub background: [f32; 3],
    /// SH degree used for colour (≤ the splats' stored degree).
    pub sh_degree: u32,
    /// Screen-space low-pass dilation added to the 2D covariance diagonal (px²).
    pub low_pass: f32,
    /// Antialiased mode (Mip-Splatting / gsplat "antialiased"): opacity is
    /// multiplied by sqrt(det(Σ) / det(Σ + low_pass·I)).
    pub antialiased: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            background: [0.0; 3],
            sh_degree: 0,
            low_pass: 0.3,
            antialiased: false,
        }
    }
}

/// A splat after projection to the image plane. Shared layout with WGSL
/// (`shaders/splat/common.wgsl`), hence `repr(C)` + Pod and 16-byte rows.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, Default)]
pub struct ProjectedSplat {
    /// Pixel-space centre.
    pub mean2d: [f32; 2],
    /// Camera-space depth (z).
    pub depth: f32,
    /// Radius in pixels (3σ of the dilated 2D covariance); 0 = culled.
    pub radius: f32,
    /// Inverse 2D covariance (a, b, c) for [[a, b], [b, c]].
    pub conic: [f32; 3],
    /// Opacity after sigmoid (and antialiasing compensation).
    pub opacity: f32,
    /// View-dependent RGB colour (clamped at 0 from below, as INRIA).
    pub color: [f32; 3],
    /// Opacity-aware tile-binning half extents in pixels, x in the low 16
    /// bits and y in the high 16 (`reference::project::pack_extent`; read by
    /// `common.wgsl`); 0 = no tiles. Keeps the struct at 48 bytes.
    pub tile_extent: u32,
}

/// Output of a forward render.
#[derive(Debug, Clone, Default)]
pub struct RenderOutput {
    pub width: u32,
    pub height: u32,
    /// RGB, row-major, `width*height*3`.
    pub image: Vec<f32>,
    /// Final transmittance per pixel (`width*height`).
    pub final_transmittance: Vec<f32>,
    /// Per splat: the projected splat (radius 0 when culled).
    pub projected: Vec<ProjectedSplat>,
}

/// Gradients w.r.t. every splat parameter, same layout as [`Splats`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SplatGrads {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub rotations: Vec<[f32; 4]>,
    pub opacity_logits: Vec<f32>,
    pub sh: Vec<f32>,
    /// |dL/d mean2d| per splat (view-space positional gradient used for
    /// densification, in pixels, as INRIA's `xyz_gradient_accum` input).
    pub mean2d_abs: Vec<f32>,
}

/// Output of the forward rasterizer, with everything the backward pass needs.
///
/// Per-tile lists: tile `t` (row-major over [`RenderCamera::tile_grid`]) owns
/// `tile_splats[tile_ranges[t][0] as usize..tile_ranges[t][1] as usize]`, the
/// indices of the splats overlapping it sorted by (depth, splat index).
#[derive(Debug, Clone, Default)]
pub struct RasterOutput {
    pub width: u32,
    pub height: u32,
    /// RGB, row-major, `width*height*3`.
    pub image: Vec<f32>,
    /// Final transmittance per pixel (`width*height`), i.e. T after the last
    /// contributing splat (the background is weighted by it).
    pub final_transmittance: Vec<f32>,
    /// Per pixel: number of entries of its tile list processed up to and
    /// including the last splat that contributed (INRIA's `n_contrib`);
    /// 0 when nothing contributed. The backward pass starts there.
    pub last_contrib: Vec<u32>,
    /// Per tile `[start, end)` into `tile_splats`.
    pub tile_ranges: Vec<[u32; 2]>,
    /// Concatenated per-tile depth-sorted splat indices.
    pub tile_splats: Vec<u32>,
}

/// Gradients w.r.t. the projected (2D) splats, one per splat, the output of
/// rasterize-backward and the input of project-backward.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, Default)]
pub struct ProjectedGrads {
    /// dL/d mean2d (pixels).
    pub mean2d: [f32; 2],
    /// Padding (keeps 16-byte rows for WGSL).
    pub _pad0: [f32; 2],
    /// dL/d conic (a, b, c) where the conic matrix is [[a, b], [b, c]]
    /// (b is one scalar used in both off-diagonal entries).
    pub conic: [f32; 3],
    /// dL/d opacity (the post-sigmoid, post-compensation opacity).
    pub opacity: f32,
    /// dL/d colour (after the clamp at 0).
    pub color: [f32; 3],
    pub _pad1: f32,
}

/// Adam optimiser state: first and second moments in the same layout as the
/// parameters (a [`Splats`] used as a container of per-parameter values), plus
/// the step count used for bias correction (shared by all groups, as in
/// torch's Adam after INRIA's densification which keeps the step).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AdamState {
    pub step: u64,
    /// First moments.
    pub m: Splats,
    /// Second moments.
    pub v: Splats,
}

impl AdamState {
    /// Zero moments shaped like `params`.
    pub fn zeros_like(params: &Splats) -> Self {
        let z = Splats {
            means: vec![[0.0; 3]; params.len()],
            log_scales: vec![[0.0; 3]; params.len()],
            rotations: vec![[0.0; 4]; params.len()],
            opacity_logits: vec![0.0; params.len()],
            sh: vec![0.0; params.sh.len()],
            sh_degree: params.sh_degree,
        };
        AdamState {
            step: 0,
            m: z.clone(),
            v: z,
        }
    }
}

/// Statistics accumulated over training steps for densification decisions
/// (INRIA `xyz_gradient_accum`, `denom`, `max_radii2D`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DensifyStats {
    /// Σ over steps where the splat was visible of ‖dL/d mean2d‖ in NDC
    /// units (pixel gradient × (width/2, height/2)), so INRIA's 2e-4
    /// threshold applies unchanged.
    pub grad_accum: Vec<f32>,
    /// Number of steps where the splat was visible (radius > 0).
    pub count: Vec<u32>,
    /// Largest screen radius seen (pixels).
    pub max_radius: Vec<f32>,
}

impl DensifyStats {
    /// Zeroed statistics for `n` splats.
    pub fn zeros(n: usize) -> Self {
        DensifyStats {
            grad_accum: vec![0.0; n],
            count: vec![0; n],
            max_radius: vec![0.0; n],
        }
    }
}
