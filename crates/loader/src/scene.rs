//! The scene folder (see `docs/design.md`, "Conventions"): frames in capture order (sorted file
//! names in `images/`), cameras and poses (from `sparse/0`, else
//! `transforms.json`), masks (`masks/<name>.png`, 255 keep), the
//! NeRF On-the-go split and ground-truth motion (`gt_motion/<stem>.png`).
//! A downscale factor N reads `images_N/` when present, else resizes on load;
//! intrinsics are scaled to the loaded size either way.

use crate::camera::{Camera, Intrinsics, Pose};
use crate::colmap::{ColmapModel, find_model_dir, read_model};
use crate::error::{LoaderError, Result};
use crate::masks::{
    check_size, gt_motion_path, mask_path, read_mask, read_mask_nonzero, read_moving,
};
use crate::split::{ResolvedSplit, read_split};
use crate::transforms::read_transforms;
use image::imageops::FilterType;
use image::{GrayImage, Rgb32FImage};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// One frame of a scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Frame {
    /// Image file name relative to `images/` (e.g. `0001.jpg`); this is the
    /// key used by COLMAP, masks (`masks/<name>.png`) and split.json.
    pub name: String,
    /// Full path of the image file actually read (may be in `images_N/`).
    pub image_path: PathBuf,
    /// Pinhole intrinsics at the loaded resolution (after downscale).
    pub intrinsics: Intrinsics,
    /// The full COLMAP camera at the original resolution, when known.
    pub camera: Option<Camera>,
    /// World-to-camera pose (COLMAP convention), when known.
    pub pose: Option<Pose>,
    /// `masks/<name>.png` when present (255 keep, 0 moving), else the
    /// frame's nerfstudio `mask_path` from transforms.json.
    pub mask_path: Option<PathBuf>,
    /// The mask is a nerfstudio one: nonzero keeps, 0 ignores (masks/
    /// files are binarised at 128 instead).
    pub mask_nonzero_keeps: bool,
    /// `gt_motion/<stem>.png` when present (255 moving).
    pub gt_motion_path: Option<PathBuf>,
}

/// Smallest image side (pixels) a scene may be loaded at: below one 16×16
/// tile, SSIM's 11-pixel window and the rasteriser's tiles degenerate.
pub const MIN_SIDE: u32 = 16;

/// How to load a scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SceneOptions {
    /// Integer downscale factor (1 = full resolution). Uses `images_N/` when
    /// it exists, else resizes on load (triangle filter). Default 1.
    pub downscale: u32,
}

impl Default for SceneOptions {
    fn default() -> Self {
        SceneOptions { downscale: 1 }
    }
}

impl SceneOptions {
    /// Check the options.
    pub fn validate(&self) -> Result<()> {
        if self.downscale == 0 {
            return Err(LoaderError::Invalid("downscale must be >= 1".into()));
        }
        Ok(())
    }
}

/// Where a scene's poses came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PoseSource {
    Colmap,
    Transforms,
    None,
}

/// A loaded scene folder.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene folder.
    pub root: PathBuf,
    /// Frames in capture order (sorted image file names).
    pub frames: Vec<Frame>,
    /// split.json resolved to frame indices, when present.
    pub split: Option<ResolvedSplit>,
    /// The downscale factor the scene was loaded with.
    pub downscale: u32,
    /// The COLMAP model, when the scene has `sparse/0` (or `sparse/`).
    pub model: Option<ColmapModel>,
    /// Where poses came from.
    pub pose_source: PoseSource,
    /// Original (full-resolution) size of each frame's `images/` file.
    full_sizes: Vec<(u32, u32)>,
}

/// True for file names the loader treats as images.
pub fn is_image_name(name: &str) -> bool {
    let ext = Path::new(name)
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg"))
}

/// Sorted image file names in `dir` (error when missing or empty).
pub fn list_images(dir: &Path) -> Result<Vec<String>> {
    let rd = std::fs::read_dir(dir).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            LoaderError::Missing {
                path: dir.to_path_buf(),
                context: "image folder".into(),
            }
        } else {
            LoaderError::io(dir, e)
        }
    })?;
    let mut names = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| LoaderError::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if is_image_name(&name) && entry.path().is_file() {
            names.push(name);
        }
    }
    if names.is_empty() {
        return Err(LoaderError::format(
            dir,
            "no images (.png/.jpg/.jpeg) in folder",
        ));
    }
    names.sort();
    Ok(names)
}

