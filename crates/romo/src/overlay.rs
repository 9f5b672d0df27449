//! Content fixed in the image (ours): a broadcaster's logo, a burned-in
//! timestamp or subtitle, a letterbox bar, dirt on the lens.
//!
//! Such content is not part of the scene: when the camera moves, every
//! scene point at finite depth moves in the image, but an overlay stays put
//! to the pixel in every frame. Two-view geometry cannot see it (zero flow
//! fits any epipolar geometry as a point at infinity, see the romo README's
//! "camera follows the object"), yet a splat trained on it paints the logo
//! into the scene. [`image_fixed`] finds it from the flow the mask stage
//! already has: in a pair where the camera clearly moved, a pixel votes
//! "fixed" when the next frame at the same pixel matches it better than the
//! next frame where the flow says it went, both against the pixel times the
//! pair's exposure gain (auto exposure and flicker change the whole frame's
//! brightness). The flow of a semi-transparent logo follows the scene
//! behind it, so the logo votes in most such pairs;
//! a scene pixel votes only where the flow fails, which moves with the
//! camera. Pixels that vote in enough pairs are content fixed in the image.
//!
//! Zero flow alone is not used: it is also what a point at the focus of
//! expansion of a camera moving straight ahead has. So an opaque or
//! high-contrast overlay whose own flow is zero is not found (at most along
//! its outline, where the flow's patches take in the scene around it); a
//! faint or thin one, whose flow follows the scene behind it, is.
//!
//! Guards, so a scene is not mistaken for an overlay: only pairs whose
//! median textured-pixel flow shows camera motion count, and without enough
//! such pairs (a tripod shot) nothing is marked; a fixed area larger than a
//! share of the frame is taken for scene content far away under a camera
//! that only translates, and nothing is marked either (overlays are small).

use crate::flow::Flow;
use crate::geometry::robust::median;
use crate::plane::Plane;
use serde::{Deserialize, Serialize};

/// Options of [`image_fixed`]. Flow thresholds are in working-grid pixels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(default, deny_unknown_fields)]
pub struct OverlayOptions {
    /// Mark content fixed in the image (logos, burned-in text, letterbox
    /// bars) as moving in every frame (ours; default true).
    #[cfg_attr(feature = "cli", arg(id = "image_fixed", long = "no-image-fixed", action = clap::ArgAction::SetFalse, help = "Do not mark content fixed in the image (logos, burned-in text) as moving"))]
    pub enabled: bool,
    /// A pair shows camera motion when the median flow of its textured,
    /// cycle-consistent pixels is at least this (default 1.0 grid px,
    /// about 3 px at 854×480: ten times the flow's noise).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub min_camera_flow: f32,
    /// A pixel votes "fixed" in a pair when the next frame at the same
    /// pixel matches it better, by more than this (grey levels in [0, 1]),
    /// than the next frame where the flow says the pixel went (default 0.03).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub margin: f32,
    /// Share of the camera-motion pairs (averaged over the pixel's 3 × 3
    /// neighbourhood) in which a pixel must vote "fixed" by the photometric
    /// test (default 0.15). A scene pixel votes only where the flow fails
    /// there, which moves with the camera; a semi-transparent overlay votes
    /// wherever the flow follows the scene behind it.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub mismatch_fraction: f32,
    /// Fewest camera-motion pairs to decide anything (default 8).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub min_pairs: usize,
    /// Largest share of the frame marked; above it nothing is marked
    /// (default 0.1).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub max_area: f32,
    /// Connected fixed areas smaller than this many grid pixels are dropped
    /// as noise (default 6).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub min_size: usize,
}

impl OverlayOptions {
    /// Check the options.
    pub fn validate(&self) -> crate::Result<()> {
        let ok = self.min_camera_flow > 0.0
            && self.margin >= 0.0
            && (0.0..=1.0).contains(&self.mismatch_fraction)
            && (0.0..=1.0).contains(&self.max_area);
        if ok {
            Ok(())
        } else {
            Err(crate::RomoError::Options(
                "romo: overlay min_camera_flow must be > 0, margin >= 0, mismatch_fraction and max_area in [0, 1]".into(),
            ))
        }
    }
}

