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

use crate::error::{PoseError, Result};
use crate::model_info::read_model_info;
use crate::process::{StepOutcome, colmap_version, log_tail, require_success, run_step};
use loader::CameraModel;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How image pairs are chosen for matching.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
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
    /// A progress line from COLMAP (`Processed file [3/40]`, ...).
    Line { step: String, line: String },
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
    /// 3D points in the kept model.
    pub points: usize,
    /// Mean reprojection error of the points, pixels.
    pub mean_reprojection_error: f64,
    /// Mean track length (observations per point).
    pub mean_track_length: f64,
    /// Camera model and parameters COLMAP estimated (first camera).
    pub camera_model: String,
    pub camera_params: Vec<f64>,
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
    /// Wall time per step.
    pub timings: Vec<StepTime>,
    /// Total wall time, seconds.
    pub total_seconds: f64,
}

const IMAGE_EXTS: [&str; 6] = ["jpg", "jpeg", "png", "tif", "tiff", "bmp"];

/// Image file names in `dir`, sorted (capture order).
pub fn list_images(dir: &Path) -> Result<Vec<String>> {
    let rd = std::fs::read_dir(dir).map_err(|e| PoseError::io(dir, e))?;
    let mut names = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| PoseError::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let ext = Path::new(&name)
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if IMAGE_EXTS.contains(&ext.as_str()) && entry.path().is_file() {
            names.push(name);
        }
    }
    names.sort();
    Ok(names)
}

