//! transforms.json in the nerfstudio and instant-ngp variants: global or
//! per-frame intrinsics (`fl_x fl_y cx cy w h`), `camera_angle_x` only (NeRF
//! synthetic), OpenCV distortion `k1 k2 p1 p2` (→ COLMAP `OPENCV`), fisheye
//! `k1..k4` (→ `OPENCV_FISHEYE`), `aabb_scale`, and `file_path`s with or
//! without an extension.
//!
//! Poses there are camera-to-world with OpenGL camera axes (x right, y up,
//! z backward). This module is the ONE place that converts them to COLMAP's
//! world-to-camera with OpenCV axes: `c2w_cv = c2w_gl · diag(1, -1, -1, 1)`,
//! `w2c = c2w_cv⁻¹`. The world frame itself is left unchanged.

use crate::camera::{Camera, CameraModel, Pose};
use crate::colmap::ColmapModel;
use crate::error::{LoaderError, Result};
use crate::io::{read_string, write_atomic};
use nalgebra::{Matrix3, Matrix4, Vector3};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Intrinsics fields that may appear globally or per frame. Missing per-frame
/// fields fall back to the global ones.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct IntrinsicFields {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera_model: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera_angle_x: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera_angle_y: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fl_x: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fl_y: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cx: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cy: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub h: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k1: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k2: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k3: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k4: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p1: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p2: Option<f64>,
}

impl IntrinsicFields {
    /// Field-wise `self` or else `global`.
    fn or(&self, g: &IntrinsicFields) -> IntrinsicFields {
        IntrinsicFields {
            camera_model: self.camera_model.clone().or_else(|| g.camera_model.clone()),
            camera_angle_x: self.camera_angle_x.or(g.camera_angle_x),
            camera_angle_y: self.camera_angle_y.or(g.camera_angle_y),
            fl_x: self.fl_x.or(g.fl_x),
            fl_y: self.fl_y.or(g.fl_y),
            cx: self.cx.or(g.cx),
            cy: self.cy.or(g.cy),
            w: self.w.or(g.w),
            h: self.h.or(g.h),
            k1: self.k1.or(g.k1),
            k2: self.k2.or(g.k2),
            k3: self.k3.or(g.k3),
            k4: self.k4.or(g.k4),
            p1: self.p1.or(g.p1),
            p2: self.p2.or(g.p2),
        }
    }

    /// The fields describing `cam` (errors for models transforms.json cannot hold).
    pub fn from_camera(cam: &Camera) -> std::result::Result<Self, String> {
        let (fx, fy) = cam.focal();
        let (cx, cy) = cam.principal_point();
        let d = cam.distortion();
        let mut f = IntrinsicFields {
            fl_x: Some(fx),
            fl_y: Some(fy),
            cx: Some(cx),
            cy: Some(cy),
            w: Some(cam.width as f64),
            h: Some(cam.height as f64),
            camera_angle_x: Some(2.0 * (cam.width as f64 / (2.0 * fx)).atan()),
            camera_angle_y: Some(2.0 * (cam.height as f64 / (2.0 * fy)).atan()),
            ..Default::default()
        };
        match cam.model {
            CameraModel::SIMPLE_PINHOLE | CameraModel::PINHOLE => {
                f.camera_model = Some("OPENCV".into());
            }
            CameraModel::SIMPLE_RADIAL | CameraModel::RADIAL | CameraModel::OPENCV => {
                f.camera_model = Some("OPENCV".into());
                f.k1 = d.first().copied();
                f.k2 = Some(d.get(1).copied().unwrap_or(0.0));
                f.p1 = Some(d.get(2).copied().unwrap_or(0.0));
                f.p2 = Some(d.get(3).copied().unwrap_or(0.0));
            }
            CameraModel::OPENCV_FISHEYE => {
                f.camera_model = Some("OPENCV_FISHEYE".into());
                f.k1 = d.first().copied();
                f.k2 = d.get(1).copied();
                f.k3 = d.get(2).copied();
                f.k4 = d.get(3).copied();
            }
            m => {
                return Err(format!(
                    "camera {}: model {} cannot be stored in transforms.json",
                    cam.id,
                    m.name()
                ));
            }
        }
        Ok(f)
    }
}

/// One entry of `frames`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransformsFrame {
    /// Image path relative to the transforms.json folder, extension optional.
    pub file_path: String,
    /// Camera-to-world, OpenGL axes, row-major 4×4 (3×4 accepted on read).
    pub transform_matrix: Vec<Vec<f64>>,
    /// Per-frame intrinsics overriding the global ones.
    #[serde(flatten)]
    pub intrinsics: IntrinsicFields,
    /// Any other keys (`sharpness`, `mask_path`, ...), kept on round trip.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

/// A whole transforms.json.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Transforms {
    /// Global intrinsics.
    #[serde(flatten)]
    pub intrinsics: IntrinsicFields,
    /// instant-ngp scene bounding box scale (a power of two).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aabb_scale: Option<f64>,
    pub frames: Vec<TransformsFrame>,
    /// Any other top-level keys, kept on round trip.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

