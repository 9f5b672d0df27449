//! Tests for `composite.rs` on small backgrounds and DAVIS folders written
//! to temp dirs: pasted pixels exactly where the mask says, the rest
//! untouched, split / transforms / gt_motion consistent, bad input named.

use super::*;
use crate::transforms::{IntrinsicFields, Transforms, TransformsFrame};
use crate::{Scene, SceneOptions};
use image::{Luma, Rgb};

const MAGENTA: Rgb<u8> = Rgb([255, 0, 255]);

#[test]
fn paste_copies_exactly_the_mask_at_scale_one() {
    let mut dst = RgbImage::from_pixel(10, 8, Rgb([10, 20, 30]));
    let mut moving = GrayImage::new(10, 8);
    let src = RgbImage::from_fn(4, 3, |x, y| Rgb([x as u8 * 50, y as u8 * 70, 200]));
    let mask = GrayImage::from_fn(4, 3, |x, y| Luma([if (x + y) % 2 == 0 { 255 } else { 0 }]));
    let place = Placement {
        scale: 1.0,
        offset_x: 3.0,
        offset_y: 2.0,
    };
    let n = paste(&mut dst, &mut moving, &src, &mask, place);
    assert_eq!(n, 6);
    for (x, y, p) in dst.enumerate_pixels() {
        let inside = (3..7).contains(&x) && (2..5).contains(&y);
        let on = inside && mask.get_pixel(x - 3, y - 2)[0] == 255;
        if on {
            assert_eq!(*p, *src.get_pixel(x - 3, y - 2), "({x},{y})");
            assert_eq!(moving.get_pixel(x, y)[0], 255);
        } else {
            assert_eq!(*p, Rgb([10, 20, 30]), "({x},{y})");
            assert_eq!(moving.get_pixel(x, y)[0], 0);
        }
    }
}

#[test]
fn paste_scales_and_clips() {
    let mut dst = RgbImage::new(6, 6);
    let mut moving = GrayImage::new(6, 6);
    let src = RgbImage::from_pixel(2, 2, MAGENTA);
    let mask = GrayImage::from_pixel(2, 2, Luma([255]));
    // Scale 2 at (4, -1): covers x 4..8, y -1..3 → inside the image x 4..6, y 0..3.
    let place = Placement {
        scale: 2.0,
        offset_x: 4.0,
        offset_y: -1.0,
    };
    assert_eq!(paste(&mut dst, &mut moving, &src, &mask, place), 2 * 3);
    for (x, y, p) in dst.enumerate_pixels() {
        let on = x >= 4 && y < 3;
        assert_eq!(*p == MAGENTA, on, "({x},{y})");
        assert_eq!(moving.get_pixel(x, y)[0] == 255, on);
    }
}

fn background(root: &Path, n: usize, w: u32, h: u32) {
    let mut t = Transforms {
        intrinsics: IntrinsicFields {
            fl_x: Some(40.0),
            fl_y: Some(42.0),
            cx: Some(w as f64 / 2.0),
            cy: Some(h as f64 / 2.0),
            w: Some(w as f64),
            h: Some(h as f64),
            k1: Some(0.01),
            ..Default::default()
        },
        ..Default::default()
    };
    for i in 0..n {
        // Colours never magenta: blue channel 0..=60.
        let img = RgbImage::from_fn(w, h, |x, y| {
            Rgb([(x * 7 + i as u32) as u8, (y * 9) as u8, (i * 3) as u8])
        });
        let name = format!("{:04}.jpg", i + 1);
        // Lossless content under a .jpg name is not possible; write PNG bytes
        // under a .png name and list that in transforms.json.
        let name = name.replace(".jpg", ".png");
        write_png_rgb8(root.join("images").join(&name), &img).unwrap();
        let mut m = vec![vec![0.0; 4]; 4];
        for (k, row) in m.iter_mut().enumerate() {
            row[k] = 1.0;
        }
        m[0][3] = i as f64 * 0.1;
        t.frames.push(TransformsFrame {
            file_path: format!("images/{name}"),
            transform_matrix: m,
            intrinsics: IntrinsicFields::default(),
            extra: Default::default(),
        });
    }
    write_transforms(root.join("transforms.json"), &t).unwrap();
}

