//! wgpu compute kernels for Gaussian splatting: projection, tile binning
//! (prefix sum, radix sort, tile ranges), forward and backward rasterization,
//! backward projection and Adam. Each kernel is one WGSL file in
//! `shaders/splat/` and one host module here with the same name; the host
//! declares the bindings (bound by name, checked against naga's reflection in
//! the tests), the uniform structs (`#[repr(C)]` + Pod) and the workgroup size.
//!
//! The math follows the CPU reference in `crate::reference` exactly; tests
//! compare the two stage by stage.

pub mod adam;
pub mod backend;
pub mod backward;
pub mod context;
pub mod densify_stats;
pub mod emit_keys;
pub mod forward;
pub mod kernel;
pub mod loss;
pub mod mcmc;
pub mod prefix_sum;
pub mod profile;
pub mod project;
pub mod project_backward;
pub mod radix_sort;
pub mod rasterize;
pub mod rasterize_backward;
pub mod ssim;
pub mod tile_ranges;

#[cfg(test)]
mod tests;

pub use backend::GpuBackend;
pub use context::{GpuContext, GpuOptions};
pub use profile::profile_step;

/// Errors of the GPU backend.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No wgpu adapter (callers fall back to the CPU backend).
    #[error("no GPU adapter available (wgpu found no Vulkan/GL/Metal/DX12 device)")]
    NoAdapter,
    /// Device creation or polling failed.
    #[error("GPU device error: {0}")]
    Device(String),
    /// Mapping a buffer for readback failed.
    #[error("GPU readback failed: {0}")]
    Readback(String),
    /// A kernel was bound with a missing, unknown or duplicate buffer name.
    #[error("GPU binding error: {0}")]
    Binding(String),
    /// Input the kernels cannot handle (sizes beyond device limits, bad options).
    #[error("invalid GPU input: {0}")]
    InvalidInput(String),
}

/// Every kernel's declaration (for the naga reflection test and tooling).
pub static ALL_KERNELS: &[&kernel::KernelDecl] = &[
    &prefix_sum::DECL,
    &radix_sort::DECL,
    &emit_keys::DECL,
    &tile_ranges::DECL,
    &project::DECL,
    &rasterize::DECL,
    &rasterize_backward::DECL,
    &project_backward::DECL,
    &adam::DECL,
    &loss::DECL,
    &ssim::DECL,
    &densify_stats::DECL,
    &mcmc::NOISE_DECL,
    &mcmc::REG_DECL,
];
