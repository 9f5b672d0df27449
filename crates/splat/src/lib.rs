//! splat: Gaussian splatting with wgpu kernels and a CPU reference.

pub mod backend;
pub mod error;
pub mod export;
pub mod gpu;
pub mod init;
pub mod io;
#[cfg(feature = "onnx")]
pub mod lpips;
pub mod lpips_alex;
pub mod metrics;
pub mod reference;
pub mod strategy;
pub mod train;
pub mod types;

pub use error::{Result, SplatError};
pub use types::{
    AdamState, DensifyStats, ProjectedGrads, ProjectedSplat, RasterOutput, RenderCamera,
    RenderOptions, RenderOutput, SplatGrads, Splats,
};