/// A frame with its image resolved on disk and its camera in COLMAP terms.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedFrame {
    /// The image file found for `file_path`.
    pub image_path: PathBuf,
    /// Its file name (the key used by masks, COLMAP and split.json).
    pub name: String,
    /// Intrinsics as a COLMAP camera (`PINHOLE`, `OPENCV` or `OPENCV_FISHEYE`), id 0.
    pub camera: Camera,
    /// World-to-camera pose, OpenCV axes.
    pub pose: Pose,
}

const EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "PNG", "JPG", "JPEG"];

/// `diag(1, -1, -1)`: flips camera y and z between OpenGL and OpenCV axes.
fn flip() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
}

/// OpenGL camera-to-world → COLMAP world-to-camera (OpenCV axes).
pub fn pose_from_c2w_opengl(c2w: &Matrix4<f64>) -> Pose {
    let r_c2w = c2w.fixed_view::<3, 3>(0, 0).into_owned() * flip();
    let c = c2w.fixed_view::<3, 1>(0, 3).into_owned();
    let r = r_c2w.transpose();
    Pose::from_rt(&r, &(-(r * c)))
}

/// COLMAP world-to-camera → OpenGL camera-to-world.
pub fn c2w_opengl_from_pose(pose: &Pose) -> Matrix4<f64> {
    let mut m = pose.camera_to_world();
    let r = m.fixed_view::<3, 3>(0, 0).into_owned() * flip();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    m
}

fn matrix_from_rows(path: &Path, idx: usize, rows: &[Vec<f64>]) -> Result<Matrix4<f64>> {
    if !(rows.len() == 3 || rows.len() == 4) || rows.iter().take(3).any(|r| r.len() != 4) {
        return Err(LoaderError::format(
            path,
            format!("frame {idx}: transform_matrix must be 4x4 or 3x4"),
        ));
    }
    let mut m = Matrix4::identity();
    for (i, r) in rows.iter().take(3).enumerate() {
        for (j, v) in r.iter().enumerate() {
            if !v.is_finite() {
                return Err(LoaderError::format(
                    path,
                    format!("frame {idx}: transform_matrix has {v}"),
                ));
            }
            m[(i, j)] = *v;
        }
    }
    Ok(m)
}

/// Largest deviation from orthonormality (max |RᵀR − I|) and from
/// det R = 1 accepted in a camera-to-world rotation. Poses written as text
/// with 6–7 significant digits are orthonormal to ~1e-6; a scaled or sheared
/// matrix is off by far more.
pub const ROTATION_TOLERANCE: f64 = 1e-3;

/// Check that the upper-left 3×3 of a camera-to-world matrix is a proper
/// rotation (orthonormal, determinant +1), saying by how much it is not.
pub fn check_rotation(m: &Matrix4<f64>) -> std::result::Result<(), String> {
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let dev = (r.transpose() * r - Matrix3::identity()).amax();
    if dev.is_nan() || dev > ROTATION_TOLERANCE {
        return Err(format!(
            "rotation is not orthonormal (max |RᵀR − I| = {dev:.3e}, tolerance {ROTATION_TOLERANCE:e})"
        ));
    }
    let det = r.determinant();
    if det.is_nan() || (det - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(format!(
            "rotation has determinant {det:.4} (a reflection, not a rotation)"
        ));
    }
    Ok(())
}

/// True when `p` lies inside `base`, compared lexically (`..` resolved
/// without following symlinks, so a scene whose `images/` is a link
/// still counts as inside).
pub fn is_inside(base: &Path, p: &Path) -> bool {
    fn norm(p: &Path) -> Option<Vec<std::ffi::OsString>> {
        let abs = if p.is_absolute() {
            p.to_path_buf()
        } else {
            std::env::current_dir().ok()?.join(p)
        };
        let mut out: Vec<std::ffi::OsString> = Vec::new();
        for c in abs.components() {
            match c {
                std::path::Component::ParentDir => {
                    out.pop()?;
                }
                std::path::Component::CurDir => {}
                other => out.push(other.as_os_str().to_owned()),
            }
        }
        Some(out)
    }
    match (norm(base), norm(p)) {
        (Some(b), Some(q)) => q.len() > b.len() && q.starts_with(&b),
        _ => false,
    }
}

/// Read and parse a transforms.json (no file checks; see [`Transforms::resolve`]).
pub fn read_transforms(path: impl AsRef<Path>) -> Result<Transforms> {
    let path = path.as_ref();
    let text = read_string(path)?;
    serde_json::from_str(&text)
        .map_err(|e| LoaderError::format(path, format!("invalid transforms.json: {e}")))
}

