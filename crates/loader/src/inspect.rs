//! `romosplat inspect`: a summary of whatever is at a path — a scene folder,
//! a COLMAP model folder (or a folder holding `sparse/0`), a transforms.json
//! or a splat PLY — as a serialisable report.

use crate::camera::Camera;
use crate::colmap::{ColmapModel, ModelFormat, detect_format, find_model_dir, read_model};
use crate::error::{LoaderError, Result};
use crate::scene::{PoseSource, Scene, SceneOptions};
use crate::transforms::read_transforms;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// A camera and how many images use it.
#[derive(Debug, Clone, Serialize)]
pub struct CameraSummary {
    pub id: u32,
    pub model: String,
    pub width: u64,
    pub height: u64,
    pub params: Vec<f64>,
    pub images: usize,
}

/// An image size and how many images have it.
#[derive(Debug, Clone, Serialize)]
pub struct SizeCount {
    pub width: u32,
    pub height: u32,
    pub count: usize,
}

/// What `inspect` found.
#[derive(Debug, Clone, Default, Serialize)]
pub struct InspectReport {
    /// `scene`, `colmap_model`, `transforms` or `ply`.
    pub kind: String,
    pub path: String,
    /// Images in `images/` (scene) or frames listed (transforms).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub images: Option<usize>,
    /// Images with a pose.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub registered_images: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub points3d: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_track_length: Option<f64>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cameras: Vec<CameraSummary>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub image_sizes: Vec<SizeCount>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose_source: Option<PoseSource>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_format: Option<ModelFormat>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub masks: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gt_motion: Option<usize>,
    /// Split sizes (`clutter`, `extra`, `clean`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub split: Option<BTreeMap<String, usize>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub splats: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sh_degree: Option<u32>,
}

/// Group equal cameras, counting images per camera.
fn summarise_cameras(cams: &[Camera]) -> Vec<CameraSummary> {
    let mut out: Vec<CameraSummary> = Vec::new();
    for c in cams {
        match out.iter_mut().find(|s| {
            s.model == c.model.name()
                && s.width == c.width
                && s.height == c.height
                && s.params == c.params
        }) {
            Some(s) => s.images += 1,
            None => out.push(CameraSummary {
                id: c.id,
                model: c.model.name().into(),
                width: c.width,
                height: c.height,
                params: c.params.clone(),
                images: 1,
            }),
        }
    }
    out
}

fn sizes(iter: impl Iterator<Item = (u32, u32)>) -> Vec<SizeCount> {
    let mut m: BTreeMap<(u32, u32), usize> = BTreeMap::new();
    for s in iter {
        *m.entry(s).or_default() += 1;
    }
    m.into_iter()
        .map(|((width, height), count)| SizeCount {
            width,
            height,
            count,
        })
        .collect()
}

fn model_report(r: &mut InspectReport, m: &ColmapModel) {
    r.registered_images = Some(m.images.len());
    r.points3d = Some(m.points3d.len());
    let tl: usize = m.points3d.values().map(|p| p.track.len()).sum();
    r.mean_track_length = (!m.points3d.is_empty()).then(|| tl as f64 / m.points3d.len() as f64);
    r.cameras = m
        .cameras
        .values()
        .map(|c| CameraSummary {
            id: c.id,
            model: c.model.name().into(),
            width: c.width,
            height: c.height,
            params: c.params.clone(),
            images: m.images.values().filter(|i| i.camera_id == c.id).count(),
        })
        .collect();
}

