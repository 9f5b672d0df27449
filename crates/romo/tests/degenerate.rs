//! Degenerate videos: frames without texture or without valid
//! correspondences carry no evidence of motion. They are kept whole (moving
//! probability 0) with a warning naming them, the pairs they spoil are
//! skipped, their neighbours are labelled from their other side, and the
//! stage never stops. An underexposed video is segmented as the
//! well-exposed one is.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use romo::plane::Rgb;

const W: usize = 160;
const H: usize = 120;

/// A smooth, aperiodic texture value at (x, y) in world units.
fn texture(x: f32, y: f32) -> f32 {
    let s = (0.11 * x + 0.05 * y).sin() * (0.07 * y - 0.03 * x).cos()
        + 0.5 * (0.23 * x - 0.17 * y + 1.0).sin()
        + 0.35 * (0.31 * y + 0.13 * x).cos() * (0.019 * x * y * 0.05).sin();
    0.5 + 0.2 * s
}

/// Frame t of a panning camera (the world shifts by (2t, t) px) with a
/// 30×30 square of its own texture moving by (−3, 1) px per frame.
fn frame(t: usize) -> Rgb {
    let (cx, cy) = (2.0 * t as f32, t as f32);
    let (sx, sy) = (100.0 - 3.0 * t as f32, 40.0 + t as f32);
    let mut data = Vec::with_capacity(W * H * 3);
    for y in 0..H {
        for x in 0..W {
            let (xf, yf) = (x as f32, y as f32);
            let inside = xf >= sx && xf < sx + 30.0 && yf >= sy && yf < sy + 30.0;
            let v = if inside {
                1.0 - texture(3.0 * (xf - sx), 3.0 * (yf - sy))
            } else {
                texture(xf + cx, yf + cy)
            };
            data.extend_from_slice(&[v, 0.8 * v + 0.1, 1.0 - 0.6 * v]);
        }
    }
    Rgb::from_interleaved(W, H, &data)
}

fn black() -> Rgb {
    Rgb::from_interleaved(W, H, &vec![0.0; W * H * 3])
}

/// Independent uniform noise per pixel (seeded): texture, but no frame
/// corresponds to it.
fn noise(seed: u64) -> Rgb {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let data: Vec<f32> = (0..W * H * 3)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect();
    Rgb::from_interleaved(W, H, &data)
}

fn run(frames: Vec<Rgb>) -> romo::pipeline::Segmentation {
    let mut o = romo::RomoOptions::default();
    o.labels.robust.iterations = 200;
    let fx = romo::scene::make_extractor(&o).unwrap();
    let flow = romo::scene::make_flow(&o).unwrap();
    romo::pipeline::segment_frames(&frames, &o, flow.as_ref(), fx.as_ref(), &|_, _, _| {}).unwrap()
}

fn all_zero(p: &romo::plane::Plane) -> bool {
    p.data.iter().all(|v| *v == 0.0)
}

#[test]
fn black_frames_are_kept_whole_with_a_warning() {
    let frames: Vec<Rgb> = (0..10)
        .map(|t| if t == 4 || t == 5 { black() } else { frame(t) })
        .collect();
    let seg = run(frames);
    let r = &seg.report;
    assert_eq!(r.no_evidence_frames, vec![4, 5], "{:?}", r.warnings);
    let skipped: Vec<usize> = r.skipped_pairs.iter().map(|p| p.pair).collect();
    assert_eq!(skipped, vec![3, 4, 5], "{:?}", r.skipped_pairs);
    assert!(r.skipped_pairs[0].reason.contains("no texture in frame 4"));
    assert!(
        r.warnings.iter().any(|w| w.contains("frame(s) 4, 5")),
        "{:?}",
        r.warnings
    );
    assert!(all_zero(&seg.probs[4]) && all_zero(&seg.probs[5]));
    // Their neighbours are labelled from their other side.
    for t in [3, 6] {
        assert!(
            r.frames[t].valid_ratio > 0.5,
            "frame {t}: {:?}",
            r.frames[t]
        );
        assert!(r.frames[t].l_coverage > 0.3, "frame {t}: {:?}", r.frames[t]);
    }
    assert_eq!(r.frames[3].model_fwd, "");
    assert_ne!(r.frames[2].model_fwd, "");
}

