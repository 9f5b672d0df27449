//! COLMAP sparse models (`cameras`, `images`, `points3D`), binary and text,
//! read and write, following COLMAP's `src/colmap/scene/reconstruction_io.cc`
//! layout (little-endian; ids u32/u64; invalid point3D id = u64::MAX / `-1`).
//!
//! The binary writer is byte-exact: reading a file and writing it back gives
//! the same bytes, including the record order of models written by COLMAP
//! itself (kept in [`FileOrder`]). The extra files COLMAP 4 / pycolmap write
//! next to a model (`rigs.bin`, `frames.bin`, `project.ini`, ...) are ignored.

mod binary;
mod text;

pub use binary::{read_model_binary, write_model_binary};
pub use text::{read_model_text, write_model_text};

use crate::camera::{Camera, Pose};
use crate::error::{LoaderError, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One 2D keypoint of an image, optionally observing a 3D point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point2D {
    /// Pixel coordinates (COLMAP: pixel centre of the top-left pixel is (0.5, 0.5)).
    pub xy: [f64; 2],
    /// The 3D point this keypoint observes, if triangulated.
    pub point3d_id: Option<u64>,
}

/// A registered image: its pose, camera and keypoints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColmapImage {
    /// COLMAP image id.
    pub id: u32,
    /// World-to-camera pose (qvec w,x,y,z + tvec), stored exactly as read.
    pub pose: Pose,
    /// Id of the camera (intrinsics) in [`ColmapModel::cameras`].
    pub camera_id: u32,
    /// Image file name relative to the image folder.
    pub name: String,
    /// Keypoints, in file order (their index is the `point2d_idx` of tracks).
    pub points2d: Vec<Point2D>,
}

impl ColmapImage {
    /// An image with no keypoints.
    pub fn new(id: u32, pose: Pose, camera_id: u32, name: impl Into<String>) -> Self {
        ColmapImage {
            id,
            pose,
            camera_id,
            name: name.into(),
            points2d: Vec::new(),
        }
    }
}

/// A triangulated 3D point with its colour, reprojection error and track.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Point3D {
    /// COLMAP point3D id.
    pub id: u64,
    /// World position.
    pub xyz: [f64; 3],
    /// Colour, 8-bit RGB.
    pub rgb: [u8; 3],
    /// Mean reprojection error in pixels (COLMAP writes -1 when unknown).
    pub error: f64,
    /// Observations as (image id, index into that image's `points2d`).
    pub track: Vec<(u32, u32)>,
}

/// The order records appeared in the files a model was read from, so writing
/// it back reproduces COLMAP's (hash-map) order byte for byte. Writers use it
/// only when it lists exactly the model's ids; otherwise they write in
/// ascending id order. Leave it `Default` when building a model by hand.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FileOrder {
    pub cameras: Vec<u32>,
    pub images: Vec<u32>,
    pub points3d: Vec<u64>,
}

/// A COLMAP sparse model. Build one with `ColmapModel::default()` and insert
/// into the maps (ids as keys; each value's `id` must equal its key).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ColmapModel {
    pub cameras: BTreeMap<u32, Camera>,
    pub images: BTreeMap<u32, ColmapImage>,
    pub points3d: BTreeMap<u64, Point3D>,
    /// Record order of the files this was read from (see [`FileOrder`]).
    #[serde(default)]
    pub file_order: FileOrder,
}

/// Which on-disk form a model folder holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModelFormat {
    Binary,
    Text,
}

impl ColmapModel {
    /// Images in ascending name order (capture order for our scenes).
    pub fn images_by_name(&self) -> Vec<&ColmapImage> {
        let mut v: Vec<&ColmapImage> = self.images.values().collect();
        v.sort_by(|a, b| a.name.cmp(&b.name));
        v
    }

    /// The image with this file name, if registered.
    pub fn image_by_name(&self, name: &str) -> Option<&ColmapImage> {
        self.images.values().find(|im| im.name == name)
    }

