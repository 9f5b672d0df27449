//! Stage 10 of RoMo and the entry point the CLI calls: run the pipeline on
//! a scene folder (or a list of image files), refine each frame's
//! probability to full resolution, and write `masks/<name>.png` (255 keep,
//! 0 moving; COLMAP's convention), optional `motion/<name>.png` overlays and
//! `probabilities/<stem>.exr`.

use crate::exposure::Exposure;
use crate::features::{FeatureExtractor, HandFeatures};
use crate::flow::FlowEstimator;
use crate::flow::dis::Dis;
use crate::pipeline::{
    FeatureBackend, FlowBackend, FrameSource, RomoOptions, RomoReport, segment_frames,
};
use crate::plane::{Plane, Rgb};
use crate::refine::{to_keep_mask, upsample_probability};
use crate::{Result, RomoError};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Frames read from image files.
pub struct PathSource {
    /// Image files in capture order.
    pub paths: Vec<PathBuf>,
}

impl FrameSource for PathSource {
    fn len(&self) -> usize {
        self.paths.len()
    }
    fn frame(&self, i: usize) -> Result<Rgb> {
        let p = self
            .paths
            .get(i)
            .ok_or_else(|| RomoError::Input(format!("frame {i} out of range")))?;
        Ok(Rgb::from_dynamic(loader::io::read_image(p)?))
    }
    fn size(&self, i: usize) -> Result<(usize, usize)> {
        let p = self
            .paths
            .get(i)
            .ok_or_else(|| RomoError::Input(format!("frame {i} out of range")))?;
        let (w, h) = image::image_dimensions(p).map_err(|e| loader::LoaderError::image(p, e))?;
        Ok((w as usize, h as usize))
    }
    fn describe(&self, i: usize) -> String {
        self.paths
            .get(i)
            .map_or_else(|| format!("frame {i}"), |p| p.display().to_string())
    }
}

/// A scene's video frames (indices into `scene.frames`).
struct SceneSource<'a>(&'a loader::scene::Scene, Vec<usize>);

impl FrameSource for SceneSource<'_> {
    fn len(&self) -> usize {
        self.1.len()
    }
    fn frame(&self, i: usize) -> Result<Rgb> {
        let k = *self
            .1
            .get(i)
            .ok_or_else(|| RomoError::Input(format!("frame {i} out of range")))?;
        Ok(Rgb::from_image(&self.0.load_image(k)?))
    }
    fn size(&self, i: usize) -> Result<(usize, usize)> {
        let f = self
            .1
            .get(i)
            .and_then(|&k| self.0.frames.get(k))
            .ok_or_else(|| RomoError::Input(format!("frame {i} out of range")))?;
        Ok((f.intrinsics.width as usize, f.intrinsics.height as usize))
    }
    fn describe(&self, i: usize) -> String {
        self.1
            .get(i)
            .and_then(|&k| self.0.frames.get(k))
            .map_or_else(
                || format!("frame {i}"),
                |f| f.image_path.display().to_string(),
            )
    }
}

/// The feature extractor selected by the options.
pub fn make_extractor(o: &RomoOptions) -> Result<Box<dyn FeatureExtractor>> {
    let hand = HandFeatures {
        chromaticity: o.chromaticity_features,
    };
    match &o.features {
        FeatureBackend::Hand => Ok(Box::new(hand)),
        #[cfg(feature = "onnx")]
        FeatureBackend::Onnx { model } => Ok(Box::new(crate::onnx::WithHand(
            crate::onnx::OnnxFeatures::load(model)?,
            hand,
        ))),
        #[cfg(not(feature = "onnx"))]
        FeatureBackend::Onnx { model } => Err(RomoError::Onnx(format!(
            "{}: this build has no ONNX support (rebuild with `--features romo/onnx`)",
            model.display()
        ))),
    }
}

/// The flow estimator `opts.flow_backend` names.
pub fn make_flow(o: &RomoOptions) -> Result<Box<dyn FlowEstimator>> {
    match &o.flow_backend {
        FlowBackend::Dis => Ok(Box::new(Dis::new(o.flow.clone()))),
        #[cfg(feature = "onnx")]
        FlowBackend::Onnx { model } => Ok(Box::new(crate::onnx::OnnxFlow::load(
            model,
            o.onnx_flow_scale,
        )?)),
        #[cfg(not(feature = "onnx"))]
        FlowBackend::Onnx { model, .. } => Err(RomoError::Onnx(format!(
            "{}: this build has no ONNX support (rebuild with `--features romo/onnx`)",
            model.display()
        ))),
    }
}

