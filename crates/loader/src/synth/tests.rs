//! Tests of the synthetic scenes: renderer known answers, determinism,
//! ground-truth consistency (masks, points), and the shipped specs.

use super::raster::{self, NONE, Tri, Vertex, View};
use super::texture::{Pattern, Style, Texture};
use super::*;
use nalgebra::Vector3;
use std::path::PathBuf;

fn flat_texture() -> Texture {
    let style = Style {
        pattern: Pattern::Checker,
        palette: [[0.5; 3]; 4],
        seed: 3,
    };
    Texture::bake(&style, 1.0, 1.0, 16.0)
}

fn quad(c: [[f64; 3]; 4], material: u32) -> [Tri; 2] {
    let uv = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
    let v = |i: usize| Vertex {
        p: Vector3::from(c[i]),
        uv: uv[i],
    };
    [
        Tri {
            v: [v(0), v(1), v(2)],
            material,
            shade: 1.0,
        },
        Tri {
            v: [v(0), v(2), v(3)],
            material,
            shade: 1.0,
        },
    ]
}

fn test_view(ss: u32) -> View {
    let intr = Intrinsics {
        width: 64,
        height: 48,
        fx: 50.0,
        fy: 50.0,
        cx: 32.0,
        cy: 24.0,
    };
    View {
        pose: Pose::identity(),
        intr,
        ss,
    }
}

/// Covered sample count per pixel of a rasterised buffer, and the setups.
fn raster_counts(
    view: &View,
    tris: &[Tri],
) -> (Vec<usize>, Vec<raster::Sample>, Vec<raster::Setup>) {
    let tex = vec![flat_texture(), flat_texture()];
    let setups = raster::setup(view, tris, &tex);
    let mut buf = raster::new_buffer(view);
    let (ws, _) = view.sample_dims();
    raster::rasterize(&setups, &mut buf, ws, None);
    let s = view.ss as usize;
    let (w, h) = (view.intr.width as usize, view.intr.height as usize);
    let mut counts = vec![0; w * h];
    for (i, smp) in buf.iter().enumerate() {
        if smp.tri != NONE {
            counts[(i / ws / s) * w + (i % ws) / s] += 1;
        }
    }
    (counts, buf, setups)
}

#[test]
fn quad_at_known_depth_covers_expected_pixel_rectangle() {
    // x ∈ [-1, 1], y ∈ [-0.5, 0.5] at z = 5 with f = 50 → pixels x ∈ [22, 42), y ∈ [19, 29).
    let view = test_view(3);
    let tris = quad(
        [
            [-1.0, 0.5, 5.0],
            [1.0, 0.5, 5.0],
            [1.0, -0.5, 5.0],
            [-1.0, -0.5, 5.0],
        ],
        0,
    );
    let (counts, buf, _) = raster_counts(&view, &tris);
    for y in 0..48 {
        for x in 0..64 {
            let inside = (22..42).contains(&x) && (19..29).contains(&y);
            assert_eq!(
                counts[y * 64 + x],
                if inside { 9 } else { 0 },
                "pixel ({x}, {y})"
            );
        }
    }
    assert!(
        buf.iter()
            .filter(|s| s.tri != NONE)
            .all(|s| (s.depth - 5.0).abs() < 1e-5)
    );
}

#[test]
fn texture_coordinates_are_perspective_correct() {
    // A quad receding in depth: the u at each sample must equal the u of the
    // exact ray–plane intersection (affine screen interpolation would not).
    let view = test_view(2);
    let c = [
        [-1.0, 0.8, 2.0],
        [1.5, 0.8, 9.0],
        [1.5, -0.8, 9.0],
        [-1.0, -0.8, 2.0],
    ];
    let tris = quad(c, 0);
    let (_, buf, _) = raster_counts(&view, &tris);
    let (ws, _) = view.sample_dims();
    let mut checked = 0;
    for (i, s) in buf.iter().enumerate().filter(|(_, s)| s.tri != NONE) {
        let (sx, sy) = ((i % ws) as f64 + 0.5, (i / ws) as f64 + 0.5);
        let d = Vector3::new((sx / 2.0 - 32.0) / 50.0, (sy / 2.0 - 24.0) / 50.0, 1.0);
        // The plane contains the x-z line from (-1, 2) to (1.5, 9): x = -1 + 2.5 u, z = 2 + 7 u.
        // Ray: x = d.x z → d.x (2 + 7u) = -1 + 2.5u → u = (1 + 2 d.x) / (2.5 − 7 d.x).
        let u = (1.0 + 2.0 * d.x) / (2.5 - 7.0 * d.x);
        assert!((s.u as f64 - u).abs() < 1e-4, "sample {i}: {} vs {u}", s.u);
        assert!((s.depth as f64 - (2.0 + 7.0 * u)).abs() < 1e-3);
        checked += 1;
    }
    assert!(checked > 500, "{checked}");
}

