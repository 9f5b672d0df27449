//! The pose stage: COLMAP structure-from-motion with the RoMo motion masks.
//!
//! RoMo (Goli, Sabour et al. 2025) feeds its motion masks to an unmodified
//! COLMAP through `--ImageReader.mask_path`: SIFT keypoints on masked (moving)
//! pixels are never extracted, so matching, geometric verification and the
//! incremental mapper only see the static scene. This module drives the
//! Debian `colmap` binary (3.8, CPU SIFT) step by step:
//!
//! 1. `feature_extractor` — one shared camera for a video, the chosen camera
//!    model, masks from `scene/masks` (`<image name>.png`, 0 = ignore; the
//!    COLMAP convention is ours) unless disabled;
//! 2. `sequential_matcher` (videos; overlap 10, loop detection off) or
//!    `exhaustive_matcher` (photo collections);
//! 3. `mapper`; of several models the one with most registered images wins,
//!    and the frames it leaves out are reported by name;
//! 4. `image_undistorter` to a PINHOLE copy when the camera has distortion
//!    (the splat trainer assumes pinhole);
//!
//! then copies the model to `scene/sparse/0` (or a chosen folder). COLMAP's
//! logs stay in the work folder; a [`ColmapReport`] says how it went.
//!
//! The database is kept in the work folder and reused when it was built from
//! the same images, masks and settings ([`crate::resume`]): COLMAP skips
//! images already extracted and pairs already matched, so an interrupted run
//! resumes. When the mapper builds no model at all (typically "No good
//! initial image pair found"), it is retried once with relaxed initialisation
//! settings ([`relaxed_init_args`]). The matcher's verdicts are read back
//! from the database ([`crate::pairs`]) to name the cause when no model comes
//! out ("no parallax" when every verified pair is a homography) and to warn
//! when a model is built from such pairs.

use crate::error::{PoseError, Result};
use crate::model_info::read_model_info;
use crate::process::{
    StepOutcome, colmap_version, log_tail, require_success, run_step_cancellable,
};
use crate::progress::{Count, Unit, parse_line};
use crate::resume::{self, Decision, FeatureKey, MatchKey, ResumeState};
use loader::CameraModel;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// How image pairs are chosen for matching.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Matcher {
    /// Each frame against the next `overlap` frames (videos). Default.
    #[default]
    Sequential,
    /// Every pair (photo collections; quadratic in the image count).
    Exhaustive,
}

impl Matcher {
    fn step(self) -> &'static str {
        match self {
            Matcher::Sequential => "sequential_matcher",
            Matcher::Exhaustive => "exhaustive_matcher",
        }
    }
}

/// Options of [`run_colmap`]. Defaults follow the RoMo paper's COLMAP setup
/// for casual videos and COLMAP 3.8's own defaults elsewhere.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct ColmapOptions {
    /// The `colmap` executable (a name on PATH or a path). Default `colmap`.
    pub colmap: PathBuf,
    /// Pair selection. Default sequential (videos).
    pub matcher: Matcher,
    /// COLMAP camera model for `--ImageReader.camera_model`. Default
    /// SIMPLE_RADIAL (COLMAP's default: one focal length, one radial term).
    pub camera_model: CameraModel,
    /// One camera shared by every image (`--ImageReader.single_camera 1`),
    /// right for a video. Default true; set false for photo collections.
    /// Images of more than one size get one camera each regardless (COLMAP
    /// would skip every image whose size differs from the first), with a
    /// note.
    pub single_camera: bool,
    /// Use `scene/masks` as `--ImageReader.mask_path`. Default true.
    pub use_masks: bool,
    /// Sequential matching: frames matched after each frame
    /// (`--SequentialMatching.overlap`). Default 10.
    pub overlap: u32,
    /// Sequential matching: vocabulary-tree loop detection. Default false
    /// (it needs a vocabulary file Debian does not ship).
    pub loop_detection: bool,
    /// Longest image side used for SIFT, pixels (`--SiftExtraction.max_image_size`).
    /// Default 3200 (COLMAP's default).
    pub max_image_size: u32,
    /// Most SIFT features per image (`--SiftExtraction.max_num_features`).
    /// Default 8192 (COLMAP's default).
    pub max_num_features: u32,
    /// Threads for every step; -1 = all cores (COLMAP's default). Default -1.
    pub threads: i32,
    /// `--random_seed` passed to every step (RANSAC sampling). Default 0.
    pub seed: u64,
    /// Write an undistorted PINHOLE copy when the camera has distortion.
    /// Default true.
    pub undistort: bool,
    /// Use every `stride`-th image (in name order) for COLMAP
    /// (`--image_list_path`). Default 1 (all).
    pub stride: usize,
    /// Mapper settings (bundle-adjustment effort, initialisation).
    pub mapper: MapperOptions,
    /// Retry the mapper once with [`relaxed_init_args`] when it builds no
    /// model. Default true.
    pub retry_init: bool,
}

