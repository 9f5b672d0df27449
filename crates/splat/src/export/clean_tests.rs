#![allow(clippy::needless_range_loop)]
use super::*;
use crate::types::sh_coeffs;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// A camera at `eye` looking at `target` (OpenCV axes, world y down), 90°
/// horizontal field of view, 200×150 pixels.
fn look_at(eye: [f32; 3], target: [f32; 3]) -> RenderCamera {
    let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let norm = |a: [f32; 3]| {
        let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        a.map(|v| v / n)
    };
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let z = norm(sub(target, eye));
    let x = norm(cross([0.0, 1.0, 0.0], z));
    let y = cross(z, x);
    let rotation = [x, y, z];
    let t = [0, 1, 2]
        .map(|r| -(rotation[r][0] * eye[0] + rotation[r][1] * eye[1] + rotation[r][2] * eye[2]));
    RenderCamera {
        width: 200,
        height: 150,
        fx: 100.0,
        fy: 100.0,
        cx: 100.0,
        cy: 75.0,
        rotation,
        translation: t,
        near: 0.01,
        far: 1e10,
    }
}

/// 2000 well-behaved splats in the unit cube plus planted outliers; returns
/// the set, the cameras (a ring of 8 at radius 4 around the cube centre in
/// the x–z plane) and the planted index lists per criterion.
fn planted() -> (Splats, Vec<RenderCamera>, [Vec<usize>; 4]) {
    let mut rng = Pcg64::seed_from_u64(5);
    let mut s = Splats {
        sh_degree: 1,
        ..Default::default()
    };
    let k3 = sh_coeffs(1) * 3;
    let push = |s: &mut Splats, p: [f32; 3], ls: f32, op: f32| {
        s.means.push(p);
        s.log_scales.push([ls, ls - 0.3, ls - 0.6]);
        s.rotations.push([1.0, 0.1, 0.0, 0.0]);
        s.opacity_logits.push(op);
        s.sh.extend(std::iter::repeat_n(0.1, k3));
    };
    for _ in 0..2000 {
        let p = [0; 3].map(|_| rng.random_range(0.0f32..1.0));
        let ls = rng.random_range(0.005f32..0.02).ln();
        let op = rng.random_range(-2.0f32..3.0);
        push(&mut s, p, ls, op);
    }
    let mut planted: [Vec<usize>; 4] = Default::default();
    // 1. transparent, inside the cube.
    for i in 0..5 {
        planted[0].push(s.len());
        push(&mut s, [0.2 + 0.1 * i as f32, 0.5, 0.5], 0.01f32.ln(), -8.0);
    }
    // 2. unseen: far along -y (above the ring, outside every frustum).
    for i in 0..4 {
        planted[1].push(s.len());
        push(
            &mut s,
            [0.5 + 0.1 * i as f32, -30.0, 0.5],
            0.01f32.ln(),
            2.0,
        );
    }
    // 3. oversized, inside the cube: σ = 1.5 > 50 × median (≈ 0.63) and > 0.1 × 4.4.
    for i in 0..3 {
        planted[2].push(s.len());
        push(&mut s, [0.5, 0.3 + 0.2 * i as f32, 0.5], 1.5f32.ln(), 1.0);
    }
    // 4. floaters between the cameras and the cube (outside [-0.5, 1.5]³).
    for i in 0..6 {
        planted[3].push(s.len());
        let a = i as f32 * std::f32::consts::TAU / 6.0;
        push(
            &mut s,
            [0.5 + 2.2 * a.cos(), 0.5, 0.5 + 2.2 * a.sin()],
            0.01f32.ln(),
            2.0,
        );
    }
    let cams = (0..8)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 8.0 + 0.2;
            look_at(
                [0.5 + 4.0 * a.cos(), 0.5, 0.5 + 4.0 * a.sin()],
                [0.5, 0.5, 0.5],
            )
        })
        .collect();
    (s, cams, planted)
}