#[test]
fn nearer_object_hides_farther_in_any_order() {
    let view = test_view(2);
    let far = quad(
        [
            [-3.0, 2.0, 8.0],
            [3.0, 2.0, 8.0],
            [3.0, -2.0, 8.0],
            [-3.0, -2.0, 8.0],
        ],
        0,
    );
    let near = quad(
        [
            [-0.4, 0.4, 4.0],
            [0.4, 0.4, 4.0],
            [0.4, -0.4, 4.0],
            [-0.4, -0.4, 4.0],
        ],
        1,
    );
    let a: Vec<Tri> = far.iter().chain(near.iter()).copied().collect();
    let b: Vec<Tri> = near.iter().chain(far.iter()).copied().collect();
    let (_, ba, sa) = raster_counts(&view, &a);
    let (_, bb, sb) = raster_counts(&view, &b);
    let (ws, _) = view.sample_dims();
    // Centre pixel (32, 24) shows the near quad (material 1) at depth 4.
    let centre = (24 * 2) * ws + 32 * 2;
    for (buf, setups) in [(&ba, &sa), (&bb, &sb)] {
        assert_eq!(setups[buf[centre].tri as usize].material, 1);
        assert!((buf[centre].depth - 4.0).abs() < 1e-5);
        // A pixel outside the near quad's footprint (|x| > 0.4·50/4 = 5 px) shows the far one.
        let side = (24 * 2) * ws + 42 * 2;
        assert_eq!(setups[buf[side].tri as usize].material, 0);
    }
    let da: Vec<f32> = ba.iter().map(|s| s.depth).collect();
    let db: Vec<f32> = bb.iter().map(|s| s.depth).collect();
    assert_eq!(da, db);
}

#[test]
fn ground_through_near_plane_is_clipped_not_lost() {
    // A camera 1.6 m above a ground plane that extends behind it, looking
    // level: every pixel centre clearly below the horizon (y > cy) sees ground.
    let pose = Pose::look_at(
        Vector3::new(0.0, 0.0, 1.6),
        Vector3::new(0.0, 10.0, 1.6),
        Vector3::z(),
    );
    let view = View {
        pose,
        ..test_view(1)
    };
    let tris = quad(
        [
            [-500.0, -20.0, 0.0],
            [500.0, -20.0, 0.0],
            [500.0, 2000.0, 0.0],
            [-500.0, 2000.0, 0.0],
        ],
        0,
    );
    let (counts, buf, _) = raster_counts(&view, &tris);
    for y in 0..48 {
        for x in 0..64 {
            let c = counts[y * 64 + x];
            if y >= 25 {
                assert_eq!(c, 1, "({x}, {y})");
            } else if y <= 23 {
                assert_eq!(c, 0, "({x}, {y})");
            }
        }
    }
    assert!(buf.iter().all(|s| !s.depth.is_nan()));
}

/// A tiny, fast variant of the small scene.
fn tiny_spec(seed: u64) -> SceneSpec {
    let mut s = load_spec(repo_scene("small.toml")).unwrap();
    s.seed = seed;
    s.width = 96;
    s.height = 72;
    s.frames = 6;
    s.supersample = 2;
    s.test_views = 2;
    s.points3d = 300;
    s.world.texels_per_meter = 12.0;
    s
}

fn repo_scene(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes")
        .join(name)
}