/// Incremental-mapper settings. `Default` is COLMAP 3.8's own;
/// [`MapperOptions::video`] bounds the bundle-adjustment effort the way
/// `colmap automatic_reconstructor --data_type video --quality low` does.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MapperOptions {
    /// `--Mapper.ba_local_max_num_iterations` (COLMAP: 25).
    pub ba_local_max_num_iterations: u32,
    /// `--Mapper.ba_global_max_num_iterations` (COLMAP: 50).
    pub ba_global_max_num_iterations: u32,
    /// `--Mapper.ba_global_max_refinements` (COLMAP: 5).
    pub ba_global_max_refinements: u32,
    /// Global BA runs when the model grew by this factor in images
    /// (`--Mapper.ba_global_images_ratio`, COLMAP: 1.1).
    pub ba_global_images_ratio: f64,
    /// ... or in points (`--Mapper.ba_global_points_ratio`, COLMAP: 1.1).
    pub ba_global_points_ratio: f64,
    /// Smallest triangulation angle of the initial pair, degrees
    /// (`--Mapper.init_min_tri_angle`, COLMAP: 16).
    pub init_min_tri_angle: f64,
}

impl Default for MapperOptions {
    fn default() -> Self {
        MapperOptions {
            ba_local_max_num_iterations: 25,
            ba_global_max_num_iterations: 50,
            ba_global_max_refinements: 5,
            ba_global_images_ratio: 1.1,
            ba_global_points_ratio: 1.1,
            init_min_tri_angle: 16.0,
        }
    }
}

impl MapperOptions {
    /// COLMAP's video preset with its low-quality bundle adjustment
    /// (`OptionManager::ModifyForVideoData` then `ModifyForLowQuality`):
    /// initial triangulation angle halved (8°), global BA only after the
    /// model grew 1.4 × 1.2 = 1.68-fold, local / global BA iterations halved
    /// (12 / 25), two global refinements. Consecutive video frames overlap
    /// heavily, so the model needs far fewer global adjustments.
    pub fn video() -> Self {
        let d = MapperOptions::default();
        MapperOptions {
            ba_local_max_num_iterations: d.ba_local_max_num_iterations / 2,
            ba_global_max_num_iterations: d.ba_global_max_num_iterations / 2,
            ba_global_max_refinements: 2,
            ba_global_images_ratio: 1.4 * 1.2,
            ba_global_points_ratio: 1.4 * 1.2,
            init_min_tri_angle: d.init_min_tri_angle / 2.0,
        }
    }

    fn args(&self) -> Vec<String> {
        let mut a = Vec::new();
        a.extend(arg(
            "Mapper.ba_local_max_num_iterations",
            self.ba_local_max_num_iterations,
        ));
        a.extend(arg(
            "Mapper.ba_global_max_num_iterations",
            self.ba_global_max_num_iterations,
        ));
        a.extend(arg(
            "Mapper.ba_global_max_refinements",
            self.ba_global_max_refinements,
        ));
        a.extend(arg(
            "Mapper.ba_global_images_ratio",
            self.ba_global_images_ratio,
        ));
        a.extend(arg(
            "Mapper.ba_global_points_ratio",
            self.ba_global_points_ratio,
        ));
        a.extend(arg("Mapper.init_min_tri_angle", self.init_min_tri_angle));
        a
    }
}

/// The settings of the one retry after the mapper built no model. COLMAP
/// already halves the initial pair's inlier count and triangulation angle
/// twice before it gives up; the retry starts from half the inliers (50) and
/// half the angle, also accepts initial pairs along the viewing direction
/// (forward motion ≤ 0.995 instead of 0.95: a camera walking forward), needs
/// 15 instead of 30 inliers to register a further image, and keeps models of
/// 3 or more images (COLMAP: 10, which discards a short clip's model).
pub fn relaxed_init_args(mapper: &MapperOptions) -> Vec<String> {
    let mut a = Vec::new();
    a.extend(arg("Mapper.init_min_num_inliers", 50));
    a.extend(arg("Mapper.init_max_forward_motion", 0.995));
    a.extend(arg("Mapper.abs_pose_min_num_inliers", 15));
    a.extend(arg("Mapper.min_model_size", 3));
    a.extend(arg(
        "Mapper.init_min_tri_angle",
        mapper.init_min_tri_angle / 2.0,
    ));
    a
}

impl Default for ColmapOptions {
    fn default() -> Self {
        ColmapOptions {
            colmap: PathBuf::from("colmap"),
            matcher: Matcher::Sequential,
            camera_model: CameraModel::SIMPLE_RADIAL,
            single_camera: true,
            use_masks: true,
            overlap: 10,
            loop_detection: false,
            max_image_size: 3200,
            max_num_features: 8192,
            threads: -1,
            seed: 0,
            undistort: true,
            stride: 1,
            mapper: MapperOptions::default(),
            retry_init: true,
        }
    }
}