fn dims(path: &Path) -> Result<(u32, u32)> {
    image::image_dimensions(path).map_err(|e| LoaderError::image(path, e))
}

/// Intrinsics used when nothing is known: COLMAP's default prior
/// (focal = 1.2 · max(w, h), principal point at the centre).
pub fn default_intrinsics(width: u32, height: u32) -> Intrinsics {
    let f = 1.2 * width.max(height) as f64;
    Intrinsics {
        width,
        height,
        fx: f,
        fy: f,
        cx: width as f64 / 2.0,
        cy: height as f64 / 2.0,
    }
}

impl Scene {
    /// Load the scene folder `root`.
    pub fn load(root: impl AsRef<Path>, opts: &SceneOptions) -> Result<Scene> {
        opts.validate()?;
        let root = root.as_ref().to_path_buf();
        let images_dir = root.join("images");
        let names = list_images(&images_dir)?;
        let n = opts.downscale;
        let down_dir = root.join(format!("images_{n}"));
        let use_down = n > 1 && down_dir.is_dir();

        // Poses and cameras: sparse/0 preferred, then transforms.json.
        let mut cams: HashMap<String, (Camera, Pose)> = HashMap::new();
        let mut model = None;
        let mut pose_source = PoseSource::None;
        if let Some(dir) = find_model_dir(&root) {
            let m = read_model(&dir)?;
            for im in m.images.values() {
                if let Some(c) = m.cameras.get(&im.camera_id) {
                    cams.insert(im.name.clone(), (c.clone(), im.pose));
                }
            }
            model = Some(m);
            pose_source = PoseSource::Colmap;
        } else {
            let tp = root.join("transforms.json");
            if tp.is_file() {
                for f in read_transforms(&tp)?.resolve(&tp, &root)? {
                    cams.insert(f.name, (f.camera, f.pose));
                }
                pose_source = PoseSource::Transforms;
            }
        }

        // nerfstudio masks: each frame's `mask_path` in transforms.json,
        // resolved against the file's real folder (a linked copy still
        // finds them); used where masks/<name>.png is absent.
        let tp = root.join("transforms.json");
        let ns_masks: HashMap<String, PathBuf> = match read_transforms(&tp) {
            Ok(t) if tp.is_file() => {
                let base = tp
                    .canonicalize()
                    .ok()
                    .and_then(|p| p.parent().map(Path::to_path_buf))
                    .unwrap_or_else(|| root.clone());
                t.mask_paths(&tp, &base)?.into_iter().collect()
            }
            // transforms.json unreadable: an error when it gives the poses
            // (reported above), otherwise not used.
            _ => HashMap::new(),
        };

        let mut frames = Vec::with_capacity(names.len());
        let mut full_sizes = Vec::with_capacity(names.len());
        for name in &names {
            let full_path = images_dir.join(name);
            let full = dims(&full_path)?;
            let (image_path, loaded) = match use_down
                .then(|| down_dir.join(name))
                .filter(|p| p.is_file())
            {
                Some(p) => {
                    let d = dims(&p)?;
                    (p, d)
                }
                None => {
                    let s = |v: u32| ((v as f64 / n as f64).round() as u32).max(1);
                    (full_path, (s(full.0), s(full.1)))
                }
            };
            if n > 1 && loaded.0.min(loaded.1) < MIN_SIDE {
                let largest = (full.0.min(full.1) as f64 / (MIN_SIDE as f64 - 0.5))
                    .floor()
                    .max(1.0);
                return Err(LoaderError::Invalid(format!(
                    "downscale {n} leaves {}x{} px of {} ({}x{}); images need at least {MIN_SIDE} px per side, so use a downscale from 1 to {largest}",
                    loaded.0,
                    loaded.1,
                    image_path.display(),
                    full.0,
                    full.1
                )));
            }
            let (camera, pose) = match cams.get(name) {
                Some((c, p)) => (Some(c.clone()), Some(*p)),
                None => (None, None),
            };
            let intrinsics = match &camera {
                Some(c) if c.width > 0 && c.height > 0 => {
                    c.intrinsics().scaled_to(loaded.0, loaded.1)
                }
                _ => default_intrinsics(full.0, full.1).scaled_to(loaded.0, loaded.1),
            };
            let mp = mask_path(&root.join("masks"), name);
            let ns = ns_masks.get(name).filter(|_| !mp.is_file());
            let mp = ns.cloned().unwrap_or(mp);
            // A mask must have its image's size.
            let check_size = |p: &Path, what: &str| -> Result<()> {
                let d = dims(p)?;
                if d != full {
                    return Err(LoaderError::format(
                        p,
                        format!(
                            "{what} is {}x{} but its image {name} is {}x{}",
                            d.0, d.1, full.0, full.1
                        ),
                    ));
                }
                Ok(())
            };
            let mask_path = if mp.is_file() {
                check_size(&mp, "mask")?;
                Some(mp)
            } else {
                None
            };
            let gp = gt_motion_path(&root.join("gt_motion"), name);
            if gp.is_file() {
                check_size(&gp, "ground-truth mask")?;
            }
            frames.push(Frame {
                name: name.clone(),
                image_path,
                intrinsics,
                camera,
                pose,
                mask_path,
                mask_nonzero_keeps: ns.is_some(),
                gt_motion_path: gp.is_file().then_some(gp),
            });
            full_sizes.push(full);
        }

        let sp = root.join("split.json");
        let split = if sp.is_file() {
            Some(read_split(&sp)?.resolve(&sp, &names)?)
        } else {
            None
        };
        Ok(Scene {
            root,
            frames,
            split,
            downscale: n,
            model,
            pose_source,
            full_sizes,
        })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// True when the scene has no frames (never after a successful load).
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Image file names in capture order.
    pub fn names(&self) -> Vec<String> {
        self.frames.iter().map(|f| f.name.clone()).collect()
    }

    /// Index of the frame with this image name.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.frames.iter().position(|f| f.name == name)
    }

