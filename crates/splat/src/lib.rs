//! splat: Gaussian splatting with wgpu kernels and a CPU reference.

pub mod types;

pub use types::{ProjectedSplat, RenderCamera, RenderOptions, RenderOutput, SplatGrads, Splats};
