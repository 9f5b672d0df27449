//! A real-image distractor scene in the NeRF On-the-go layout (Ren et al.,
//! CVPR 2024): moving DAVIS-2016 objects (Perazzi et al., CVPR 2016), cut
//! out with their ground-truth masks, pasted onto the frames of a static
//! capture (e.g. instant-ngp's `fox`). Every 8th view (index % 8 == 0, the
//! LLFF / Mip-NeRF 360 hold-out) stays clean and becomes the `extra` test
//! split; the others get distractors and become `clutter`.
//!
//! A run of consecutive clutter frames shares one DAVIS sequence: the
//! object's own frames advance by `davis_stride` per background frame while
//! its bounding-box centre slides across the image, so the distractor
//! moves in the image *and* is inconsistent with the static scene's
//! epipolar geometry, like a passer-by.
//!
//! Output (what [`crate::Scene::load`] reads unchanged): `images/<stem>.png`,
//! `clean/<stem>.png` (the clutter frames without distractors: the oracle),
//! `gt_motion/<stem>.png` (255 where a distractor pixel was pasted),
//! `split.json` and `transforms.json` (intrinsics scaled to the output size).

use crate::davis::{Davis, DavisSequence};
use crate::error::{LoaderError, Result};
use crate::io::{read_gray8, read_rgb8, write_png_gray8, write_png_rgb8};
use crate::masks::gt_motion_path;
use crate::scene::list_images;
use crate::split::{Split, write_split};
use crate::transforms::{Transforms, read_transforms, resolve_image_path, write_transforms};
use image::imageops::FilterType;
use image::{GrayImage, RgbImage};
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// How to build a composite scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CompositeOptions {
    /// Integer downscale of the background frames (1 = full size). Default 4
    /// (fox: 1080×1920 → 270×480).
    pub downscale: u32,
    /// Hold out views with index % `test_every` == 0 as clean test views.
    /// Default 8 (the LLFF / On-the-go convention).
    pub test_every: usize,
    /// Consecutive clutter frames that share one DAVIS object. Default 6.
    pub run_length: usize,
    /// DAVIS frames advanced per background frame (DAVIS is 24 fps video,
    /// the background a sparse photo set). Default 3.
    pub davis_stride: usize,
    /// Pasted object height as a fraction of the output frame height, drawn
    /// uniformly in [min, max] per run. Default [0.3, 0.55].
    pub object_height: [f64; 2],
    /// Upper bound of the pasted object width, fraction of the frame width.
    /// Default 0.7.
    pub max_object_width: f64,
    /// DAVIS sequences to use (empty = all, sorted). Default empty.
    pub sequences: Vec<String>,
    /// DAVIS resolution folder. Default "480p".
    pub resolution: String,
    /// Seed for sequence order, sizes, paths and DAVIS start frames. Default 0.
    pub seed: u64,
    /// The camera follows each object: its box stays at one place in the
    /// image for the whole run (only its own articulation moves) while the
    /// background moves with the capture's camera, as when a video tracks a
    /// runner or a car. Default false (objects cross the frame).
    #[serde(default)]
    pub follow: bool,
    /// Objects pasted into each clutter frame (default 1). Each is its own
    /// run of DAVIS frames with its own sequence, size and path; later ones
    /// are pasted over earlier ones. Several make the heavier clutter of a
    /// crowded place.
    #[serde(default = "one")]
    pub objects_per_frame: usize,
}

fn one() -> usize {
    1
}

impl Default for CompositeOptions {
    fn default() -> Self {
        CompositeOptions {
            downscale: 4,
            test_every: 8,
            run_length: 6,
            davis_stride: 3,
            object_height: [0.3, 0.55],
            max_object_width: 0.7,
            sequences: Vec::new(),
            resolution: "480p".into(),
            seed: 0,
            follow: false,
            objects_per_frame: 1,
        }
    }
}