impl ColmapOptions {
    /// Check the options.
    pub fn validate(&self) -> Result<()> {
        if self.overlap == 0 {
            return Err(PoseError::Invalid("overlap must be ≥ 1".into()));
        }
        if self.max_image_size < 16 {
            return Err(PoseError::Invalid(format!(
                "max_image_size {} is too small (≥ 16 pixels)",
                self.max_image_size
            )));
        }
        if self.max_num_features == 0 {
            return Err(PoseError::Invalid("max_num_features must be ≥ 1".into()));
        }
        if self.threads == 0 || self.threads < -1 {
            return Err(PoseError::Invalid(format!(
                "threads must be -1 (all) or ≥ 1, got {}",
                self.threads
            )));
        }
        if self.stride == 0 {
            return Err(PoseError::Invalid("stride must be ≥ 1".into()));
        }
        let m = &self.mapper;
        if m.ba_local_max_num_iterations == 0 || m.ba_global_max_num_iterations == 0 {
            return Err(PoseError::Invalid(
                "bundle-adjustment iterations must be ≥ 1".into(),
            ));
        }
        if !(m.ba_global_images_ratio >= 1.0 && m.ba_global_points_ratio >= 1.0) {
            return Err(PoseError::Invalid(format!(
                "global BA ratios must be ≥ 1, got {} / {}",
                m.ba_global_images_ratio, m.ba_global_points_ratio
            )));
        }
        if !(m.init_min_tri_angle > 0.0 && m.init_min_tri_angle < 90.0) {
            return Err(PoseError::Invalid(format!(
                "init_min_tri_angle must be in (0°, 90°), got {}",
                m.init_min_tri_angle
            )));
        }
        if self.loop_detection && self.matcher == Matcher::Exhaustive {
            return Err(PoseError::Invalid(
                "loop detection applies to the sequential matcher only".into(),
            ));
        }
        Ok(())
    }
}

/// Where things are read and written.
#[derive(Debug, Clone)]
pub struct ColmapPaths {
    /// The scene folder (`images/`, optional `masks/`).
    pub scene: PathBuf,
    /// Images folder; default `scene/images`.
    pub images: PathBuf,
    /// Masks folder; default `scene/masks`.
    pub masks: PathBuf,
    /// Work folder for the database, raw models and logs; default `scene/colmap`.
    pub work: PathBuf,
    /// Final model folder; default `scene/sparse/0`.
    pub out: PathBuf,
    /// Undistorted scene copy (`images/`, `masks/`, `sparse/0/`); default
    /// `scene/undistorted`.
    pub undistorted: PathBuf,
}

impl ColmapPaths {
    /// The default layout for a scene folder.
    pub fn for_scene(scene: impl AsRef<Path>) -> Self {
        let scene = scene.as_ref().to_path_buf();
        ColmapPaths {
            images: scene.join("images"),
            masks: scene.join("masks"),
            work: scene.join("colmap"),
            out: scene.join("sparse").join("0"),
            undistorted: scene.join("undistorted"),
            scene,
        }
    }
}

/// Progress reported while COLMAP runs.
#[derive(Debug, Clone, PartialEq)]
pub enum Progress {
    /// Step `index` (0-based) of `of` started.
    Started {
        step: String,
        index: usize,
        of: usize,
    },
    /// A count read from COLMAP's log ([`crate::progress`]); the mapper's
    /// total is filled in with the number of images.
    Count { step: String, count: Count },
    /// A note from the runner (resume decision, retry).
    Note { step: String, message: String },
    /// The step finished after `seconds`.
    Finished { step: String, seconds: f64 },
}

/// Time spent in one step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StepTime {
    pub step: String,
    pub seconds: f64,
}

/// How the COLMAP run went.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ColmapReport {
    /// The `colmap -h` version line.
    pub colmap_version: String,
    /// Images registered in the kept model.
    pub registered: usize,
    /// Images in the scene.
    pub total: usize,
    /// Images the kept model does not contain, by name (sorted).
    pub left_out: Vec<String>,
    /// Number of models the mapper produced.
    pub models_found: usize,
    /// Registered images of every model, largest first.
    pub model_sizes: Vec<usize>,
    /// The kept model's points and the camera COLMAP estimated.
    #[serde(flatten)]
    pub model: crate::model_info::ModelStats,
    /// Whether masks were passed to COLMAP.
    pub used_masks: bool,
    /// Matcher used.
    pub matcher: Matcher,
    /// Final model folder.
    pub model_dir: PathBuf,
    /// Undistorted PINHOLE scene copy, when one was made.
    pub undistorted_dir: Option<PathBuf>,
    /// Work folder with the database, raw models and logs.
    pub work_dir: PathBuf,
    /// What happened to the kept database ([`crate::resume`]).
    pub database: Decision,
    /// Images whose features came from the kept database.
    pub features_reused: usize,
    /// The mapper built no model at first and was retried with relaxed
    /// initialisation settings.
    pub init_retried: bool,
    /// What geometric verification found for the image pairs, when the
    /// database could be read.
    #[serde(default)]
    pub pairs: Option<crate::pairs::PairStats>,
    /// Wall time per step.
    pub timings: Vec<StepTime>,
    /// Total wall time, seconds.
    pub total_seconds: f64,
}

/// Image file names in `dir`, sorted (capture order): the loader's listing,
/// so COLMAP sees exactly the frames the other stages see.
pub use loader::scene::list_images;

