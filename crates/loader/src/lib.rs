//! loader: romosplat's on-disk world. Scene folders, images, masks, COLMAP
//! models, transforms.json, split.json, the DAVIS layout, Middlebury `.flo`,
//! float EXR, splat PLY, video → frames, and the built-in synthetic scenes.
//!
//! Everything here returns [`LoaderError`], whose message names the file.

pub mod camera;
pub mod colmap;
pub mod composite;
pub mod davis;
pub mod error;
pub mod exr;
pub mod flo;
pub mod inspect;
pub mod io;
pub mod masks;
pub mod ply;
pub mod scene;
pub mod split;
pub mod synth;
pub mod transforms;
pub mod video;

pub use camera::{Camera, CameraModel, Intrinsics, Pose};
pub use error::{LoaderError, Result};
pub use scene::{Frame, Scene, SceneOptions};
