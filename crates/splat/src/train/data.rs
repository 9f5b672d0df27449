//! Training and evaluation views from a [`loader::Scene`]: cameras, target
//! images and keep-masks in memory, the scene extent (INRIA
//! `getNerfppNorm`), and the initial splats from the scene's COLMAP points
//! (skipping points seen mostly on moving pixels) or at random.

use super::options::{InitMode, TrainOptions};
use crate::backend::{LearningRates, LossConfig, StepInput};
use crate::error::{Result, SplatError};
use crate::init::{ObservedPoint, filter_points, random_splats, splats_from_points};
use crate::types::{RenderCamera, RenderOptions, Splats};
use loader::Scene;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// One view in memory.
#[derive(Debug, Clone)]
pub struct View {
    /// Frame index in the scene.
    pub index: usize,
    pub name: String,
    pub camera: RenderCamera,
    /// RGB f32 in [0, 1], `w×h×3`.
    pub image: Vec<f32>,
    /// Keep weights (`w×h`, 1 keep / 0 moving) when masks are used.
    pub mask: Option<Vec<f32>>,
}

impl View {
    /// One training step on this view with these rates, loss and render
    /// options (the view's index is its device-cache id).
    pub fn step_input(
        &self,
        lr: LearningRates,
        loss: LossConfig,
        render: RenderOptions,
    ) -> StepInput<'_> {
        StepInput {
            camera: &self.camera,
            target: &self.image,
            mask: self.mask.as_deref(),
            view_id: Some(self.index),
            lr,
            loss,
            render,
        }
    }
}

/// Views to train on and the scene extent.
#[derive(Debug, Clone)]
pub struct TrainData {
    pub views: Vec<View>,
    /// INRIA `cameras_extent`.
    pub extent: f32,
}

/// How the model was initialised.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct InitReport {
    /// `points` or `random`.
    pub source: String,
    pub splats: usize,
    /// COLMAP points skipped because most observations were on moving pixels.
    pub skipped_moving: usize,
}

/// Camera of frame `i` (error when it has no pose).
pub fn camera_of(scene: &Scene, i: usize) -> Result<RenderCamera> {
    let f = scene
        .frames
        .get(i)
        .ok_or_else(|| SplatError::Invalid(format!("no frame {i}")))?;
    let pose = f.pose.as_ref().ok_or_else(|| {
        SplatError::Invalid(format!(
            "{}: frame {} has no pose",
            scene.root.display(),
            f.name
        ))
    })?;
    Ok(RenderCamera::from_loader(&f.intrinsics, pose))
}

/// Load views `indices`; with `masks`, each frame's `masks/` file (when
/// present) becomes its keep-weights.
pub fn load_views(scene: &Scene, indices: &[usize], masks: bool) -> Result<Vec<View>> {
    use rayon::prelude::*;
    indices
        .par_iter()
        .map(|&i| {
            let camera = camera_of(scene, i)?;
            let img = scene.load_image(i)?;
            let image: Vec<f32> = img.into_raw();
            if image.len() != (camera.width * camera.height * 3) as usize {
                return Err(SplatError::Invalid(format!(
                    "frame {i}: image size disagrees with intrinsics"
                )));
            }
            let mask = if masks {
                scene.load_mask(i)?.map(|m| {
                    m.into_raw()
                        .into_iter()
                        .map(|v| if v >= 128 { 1.0 } else { 0.0 })
                        .collect()
                })
            } else {
                None
            };
            Ok(View {
                index: i,
                name: scene.frames[i].name.clone(),
                camera,
                image,
                mask,
            })
        })
        .collect()
}