/// Inspect `path` (scene folder, COLMAP model folder, transforms.json or PLY).
pub fn inspect(path: impl AsRef<Path>) -> Result<InspectReport> {
    let path = path.as_ref();
    let mut r = InspectReport {
        path: path.display().to_string(),
        ..Default::default()
    };
    if path.is_file() {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "ply" => {
                let s = crate::ply::read_ply(path)?;
                r.kind = "ply".into();
                r.splats = Some(s.len());
                r.sh_degree = Some(s.sh_degree);
            }
            "json" => {
                let base = path.parent().unwrap_or(Path::new("."));
                let frames = read_transforms(path)?.resolve(path, base)?;
                r.kind = "transforms".into();
                r.images = Some(frames.len());
                r.registered_images = Some(frames.len());
                let cams: Vec<Camera> = frames.iter().map(|f| f.camera.clone()).collect();
                r.cameras = summarise_cameras(&cams);
                r.image_sizes = sizes(cams.iter().map(|c| (c.width as u32, c.height as u32)));
                r.pose_source = Some(PoseSource::Transforms);
            }
            _ => {
                return Err(LoaderError::format(
                    path,
                    "cannot inspect: expected a folder, a .ply, .spz, .splat, .glb or a transforms .json",
                ));
            }
        }
        return Ok(r);
    }
    if !path.is_dir() {
        return Err(LoaderError::Missing {
            path: path.to_path_buf(),
            context: String::new(),
        });
    }
    if path.join("images").is_dir() {
        let s = Scene::load(path, &SceneOptions::default())?;
        r.kind = "scene".into();
        r.images = Some(s.len());
        r.registered_images = Some(s.frames.iter().filter(|f| f.pose.is_some()).count());
        r.pose_source = Some(s.pose_source);
        r.image_sizes = sizes((0..s.len()).filter_map(|i| s.full_size(i)));
        r.masks = Some(s.frames.iter().filter(|f| f.mask_path.is_some()).count());
        r.gt_motion = Some(
            s.frames
                .iter()
                .filter(|f| f.gt_motion_path.is_some())
                .count(),
        );
        r.split = s.split.as_ref().map(|sp| {
            let mut m = BTreeMap::from([
                ("clutter".to_string(), sp.clutter.len()),
                ("extra".into(), sp.extra.len()),
            ]);
            if let Some(c) = &sp.clean {
                m.insert("clean".into(), c.len());
            }
            m
        });
        if let Some(m) = &s.model {
            model_report(&mut r, m);
            r.registered_images = Some(s.frames.iter().filter(|f| f.pose.is_some()).count());
            r.model_format = find_model_dir(path).and_then(|d| detect_format(&d));
        } else {
            let cams: Vec<Camera> = s.frames.iter().filter_map(|f| f.camera.clone()).collect();
            r.cameras = summarise_cameras(&cams);
        }
        return Ok(r);
    }
    if let Some(dir) = find_model_dir(path) {
        let m = read_model(&dir)?;
        r.kind = "colmap_model".into();
        r.model_format = detect_format(&dir);
        r.images = Some(m.images.len());
        model_report(&mut r, &m);
        return Ok(r);
    }
    Err(LoaderError::format(
        path,
        "cannot inspect: no images/, no COLMAP model (cameras.bin/txt, sparse/0), not a .ply or .json",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{CameraModel, Pose};
    use crate::colmap::{ColmapImage, Point3D, write_model_text};

    #[test]
    fn reports_scene_model_transforms_and_ply() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        for n in ["a.png", "b.png"] {
            crate::io::write_png_rgb8(root.join("images").join(n), &image::RgbImage::new(8, 6))
                .unwrap();
        }
        let mut m = ColmapModel::default();
        m.cameras.insert(
            1,
            Camera {
                id: 1,
                model: CameraModel::SIMPLE_RADIAL,
                width: 8,
                height: 6,
                params: vec![9.0, 4.0, 3.0, 0.01],
            },
        );
        m.images
            .insert(1, ColmapImage::new(1, Pose::identity(), 1, "a.png"));
        m.points3d.insert(
            3,
            Point3D {
                id: 3,
                xyz: [0.0; 3],
                rgb: [0; 3],
                error: 0.5,
                track: vec![(1, 0), (1, 1)],
            },
        );
        write_model_text(&m, root.join("sparse/0")).unwrap();
        let r = inspect(root).unwrap();
        assert_eq!(r.kind, "scene");
        assert_eq!(
            (r.images, r.registered_images, r.points3d),
            (Some(2), Some(1), Some(1))
        );
        assert_eq!(r.cameras[0].model, "SIMPLE_RADIAL");
        assert_eq!(r.image_sizes[0].count, 2);
        assert_eq!(r.mean_track_length, Some(2.0));
        assert_eq!(r.model_format, Some(ModelFormat::Text));

        let r = inspect(root.join("sparse/0")).unwrap();
        assert_eq!(r.kind, "colmap_model");
        assert_eq!(r.registered_images, Some(1));

        let t = crate::transforms::Transforms::from_model(&m, "images/").unwrap();
        crate::transforms::write_transforms(root.join("transforms.json"), &t).unwrap();
        let r = inspect(root.join("transforms.json")).unwrap();
        assert_eq!(r.kind, "transforms");
        assert_eq!(r.cameras.len(), 1);
        assert_eq!(r.cameras[0].model, "OPENCV");
        assert_eq!(
            r.cameras[0].params,
            vec![9.0, 9.0, 4.0, 3.0, 0.01, 0.0, 0.0, 0.0]
        );

        let s = crate::ply::PlySplats {
            means: vec![[0.0; 3]; 4],
            f_dc: vec![[0.0; 3]; 4],
            f_rest: vec![0.0; 4 * 9],
            opacities: vec![0.0; 4],
            scales: vec![[0.0; 3]; 4],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; 4],
            sh_degree: 1,
            normals: None,
        };
        crate::ply::write_ply(root.join("s.ply"), &s).unwrap();
        let r = inspect(root.join("s.ply")).unwrap();
        assert_eq!((r.splats, r.sh_degree), (Some(4), Some(1)));
        let e = inspect(root.join("images")).unwrap_err().to_string();
        assert!(e.contains("cannot inspect"), "{e}");
    }
}