impl CompositeOptions {
    /// Check the options.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: &str| Err(LoaderError::Invalid(m.into()));
        if self.downscale == 0 {
            return bad("downscale must be >= 1");
        }
        if self.test_every < 2 {
            return bad("test_every must be >= 2");
        }
        if self.run_length == 0 || self.davis_stride == 0 || self.objects_per_frame == 0 {
            return bad("run_length, davis_stride and objects_per_frame must be >= 1");
        }
        let [a, b] = self.object_height;
        if !(a > 0.0 && a <= b && b <= 2.0) {
            return bad("object_height must satisfy 0 < min <= max <= 2");
        }
        if !(self.max_object_width > 0.0 && self.max_object_width <= 2.0) {
            return bad("max_object_width must be in (0, 2]");
        }
        Ok(())
    }
}

/// Where a source cut-out lands: destination pixel centre `(x + ½, y + ½)`
/// samples the source at `((x + ½ − offset_x) / scale, (y + ½ − offset_y) / scale)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Source → destination magnification.
    pub scale: f64,
    /// Destination position of the source's top-left corner, pixels.
    pub offset_x: f64,
    pub offset_y: f64,
}

fn bilinear(w: u32, h: u32, x: f64, y: f64, get: impl Fn(u32, u32) -> f64) -> f64 {
    let x = x.clamp(0.0, (w - 1) as f64);
    let y = y.clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let top = get(x0, y0) * (1.0 - fx) + get(x1, y0) * fx;
    let bot = get(x0, y1) * (1.0 - fx) + get(x1, y1) * fx;
    top * (1.0 - fy) + bot * fy
}

/// Paste `src` where `mask` ≥ 128 onto `dst` at `place` (bilinear colour;
/// the bilinearly resampled mask thresholded at ½ decides coverage, so at
/// scale 1 and an integer offset exactly the mask's pixels are copied), and
/// set `moving` to 255 on every pasted pixel. Returns the pasted pixel count.
/// `src` and `mask` must have the same size (checked by the caller).
pub fn paste(
    dst: &mut RgbImage,
    moving: &mut GrayImage,
    src: &RgbImage,
    mask: &GrayImage,
    place: Placement,
) -> usize {
    let (sw, sh) = src.dimensions();
    if sw == 0 || sh == 0 || place.scale <= 0.0 {
        return 0;
    }
    let (dw, dh) = dst.dimensions();
    // Destination rectangle covered by the source.
    let x0 = place.offset_x.floor().max(0.0) as u32;
    let y0 = place.offset_y.floor().max(0.0) as u32;
    let x1 = (place.offset_x + sw as f64 * place.scale)
        .ceil()
        .min(dw as f64);
    let y1 = (place.offset_y + sh as f64 * place.scale)
        .ceil()
        .min(dh as f64);
    let (x1, y1) = (x1.max(0.0) as u32, y1.max(0.0) as u32);
    let mut n = 0;
    for y in y0..y1 {
        let sy = (y as f64 + 0.5 - place.offset_y) / place.scale - 0.5;
        if sy < -0.5 || sy > sh as f64 - 0.5 {
            continue;
        }
        for x in x0..x1 {
            let sx = (x as f64 + 0.5 - place.offset_x) / place.scale - 0.5;
            if sx < -0.5 || sx > sw as f64 - 0.5 {
                continue;
            }
            let m = bilinear(sw, sh, sx, sy, |u, v| {
                if mask.get_pixel(u, v)[0] >= 128 {
                    1.0
                } else {
                    0.0
                }
            });
            if m < 0.5 {
                continue;
            }
            let mut px = [0u8; 3];
            for (k, c) in px.iter_mut().enumerate() {
                let v = bilinear(sw, sh, sx, sy, |u, v| src.get_pixel(u, v)[k] as f64);
                *c = v.round().clamp(0.0, 255.0) as u8;
            }
            dst.put_pixel(x, y, image::Rgb(px));
            moving.put_pixel(x, y, image::Luma([255]));
            n += 1;
        }
    }
    n
}

/// Bounding box `(x0, y0, x1, y1)` (exclusive) of mask pixels ≥ 128.
pub fn mask_bbox(mask: &GrayImage) -> Option<(u32, u32, u32, u32)> {
    let mut b: Option<(u32, u32, u32, u32)> = None;
    for (x, y, p) in mask.enumerate_pixels() {
        if p[0] >= 128 {
            b = Some(match b {
                None => (x, y, x + 1, y + 1),
                Some((a, c, d, e)) => (a.min(x), c.min(y), d.max(x + 1), e.max(y + 1)),
            });
        }
    }
    b
}

