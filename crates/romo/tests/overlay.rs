//! The fixed-content test (`romo::overlay`) inside the mask pipeline: it
//! only ever adds pixels fixed in the image, and leaves a video without
//! such content as it was. Its detection itself is tested in
//! `romo::overlay::tests`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use romo::plane::Rgb;

const W: usize = 160;
const H: usize = 120;
/// The logo: x, y, width, height.
const LOGO: (usize, usize, usize, usize) = (120, 8, 30, 12);

/// A busy texture (a café's chairs and windows rather than a wall).
fn texture(x: f32, y: f32) -> f32 {
    let s = (0.31 * x + 0.15 * y).sin() * (0.27 * y - 0.13 * x).cos()
        + 0.5 * (0.53 * x - 0.37 * y + 1.0).sin()
        + 0.35 * (0.61 * y + 0.23 * x).cos();
    0.5 + 0.25 * s
}

fn in_logo(x: usize, y: usize) -> bool {
    let (lx, ly, lw, lh) = LOGO;
    x >= lx && x < lx + lw && y >= ly && y < ly + lh
}

/// Frame t of a camera moving forward through a scene of two depths (the
/// left half near, zooming by 8% a frame; the right half far, 3%), where
/// zero flow fits the two-view geometry as a point at infinity; a 20×20
/// square of its own texture moves by (3, 1) px a frame; thin, faint
/// white strokes (a watermark's lettering) are drawn over the top right.
fn frame(t: usize, logo: bool) -> Rgb {
    let (sx, sy) = (20.0 + 3.0 * t as f32, 70.0 + t as f32);
    let (cx, cy) = (W as f32 / 2.0, H as f32 / 2.0);
    let mut data = Vec::with_capacity(W * H * 3);
    for y in 0..H {
        for x in 0..W {
            let (xf, yf) = (x as f32, y as f32);
            let inside = xf >= sx && xf < sx + 20.0 && yf >= sy && yf < sy + 20.0;
            let mut v = if inside {
                1.0 - texture(3.0 * (xf - sx), 3.0 * (yf - sy))
            } else {
                let (rate, offset) = if x < W / 2 {
                    (0.08, 0.0)
                } else {
                    (0.03, 500.0)
                };
                let s = 1.0 + rate * t as f32;
                texture(cx + (xf - cx) / s + offset, cy + (yf - cy) / s)
            };
            if logo && in_logo(x, y) && x % 8 == 0 {
                v = 0.8 * v + 0.2;
            }
            data.extend_from_slice(&[v, 0.8 * v + 0.1, 1.0 - 0.6 * v]);
        }
    }
    Rgb::from_interleaved(W, H, &data)
}

fn run(image_fixed: bool, logo: bool) -> romo::pipeline::Segmentation {
    let mut o = romo::RomoOptions::default();
    o.labels.robust.iterations = 200;
    o.overlay.enabled = image_fixed;
    let fx = romo::scene::make_extractor(&o).unwrap();
    let flow = romo::scene::make_flow(&o).unwrap();
    let frames: Vec<Rgb> = (0..12).map(|t| frame(t, logo)).collect();
    romo::pipeline::segment_frames(&frames, &o, flow.as_ref(), fx.as_ref(), &|_, _, _| {}).unwrap()
}

/// Share of the logo's pixels called moving in frame `t`, and the pixels
/// called moving outside the logo grown by 3 px.
fn counts(seg: &romo::pipeline::Segmentation, t: usize) -> (f32, usize) {
    let p = &seg.probs[t];
    assert_eq!((p.w, p.h), (W, H));
    let (lx, ly, lw, lh) = LOGO;
    let near =
        |x: usize, y: usize| x + 3 >= lx && x < lx + lw + 3 && y + 3 >= ly && y < ly + lh + 3;
    let (mut logo, mut outside) = (0, 0);
    for y in 0..H {
        for x in 0..W {
            let moving = p.data[y * W + x] > 0.5;
            if in_logo(x, y) && moving {
                logo += 1;
            } else if !near(x, y) && moving {
                outside += 1;
            }
        }
    }
    (logo as f32 / (lw * lh) as f32, outside)
}

#[test]
fn without_an_overlay_the_test_changes_nothing_and_says_so() {
    let on = run(true, false);
    let off = run(false, false);
    assert!(
        on.report.image_fixed.contains("marked moving"),
        "{}",
        on.report.image_fixed
    );
    assert_eq!(on.report.image_fixed_fraction, 0.0);
    assert!(off.report.image_fixed.is_empty());
    for t in 0..12 {
        assert_eq!(on.probs[t], off.probs[t], "frame {t}");
    }
}

#[test]
fn a_fixed_logo_is_never_less_moving_with_the_test() {
    let on = run(true, true);
    let off = run(false, true);
    for t in 0..12 {
        let (logo_on, outside_on) = counts(&on, t);
        let (logo_off, outside_off) = counts(&off, t);
        assert!(logo_on >= logo_off, "frame {t}: {logo_on} < {logo_off}");
        assert_eq!(outside_on, outside_off, "frame {t}");
    }
}
