//! Masks in COLMAP's convention (also nerfstudio's and Brush's):
//! `masks/<image file name>.png` (so `0001.jpg` → `0001.jpg.png`), 8-bit,
//! 255 = static (keep), 0 = moving (ignore). Ground-truth motion uses the
//! opposite polarity, `gt_motion/<stem>.png` with 255 = moving, as DAVIS
//! annotations do; helpers here convert between the two.

use crate::error::{LoaderError, Result};
use crate::io::{read_gray8, write_png_gray8};
use image::{GrayImage, Luma};
use std::path::{Path, PathBuf};

/// Value of a kept (static) pixel in a COLMAP mask.
pub const KEEP: u8 = 255;
/// Value of an ignored (moving) pixel in a COLMAP mask.
pub const IGNORE: u8 = 0;

/// The mask file name for an image name: `<name>.png`.
pub fn mask_file_name(image_name: &str) -> String {
    format!("{image_name}.png")
}

/// `masks_dir/<image name>.png`.
pub fn mask_path(masks_dir: &Path, image_name: &str) -> PathBuf {
    masks_dir.join(mask_file_name(image_name))
}

/// `gt_dir/<image stem>.png` (ground-truth motion naming, DAVIS-like).
pub fn gt_motion_path(gt_dir: &Path, image_name: &str) -> PathBuf {
    let stem = Path::new(image_name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned());
    gt_dir.join(format!(
        "{}.png",
        stem.unwrap_or_else(|| image_name.to_string())
    ))
}

/// Binarise at 128: values ≥ 128 become `hi`, the rest `lo`.
fn binarise(img: &GrayImage, hi: u8, lo: u8) -> GrayImage {
    GrayImage::from_fn(img.width(), img.height(), |x, y| {
        Luma([if img.get_pixel(x, y).0[0] >= 128 {
            hi
        } else {
            lo
        }])
    })
}

/// Read a COLMAP keep-mask, binarised (≥ 128 → 255 keep, else 0 ignore).
pub fn read_mask(path: impl AsRef<Path>) -> Result<GrayImage> {
    Ok(binarise(&read_gray8(path)?, KEEP, IGNORE))
}

/// Read a nerfstudio mask (`mask_path`: nonzero → 255 keep, 0 → 0 ignore).
pub fn read_mask_nonzero(path: impl AsRef<Path>) -> Result<GrayImage> {
    let mut m = read_gray8(path)?;
    for p in m.pixels_mut() {
        p.0[0] = if p.0[0] > 0 { KEEP } else { IGNORE };
    }
    Ok(m)
}

/// Write a COLMAP keep-mask PNG atomically (binarised at 128).
pub fn write_mask(path: impl AsRef<Path>, keep: &GrayImage) -> Result<()> {
    write_png_gray8(path, &binarise(keep, KEEP, IGNORE))
}

/// Read a ground-truth motion mask (255 = moving), binarised.
pub fn read_moving(path: impl AsRef<Path>) -> Result<GrayImage> {
    Ok(binarise(&read_gray8(path)?, 255, 0))
}

/// Convert a moving mask (255 = moving) to a COLMAP keep-mask (255 = static).
pub fn keep_from_moving(moving: &GrayImage) -> GrayImage {
    binarise(moving, IGNORE, KEEP)
}

/// Convert a COLMAP keep-mask to a moving mask (255 = moving).
pub fn moving_from_keep(keep: &GrayImage) -> GrayImage {
    binarise(keep, 0, 255)
}

/// A keep-mask from a per-pixel "moving" flag (row-major, `width*height`).
pub fn keep_from_bools(width: u32, height: u32, moving: &[bool]) -> Option<GrayImage> {
    if moving.len() != width as usize * height as usize {
        return None;
    }
    let data = moving
        .iter()
        .map(|m| if *m { IGNORE } else { KEEP })
        .collect();
    GrayImage::from_raw(width, height, data)
}

/// Fail unless `mask` is `width`×`height`; `path` names the mask file.
pub fn check_size(path: &Path, mask: &GrayImage, width: u32, height: u32) -> Result<()> {
    if mask.dimensions() != (width, height) {
        return Err(LoaderError::format(
            path,
            format!(
                "mask is {}x{} but its image is {width}x{height}",
                mask.width(),
                mask.height()
            ),
        ));
    }
    Ok(())
}

/// Write keep-masks for `names` into `masks_dir` from moving masks
/// (255 = moving); returns the written paths.
pub fn write_keep_masks_from_moving(
    masks_dir: &Path,
    items: &[(String, GrayImage)],
) -> Result<Vec<PathBuf>> {
    items
        .iter()
        .map(|(name, moving)| {
            let p = mask_path(masks_dir, name);
            write_mask(&p, &keep_from_moving(moving))?;
            Ok(p)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn naming_follows_colmap() {
        assert_eq!(
            mask_path(Path::new("s/masks"), "0001.jpg"),
            Path::new("s/masks/0001.jpg.png")
        );
        assert_eq!(
            gt_motion_path(Path::new("g"), "0001.jpg"),
            Path::new("g/0001.png")
        );
    }

    #[test]
    fn moving_to_keep_round_trip_on_disk() {
        let dir = tempfile::tempdir().unwrap();
        let moving = GrayImage::from_fn(5, 4, |x, y| {
            Luma([if x == y {
                255
            } else if x > 3 {
                200
            } else {
                3
            }])
        });
        let paths = write_keep_masks_from_moving(
            &dir.path().join("masks"),
            &[("a.jpg".into(), moving.clone())],
        )
        .unwrap();
        assert_eq!(paths[0], dir.path().join("masks/a.jpg.png"));
        let keep = read_mask(&paths[0]).unwrap();
        assert_eq!(keep.get_pixel(1, 1).0[0], IGNORE);
        assert_eq!(keep.get_pixel(4, 0).0[0], IGNORE); // 200 ≥ 128 → moving
        assert_eq!(keep.get_pixel(1, 0).0[0], KEEP);
        assert_eq!(moving_from_keep(&keep), binarise(&moving, 255, 0));
        let kb = keep_from_bools(2, 1, &[true, false]).unwrap();
        assert_eq!(kb.as_raw(), &vec![IGNORE, KEEP]);
        assert!(keep_from_bools(2, 2, &[true]).is_none());
    }

    #[test]
    fn size_mismatch_names_the_mask() {
        let m = GrayImage::new(4, 3);
        let e = check_size(Path::new("masks/x.jpg.png"), &m, 8, 6)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("masks/x.jpg.png") && e.contains("4x3") && e.contains("8x6"),
            "{e}"
        );
        assert!(check_size(Path::new("m"), &m, 4, 3).is_ok());
    }
}