/// INRIA `getNerfppNorm`: 1.1 × the largest distance of a camera centre from
/// the mean centre (1.0 when there is a single camera or they coincide).
pub fn scene_extent(cams: &[RenderCamera]) -> f32 {
    if cams.is_empty() {
        return 1.0;
    }
    let cs: Vec<[f32; 3]> = cams.iter().map(|c| c.center()).collect();
    let mut m = [0.0f32; 3];
    for c in &cs {
        for a in 0..3 {
            m[a] += c[a] / cs.len() as f32;
        }
    }
    let d = cs
        .iter()
        .map(|c| (0..3).map(|a| (c[a] - m[a]).powi(2)).sum::<f32>().sqrt())
        .fold(0.0f32, f32::max);
    if d > 1e-6 { 1.1 * d } else { 1.0 }
}

/// COLMAP points with their observations checked against keep-masks.
pub fn observed_points(scene: &Scene, use_masks: bool) -> Result<Vec<ObservedPoint>> {
    let Some(model) = &scene.model else {
        return Ok(Vec::new());
    };
    let mut masks: HashMap<u32, Option<(image::GrayImage, f64, f64)>> = HashMap::new();
    if use_masks {
        for (id, im) in &model.images {
            let entry = match scene.index_of(&im.name) {
                Some(fi) => match scene.load_mask(fi)? {
                    Some(m) => {
                        let cam = model.cameras.get(&im.camera_id);
                        let (cw, ch) = cam.map_or((m.width() as f64, m.height() as f64), |c| {
                            (c.width as f64, c.height as f64)
                        });
                        Some((m.clone(), m.width() as f64 / cw, m.height() as f64 / ch))
                    }
                    None => None,
                },
                None => None,
            };
            masks.insert(*id, entry);
        }
    }
    let mut out = Vec::with_capacity(model.points3d.len());
    for p in model.points3d.values() {
        let (mut checked, mut on_moving) = (0, 0);
        for &(img_id, p2d) in &p.track {
            let Some(Some((m, sx, sy))) = masks.get(&img_id) else {
                continue;
            };
            let Some(kp) = model
                .images
                .get(&img_id)
                .and_then(|im| im.points2d.get(p2d as usize))
            else {
                continue;
            };
            let (x, y) = ((kp.xy[0] * sx).floor(), (kp.xy[1] * sy).floor());
            if x < 0.0 || y < 0.0 || x >= m.width() as f64 || y >= m.height() as f64 {
                continue;
            }
            checked += 1;
            if m.get_pixel(x as u32, y as u32).0[0] < 128 {
                on_moving += 1;
            }
        }
        out.push(ObservedPoint {
            xyz: p.xyz.map(|v| v as f32),
            rgb: p.rgb.map(|v| v as f32 / 255.0),
            checked,
            on_moving,
        });
    }
    Ok(out)
}

/// Initial splats for a scene according to `opts.init`.
pub fn initial_splats(
    scene: &Scene,
    cams: &[RenderCamera],
    extent: f32,
    opts: &TrainOptions,
) -> Result<(Splats, InitReport)> {
    let pts = match opts.init {
        InitMode::Random => Vec::new(),
        _ => observed_points(scene, opts.use_masks)?,
    };
    if opts.init == InitMode::Points && pts.is_empty() {
        return Err(SplatError::Invalid(format!(
            "{}: no COLMAP points3D to initialise from",
            scene.root.display()
        )));
    }
    if !pts.is_empty() {
        let (kept, skipped) = filter_points(&pts, opts.init_max_moving_fraction);
        if !kept.is_empty() {
            let xyz: Vec<[f32; 3]> = kept.iter().map(|p| p.xyz).collect();
            let rgb: Vec<[f32; 3]> = kept.iter().map(|p| p.rgb).collect();
            let s = splats_from_points(&xyz, &rgb, opts.sh_degree);
            let rep = InitReport {
                source: "points".into(),
                splats: s.len(),
                skipped_moving: skipped,
            };
            return Ok((s, rep));
        }
    }
    let centers: Vec<[f32; 3]> = cams.iter().map(|c| c.center()).collect();
    let s = random_splats(
        &centers,
        extent,
        opts.random_init_count,
        opts.sh_degree,
        opts.seed,
    );
    let rep = InitReport {
        source: "random".into(),
        splats: s.len(),
        skipped_moving: 0,
    };
    Ok((s, rep))
}