    /// Check the model is usable, naming the file (`dir/cameras.bin`, ...)
    /// and the record in errors: map keys equal ids; cameras have a size,
    /// the right parameter count, finite parameters and focal lengths > 0;
    /// every image's camera exists and its pose is finite with a
    /// quaternion that can be normalised; 3D points are finite.
    pub fn validate(&self, dir: &Path) -> Result<()> {
        let ext = match detect_format(dir) {
            Some(ModelFormat::Binary) => Some("bin"),
            Some(ModelFormat::Text) => Some("txt"),
            None => None,
        };
        self.validate_files(dir, ext)
    }

    /// [`ColmapModel::validate`] naming `dir/<file>.<ext>` (or `dir` alone).
    pub(crate) fn validate_files(&self, dir: &Path, ext: Option<&str>) -> Result<()> {
        let file = |stem: &str| match ext {
            Some(e) => dir.join(format!("{stem}.{e}")),
            None => dir.to_path_buf(),
        };
        for (k, c) in &self.cameras {
            let bad =
                |msg: String| LoaderError::format(file("cameras"), format!("camera {k}: {msg}"));
            if *k != c.id {
                return Err(bad(format!("key != camera id {}", c.id)));
            }
            if c.params.len() != c.model.num_params() {
                return Err(bad(format!(
                    "model {} needs {} params, has {}",
                    c.model.name(),
                    c.model.num_params(),
                    c.params.len()
                )));
            }
            if c.width == 0
                || c.height == 0
                || c.width > u32::MAX as u64
                || c.height > u32::MAX as u64
            {
                return Err(bad(format!(
                    "image size {}x{} is not usable",
                    c.width, c.height
                )));
            }
            if let Some(v) = c.params.iter().find(|v| !v.is_finite()) {
                return Err(bad(format!("parameter {v} is not finite")));
            }
            let (fx, fy) = c.focal();
            if fx <= 0.0 || fy <= 0.0 {
                return Err(bad(format!("focal length {fx}, {fy} is not > 0")));
            }
        }
        for (k, im) in &self.images {
            let bad = |msg: String| {
                LoaderError::format(file("images"), format!("image {k} ({}): {msg}", im.name))
            };
            if *k != im.id {
                return Err(bad(format!("key != image id {}", im.id)));
            }
            if !self.cameras.contains_key(&im.camera_id) {
                return Err(bad(format!("refers to missing camera {}", im.camera_id)));
            }
            check_pose(&im.pose).map_err(bad)?;
        }
        for (k, p) in &self.points3d {
            let bad =
                |msg: String| LoaderError::format(file("points3D"), format!("point {k}: {msg}"));
            if *k != p.id {
                return Err(bad(format!("key != point id {}", p.id)));
            }
            if p.xyz.iter().any(|v| !v.is_finite()) {
                return Err(bad(format!("position {:?} is not finite", p.xyz)));
            }
        }
        Ok(())
    }

    pub(crate) fn camera_order(&self) -> Vec<u32> {
        ordered(&self.file_order.cameras, &self.cameras)
    }
    pub(crate) fn image_order(&self) -> Vec<u32> {
        ordered(&self.file_order.images, &self.images)
    }
    pub(crate) fn point_order(&self) -> Vec<u64> {
        ordered(&self.file_order.points3d, &self.points3d)
    }
}

/// `order` if it lists exactly the keys of `map` (each once), else sorted keys.
fn ordered<K: Ord + Copy, V>(order: &[K], map: &BTreeMap<K, V>) -> Vec<K> {
    if order.len() == map.len() && order.iter().all(|k| map.contains_key(k)) {
        let mut seen: Vec<K> = order.to_vec();
        seen.sort();
        seen.dedup();
        if seen.len() == order.len() {
            return order.to_vec();
        }
    }
    map.keys().copied().collect()
}

/// Check a world-to-camera pose: finite, with a quaternion whose norm is
/// far enough from 0 to normalise (COLMAP normalises on read; a zero or
/// NaN quaternion has no rotation).
pub fn check_pose(p: &Pose) -> std::result::Result<(), String> {
    let n = p.qvec.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !n.is_finite() || n < 1e-6 {
        return Err(format!(
            "quaternion {:?} cannot be normalised to a rotation",
            p.qvec
        ));
    }
    if p.tvec.iter().any(|v| !v.is_finite()) {
        return Err(format!("translation {:?} is not finite", p.tvec));
    }
    Ok(())
}