#[test]
fn clean_removes_exactly_the_planted_outliers() {
    let (s, cams, planted) = planted();
    let scene = SceneGeometry {
        cameras: cams,
        points: Vec::new(),
    };
    let (kept, rep) = clean(&s, &scene, &CleanOptions::default()).unwrap();
    assert!(rep.unseen_checked);
    assert_eq!(rep.removed_transparent, 5, "{rep:?}");
    assert_eq!(rep.removed_unseen, 4, "{rep:?}");
    assert_eq!(rep.removed_oversized, 3, "{rep:?}");
    assert_eq!(rep.removed_outside_bounds, 6, "{rep:?}");
    assert_eq!(rep.kept, 2000);
    assert_eq!(kept.len(), 2000);
    assert_eq!(kept.sh.len(), 2000 * 12);
    // The kept set is exactly the first 2000 splats, in order.
    assert_eq!(kept.means[..], s.means[..2000]);
    assert_eq!(rep.extent_source, "cameras");
    assert!(
        (rep.scene_extent - 4.4).abs() < 1e-3,
        "{}",
        rep.scene_extent
    );
    assert!(planted.iter().flatten().all(|&i| i >= 2000));
}

#[test]
fn clean_without_cameras_skips_unseen_and_says_so() {
    let (s, _, _) = planted();
    let (_, rep) = clean(&s, &SceneGeometry::default(), &CleanOptions::default()).unwrap();
    assert!(!rep.unseen_checked);
    assert!(rep.notes.iter().any(|n| n.contains("unseen")));
    assert_eq!(rep.removed_unseen, 0);
    assert_eq!(rep.removed_transparent, 5);
    assert_eq!(rep.removed_oversized, 3);
    // Unseen splats far away now count as outside the bounds.
    assert_eq!(rep.removed_outside_bounds, 6 + 4);
    assert_eq!(rep.kept, 2000);
    assert_eq!(rep.extent_source, "bounds");
}

#[test]
fn static_points_define_the_bounds() {
    let (s, cams, _) = planted();
    // Static points only span x, z in [0, 0.5]: with the 0/100 percentiles the
    // box grows to [-0.25, 0.75], so splats with x or z > 0.75 go too.
    let points: Vec<[f32; 3]> = (0..500)
        .map(|i| {
            let t = i as f32 / 499.0;
            [0.5 * t, t, 0.5 * (1.0 - t)]
        })
        .collect();
    let expect_out = s.means[..2000]
        .iter()
        .filter(|p| p[0] > 0.75 || p[2] > 0.75)
        .count();
    let scene = SceneGeometry {
        cameras: cams,
        points,
    };
    let opts = CleanOptions {
        bounds_percentile: 0.0,
        ..Default::default()
    };
    let (_, rep) = clean(&s, &scene, &opts).unwrap();
    assert_eq!(rep.bounds_source, "points");
    assert_eq!(rep.removed_outside_bounds, 6 + expect_out);
    assert!(
        (rep.bounds_max[0] - 0.75).abs() < 1e-6,
        "{:?}",
        rep.bounds_max
    );
}

#[test]
fn invalid_options_are_rejected() {
    let o = CleanOptions {
        min_opacity: 1.5,
        ..Default::default()
    };
    assert!(clean(&Splats::default(), &SceneGeometry::default(), &o).is_err());
    let o = CleanOptions {
        bounds_percentile: 60.0,
        ..Default::default()
    };
    assert!(o.validate().is_err());
}