/// What [`composite`] wrote.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct CompositeReport {
    /// Output scene folder.
    pub out: PathBuf,
    /// Output frame size.
    pub width: u32,
    pub height: u32,
    /// Frames written (clutter + extra).
    pub frames: usize,
    pub clutter: usize,
    pub extra: usize,
    /// Per clutter frame: (image name, DAVIS sequences, DAVIS frames,
    /// fraction of pixels pasted); with several objects per frame the
    /// sequences and frames are joined by `+`.
    pub pasted: Vec<(String, String, String, f64)>,
    /// Mean / min / max distractor coverage over clutter frames.
    pub coverage_mean: f64,
    pub coverage_min: f64,
    pub coverage_max: f64,
}

fn missing(path: PathBuf, ctx: &str) -> LoaderError {
    LoaderError::Missing {
        path,
        context: ctx.into(),
    }
}

fn stem(name: &str) -> String {
    Path::new(name)
        .file_stem()
        .map_or_else(|| name.to_string(), |s| s.to_string_lossy().into_owned())
}

/// One DAVIS frame with its annotation, checked to be the same size.
fn davis_frame(img: &Path, ann: Option<&PathBuf>, seq: &str) -> Result<(RgbImage, GrayImage)> {
    let ann = ann.ok_or_else(|| {
        missing(
            img.with_extension("png"),
            &format!("DAVIS annotation for {} of sequence {seq}", img.display()),
        )
    })?;
    let rgb = read_rgb8(img)?;
    let m = read_gray8(ann)?;
    if m.dimensions() != rgb.dimensions() {
        return Err(LoaderError::format(
            ann,
            format!(
                "annotation is {}x{} but its image {} is {}x{}",
                m.width(),
                m.height(),
                img.display(),
                rgb.width(),
                rgb.height()
            ),
        ));
    }
    Ok((rgb, m))
}

/// Build the composite scene in `out` from a background scene folder
/// (`images/` + `transforms.json`) and a DAVIS root.
pub fn composite(
    background: &Path,
    davis_root: &Path,
    out: &Path,
    opts: &CompositeOptions,
) -> Result<CompositeReport> {
    opts.validate()?;
    let names = list_images(&background.join("images"))?;
    let tp = background.join("transforms.json");
    if !tp.is_file() {
        return Err(missing(tp, "background transforms.json"));
    }
    let mut transforms = read_transforms(&tp)?;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(opts.seed);
    let sequences = shuffled_sequences(davis_root, opts, &mut rng)?;

    for d in ["images", "clean", "gt_motion"] {
        let p = out.join(d);
        std::fs::create_dir_all(&p).map_err(|e| LoaderError::io(&p, e))?;
    }

    let mut report = CompositeReport {
        out: out.to_path_buf(),
        coverage_min: f64::INFINITY,
        ..Default::default()
    };
    let (mut clutter, mut extra) = (Vec::new(), Vec::new());
    let mut new_name: HashMap<String, String> = HashMap::new();
    let clutter_idx: Vec<usize> = (0..names.len())
        .filter(|i| i % opts.test_every != 0)
        .collect();
    // One list of runs per object slot, drawn in slot order; slot `j` is
    // `j` sequences ahead, so the objects of one frame differ while there
    // are enough, and slot 0 is the one-object scene's.
    let lanes: Vec<Vec<Run>> = (0..opts.objects_per_frame)
        .map(|j| plan_runs(clutter_idx.len(), j, &sequences, opts, &mut rng))
        .collect();

    for (i, name) in names.iter().enumerate() {
        let mut img = downscaled(&background.join("images").join(name), opts.downscale)?;
        let (w, h) = img.dimensions();
        report.width = w;
        report.height = h;
        let out_name = format!("{}.png", stem(name));
        new_name.insert(name.clone(), out_name.clone());
        let mut moving = GrayImage::new(w, h);
        if let Some(k) = clutter_idx.iter().position(|&c| c == i) {
            write_png_rgb8(out.join("clean").join(&out_name), &img)?;
            let t = k % opts.run_length;
            let (mut seqs, mut frames) = (Vec::new(), Vec::new());
            for lane in &lanes {
                let run = &lane[k / opts.run_length];
                let seq = &sequences[run.seq];
                let fi = (run.start + t * opts.davis_stride) % seq.frames.len();
                let f = &seq.frames[fi];
                let (obj, mask) = davis_frame(&f.image, f.annotation.as_ref(), &seq.name)?;
                if let Some(place) = run.placement(&mask, t, (w, h), opts) {
                    paste(&mut img, &mut moving, &obj, &mask, place);
                }
                seqs.push(seq.name.clone());
                frames.push(f.name.clone());
            }
            let n = moving.pixels().filter(|p| p[0] == 255).count();
            let cov = n as f64 / (w as f64 * h as f64);
            report.coverage_mean += cov;
            report.coverage_min = report.coverage_min.min(cov);
            report.coverage_max = report.coverage_max.max(cov);
            report
                .pasted
                .push((out_name.clone(), seqs.join("+"), frames.join("+"), cov));
            clutter.push(out_name.clone());
        } else {
            extra.push(out_name.clone());
        }
        write_png_rgb8(out.join("images").join(&out_name), &img)?;
        write_png_gray8(gt_motion_path(&out.join("gt_motion"), &out_name), &moving)?;
    }
    if !clutter.is_empty() {
        report.coverage_mean /= clutter.len() as f64;
    } else {
        report.coverage_min = 0.0;
    }

    rename_and_rescale(
        &mut transforms,
        background,
        &tp,
        &new_name,
        (report.width, report.height),
    )?;
    write_transforms(out.join("transforms.json"), &transforms)?;
    write_split(
        out.join("split.json"),
        &Split::from_names(&clutter, &extra, None),
    )?;
    report.frames = names.len();
    report.clutter = clutter.len();
    report.extra = extra.len();
    Ok(report)
}