/// Which form `dir` holds: binary when `cameras.bin` exists, text when
/// `cameras.txt` exists (binary preferred when both do).
pub fn detect_format(dir: &Path) -> Option<ModelFormat> {
    if dir.join("cameras.bin").is_file() {
        Some(ModelFormat::Binary)
    } else if dir.join("cameras.txt").is_file() {
        Some(ModelFormat::Text)
    } else {
        None
    }
}

/// Find the model folder for `path`: `path` itself when it holds
/// `cameras.{bin,txt}`, else `path/sparse/0`, else `path/sparse`.
pub fn find_model_dir(path: &Path) -> Option<PathBuf> {
    [
        path.to_path_buf(),
        path.join("sparse/0"),
        path.join("sparse"),
    ]
    .into_iter()
    .find(|p| detect_format(p).is_some())
}

/// Read the model in `dir`, binary or text (binary preferred).
pub fn read_model(dir: impl AsRef<Path>) -> Result<ColmapModel> {
    let dir = dir.as_ref();
    match detect_format(dir) {
        Some(ModelFormat::Binary) => read_model_binary(dir),
        Some(ModelFormat::Text) => read_model_text(dir),
        None => Err(LoaderError::format(
            dir,
            "not a COLMAP model folder (no cameras.bin or cameras.txt)",
        )),
    }
}

/// The records of one model file, keyed by id, with the order they appeared
/// in (see [`FileOrder`]); a repeated id is an error naming the file.
pub(crate) struct Records<K, V> {
    pub map: BTreeMap<K, V>,
    pub order: Vec<K>,
}

/// A model record that carries its own id.
pub(crate) trait Record {
    type Id: Ord + Copy + std::fmt::Display;
    /// What it is in error messages ("camera", "image", "point3D").
    const KIND: &'static str;
    fn id(&self) -> Self::Id;
}

impl Record for Camera {
    type Id = u32;
    const KIND: &'static str = "camera";
    fn id(&self) -> u32 {
        self.id
    }
}

impl Record for ColmapImage {
    type Id = u32;
    const KIND: &'static str = "image";
    fn id(&self) -> u32 {
        self.id
    }
}

impl Record for Point3D {
    type Id = u64;
    const KIND: &'static str = "point3D";
    fn id(&self) -> u64 {
        self.id
    }
}

impl<K: Ord + Copy + std::fmt::Display, V: Record<Id = K>> Records<K, V> {
    pub fn with_capacity(n: usize) -> Self {
        Records {
            map: BTreeMap::new(),
            order: Vec::with_capacity(n),
        }
    }

    /// Add a record read from `path`, at text line `line` when there is one.
    pub fn insert(&mut self, path: &Path, line: Option<usize>, v: V) -> Result<()> {
        let id = v.id();
        if self.map.insert(id, v).is_some() {
            let at = line.map_or(String::new(), |ln| format!("line {ln}: "));
            return Err(LoaderError::format(
                path,
                format!("{at}duplicate {} id {id}", V::KIND),
            ));
        }
        self.order.push(id);
        Ok(())
    }
}

/// A reader of one model file.
pub(crate) type ReadFile<K, V> = fn(&Path) -> Result<Records<K, V>>;

/// Read `cameras.EXT`, `images.EXT` and `points3D.EXT` from `dir` with the
/// format's three readers, then validate the model.
pub(crate) fn read_model_files(
    dir: &Path,
    ext: &str,
    cameras: ReadFile<u32, Camera>,
    images: ReadFile<u32, ColmapImage>,
    points: ReadFile<u64, Point3D>,
) -> Result<ColmapModel> {
    let c = cameras(&model_file(dir, &format!("cameras.{ext}"))?)?;
    let i = images(&model_file(dir, &format!("images.{ext}"))?)?;
    let p = points(&model_file(dir, &format!("points3D.{ext}"))?)?;
    let model = ColmapModel {
        cameras: c.map,
        images: i.map,
        points3d: p.map,
        file_order: FileOrder {
            cameras: c.order,
            images: i.order,
            points3d: p.order,
        },
    };
    model.validate_files(dir, Some(ext))?;
    Ok(model)
}