    /// Frame indices of a split (`clutter`/`train`, `extra`/`test`, `clean`);
    /// without split.json, `train` is every frame and `test` is empty.
    pub fn split_indices(&self, which: &str) -> Vec<usize> {
        match &self.split {
            Some(s) => s.get(which).map(|v| v.to_vec()).unwrap_or_default(),
            None if matches!(which, "clutter" | "train") => (0..self.len()).collect(),
            None => Vec::new(),
        }
    }

    /// Original size of frame `i`'s image in `images/`.
    pub fn full_size(&self, i: usize) -> Option<(u32, u32)> {
        self.full_sizes.get(i).copied()
    }

    fn frame(&self, i: usize) -> Result<&Frame> {
        self.frames.get(i).ok_or_else(|| {
            LoaderError::Invalid(format!(
                "frame index {i} out of range ({} frames)",
                self.frames.len()
            ))
        })
    }

    /// Frame `i`'s image as RGB f32 in [0, 1] at the loaded resolution.
    pub fn load_image(&self, i: usize) -> Result<Rgb32FImage> {
        let f = self.frame(i)?;
        let img = crate::io::read_rgb32f(&f.image_path)?;
        let (w, h) = (f.intrinsics.width, f.intrinsics.height);
        if img.dimensions() == (w, h) {
            Ok(img)
        } else {
            Ok(image::imageops::resize(&img, w, h, FilterType::Triangle))
        }
    }

    /// Frame `i`'s keep-mask (255 keep, 0 moving) at the loaded resolution
    /// (nearest-neighbour resize), or `None` when it has no mask.
    pub fn load_mask(&self, i: usize) -> Result<Option<GrayImage>> {
        let f = self.frame(i)?;
        let Some(p) = &f.mask_path else {
            return Ok(None);
        };
        let m = if f.mask_nonzero_keeps {
            read_mask_nonzero(p)?
        } else {
            read_mask(p)?
        };
        self.load_sized(i, m, p).map(Some)
    }

    /// Frame `i`'s ground-truth motion (255 moving) at the loaded resolution.
    pub fn load_gt_motion(&self, i: usize) -> Result<Option<GrayImage>> {
        let f = self.frame(i)?;
        let Some(p) = &f.gt_motion_path else {
            return Ok(None);
        };
        self.load_sized(i, read_moving(p)?, p).map(Some)
    }

    fn load_sized(&self, i: usize, m: GrayImage, path: &Path) -> Result<GrayImage> {
        let f = self.frame(i)?;
        let (fw, fh) = self
            .full_size(i)
            .unwrap_or((f.intrinsics.width, f.intrinsics.height));
        check_size(path, &m, fw, fh)?;
        let (w, h) = (f.intrinsics.width, f.intrinsics.height);
        Ok(if m.dimensions() == (w, h) {
            m
        } else {
            image::imageops::resize(&m, w, h, FilterType::Nearest)
        })
    }
}

#[cfg(test)]
#[path = "scene_tests.rs"]
mod tests;
