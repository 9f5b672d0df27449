//! The DAVIS video-segmentation layout (Perazzi et al., CVPR 2016; Pont-Tuset
//! et al. 2017): `JPEGImages/<res>/<seq>/00000.jpg…` and
//! `Annotations/<res>/<seq>/00000.png…` (for DAVIS 2016: binary, 255 = the
//! main moving object). Used to measure motion segmentation (J = IoU).

use crate::error::{LoaderError, Result};
use crate::scene::list_images;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One frame of a DAVIS sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DavisFrame {
    /// File name (e.g. `00000.jpg`).
    pub name: String,
    /// Image path.
    pub image: PathBuf,
    /// Annotation path (`<stem>.png`) when it exists.
    pub annotation: Option<PathBuf>,
}

/// One DAVIS sequence, frames in file-name order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DavisSequence {
    pub name: String,
    pub frames: Vec<DavisFrame>,
}

/// A DAVIS dataset root at one resolution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Davis {
    pub root: PathBuf,
    /// Resolution folder, `480p` by default.
    pub resolution: String,
}

impl Davis {
    /// Open a DAVIS root (must contain `JPEGImages/<resolution>`).
    pub fn open(root: impl AsRef<Path>, resolution: &str) -> Result<Davis> {
        let root = root.as_ref().to_path_buf();
        let img = root.join("JPEGImages").join(resolution);
        if !img.is_dir() {
            return Err(LoaderError::Missing {
                path: img,
                context: "DAVIS JPEGImages folder".into(),
            });
        }
        Ok(Davis {
            root,
            resolution: resolution.to_string(),
        })
    }

    /// Sequence names (sorted).
    pub fn sequences(&self) -> Result<Vec<String>> {
        let dir = self.root.join("JPEGImages").join(&self.resolution);
        let rd = std::fs::read_dir(&dir).map_err(|e| LoaderError::io(&dir, e))?;
        let mut v = Vec::new();
        for e in rd {
            let e = e.map_err(|err| LoaderError::io(&dir, err))?;
            if e.path().is_dir() {
                v.push(e.file_name().to_string_lossy().into_owned());
            }
        }
        v.sort();
        Ok(v)
    }

    /// Load one sequence's frame list with annotation paths.
    pub fn sequence(&self, name: &str) -> Result<DavisSequence> {
        let img_dir = self
            .root
            .join("JPEGImages")
            .join(&self.resolution)
            .join(name);
        let ann_dir = self
            .root
            .join("Annotations")
            .join(&self.resolution)
            .join(name);
        let frames = list_images(&img_dir)?
            .into_iter()
            .map(|n| {
                let stem = Path::new(&n)
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let ann = ann_dir.join(format!("{stem}.png"));
                DavisFrame {
                    image: img_dir.join(&n),
                    annotation: ann.is_file().then_some(ann),
                    name: n,
                }
            })
            .collect();
        Ok(DavisSequence {
            name: name.to_string(),
            frames,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_sequences_frames_and_annotations() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        for seq in ["cows", "bear"] {
            for i in 0..3 {
                let img = root.join(format!("JPEGImages/480p/{seq}/{i:05}.jpg"));
                std::fs::create_dir_all(img.parent().unwrap()).unwrap();
                image::RgbImage::new(4, 4).save(&img).unwrap();
                if i != 1 {
                    crate::io::write_png_gray8(
                        root.join(format!("Annotations/480p/{seq}/{i:05}.png")),
                        &image::GrayImage::new(4, 4),
                    )
                    .unwrap();
                }
            }
        }
        let d = Davis::open(root, "480p").unwrap();
        assert_eq!(d.sequences().unwrap(), vec!["bear", "cows"]);
        let s = d.sequence("cows").unwrap();
        assert_eq!(s.frames.len(), 3);
        assert_eq!(s.frames[0].name, "00000.jpg");
        assert_eq!(
            s.frames[2].annotation,
            Some(root.join("Annotations/480p/cows/00002.png"))
        );
        assert_eq!(s.frames[1].annotation, None);
        let e = Davis::open(root, "1080p").unwrap_err().to_string();
        assert!(
            e.contains("JPEGImages/1080p") && e.contains("not found"),
            "{e}"
        );
        let e = d.sequence("nope").unwrap_err().to_string();
        assert!(e.contains("nope"), "{e}");
    }
}
