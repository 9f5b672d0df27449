//! Ground-truth motion → COLMAP masks, for measuring the pose stage with
//! oracle masks (the "GT masks" rows of the RoMo paper's SfM tables).
//!
//! `gt_motion/<stem>.png` marks moving pixels with 255; COLMAP's (and our)
//! `masks/<image name>.png` marks pixels to *keep* with 255. The conversion is
//! an inversion plus the renaming, both `loader::masks`'s; images without a ground-truth file (e.g.
//! clean held-out views) get an all-keep mask.

use crate::error::{PoseError, Result};
use loader::masks;
use loader::scene::list_images;
use std::path::Path;

/// Write `out/<image name>.png` for every image in `images`, from
/// `gt_motion/<stem>.png` (inverted) or all-keep when that file is absent.
/// Returns (masks written, masks that came from a ground-truth file).
pub fn masks_from_gt_motion(images: &Path, gt_motion: &Path, out: &Path) -> Result<(usize, usize)> {
    let names = list_images(images)?;
    std::fs::create_dir_all(out).map_err(|e| PoseError::io(out, e))?;
    let mut from_gt = 0;
    for name in &names {
        let (w, h) = image::image_dimensions(images.join(name))
            .map_err(|e| PoseError::Invalid(format!("{}: {e}", images.join(name).display())))?;
        let gt_path = masks::gt_motion_path(gt_motion, name);
        let keep = if gt_path.is_file() {
            let gt = masks::read_moving(&gt_path)?;
            if gt.dimensions() != (w, h) {
                return Err(PoseError::Invalid(format!(
                    "{}: ground-truth motion is {}×{} but its image is {w}×{h}",
                    gt_path.display(),
                    gt.width(),
                    gt.height()
                )));
            }
            from_gt += 1;
            masks::keep_from_moving(&gt)
        } else {
            image::GrayImage::from_pixel(w, h, image::Luma([masks::KEEP]))
        };
        masks::write_mask(masks::mask_path(out, name), &keep)?;
    }
    Ok((names.len(), from_gt))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverts_and_renames_and_fills_missing() {
        let d = tempfile::tempdir().unwrap();
        let images = d.path().join("images");
        let gt = d.path().join("gt_motion");
        let img = image::RgbImage::new(8, 4);
        loader::io::write_png_rgb8(images.join("00000.png"), &img).unwrap();
        loader::io::write_png_rgb8(images.join("test_000.png"), &img).unwrap();
        let g = image::GrayImage::from_fn(8, 4, |x, _| image::Luma([if x < 3 { 255 } else { 0 }]));
        loader::io::write_png_gray8(gt.join("00000.png"), &g).unwrap();
        let out = d.path().join("masks");
        assert_eq!(masks_from_gt_motion(&images, &gt, &out).unwrap(), (2, 1));
        let m = loader::io::read_gray8(out.join("00000.png.png")).unwrap();
        assert_eq!(m.get_pixel(0, 0).0[0], 0);
        assert_eq!(m.get_pixel(5, 3).0[0], 255);
        let t = loader::io::read_gray8(out.join("test_000.png.png")).unwrap();
        assert!(t.pixels().all(|p| p.0[0] == 255));
        // A size mismatch names the file.
        let small = image::GrayImage::new(4, 4);
        loader::io::write_png_gray8(gt.join("test_000.png"), &small).unwrap();
        let e = masks_from_gt_motion(&images, &gt, &out)
            .unwrap_err()
            .to_string();
        assert!(e.contains("test_000.png") && e.contains("4×4"), "{e}");
    }
}