/// Every image must have `masks/<name>.png` of the same size.
fn check_masks(images: &Path, masks: &Path, names: &[String]) -> Result<()> {
    if !masks.is_dir() {
        return Err(PoseError::Invalid(format!(
            "{}: no masks folder; run `romosplat mask` first or pass --no-masks",
            masks.display()
        )));
    }
    for n in names {
        let m = loader::masks::mask_path(masks, n);
        if !m.is_file() {
            return Err(PoseError::Invalid(format!(
                "{}: mask missing for image {n} (masks are <image name>.png)",
                m.display()
            )));
        }
        let img = images.join(n);
        let di = image::image_dimensions(&img)
            .map_err(|e| PoseError::Invalid(format!("{}: {e}", img.display())))?;
        let dm = image::image_dimensions(&m)
            .map_err(|e| PoseError::Invalid(format!("{}: {e}", m.display())))?;
        if di != dm {
            return Err(PoseError::Invalid(format!(
                "{}: mask is {}×{} but its image is {}×{}",
                m.display(),
                dm.0,
                dm.1,
                di.0,
                di.1
            )));
        }
    }
    Ok(())
}

fn arg(k: &str, v: impl ToString) -> [String; 2] {
    [format!("--{k}"), v.to_string()]
}

/// `base` (`--name value` pairs) with every option that `over` also sets
/// replaced by `over`'s value, which is appended. COLMAP's option parser
/// rejects an option given twice.
fn override_args(base: Vec<String>, over: &[String]) -> Vec<String> {
    let overridden: std::collections::HashSet<&str> =
        over.chunks(2).map(|kv| kv[0].as_str()).collect();
    let mut out: Vec<String> = base
        .chunks(2)
        .filter(|kv| !overridden.contains(kv[0].as_str()))
        .flatten()
        .cloned()
        .collect();
    out.extend(over.iter().cloned());
    out
}

fn path_str(p: &Path) -> String {
    p.display().to_string()
}

/// Remove and recreate a folder the runner owns inside the work folder.
fn fresh_dir(dir: &Path) -> Result<()> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| PoseError::io(dir, e))?;
    }
    std::fs::create_dir_all(dir).map_err(|e| PoseError::io(dir, e))
}

struct Runner<'a> {
    opts: &'a ColmapOptions,
    progress: &'a mut dyn FnMut(Progress),
    cancel: &'a AtomicBool,
    timings: Vec<StepTime>,
    index: usize,
    of: usize,
    work: PathBuf,
    /// Total for counts whose line does not carry one (the mapper).
    images: u64,
}

impl Runner<'_> {
    /// Run one COLMAP step logging to `work/<log>.log`.
    fn step(&mut self, step: &str, log: &str, args: Vec<String>) -> Result<StepOutcome> {
        (self.progress)(Progress::Started {
            step: step.to_string(),
            index: self.index,
            of: self.of,
        });
        self.index += 1;
        let log = self.work.join(format!("{log}.log"));
        let progress = &mut *self.progress;
        let images = self.images;
        let out = run_step_cancellable(
            &self.opts.colmap,
            step,
            &args,
            &log,
            &mut |line| {
                if let Some(mut count) = parse_line(line) {
                    if count.unit == Unit::Registered {
                        count.total = Some(images);
                    }
                    progress(Progress::Count {
                        step: step.to_string(),
                        count,
                    });
                }
            },
            self.cancel,
        )?;
        (self.progress)(Progress::Finished {
            step: step.to_string(),
            seconds: out.seconds,
        });
        self.timings.push(StepTime {
            step: step.to_string(),
            seconds: out.seconds,
        });
        Ok(out)
    }

    fn note(&mut self, step: &str, message: String) {
        (self.progress)(Progress::Note {
            step: step.to_string(),
            message,
        });
    }
}

/// One image's header: (width, height) and bits per channel, or why the
/// `image` crate could not read it.
type Header = std::result::Result<((u32, u32), u16), String>;

/// The headers of `dir/<name>` over `names`, read once for the checks
/// below.
fn image_headers(dir: &Path, names: &[String]) -> Vec<Header> {
    use image::ImageDecoder;
    names
        .iter()
        .map(|n| {
            let decoder = image::ImageReader::open(dir.join(n))
                .map_err(|e| e.to_string())?
                .with_guessed_format()
                .map_err(|e| e.to_string())?
                .into_decoder()
                .map_err(|e| e.to_string())?;
            let colour = decoder.color_type();
            let bits = colour.bits_per_pixel() / u16::from(colour.channel_count()).max(1);
            Ok((decoder.dimensions(), bits))
        })
        .collect()
}

/// The distinct pixel sizes over `headers` (of `dir/<name>` over `names`),
/// in order of first appearance.
fn distinct_sizes(dir: &Path, names: &[String], headers: &[Header]) -> Result<Vec<(u32, u32)>> {
    let mut sizes: Vec<(u32, u32)> = Vec::new();
    for (n, h) in names.iter().zip(headers) {
        let (d, _) = h.as_ref().map_err(|e| {
            PoseError::Invalid(format!(
                "{}: cannot read the image size: {e}",
                dir.join(n).display()
            ))
        })?;
        if !sizes.contains(d) {
            sizes.push(*d);
        }
    }
    Ok(sizes)
}

/// Folder under the work folder that holds 8-bit copies for COLMAP.
const EIGHT_BIT_DIR: &str = "images_8bit";