fn davis(root: &Path, seq: &str, n: usize, w: u32, h: u32, mask_size: (u32, u32)) {
    for i in 0..n {
        let img = root.join(format!("JPEGImages/480p/{seq}/{i:05}.png"));
        std::fs::create_dir_all(img.parent().unwrap()).unwrap();
        write_png_rgb8(&img, &RgbImage::from_pixel(w, h, MAGENTA)).unwrap();
        // A rectangle that moves one pixel per frame.
        let m = GrayImage::from_fn(mask_size.0, mask_size.1, |x, y| {
            let on = x >= 2 + i as u32 % 4 && x < 9 + i as u32 % 4 && (3..12).contains(&y);
            Luma([if on { 255 } else { 0 }])
        });
        write_png_gray8(root.join(format!("Annotations/480p/{seq}/{i:05}.png")), &m).unwrap();
    }
}

#[test]
fn composite_scene_is_consistent() {
    let dir = tempfile::tempdir().unwrap();
    let (bg, dv, out) = (
        dir.path().join("bg"),
        dir.path().join("davis"),
        dir.path().join("out"),
    );
    background(&bg, 17, 32, 24);
    davis(&dv, "swan", 30, 16, 16, (16, 16));
    davis(&dv, "car", 30, 16, 16, (16, 16));
    let opts = CompositeOptions {
        downscale: 1,
        run_length: 4,
        ..Default::default()
    };
    let rep = composite(&bg, &dv, &out, &opts).unwrap();
    assert_eq!((rep.frames, rep.clutter, rep.extra), (17, 14, 3));
    assert_eq!((rep.width, rep.height), (32, 24));
    assert!(rep.coverage_min > 0.0 && rep.coverage_max < 0.6);

    let scene = Scene::load(&out, &SceneOptions::default()).unwrap();
    assert_eq!(scene.len(), 17);
    assert_eq!(scene.split_indices("extra"), vec![0, 8, 16]);
    let clutter = scene.split_indices("clutter");
    assert_eq!(clutter.len(), 14);
    for i in 0..17 {
        let f = &scene.frames[i];
        assert_eq!(f.name, format!("{:04}.png", i + 1));
        assert!(f.pose.is_some(), "frame {i} has a pose");
        let t = f.pose.unwrap().tvec;
        let norm = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
        assert!((norm - i as f64 * 0.1).abs() < 1e-9, "frame {i} pose");
        let orig = read_rgb8(bg.join("images").join(&f.name)).unwrap();
        let got = read_rgb8(&f.image_path).unwrap();
        let gt = scene.load_gt_motion(i).unwrap().unwrap();
        let mut pasted = 0;
        for (x, y, p) in got.enumerate_pixels() {
            let moving = gt.get_pixel(x, y)[0] == 255;
            if moving {
                assert_eq!(*p, MAGENTA, "frame {i} ({x},{y}) pasted");
                pasted += 1;
            } else {
                assert_eq!(p, orig.get_pixel(x, y), "frame {i} ({x},{y}) untouched");
            }
        }
        if i % 8 == 0 {
            assert_eq!(pasted, 0, "test view {i} is clean");
            assert!(!out.join("clean").join(&f.name).exists());
        } else {
            assert!(pasted > 0, "clutter frame {i} has a distractor");
            assert_eq!(read_rgb8(out.join("clean").join(&f.name)).unwrap(), orig);
            let cov = rep.pasted.iter().find(|p| p.0 == f.name).unwrap().3;
            assert!((cov - pasted as f64 / (32.0 * 24.0)).abs() < 1e-12);
        }
    }
    // Same seed → same bytes; the distractor moves between consecutive frames.
    let out2 = dir.path().join("out2");
    composite(&bg, &dv, &out2, &opts).unwrap();
    let a = std::fs::read(out.join("gt_motion/0002.png")).unwrap();
    assert_eq!(a, std::fs::read(out2.join("gt_motion/0002.png")).unwrap());
    assert_ne!(a, std::fs::read(out.join("gt_motion/0003.png")).unwrap());
}

#[test]
fn a_followed_object_keeps_its_place_in_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let (bg, dv) = (dir.path().join("bg"), dir.path().join("davis"));
    background(&bg, 9, 32, 24);
    // The DAVIS object moves 1 px per frame in its own video.
    davis(&dv, "swan", 30, 16, 16, (16, 16));
    let gt = |out: &Path, name: &str| std::fs::read(out.join("gt_motion").join(name)).unwrap();
    for follow in [false, true] {
        let out = dir.path().join(format!("out_{follow}"));
        let opts = CompositeOptions {
            downscale: 1,
            run_length: 4,
            follow,
            ..Default::default()
        };
        composite(&bg, &dv, &out, &opts).unwrap();
        // Frames 0002–0005 are the first run (0001 is a test view).
        let first = gt(&out, "0002.png");
        let same = ["0003.png", "0004.png", "0005.png"]
            .iter()
            .all(|n| gt(&out, n) == first);
        assert_eq!(same, follow, "follow {follow}");
    }
}