impl Default for OverlayOptions {
    fn default() -> Self {
        Self {
            enabled: true,
            min_camera_flow: 1.0,
            margin: 0.03,
            mismatch_fraction: 0.15,
            min_pairs: 8,
            max_area: 0.1,
            min_size: 6,
        }
    }
}

/// What [`image_fixed`] found.
#[derive(Debug, Clone, PartialEq)]
pub enum Overlay {
    /// Pixels (grid, row-major) fixed in the image; may be all false.
    Found(Vec<bool>),
    /// Fewer than `min_pairs` pairs show camera motion: no decision.
    TooLittleMotion { pairs: usize },
    /// The fixed area is larger than `max_area` of the frame: taken for
    /// distant scene content, nothing marked.
    TooLarge { fraction: f32 },
}

/// Content fixed in the image over the video (module docs). `fwd[p]` /
/// `bwd[p]` are pair p's flows on the grid, `valid_f[p]` its
/// cycle-consistent pixels, `textured[t]` frame t's textured pixels and
/// `greys[t]` its grey levels in [0, 1] on the grid.
pub fn image_fixed(
    fwd: &[Flow],
    bwd: &[Flow],
    valid_f: &[Vec<bool>],
    textured: &[Vec<bool>],
    greys: &[Plane],
    o: &OverlayOptions,
) -> Overlay {
    let Some(first) = fwd.first() else {
        return Overlay::TooLittleMotion { pairs: 0 };
    };
    let (w, h) = (first.w(), first.h());
    let n = w * h;
    let moving_pairs: Vec<usize> = (0..fwd.len())
        .filter(|&p| {
            let f = &fwd[p];
            let mut mags: Vec<f64> = (0..n)
                .filter(|&i| valid_f[p][i] && textured[p][i])
                .map(|i| f64::from(f.u.data[i].hypot(f.v.data[i])))
                .collect();
            // Too few correspondences to say how the camera moved.
            mags.len() * 20 >= n && median(&mut mags) >= f64::from(o.min_camera_flow)
        })
        .collect();
    if moving_pairs.len() < o.min_pairs.max(1) {
        return Overlay::TooLittleMotion {
            pairs: moving_pairs.len(),
        };
    }
    // Per pixel: pairs in which staying put explains the next frame better
    // than the flow does, over pairs in which its flow stays in the frame.
    let mut votes = vec![0u32; n];
    let mut chances = vec![0u32; n];
    // Frame `from` against frame `to` with the flow `f` from `from` to `to`.
    let mut vote = |f: &Flow, from: &Plane, to: &Plane| {
        let landed: Vec<Option<f32>> = (0..n)
            .map(|i| {
                let (x, y) = ((i % w) as f32 + f.u.data[i], (i / w) as f32 + f.v.data[i]);
                let inside = x >= 0.0 && y >= 0.0 && x <= (w - 1) as f32 && y <= (h - 1) as f32;
                inside.then(|| to.bilinear(x, y))
            })
            .collect();
        // The camera's exposure may change between the frames (auto
        // exposure, flicker): `to` is predicted from `from` times the
        // pair's gain, else a brighter frame makes the flow's match look
        // worse than staying put wherever the scene happens to be darker.
        let gain = exposure_gain(from, &landed);
        for (i, l) in landed.iter().enumerate() {
            let Some(l) = l else { continue };
            chances[i] += 1;
            let predicted = gain * from.data[i];
            let d_fixed = (to.data[i] - predicted).abs();
            let d_flow = (l - predicted).abs();
            if d_flow > d_fixed + o.margin {
                votes[i] += 1;
            }
        }
    };
    for &p in &moving_pairs {
        vote(&fwd[p], &greys[p], &greys[p + 1]);
        vote(&bwd[p], &greys[p + 1], &greys[p]);
    }
    let share = Plane::from_fn(w, h, |x, y| {
        let i = y * w + x;
        votes[i] as f32 / chances[i].max(1) as f32
    })
    .box_mean(1);
    let fixed: Vec<bool> = share
        .data
        .iter()
        .map(|&s| s >= o.mismatch_fraction)
        .collect();
    let fixed = drop_small(&fixed, w, h, o.min_size);
    let fraction = fixed.iter().filter(|b| **b).count() as f32 / n as f32;
    if fraction > o.max_area {
        return Overlay::TooLarge { fraction };
    }
    Overlay::Found(dilate(&fixed, w, h))
}

