//! CPU reference of every GPU stage, in plain Rust + rayon, with the same
//! names as the kernels (gsplat's `_torch_impl.py` habit): `project`,
//! `rasterize`, `rasterize_backward`, `project_backward`. Each is generic over
//! f32/f64 (`*_t` functions) so finite-difference tests run in f64 while
//! training and GPU comparisons use f32.
// Small fixed-size matrix algebra reads best with index loops; `!(x > 0)`
// is deliberate: it is true for NaN, which must be culled.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod backend;
pub mod mcmc;
pub mod project;
pub mod project_backward;
pub mod rasterize;
pub mod rasterize_backward;
pub mod real;
pub mod sh;

pub use backend::CpuBackend;
pub use project::project;
pub use project_backward::project_backward;
pub use rasterize::rasterize;
pub use rasterize_backward::rasterize_backward;

use crate::error::{Result, check_camera, check_splats};
use crate::types::{RenderCamera, RenderOptions, RenderOutput, Splats};

/// Forward render (project + rasterize) with input checks.
pub fn render(splats: &Splats, cam: &RenderCamera, opts: &RenderOptions) -> Result<RenderOutput> {
    check_splats(splats)?;
    check_camera(cam)?;
    let projected = project(splats, cam, opts);
    let r = rasterize(&projected, cam, opts);
    Ok(RenderOutput {
        width: cam.width,
        height: cam.height,
        image: r.image,
        final_transmittance: r.final_transmittance,
        projected,
    })
}