/// The DAVIS sequences to paste (all, or `opts.sequences`), each with frames,
/// in a seeded order (Fisher–Yates) that the runs cycle over.
fn shuffled_sequences(
    davis_root: &Path,
    opts: &CompositeOptions,
    rng: &mut rand_pcg::Pcg64,
) -> Result<Vec<DavisSequence>> {
    let davis = Davis::open(davis_root, &opts.resolution)?;
    let seq_names = if opts.sequences.is_empty() {
        davis.sequences()?
    } else {
        opts.sequences.clone()
    };
    let mut sequences = Vec::new();
    for s in &seq_names {
        let seq = davis.sequence(s)?;
        if seq.frames.is_empty() {
            return Err(LoaderError::format(
                &davis.root,
                format!("sequence {s} has no frames"),
            ));
        }
        sequences.push(seq);
    }
    if sequences.is_empty() {
        return Err(LoaderError::format(davis_root, "no DAVIS sequences"));
    }
    for i in (1..sequences.len()).rev() {
        let j = rng.random_range(0..=i);
        sequences.swap(i, j);
    }
    Ok(sequences)
}

/// One run of `opts.run_length` clutter frames: one DAVIS sequence from a
/// start frame, its object at one size walking along one path.
struct Run {
    seq: usize,
    start: usize,
    /// Object height as a fraction of the frame height.
    height_frac: f64,
    /// Horizontal path of the object's centre, as fractions of the width.
    x_from: f64,
    x_to: f64,
    /// The object's bottom, as a fraction of the height.
    y_bottom: f64,
}

impl Run {
    /// Where the object of `mask` goes in frame `t` of the run, in a `w×h`
    /// frame; `None` when the mask is empty.
    fn placement(
        &self,
        mask: &GrayImage,
        t: usize,
        (w, h): (u32, u32),
        opts: &CompositeOptions,
    ) -> Option<Placement> {
        let (bx0, by0, bx1, by1) = mask_bbox(mask)?;
        let (bw, bh) = ((bx1 - bx0) as f64, (by1 - by0) as f64);
        let scale = (self.height_frac * h as f64 / bh).min(opts.max_object_width * w as f64 / bw);
        let frac = if opts.run_length > 1 {
            t as f64 / (opts.run_length - 1) as f64
        } else {
            0.5
        };
        let cx = (self.x_from + (self.x_to - self.x_from) * frac) * w as f64;
        let bottom = self.y_bottom * h as f64;
        Some(Placement {
            scale,
            offset_x: cx - scale * (bx0 as f64 + bw / 2.0),
            offset_y: bottom - scale * by1 as f64,
        })
    }
}