/// COLMAP 3.8 reads 8-bit images only: FreeImage cannot convert 16-bit PNG
/// or TIFF pixels, so the feature extractor skips such an image ("Failed to
/// read image file format") and leaves it out. When any of `names` has more
/// than 8 bits per channel, `work/images_8bit/` is made anew with an 8-bit
/// copy of each such image under its own name (and format) and a link to
/// each other image, and returned with the number of copies; `None` when
/// every image is 8-bit. Image names, and so the masks and the model, are
/// unchanged. An image whose header cannot be read is left to COLMAP.
fn eight_bit_images(
    images: &Path,
    names: &[String],
    headers: &[Header],
    work: &Path,
) -> Result<Option<(PathBuf, usize)>> {
    let deep: Vec<bool> = headers
        .iter()
        .map(|h| h.as_ref().is_ok_and(|(_, bits)| *bits > 8))
        .collect();
    let copies = deep.iter().filter(|d| **d).count();
    if copies == 0 {
        return Ok(None);
    }
    let dir = work.join(EIGHT_BIT_DIR);
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|e| PoseError::io(&dir, e))?;
    }
    for (n, deep) in names.iter().zip(deep) {
        let src = images.join(n);
        let dst = dir.join(n);
        if let Some(parent) = dst.parent() {
            std::fs::create_dir_all(parent).map_err(|e| PoseError::io(parent, e))?;
        }
        if deep {
            let img = image::open(&src).map_err(|e| {
                PoseError::Invalid(format!("{}: cannot read the image: {e}", src.display()))
            })?;
            let img = if img.color().has_color() {
                image::DynamicImage::ImageRgb8(img.to_rgb8())
            } else {
                image::DynamicImage::ImageLuma8(img.to_luma8())
            };
            img.save(&dst).map_err(|e| {
                PoseError::Invalid(format!(
                    "{}: cannot write an 8-bit copy: {e}",
                    dst.display()
                ))
            })?;
        } else {
            let src = std::path::absolute(&src).map_err(|e| PoseError::io(&src, e))?;
            link_or_copy(&src, &dst)?;
        }
    }
    Ok(Some((dir, copies)))
}

#[cfg(unix)]
fn link_or_copy(src: &Path, dst: &Path) -> Result<()> {
    std::os::unix::fs::symlink(src, dst).map_err(|e| PoseError::io(dst, e))
}

#[cfg(not(unix))]
fn link_or_copy(src: &Path, dst: &Path) -> Result<()> {
    std::fs::copy(src, dst)
        .map(|_| ())
        .map_err(|e| PoseError::io(dst, e))
}

/// Images the feature extractor could not read, from its log: each
/// `Name: …` followed by an `ERROR: …` line, as (name, error).
fn unreadable_images(log: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut name: Option<&str> = None;
    for line in log.lines().map(str::trim) {
        if let Some(n) = line.strip_prefix("Name:") {
            name = Some(n.trim());
        } else if let (Some(err), Some(n)) = (line.strip_prefix("ERROR:"), name) {
            out.push((n.to_string(), err.trim().to_string()));
            name = None;
        }
    }
    out
}

/// Remove the database and its SQLite side files.
fn remove_database(db: &Path) -> Result<()> {
    let mut side = db.as_os_str().to_os_string();
    side.push("-shm");
    let shm = PathBuf::from(&side);
    let mut side = db.as_os_str().to_os_string();
    side.push("-wal");
    let wal = PathBuf::from(&side);
    for f in [db.to_path_buf(), shm, wal] {
        if f.exists() {
            std::fs::remove_file(&f).map_err(|e| PoseError::io(&f, e))?;
        }
    }
    Ok(())
}

/// The keys of what the database holds for these inputs and options.
fn resume_keys(
    paths: &ColmapPaths,
    opts: &ColmapOptions,
    names: &[String],
    version: &str,
) -> Result<(FeatureKey, MatchKey)> {
    let images = names
        .iter()
        .map(|n| resume::file_key_stat(&paths.images, n))
        .collect::<Result<Vec<_>>>()?;
    let masks = if opts.use_masks {
        names
            .iter()
            .map(|n| resume::file_key_hash(&paths.masks, &format!("{n}.png")))
            .collect::<Result<Vec<_>>>()?
    } else {
        Vec::new()
    };
    let kv = |k: &str, v: String| (k.to_string(), v);
    let features = FeatureKey {
        colmap_version: version.to_string(),
        images,
        masks,
        settings: vec![
            kv("images", path_str(&paths.images)),
            kv("camera_model", opts.camera_model.name().to_string()),
            kv("single_camera", opts.single_camera.to_string()),
            kv("max_image_size", opts.max_image_size.to_string()),
            kv("max_num_features", opts.max_num_features.to_string()),
            kv("seed", opts.seed.to_string()),
        ],
    };
    let matching = MatchKey {
        settings: vec![
            kv("matcher", opts.matcher.step().to_string()),
            kv("overlap", opts.overlap.to_string()),
            kv("loop_detection", opts.loop_detection.to_string()),
            kv("seed", opts.seed.to_string()),
        ],
    };
    Ok((features, matching))
}