/// File stems of a scene's held-out views (split.json `extra`), the frames
/// to leave out when scoring its masks (see
/// [`crate::metrics::evaluate_masks_excluding`]): they get all-keep masks
/// and have empty ground truth, a perfect J of 1 each.
pub fn held_out_stems(scene: &loader::scene::Scene) -> Vec<String> {
    scene
        .split_indices("extra")
        .into_iter()
        .filter_map(|i| {
            // The stem of the ground-truth file the loader names for it.
            let gt = loader::masks::gt_motion_path(Path::new(""), &scene.frames[i].name);
            gt.file_stem().map(|s| s.to_string_lossy().into_owned())
        })
        .collect()
}

/// Score a scene's masks (`masks_dir`, e.g. `masks/` written by
/// [`segment_scene`]) against its `gt_motion/`, over the video frames only
/// (without [`held_out_stems`]).
pub fn evaluate_scene_masks(
    scene: &loader::scene::Scene,
    masks_dir: &Path,
) -> Result<crate::metrics::SequenceMetrics> {
    crate::metrics::evaluate_sequence_excluding(
        masks_dir,
        &scene.root.join("gt_motion"),
        "",
        &held_out_stems(scene),
    )
}

/// Run RoMo on a loaded scene; writes into `opts.out` or the scene folder.
///
/// The video is the scene's frames minus split.json's `extra` views: those
/// are held-out clean test images (NeRF On-the-go convention), not part of
/// the capture sequence, so they get all-keep masks.
pub fn segment_scene(
    scene: &loader::scene::Scene,
    opts: &RomoOptions,
    progress: &dyn Fn(&str, usize, usize),
) -> Result<RomoReport> {
    let extra = scene.split_indices("extra");
    let video: Vec<usize> = (0..scene.frames.len())
        .filter(|i| !extra.contains(i))
        .collect();
    let names: Vec<String> = video
        .iter()
        .map(|&i| scene.frames[i].name.clone())
        .collect();
    let out = opts.out.clone().unwrap_or_else(|| scene.root.clone());
    // The scene's focal length (or the loader's 1.2 × long side prior when
    // it has no cameras) for the cheirality test, at the frames' size.
    let mut opts = opts.clone();
    if opts.focal_ratio.is_none()
        && let Some(&i) = video.first()
    {
        let k = &scene.frames[i].intrinsics;
        opts.focal_ratio = Some(0.5 * (k.fx + k.fy) / k.width.max(1) as f64);
    }
    let opts = &opts;
    // Masks are written at the images' own size, also when the scene was
    // loaded downscaled (`train` and COLMAP expect them at that size).
    let own_size = |i: usize| {
        let k = &scene.frames[i].intrinsics;
        scene.full_size(i).unwrap_or((k.width, k.height))
    };
    let sizes: Vec<(usize, usize)> = video
        .iter()
        .map(|&i| {
            let (w, h) = own_size(i);
            (w as usize, h as usize)
        })
        .collect();
    let mut report = segment_source(
        &SceneSource(scene, video),
        &names,
        Some(&sizes),
        &out,
        opts,
        progress,
    )?;
    for &i in &extra {
        let (w, h) = own_size(i);
        let keep = image::GrayImage::from_pixel(w, h, image::Luma([255]));
        loader::masks::write_mask(
            loader::masks::mask_path(&out.join("masks"), &scene.frames[i].name),
            &keep,
        )?;
    }
    report.held_out_views = extra.len();
    Ok(report)
}

/// Run RoMo on image files; `names[i]` names frame i's outputs.
pub fn segment_paths(
    paths: &[PathBuf],
    names: &[String],
    out: &Path,
    opts: &RomoOptions,
    progress: &dyn Fn(&str, usize, usize),
) -> Result<RomoReport> {
    let src = PathSource {
        paths: paths.to_vec(),
    };
    segment_source(&src, names, None, out, opts, progress)
}

