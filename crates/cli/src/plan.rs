//! The time-budget planner of `romosplat run --budget-minutes N`.
//!
//! It picks what the user did not set — how many frames go to COLMAP
//! (stride), COLMAP's SIFT image size and feature count, the training
//! downscale and step count — so that the estimated wall time of all stages
//! fits the budget. Estimates come from [`Rates`]: the training step time is
//! probed on this machine's adapter ([`probe_step_seconds`], a few steps on
//! synthetic splats at two resolutions and two splat counts, fitted as
//! bilinear in pixels and splats, [`probe_train_rates`]) and charged at the
//! splat count the schedule's densification is expected to average
//! ([`mean_splats`]); the mask and COLMAP costs are per-pixel / per-feature
//! rates measured on the 2-core development machine, scaled by how much
//! slower or faster this machine's CPU runs the mask stage's optical flow
//! ([`probe_cpu_factor`], [`Rates::measured`]), with the features per image
//! that COLMAP's matching and mapper cost grow with measured by running its
//! SIFT on three of the input's frames ([`probe_px_per_feature`]).
//!
//! Order of choices:
//! 1. masks: every frame, full resolution (RoMo needs consecutive frames),
//!    unless a video's masks alone would take over [`MASK_SHARE`] of the
//!    budget: then every k-th frame is extracted (the smallest k that fits;
//!    a long video, where dropping frames costs less than the budget);
//! 2. COLMAP: the best of COLMAP's quality tiers (automatic_reconstructor's
//!    medium / low, then smaller) whose estimate fits [`POSE_SHARE`] of the
//!    budget; if even the smallest does not, a frame stride;
//! 3. training gets what is left after masks, COLMAP and a reserve for
//!    evaluation / export / report, shared equally by the models it trains
//!    (the masked one and, by default, the unmasked baseline at the same
//!    steps): the finest downscale at which [`TARGET_STEPS`] fit, capped at
//!    [`MAX_STEPS`]; below that, the coarsest allowed downscale with the
//!    steps that fit.
//!
//! Explicit `--steps`, `--downscale`, `--pose-stride`, `--pose-features` and
//! `--pose-max-image-size` are kept as given (the plan may then exceed the
//! budget, and says so).

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Share of the budget COLMAP may take.
pub const POSE_SHARE: f64 = 0.30;
/// Share of the budget the mask stage may take before a video's frames are
/// subsampled at extraction.
pub const MASK_SHARE: f64 = 0.35;
/// Steps the planner aims for before it trades resolution for them.
pub const TARGET_STEPS: usize = 3000;
/// INRIA's first evaluation checkpoint; more is not planned on a CPU budget.
pub const MAX_STEPS: usize = 7000;
/// Fewest steps worth training.
pub const MIN_STEPS: usize = 300;
/// Shortest training-image side the planner goes down to, pixels.
pub const MIN_TRAIN_SIDE: u32 = 120;

/// Splats a run's training starts from, for the estimate: COLMAP's sparse
/// points of a video at the planner's features (4 900–6 500 in the 854×480
/// runs of `docs/results.md`, fewer for short clips).
pub const INIT_SPLATS: f64 = 5000.0;
/// Growth of the splat count per densification round of the default
/// strategy, the highest of nine runs of 100 to 2700 steps at 214×120 to
/// 854×480 (1.27–1.34: final over initial count, to the power one over the
/// rounds), so that the estimate errs long.
pub const DENSIFY_GROWTH: f64 = 1.34;
/// A real scene's training step over the synthetic probe's at the same size
/// and splat count: 1.12 on lady-running (0.200 s against 0.178) and 1.11 on
/// the fox + DAVIS composite (0.224 against 0.202), `run` with defaults.
pub const SCENE_STEP_FACTOR: f64 = 1.12;
/// Splat counts the training probe runs at (the bilinear fit's two ends).
pub const PROBE_SPLATS: [usize; 2] = [5_000, 40_000];

/// Training-step time, seconds = `a + per_px · pixels + per_splat · splats
/// + per_px_splat · pixels · splats` (rasterisation grows with both).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StepRates {
    pub a: f64,
    pub per_px: f64,
    pub per_splat: f64,
    pub per_px_splat: f64,
}

impl StepRates {
    /// A step that does not depend on the splat count.
    #[cfg(test)]
    pub fn flat(a: f64, per_px: f64) -> Self {
        StepRates {
            a,
            per_px,
            ..Default::default()
        }
    }

    /// Seconds of one step at `pixels` with `splats`.
    pub fn step(&self, pixels: f64, splats: f64) -> f64 {
        let per_splat = (self.per_splat + self.per_px_splat * pixels).max(0.0);
        self.a + self.per_px * pixels + per_splat * splats
    }
}

/// Measured costs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Rates {
    /// Training step time on this adapter.
    pub train: StepRates,
    /// RoMo mask stage, seconds per frame = `mask_s_per_frame +
    /// mask_s_per_px · pixels`: most of it runs on the fixed working grid,
    /// the rest (decoding, the guided filter, writing) at full resolution.
    pub mask_s_per_frame: f64,
    pub mask_s_per_px: f64,
    /// COLMAP SIFT extraction, seconds per image plus per pixel at the
    /// SIFT size.
    pub sift_s_per_image: f64,
    pub sift_s_per_px: f64,
    /// COLMAP matching, seconds per image pair per feature.
    pub match_s_per_pair_feature: f64,
    /// COLMAP mapper, seconds per image per 1000 features.
    pub mapper_s_per_image_kfeature: f64,
    /// COLMAP image undistorter, seconds per pixel of the frames.
    pub undistort_s_per_px: f64,
    /// Pixels per SIFT feature COLMAP finds on the input's frames at the
    /// first tier's size: [`probe_px_per_feature`], else [`PX_PER_FEATURE`].
    pub px_per_feature: f64,
    /// Evaluation, export and report, seconds per training-image pixel
    /// (renders of the held-out views) plus a fixed part.
    pub finish_s: f64,
    /// This CPU's time for the flow probe over the development machine's
    /// (1 = as fast; the mask and COLMAP rates above include it).
    pub cpu_factor: f64,
}

impl Rates {
    /// Mask and COLMAP rates of the development machine (where the CPU
    /// probe takes [`CPU_PROBE_REFERENCE_S`]) times `cpu_factor` (this CPU's
    /// [`probe_cpu_factor`]), with the training terms given by a probe of
    /// the adapter.
    /// - Mask stage: 0.155 s a 854×480 frame over a 650-frame video
    ///   (`romosplat mask` on `lady-running.mp4` looped ten times, 101 s,
    ///   the probe at 1.02) and 0.384 s a 3840×2160 frame (its 65 frames
    ///   upscaled, 25 s, probe at 0.95): 0.141 s a frame plus 0.030 s a
    ///   megapixel.
    /// - COLMAP 3.8, from the stage timings of 19 `run`s of 10–455 frames
    ///   (`docs/results.md`, "Time-budget plan"): SIFT 0.02 s an image plus
    ///   0.8 s a megapixel at the SIFT size; matching 5.3e-5 s a pair per
    ///   feature; the mapper 0.19 s an image per 1000 features (sequential
    ///   matching; photo collections matched exhaustively ran 0.06–1.2);
    ///   the undistorter 0.25 s a megapixel of the frames.
    pub fn measured(train: StepRates, cpu_factor: f64) -> Self {
        Rates {
            train,
            mask_s_per_frame: cpu_factor * 0.141,
            mask_s_per_px: cpu_factor * 0.030e-6,
            sift_s_per_image: cpu_factor * 0.02,
            sift_s_per_px: cpu_factor * 0.8e-6,
            match_s_per_pair_feature: cpu_factor * 5.3e-5,
            mapper_s_per_image_kfeature: cpu_factor * 0.19,
            undistort_s_per_px: cpu_factor * 0.25e-6,
            px_per_feature: PX_PER_FEATURE,
            finish_s: 30.0,
            cpu_factor,
        }
    }
}