/// Models the mapper wrote into `sparse`, with at least one image.
fn read_models(sparse: &Path) -> Result<Vec<(crate::model_info::ModelInfo, PathBuf)>> {
    let mut models = Vec::new();
    if let Ok(rd) = std::fs::read_dir(sparse) {
        for e in rd.flatten() {
            let p = e.path();
            if p.join("images.bin").is_file() {
                models.push((read_model_info(&p)?, p));
            }
        }
    }
    models.retain(|(m, _)| m.registered() > 0);
    Ok(models)
}

/// Run the whole pose stage on a scene. See the module documentation.
pub fn run_colmap(
    paths: &ColmapPaths,
    opts: &ColmapOptions,
    progress: &mut dyn FnMut(Progress),
) -> Result<ColmapReport> {
    run_colmap_cancellable(paths, opts, progress, &AtomicBool::new(false))
}

/// [`run_colmap`] that stops with [`PoseError::Cancelled`] once `cancel` is
/// set (the running COLMAP process is killed; the database keeps what was
/// done and a rerun resumes from it). The steps: pick the images, decide what
/// the kept database can resume, extract features, match, map (retried once
/// with relaxed initialisation), undistort, install the largest model.
pub fn run_colmap_cancellable(
    paths: &ColmapPaths,
    opts: &ColmapOptions,
    progress: &mut dyn FnMut(Progress),
    cancel: &AtomicBool,
) -> Result<ColmapReport> {
    opts.validate()?;
    let t0 = Instant::now();
    let version = colmap_version(&opts.colmap)?;
    let names = selected_images(paths, opts)?;
    let headers = image_headers(&paths.images, &names);
    // Only a shared camera needs one size.
    let sizes = if opts.single_camera {
        distinct_sizes(&paths.images, &names, &headers)?
    } else {
        Vec::new()
    };
    let per_image = sizes.len() > 1;
    let own;
    let opts = if per_image {
        own = ColmapOptions {
            single_camera: false,
            ..opts.clone()
        };
        &own
    } else {
        opts
    };
    std::fs::create_dir_all(&paths.work).map_err(|e| PoseError::io(&paths.work, e))?;
    let db = paths.work.join("database.db");
    let state_path = paths.work.join("resume.json");
    let (feature_key, match_key) = resume_keys(paths, opts, &names, &version)?;
    // COLMAP reads 8-bit copies of deeper images; keys stay on the originals.
    let eight_bit = eight_bit_images(&paths.images, &names, &headers, &paths.work)?;
    let staged;
    let paths = match &eight_bit {
        Some((dir, _)) => {
            staged = ColmapPaths {
                images: dir.clone(),
                ..paths.clone()
            };
            &staged
        }
        None => paths,
    };
    let saved = resume::load(&state_path);
    let decision = resume::decide(saved.as_ref(), db.is_file(), &feature_key, &match_key);
    let sparse = paths.work.join("sparse");
    fresh_dir(&sparse)?;
    let list = paths.work.join("image_list.txt");
    let mut text = names.join("\n");
    text.push('\n');
    std::fs::write(&list, text).map_err(|e| PoseError::io(&list, e))?;

    let mut r = Runner {
        opts,
        progress,
        cancel,
        timings: Vec::new(),
        index: 0,
        of: if opts.undistort { 4 } else { 3 },
        work: paths.work.clone(),
        images: names.len() as u64,
    };
    if let Some((dir, copies)) = &eight_bit {
        r.note(
            "feature_extractor",
            format!(
                "{copies} of {} images have more than 8 bits per channel, which COLMAP 3.8 cannot read: it reads 8-bit copies in {}",
                names.len(),
                dir.display()
            ),
        );
    }
    if per_image {
        r.note(
            "feature_extractor",
            format!(
                "the images have {} sizes ({}): one camera per image instead of one shared",
                sizes.len(),
                sizes
                    .iter()
                    .take(4)
                    .map(|(w, h)| format!("{w}×{h}"))
                    .collect::<Vec<_>>()
                    .join(", ")
                    + if sizes.len() > 4 { ", …" } else { "" }
            ),
        );
    }
    let steps = Steps {
        paths,
        db,
        seed: arg("random_seed", opts.seed),
    };
    steps.prepare_database(&mut r, decision, &state_path, &feature_key)?;
    let features_reused = steps.extract_features(&mut r, &list)?;
    resume::save(
        &state_path,
        &ResumeState {
            features: feature_key,
            matching: Some(match_key),
        },
    )?;
    steps.match_features(&mut r)?;
    // The matcher's verdicts on the image pairs: they name the cause when no
    // model comes out, and warn when one is built without parallax.
    let pairs = crate::pairs::read_pair_stats(&steps.db).ok();
    let no_parallax = pairs.is_some_and(|p| p.no_parallax());
    let (out, mut models, init_retried) = steps.map(&mut r, &sparse)?;
    if models.is_empty() {
        return Err(no_model_error(opts, &out, pairs, names.len(), init_retried));
    }
    require_success("mapper", &out)?;
    if no_parallax {
        r.note(
            "mapper",
            "warning: every verified image pair is related by a homography: little or no parallax (a camera that mostly rotates, or a flat scene); check the poses".into(),
        );
    }
    models.sort_by_key(|(m, _)| {
        (
            std::cmp::Reverse(m.registered()),
            std::cmp::Reverse(m.stats.points),
        )
    });
    let model_sizes: Vec<usize> = models.iter().map(|(m, _)| m.registered()).collect();
    let (best, best_dir) = models.swap_remove(0);
    let registered_names: std::collections::HashSet<&str> =
        best.image_names.iter().map(String::as_str).collect();
    let left_out: Vec<String> = names
        .iter()
        .filter(|n| !registered_names.contains(n.as_str()))
        .cloned()
        .collect();
    let undistorted_dir = if opts.undistort && best.has_distortion {
        Some(steps.undistort(&mut r, &best_dir)?)
    } else {
        None
    };
    crate::model_info::install_model(&best_dir, &paths.out)?;

    Ok(ColmapReport {
        colmap_version: version,
        registered: best.registered(),
        total: names.len(),
        left_out,
        models_found: model_sizes.len(),
        model_sizes,
        model: best.stats.clone(),
        used_masks: opts.use_masks,
        matcher: opts.matcher,
        model_dir: paths.out.clone(),
        undistorted_dir,
        work_dir: paths.work.clone(),
        database: decision,
        features_reused,
        init_retried,
        pairs,
        timings: r.timings,
        total_seconds: t0.elapsed().as_secs_f64(),
    })
}