/// Write a transforms.json atomically (pretty-printed).
pub fn write_transforms(path: impl AsRef<Path>, t: &Transforms) -> Result<()> {
    let path = path.as_ref();
    let text =
        serde_json::to_string_pretty(t).map_err(|e| LoaderError::format(path, e.to_string()))?;
    write_atomic(path, |w: &mut dyn Write| {
        w.write_all(text.as_bytes())
            .map_err(|e| LoaderError::io(path, e))
    })
}

/// Find the image for a `file_path`: as given, else with each common
/// extension appended (instant-ngp / NeRF synthetic omit it).
pub fn resolve_image_path(base: &Path, file_path: &str) -> Option<PathBuf> {
    let p = base.join(file_path);
    if p.is_file() {
        return Some(p);
    }
    EXTENSIONS
        .iter()
        .map(|e| base.join(format!("{file_path}.{e}")))
        .find(|c| c.is_file())
}

/// The image a frame of the transforms file `path` lists (see
/// [`resolve_image_path`]) and its file name; missing is an error naming
/// `path`.
fn listed_image(path: &Path, base: &Path, file_path: &str) -> Result<(PathBuf, String)> {
    let image = resolve_image_path(base, file_path).ok_or_else(|| LoaderError::Missing {
        path: base.join(file_path),
        context: format!("image listed in {}", path.display()),
    })?;
    let name = image
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok((image, name))
}

impl Transforms {
    /// Build from COLMAP cameras and poses. `entries` are (file_path, camera,
    /// pose). Intrinsics are global when every camera is equal, else per frame.
    pub fn from_cameras(entries: &[(String, Camera, Pose)]) -> std::result::Result<Self, String> {
        let shared = entries.windows(2).all(|w| {
            let (a, b) = (&w[0].1, &w[1].1);
            a.model == b.model && a.width == b.width && a.height == b.height && a.params == b.params
        });
        let mut t = Transforms::default();
        if shared && let Some((_, cam, _)) = entries.first() {
            t.intrinsics = IntrinsicFields::from_camera(cam)?;
        }
        for (file_path, cam, pose) in entries {
            let m = c2w_opengl_from_pose(pose);
            t.frames.push(TransformsFrame {
                file_path: file_path.clone(),
                transform_matrix: (0..4)
                    .map(|i| (0..4).map(|j| m[(i, j)]).collect())
                    .collect(),
                intrinsics: if shared {
                    IntrinsicFields::default()
                } else {
                    IntrinsicFields::from_camera(cam)?
                },
                extra: Default::default(),
            });
        }
        Ok(t)
    }

    /// Build from a COLMAP model, images in name order, paths `{prefix}{name}`
    /// (use `"images/"` for a scene folder).
    pub fn from_model(model: &ColmapModel, prefix: &str) -> std::result::Result<Self, String> {
        let mut entries = Vec::new();
        for im in model.images_by_name() {
            let cam = model
                .cameras
                .get(&im.camera_id)
                .ok_or(format!("image {} has no camera", im.name))?;
            entries.push((format!("{prefix}{}", im.name), cam.clone(), im.pose));
        }
        Self::from_cameras(&entries)
    }

    /// Resolve every frame: find its image under `base` (the transforms.json
    /// folder; `path` names the file in errors), build its camera, convert
    /// its pose. Missing `w`/`h` are read from the image header.
    pub fn resolve(&self, path: &Path, base: &Path) -> Result<Vec<ResolvedFrame>> {
        let mut out = Vec::with_capacity(self.frames.len());
        for (idx, f) in self.frames.iter().enumerate() {
            let (image_path, name) = listed_image(path, base, &f.file_path)?;
            if !is_inside(base, &image_path) {
                return Err(LoaderError::format(
                    path,
                    format!(
                        "frame {idx}: file_path {:?} is outside the scene folder {}",
                        f.file_path,
                        base.display()
                    ),
                ));
            }
            let fields = f.intrinsics.or(&self.intrinsics);
            let camera = camera_from_fields(path, idx, &fields, &image_path)?;
            let c2w = matrix_from_rows(path, idx, &f.transform_matrix)?;
            check_rotation(&c2w).map_err(|m| {
                LoaderError::format(path, format!("frame {idx} ({}): {m}", f.file_path))
            })?;
            let pose = pose_from_c2w_opengl(&c2w);
            out.push(ResolvedFrame {
                image_path,
                name,
                camera,
                pose,
            });
        }
        Ok(out)
    }
}

/// nerfstudio's per-frame mask key: a single-channel image, path relative to
/// the transforms.json folder, the image's size; nonzero = use the pixel,
/// 0 = ignore it (nerfstudio `get_image_mask_tensor_from_path`).
pub const MASK_PATH_KEY: &str = "mask_path";

