//! Tests for `scene.rs` on small scene folders written to temp dirs.

use super::*;
use crate::camera::CameraModel;
use crate::colmap::{ColmapImage, write_model_binary};
use crate::io::{write_png_gray8, write_png_rgb8};
use crate::split::{Split, SplitEntry, write_split};
use crate::transforms::{Transforms, write_transforms};
use image::{Luma, Rgb, RgbImage};
use nalgebra::Vector3;

const NAMES: [&str; 3] = ["b.png", "a.png", "c.png"];

fn write_images(root: &Path, w: u32, h: u32) {
    for (k, n) in NAMES.iter().enumerate() {
        let img = RgbImage::from_fn(w, h, |x, y| {
            Rgb([(x * 20) as u8, (y * 30) as u8, k as u8 * 100])
        });
        write_png_rgb8(root.join("images").join(n), &img).unwrap();
    }
}

fn model() -> ColmapModel {
    let mut m = ColmapModel::default();
    m.cameras.insert(
        1,
        Camera {
            id: 1,
            model: CameraModel::PINHOLE,
            width: 8,
            height: 6,
            params: vec![10.0, 11.0, 4.0, 3.0],
        },
    );
    for (k, n) in NAMES.iter().enumerate() {
        let pose = Pose::look_at(
            Vector3::new(k as f64, -3.0, 0.0),
            Vector3::zeros(),
            Vector3::z(),
        );
        m.images
            .insert(k as u32 + 1, ColmapImage::new(k as u32 + 1, pose, 1, *n));
    }
    m
}

#[test]
fn loads_colmap_scene_with_masks_split_and_gt() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_images(root, 8, 6);
    let m = model();
    write_model_binary(&m, root.join("sparse/0")).unwrap();
    let mut mask = GrayImage::from_pixel(8, 6, Luma([255]));
    mask.put_pixel(2, 1, Luma([0]));
    write_png_gray8(root.join("masks/a.png.png"), &mask).unwrap();
    write_png_gray8(
        root.join("gt_motion/c.png"),
        &GrayImage::from_pixel(8, 6, Luma([255])),
    )
    .unwrap();
    let split = Split {
        clutter: vec![SplitEntry::Index(0), SplitEntry::Index(1)],
        extra: vec![SplitEntry::Name("c.png".into())],
        clean: None,
    };
    write_split(root.join("split.json"), &split).unwrap();

    let s = Scene::load(root, &SceneOptions::default()).unwrap();
    assert_eq!(s.names(), vec!["a.png", "b.png", "c.png"]);
    assert_eq!(s.pose_source, PoseSource::Colmap);
    assert_eq!(s.frames[0].pose, Some(m.images[&2].pose)); // a.png is image id 2
    assert_eq!(s.frames[0].intrinsics.fx, 10.0);
    assert_eq!(s.split_indices("test"), vec![2]);
    assert_eq!(s.split_indices("train"), vec![0, 1]);
    let mk = s.load_mask(0).unwrap().unwrap();
    assert_eq!(mk.get_pixel(2, 1).0[0], 0);
    assert!(s.load_mask(1).unwrap().is_none());
    assert!(s.load_gt_motion(2).unwrap().is_some());
    let img = s.load_image(1).unwrap();
    assert_eq!(img.dimensions(), (8, 6));
    assert!((img.get_pixel(3, 2).0[0] - 60.0 / 255.0).abs() < 1e-6);
}

#[test]
fn downscale_resizes_or_uses_images_n() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    // Images 8× the camera's 8×6 calibration size: intrinsics scale by 4
    // after the downscale of 2.
    write_images(root, 64, 48);
    write_model_binary(&model(), root.join("sparse/0")).unwrap();
    let mut mask = GrayImage::from_pixel(64, 48, Luma([255]));
    mask.put_pixel(63, 47, Luma([0]));
    write_png_gray8(root.join("masks/a.png.png"), &mask).unwrap();
    let s = Scene::load(root, &SceneOptions { downscale: 2 }).unwrap();
    let k = s.frames[0].intrinsics;
    assert_eq!(
        (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
        (32, 24, 40.0, 44.0, 16.0, 12.0)
    );
    assert_eq!(s.load_image(0).unwrap().dimensions(), (32, 24));
    let m = s.load_mask(0).unwrap().unwrap();
    assert_eq!(m.dimensions(), (32, 24));
    assert_eq!(m.get_pixel(31, 23).0[0], 0); // nearest keeps the hard edge value
    // With images_2/ present the files there are used as they are.
    for n in NAMES {
        write_png_rgb8(
            root.join("images_2").join(n),
            &RgbImage::from_pixel(32, 24, Rgb([9, 9, 9])),
        )
        .unwrap();
    }
    let s = Scene::load(root, &SceneOptions { downscale: 2 }).unwrap();
    assert!(s.frames[0].image_path.starts_with(root.join("images_2")));
    assert_eq!(s.load_image(0).unwrap().get_pixel(0, 0).0[0], 9.0 / 255.0);
    assert!(Scene::load(root, &SceneOptions { downscale: 0 }).is_err());
    // A downscale leaving fewer than 16 px per side is refused with the range.
    let e = Scene::load(root, &SceneOptions { downscale: 4 })
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("downscale 4 leaves 16x12 px") && e.contains("from 1 to 3"),
        "{e}"
    );
}

#[test]
fn transforms_json_used_without_sparse() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_images(root, 8, 6);
    let m = model();
    let t = Transforms::from_model(&m, "images/").unwrap();
    write_transforms(root.join("transforms.json"), &t).unwrap();
    let s = Scene::load(root, &SceneOptions::default()).unwrap();
    assert_eq!(s.pose_source, PoseSource::Transforms);
    let p = s.frames[2].pose.unwrap();
    assert!((p.world_to_camera() - m.images[&3].pose.world_to_camera()).norm() < 1e-12);
    assert_eq!(s.frames[2].intrinsics.fy, 11.0);
}

#[test]
fn errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    std::fs::create_dir_all(root.join("images")).unwrap();
    let e = Scene::load(root, &SceneOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("images") && e.contains("no images"), "{e}");

    write_images(root, 8, 6);
    write_png_gray8(root.join("masks/b.png.png"), &GrayImage::new(4, 3)).unwrap();
    let e = Scene::load(root, &SceneOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("b.png.png") && e.contains("4x3") && e.contains("8x6"),
        "{e}"
    );
    std::fs::remove_file(root.join("masks/b.png.png")).unwrap();

    let mut m = model();
    m.images.get_mut(&1).unwrap().name = "missing.png".into();
    write_transforms(
        root.join("transforms.json"),
        &Transforms::from_model(&m, "images/").unwrap(),
    )
    .unwrap();
    let e = Scene::load(root, &SceneOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("missing.png") && e.contains("transforms.json"),
        "{e}"
    );
}