/// Every image must have `masks/<name>.png` of the same size.
fn check_masks(images: &Path, masks: &Path, names: &[String]) -> Result<()> {
    if !masks.is_dir() {
        return Err(PoseError::Invalid(format!(
            "{}: no masks folder; run `romosplat mask` first or pass --no-masks",
            masks.display()
        )));
    }
    for n in names {
        let m = masks.join(format!("{n}.png"));
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
    timings: Vec<StepTime>,
    index: usize,
    of: usize,
    work: PathBuf,
}

impl Runner<'_> {
    fn step(&mut self, step: &str, args: Vec<String>) -> Result<StepOutcome> {
        (self.progress)(Progress::Started {
            step: step.to_string(),
            index: self.index,
            of: self.of,
        });
        self.index += 1;
        let log = self.work.join(format!("{step}.log"));
        let progress = &mut *self.progress;
        let out = run_step(&self.opts.colmap, step, &args, &log, &mut |line| {
            progress(Progress::Line {
                step: step.to_string(),
                line: line.to_string(),
            })
        })?;
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
}

/// Run the whole pose stage on a scene. See the module documentation.
pub fn run_colmap(
    paths: &ColmapPaths,
    opts: &ColmapOptions,
    progress: &mut dyn FnMut(Progress),
) -> Result<ColmapReport> {
    opts.validate()?;
    let t0 = Instant::now();
    let version = colmap_version(&opts.colmap)?;
    let names = list_images(&paths.images)?;
    if names.len() < 2 {
        return Err(PoseError::Invalid(format!(
            "{}: {} images found; structure from motion needs at least 2",
            paths.images.display(),
            names.len()
        )));
    }
    if opts.use_masks {
        check_masks(&paths.images, &paths.masks, &names)?;
    }
    std::fs::create_dir_all(&paths.work).map_err(|e| PoseError::io(&paths.work, e))?;
    let db = paths.work.join("database.db");
    for f in [
        db.clone(),
        paths.work.join("database.db-shm"),
        paths.work.join("database.db-wal"),
    ] {
        if f.exists() {
            std::fs::remove_file(&f).map_err(|e| PoseError::io(&f, e))?;
        }
    }
    let sparse = paths.work.join("sparse");
    fresh_dir(&sparse)?;

    let mut r = Runner {
        opts,
        progress,
        timings: Vec::new(),
        index: 0,
        of: if opts.undistort { 4 } else { 3 },
        work: paths.work.clone(),
    };
    let seed = arg("random_seed", opts.seed);

    // 1. Features.
    let mut a: Vec<String> = Vec::new();
    a.extend(arg("database_path", path_str(&db)));
    a.extend(arg("image_path", path_str(&paths.images)));
    a.extend(arg("ImageReader.camera_model", opts.camera_model.name()));
    a.extend(arg(
        "ImageReader.single_camera",
        u8::from(opts.single_camera),
    ));
    if opts.use_masks {
        a.extend(arg("ImageReader.mask_path", path_str(&paths.masks)));
    }
    a.extend(arg("SiftExtraction.use_gpu", 0));
    a.extend(arg("SiftExtraction.num_threads", opts.threads));
    a.extend(arg("SiftExtraction.max_image_size", opts.max_image_size));
    a.extend(arg(
        "SiftExtraction.max_num_features",
        opts.max_num_features,
    ));
    a.extend(seed.clone());
    let out = r.step("feature_extractor", a)?;
    require_success("feature_extractor", &out)?;

    // 2. Matching.
    let mut a: Vec<String> = Vec::new();
    a.extend(arg("database_path", path_str(&db)));
    a.extend(arg("SiftMatching.use_gpu", 0));
    a.extend(arg("SiftMatching.num_threads", opts.threads));
    if opts.matcher == Matcher::Sequential {
        a.extend(arg("SequentialMatching.overlap", opts.overlap));
        a.extend(arg(
            "SequentialMatching.loop_detection",
            u8::from(opts.loop_detection),
        ));
    }
    a.extend(seed.clone());
    let step = opts.matcher.step();
    let out = r.step(step, a)?;
    require_success(step, &out)?;

    // 3. Mapping.
    let mut a: Vec<String> = Vec::new();
    a.extend(arg("database_path", path_str(&db)));
    a.extend(arg("image_path", path_str(&paths.images)));
    a.extend(arg("output_path", path_str(&sparse)));
    a.extend(arg("Mapper.num_threads", opts.threads));
    a.extend(seed.clone());
    let out = r.step("mapper", a)?;
    let mut models = Vec::new();
    if let Ok(rd) = std::fs::read_dir(&sparse) {
        for e in rd.flatten() {
            let p = e.path();
            if p.join("images.bin").is_file() {
                models.push((read_model_info(&p)?, p));
            }
        }
    }
    models.retain(|(m, _)| m.registered() > 0);
    if models.is_empty() {
        let mut msg = format!(
            "COLMAP built no model from {} images: too few static features could be matched; try `--matcher exhaustive`{} (mapper log {})",
            names.len(),
            if opts.use_masks {
                " or `--no-masks`"
            } else {
                ""
            },
            out.log.display()
        );
        if !out.success {
            msg.push_str(&format!(
                "; mapper {}: {}",
                out.status,
                log_tail(&out.log, 4)
            ));
        }
        return Err(PoseError::NoModel(msg));
    }
    require_success("mapper", &out)?;
    models.sort_by_key(|(m, _)| {
        (
            std::cmp::Reverse(m.registered()),
            std::cmp::Reverse(m.points),
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

    // 4. Undistortion, when the camera has distortion.
    let mut undistorted_dir = None;
    if opts.undistort && best.has_distortion {
        let und = paths.work.join("undistorted");
        fresh_dir(&und)?;
        let mut a: Vec<String> = Vec::new();
        a.extend(arg("image_path", path_str(&paths.images)));
        a.extend(arg("input_path", path_str(&best_dir)));
        a.extend(arg("output_path", path_str(&und)));
        a.extend(arg("output_type", "COLMAP"));
        let out = r.step("image_undistorter", a)?;
        require_success("image_undistorter", &out)?;
        let masks = opts.use_masks.then_some(paths.masks.as_path());
        crate::undistort::install_undistorted(&und, &best_dir, masks, &paths.undistorted)?;
        undistorted_dir = Some(paths.undistorted.clone());
    }

    crate::model_info::install_model(&best_dir, &paths.out)?;

    Ok(ColmapReport {
        colmap_version: version,
        registered: best.registered(),
        total: names.len(),
        left_out,
        models_found: model_sizes.len(),
        model_sizes,
        points: best.points,
        mean_reprojection_error: best.mean_reprojection_error,
        mean_track_length: best.mean_track_length,
        camera_model: best.camera_model.clone(),
        camera_params: best.camera_params.clone(),
        used_masks: opts.use_masks,
        matcher: opts.matcher,
        model_dir: paths.out.clone(),
        undistorted_dir,
        work_dir: paths.work.clone(),
        timings: r.timings,
        total_seconds: t0.elapsed().as_secs_f64(),
    })
}