#[test]
fn several_objects_per_frame_add_up() {
    let dir = tempfile::tempdir().unwrap();
    let (bg, dv) = (dir.path().join("bg"), dir.path().join("davis"));
    background(&bg, 9, 32, 24);
    davis(&dv, "car", 30, 16, 16, (16, 16));
    davis(&dv, "swan", 30, 16, 16, (16, 16));
    let run = |n: usize| {
        let out = dir.path().join(format!("out{n}"));
        let opts = CompositeOptions {
            downscale: 1,
            run_length: 4,
            objects_per_frame: n,
            object_height: [0.3, 0.3],
            ..Default::default()
        };
        (composite(&bg, &dv, &out, &opts), out)
    };
    let (one, _) = run(1);
    let (two, out2) = run(2);
    let (one, two) = (one.unwrap(), two.unwrap());
    // The first slot is the one-object scene's, so the two-object frames
    // hold it and more; each frame names both sequences.
    for (a, b) in one.pasted.iter().zip(&two.pasted) {
        assert_eq!(a.0, b.0);
        assert!(b.3 >= a.3, "{} covers {} < {}", b.0, b.3, a.3);
        let seqs: Vec<&str> = b.1.split('+').collect();
        assert_eq!(seqs.len(), 2, "{}", b.1);
        assert_ne!(seqs[0], seqs[1]);
        assert!(b.1.starts_with(&a.1));
        // The reported coverage is the ground truth's.
        let gt = read_gray8(out2.join("gt_motion").join(&b.0)).unwrap();
        let n = gt.pixels().filter(|p| p[0] == 255).count();
        assert!((b.3 - n as f64 / (32.0 * 24.0)).abs() < 1e-12);
    }
    assert!(two.coverage_mean > one.coverage_mean);
    let e = run(0).0.unwrap_err().to_string();
    assert!(e.contains("objects_per_frame"), "{e}");
}

#[test]
fn downscale_scales_images_and_intrinsics() {
    let dir = tempfile::tempdir().unwrap();
    let (bg, dv, out) = (
        dir.path().join("bg"),
        dir.path().join("davis"),
        dir.path().join("out"),
    );
    background(&bg, 9, 32, 24);
    davis(&dv, "swan", 10, 16, 16, (16, 16));
    let opts = CompositeOptions {
        downscale: 2,
        ..Default::default()
    };
    let rep = composite(&bg, &dv, &out, &opts).unwrap();
    assert_eq!((rep.width, rep.height), (16, 12));
    let t = read_transforms(out.join("transforms.json")).unwrap();
    let f = &t.intrinsics;
    assert_eq!((f.fl_x, f.fl_y), (Some(20.0), Some(21.0)));
    assert_eq!(
        (f.cx, f.cy, f.w, f.h),
        (Some(8.0), Some(6.0), Some(16.0), Some(12.0))
    );
    assert_eq!(f.k1, Some(0.01));
    let scene = Scene::load(&out, &SceneOptions::default()).unwrap();
    assert_eq!(scene.frames[3].intrinsics.width, 16);
    assert!((scene.frames[3].intrinsics.fx - 20.0).abs() < 1e-9);
    assert_eq!(
        scene.load_gt_motion(3).unwrap().unwrap().dimensions(),
        (16, 12)
    );
}

#[test]
fn bad_input_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (bg, dv, out) = (
        dir.path().join("bg"),
        dir.path().join("davis"),
        dir.path().join("out"),
    );
    let opts = CompositeOptions {
        downscale: 1,
        ..Default::default()
    };
    // Missing background images/.
    let e = composite(&bg, &dv, &out, &opts).unwrap_err().to_string();
    assert!(e.contains("bg/images"), "{e}");
    background(&bg, 3, 32, 24);
    // Missing DAVIS folder.
    let e = composite(&bg, &dv, &out, &opts).unwrap_err().to_string();
    assert!(e.contains("JPEGImages/480p"), "{e}");
    // Annotation of another size than its image.
    davis(&dv, "swan", 5, 16, 16, (15, 16));
    let e = composite(&bg, &dv, &out, &opts).unwrap_err().to_string();
    assert!(
        e.contains("Annotations/480p/swan/") && e.contains("15x16"),
        "{e}"
    );
    assert!(!e.contains('\n'));
    // Missing transforms.json.
    std::fs::remove_file(bg.join("transforms.json")).unwrap();
    let e = composite(&bg, &dv, &out, &opts).unwrap_err().to_string();
    assert!(e.contains("transforms.json"), "{e}");
    // Bad options.
    let bad = CompositeOptions {
        downscale: 0,
        ..Default::default()
    };
    assert!(bad.validate().is_err());
}