/// A video's first stream, from ffprobe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VideoInfo {
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    /// Average frame rate, when the container says.
    pub fps: Option<f64>,
}

impl VideoInfo {
    /// Frames extracted at `fps` (`None`: every frame).
    pub fn frames_at(&self, fps: Option<f64>) -> usize {
        match (fps, self.fps) {
            (Some(want), Some(have)) if want > 0.0 && have > 0.0 && want < have => {
                ((self.frames as f64 * want / have).ceil() as usize).max(1)
            }
            _ => self.frames,
        }
    }
}

/// ffprobe beside `ffmpeg` (same folder, or PATH when `ffmpeg` is a bare name).
pub fn ffprobe_for(ffmpeg: &Path) -> PathBuf {
    match ffmpeg.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => dir.join("ffprobe"),
        None => PathBuf::from("ffprobe"),
    }
}

/// Size of the frames extraction writes (a rotated phone video's display
/// orientation, anamorphic pixels widened, as `loader::video` does), frame
/// count (packets counted, so containers without a frame count work too)
/// and frame rate of `video`'s first stream.
pub fn probe_video(ffmpeg: &Path, video: &Path) -> anyhow::Result<VideoInfo> {
    let ffprobe = ffprobe_for(ffmpeg);
    let out = std::process::Command::new(&ffprobe)
        .args([
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-count_packets",
            "-show_entries",
            "stream=width,height,sample_aspect_ratio,avg_frame_rate,nb_read_packets:stream_side_data=rotation:stream_tags=rotate",
            "-of",
            "default=noprint_wrappers=1",
        ])
        .arg(video)
        .output()
        .map_err(|e| {
            anyhow::anyhow!(
                "{}: cannot run ({e}); apt-get install -y ffmpeg",
                ffprobe.display()
            )
        })?;
    let text = String::from_utf8_lossy(&out.stdout);
    let field = |k: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(k)?.strip_prefix('='))
            .map(str::trim)
    };
    let num = |k: &str| field(k).and_then(|v| v.parse::<u64>().ok());
    let fps = field("avg_frame_rate").and_then(|r| loader::video::ffprobe_ratio(r, '/'));
    match (num("width"), num("height"), num("nb_read_packets")) {
        (Some(w), Some(h), Some(n)) if out.status.success() && w > 0 && h > 0 && n > 0 => {
            let sar =
                field("sample_aspect_ratio").and_then(|r| loader::video::ffprobe_ratio(r, ':'));
            let w = match sar {
                Some(r) => ((w as f64 * r).round() as u64).max(1),
                None => w,
            };
            // ffmpeg turns the frames upright: a quarter turn swaps the sides.
            let quarter = ["rotation", "TAG:rotate"].iter().any(|k| {
                field(k)
                    .and_then(|v| v.parse::<f64>().ok())
                    .is_some_and(|deg| (deg.abs() / 90.0).round() as i64 % 2 == 1)
            });
            let (w, h) = if quarter { (h, w) } else { (w, h) };
            Ok(VideoInfo {
                width: w as u32,
                height: h as u32,
                frames: n as usize,
                fps,
            })
        }
        _ => {
            let why = String::from_utf8_lossy(&out.stderr);
            let why = why.split_whitespace().collect::<Vec<_>>().join(" ");
            if why.is_empty() {
                anyhow::bail!("{}: the file has no video stream", video.display())
            }
            anyhow::bail!("{}: ffprobe found no video stream ({why})", video.display())
        }
    }
}

/// Frame count and size (of the first image) of a scene folder's `images/`.
pub fn probe_scene(scene: &Path) -> anyhow::Result<(usize, u32, u32)> {
    let images = scene.join("images");
    let names = loader::scene::list_images(&images)?;
    let first = names
        .first()
        .ok_or_else(|| anyhow::anyhow!("{}: no images", images.display()))?;
    let (w, h) = image::image_dimensions(images.join(first))
        .map_err(|e| anyhow::anyhow!("{}: cannot read ({e})", images.join(first).display()))?;
    Ok((names.len(), w, h))
}

/// What the planner plans for.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Input {
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    /// Sequential matching overlap that will be used.
    pub overlap: u32,
    /// COLMAP matches every pair (photo collections) instead of each frame
    /// with the next `overlap`.
    #[serde(default)]
    pub exhaustive: bool,
    /// Models trained at the planned resolution and steps: 2 with the
    /// unmasked baseline, else 1.
    pub trainings: usize,
    /// The RoMo mask stage runs (false under `--no-masks`).
    pub masks: bool,
    /// A video's frame rate when the planner may extract fewer frames
    /// (`None`: a scene folder, or `--fps` given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
}

/// Values the user set; `None` = plan it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Fixed {
    pub steps: Option<usize>,
    pub downscale: Option<u32>,
    pub pose_stride: Option<usize>,
    pub pose_features: Option<u32>,
    pub pose_max_image_size: Option<u32>,
}

/// The plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub budget_s: f64,
    /// Frames the stages see (after `frame_step`).
    pub frames: usize,
    /// Every `frame_step`-th video frame is extracted (1: all).
    #[serde(default = "one")]
    pub frame_step: usize,
    /// The extraction frame rate that gives it (`None`: the video's own).
    #[serde(default)]
    pub extract_fps: Option<f64>,
    pub pose_stride: usize,
    pub pose_max_image_size: u32,
    pub pose_features: u32,
    pub downscale: u32,
    pub train_width: u32,
    pub train_height: u32,
    pub steps: usize,
    /// Models trained with those steps (2: masked and the unmasked baseline).
    #[serde(default = "one")]
    pub trainings: usize,
    /// The RoMo mask stage runs.
    #[serde(default = "yes")]
    pub masks: bool,
    /// Estimated seconds per stage: mask, pose, train (all models), finish.
    pub mask_s: f64,
    pub pose_s: f64,
    pub train_s: f64,
    pub finish_s: f64,
    /// Splats the training estimate assumes on average ([`mean_splats`]).
    #[serde(default)]
    pub mean_splats: f64,
    /// False when `--steps` and `--downscale` were both given and the
    /// training rate was not probed (`train_s` is then 0).
    #[serde(default = "yes")]
    pub train_estimated: bool,
    /// [`Rates::cpu_factor`] of the rates the plan was made with.
    #[serde(default = "one_f64")]
    pub cpu_factor: f64,
    /// [`Rates::px_per_feature`] of the rates the plan was made with.
    #[serde(default = "assumed_px_per_feature")]
    pub px_per_feature: f64,
    /// SIFT features an image the COLMAP estimate expects.
    #[serde(default)]
    pub sift_features: f64,
}

fn assumed_px_per_feature() -> f64 {
    PX_PER_FEATURE
}