/// Path of a model file, failing with a clear error when it is absent.
pub(crate) fn model_file(dir: &Path, name: &str) -> Result<PathBuf> {
    let p = dir.join(name);
    if p.is_file() {
        Ok(p)
    } else {
        Err(LoaderError::Missing {
            path: p,
            context: "COLMAP model file".into(),
        })
    }
}

#[cfg(test)]
pub(crate) mod testutil {
    use super::*;
    use crate::camera::CameraModel;

    /// A small model using every camera model, keypoints with and without
    /// 3D points, and non-sorted file order.
    pub fn sample_model() -> ColmapModel {
        let mut m = ColmapModel::default();
        for (i, model) in CameraModel::ALL.iter().enumerate() {
            let id = i as u32 + 1;
            let params = (0..model.num_params())
                .map(|k| 100.0 + k as f64 * 0.37 - i as f64 / 3.0)
                .collect();
            m.cameras.insert(
                id,
                Camera {
                    id,
                    model: *model,
                    width: 640 + i as u64,
                    height: 480,
                    params,
                },
            );
        }
        for id in [3u32, 1, 2] {
            let pose = Pose {
                qvec: [0.9, 0.1 * id as f64, -0.2, 0.3],
                tvec: [1.0 / 3.0, -2.5e-7, id as f64],
            };
            let mut im = ColmapImage::new(id, pose, id, format!("frame_{id:04}.jpg"));
            im.points2d = vec![
                Point2D {
                    xy: [10.5, 20.25],
                    point3d_id: Some(7),
                },
                Point2D {
                    xy: [0.1, 1e6],
                    point3d_id: None,
                },
            ];
            m.images.insert(id, im);
        }
        m.points3d.insert(
            7,
            Point3D {
                id: 7,
                xyz: [1.0, 2.0, -3.5],
                rgb: [255, 0, 17],
                error: 0.42,
                track: vec![(3, 0), (1, 0), (2, 0)],
            },
        );
        m.points3d.insert(
            9,
            Point3D {
                id: 9,
                xyz: [0.0; 3],
                rgb: [1, 2, 3],
                error: -1.0,
                track: vec![],
            },
        );
        m.file_order = FileOrder {
            cameras: (1..=12).collect(),
            images: vec![3, 1, 2],
            points3d: vec![9, 7],
        };
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_model_detects_format_and_ignores_colmap4_extras() {
        let dir = tempfile::tempdir().unwrap();
        let m = testutil::sample_model();
        let bin = dir.path().join("bin");
        let txt = dir.path().join("txt");
        write_model_binary(&m, &bin).unwrap();
        write_model_text(&m, &txt).unwrap();
        std::fs::write(bin.join("rigs.bin"), [1u8, 2, 3]).unwrap();
        std::fs::write(bin.join("frames.bin"), [9u8; 17]).unwrap();
        std::fs::write(txt.join("rigs.txt"), "# whatever\n1 2 3\n").unwrap();
        assert_eq!(detect_format(&bin), Some(ModelFormat::Binary));
        assert_eq!(detect_format(&txt), Some(ModelFormat::Text));
        assert_eq!(read_model(&bin).unwrap(), m);
        let t = read_model(&txt).unwrap();
        assert_eq!(t.cameras, m.cameras);
        assert_eq!(t.images, m.images);
        assert_eq!(t.points3d, m.points3d);
        let e = read_model(dir.path()).unwrap_err().to_string();
        assert!(e.contains("not a COLMAP model"), "{e}");
        // find_model_dir looks into sparse/0.
        let scene = dir.path().join("scene");
        write_model_binary(&m, scene.join("sparse/0")).unwrap();
        assert_eq!(find_model_dir(&scene), Some(scene.join("sparse/0")));
    }

    #[test]
    fn missing_model_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        write_model_binary(&testutil::sample_model(), dir.path()).unwrap();
        std::fs::remove_file(dir.path().join("points3D.bin")).unwrap();
        let e = read_model(dir.path()).unwrap_err().to_string();
        assert!(e.contains("points3D.bin") && e.contains("not found"), "{e}");
    }

