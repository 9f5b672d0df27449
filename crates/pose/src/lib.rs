//! pose: the pose stage of romosplat. Runs COLMAP (feature extraction with
//! the RoMo motion masks, sequential or exhaustive matching, incremental
//! mapping) to recover camera poses from a casual video, and measures pose
//! quality against ground truth (Umeyama Sim(3) alignment, ATE, RPE as in evo).
//!
//! This is where the RoMo paper's central claim — masks make ordinary SfM
//! robust to moving objects — is delivered and measured.

pub mod colmap_runner;
pub mod error;
pub mod gt_masks;
pub mod metrics;
pub mod model_info;
pub mod pairs;
pub mod process;
pub mod progress;
pub mod resume;
pub mod trajectory;
pub mod undistort;

pub use colmap_runner::{
    ColmapOptions, ColmapPaths, ColmapReport, MapperOptions, Matcher, Progress, run_colmap,
    run_colmap_cancellable,
};
pub use error::{PoseError, Result};
pub use metrics::{
    Alignment, ErrorStats, NamedPose, PoseMetrics, PoseMetricsOptions, Sim3, evaluate, umeyama,
};