/// 2 → "2nd", 3 → "3rd", 11 → "11th", 21 → "21st".
fn ordinal(n: usize) -> String {
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

fn one_f64() -> f64 {
    1.0
}

fn yes() -> bool {
    true
}

fn one() -> usize {
    1
}

impl Plan {
    /// Total estimate, seconds.
    pub fn total_s(&self) -> f64 {
        self.mask_s + self.pose_s + self.train_s + self.finish_s
    }

    /// Human lines, e.g. `training: 240×135, 3000 steps, ≈ 9 min`.
    pub fn lines(&self) -> Vec<String> {
        let m = |s: f64| format!("≈ {:.1} min", s / 60.0);
        let posed = self.frames.div_ceil(self.pose_stride);
        vec![
            if self.masks && self.frame_step > 1 {
                format!(
                    "masks: {} frames (every {} of the video's, extracted at {:.2} fps), {}",
                    self.frames,
                    ordinal(self.frame_step),
                    self.extract_fps.unwrap_or(0.0),
                    m(self.mask_s)
                )
            } else if self.masks {
                format!("masks: {} frames, {}", self.frames, m(self.mask_s))
            } else {
                "masks: none (--no-masks)".into()
            },
            format!(
                "COLMAP: {posed} frames (stride {}), SIFT ≤ {} px, {} features (≈ {:.0} an image, one per {:.0} px), {}",
                self.pose_stride,
                self.pose_max_image_size,
                self.pose_features,
                self.sift_features,
                self.px_per_feature,
                m(self.pose_s)
            ),
            format!(
                "training: {}×{} (downscale {}), {} steps{}, {}",
                self.train_width,
                self.train_height,
                self.downscale,
                self.steps,
                if self.trainings > 1 {
                    " each, masked and an unmasked baseline"
                } else {
                    ""
                },
                if self.train_estimated {
                    format!(
                        "{} (at ≈ {:.0}k splats on average)",
                        m(self.train_s),
                        self.mean_splats / 1000.0
                    )
                } else {
                    "set by --steps and --downscale (not estimated)".into()
                }
            ),
            format!(
                "CPU: the flow probe ran at {:.2}× the development machine's time (mask and COLMAP estimates scaled)",
                self.cpu_factor
            ),
            format!(
                "total {} of the {:.0}-minute budget{}",
                m(self.total_s()),
                self.budget_s / 60.0,
                if self.total_s() > self.budget_s * 1.01 {
                    " (over budget: set values take precedence)"
                } else {
                    ""
                }
            ),
        ]
    }
}

/// COLMAP tiers, best first: (max image size, features). The first two are
/// `colmap automatic_reconstructor`'s medium and low quality.
const POSE_TIERS: [(u32, u32); 4] = [(1600, 4096), (1000, 2048), (640, 1024), (400, 512)];

/// Pixels per SIFT feature assumed when the SIFT probe cannot run: about
/// the densest of the 19 runs of [`Rates::measured`] (133–294).
pub const PX_PER_FEATURE: f64 = 150.0;

/// Frames [`probe_px_per_feature`] reads, spread over the input.
pub const FEATURE_PROBE_FRAMES: usize = 3;

/// The SIFT probe's feature cap: above every tier's, so that it measures the
/// frames' own density (a tier's cap is applied in the estimate).
const FEATURE_PROBE_CAP: u32 = 16_384;

/// Long side COLMAP's SIFT would see at the first tier (or at the size the
/// user set): the size [`probe_px_per_feature`] runs at.
pub fn probe_sift_size(width: u32, height: u32, fixed: &Fixed) -> u32 {
    fixed
        .pose_max_image_size
        .unwrap_or(POSE_TIERS[0].0)
        .min(width.max(height))
}

/// Pixels per SIFT feature on `images` with the long side at most `size`:
/// `colmap feature_extractor` (CPU, no masks, as the pose stage runs it) on
/// them in a temporary folder, the keypoints read back from its database.
/// Without masks it counts the features on moving objects too, so the
/// estimate errs long.
pub fn probe_px_per_feature(colmap: &Path, images: &[PathBuf], size: u32) -> anyhow::Result<f64> {
    use anyhow::Context;
    anyhow::ensure!(!images.is_empty(), "no frames to probe SIFT on");
    let dir = tempfile::Builder::new()
        .prefix("romosplat-sift-probe")
        .tempdir()
        .context("temporary folder for the SIFT probe")?;
    let folder = dir.path().join("images");
    std::fs::create_dir_all(&folder).with_context(|| folder.display().to_string())?;
    let mut px = 0.0;
    for (i, p) in images.iter().enumerate() {
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("png");
        let to = folder.join(format!("{i:03}.{ext}"));
        std::fs::copy(p, &to).with_context(|| format!("{}: cannot copy", p.display()))?;
        let (w, h) = image::image_dimensions(p)
            .map_err(|e| anyhow::anyhow!("{}: cannot read ({e})", p.display()))?;
        let s = (f64::from(size) / f64::from(w.max(h))).min(1.0);
        px += f64::from(w) * f64::from(h) * s * s;
    }
    let db = dir.path().join("database.db");
    let path = |p: &Path| p.to_string_lossy().into_owned();
    let args: Vec<String> = [
        ("database_path", path(&db)),
        ("image_path", path(&folder)),
        ("SiftExtraction.use_gpu", "0".into()),
        ("SiftExtraction.max_image_size", size.to_string()),
        (
            "SiftExtraction.max_num_features",
            FEATURE_PROBE_CAP.to_string(),
        ),
    ]
    .into_iter()
    .flat_map(|(k, v)| [format!("--{k}"), v])
    .collect();
    let log = dir.path().join("feature_extractor.log");
    let out = pose::process::run_step(colmap, "feature_extractor", &args, &log, &mut |_| {})?;
    pose::process::require_success("feature_extractor", &out)?;
    let stats = pose::pairs::read_pair_stats(&db)?;
    anyhow::ensure!(
        stats.images == images.len(),
        "COLMAP read {} of the {} probe frames ({})",
        stats.images,
        images.len(),
        pose::process::log_tail(&log, 3)
    );
    Ok(px / stats.keypoints.max(1) as f64)
}

/// Pixels of a frame at SIFT's long side `size`, and the features an image
/// COLMAP is expected to find there (at most `features`).
fn sift_image(r: &Rates, inp: &Input, size: u32, features: u32) -> (f64, f64) {
    let long = f64::from(inp.width.max(inp.height));
    let s = (f64::from(size) / long).min(1.0);
    let px = f64::from(inp.width) * f64::from(inp.height) * s * s;
    (px, f64::from(features).min(px / r.px_per_feature.max(1.0)))
}

fn pose_seconds(r: &Rates, inp: &Input, stride: usize, size: u32, features: u32) -> f64 {
    let n = inp.frames.div_ceil(stride.max(1)) as f64;
    let frame_px = f64::from(inp.width) * f64::from(inp.height);
    let (px, feats) = sift_image(r, inp, size, features);
    let pairs = if inp.exhaustive {
        n * (n - 1.0) / 2.0
    } else {
        n * f64::from(inp.overlap).min(n - 1.0).max(0.0)
    };
    n * (r.sift_s_per_image + px * r.sift_s_per_px)
        + pairs * feats * r.match_s_per_pair_feature
        + n * feats / 1000.0 * r.mapper_s_per_image_kfeature
        + n * frame_px * r.undistort_s_per_px
}

/// The splat count a `run` training of `steps` steps averages over its
/// steps: [`INIT_SPLATS`] times [`DENSIFY_GROWTH`] per densification round of
/// its schedule (`short_schedule`), capped at the schedule's maximum.
pub fn mean_splats(steps: usize) -> f64 {
    let steps = steps.max(1);
    let o = crate::cmd::train_common::short_schedule(steps as u32, true).strategy;
    let (from, every, until) = (
        o.densify_from as usize,
        (o.densify_every as usize).max(1),
        o.densify_until as usize,
    );
    let cap = o.max_splats as f64;
    let (mut n, mut at, mut sum) = (INIT_SPLATS.min(cap), 0usize, 0.0);
    let mut round = from.max(1);
    while round < steps && round <= until {
        sum += n * (round - at) as f64;
        at = round;
        n = (n * DENSIFY_GROWTH).min(cap);
        round += every;
    }
    sum += n * (steps - at) as f64;
    sum / steps as f64
}

/// Seconds `steps` training steps take at `w`×`h` (one model).
fn train_seconds(r: &Rates, w: u32, h: u32, steps: usize) -> f64 {
    let step = r
        .train
        .step(f64::from(w) * f64::from(h), mean_splats(steps));
    steps as f64 * SCENE_STEP_FACTOR * step
}

/// The most steps (up to `limit`) whose training at `w`×`h` fits `seconds`.
fn steps_fitting(r: &Rates, w: u32, h: u32, seconds: f64, limit: usize) -> usize {
    let (mut lo, mut hi) = (0usize, limit);
    while lo < hi {
        let mid = (lo + hi).div_ceil(2);
        if train_seconds(r, w, h, mid) <= seconds {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    lo
}

fn scaled(v: u32, d: u32) -> u32 {
    v.div_ceil(d).max(1)
}

/// Plan for `input` within `budget_s` seconds. Pure.
pub fn plan(input: &Input, rates: &Rates, budget_s: f64, fixed: &Fixed) -> Plan {
    let per_frame = rates.mask_s_per_frame
        + f64::from(input.width) * f64::from(input.height) * rates.mask_s_per_px;
    // A long video: every k-th frame, the smallest k whose masks fit.
    let mut frame_step = 1;
    if input.masks && input.fps.is_some_and(|f| f > 0.0) {
        while input.frames.div_ceil(frame_step) > 2
            && input.frames.div_ceil(frame_step) as f64 * per_frame > MASK_SHARE * budget_s
        {
            frame_step += 1;
        }
    }
    let extract_fps = input
        .fps
        .filter(|_| frame_step > 1)
        .map(|f| f / frame_step as f64);
    let input = &Input {
        frames: input.frames.div_ceil(frame_step),
        ..*input
    };
    let mask_s = if input.masks {
        input.frames as f64 * per_frame
    } else {
        0.0
    };
    // COLMAP.
    let long = input.width.max(input.height);
    let pose_budget = POSE_SHARE * budget_s;
    let mut choice = None;
    'tiers: for (size, feats) in POSE_TIERS {
        let size = fixed.pose_max_image_size.unwrap_or(size.min(long));
        let feats = fixed.pose_features.unwrap_or(feats);
        let strides: Vec<usize> = match fixed.pose_stride {
            Some(s) => vec![s],
            None => vec![1],
        };
        for stride in strides {
            let t = pose_seconds(rates, input, stride, size, feats);
            if t <= pose_budget {
                choice = Some((stride, size, feats, t));
                break 'tiers;
            }
        }
    }
    let (pose_stride, pose_max_image_size, pose_features, pose_s) = choice.unwrap_or_else(|| {
        // Even the smallest tier is too slow: subsample frames.
        let (size, feats) = POSE_TIERS[POSE_TIERS.len() - 1];
        let size = fixed.pose_max_image_size.unwrap_or(size.min(long));
        let feats = fixed.pose_features.unwrap_or(feats);
        let mut stride = fixed.pose_stride.unwrap_or(1);
        if fixed.pose_stride.is_none() {
            while stride < input.frames / 2
                && pose_seconds(rates, input, stride, size, feats) > pose_budget
            {
                stride += 1;
            }
        }
        (
            stride,
            size,
            feats,
            pose_seconds(rates, input, stride, size, feats),
        )
    });
    // Training.
    let finish_s = rates.finish_s;
    let left = (budget_s - mask_s - pose_s - finish_s).max(0.0);
    let max_d = (input.width.min(input.height) / MIN_TRAIN_SIDE).max(1);
    let downscales: Vec<u32> = match fixed.downscale {
        Some(d) => vec![d],
        None => (1..=max_d).collect(),
    };
    let trainings = input.trainings.max(1);
    let limit = fixed.steps.unwrap_or(0).max(MAX_STEPS);
    let fit = |d: u32| {
        let (w, h) = (scaled(input.width, d), scaled(input.height, d));
        steps_fitting(rates, w, h, left / trainings as f64, limit)
    };
    let (downscale, steps) = match fixed.steps {
        Some(steps) => {
            // Steps set: the finest downscale whose steps fit.
            let d = downscales
                .iter()
                .copied()
                .find(|&d| fit(d) >= steps)
                .unwrap_or(*downscales.last().unwrap_or(&1));
            (d, steps)
        }
        None => match downscales.iter().copied().find(|&d| fit(d) >= TARGET_STEPS) {
            Some(d) => (d, fit(d).min(MAX_STEPS)),
            None => {
                let d = *downscales.last().unwrap_or(&1);
                (d, fit(d).max(MIN_STEPS))
            }
        },
    };
    // Round planned steps down to a hundred.
    let steps = if fixed.steps.is_none() && steps >= 200 {
        steps / 100 * 100
    } else {
        steps
    };
    let (tw, th) = (
        scaled(input.width, downscale),
        scaled(input.height, downscale),
    );
    Plan {
        budget_s,
        frames: input.frames,
        frame_step,
        extract_fps,
        pose_stride,
        pose_max_image_size,
        pose_features,
        downscale,
        train_width: tw,
        train_height: th,
        steps,
        trainings,
        masks: input.masks,
        mask_s,
        pose_s,
        train_s: trainings as f64 * train_seconds(rates, tw, th, steps),
        mean_splats: mean_splats(steps),
        finish_s,
        train_estimated: true,
        cpu_factor: rates.cpu_factor,
        px_per_feature: rates.px_per_feature,
        sift_features: sift_image(rates, input, pose_max_image_size, pose_features).1,
    }
}

/// Median seconds of one training step on `backend` at `width`×`height`
/// with `splats` synthetic splats (3 warm-up steps, then `steps` timed).
pub fn probe_step_seconds(
    backend: &mut dyn splat::backend::TrainBackend,
    width: u32,
    height: u32,
    splats: usize,
    steps: usize,
) -> anyhow::Result<f64> {
    use splat::backend::{LossConfig, StepInput};
    use splat::train::TrainOptions;
    use splat::types::{RenderCamera, RenderOptions, Splats};
    let coeffs = 16;
    let mut s = Splats::with_capacity(splats, 3);
    // A deterministic low-discrepancy cloud filling the view at depth 2–6.
    for i in 0..splats {
        let f = i as f32;
        let (u, v, w) = (
            (f * 0.618_034).fract(),
            (f * 0.754_878).fract(),
            (f * 0.569_840).fract(),
        );
        let z = 2.0 + 4.0 * w;
        s.means.push([(u - 0.5) * z * 1.2, (v - 0.5) * z * 0.8, z]);
        s.log_scales.push([(-4.0f32); 3]);
        s.rotations.push([1.0, 0.0, 0.0, 0.0]);
        s.opacity_logits.push(0.0);
        s.sh[i * coeffs * 3] = u - 0.5;
        s.sh[i * coeffs * 3 + 1] = v - 0.5;
        s.sh[i * coeffs * 3 + 2] = w - 0.5;
    }
    let camera = RenderCamera::at_origin(width, height, width as f32);
    let target: Vec<f32> = (0..(width * height * 3) as usize)
        .map(|i| ((i * 7919) % 255) as f32 / 255.0)
        .collect();
    let start = splat::train::fresh_start(s);
    backend.upload(&start.splats, &start.adam)?;
    let opts = TrainOptions::default();
    let mut times = Vec::new();
    for k in 0..steps + 3 {
        let input = StepInput {
            camera: &camera,
            target: &target,
            mask: None,
            view_id: Some(0),
            lr: opts.learning_rates(k as u32, 4.0),
            loss: LossConfig::default(),
            render: RenderOptions {
                sh_degree: 3,
                ..Default::default()
            },
        };
        let t = std::time::Instant::now();
        backend.step(&input)?;
        if k >= 3 {
            times.push(t.elapsed().as_secs_f64());
        }
    }
    times.sort_by(f64::total_cmp);
    Ok(times[times.len() / 2])
}

/// Fit [`StepRates`] from probes at two sizes of a `w`×`h` frame (longer
/// side 160 and 480 px, never above the frame's own) and the two
/// [`PROBE_SPLATS`] counts: exact through the four points, slopes clamped at
/// zero.
pub fn probe_train_rates(
    backend: &mut dyn splat::backend::TrainBackend,
    w: u32,
    h: u32,
) -> anyhow::Result<StepRates> {
    let size = |long: u32| {
        let s = f64::from(long) / f64::from(w.max(h));
        (
            ((f64::from(w) * s).round() as u32).max(8),
            ((f64::from(h) * s).round() as u32).max(8),
        )
    };
    let long = w.max(h);
    let (w0, h0) = size(long.min(160));
    let (w1, h1) = size(long.min(480));
    let mut at = |w: u32, h: u32| -> anyhow::Result<[f64; 2]> {
        Ok([
            probe_step_seconds(backend, w, h, PROBE_SPLATS[0], 5)?,
            probe_step_seconds(backend, w, h, PROBE_SPLATS[1], 5)?,
        ])
    };
    let small = at(w0, h0)?;
    let p0 = f64::from(w0 * h0);
    if w0 * h0 >= w1 * h1 {
        return Ok(fit_step_rates([p0, p0], [small, small]));
    }
    let large = at(w1, h1)?;
    Ok(fit_step_rates([p0, f64::from(w1 * h1)], [small, large]))
}

/// [`StepRates`] through step times `t[i][j]` at `pixels[i]` and
/// [`PROBE_SPLATS`]`[j]` (bilinear; the slopes clamped at zero, so noise
/// never makes more splats or pixels cheaper; equal `pixels`: no pixel
/// terms).
pub fn fit_step_rates(pixels: [f64; 2], t: [[f64; 2]; 2]) -> StepRates {
    let [n0, n1] = PROBE_SPLATS.map(|n| n as f64);
    // Per-splat slope and intercept at zero splats, at each size.
    let line = |t: [f64; 2]| {
        let slope = ((t[1] - t[0]) / (n1 - n0)).max(0.0);
        (slope, (t[0] - slope * n0).max(0.0))
    };
    let ((s0, i0), (s1, i1)) = (line(t[0]), line(t[1]));
    let [p0, p1] = pixels;
    if p1 <= p0 {
        return StepRates {
            a: i0,
            per_splat: s0,
            ..Default::default()
        };
    }
    let per_px_splat = ((s1 - s0) / (p1 - p0)).max(0.0);
    let per_px = ((i1 - i0) / (p1 - p0)).max(0.0);
    StepRates {
        a: (i0 - per_px * p0).max(0.0),
        per_px,
        per_splat: s0 - per_px_splat * p0,
        per_px_splat,
    }
}

/// Size of the CPU probe's frames: the mask stage's flow resolution for
/// 16:9 video (its 256-px grid at flow scale 2).
const CPU_PROBE_SIZE: (usize, usize) = (512, 288);
/// Seconds of [`probe_cpu_factor`]'s fastest [`cpu_probe_once`] on the
/// 2-core development machine, the one the mask and COLMAP rates of
/// [`Rates::measured`] were measured on: 0.078–0.084 over 8 plans, idle
/// (the median of 7 runs spread 0.079–0.098 over the same plans).
pub const CPU_PROBE_REFERENCE_S: f64 = 0.08;
/// Timed runs of the CPU probe.
const CPU_PROBE_RUNS: usize = 7;

/// One forward and one backward DIS flow (the mask stage's preset) between
/// two synthetic textured frames a few pixels apart, seconds.
fn cpu_probe_once(a: &romo::plane::Plane, b: &romo::plane::Plane) -> anyhow::Result<f64> {
    let dis = romo::flow::dis::Dis::new(romo::flow::dis::DisOptions::masks());
    let t = std::time::Instant::now();
    dis.compute(a, b)?;
    dis.compute(b, a)?;
    Ok(t.elapsed().as_secs_f64())
}

/// A smooth, non-repeating texture (sum of sines at unrelated frequencies)
/// shifted by (`dx`, `dy`) pixels.
fn probe_frame(dx: f32, dy: f32) -> romo::plane::Plane {
    let (w, h) = CPU_PROBE_SIZE;
    romo::plane::Plane::from_fn(w, h, |x, y| {
        let (x, y) = (x as f32 - dx, y as f32 - dy);
        0.5 + 0.2 * (0.11 * x + 0.07 * y).sin()
            + 0.15 * (0.23 * x - 0.17 * y + 1.0).sin()
            + 0.1 * (0.051 * x * 0.9 + 0.37 * y).sin() * (0.029 * y).cos()
    })
}

/// How long this CPU takes for the mask stage's optical flow on a fixed
/// synthetic pair, over the development machine's time
/// ([`CPU_PROBE_REFERENCE_S`]): the fastest of [`CPU_PROBE_RUNS`] timed
/// runs after one warm-up (other work only ever adds time), clamped to
/// [0.1, 20]. The mask stage and COLMAP are CPU-bound, so their measured
/// rates scale with it. Takes about 0.6 s here.
pub fn probe_cpu_factor() -> anyhow::Result<f64> {
    let (a, b) = (probe_frame(0.0, 0.0), probe_frame(2.5, 1.5));
    cpu_probe_once(&a, &b)?;
    let mut least = f64::INFINITY;
    for _ in 0..CPU_PROBE_RUNS {
        least = least.min(cpu_probe_once(&a, &b)?);
    }
    Ok((least / CPU_PROBE_REFERENCE_S).clamp(0.1, 20.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn video() -> Input {
        Input {
            frames: 65,
            width: 854,
            height: 480,
            overlap: 10,
            exhaustive: false,
            trainings: 2,
            masks: true,
            fps: Some(30.0),
        }
    }

    /// Every planned value set (500 steps at downscale 4, COLMAP at 640 px
    /// with 1024 features on every frame).
    fn all_set() -> Fixed {
        Fixed {
            steps: Some(500),
            downscale: Some(4),
            pose_stride: Some(1),
            pose_features: Some(1024),
            pose_max_image_size: Some(640),
        }
    }

    /// 0.05 s a step plus 0.5 µs a pixel: 240×135 → 0.066 s a step.
    fn rates() -> Rates {
        Rates::measured(StepRates::flat(0.05, 0.5e-6), 1.0)
    }

    /// The plan sees the frames' size as extraction writes them: a phone
    /// video stored sideways with a rotation tag, and anamorphic pixels.
    #[test]
    fn video_size_is_the_extracted_frames_size() {
        if !loader::video::ffmpeg_available() {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI is set but ffmpeg is missing"
            );
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        for (name, filters, extra) in [
            ("plain.mp4", "null", &[][..]),
            ("rotated.mp4", "null", &["-metadata:s:v:0", "rotate=90"][..]),
            ("anamorphic.mp4", "setsar=4/3", &[][..]),
        ] {
            let v = dir.path().join(name);
            let st = std::process::Command::new("ffmpeg")
                .args(["-hide_banner", "-loglevel", "error", "-nostdin", "-y"])
                .args(["-f", "lavfi", "-i", "testsrc=size=64x48:rate=10:duration=1"])
                .args(["-vf", filters, "-c:v", "mpeg4"])
                .args(extra)
                .arg(&v)
                .status()
                .unwrap();
            assert!(st.success());
            let info = probe_video(Path::new("ffmpeg"), &v).unwrap();
            let frames =
                loader::video::extract_frames(&v, dir.path().join(name).with_extension(""), None)
                    .unwrap()
                    .frames;
            assert_eq!(info.frames, frames.len(), "{name}");
            assert_eq!(
                (info.width, info.height),
                image::image_dimensions(&frames[0]).unwrap(),
                "{name}"
            );
            // The SIFT probe's frames are decoded the same way.
            let sampled = dir.path().join(format!("{name}.sampled"));
            std::fs::create_dir_all(&sampled).unwrap();
            let at = loader::video::extract_frames_at("ffmpeg", &v, &[0.5], &sampled).unwrap();
            assert_eq!(
                image::image_dimensions(&at[0]).unwrap(),
                (info.width, info.height),
                "{name}"
            );
        }
    }

    #[test]
    fn plan_fits_the_budget() {
        for minutes in [5.0, 10.0, 20.0, 60.0] {
            let b = minutes * 60.0;
            let p = plan(&video(), &rates(), b, &Fixed::default());
            assert!(p.total_s() <= b, "{minutes} min: {:?}", p.lines());
            assert!(p.steps >= MIN_STEPS);
            assert!(p.pose_s <= POSE_SHARE * b + 1e-9, "{p:?}");
        }
    }

    #[test]
    fn the_baseline_shares_the_training_time() {
        let one = Input {
            trainings: 1,
            ..video()
        };
        let alone = plan(&one, &rates(), 1200.0, &Fixed::default());
        let both = plan(&video(), &rates(), 1200.0, &Fixed::default());
        assert!(both.total_s() <= 1200.0, "{:?}", both.lines());
        // The same per-step time for both models, half the training budget
        // each (what masks, COLMAP and the finish leave).
        let work = |p: &Plan| train_seconds(&rates(), p.train_width, p.train_height, p.steps);
        let left = 1200.0 - both.mask_s - both.pose_s - both.finish_s;
        assert!(work(&both) <= left / 2.0 + 1e-9, "{alone:?} {both:?}");
        assert!(alone.train_s <= left + 1e-9);
        assert!((both.train_s - 2.0 * work(&both)).abs() < 1e-6);
        // Set steps and size: the estimate doubles.
        let f = Fixed {
            steps: Some(1000),
            downscale: Some(4),
            ..Fixed::default()
        };
        let (a, b) = (
            plan(&one, &rates(), 1200.0, &f),
            plan(&video(), &rates(), 1200.0, &f),
        );
        assert_eq!((a.steps, b.steps), (1000, 1000));
        assert!((b.train_s - 2.0 * a.train_s).abs() < 1e-6);
        assert!(both.lines()[2].contains("each, masked and an unmasked baseline"));
        assert!(!alone.lines()[2].contains("baseline"));
    }

    #[test]
    fn no_masks_plans_no_mask_time() {
        let bare = Input {
            masks: false,
            trainings: 1,
            ..video()
        };
        let masked = Input {
            trainings: 1,
            ..video()
        };
        let (p, q) = (
            plan(&bare, &rates(), 1200.0, &Fixed::default()),
            plan(&masked, &rates(), 1200.0, &Fixed::default()),
        );
        assert_eq!(p.mask_s, 0.0);
        assert!(q.mask_s > 0.0);
        assert_eq!(p.lines()[0], "masks: none (--no-masks)");
        // The time the masks would take is free for training.
        assert!(p.train_s >= q.train_s, "{p:?} {q:?}");
        assert!(p.total_s() <= 1200.0);
    }

    #[test]
    fn more_budget_buys_quality() {
        let small = plan(&video(), &rates(), 600.0, &Fixed::default());
        let large = plan(&video(), &rates(), 3600.0, &Fixed::default());
        let px = |p: &Plan| u64::from(p.train_width * p.train_height) * p.steps as u64;
        assert!(px(&large) > px(&small), "{small:?} {large:?}");
        assert!(large.pose_max_image_size >= small.pose_max_image_size);
    }

    #[test]
    fn a_slow_adapter_gets_coarser_training() {
        let fast = plan(&video(), &rates(), 1200.0, &Fixed::default());
        let slow = plan(
            &video(),
            &Rates::measured(StepRates::flat(0.2, 4e-6), 1.0),
            1200.0,
            &Fixed::default(),
        );
        assert!(slow.downscale > fast.downscale, "{fast:?} {slow:?}");
        assert!(slow.total_s() <= 1200.0);
    }

    #[test]
    fn set_values_win() {
        let f = Fixed {
            steps: Some(123),
            downscale: Some(3),
            pose_stride: Some(2),
            pose_features: Some(777),
            pose_max_image_size: Some(500),
        };
        let p = plan(&video(), &rates(), 1200.0, &f);
        assert_eq!(
            (
                p.steps,
                p.downscale,
                p.pose_stride,
                p.pose_features,
                p.pose_max_image_size
            ),
            (123, 3, 2, 777, 500)
        );
        assert_eq!((p.train_width, p.train_height), (285, 160));
        // Set values may exceed the budget; the plan says so.
        let over = plan(
            &video(),
            &rates(),
            60.0,
            &Fixed {
                steps: Some(7000),
                downscale: Some(1),
                ..Fixed::default()
            },
        );
        assert!(over.total_s() > 60.0);
        assert!(
            over.lines()[4].contains("over budget"),
            "{:?}",
            over.lines()
        );
    }

    #[test]
    fn a_slower_cpu_scales_the_mask_and_colmap_estimates() {
        let f = all_set();
        let here = plan(&video(), &rates(), 1200.0, &f);
        let slow = plan(
            &video(),
            &Rates::measured(StepRates::flat(0.05, 0.5e-6), 3.0),
            1200.0,
            &f,
        );
        assert!((slow.mask_s / here.mask_s - 3.0).abs() < 1e-9);
        assert!((slow.pose_s / here.pose_s - 3.0).abs() < 1e-9);
        assert_eq!(slow.train_s, here.train_s);
        assert!(slow.lines()[3].contains("3.00×"), "{:?}", slow.lines());
        // A slow CPU makes the planner cheapen COLMAP to stay in budget.
        let auto_here = plan(&video(), &rates(), 900.0, &Fixed::default());
        let auto_slow = plan(
            &video(),
            &Rates::measured(StepRates::flat(0.05, 0.5e-6), 3.0),
            900.0,
            &Fixed::default(),
        );
        assert!(
            auto_slow.pose_max_image_size < auto_here.pose_max_image_size
                || auto_slow.pose_stride > auto_here.pose_stride,
            "{auto_here:?} {auto_slow:?}"
        );
    }

    #[test]
    fn the_cpu_probe_times_a_flow_that_recovers_its_shift() {
        let (a, b) = (probe_frame(0.0, 0.0), probe_frame(2.5, 1.5));
        let dis = romo::flow::dis::Dis::new(romo::flow::dis::DisOptions::masks());
        let f = dis.compute(&a, &b).unwrap();
        // Median flow over the interior (borders see texture enter / leave).
        let (mut u, mut v) = (Vec::new(), Vec::new());
        for y in 20..f.h() - 20 {
            for x in 20..f.w() - 20 {
                let (fu, fv) = f.sample(x as f32, y as f32);
                u.push(fu);
                v.push(fv);
            }
        }
        u.sort_by(f32::total_cmp);
        v.sort_by(f32::total_cmp);
        let (mu, mv) = (u[u.len() / 2], v[v.len() / 2]);
        assert!(
            (mu - 2.5).abs() < 0.1 && (mv - 1.5).abs() < 0.1,
            "{mu} {mv}"
        );
        let k = probe_cpu_factor().unwrap();
        assert!(k.is_finite() && (0.1..=20.0).contains(&k), "{k}");
    }

    #[test]
    fn the_mean_splat_count_follows_the_schedules_densification() {
        // 2000 steps: a round every 250 steps from 250 to 1500, step by step.
        let (mut n, mut sum) = (INIT_SPLATS, 0.0);
        for step in 0..2000 {
            if (250..=1500).contains(&step) && step % 250 == 0 {
                n *= DENSIFY_GROWTH;
            }
            sum += n;
        }
        let m = mean_splats(2000);
        assert!((m - sum / 2000.0).abs() < 1e-6 * m, "{m} {}", sum / 2000.0);
        // lady-running's runs averaged 13 391 splats over 2000 steps (4 864 →
        // 21 565) and 25 015 over 2700 (4 836 → 48 580): covered, within 25%.
        for (steps, seen) in [(2000, 13_391.0), (2700, 25_015.0)] {
            let r = mean_splats(steps) / seen;
            assert!((1.0..1.25).contains(&r), "{steps}: {r}");
        }
        // Longer schedules densify more rounds, up to the cap.
        let long = mean_splats(7000);
        assert!(long > m && long <= 60_000.0, "{long}");
        assert!(mean_splats(1) >= INIT_SPLATS.min(20_000.0) - 1e-9);
    }

    #[test]
    fn the_step_fit_goes_through_its_four_probes() {
        let truth = StepRates {
            a: 0.03,
            per_px: 2e-7,
            per_splat: 5e-6,
            per_px_splat: 1e-11,
        };
        let px = [160.0 * 90.0, 480.0 * 270.0];
        let t = px.map(|p| PROBE_SPLATS.map(|n| truth.step(p, n as f64)));
        let fit = fit_step_rates(px, t);
        for (got, want) in [
            (fit.a, truth.a),
            (fit.per_px, truth.per_px),
            (fit.per_splat, truth.per_splat),
            (fit.per_px_splat, truth.per_px_splat),
        ] {
            assert!(
                (got - want).abs() <= 1e-9 * want.abs().max(1e-12),
                "{fit:?}"
            );
        }
        // Noise that makes more splats look cheaper gives a flat step.
        let noisy = fit_step_rates(px, [[0.2, 0.1], [0.5, 0.4]]);
        assert_eq!((noisy.per_splat, noisy.per_px_splat), (0.0, 0.0));
        assert!(noisy.step(px[0], 1e6) > 0.0);
        // One size only (a frame at most 160 px long): no pixel terms.
        let one = fit_step_rates([px[0]; 2], [t[0], t[0]]);
        assert_eq!((one.per_px, one.per_px_splat), (0.0, 0.0));
        assert!((one.step(px[0], 15_000.0) - truth.step(px[0], 15_000.0)).abs() < 1e-9);
    }

    #[test]
    fn training_is_charged_at_the_expected_splat_count() {
        let splats = Rates::measured(
            StepRates {
                a: 0.03,
                per_px: 2e-7,
                per_splat: 5e-6,
                per_px_splat: 1e-11,
            },
            1.0,
        );
        let p = plan(&video(), &splats, 1200.0, &Fixed::default());
        let px = f64::from(p.train_width * p.train_height);
        let step = SCENE_STEP_FACTOR * splats.train.step(px, mean_splats(p.steps));
        let want = 2.0 * p.steps as f64 * step;
        assert!((p.train_s - want).abs() < 1e-6, "{p:?}");
        assert_eq!(p.mean_splats, mean_splats(p.steps));
        assert!(p.total_s() <= 1200.0, "{:?}", p.lines());
        // Steps are the most that fit: a hundred more would not.
        let left = 1200.0 - p.mask_s - p.pose_s - p.finish_s;
        let more = 2.0 * train_seconds(&splats, p.train_width, p.train_height, p.steps + 100);
        assert!(more > left || p.steps >= MAX_STEPS, "{p:?}");
    }

    #[test]
    fn photo_collections_plan_every_pair() {
        let f = all_set();
        let seq = plan(&video(), &rates(), 1e6, &f);
        let all = plan(
            &Input {
                exhaustive: true,
                ..video()
            },
            &rates(),
            1e6,
            &f,
        );
        // 65 frames: 2080 pairs against 650, 1024 features each.
        let extra = (2080.0 - 650.0) * 1024.0 * rates().match_s_per_pair_feature;
        assert!(
            (all.pose_s - seq.pose_s - extra).abs() < 1e-6,
            "{seq:?} {all:?}"
        );
    }

    #[test]
    fn the_colmap_rates_reproduce_a_measured_run() {
        // lady-running, 54 keyframes of 854×480, SIFT ≤ 854 px, 4096
        // features, sequential overlap 10: 91.2 s of COLMAP stages with the
        // CPU probe at 0.92 (`docs/results.md`, "Time-budget plan").
        let f = Fixed {
            steps: Some(100),
            downscale: Some(4),
            pose_stride: Some(1),
            pose_features: Some(4096),
            pose_max_image_size: Some(854),
        };
        let input = Input {
            frames: 54,
            ..video()
        };
        let p = plan(
            &input,
            &Rates::measured(StepRates::default(), 0.92),
            1e6,
            &f,
        );
        assert!((1.0..1.5).contains(&(p.pose_s / 91.2)), "{}", p.pose_s);
        // At the density that run found (2 017 keypoints an image, masked),
        // the estimate is close.
        let found = Rates {
            px_per_feature: 854.0 * 480.0 / 2017.0,
            ..Rates::measured(StepRates::default(), 0.92)
        };
        let p = plan(&input, &found, 1e6, &f);
        assert!((0.85..1.15).contains(&(p.pose_s / 91.2)), "{}", p.pose_s);
        assert!(
            (p.sift_features - 2017.0).abs() < 1.0,
            "{}",
            p.sift_features
        );
    }

    /// Matching and the mapper scale with the features the probe expects,
    /// up to the tier's cap; extraction and undistortion do not.
    #[test]
    fn the_colmap_estimate_follows_the_probed_density() {
        let f = Fixed {
            pose_max_image_size: Some(854),
            pose_features: Some(4096),
            pose_stride: Some(1),
            ..all_set()
        };
        let at = |px_per_feature: f64| {
            let r = Rates {
                px_per_feature,
                ..rates()
            };
            plan(&video(), &r, 1e6, &f)
        };
        let (sparse, dense, capped) = (at(400.0), at(200.0), at(10.0));
        let feats = 854.0 * 480.0 / 400.0;
        assert!((sparse.sift_features - feats).abs() < 1e-6);
        assert!((dense.sift_features - 2.0 * feats).abs() < 1e-6);
        assert_eq!(capped.sift_features, 4096.0);
        let r = rates();
        let n = video().frames as f64;
        let pairs = n * 10.0;
        let per_feature =
            pairs * r.match_s_per_pair_feature + n * r.mapper_s_per_image_kfeature / 1000.0;
        let extra = dense.pose_s - sparse.pose_s;
        assert!((extra - feats * per_feature).abs() < 1e-6, "{extra}");
        let extra = capped.pose_s - sparse.pose_s;
        assert!(
            (extra - (4096.0 - feats) * per_feature).abs() < 1e-6,
            "{extra}"
        );
    }

    /// Frames of `w`×`h`: a smoothed random texture (blocks of a 40th of
    /// the width) over the leftmost `textured` share of the width, flat grey
    /// elsewhere; the same texture at every size.
    fn texture_frames(dir: &Path, w: u32, h: u32, textured: f64) -> Vec<PathBuf> {
        (0..3u64)
            .map(|k| {
                let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ k;
                let mut next = || {
                    state = state
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    (state >> 56) as u8
                };
                // Random blocks, blurred: corners and blobs for SIFT.
                let b = (w / 40).max(1);
                let blocks: Vec<u8> = (0..41 * 41).map(|_| next()).collect();
                let img = image::GrayImage::from_fn(w, h, |x, y| {
                    if f64::from(x) < textured * f64::from(w) {
                        image::Luma([blocks[((y / b) * 41 + x / b) as usize]])
                    } else {
                        image::Luma([128])
                    }
                });
                let p = dir.join(format!("{k}.png"));
                let sigma = 1.5 * w as f32 / 320.0;
                image::imageops::blur(&img, sigma).save(&p).unwrap();
                p
            })
            .collect()
    }

    /// The SIFT probe measures the frames' own density: a quarter of the
    /// texture gives about four times the pixels per feature, and frames at
    /// twice the size probed at the original size (COLMAP scales them down)
    /// give about the same density as the originals.
    #[test]
    fn the_sift_probe_measures_the_frames_density() {
        let colmap = Path::new("colmap");
        if pose::process::colmap_version(colmap).is_err() {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI is set but colmap is missing"
            );
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let (full, quarter, big) = (
            dir.path().join("full"),
            dir.path().join("quarter"),
            dir.path().join("big"),
        );
        for d in [&full, &quarter, &big] {
            std::fs::create_dir_all(d).unwrap();
        }
        let full =
            probe_px_per_feature(colmap, &texture_frames(&full, 320, 240, 1.0), 320).unwrap();
        let quarter =
            probe_px_per_feature(colmap, &texture_frames(&quarter, 320, 240, 0.25), 320).unwrap();
        let big = probe_px_per_feature(colmap, &texture_frames(&big, 640, 480, 1.0), 320).unwrap();
        assert!((20.0..2000.0).contains(&full), "{full}");
        assert!((2.5..6.0).contains(&(quarter / full)), "{full} {quarter}");
        assert!((0.6..1.6).contains(&(big / full)), "{full} {big}");
        // No frames, and a file COLMAP cannot read, are errors.
        assert!(probe_px_per_feature(colmap, &[], 320).is_err());
        let bad = dir.path().join("bad.png");
        std::fs::write(&bad, b"not a png").unwrap();
        assert!(probe_px_per_feature(colmap, &[bad], 320).is_err());
    }

    #[test]
    fn long_videos_are_subsampled_for_colmap() {
        let long = Input {
            frames: 2000,
            ..video()
        };
        let p = plan(&long, &rates(), 1200.0, &Fixed::default());
        assert!(p.pose_stride > 1, "{p:?}");
        assert!(p.pose_s <= POSE_SHARE * 1200.0, "{p:?}");
    }
}

#[cfg(test)]
mod frame_step_tests {
    use super::*;

    fn long(frames: usize, fps: Option<f64>) -> Input {
        Input {
            frames,
            width: 854,
            height: 480,
            overlap: 10,
            exhaustive: false,
            trainings: 2,
            masks: true,
            fps,
        }
    }

    #[test]
    fn a_long_video_is_extracted_at_a_lower_rate_so_its_masks_fit() {
        // 0.153 s a 854×480 frame at factor 1: 3640 frames would take 9.3
        // minutes, over the 7 the masks may have of 20.
        let rates = Rates::measured(StepRates::flat(0.05, 0.5e-6), 1.0);
        let p = plan(&long(3640, Some(30.0)), &rates, 1200.0, &Fixed::default());
        assert!(p.frame_step > 1, "{p:?}");
        assert!(p.mask_s <= MASK_SHARE * 1200.0 + 1e-9, "{p:?}");
        assert_eq!(p.frames, 3640usize.div_ceil(p.frame_step));
        let fps = p.extract_fps.unwrap();
        assert!((fps - 30.0 / p.frame_step as f64).abs() < 1e-9);
        // The smallest step that fits.
        let per_frame = rates.mask_s_per_frame + 854.0 * 480.0 * rates.mask_s_per_px;
        let one_less = 3640usize.div_ceil(p.frame_step - 1) as f64 * per_frame;
        assert!(one_less > MASK_SHARE * 1200.0);
        assert!(
            p.lines()[0].contains(&format!("every {} of", ordinal(p.frame_step))),
            "{:?}",
            p.lines()
        );
        assert_eq!(
            [1, 2, 3, 4, 11, 12, 13, 21, 22, 101].map(ordinal),
            [
                "1st", "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "101st"
            ]
        );
        // The planned frame count is what COLMAP's stride divides.
        assert!(p.pose_s <= POSE_SHARE * 1200.0 + 1e-9, "{p:?}");
    }

    #[test]
    fn the_mask_rate_reproduces_its_two_measurements() {
        // 0.155 s a 854×480 frame with the probe at 1.02, 0.384 s a
        // 3840×2160 frame at 0.95 (`Rates::measured`).
        let per_frame = |factor: f64, w: u32, h: u32| {
            let p = plan(
                &Input {
                    frames: 100,
                    width: w,
                    height: h,
                    fps: None,
                    ..long(100, None)
                },
                &Rates::measured(StepRates::flat(0.05, 0.5e-6), factor),
                1e6,
                &Fixed::default(),
            );
            p.mask_s / 100.0
        };
        assert!((per_frame(1.02, 854, 480) - 0.155).abs() < 0.01);
        assert!((per_frame(0.95, 3840, 2160) - 0.384).abs() < 0.02);
    }

    #[test]
    fn short_videos_scenes_and_set_rates_keep_every_frame() {
        let rates = Rates::measured(StepRates::flat(0.05, 0.5e-6), 1.0);
        for input in [
            long(65, Some(30.0)),
            long(3640, None),
            Input {
                masks: false,
                ..long(3640, Some(30.0))
            },
        ] {
            let p = plan(&input, &rates, 1200.0, &Fixed::default());
            assert_eq!((p.frame_step, p.extract_fps), (1, None), "{input:?}");
            assert_eq!(p.frames, input.frames);
        }
    }
}