/// The images the pose stage uses (every `stride`-th), at least two, with
/// their masks checked when masks are used.
fn selected_images(paths: &ColmapPaths, opts: &ColmapOptions) -> Result<Vec<String>> {
    let all_names = list_images(&paths.images)?;
    let names: Vec<String> = all_names.iter().step_by(opts.stride).cloned().collect();
    if names.len() < 2 {
        return Err(PoseError::Invalid(format!(
            "{}: {} images{}; structure from motion needs at least 2",
            paths.images.display(),
            names.len(),
            if opts.stride > 1 {
                format!(" at stride {}", opts.stride)
            } else {
                String::new()
            }
        )));
    }
    if opts.use_masks {
        check_masks(&paths.images, &paths.masks, &names)?;
    }
    Ok(names)
}

/// What every COLMAP step of one run shares: the scene's paths, the
/// database and the seed argument.
struct Steps<'a> {
    paths: &'a ColmapPaths,
    db: PathBuf,
    seed: [String; 2],
}

impl Steps<'_> {
    /// Make the database match the resume `decision`: a fresh one (its
    /// resume state written first, so an interrupted extraction leaves a
    /// database that matches it), the kept features without their matches,
    /// or everything kept.
    fn prepare_database(
        &self,
        r: &mut Runner,
        decision: Decision,
        state_path: &Path,
        feature_key: &FeatureKey,
    ) -> Result<()> {
        match decision {
            Decision::Fresh => {
                remove_database(&self.db)?;
                resume::save(
                    state_path,
                    &ResumeState {
                        features: feature_key.clone(),
                        matching: None,
                    },
                )
            }
            Decision::KeepFeatures => {
                r.note(
                    "database_cleaner",
                    "matching settings changed: clearing the kept matches".into(),
                );
                let mut a: Vec<String> = Vec::new();
                a.extend(arg("database_path", path_str(&self.db)));
                a.extend(arg("type", "matches"));
                let out = r.step("database_cleaner", "database_cleaner", a)?;
                require_success("database_cleaner", &out)
            }
            Decision::KeepAll => {
                r.note(
                    "feature_extractor",
                    format!(
                        "resuming from the kept database {} (done images and pairs are skipped)",
                        self.db.display()
                    ),
                );
                Ok(())
            }
        }
    }

    /// Step 1, SIFT features of the images in `list` (masked pixels
    /// ignored). Returns how many images the kept database already had.
    fn extract_features(&self, r: &mut Runner, list: &Path) -> Result<usize> {
        let opts = r.opts;
        let mut a: Vec<String> = Vec::new();
        a.extend(arg("database_path", path_str(&self.db)));
        a.extend(arg("image_path", path_str(&self.paths.images)));
        a.extend(arg("image_list_path", path_str(list)));
        a.extend(arg("ImageReader.camera_model", opts.camera_model.name()));
        a.extend(arg(
            "ImageReader.single_camera",
            u8::from(opts.single_camera),
        ));
        if opts.use_masks {
            a.extend(arg("ImageReader.mask_path", path_str(&self.paths.masks)));
        }
        a.extend(arg("SiftExtraction.use_gpu", 0));
        a.extend(arg("SiftExtraction.num_threads", opts.threads));
        a.extend(arg("SiftExtraction.max_image_size", opts.max_image_size));
        a.extend(arg(
            "SiftExtraction.max_num_features",
            opts.max_num_features,
        ));
        a.extend(self.seed.clone());
        let out = r.step("feature_extractor", "feature_extractor", a)?;
        require_success("feature_extractor", &out)?;
        let log = std::fs::read_to_string(&out.log).unwrap_or_default();
        // COLMAP exits 0 when it skips images it cannot read; the matcher
        // then aborts on an empty database. Name them here instead.
        let unreadable = unreadable_images(&log);
        if let Some((name, err)) = unreadable.first() {
            let images = r.images;
            let message = format!(
                "COLMAP could not read {} of {images} images in {} (first {name}: {err}); log {}",
                unreadable.len(),
                self.paths.images.display(),
                out.log.display()
            );
            if unreadable.len() as u64 + 2 > images {
                return Err(PoseError::Degenerate(message));
            }
            r.note("feature_extractor", format!("warning: {message}"));
        }
        Ok(log
            .lines()
            .filter(|l| l.contains("SKIP: Features for image already extracted"))
            .count())
    }

    /// Step 2, matching (sequential or exhaustive).
    fn match_features(&self, r: &mut Runner) -> Result<()> {
        let opts = r.opts;
        let mut a: Vec<String> = Vec::new();
        a.extend(arg("database_path", path_str(&self.db)));
        a.extend(arg("SiftMatching.use_gpu", 0));
        a.extend(arg("SiftMatching.num_threads", opts.threads));
        if opts.matcher == Matcher::Sequential {
            a.extend(arg("SequentialMatching.overlap", opts.overlap));
            a.extend(arg(
                "SequentialMatching.loop_detection",
                u8::from(opts.loop_detection),
            ));
        }
        a.extend(self.seed.clone());
        let step = opts.matcher.step();
        let out = r.step(step, step, a)?;
        require_success(step, &out)
    }

    /// Step 3, mapping into `sparse`, retried once with relaxed
    /// initialisation when no model comes out. Returns the last mapper run,
    /// the models it wrote and whether it was the retry.
    #[allow(clippy::type_complexity)]
    fn map(
        &self,
        r: &mut Runner,
        sparse: &Path,
    ) -> Result<(
        StepOutcome,
        Vec<(crate::model_info::ModelInfo, PathBuf)>,
        bool,
    )> {
        let opts = r.opts;
        let mut a: Vec<String> = Vec::new();
        a.extend(arg("database_path", path_str(&self.db)));
        a.extend(arg("image_path", path_str(&self.paths.images)));
        a.extend(arg("output_path", path_str(sparse)));
        a.extend(arg("Mapper.num_threads", opts.threads));
        a.extend(opts.mapper.args());
        a.extend(self.seed.clone());
        let out = r.step("mapper", "mapper", a.clone())?;
        let models = read_models(sparse)?;
        if !models.is_empty() || !opts.retry_init {
            return Ok((out, models, false));
        }
        r.note(
            "mapper",
            "no model: retrying once with relaxed initialisation settings".into(),
        );
        fresh_dir(sparse)?;
        // COLMAP refuses an option given twice, so the relaxed values replace
        // the ones already in the argument list.
        let a = override_args(a, &relaxed_init_args(&opts.mapper));
        let out = r.step("mapper", "mapper_relaxed", a)?;
        Ok((out, read_models(sparse)?, true))
    }

    /// Step 4, undistortion of the model in `model_dir` (its camera has
    /// distortion), installed with its masks; returns where.
    fn undistort(&self, r: &mut Runner, model_dir: &Path) -> Result<PathBuf> {
        let und = self.paths.work.join("undistorted");
        fresh_dir(&und)?;
        let mut a: Vec<String> = Vec::new();
        a.extend(arg("image_path", path_str(&self.paths.images)));
        a.extend(arg("input_path", path_str(model_dir)));
        a.extend(arg("output_path", path_str(&und)));
        a.extend(arg("output_type", "COLMAP"));
        let out = r.step("image_undistorter", "image_undistorter", a)?;
        require_success("image_undistorter", &out)?;
        let masks = r.opts.use_masks.then_some(self.paths.masks.as_path());
        crate::undistort::install_undistorted(&und, model_dir, masks, &self.paths.undistorted)?;
        Ok(self.paths.undistorted.clone())
    }
}