/// `sizes[i]`: the size frame i's mask and probabilities are written at
/// (None: the frame's own).
///
/// Frames of several sizes (a phone's portrait and landscape photos, a
/// folder of photos from several cameras) cannot share a flow: each size's
/// frames are segmented as their own sequence (ordered as one folder is),
/// and a frame alone at its size has no pair, so no evidence of motion: it
/// is kept whole. The report lists the groups one after the other.
fn segment_source(
    src: &dyn FrameSource,
    names: &[String],
    sizes: Option<&[(usize, usize)]>,
    out: &Path,
    opts: &RomoOptions,
    progress: &dyn Fn(&str, usize, usize),
) -> Result<RomoReport> {
    if names.len() != src.len() {
        return Err(RomoError::Input("one name per frame required".into()));
    }
    let groups = size_groups(src)?;
    if groups.len() <= 1 {
        return segment_sequence(src, names, sizes, out, opts, progress);
    }
    let mut report: Option<RomoReport> = None;
    let mut alone = vec![];
    let mut start = 0;
    for ((sub_w, sub_h), members) in &groups {
        let part = if members.len() == 1 {
            // No pair: no evidence of motion, kept whole.
            let i = members[0];
            let (w, h) = sizes.map_or((*sub_w, *sub_h), |s| s[i]);
            let keep = image::GrayImage::from_pixel(w as u32, h as u32, image::Luma([255]));
            loader::masks::write_mask(
                loader::masks::mask_path(&out.join("masks"), &names[i]),
                &keep,
            )?;
            alone.push((start, names[i].clone()));
            // Without evidence, but named in the one warning below rather
            // than in one "no evidence" warning each.
            RomoReport {
                frames: vec![crate::pipeline::FrameReport {
                    index: 0,
                    name: names[i].clone(),
                    ..Default::default()
                }],
                ..Default::default()
            }
        } else {
            let sub = Subset { src, idx: members };
            let sub_names: Vec<String> = members.iter().map(|&i| names[i].clone()).collect();
            let sub_sizes: Option<Vec<(usize, usize)>> =
                sizes.map(|s| members.iter().map(|&i| s[i]).collect());
            let labelled = |stage: &str, done: usize, total: usize| {
                progress(&format!("{stage}, {}x{} frames", sub_w, sub_h), done, total)
            };
            segment_sequence(&sub, &sub_names, sub_sizes.as_deref(), out, opts, &labelled)?
        };
        report = Some(match report {
            None => part,
            Some(whole) => merge_window(whole, part, start, false),
        });
        start += members.len();
    }
    let mut report = report.unwrap_or_default();
    report
        .no_evidence_frames
        .extend(alone.iter().map(|(t, _)| *t));
    report.no_evidence_frames.sort_unstable();
    let alone: Vec<String> = alone.into_iter().map(|(_, n)| n).collect();
    let described: Vec<String> = groups
        .iter()
        .map(|((w, h), m)| format!("{w}x{h}: {}", m.len()))
        .collect();
    report.warnings.insert(
        0,
        format!(
            "frames of {} sizes ({}): each size is segmented as its own sequence, one after the other in the report's `frames` list{}",
            groups.len(),
            described.join(", "),
            if alone.is_empty() {
                String::new()
            } else {
                format!(
                    "; alone at its size, so without a pair and kept whole: {}",
                    alone.join(", ")
                )
            }
        ),
    );
    report.masks_dir = Some(out.join("masks"));
    Ok(report)
}

/// Frames of one size: (width, height) and their indices.
type SizeGroup = ((usize, usize), Vec<usize>);

/// `src`'s frames grouped by size, groups in order of first appearance,
/// frames in order within each.
fn size_groups(src: &dyn FrameSource) -> Result<Vec<SizeGroup>> {
    let sizes = (0..src.len())
        .into_par_iter()
        .map(|i| src.size(i))
        .collect::<Result<Vec<_>>>()?;
    let mut groups: Vec<SizeGroup> = vec![];
    for (i, s) in sizes.into_iter().enumerate() {
        match groups.iter_mut().find(|(g, _)| *g == s) {
            Some((_, m)) => m.push(i),
            None => groups.push((s, vec![i])),
        }
    }
    Ok(groups)
}

/// The frames `idx` of `src`, in that order.
struct Subset<'a> {
    src: &'a dyn FrameSource,
    idx: &'a [usize],
}

impl Subset<'_> {
    /// `src`'s index of frame `i`.
    fn at(&self, i: usize) -> Result<usize> {
        self.idx
            .get(i)
            .copied()
            .ok_or_else(|| RomoError::Input(format!("frame {i} out of range")))
    }
}