/// The runs covering `clutter` frames for object slot `lane`, drawn from
/// `rng`.
fn plan_runs(
    clutter: usize,
    lane: usize,
    sequences: &[DavisSequence],
    opts: &CompositeOptions,
    rng: &mut rand_pcg::Pcg64,
) -> Vec<Run> {
    let mut runs = Vec::new();
    for r in 0..clutter.div_ceil(opts.run_length) {
        let seq = (r + lane) % sequences.len();
        let span = (opts.run_length - 1) * opts.davis_stride + 1;
        let n = sequences[seq].frames.len();
        let start = if n > span {
            rng.random_range(0..n - span)
        } else {
            0
        };
        let [a, b] = opts.object_height;
        let (p, q) = (rng.random_range(0.1..0.35), rng.random_range(0.65..0.9));
        let flip = rng.random_bool(0.5);
        // A followed object stays at the middle of the path it would cross.
        let (x_from, x_to) = match (opts.follow, flip) {
            (true, _) => ((p + q) / 2.0, (p + q) / 2.0),
            (false, true) => (q, p),
            (false, false) => (p, q),
        };
        runs.push(Run {
            seq,
            start,
            height_frac: if b > a { rng.random_range(a..=b) } else { a },
            x_from,
            x_to,
            y_bottom: rng.random_range(0.75..0.98),
        });
    }
    runs
}

/// The background image `src`, downscaled by `downscale` (each side rounded,
/// at least 1 px).
fn downscaled(src: &Path, downscale: u32) -> Result<RgbImage> {
    let full = read_rgb8(src)?;
    let s = |v: u32| ((v as f64 / downscale as f64).round() as u32).max(1);
    let (w, h) = (s(full.width()), s(full.height()));
    Ok(if (w, h) == full.dimensions() {
        full
    } else {
        image::imageops::resize(&full, w, h, FilterType::Triangle)
    })
}

/// transforms.json of the composite: file paths renamed to the written
/// images, intrinsics scaled to the output size `(w, h)`.
fn rename_and_rescale(
    transforms: &mut Transforms,
    background: &Path,
    tp: &Path,
    new_name: &HashMap<String, String>,
    (w, h): (u32, u32),
) -> Result<()> {
    let sx = |v: Option<f64>, r: f64| v.map(|v| v * r);
    let scale_fields = |f: &mut crate::transforms::IntrinsicFields, w0: f64, h0: f64| {
        let (rx, ry) = (w as f64 / w0, h as f64 / h0);
        f.fl_x = sx(f.fl_x, rx);
        f.fl_y = sx(f.fl_y, ry);
        f.cx = sx(f.cx, rx);
        f.cy = sx(f.cy, ry);
        f.w = f.w.map(|_| w as f64);
        f.h = f.h.map(|_| h as f64);
    };
    let global_size = transforms.intrinsics.w.zip(transforms.intrinsics.h);
    for (idx, fr) in transforms.frames.iter_mut().enumerate() {
        let p = resolve_image_path(background, &fr.file_path)
            .ok_or_else(|| missing(background.join(&fr.file_path), "listed in transforms.json"))?;
        let name = p
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let nn = new_name.get(&name).ok_or_else(|| {
            LoaderError::format(
                tp,
                format!("frame {idx}: {} is not in images/", fr.file_path),
            )
        })?;
        fr.file_path = format!("images/{nn}");
        if let Some((w0, h0)) = fr.intrinsics.w.zip(fr.intrinsics.h).or(global_size) {
            scale_fields(&mut fr.intrinsics, w0, h0);
        } else if fr.intrinsics.fl_x.is_some() {
            return Err(LoaderError::format(
                tp,
                format!("frame {idx}: focal length given without w/h; cannot rescale"),
            ));
        }
        fr.extra.remove("mask_path");
    }
    if let Some((w0, h0)) = global_size {
        scale_fields(&mut transforms.intrinsics, w0, h0);
    } else if transforms.intrinsics.fl_x.is_some() {
        return Err(LoaderError::format(
            tp,
            "focal length given without w/h; cannot rescale",
        ));
    }
    Ok(())
}

#[cfg(test)]
#[path = "composite_tests.rs"]
mod tests;