/// `path` relative to the directory `from` (both made absolute and
/// canonical where they exist); absolute when they share no root.
pub fn relative_path(path: &Path, from: &Path) -> PathBuf {
    let abs = |p: &Path| {
        p.canonicalize().unwrap_or_else(|_| {
            std::env::current_dir()
                .map(|d| d.join(p))
                .unwrap_or_else(|_| p.to_path_buf())
        })
    };
    let (p, f) = (abs(path), abs(from));
    let (pc, fc): (Vec<_>, Vec<_>) = (p.components().collect(), f.components().collect());
    let common = pc.iter().zip(&fc).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return p;
    }
    let mut out = PathBuf::new();
    for _ in common..fc.len() {
        out.push("..");
    }
    for c in &pc[common..] {
        out.push(c.as_os_str());
    }
    out
}

impl Transforms {
    /// Each frame's `mask_path` (nerfstudio), as (image file name, mask
    /// file), resolved against `base` (the transforms.json folder; `path`
    /// names the file in errors). A listed mask that does not exist, or an
    /// image that cannot be found, is an error.
    pub fn mask_paths(&self, path: &Path, base: &Path) -> Result<Vec<(String, PathBuf)>> {
        let mut out = Vec::new();
        for (idx, f) in self.frames.iter().enumerate() {
            let Some(v) = f.extra.get(MASK_PATH_KEY) else {
                continue;
            };
            let Some(m) = v.as_str() else {
                return Err(LoaderError::format(
                    path,
                    format!("frame {idx}: mask_path must be a string, not {v}"),
                ));
            };
            let image =
                resolve_image_path(base, &f.file_path).ok_or_else(|| LoaderError::Missing {
                    path: base.join(&f.file_path),
                    context: format!("image listed in {}", path.display()),
                })?;
            let mask = base.join(m);
            if !mask.is_file() {
                return Err(LoaderError::Missing {
                    path: mask,
                    context: format!("mask_path of frame {idx} in {}", path.display()),
                });
            }
            let name = image
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            out.push((name, mask));
        }
        Ok(out)
    }

    /// A copy for the folder `out_dir` with every frame's `mask_path` set to
    /// `masks_dir/<image name>.png` (romosplat's keep-masks: 255 keep,
    /// 0 ignore, single channel, the image's size — nerfstudio's
    /// convention), relative to `out_dir`. Every path stays inside
    /// `out_dir`: an image outside it is listed as `images/<name>` and
    /// returned as (source, destination) for the caller to place there
    /// (see [`write_with_masks`]). `base` is the source transforms.json
    /// folder, `path` names it in errors. Every frame must have its image
    /// and mask, and `masks_dir` must be inside `out_dir`.
    pub fn with_masks(
        &self,
        path: &Path,
        base: &Path,
        out_dir: &Path,
        masks_dir: &Path,
    ) -> Result<(Transforms, Vec<(PathBuf, PathBuf)>)> {
        self.with_masks_found_in(path, base, out_dir, masks_dir, masks_dir)
    }

    /// [`Transforms::with_masks`], with the masks that will be at
    /// `masks_dir` looked for in `present` (a staging folder).
    fn with_masks_found_in(
        &self,
        path: &Path,
        base: &Path,
        out_dir: &Path,
        masks_dir: &Path,
        present: &Path,
    ) -> Result<(Transforms, Vec<(PathBuf, PathBuf)>)> {
        let mut t = self.clone();
        let mut place = Vec::new();
        let slash = |p: PathBuf| p.to_string_lossy().replace('\\', "/");
        for (idx, f) in t.frames.iter_mut().enumerate() {
            let (image, name) = listed_image(path, base, &f.file_path)?;
            let mask = crate::masks::mask_path(masks_dir, &name);
            let found = crate::masks::mask_path(present, &name);
            if !found.is_file() {
                return Err(LoaderError::Missing {
                    path: found,
                    context: format!("mask for frame {idx} ({name}) of {}", path.display()),
                });
            }
            if !is_inside(out_dir, &mask) {
                return Err(LoaderError::format(
                    path,
                    format!(
                        "masks folder {} is not inside the output folder {}",
                        masks_dir.display(),
                        out_dir.display()
                    ),
                ));
            }
            f.file_path = if is_inside(out_dir, &image) {
                slash(relative_path(&image, out_dir))
            } else {
                let rel = Path::new("images").join(&name);
                place.push((image.clone(), out_dir.join(&rel)));
                slash(rel)
            };
            f.extra.insert(
                MASK_PATH_KEY.into(),
                serde_json::Value::String(slash(relative_path(&mask, out_dir))),
            );
        }
        Ok((t, place))
    }
}

/// Write the nerfstudio copy of the transforms.json `src` (folder `base`)
/// into `out_dir` with every frame's `mask_path` set (see
/// [`Transforms::with_masks`]). Images outside `out_dir` are hard-linked
/// (copied across file systems) to `out_dir/images/`, so the copy is a
/// self-contained scene folder with every path inside it. The copy is
/// `out_dir/transforms.json`, or `out_dir/transforms_masks.json` when that
/// would replace `src`. Returns the copy's path.
pub fn write_with_masks(
    src: &Path,
    base: &Path,
    out_dir: &Path,
    masks_dir: &Path,
) -> Result<PathBuf> {
    write_with_masks_staged(src, base, out_dir, masks_dir, out_dir)
}