/// The error when the mapper built no model from `images` images: the cause
/// from the matcher's verdicts (`pairs`) when they tell, else generic
/// advice, and the mapper's log.
fn no_model_error(
    opts: &ColmapOptions,
    out: &StepOutcome,
    pairs: Option<crate::pairs::PairStats>,
    images: usize,
    init_retried: bool,
) -> PoseError {
    let no_init = std::fs::read_to_string(&out.log)
        .unwrap_or_default()
        .contains("No good initial image pair found");
    let cause = if no_init {
        "COLMAP found no initial image pair"
    } else {
        "COLMAP built no model"
    };
    let retried = if init_retried {
        ", also with relaxed initialisation settings"
    } else {
        ""
    };
    let mask_hint = if opts.use_masks {
        " or `--no-masks`"
    } else {
        ""
    };
    let mut msg = match pairs.and_then(|s| s.cause().map(|d| (s, d))) {
        Some((s, d)) => format!(
            "{cause} from {images} images{retried}: {d}{} (mapper log {})",
            if s.verified == 0 && opts.use_masks {
                "; try `--no-masks`"
            } else {
                ""
            },
            out.log.display()
        ),
        None => format!(
            "{cause} from {images} images{retried}: the frames have too little parallax or too few static features match; use more frames (a higher --fps or --pose-stride 1), more features, `--matcher exhaustive`{} (mapper log {})",
            mask_hint,
            out.log.display()
        ),
    };
    if !out.success {
        msg.push_str(&format!(
            "; mapper {}: {}",
            out.status,
            log_tail(&out.log, 4)
        ));
    }
    PoseError::NoModel(msg)
}