/// The gain of a pair's exposure: the median over pixels of where the flow
/// landed in the next frame (`landed`, None outside it) over the pixel's
/// own grey level, in [1/2, 2]; 1 when too few pixels are bright enough to
/// tell (a ratio of near-black levels is noise).
fn exposure_gain(from: &Plane, landed: &[Option<f32>]) -> f32 {
    let mut ratios: Vec<f64> = from
        .data
        .iter()
        .zip(landed)
        .filter_map(|(a, b)| b.filter(|_| *a > MIN_GAIN_LEVEL).map(|b| f64::from(b / a)))
        .collect();
    if ratios.len() * 10 < from.data.len() {
        return 1.0;
    }
    (median(&mut ratios) as f32).clamp(0.5, 2.0)
}

/// Grey level below which a pixel does not vote on the exposure gain.
const MIN_GAIN_LEVEL: f32 = 0.05;

/// `m` without its 4-connected components smaller than `min_size`.
fn drop_small(m: &[bool], w: usize, h: usize, min_size: usize) -> Vec<bool> {
    let mut out = vec![false; m.len()];
    let mut seen = vec![false; m.len()];
    let mut stack = Vec::new();
    let mut comp = Vec::new();
    for s in 0..m.len() {
        if !m[s] || seen[s] {
            continue;
        }
        comp.clear();
        seen[s] = true;
        stack.push(s);
        while let Some(i) = stack.pop() {
            comp.push(i);
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if m[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        if comp.len() >= min_size {
            for &i in &comp {
                out[i] = true;
            }
        }
    }
    out
}

/// `m` grown by one grid pixel (8-neighbourhood): the flow's patches blur an
/// overlay's outline by about that much.
fn dilate(m: &[bool], w: usize, h: usize) -> Vec<bool> {
    let mut out = m.to_vec();
    for y in 0..h {
        for x in 0..w {
            if !m[y * w + x] {
                continue;
            }
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    out[yy * w + xx] = true;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: usize = 64;
    const H: usize = 36;

    /// A non-repeating texture.
    fn tex(x: f32, y: f32) -> f32 {
        0.5 + 0.2 * (0.9 * x + 0.3 * y).sin() + 0.15 * (0.37 * x - 0.81 * y + 1.0).sin()
    }

    /// A pan of `speed` px a frame with a logo in the `block` (x, y, w, h)
    /// fixed in the image. `opaque`: the logo hides the scene and its flow
    /// is zero; else it is drawn over the scene, whose flow it has.
    fn pan(
        frames: usize,
        speed: f32,
        block: (usize, usize, usize, usize),
        opaque: bool,
    ) -> Overlay {
        flickering_pan(frames, speed, block, opaque, 0.0)
    }

    /// [`pan`] with every other frame's exposure `1 + flicker`, the others'
    /// `1 − flicker`.
    fn flickering_pan(
        frames: usize,
        speed: f32,
        block: (usize, usize, usize, usize),
        opaque: bool,
        flicker: f32,
    ) -> Overlay {
        let (bx, by, bw, bh) = block;
        let inside = |x: usize, y: usize| x >= bx && x < bx + bw && y >= by && y < by + bh;
        let greys: Vec<Plane> = (0..frames)
            .map(|t| {
                let gain = if t % 2 == 0 {
                    1.0 - flicker
                } else {
                    1.0 + flicker
                };
                Plane::from_fn(W, H, |x, y| {
                    let scene = tex(x as f32 - speed * t as f32, y as f32);
                    let logo = 0.5 + 0.4 * ((x as f32 * 1.7).sin() * (y as f32 * 1.3).cos());
                    gain * match (inside(x, y), opaque) {
                        (false, _) => scene,
                        (true, true) => logo,
                        (true, false) => 0.5 * scene + 0.5 * logo,
                    }
                })
            })
            .collect();
        let flow = |s: f32| Flow {
            u: Plane::from_fn(W, H, |x, y| if opaque && inside(x, y) { 0.0 } else { s }),
            v: Plane::filled(W, H, 0.0),
        };
        let fwd = vec![flow(speed); frames - 1];
        let bwd = vec![flow(-speed); frames - 1];
        let all = vec![vec![true; W * H]; frames];
        image_fixed(
            &fwd,
            &bwd,
            &all[1..],
            &all,
            &greys,
            &OverlayOptions::default(),
        )
    }

    /// The found pixels are the block grown by `grow` pixels, give or take
    /// `slack` pixels in all.
    fn assert_block(found: Overlay, block: (usize, usize, usize, usize), slack: usize) {
        let Overlay::Found(m) = found else {
            panic!("no decision: {found:?}");
        };
        let (bx, by, bw, bh) = block;
        let mut wrong = 0;
        for y in 0..H {
            for x in 0..W {
                let inside = x + 1 >= bx && x < bx + bw + 1 && y + 1 >= by && y < by + bh + 1;
                if m[y * W + x] != inside {
                    wrong += 1;
                }
            }
        }
        assert!(wrong <= slack, "{wrong} pixels wrong");
    }

    #[test]
    fn an_opaque_logo_with_a_correct_zero_flow_is_not_found() {
        // The known limit (module docs): its flow explains it as well as
        // staying put does, as for a point at the focus of expansion.
        let Overlay::Found(m) = pan(20, 2.0, (40, 4, 12, 6), true) else {
            panic!("no decision");
        };
        assert!(!m[7 * W + 46], "the logo's interior");
    }

    #[test]
    fn a_semi_transparent_logo_whose_flow_follows_the_scene_is_found() {
        // Near the block's edge the 3 × 3 average may take or leave one ring.
        assert_block(
            pan(20, 2.0, (40, 4, 12, 6), false),
            (40, 4, 12, 6),
            2 * (14 + 8),
        );
    }

    #[test]
    fn a_plain_pan_marks_nothing() {
        let Overlay::Found(m) = pan(20, 2.0, (0, 0, 0, 0), false) else {
            panic!("no decision");
        };
        assert!(m.iter().all(|b| !b));
    }

    #[test]
    fn a_flickering_pan_marks_nothing() {
        // ±15% exposure every other frame: without the pair's gain, a
        // brighter next frame votes "fixed" wherever the scene is darker
        // where the pixel stands.
        let Overlay::Found(m) = flickering_pan(20, 2.0, (0, 0, 0, 0), false, 0.15) else {
            panic!("no decision");
        };
        let k = m.iter().filter(|b| **b).count();
        assert_eq!(k, 0, "{k} pixels marked");
    }

    #[test]
    fn a_semi_transparent_logo_is_found_under_flicker() {
        assert_block(
            flickering_pan(20, 2.0, (40, 4, 12, 6), false, 0.15),
            (40, 4, 12, 6),
            2 * (14 + 8),
        );
    }

    #[test]
    fn the_exposure_gain_is_the_median_ratio() {
        let from = Plane::from_fn(W, H, |x, y| tex(x as f32, y as f32));
        let landed: Vec<Option<f32>> = from.data.iter().map(|v| Some(1.2 * v)).collect();
        assert!((exposure_gain(&from, &landed) - 1.2).abs() < 1e-5);
        // Too few pixels landed in the frame: no estimate.
        let out = vec![None; W * H];
        assert_eq!(exposure_gain(&from, &out), 1.0);
        // A black frame: no pixel bright enough.
        let black = Plane::filled(W, H, 0.0);
        assert_eq!(exposure_gain(&black, &landed), 1.0);
    }

    #[test]
    fn a_tripod_shot_decides_nothing() {
        assert_eq!(
            pan(20, 0.0, (40, 4, 12, 6), true),
            Overlay::TooLittleMotion { pairs: 0 }
        );
        // Too few pairs with motion.
        assert_eq!(
            pan(5, 2.0, (40, 4, 12, 6), true),
            Overlay::TooLittleMotion { pairs: 4 }
        );
    }

    #[test]
    fn a_large_still_area_is_taken_for_distant_scene() {
        match pan(20, 2.0, (0, 0, 40, 20), false) {
            Overlay::TooLarge { fraction } => assert!(fraction > 0.3, "{fraction}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn specks_are_dropped() {
        let Overlay::Found(m) = pan(20, 2.0, (10, 10, 2, 2), true) else {
            panic!("no decision");
        };
        assert!(m.iter().all(|b| !b));
    }
}
