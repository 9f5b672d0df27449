//! Writing a generated scene: PNG frames, clean oracle frames and motion
//! masks, and the ground-truth model (COLMAP `sparse/0` in text and binary,
//! transforms.json, split.json) through the loader's own writers.

use super::{RenderedView, SceneSpec, SurfacePoint, raster::Resolved};
use crate::camera::{Camera, CameraModel, Intrinsics};
use crate::colmap::{
    ColmapImage, ColmapModel, Point2D, Point3D, write_model_binary, write_model_text,
};
use crate::error::{LoaderError, Result};
use crate::io::{write_png_gray8, write_png_rgb8};
use crate::split::{Split, write_split};
use crate::transforms::{Transforms, write_transforms};
use image::{GrayImage, RgbImage};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_pcg::Pcg64;
use std::path::Path;

fn rgb(intr: &Intrinsics, data: &[u8], path: &Path) -> Result<RgbImage> {
    RgbImage::from_raw(intr.width, intr.height, data.to_vec())
        .ok_or_else(|| LoaderError::format(path, "internal: image buffer size mismatch"))
}

/// Write `images/<name>`, `gt_motion/<stem>.png` and, for training frames,
/// `clean/<name>`.
pub(crate) fn write_frame(
    out: &Path,
    intr: &Intrinsics,
    name: &str,
    r: &Resolved,
    mask: &[u8],
    training: bool,
) -> Result<()> {
    let img_path = out.join("images").join(name);
    write_png_rgb8(&img_path, &rgb(intr, &r.frame, &img_path)?)?;
    if training {
        let p = out.join("clean").join(name);
        write_png_rgb8(&p, &rgb(intr, &r.clean, &p)?)?;
    }
    let stem = Path::new(name)
        .file_stem()
        .map_or_else(|| name.to_string(), |s| s.to_string_lossy().into_owned());
    let p = out.join("gt_motion").join(format!("{stem}.png"));
    let m = GrayImage::from_raw(intr.width, intr.height, mask.to_vec())
        .ok_or_else(|| LoaderError::format(&p, "internal: mask size mismatch"))?;
    write_png_gray8(&p, &m)
}

/// The ground-truth sparse model before it is handed to the COLMAP writer.
pub(crate) struct GtModel {
    /// Kept candidates, in point-id order (id = index + 1).
    pub points: Vec<usize>,
    /// Per point: (image index, observation index within that image).
    pub tracks: Vec<Vec<(usize, usize)>>,
    /// Per image: (x, y, point index) observations.
    pub obs: Vec<Vec<(f64, f64, usize)>>,
}

/// Keep candidates seen in at least two views, at most `spec.points3d` of
/// them (a seeded random subset), and build tracks and observations.
pub(crate) fn build_model(
    spec: &SceneSpec,
    views: &[RenderedView],
    n_candidates: usize,
) -> GtModel {
    let mut count = vec![0usize; n_candidates];
    for v in views {
        for (i, _, _) in &v.seen {
            count[*i] += 1;
        }
    }
    let mut keep: Vec<usize> = (0..n_candidates).filter(|i| count[*i] >= 2).collect();
    let mut rng = Pcg64::seed_from_u64(super::mix64(spec.seed ^ 0x7001_0004));
    keep.shuffle(&mut rng);
    keep.truncate(spec.points3d as usize);
    keep.sort_unstable();
    let mut id_of = vec![usize::MAX; n_candidates];
    for (pid, c) in keep.iter().enumerate() {
        id_of[*c] = pid;
    }
    let mut tracks = vec![Vec::new(); keep.len()];
    let mut obs = Vec::with_capacity(views.len());
    for (vi, v) in views.iter().enumerate() {
        let mut o = Vec::new();
        for (c, x, y) in &v.seen {
            let pid = id_of[*c];
            if pid != usize::MAX {
                tracks[pid].push((vi, o.len()));
                o.push((*x, *y, pid));
            }
        }
        obs.push(o);
    }
    GtModel {
        points: keep,
        tracks,
        obs,
    }
}

/// The ground-truth COLMAP model: one PINHOLE camera, every view as an
/// image (id = index + 1) with its exact observations, and the kept points
/// (error 0: observations are exact projections).
pub(crate) fn colmap_model(
    spec: &SceneSpec,
    intr: &Intrinsics,
    views: &[RenderedView],
    pts: &[SurfacePoint],
) -> ColmapModel {
    let gt = build_model(spec, views, pts.len());
    let mut model = ColmapModel::default();
    let camera = Camera {
        id: 1,
        model: CameraModel::PINHOLE,
        width: intr.width as u64,
        height: intr.height as u64,
        params: vec![intr.fx, intr.fy, intr.cx, intr.cy],
    };
    model.cameras.insert(1, camera);
    for (vi, (v, obs)) in views.iter().zip(&gt.obs).enumerate() {
        let id = vi as u32 + 1;
        let mut im = ColmapImage::new(id, v.pose, 1, v.name.clone());
        im.points2d = obs
            .iter()
            .map(|(x, y, pid)| Point2D {
                xy: [*x, *y],
                point3d_id: Some(*pid as u64 + 1),
            })
            .collect();
        model.images.insert(id, im);
    }
    for (pid, (c, track)) in gt.points.iter().zip(&gt.tracks).enumerate() {
        let p = &pts[*c];
        let id = pid as u64 + 1;
        let track = track
            .iter()
            .map(|(vi, oi)| (*vi as u32 + 1, *oi as u32))
            .collect();
        model.points3d.insert(
            id,
            Point3D {
                id,
                xyz: [p.xyz.x, p.xyz.y, p.xyz.z],
                rgb: p.rgb,
                error: 0.0,
                track,
            },
        );
    }
    model
}

/// Write `sparse/0` (text and binary), `transforms.json` and `split.json`.
/// Returns (number of points, number of observations).
pub(crate) fn write_model(
    out: &Path,
    spec: &SceneSpec,
    intr: &Intrinsics,
    views: &[RenderedView],
    pts: &[SurfacePoint],
) -> Result<(usize, usize)> {
    let model = colmap_model(spec, intr, views, pts);
    let sparse = out.join("sparse").join("0");
    write_model_text(&model, &sparse)?;
    write_model_binary(&model, &sparse)?;
    let tf = out.join("transforms.json");
    let transforms =
        Transforms::from_model(&model, "images/").map_err(|e| LoaderError::format(&tf, e))?;
    write_transforms(&tf, &transforms)?;
    let (train, test): (Vec<_>, Vec<_>) = views
        .iter()
        .map(|v| v.name.clone())
        .partition(|n| !n.starts_with("test_"));
    write_split(
        out.join("split.json"),
        &Split::from_names(&train, &test, None),
    )?;
    let n_obs = model.images.values().map(|im| im.points2d.len()).sum();
    Ok((model.points3d.len(), n_obs))
}