/// [`write_with_masks`] for an output folder that is being staged: paths
/// are computed for `out_dir` and `masks_dir` (where the files will be), and
/// everything, masks included, is read from or written to the same relative
/// places under `stage` ([`crate::io::Staging::path`]). Returns the copy's
/// final path.
pub fn write_with_masks_staged(
    src: &Path,
    base: &Path,
    out_dir: &Path,
    masks_dir: &Path,
    stage: &Path,
) -> Result<PathBuf> {
    let staged = |p: &Path| match p.strip_prefix(out_dir) {
        Ok(rel) => stage.join(rel),
        Err(_) => p.to_path_buf(),
    };
    let (t, place) = read_transforms(src)?.with_masks_found_in(
        src,
        base,
        out_dir,
        masks_dir,
        &staged(masks_dir),
    )?;
    let mut seen = std::collections::HashSet::new();
    for (from, to) in &place {
        let to = &staged(to);
        if !seen.insert(to.clone()) {
            return Err(LoaderError::format(
                src,
                format!(
                    "two frames share the image name {}",
                    to.file_name().unwrap_or_default().to_string_lossy()
                ),
            ));
        }
        if let Some(dir) = to.parent() {
            crate::io::io_ctx(dir, std::fs::create_dir_all(dir))?;
        }
        if to.exists() {
            crate::io::io_ctx(to, std::fs::remove_file(to))?;
        }
        if std::fs::hard_link(from, to).is_err() {
            crate::io::io_ctx(to, std::fs::copy(from, to))?;
        }
    }
    let same = |a: &Path, b: &Path| matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y);
    let mut dst = out_dir.join("transforms.json");
    if same(&dst, src) {
        dst = out_dir.join("transforms_masks.json");
    }
    write_transforms(staged(&dst), &t)?;
    Ok(dst)
}

