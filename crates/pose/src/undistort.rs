//! Installing COLMAP's undistorted PINHOLE copy of a scene, masks included.
//!
//! `colmap image_undistorter` writes undistorted images and a PINHOLE model;
//! the splat trainer also needs the motion masks in the undistorted geometry.
//! COLMAP cannot undistort masks itself (they are named `<image>.png` and are
//! binary), so they are warped here with the same per-pixel mapping COLMAP's
//! `WarpImageBetweenCameras` uses (`src/colmap/image/warp.cc`): the centre of
//! target pixel (x, y) is (x + 0.5, y + 0.5), unprojected through the PINHOLE
//! target camera, distorted and projected through the source camera model
//! (`src/colmap/sensor/models.h`). Masks are sampled conservatively: a pixel
//! stays "keep" only when all four bilinear neighbours are "keep", so moving
//! regions never shrink.

use crate::error::{PoseError, Result};
use crate::model_info::install_model;
use loader::colmap::read_model;
use loader::{Camera, CameraModel};
use std::path::Path;

/// Project normalized camera coordinates (u, v) = (x/z, y/z) to pixels with
/// COLMAP's model of `cam`, distortion included. None for models this
/// module does not implement (the fisheye family).
pub fn world_to_image(cam: &Camera, u: f64, v: f64) -> Option<(f64, f64)> {
    let p = &cam.params;
    if p.len() != cam.model.num_params() {
        return None;
    }
    let r2 = u * u + v * v;
    let (fx, fy, cx, cy, du, dv) = match cam.model {
        CameraModel::SIMPLE_PINHOLE => (p[0], p[0], p[1], p[2], 0.0, 0.0),
        CameraModel::PINHOLE => (p[0], p[1], p[2], p[3], 0.0, 0.0),
        CameraModel::SIMPLE_RADIAL => {
            let radial = p[3] * r2;
            (p[0], p[0], p[1], p[2], u * radial, v * radial)
        }
        CameraModel::RADIAL => {
            let radial = p[3] * r2 + p[4] * r2 * r2;
            (p[0], p[0], p[1], p[2], u * radial, v * radial)
        }
        CameraModel::OPENCV => {
            let (k1, k2, p1, p2) = (p[4], p[5], p[6], p[7]);
            let radial = k1 * r2 + k2 * r2 * r2;
            let uv = u * v;
            (
                p[0],
                p[1],
                p[2],
                p[3],
                u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u * u),
                v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v * v),
            )
        }
        CameraModel::FULL_OPENCV => {
            let (k1, k2, p1, p2, k3, k4, k5, k6) =
                (p[4], p[5], p[6], p[7], p[8], p[9], p[10], p[11]);
            let r4 = r2 * r2;
            let r6 = r4 * r2;
            let radial = (1.0 + k1 * r2 + k2 * r4 + k3 * r6) / (1.0 + k4 * r2 + k5 * r4 + k6 * r6);
            let uv = u * v;
            (
                p[0],
                p[1],
                p[2],
                p[3],
                u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u * u) - u,
                v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v * v) - v,
            )
        }
        _ => return None,
    };
    Some((fx * (u + du) + cx, fy * (v + dv) + cy))
}

/// Warp a mask (255 keep, 0 ignore) from the distorted `src` camera to the
/// PINHOLE `dst` camera. Pixels that fall outside the source are "ignore".
pub fn warp_mask(mask: &image::GrayImage, src: &Camera, dst: &Camera) -> Result<image::GrayImage> {
    let (fx, fy) = dst.focal();
    let (cx, cy) = dst.principal_point();
    if !matches!(
        dst.model,
        CameraModel::PINHOLE | CameraModel::SIMPLE_PINHOLE
    ) {
        return Err(PoseError::Invalid(format!(
            "undistorted camera {} is {}, expected PINHOLE",
            dst.id,
            dst.model.name()
        )));
    }
    if world_to_image(src, 0.0, 0.0).is_none() {
        return Err(PoseError::Invalid(format!(
            "cannot undistort masks for camera model {}",
            src.model.name()
        )));
    }
    let (w, h) = (mask.width() as i64, mask.height() as i64);
    let keep = |x: i64, y: i64| -> bool {
        x >= 0 && y >= 0 && x < w && y < h && mask.get_pixel(x as u32, y as u32).0[0] >= 128
    };
    let out = image::GrayImage::from_fn(dst.width as u32, dst.height as u32, |x, y| {
        let u = (x as f64 + 0.5 - cx) / fx;
        let v = (y as f64 + 0.5 - cy) / fy;
        let Some((sx, sy)) = world_to_image(src, u, v) else {
            return image::Luma([0]);
        };
        // Bilinear footprint in pixel-index space (centres at integer + 0.5).
        let (px, py) = (sx - 0.5, sy - 0.5);
        let (x0, y0) = (px.floor() as i64, py.floor() as i64);
        let (ax, ay) = (px - x0 as f64, py - y0 as f64);
        let mut ok = true;
        for (dx, dy, wgt) in [
            (0, 0, (1.0 - ax) * (1.0 - ay)),
            (1, 0, ax * (1.0 - ay)),
            (0, 1, (1.0 - ax) * ay),
            (1, 1, ax * ay),
        ] {
            if wgt > 1e-9 && !keep(x0 + dx, y0 + dy) {
                ok = false;
            }
        }
        image::Luma([if ok { 255 } else { 0 }])
    });
    Ok(out)
}

fn replace_dir(dir: &Path) -> Result<()> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| PoseError::io(dir, e))?;
    }
    Ok(())
}