impl FrameSource for Subset<'_> {
    fn len(&self) -> usize {
        self.idx.len()
    }
    fn frame(&self, i: usize) -> Result<Rgb> {
        self.src.frame(self.at(i)?)
    }
    fn size(&self, i: usize) -> Result<(usize, usize)> {
        self.src.size(self.at(i)?)
    }
    fn describe(&self, i: usize) -> String {
        self.idx
            .get(i)
            .map_or_else(|| format!("frame {i}"), |&k| self.src.describe(k))
    }
}

/// One sequence of frames of one size: ordered ([`crate::order`]), then
/// segmented in windows of at most `chunk_frames`.
fn segment_sequence(
    src: &dyn FrameSource,
    names: &[String],
    sizes: Option<&[(usize, usize)]>,
    out: &Path,
    opts: &RomoOptions,
    progress: &dyn Fn(&str, usize, usize),
) -> Result<RomoReport> {
    let t = Instant::now();
    let ordering = crate::order::choose(src, opts.frame_order)?;
    let order_ms = t.elapsed().as_secs_f64() * 1e3;
    let ordered = Subset {
        src,
        idx: &ordering.order,
    };
    let src: &dyn FrameSource = &ordered;
    let names: Vec<String> = ordering.order.iter().map(|&i| names[i].clone()).collect();
    let sizes: Option<Vec<(usize, usize)>> =
        sizes.map(|s| ordering.order.iter().map(|&i| s[i]).collect());
    let sizes = sizes.as_deref();
    // Bars at the edges (pillarbox, letterbox) are left out of the
    // segmentation and masked ([`crate::borders`]).
    let borders = {
        let n = src.len();
        let k = n.min(8);
        let sample = (0..k)
            .map(|j| src.frame(j * n.saturating_sub(1) / k.saturating_sub(1).max(1)))
            .collect::<Result<Vec<_>>>()?;
        crate::borders::detect(&sample)
    };
    let cropped = Cropped { src, borders };
    let full = src;
    let src: &dyn FrameSource = if borders.is_empty() { full } else { &cropped };
    let fx = make_extractor(opts)?;
    let flow = make_flow(opts)?;
    let masks_dir = out.join("masks");
    let mut report: Option<RomoReport> = None;
    let windows = chunks(src.len(), opts.chunk_frames);
    let count = windows.len();
    for (k, (start, end)) in windows.into_iter().enumerate() {
        let sub = Window {
            src,
            start,
            len: end - start,
        };
        // Each window counts its own frames: say which window it is.
        let labelled = |stage: &str, done: usize, total: usize| {
            progress(
                &format!("{stage}, window {} of {count}", k + 1),
                done,
                total,
            )
        };
        let progress: &dyn Fn(&str, usize, usize) = if count > 1 { &labelled } else { progress };
        let seg = segment_frames(&sub, opts, flow.as_ref(), fx.as_ref(), progress)?;
        // A window's first frame is the previous window's last, written there.
        let first = usize::from(k > 0);
        let t = Instant::now();
        write_outputs(
            (
                &Window {
                    src: full,
                    start,
                    len: end - start,
                },
                borders,
            ),
            &seg.probs,
            seg.exposure,
            first,
            &names[start..end],
            sizes.map(|s| &s[start..end]),
            out,
            opts,
            progress,
        )?;
        let mut part = seg.report;
        part.timings_ms
            .insert("refine_write".into(), t.elapsed().as_secs_f64() * 1e3);
        report = Some(match report {
            None => part,
            Some(whole) => merge_window(whole, part, start, true),
        });
    }
    let mut report = report.unwrap_or_default();
    for (f, n) in report.frames.iter_mut().zip(&names) {
        f.name = n.clone();
    }
    report.masks_dir = Some(masks_dir);
    if !borders.is_empty() {
        report.warnings.insert(
            0,
            format!(
                "bars at the frame's edges (left {}, right {}, top {}, bottom {} px) are not part of the scene: segmented without them and masked",
                borders.left, borders.right, borders.top, borders.bottom
            ),
        );
    }
    report.timings_ms.insert("order".into(), order_ms);
    report.name_order_ratio = ordering.ratio.is_finite().then_some(ordering.ratio);
    report.reordered = ordering.reordered;
    if ordering.reordered {
        report.warnings.insert(
            0,
            format!(
                "the file names are not in capture order (neighbours by name are {:.1}× as far apart as along a similarity path): frames segmented along that path, from {} to {}; frame and pair numbers follow it (the report's `frames` list)",
                ordering.ratio,
                names.first().map_or("", String::as_str),
                names.last().map_or("", String::as_str),
            ),
        );
    }
    Ok(report)
}