/// A random-dot texture of 2×2 px cells (seeded hash), values in
/// [0.2, 0.9]: sharp, as a photo's detail is.
fn dots(x: i64, y: i64, seed: u64) -> f32 {
    let mut h = (x.div_euclid(2) as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
        ^ (y.div_euclid(2) as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
        ^ seed;
    h ^= h >> 31;
    h = h.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h ^= h >> 29;
    0.2 + 0.7 * (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Frame t of the camera panning over [`dots`] (the world shifts by
/// (2t, t) px) with a 30×30 square of other dots at (100 − 4t, 40 + 4t):
/// it moves by (−2, 5) px a frame against the background.
fn dot_frame(t: usize) -> Rgb {
    let t = t as i64;
    let mut data = Vec::with_capacity(W * H * 3);
    for y in 0..H as i64 {
        for x in 0..W as i64 {
            let (sx, sy) = (100 - 4 * t, 40 + 4 * t);
            let v = if (sx..sx + 30).contains(&x) && (sy..sy + 30).contains(&y) {
                dots(x - sx, y - sy, 7)
            } else {
                dots(x + 2 * t, y + t, 1)
            };
            data.extend_from_slice(&[v, 0.8 * v + 0.1, 1.0 - 0.6 * v]);
        }
    }
    Rgb::from_interleaved(W, H, &data)
}

/// Mean J over frames 1–8 of [`dot_frame`]'s square on the grid
/// (probabilities > 0.5).
fn square_j(seg: &romo::pipeline::Segmentation) -> f64 {
    let (gw, gh) = seg.report.grid;
    let (kx, ky) = (W as f32 / gw as f32, H as f32 / gh as f32);
    let js: Vec<f64> = (1..9)
        .map(|t| {
            let (sx, sy) = (100.0 - 4.0 * t as f32, 40.0 + 4.0 * t as f32);
            let (mut inter, mut union) = (0usize, 0usize);
            for (i, p) in seg.probs[t].data.iter().enumerate() {
                let (x, y) = (((i % gw) as f32 + 0.5) * kx, ((i / gw) as f32 + 0.5) * ky);
                let g = x >= sx && x < sx + 30.0 && y >= sy && y < sy + 30.0;
                let m = *p > 0.5;
                inter += usize::from(m && g);
                union += usize::from(m || g);
            }
            inter as f64 / union.max(1) as f64
        })
        .collect();
    js.iter().sum::<f64>() / js.len() as f64
}

/// `f` with every channel value passed through `g`.
fn levels(f: Rgb, g: impl Fn(f32) -> f32 + Sync) -> Rgb {
    Rgb {
        c: f.c.map(|c| c.map(&g)),
    }
}

/// The video at a tenth of its brightness, in 8 bits (values 2–23 of 255):
/// every gradient is ten times smaller, so no pixel passed the texture
/// thresholds and nothing was found moving. The exposure map stretches it
/// back (with a warning), and the square is found as in the original.
#[test]
fn an_underexposed_video_is_segmented_like_the_original() {
    let dark = |f: Rgb| levels(f, |v| (v * 0.1 * 255.0).round() / 255.0);
    let normal: Vec<Rgb> = (0..10).map(dot_frame).collect();
    let darkened: Vec<Rgb> = normal.iter().cloned().map(dark).collect();
    let (a, b) = (run(normal), run(darkened));
    assert!(
        b.exposure.gain() > 5.0 * a.exposure.gain(),
        "{:?} {:?}",
        a.exposure,
        b.exposure
    );
    assert!(
        b.report.warnings.iter().any(|w| w.contains("dark or flat")),
        "{:?}",
        b.report.warnings
    );
    assert!(
        b.report.no_evidence_frames.is_empty(),
        "{:?}",
        b.report.warnings
    );
    let (ja, jb) = (square_j(&a), square_j(&b));
    assert!(ja > 0.7, "well exposed: J {ja}");
    assert!(jb > ja - 0.1, "underexposed: J {jb} against {ja}");
}

/// The video flickering: every other frame 12% brighter, the others 12%
/// darker (auto exposure hunting, mains-powered lights). Against the next
/// frame's brightness, the flow's correct match looked worse than staying
/// put wherever the scene at the same pixel happened to be darker, and the
/// test for content fixed in the image marked most of the frame (then
/// dropped all of it as distant scene). With each pair's exposure gain it
/// marks nothing, and the square is found as in the original.
#[test]
fn a_flickering_video_has_no_content_fixed_in_the_image() {
    let flicker = |(t, f): (usize, Rgb)| {
        let g = if t % 2 == 0 { 0.88 } else { 1.12 };
        levels(f, |v| (v * g).min(1.0))
    };
    let normal: Vec<Rgb> = (0..10).map(dot_frame).collect();
    let flickering: Vec<Rgb> = normal.iter().cloned().enumerate().map(flicker).collect();
    let (a, b) = (run(normal), run(flickering));
    for s in [&a, &b] {
        assert!(
            s.report.image_fixed.starts_with("0.00% of the frame"),
            "{}",
            s.report.image_fixed
        );
    }
    let (ja, jb) = (square_j(&a), square_j(&b));
    assert!(ja > 0.7, "steady: J {ja}");
    assert!(jb > ja - 0.1, "flickering: J {jb} against {ja}");
}

/// [`dot_frame`] between black bars 20 px wide (pillarboxed) is segmented
/// as its content cropped is, mask for mask, and the bars are masked.
#[test]
fn a_pillarboxed_video_is_segmented_as_its_content() {
    const BAR: usize = 20;
    let dir = tempfile::tempdir().unwrap();
    let (mut padded, mut cropped, mut names) = (vec![], vec![], vec![]);
    for t in 0..10 {
        let f = dot_frame(t);
        let px = |x: usize, y: usize| {
            image::Rgb([0, 1, 2].map(|k| (f.c[k].at(x, y) * 255.0).round() as u8))
        };
        let name = format!("{t:02}.png");
        let p = dir.path().join(format!("padded_{name}"));
        image::RgbImage::from_fn(W as u32, H as u32, |x, y| {
            let x = x as usize;
            if (BAR..W - BAR).contains(&x) {
                px(x, y as usize)
            } else {
                image::Rgb([0, 0, 0])
            }
        })
        .save(&p)
        .unwrap();
        padded.push(p);
        let c = dir.path().join(format!("cropped_{name}"));
        image::RgbImage::from_fn((W - 2 * BAR) as u32, H as u32, |x, y| {
            px(x as usize + BAR, y as usize)
        })
        .save(&c)
        .unwrap();
        cropped.push(c);
        names.push(name);
    }
    let mut o = romo::RomoOptions::default();
    o.labels.robust.iterations = 200;
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let r = romo::segment_paths(&padded, &names, &a, &o, &|_, _, _| {}).unwrap();
    assert!(
        r.warnings[0].contains("left 20, right 20, top 0, bottom 0 px"),
        "{:?}",
        r.warnings
    );
    romo::segment_paths(&cropped, &names, &b, &o, &|_, _, _| {}).unwrap();
    let mut moving = 0;
    for n in &names {
        let read = |d: &std::path::Path| {
            image::open(d.join(format!("masks/{n}.png")))
                .unwrap()
                .to_luma8()
        };
        let (ma, mb) = (read(&a), read(&b));
        assert_eq!(ma.dimensions(), (W as u32, H as u32));
        for (x, y, p) in ma.enumerate_pixels() {
            let x = x as usize;
            if (BAR..W - BAR).contains(&x) {
                assert_eq!(
                    p.0[0],
                    mb.get_pixel((x - BAR) as u32, y).0[0],
                    "{n} ({x}, {y})"
                );
                moving += usize::from(p.0[0] == 0);
            } else {
                assert_eq!(p.0[0], 0, "{n}: bar pixel ({x}, {y}) kept");
            }
        }
    }
    assert!(moving > 2000, "the square is found: {moving} px");
}

#[test]
fn an_all_black_video_is_kept_whole() {
    let frames = vec![black(); 4];
    let seg = run(frames);
    assert_eq!(seg.report.no_evidence_frames, vec![0, 1, 2, 3]);
    assert_eq!(seg.report.skipped_pairs.len(), 3);
    assert!(seg.probs.iter().all(all_zero));
}

#[test]
fn noise_frames_do_not_stop_the_stage() {
    let frames: Vec<Rgb> = (0..10)
        .map(|t| match t {
            4 => noise(1),
            5 => noise(2),
            _ => frame(t),
        })
        .collect();
    let seg = run(frames);
    let r = &seg.report;
    let skipped: Vec<usize> = r.skipped_pairs.iter().map(|p| p.pair).collect();
    assert!(skipped.contains(&4), "{:?}", r.skipped_pairs);
    assert!(
        r.skipped_pairs
            .iter()
            .find(|p| p.pair == 4)
            .is_some_and(|p| p.reason.contains("photo-consistent")),
        "{:?}",
        r.skipped_pairs
    );
    // Frames 4 and 5 have no usable pair: kept whole.
    for t in &r.no_evidence_frames {
        assert!(all_zero(&seg.probs[*t]));
    }
    assert!(r.no_evidence_frames.contains(&4) && r.no_evidence_frames.contains(&5));
    // The clean frames further away keep their labels.
    for t in [0, 1, 2, 7, 8, 9] {
        assert!(r.frames[t].l_coverage > 0.3, "frame {t}: {:?}", r.frames[t]);
    }
}

/// Frame t of [`frame`] as a PNG of `w × h` (cropped or extended with the
/// same panning texture).
fn save(dir: &std::path::Path, name: &str, t: usize, (w, h): (usize, usize)) -> std::path::PathBuf {
    let f = frame(t);
    let p = dir.join(name);
    image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let (xs, ys) = (x as usize % W, y as usize % H);
        image::Rgb([0, 1, 2].map(|k| (f.c[k].at(xs, ys) * 255.0).round() as u8))
    })
    .save(&p)
    .unwrap();
    p
}

/// A photo folder of two sizes (landscape frames with portrait ones among
/// them, and one square photo): each size is segmented as its own
/// sequence, every frame gets a mask at its own size, the square photo
/// (alone at its size) is kept whole, and one warning says so.
#[test]
fn frames_of_several_sizes_are_segmented_per_size() {
    let dir = tempfile::tempdir().unwrap();
    let mut paths = vec![];
    let mut names = vec![];
    for t in 0..10 {
        let size = match t {
            3 | 5 | 7 => (H, W),
            9 => (H, H),
            _ => (W, H),
        };
        let name = format!("{t:02}.png");
        paths.push(save(dir.path(), &name, t, size));
        names.push(name);
    }
    let out = dir.path().join("out");
    let mut o = romo::RomoOptions::default();
    o.labels.robust.iterations = 200;
    let stages = std::sync::Mutex::new(std::collections::BTreeSet::new());
    let r = romo::segment_paths(&paths, &names, &out, &o, &|s, _, _| {
        stages.lock().unwrap().insert(s.to_string());
    })
    .unwrap();
    let stages = stages.into_inner().unwrap();
    assert!(stages.contains("flow, 120x160 frames"), "{stages:?}");
    let listed: Vec<&str> = r.frames.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(
        listed,
        [
            "00.png", "01.png", "02.png", "04.png", "06.png", "08.png", "03.png", "05.png",
            "07.png", "09.png"
        ]
    );
    let idx: Vec<usize> = r.frames.iter().map(|f| f.index).collect();
    assert_eq!(idx, (0..10).collect::<Vec<_>>());
    assert_eq!(r.no_evidence_frames, [9], "{:?}", r.warnings);
    assert!(
        r.warnings[0].contains("frames of 3 sizes (160x120: 6, 120x160: 3, 120x120: 1)")
            && r.warnings[0].contains("kept whole: 09.png"),
        "{:?}",
        r.warnings
    );
    for (t, p) in paths.iter().enumerate() {
        let img = image::open(p).unwrap();
        let m = image::open(out.join(format!("masks/{t:02}.png.png")))
            .unwrap()
            .to_luma8();
        assert_eq!(m.dimensions(), (img.width(), img.height()), "frame {t}");
        if t == 9 {
            assert!(
                m.pixels().all(|p| p.0[0] == 255),
                "the square photo is kept whole"
            );
        }
    }
    // The landscape sequence finds its moving square.
    let moving = |t: usize| {
        let m = image::open(out.join(format!("masks/{t:02}.png.png")))
            .unwrap()
            .to_luma8();
        m.pixels().filter(|p| p.0[0] == 0).count()
    };
    assert!(
        moving(0) > 100 && moving(4) > 100,
        "{} {}",
        moving(0),
        moving(4)
    );
}

/// `segment_frames` itself (one sequence) still needs one size: its error
/// names both files.
#[test]
fn one_sequence_of_two_sizes_is_one_error_naming_both_files() {
    let dir = tempfile::tempdir().unwrap();
    let paths: Vec<_> = [(W, H), (W, H), (H, W)]
        .into_iter()
        .enumerate()
        .map(|(t, size)| save(dir.path(), &format!("{t:02}.png"), t, size))
        .collect();
    let o = romo::RomoOptions::default();
    let fx = romo::scene::make_extractor(&o).unwrap();
    let flow = romo::scene::make_flow(&o).unwrap();
    let src = romo::scene::PathSource { paths };
    let e = romo::pipeline::segment_frames(&src, &o, flow.as_ref(), fx.as_ref(), &|_, _, _| {})
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("02.png is 120x160") && e.contains("00.png is 160x120"),
        "{e}"
    );
}

#[test]
fn warnings_of_a_later_window_name_the_videos_frames() {
    // 14 frames at most 8 at a time (windows 0–7, 7–13); frame 10 is black,
    // so pairs 9–10 and 10–11 are skipped and frame 10 has no evidence.
    let dir = tempfile::tempdir().unwrap();
    let mut paths = vec![];
    for t in 0..14 {
        let f = if t == 10 { black() } else { frame(t) };
        let p = dir.path().join(format!("{t:02}.png"));
        image::RgbImage::from_fn(W as u32, H as u32, |x, y| {
            let i = y as usize * W + x as usize;
            image::Rgb([0, 1, 2].map(|k| (f.c[k].data[i] * 255.0).round() as u8))
        })
        .save(&p)
        .unwrap();
        paths.push(p);
    }
    let names: Vec<String> = (0..14).map(|t| format!("{t:02}.png")).collect();
    let mut o = romo::RomoOptions::default();
    o.labels.robust.iterations = 200;
    o.chunk_frames = 8;
    assert_eq!(romo::scene::chunks(14, 8), [(0, 8), (7, 14)]);
    let stages = std::sync::Mutex::new(std::collections::BTreeSet::new());
    let r = romo::segment_paths(&paths, &names, &dir.path().join("out"), &o, &|s, _, _| {
        stages.lock().unwrap().insert(s.to_string());
    })
    .unwrap();
    // Each window counts its own frames, and the progress line says which.
    let stages = stages.into_inner().unwrap();
    assert!(
        stages.contains("flow, window 1 of 2") && stages.contains("write, window 2 of 2"),
        "{stages:?}"
    );
    assert_eq!(r.no_evidence_frames, [10]);
    let pairs: Vec<usize> = r.skipped_pairs.iter().map(|p| p.pair).collect();
    assert_eq!(pairs, [9, 10]);
    let w = r.warnings.join("\n");
    assert!(
        w.contains("pair 9–10 skipped") && w.contains("pair 10–11 skipped"),
        "{w}"
    );
    assert!(w.contains("no evidence of motion in frame(s) 10 "), "{w}");
    assert!(!w.contains("frame(s) 3 ") && !w.contains("pair 2–3"), "{w}");
    let m = image::open(dir.path().join("out/masks/10.png.png"))
        .unwrap()
        .to_luma8();
    assert!(m.pixels().all(|p| p.0[0] == 255), "frame 10 kept whole");
}

#[test]
fn one_frame_is_one_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("only.png");
    image::RgbImage::new(W as u32, H as u32).save(&p).unwrap();
    let o = romo::RomoOptions::default();
    let e = romo::segment_paths(
        std::slice::from_ref(&p),
        &["only.png".to_string()],
        &dir.path().join("out"),
        &o,
        &|_, _, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("only.png is the only frame"), "{e}");
    let e = romo::segment_paths(&[], &[], &dir.path().join("out"), &o, &|_, _, _| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("no frames"), "{e}");
}