    /// A record whose id repeats an earlier one is refused, naming the
    /// file, the kind of record and (in text) the line, in both formats.
    #[test]
    fn repeated_record_ids_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let m = testutil::sample_model();
        let txt = dir.path().join("txt");
        write_model_text(&m, &txt).unwrap();
        let cams = std::fs::read_to_string(txt.join("cameras.txt")).unwrap();
        let first = cams.lines().find(|l| !l.starts_with('#')).unwrap();
        std::fs::write(txt.join("cameras.txt"), format!("{cams}{first}\n")).unwrap();
        let e = read_model(&txt).unwrap_err().to_string();
        let line = cams.lines().count() + 1;
        assert!(
            e.contains("cameras.txt") && e.contains(&format!("line {line}: duplicate camera id 1")),
            "{e}"
        );
        // Binary: points3D.bin with its first point written twice.
        let bin = dir.path().join("bin");
        write_model_binary(&m, &bin).unwrap();
        let mut one = m.clone();
        let first_id = *one.points3d.keys().next().unwrap();
        one.points3d.retain(|id, _| *id == first_id);
        one.file_order = Default::default();
        let mut record = Vec::new();
        binary::encode_points(&one, &mut record);
        let mut bytes = std::fs::read(bin.join("points3D.bin")).unwrap();
        let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) + 1;
        bytes[..8].copy_from_slice(&n.to_le_bytes());
        bytes.extend_from_slice(&record[8..]);
        std::fs::write(bin.join("points3D.bin"), &bytes).unwrap();
        let e = read_model(&bin).unwrap_err().to_string();
        assert!(
            e.contains("points3D.bin") && e.contains(&format!("duplicate point3D id {first_id}")),
            "{e}"
        );
    }

    /// Every unusable record is refused at read time, naming the file and
    /// the record (the trainer would otherwise train on garbage).
    #[test]
    fn unusable_records_are_refused_naming_file_and_record() {
        let dir = tempfile::tempdir().unwrap();
        type Edit = fn(&mut ColmapModel);
        let cases: [(Edit, &str, &str); 6] = [
            (
                |m| m.images.get_mut(&2).unwrap().pose.qvec = [0.0; 4],
                "images.bin",
                "image 2 (frame_0002.jpg): quaternion",
            ),
            (
                |m| m.images.get_mut(&2).unwrap().pose.qvec[1] = f64::NAN,
                "images.bin",
                "cannot be normalised",
            ),
            (
                |m| m.images.get_mut(&3).unwrap().camera_id = 42,
                "images.bin",
                "missing camera 42",
            ),
            (
                |m| m.cameras.get_mut(&1).unwrap().width = 0,
                "cameras.bin",
                "camera 1: image size 0x480",
            ),
            (
                |m| m.cameras.get_mut(&2).unwrap().params[0] = f64::NAN,
                "cameras.bin",
                "camera 2: parameter NaN",
            ),
            (
                |m| m.points3d.get_mut(&7).unwrap().xyz[0] = f64::INFINITY,
                "points3D.bin",
                "point 7: position",
            ),
        ];
        for (k, (edit, file, want)) in cases.iter().enumerate() {
            let mut m = testutil::sample_model();
            edit(&mut m);
            // Written by hand (the writer refuses), then read.
            let d = dir.path().join(format!("m{k}"));
            std::fs::create_dir_all(&d).unwrap();
            let mut ok = testutil::sample_model();
            ok.file_order = Default::default();
            write_model_binary(&ok, &d).unwrap();
            assert!(
                write_model_binary(&m, &d).is_err(),
                "writer accepted case {k}"
            );
            let mut bytes = Vec::new();
            match *file {
                "cameras.bin" => binary::encode_cameras(&m, &mut bytes),
                "images.bin" => binary::encode_images(&m, &mut bytes),
                _ => binary::encode_points(&m, &mut bytes),
            }
            std::fs::write(d.join(file), &bytes).unwrap();
            let e = read_model(&d).unwrap_err().to_string();
            assert!(
                e.contains(&format!("m{k}/{file}")) && e.contains(want),
                "{e} (wanted {want})"
            );
        }
    }

    #[test]
    fn validate_catches_missing_camera() {
        let mut m = testutil::sample_model();
        m.images.get_mut(&1).unwrap().camera_id = 99;
        let e = m.validate(Path::new("model")).unwrap_err().to_string();
        assert!(e.contains("missing camera 99"), "{e}");
    }
}