fn camera_from_fields(
    path: &Path,
    idx: usize,
    f: &IntrinsicFields,
    image: &Path,
) -> Result<Camera> {
    let (w, h) = match (f.w, f.h) {
        (Some(w), Some(h)) => (w, h),
        _ => {
            let (w, h) =
                image::image_dimensions(image).map_err(|e| LoaderError::image(image, e))?;
            (f.w.unwrap_or(w as f64), f.h.unwrap_or(h as f64))
        }
    };
    if !(w >= 1.0 && h >= 1.0) {
        return Err(LoaderError::format(
            path,
            format!("frame {idx}: bad image size {w}x{h}"),
        ));
    }
    let from_angle = |a: Option<f64>, size: f64| a.map(|a| 0.5 * size / (0.5 * a).tan());
    let fx = f.fl_x.or_else(|| from_angle(f.camera_angle_x, w));
    let fy = f.fl_y.or_else(|| from_angle(f.camera_angle_y, h));
    let (fx, fy) = match (fx, fy) {
        (Some(x), Some(y)) => (x, y),
        (Some(x), None) => (x, x),
        (None, Some(y)) => (y, y),
        (None, None) => {
            return Err(LoaderError::format(
                path,
                format!("frame {idx}: no focal length (fl_x or camera_angle_x)"),
            ));
        }
    };
    let (cx, cy) = (f.cx.unwrap_or(w / 2.0), f.cy.unwrap_or(h / 2.0));
    let z = |v: Option<f64>| v.unwrap_or(0.0);
    let fisheye = f.camera_model.as_deref() == Some("OPENCV_FISHEYE");
    let (model, params) = if fisheye {
        (
            CameraModel::OPENCV_FISHEYE,
            vec![fx, fy, cx, cy, z(f.k1), z(f.k2), z(f.k3), z(f.k4)],
        )
    } else if [f.k1, f.k2, f.p1, f.p2].iter().any(|v| z(*v) != 0.0) {
        (
            CameraModel::OPENCV,
            vec![fx, fy, cx, cy, z(f.k1), z(f.k2), z(f.p1), z(f.p2)],
        )
    } else {
        (CameraModel::PINHOLE, vec![fx, fy, cx, cy])
    };
    if params.iter().any(|v| !v.is_finite()) || fx <= 0.0 || fy <= 0.0 {
        return Err(LoaderError::format(
            path,
            format!("frame {idx}: invalid intrinsics {params:?}"),
        ));
    }
    Ok(Camera {
        id: 0,
        model,
        width: w.round() as u64,
        height: h.round() as u64,
        params,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch_png(p: &Path, w: u32, h: u32) {
        crate::io::write_png_gray8(p, &image::GrayImage::new(w, h)).unwrap();
    }

    /// Frames whose matrix is not a rotation, or whose image lies outside
    /// the scene folder, are refused naming the file and the frame.
    #[test]
    fn bad_rotations_and_outside_paths_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene");
        touch_png(&scene.join("images/a.png"), 4, 3);
        touch_png(&dir.path().join("secret.png"), 4, 3);
        let p = scene.join("transforms.json");
        let check = |file: &str, m: [[f64; 4]; 4], want: &str| {
            let t = serde_json::json!({
                "fl_x": 3.0, "w": 4, "h": 3,
                "frames": [
                    {"file_path": "images/a.png", "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
                    {"file_path": file, "transform_matrix": m},
                ]
            });
            std::fs::write(&p, t.to_string()).unwrap();
            let r = read_transforms(&p).unwrap().resolve(&p, &scene);
            match want {
                "" => assert!(r.is_ok(), "{r:?}"),
                _ => {
                    let e = r.unwrap_err().to_string();
                    assert!(
                        e.contains("transforms.json: frame 1") && e.contains(want),
                        "{e} (wanted {want})"
                    );
                }
            }
        };
        let id = [
            [1.0, 0.0, 0.0, 0.5],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        check("images/a.png", id, "");
        let mut scaled = id;
        for r in scaled.iter_mut().take(3) {
            for v in r.iter_mut().take(3) {
                *v *= 3.0;
            }
        }
        check("images/a.png", scaled, "max |RᵀR − I| = 8.000e0");
        let mut singular = id;
        singular[2] = [0.0, 0.0, 0.0, 0.0];
        check("images/a.png", singular, "not orthonormal");
        let mut mirror = id;
        mirror[0][0] = -1.0;
        check("images/a.png", mirror, "determinant -1");
        check("../secret.png", id, "outside the scene folder");
        check(
            dir.path().join("secret.png").to_str().unwrap(),
            id,
            "outside the scene folder",
        );
    }

    /// A scene folder with two 8x6 frames, a transforms.json with
    /// extensionless paths, and keep-masks (left half ignored) in `masks`.
    fn masked_scene(root: &Path, masks: &Path) {
        for n in ["a.png", "b.png"] {
            touch_png(&root.join("images").join(n), 8, 6);
            let m =
                image::GrayImage::from_fn(8, 6, |x, _| image::Luma([if x < 4 { 0 } else { 255 }]));
            crate::masks::write_mask(crate::masks::mask_path(masks, n), &m).unwrap();
        }
        let json = r#"{"fl_x": 10.0, "fl_y": 10.0, "cx": 4.0, "cy": 3.0, "w": 8.0, "h": 6.0,
            "frames": [{"file_path": "images/a", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]]},
                       {"file_path": "./images/b.png", "transform_matrix": [[1,0,0,1],[0,1,0,0],[0,0,1,2],[0,0,0,1]]}]}"#;
        std::fs::write(root.join("transforms.json"), json).unwrap();
    }

    #[test]
    fn copy_with_mask_paths_round_trips_through_the_loader() {
        let d = tempfile::tempdir().unwrap();
        let (scene, out) = (d.path().join("scene"), d.path().join("out"));
        masked_scene(&scene, &out.join("masks"));
        let src = scene.join("transforms.json");
        let before = std::fs::read(&src).unwrap();
        let dst = write_with_masks(&src, &scene, &out, &out.join("masks")).unwrap();
        assert_eq!(dst, out.join("transforms.json"));
        assert_eq!(
            std::fs::read(&src).unwrap(),
            before,
            "user's file untouched"
        );
        // Read back from the copy's folder, as nerfstudio would: every path
        // is inside it, the images are placed beside it.
        let back = read_transforms(&dst).unwrap();
        assert_eq!(back.frames[0].file_path, "images/a.png");
        assert_eq!(back.frames[1].extra["mask_path"], "masks/b.png.png");
        assert_eq!(
            std::fs::read(out.join("images/b.png")).unwrap(),
            std::fs::read(scene.join("images/b.png")).unwrap()
        );
        let frames = back.resolve(&dst, &out).unwrap();
        assert_eq!(frames[1].name, "b.png");
        assert!((frames[1].pose.center() - Vector3::new(1.0, 0.0, 2.0)).norm() < 1e-12);
        let masks = back.mask_paths(&dst, &out).unwrap();
        assert_eq!(masks.len(), 2);
        for (name, m) in masks {
            assert_eq!(m, out.join("masks").join(format!("{name}.png")));
            let img = crate::io::read_gray8(&m).unwrap();
            assert_eq!(img.dimensions(), (8, 6));
            assert_eq!(
                (img.get_pixel(0, 0).0[0], img.get_pixel(7, 5).0[0]),
                (0, 255)
            );
        }
        // The copy is a scene folder our loader reads whole, masks included.
        let opts = crate::SceneOptions { downscale: 1 };
        let loaded = crate::Scene::load(&out, &opts).unwrap();
        assert_eq!(loaded.frames.len(), 2);
        assert!(loaded.load_mask(1).unwrap().is_some());
        // Writing again over the first copy works.
        write_with_masks(&src, &scene, &out, &out.join("masks")).unwrap();
        // Masks written into the scene folder itself: the copy sits beside
        // the user's transforms.json, never replacing it, and no image moves.
        masked_scene(&scene, &scene.join("masks"));
        let before = std::fs::read(&src).unwrap();
        let dst = write_with_masks(&src, &scene, &scene, &scene.join("masks")).unwrap();
        assert_eq!(dst, scene.join("transforms_masks.json"));
        assert_eq!(std::fs::read(&src).unwrap(), before);
        let back = read_transforms(&dst).unwrap();
        assert_eq!(back.frames[0].file_path, "images/a.png");
        assert_eq!(back.frames[0].extra["mask_path"], "masks/a.png.png");
        assert_eq!(back.mask_paths(&dst, &scene).unwrap().len(), 2);
        // A frame without its mask is an error naming the file.
        std::fs::remove_file(out.join("masks/a.png.png")).unwrap();
        let e = write_with_masks(&src, &scene, &out, &out.join("masks"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("a.png.png"), "{e}");
    }

    #[test]
    fn nerfstudio_mask_paths_are_scene_masks_nonzero_keeps() {
        let d = tempfile::tempdir().unwrap();
        let root = d.path();
        masked_scene(root, &root.join("ns_masks"));
        // nerfstudio masks are often 0/1: nonzero keeps.
        let m = image::GrayImage::from_fn(8, 6, |_, y| image::Luma([u8::from(y >= 3)]));
        crate::io::write_png_gray8(root.join("ns_masks/b.png.png"), &m).unwrap();
        let src = root.join("transforms.json");
        let mut t = read_transforms(&src).unwrap();
        for (f, n) in t.frames.iter_mut().zip(["a.png", "b.png"]) {
            f.extra
                .insert(MASK_PATH_KEY.into(), format!("ns_masks/{n}.png").into());
        }
        write_transforms(&src, &t).unwrap();
        let opts = crate::SceneOptions { downscale: 1 };
        let scene = crate::Scene::load(root, &opts).unwrap();
        assert!(scene.frames.iter().all(|f| f.mask_nonzero_keeps));
        let a = scene.load_mask(0).unwrap().unwrap();
        assert_eq!((a.get_pixel(0, 0).0[0], a.get_pixel(7, 0).0[0]), (0, 255));
        let b = scene.load_mask(1).unwrap().unwrap();
        assert_eq!((b.get_pixel(0, 0).0[0], b.get_pixel(0, 5).0[0]), (0, 255));
        // masks/<name>.png, romosplat's own, wins over mask_path.
        crate::masks::write_mask(
            crate::masks::mask_path(&root.join("masks"), "a.png"),
            &image::GrayImage::from_pixel(8, 6, image::Luma([255])),
        )
        .unwrap();
        let scene = crate::Scene::load(root, &opts).unwrap();
        assert!(!scene.frames[0].mask_nonzero_keeps && scene.frames[1].mask_nonzero_keeps);
        // A listed mask that is missing, or of another size, is an error.
        crate::io::write_png_gray8(
            root.join("ns_masks/b.png.png"),
            &image::GrayImage::new(4, 3),
        )
        .unwrap();
        let e = crate::Scene::load(root, &opts).unwrap_err().to_string();
        assert!(e.contains("b.png.png") && e.contains("4x3"), "{e}");
        std::fs::remove_file(root.join("ns_masks/b.png.png")).unwrap();
        let e = crate::Scene::load(root, &opts).unwrap_err().to_string();
        assert!(e.contains("b.png.png") && e.contains("mask_path"), "{e}");
    }

    #[test]
    fn known_camera_converts_axes() {
        // OpenGL camera at (0,0,5) with identity rotation looks down -z at the origin.
        let mut c2w = Matrix4::identity();
        c2w[(2, 3)] = 5.0;
        let pose = pose_from_c2w_opengl(&c2w);
        let o = pose.transform(Vector3::zeros());
        assert!(
            (o - Vector3::new(0.0, 0.0, 5.0)).norm() < 1e-12,
            "origin in front: {o}"
        );
        // World +x is image right, world +y (GL up) is image up (negative y).
        let px = pose.transform(Vector3::x());
        let py = pose.transform(Vector3::y());
        assert!(px.x > 0.0 && py.y < 0.0);
        assert!((pose.center() - Vector3::new(0.0, 0.0, 5.0)).norm() < 1e-12);
    }

    #[test]
    fn c2w_round_trip() {
        let pose = Pose::look_at(
            Vector3::new(1.0, -2.0, 0.7),
            Vector3::new(0.2, 0.1, 0.0),
            Vector3::z(),
        );
        let m = c2w_opengl_from_pose(&pose);
        let back = pose_from_c2w_opengl(&m);
        assert!((back.world_to_camera() - pose.world_to_camera()).norm() < 1e-12);
        // The GL camera looks along its -z column.
        let fwd = -m.fixed_view::<3, 1>(0, 2).into_owned();
        let target_dir = (Vector3::new(0.2, 0.1, 0.0) - pose.center()).normalize();
        assert!((fwd - target_dir).norm() < 1e-12);
    }

    #[test]
    fn instant_ngp_global_intrinsics_and_extensionless_paths() {
        let dir = tempfile::tempdir().unwrap();
        touch_png(&dir.path().join("images/a.png"), 8, 6);
        touch_png(&dir.path().join("images/b.png"), 8, 6);
        let json = r#"{"fl_x": 100.0, "fl_y": 101.0, "cx": 4.1, "cy": 3.2, "w": 8.0, "h": 6.0,
            "k1": 0.05, "k2": -0.01, "p1": 0.001, "p2": 0.0, "aabb_scale": 4, "sharp": true,
            "frames": [{"file_path": "images/a.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]], "sharpness": 3.5},
                       {"file_path": "images/b", "transform_matrix": [[1,0,0,1],[0,1,0,0],[0,0,1,2]]}]}"#;
        let p = dir.path().join("transforms.json");
        std::fs::write(&p, json).unwrap();
        let t = read_transforms(&p).unwrap();
        assert_eq!(t.aabb_scale, Some(4.0));
        assert_eq!(t.frames[0].extra["sharpness"], 3.5);
        let r = t.resolve(&p, dir.path()).unwrap();
        assert_eq!(r[1].name, "b.png");
        assert_eq!(r[0].camera.model, CameraModel::OPENCV);
        assert_eq!(
            r[0].camera.params,
            vec![100.0, 101.0, 4.1, 3.2, 0.05, -0.01, 0.001, 0.0]
        );
        assert!((r[1].pose.center() - Vector3::new(1.0, 0.0, 2.0)).norm() < 1e-12);
        // Write → read keeps everything, including unknown keys.
        let q = dir.path().join("out.json");
        write_transforms(&q, &t).unwrap();
        assert_eq!(read_transforms(&q).unwrap(), t);
    }

    #[test]
    fn camera_angle_only_and_per_frame_intrinsics() {
        let dir = tempfile::tempdir().unwrap();
        touch_png(&dir.path().join("r_0.png"), 10, 20);
        let json = r#"{"camera_angle_x": 0.6911112070083618, "frames": [
            {"file_path": "./r_0", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
            {"file_path": "./r_0.png", "fl_x": 7.0, "w": 10, "h": 20, "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}"#;
        let p = dir.path().join("transforms.json");
        std::fs::write(&p, json).unwrap();
        let r = read_transforms(&p)
            .unwrap()
            .resolve(&p, dir.path())
            .unwrap();
        let f = 0.5 * 10.0 / (0.5f64 * 0.6911112070083618).tan();
        assert_eq!(r[0].camera.model, CameraModel::PINHOLE);
        assert_eq!((r[0].camera.width, r[0].camera.height), (10, 20));
        assert!(
            (r[0].camera.params[0] - f).abs() < 1e-12 && (r[0].camera.params[1] - f).abs() < 1e-12
        );
        assert_eq!(r[0].camera.params[2..], [5.0, 10.0]);
        assert_eq!(r[1].camera.params, vec![7.0, 7.0, 5.0, 10.0]);
    }

    #[test]
    fn model_to_transforms_and_back() {
        let mut m = ColmapModel::default();
        let cam = Camera {
            id: 1,
            model: CameraModel::OPENCV,
            width: 8,
            height: 6,
            params: vec![9.0, 9.5, 4.0, 3.0, 0.1, 0.0, 0.0, 0.01],
        };
        m.cameras.insert(1, cam.clone());
        let pose = Pose::look_at(Vector3::new(0.0, -3.0, 1.0), Vector3::zeros(), Vector3::z());
        m.images
            .insert(5, crate::colmap::ColmapImage::new(5, pose, 1, "x.png"));
        let t = Transforms::from_model(&m, "images/").unwrap();
        let dir = tempfile::tempdir().unwrap();
        touch_png(&dir.path().join("images/x.png"), 8, 6);
        let p = dir.path().join("transforms.json");
        write_transforms(&p, &t).unwrap();
        let r = read_transforms(&p)
            .unwrap()
            .resolve(&p, dir.path())
            .unwrap();
        assert_eq!(r[0].camera.params, cam.params);
        assert!((r[0].pose.world_to_camera() - pose.world_to_camera()).norm() < 1e-12);
    }

    #[test]
    fn missing_image_and_bad_json_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("transforms.json");
        std::fs::write(&p, r#"{"fl_x": 5, "w": 4, "h": 4, "frames": [{"file_path": "images/gone.jpg", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}"#).unwrap();
        let e = read_transforms(&p)
            .unwrap()
            .resolve(&p, dir.path())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("gone.jpg") && e.contains("not found") && e.contains("transforms.json"),
            "{e}"
        );
        std::fs::write(&p, "{\"frames\": [").unwrap();
        let e = read_transforms(&p).unwrap_err().to_string();
        assert!(
            e.contains("transforms.json") && e.contains("invalid"),
            "{e}"
        );
    }
}
