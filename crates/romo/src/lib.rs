//! romo: RoMo motion segmentation (Goli, Sabour et al., "RoMo: Robust Motion
//! Segmentation Improves Structure from Motion", 2025), with classical,
//! dependency-free backends for every stage and optional neural ones through
//! ONNX Runtime (feature `onnx`).
//!
//! Stages (`docs/design.md`, "The pipeline"): [`flow`] → cycle check →
//! robust epipolar [`geometry`] → Sampson-based U/L labels → per-pixel
//! features → a tiny MLP → refinement to full resolution → masks.

pub mod borders;
#[cfg(feature = "cli")]
pub mod cli;
pub mod error;
pub mod exposure;
pub mod features;
pub mod flow;
pub mod geometry;
pub mod labels;
pub mod maxflow;
pub mod metrics;
pub mod mlp;
pub mod objects;
#[cfg(feature = "onnx")]
pub mod onnx;
pub mod order;
pub mod overlay;
pub mod pipeline;
pub mod plane;
pub mod refine;
pub mod regions;
pub mod scene;

pub use error::{Result, RomoError};
pub use pipeline::{
    FeatureBackend, FlowBackend, FrameReport, FrameSource, RomoOptions, RomoReport, Segmentation,
    segment_frames,
};
pub use scene::{evaluate_scene_masks, held_out_stems, segment_paths, segment_scene};