fn read_tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn generation_is_deterministic_in_the_seed() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    generate(&tiny_spec(5), a.path()).unwrap();
    generate(&tiny_spec(5), b.path()).unwrap();
    generate(&tiny_spec(6), c.path()).unwrap();
    let (ta, tb, tc) = (
        read_tree(a.path()),
        read_tree(b.path()),
        read_tree(c.path()),
    );
    assert!(ta.len() >= 6 * 3 + 2 * 2 + 2, "{} files", ta.len());
    assert_eq!(ta, tb);
    let img = |t: &[(PathBuf, Vec<u8>)]| {
        t.iter()
            .find(|(p, _)| p.ends_with("images/00003.png"))
            .map(|(_, b)| b.clone())
            .unwrap()
    };
    assert_ne!(img(&ta), img(&tc));
}

#[test]
fn gt_motion_marks_exactly_where_frame_differs_from_clean() {
    let dir = tempfile::tempdir().unwrap();
    let mut spec = tiny_spec(11);
    spec.frames = 4;
    generate(&spec, dir.path()).unwrap();
    let (w, h) = (spec.width as usize, spec.height as usize);
    let mut moving_total = 0;
    for i in 0..spec.frames as usize {
        let img = image::open(dir.path().join("images").join(frame_name(i)))
            .unwrap()
            .to_rgb8();
        let clean = image::open(dir.path().join("clean").join(frame_name(i)))
            .unwrap()
            .to_rgb8();
        let mask = image::open(dir.path().join("gt_motion").join(format!("{i:05}.png")))
            .unwrap()
            .to_luma8();
        let moving = |x: i64, y: i64| {
            x >= 0
                && y >= 0
                && (x as usize) < w
                && (y as usize) < h
                && mask.get_pixel(x as u32, y as u32)[0] == 255
        };
        let (mut same_in_mask, mut n_mask) = (0, 0);
        for y in 0..h {
            for x in 0..w {
                let differs =
                    img.get_pixel(x as u32, y as u32) != clean.get_pixel(x as u32, y as u32);
                let m = mask.get_pixel(x as u32, y as u32)[0];
                assert!(m == 0 || m == 255);
                if m == 255 {
                    n_mask += 1;
                    same_in_mask += usize::from(!differs);
                } else if differs {
                    // Differences outside the mask are antialiased boundary pixels.
                    let (xi, yi) = (x as i64, y as i64);
                    let near = (-1..=1).any(|dy| (-1..=1).any(|dx| moving(xi + dx, yi + dy)));
                    assert!(
                        near,
                        "frame {i}: pixel ({x}, {y}) differs from clean far from the mask"
                    );
                }
            }
        }
        assert!(
            same_in_mask * 50 <= n_mask.max(1),
            "frame {i}: {same_in_mask} of {n_mask} masked pixels equal clean"
        );
        moving_total += n_mask;
    }
    assert!(moving_total > 0, "no pedestrian visible in any frame");
}

#[test]
fn shipped_specs_parse_and_validate() {
    for name in ["small.toml", "demo.toml", "rotation.toml", "follow.toml"] {
        let s = load_spec(repo_scene(name)).unwrap();
        assert!(!s.pedestrians.is_empty(), "{name}");
    }
    let small = load_spec(repo_scene("small.toml")).unwrap();
    assert!(small.frames <= 40 && small.width <= 320 && small.height <= 240);
    let demo = load_spec(repo_scene("demo.toml")).unwrap();
    assert!((60..=120).contains(&demo.frames));
}

#[test]
fn bad_specs_are_rejected_with_the_file_name() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.toml");
    std::fs::write(&p, "width = 0\n").unwrap();
    let e = load_spec(&p).unwrap_err().to_string();
    assert!(e.contains("bad.toml") && e.contains("width"), "{e}");
    std::fs::write(&p, "widht = 10\n").unwrap();
    let e = load_spec(&p).unwrap_err().to_string();
    assert!(e.contains("bad.toml") && e.contains("widht"), "{e}");
    let mut s = SceneSpec::default();
    s.pedestrians[0].end = s.pedestrians[0].start;
    assert!(s.validate().is_err());
    let mut s = SceneSpec::default();
    s.camera.eye = vec![[1.0, 2.0, 1.5]];
    s.camera.target = vec![[1.0, 2.0, 1.5]];
    assert!(s.validate().unwrap_err().to_string().contains("coincide"));
    let s = SceneSpec {
        width: 8000,
        height: 8000,
        supersample: 8,
        ..SceneSpec::default()
    };
    assert!(s.validate().is_err());
    assert!(SceneSpec::default().validate().is_ok());
}