/// `src`'s frames cropped to what lies between their bars.
struct Cropped<'a> {
    src: &'a dyn FrameSource,
    borders: crate::borders::Borders,
}

impl FrameSource for Cropped<'_> {
    fn len(&self) -> usize {
        self.src.len()
    }
    fn frame(&self, i: usize) -> Result<Rgb> {
        Ok(crate::borders::crop(&self.src.frame(i)?, &self.borders))
    }
    fn size(&self, i: usize) -> Result<(usize, usize)> {
        let (w, h) = self.src.size(i)?;
        let (_, _, cw, ch) = self.borders.content(w, h);
        Ok((cw, ch))
    }
    fn describe(&self, i: usize) -> String {
        self.src.describe(i)
    }
}

/// Frames `start .. start + len` of `src`.
struct Window<'a> {
    src: &'a dyn FrameSource,
    start: usize,
    len: usize,
}

impl FrameSource for Window<'_> {
    fn len(&self) -> usize {
        self.len
    }
    fn frame(&self, i: usize) -> Result<Rgb> {
        if i >= self.len {
            return Err(RomoError::Input(format!("frame {i} out of range")));
        }
        self.src.frame(self.start + i)
    }
    fn describe(&self, i: usize) -> String {
        self.src.describe(self.start + i)
    }
}

/// The windows `[start, end)` that segment `n` frames at most `max` at a
/// time (0: all at once): equal lengths, each sharing its first frame with
/// the previous window's last, so every pair of consecutive frames lies in
/// one window.
pub fn chunks(n: usize, max: usize) -> Vec<(usize, usize)> {
    if max < 2 || n <= max {
        return vec![(0, n)];
    }
    let pairs = n - 1;
    let count = pairs.div_ceil(max - 1);
    let per = pairs.div_ceil(count);
    (0..count)
        .map(|k| (k * per, ((k + 1) * per + 1).min(n)))
        .filter(|(s, e)| e > s)
        .collect()
}

/// `whole` (frames `0 ..= start`) followed by `part` (frames `start ..`):
/// frame `start` keeps `whole`'s entry when the two share it (`shared`:
/// windows of one video), else `part` starts after `whole` (size groups);
/// indices in `part` shift by `start`.
fn merge_window(mut whole: RomoReport, part: RomoReport, start: usize, shared: bool) -> RomoReport {
    let skip = usize::from(shared);
    // The part's warnings that name frames or pairs by its own indices;
    // they are written again below with the video's.
    let mut local: Vec<String> = part
        .skipped_pairs
        .iter()
        .map(|sp| crate::pipeline::skipped_pair_warning(sp.pair, &sp.reason))
        .collect();
    if !part.no_evidence_frames.is_empty() {
        local.push(crate::pipeline::no_evidence_warning(
            &part.no_evidence_frames,
        ));
    }
    whole
        .frames
        .extend(part.frames.into_iter().skip(skip).map(|mut f| {
            f.index += start;
            f
        }));
    whole.dropped_frames.extend(
        part.dropped_frames
            .iter()
            .filter(|&&t| t >= skip)
            .map(|t| t + start),
    );
    whole.rounds.extend(part.rounds);
    whole.pairs.extend(part.pairs);
    for (k, v) in part.timings_ms {
        *whole.timings_ms.entry(k).or_insert(0.0) += v;
    }
    for sp in part.skipped_pairs {
        let pair = sp.pair + start;
        whole
            .warnings
            .push(crate::pipeline::skipped_pair_warning(pair, &sp.reason));
        whole.skipped_pairs.push(crate::pipeline::SkippedPair {
            pair,
            reason: sp.reason,
        });
    }
    let fresh: Vec<usize> = part
        .no_evidence_frames
        .iter()
        .map(|t| t + start)
        .filter(|t| !whole.no_evidence_frames.contains(t))
        .collect();
    if !fresh.is_empty() {
        whole
            .warnings
            .push(crate::pipeline::no_evidence_warning(&fresh));
        whole.no_evidence_frames.extend(fresh);
    }
    whole
        .warnings
        .extend(part.warnings.into_iter().filter(|w| !local.contains(w)));
    if part.image_fixed_fraction > whole.image_fixed_fraction {
        whole.image_fixed_fraction = part.image_fixed_fraction;
        whole.image_fixed = part.image_fixed;
    }
    whole
}