#[test]
fn scene_geometry_from_a_colmap_model() {
    use loader::colmap::{ColmapImage, ColmapModel, Point3D};
    let mut m = ColmapModel::default();
    m.cameras.insert(
        1,
        loader::Camera {
            id: 1,
            model: loader::CameraModel::PINHOLE,
            width: 640,
            height: 480,
            params: vec![500.0, 510.0, 320.0, 240.0],
        },
    );
    // 90° about z, then a translation: centre = -Rᵀ t.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let pose = loader::Pose {
        qvec: [h, 0.0, 0.0, h],
        tvec: [1.0, 2.0, 3.0],
    };
    m.images.insert(7, ColmapImage::new(7, pose, 1, "a.jpg"));
    m.images
        .insert(9, ColmapImage::new(9, loader::Pose::identity(), 1, "b.jpg"));
    for id in 0..3u64 {
        let xyz = [id as f64, 0.5, -1.0];
        m.points3d.insert(
            id,
            Point3D {
                id,
                xyz,
                rgb: [0; 3],
                error: 0.1,
                track: Vec::new(),
            },
        );
    }
    let g = SceneGeometry::from_colmap(&m);
    assert_eq!(g.cameras.len(), 2);
    assert_eq!(g.points.len(), 3);
    assert_eq!(g.points[2], [2.0, 0.5, -1.0]);
    let c = g.cameras[0];
    assert_eq!((c.width, c.height, c.fx, c.fy), (640, 480, 500.0, 510.0));
    let want = pose.center();
    for a in 0..3 {
        assert!((c.center()[a] - want[a] as f32).abs() < 1e-5);
    }
}

#[test]
fn a_view_filling_blob_near_a_camera_is_oversized() {
    let (mut s, mut cams, _) = planted();
    // A camera just outside the cube, and a splat 0.5 in front of it whose σ
    // (0.4) passes the median rule (50 × ≈ 0.0126) but whose 3σ radius is
    // 3 × 0.4 × 100 / 0.5 = 240 px > 200 px, the image's larger side.
    cams.push(look_at([0.5, 0.5, -0.3], [0.5, 0.5, 0.5]));
    let blob = s.len();
    s.means.push([0.5, 0.5, 0.2]);
    s.log_scales.push([0.4f32.ln(), 0.1f32.ln(), 0.1f32.ln()]);
    s.rotations.push([1.0, 0.0, 0.0, 0.0]);
    s.opacity_logits.push(2.0);
    let k3 = s.coeffs_per_channel() * 3;
    s.sh.extend(std::iter::repeat_n(0.1, k3));
    let scene = SceneGeometry {
        cameras: cams.clone(),
        points: Vec::new(),
    };
    let (kept, rep) = clean(&s, &scene, &CleanOptions::default()).unwrap();
    assert_eq!(rep.removed_oversized, 3 + 1, "{rep:?}");
    assert_eq!(rep.kept, 2000);
    assert!(!kept.means.contains(&s.means[blob]));
    // The same splat half as large (120 px) stays, and so does everything with
    // the rule off.
    s.log_scales[blob] = [0.2f32.ln(), 0.1f32.ln(), 0.1f32.ln()];
    let (_, rep) = clean(&s, &scene, &CleanOptions::default()).unwrap();
    assert_eq!((rep.removed_oversized, rep.kept), (3, 2001), "{rep:?}");
    s.log_scales[blob] = [0.4f32.ln(), 0.1f32.ln(), 0.1f32.ln()];
    let off = CleanOptions {
        max_footprint: 0.0,
        ..Default::default()
    };
    let (_, rep) = clean(&s, &scene, &off).unwrap();
    assert_eq!((rep.removed_oversized, rep.kept), (3, 2001), "{rep:?}");
}

#[test]
fn the_extent_rule_is_off_by_default_and_available() {
    let (s, cams, _) = planted();
    let scene = SceneGeometry {
        cameras: cams,
        points: Vec::new(),
    };
    // 0.1 × extent 4.4 = 0.44 < σ 1.5 of the planted oversized splats, and
    // above every regular σ (≤ 0.02): same three removed either way, while a
    // tight fraction removes regular splats too.
    let on = CleanOptions {
        max_scale_extent_fraction: 0.1,
        ..Default::default()
    };
    assert_eq!(clean(&s, &scene, &on).unwrap().1.removed_oversized, 3);
    let tight = CleanOptions {
        max_scale_extent_fraction: 0.003,
        ..Default::default()
    };
    let rep = clean(&s, &scene, &tight).unwrap().1;
    assert!(rep.removed_oversized > 100, "{rep:?}");
}