/// Move COLMAP's undistorter output in `und` (`images/`, `sparse/`) into the
/// scene-layout folder `dest` (`images/`, `sparse/0/`, and `masks/` warped
/// from `masks` when given). `distorted_model` is the model the undistorter
/// read (it gives each image's original camera).
pub fn install_undistorted(
    und: &Path,
    distorted_model: &Path,
    masks: Option<&Path>,
    dest: &Path,
) -> Result<()> {
    std::fs::create_dir_all(dest).map_err(|e| PoseError::io(dest, e))?;
    let images = dest.join("images");
    replace_dir(&images)?;
    let src_images = und.join("images");
    if std::fs::rename(&src_images, &images).is_err() {
        std::fs::create_dir_all(&images).map_err(|e| PoseError::io(&images, e))?;
        let rd = std::fs::read_dir(&src_images).map_err(|e| PoseError::io(&src_images, e))?;
        for e in rd.flatten() {
            let to = images.join(e.file_name());
            std::fs::copy(e.path(), &to).map_err(|err| PoseError::io(&to, err))?;
        }
    }
    let sparse = dest.join("sparse").join("0");
    install_model(&und.join("sparse"), &sparse)?;

    let masks_out = dest.join("masks");
    replace_dir(&masks_out)?;
    if let Some(masks) = masks {
        let before = read_model(distorted_model)?;
        let after = read_model(&sparse)?;
        for im in after.images.values() {
            let Some(orig) = before.image_by_name(&im.name) else {
                continue;
            };
            let (Some(src_cam), Some(dst_cam)) = (
                before.cameras.get(&orig.camera_id),
                after.cameras.get(&im.camera_id),
            ) else {
                continue;
            };
            let mask = loader::io::read_gray8(masks.join(format!("{}.png", im.name)))?;
            if mask.width() as u64 != src_cam.width || mask.height() as u64 != src_cam.height {
                return Err(PoseError::Invalid(format!(
                    "{}: mask is {}×{} but camera {} is {}×{}",
                    masks.join(format!("{}.png", im.name)).display(),
                    mask.width(),
                    mask.height(),
                    src_cam.id,
                    src_cam.width,
                    src_cam.height
                )));
            }
            let warped = warp_mask(&mask, src_cam, dst_cam)?;
            loader::io::write_png_gray8(masks_out.join(format!("{}.png", im.name)), &warped)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(model: CameraModel, params: Vec<f64>) -> Camera {
        Camera {
            id: 1,
            model,
            width: 64,
            height: 48,
            params,
        }
    }

    fn test_mask() -> image::GrayImage {
        image::GrayImage::from_fn(64, 48, |x, y| {
            image::Luma([if (20..40).contains(&x) && (10..30).contains(&y) {
                0
            } else {
                255
            }])
        })
    }

    #[test]
    fn zero_distortion_warp_is_identity_inside() {
        let src = cam(CameraModel::SIMPLE_RADIAL, vec![50.0, 32.0, 24.0, 0.0]);
        let dst = cam(CameraModel::PINHOLE, vec![50.0, 50.0, 32.0, 24.0]);
        let m = test_mask();
        let w = warp_mask(&m, &src, &dst).unwrap();
        assert_eq!(w, m);
    }

    #[test]
    fn opencv_matches_simple_radial_and_moving_regions_never_shrink() {
        let k = 0.08;
        let a = cam(CameraModel::SIMPLE_RADIAL, vec![50.0, 32.0, 24.0, k]);
        let b = cam(
            CameraModel::OPENCV,
            vec![50.0, 50.0, 32.0, 24.0, k, 0.0, 0.0, 0.0],
        );
        let c = cam(
            CameraModel::FULL_OPENCV,
            vec![50.0, 50.0, 32.0, 24.0, k, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        for (u, v) in [(0.3, -0.2), (-0.5, 0.4), (0.0, 0.0)] {
            let pa = world_to_image(&a, u, v).unwrap();
            let pb = world_to_image(&b, u, v).unwrap();
            let pc = world_to_image(&c, u, v).unwrap();
            assert!((pa.0 - pb.0).abs() < 1e-12 && (pa.1 - pb.1).abs() < 1e-12);
            assert!((pa.0 - pc.0).abs() < 1e-12 && (pa.1 - pc.1).abs() < 1e-12);
            // Radial distortion with k > 0 pushes points outward.
            let r = ((pa.0 - 32.0).powi(2) + (pa.1 - 24.0).powi(2)).sqrt();
            assert!(r >= 50.0 * (u * u + v * v).sqrt() - 1e-12);
        }
        let dst = cam(CameraModel::PINHOLE, vec![50.0, 50.0, 32.0, 24.0]);
        let m = test_mask();
        let w = warp_mask(&m, &a, &dst).unwrap();
        // Every target pixel whose source position is on a masked pixel is masked.
        for y in 0..48u32 {
            for x in 0..64u32 {
                let u = (x as f64 + 0.5 - 32.0) / 50.0;
                let v = (y as f64 + 0.5 - 24.0) / 50.0;
                let (sx, sy) = world_to_image(&a, u, v).unwrap();
                let (ix, iy) = (sx.floor() as i64, sy.floor() as i64);
                let inside = ix >= 0 && iy >= 0 && ix < 64 && iy < 48;
                if !inside || m.get_pixel(ix as u32, iy as u32).0[0] == 0 {
                    assert_eq!(w.get_pixel(x, y).0[0], 0, "({x},{y})");
                }
            }
        }
        assert!(w.pixels().any(|p| p.0[0] == 255));
        let fish = cam(
            CameraModel::OPENCV_FISHEYE,
            vec![50.0, 50.0, 32.0, 24.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert!(warp_mask(&m, &fish, &dst).is_err());
    }
}