/// Masks (and overlays, probabilities) of `src`'s frames `first ..` from
/// their grid probabilities; the frames (guide and overlay) through
/// `exposure`. What was segmented is `src`'s frames between their
/// `borders`, whose bars are masked.
#[allow(clippy::too_many_arguments)]
fn write_outputs(
    (src, borders): (&dyn FrameSource, crate::borders::Borders),
    probs: &[Plane],
    exposure: Exposure,
    first: usize,
    names: &[String],
    sizes: Option<&[(usize, usize)]>,
    out: &Path,
    opts: &RomoOptions,
    progress: &dyn Fn(&str, usize, usize),
) -> Result<()> {
    let masks_dir = out.join("masks");
    progress("write", 0, names.len());
    (first..names.len())
        .into_par_iter()
        .try_for_each(|i| -> Result<()> {
            // The guide as the stages saw it: the guided filter's ε is in
            // absolute grey levels.
            // Each frame is read once: the guide is its content, the overlay
            // the whole frame.
            let frame = exposure.applied(src.frame(i)?);
            let prob = if borders.is_empty() {
                upsample_probability(&probs[i], &frame, &opts.refine)
            } else {
                let guide = crate::borders::crop(&frame, &borders);
                let content = upsample_probability(&probs[i], &guide, &opts.refine);
                crate::borders::paste(&content, &borders, (frame.w(), frame.h()), 1.0)
            };
            let sized = match sizes.and_then(|s| s.get(i)) {
                Some(&(w, h)) if (w, h) != (prob.w, prob.h) => {
                    std::borrow::Cow::Owned(prob.resize(w, h))
                }
                _ => std::borrow::Cow::Borrowed(&prob),
            };
            let keep = to_keep_mask(&sized, opts.refine.threshold);
            loader::masks::write_mask(loader::masks::mask_path(&masks_dir, &names[i]), &keep)?;
            if opts.overlays {
                write_overlay(
                    &out.join("motion").join(format!("{}.png", names[i])),
                    &frame,
                    &prob,
                    opts,
                )?;
            }
            if opts.save_probabilities {
                let stem = Path::new(&names[i])
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| names[i].clone());
                write_exr(
                    &out.join("probabilities").join(format!("{stem}.exr")),
                    &sized,
                )?;
            }
            Ok(())
        })?;
    progress("write", names.len(), names.len());
    Ok(())
}

/// Frame darkened, with moving pixels tinted red.
fn write_overlay(path: &Path, frame: &Rgb, prob: &Plane, o: &RomoOptions) -> Result<()> {
    let (w, h) = (frame.w(), frame.h());
    let img = image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let i = y as usize * w + x as usize;
        let moving = prob.data[i] > o.refine.threshold;
        let px = |k: usize| frame.c[k].data[i].clamp(0.0, 1.0);
        let (r, g, b) = if moving {
            (0.5 + 0.5 * px(0), 0.4 * px(1), 0.4 * px(2))
        } else {
            (0.7 * px(0), 0.7 * px(1), 0.7 * px(2))
        };
        image::Rgb([(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8])
    });
    Ok(loader::io::write_png_rgb8(path, &img)?)
}

/// Single-channel ("Y") float EXR of the moving probability.
fn write_exr(path: &Path, prob: &Plane) -> Result<()> {
    use exr::prelude::*;
    let (w, h) = (prob.w, prob.h);
    let channels = SpecificChannels::build()
        .with_channel("Y")
        .with_pixel_fn(|p: Vec2<usize>| (prob.data[p.y() * w + p.x()],));
    let image = Image::from_channels((w, h), channels);
    let mut buf = std::io::Cursor::new(Vec::new());
    image
        .write()
        .to_buffered(&mut buf)
        .map_err(|e| RomoError::Input(format!("{}: EXR encoding failed: {e}", path.display())))?;
    Ok(loader::io::write_bytes_atomic(path, buf.get_ref())?)
}