#[test]
fn demo_spec_coverage_is_between_10_and_30_percent() {
    // The demo spec at a quarter of its resolution: coverage is a fraction of
    // the image, so it barely depends on resolution.
    let mut spec = load_spec(repo_scene("demo.toml")).unwrap();
    spec.width /= 4;
    spec.height /= 4;
    spec.supersample = 2;
    spec.test_views = 0;
    spec.points3d = 100;
    spec.world.texels_per_meter = 8.0;
    let dir = tempfile::tempdir().unwrap();
    let r = generate(&spec, dir.path()).unwrap();
    assert!((0.10..=0.30).contains(&r.coverage.mean), "{:?}", r.coverage);
    assert!(r.coverage.frames_in_10_30 >= 0.75, "{:?}", r.coverage);
}

#[test]
fn points3d_project_onto_their_observations_and_colours() {
    let dir = tempfile::tempdir().unwrap();
    let spec = tiny_spec(3);
    let report = generate(&spec, dir.path()).unwrap();
    let sparse = dir.path().join("sparse/0");
    let text = crate::colmap::read_model_text(&sparse).unwrap();
    let bin = crate::colmap::read_model_binary(&sparse).unwrap();
    assert_eq!(text.points3d.len(), report.points3d);
    assert_eq!(bin.images.len(), (spec.frames + spec.test_views) as usize);
    assert!(report.points3d > 100, "{}", report.points3d);
    let cam = bin.cameras[&1].intrinsics();
    let (mut n, mut colour_err) = (0usize, Vec::new());
    for p in bin.points3d.values() {
        assert!(p.track.len() >= 2);
        for (img_id, idx) in &p.track {
            let im = &bin.images[img_id];
            let ob = im.points2d[*idx as usize];
            assert_eq!(ob.point3d_id, Some(p.id));
            let (x, y) = cam
                .project(im.pose.transform(Vector3::from(p.xyz)))
                .unwrap();
            assert!(
                (x - ob.xy[0]).hypot(y - ob.xy[1]) < 0.5,
                "point {} in {}",
                p.id,
                im.name
            );
            // The clean image shows the point's colour at the observation.
            if let Some(stem) = im
                .name
                .strip_suffix(".png")
                .filter(|s| !s.starts_with("test"))
            {
                let clean = image::open(dir.path().join("clean").join(format!("{stem}.png")))
                    .unwrap()
                    .to_rgb8();
                let px = clean.get_pixel(ob.xy[0] as u32, ob.xy[1] as u32);
                let e: i32 = (0..3)
                    .map(|k| (px[k] as i32 - p.rgb[k] as i32).abs())
                    .max()
                    .unwrap();
                colour_err.push(e);
                n += 1;
            }
        }
    }
    assert!(n > 200);
    colour_err.sort_unstable();
    let median = colour_err[colour_err.len() / 2];
    assert!(median <= 30, "median colour error {median}");
    // Every observation lies on its point's track (no dangling 2D points).
    let tracked: usize = bin.points3d.values().map(|p| p.track.len()).sum();
    assert_eq!(tracked, report.observations);
    assert_eq!(text, bin);
    // split.json: training frames as clutter, test views as extra, in order.
    let split = crate::split::read_split(dir.path().join("split.json")).unwrap();
    let names: Vec<String> = bin
        .images_by_name()
        .iter()
        .map(|im| im.name.clone())
        .collect();
    let r = split
        .resolve(&dir.path().join("split.json"), &names)
        .unwrap();
    assert_eq!(r.clutter, (0..spec.frames as usize).collect::<Vec<_>>());
    assert_eq!(
        r.extra,
        (spec.frames as usize..names.len()).collect::<Vec<_>>()
    );
    // transforms.json holds the same poses (OpenGL camera-to-world).
    let tf = crate::transforms::read_transforms(dir.path().join("transforms.json")).unwrap();
    let frames = tf
        .resolve(&dir.path().join("transforms.json"), dir.path())
        .unwrap();
    assert_eq!(frames.len(), bin.images.len());
    for f in &frames {
        let im = bin.image_by_name(&f.name).unwrap();
        assert!(
            (f.pose.center() - im.pose.center()).norm() < 1e-9,
            "{}",
            f.name
        );
        assert!(
            (f.pose.rotation() - im.pose.rotation()).norm() < 1e-9,
            "{}",
            f.name
        );
        assert!((f.camera.params[0] - cam.fx).abs() < 1e-9);
    }
}

#[test]
fn scene_load_reads_the_generated_folder_in_capture_order() {
    let dir = tempfile::tempdir().unwrap();
    let spec = tiny_spec(8);
    generate(&spec, dir.path()).unwrap();
    let scene = crate::Scene::load(dir.path(), &crate::SceneOptions::default()).unwrap();
    let n = spec.frames as usize;
    let mut expect: Vec<String> = (0..n).map(frame_name).collect();
    expect.extend((0..spec.test_views as usize).map(test_name));
    assert_eq!(scene.names(), expect);
    assert_eq!(scene.split_indices("clutter"), (0..n).collect::<Vec<_>>());
    assert_eq!(
        scene.split_indices("extra"),
        (n..expect.len()).collect::<Vec<_>>()
    );
    let poses = path::training_poses(&spec);
    for (i, f) in scene.frames.iter().enumerate() {
        assert!(f.gt_motion_path.is_some(), "{}", f.name);
        let pose = f.pose.unwrap();
        if i < n {
            assert!((pose.center() - poses[i].center()).norm() < 1e-9);
        }
        assert_eq!(f.intrinsics, intrinsics(&spec));
    }
}

#[test]
fn rotation_spec_never_translates_and_test_views_leave_the_path() {
    let rot = load_spec(repo_scene("rotation.toml")).unwrap();
    let poses = path::training_poses(&rot);
    let c0 = poses[0].center();
    assert!(poses.iter().all(|p| (p.center() - c0).norm() < 1e-9));
    let first = poses[0].rotation();
    let last = poses[poses.len() - 1].rotation();
    let angle = ((first * last.transpose()).trace() - 1.0).clamp(-2.0, 2.0) / 2.0;
    assert!(angle.acos().to_degrees() > 10.0, "the camera pans");

    let small = load_spec(repo_scene("small.toml")).unwrap();
    let train = path::training_poses(&small);
    for t in path::test_poses(&small) {
        let d = train
            .iter()
            .map(|p| (p.center() - t.center()).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(d > 0.15, "test view {d} m from the training path");
    }
}

/// `scenes/follow.toml` is a camera that follows its pedestrian: the
/// pedestrian's image centroid stays within a few pixels over the video
/// (the legs swing), while a static point at the pedestrian's depth sweeps
/// across most of the image.
#[test]
fn follow_spec_keeps_the_pedestrian_still_in_the_image() {
    let mut spec = load_spec(repo_scene("follow.toml")).unwrap();
    spec.supersample = 1;
    spec.test_views = 0;
    spec.points3d = 10;
    let dir = tempfile::tempdir().unwrap();
    generate(&spec, dir.path()).unwrap();
    let mut xs = Vec::new();
    for i in 0..spec.frames as usize {
        let mask = image::open(dir.path().join("gt_motion").join(format!("{i:05}.png")))
            .unwrap()
            .to_luma8();
        let (mut n, mut sx) = (0usize, 0usize);
        for (x, _, p) in mask.enumerate_pixels() {
            if p[0] == 255 {
                n += 1;
                sx += x as usize;
            }
        }
        assert!(n > 500, "frame {i}: the pedestrian covers only {n} px");
        xs.push(sx as f64 / n as f64);
    }
    let span = |v: &[f64]| {
        v.iter().fold(f64::NEG_INFINITY, |a, b| a.max(*b))
            - v.iter().fold(f64::INFINITY, |a, b| a.min(*b))
    };
    assert!(
        span(&xs) < 10.0,
        "pedestrian centroid moves {} px",
        span(&xs)
    );
    // A static point where the pedestrian starts, at hip height.
    let intr = intrinsics(&spec);
    let p = &spec.pedestrians[0];
    let x = Vector3::new(p.start[0], p.start[1], 0.9);
    let us: Vec<f64> = path::training_poses(&spec)
        .iter()
        .map(|pose| {
            let c = pose.transform(x);
            intr.fx * c.x / c.z + intr.cx
        })
        .collect();
    assert!(span(&us) > 150.0, "a static point moves {} px", span(&us));
}
