//! Keyframe selection for videos: drop frames without texture, blurry frames
//! and near-duplicates before the pose and training stages.
//!
//! Every frame is read as grey and resized so its longer side is
//! [`KeyframeOptions::long_side`] pixels.
//!
//! 0. **No texture.** A frame whose textured fraction
//!    ([`romo::pipeline::texture_fraction`]: pixels whose gradient exceeds
//!    about 2 grey levels per pixel) is below `min_texture` is dropped: a
//!    black, white or flat frame (a fade, a covered lens) gives the pose
//!    stage no features and the trainer a wrong picture. Such frames are
//!    also left out of the blur test's neighbours.
//! 1. **Blur.** Sharpness is the variance of the 4-neighbour Laplacian. A
//!    frame is blurry when its sharpness is below `blur_ratio` × the median
//!    sharpness of the frames within `blur_window` on either side: judged
//!    against its neighbours, a dull scene is not mistaken for a blurred one.
//! 2. **Near-duplicates.** Walking forward from the first sharp frame, the
//!    next frame is kept once the parallax to the last kept frame — the
//!    median optical-flow magnitude (DIS, `romo::flow`) over static pixels
//!    (mask 255; the moving ones say nothing about the camera) — reaches
//!    `min_parallax` × the image diagonal. A frame is also kept when
//!    `max_gap` frames went by since the last kept one, so a slow pan keeps
//!    enough overlap for sequential matching.
//!
//! The masks of the kept frames are the masks of the same names: selection
//! returns names, and [`link_keyframes`] links images and masks together.

use anyhow::{Context, Result};
use romo::flow::dis::{Dis, DisOptions};
use romo::plane::{Plane, Rgb};
use std::path::Path;

/// Settings of [`select_keyframes`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct KeyframeOptions {
    /// Longer side of the analysis images, pixels. Default 320.
    pub long_side: u32,
    /// Blurry below this fraction of the neighbours' median sharpness.
    /// Default 0.5.
    pub blur_ratio: f64,
    /// Neighbours on each side for the blur test. Default 3.
    pub blur_window: usize,
    /// Smallest parallax to the last kept frame, as a fraction of the image
    /// diagonal. Default 0.01 (1 %).
    pub min_parallax: f64,
    /// Keep a frame at least every `max_gap` frames. Default 4.
    pub max_gap: usize,
    /// Smallest textured fraction of a frame. Default 0.01, the mask
    /// stage's `labels.min_texture_fraction`, below which a frame carries
    /// no motion evidence either.
    pub min_texture: f64,
}

impl Default for KeyframeOptions {
    fn default() -> Self {
        KeyframeOptions {
            long_side: 320,
            blur_ratio: 0.5,
            blur_window: 3,
            min_parallax: 0.01,
            max_gap: 4,
            min_texture: 0.01,
        }
    }
}

/// Why a frame was dropped, or that it was kept.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "verdict")]
pub enum Verdict {
    Kept,
    Untextured { texture: f64 },
    Blurry { sharpness: f64, neighbours: f64 },
    Duplicate { parallax_px: f64 },
}

/// The selection.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Keyframes {
    /// Kept frame names, in order.
    pub kept: Vec<String>,
    /// One verdict per input frame.
    pub verdicts: Vec<(String, Verdict)>,
}

/// How many frames were dropped, by reason.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct Dropped {
    /// Black, white or flat frames.
    #[serde(default)]
    pub untextured: usize,
    pub blurry: usize,
    pub duplicates: usize,
}

impl std::fmt::Display for Dropped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.untextured > 0 {
            write!(f, "{} without texture, ", self.untextured)?;
        }
        write!(
            f,
            "{} blurry, {} near-duplicates",
            self.blurry, self.duplicates
        )
    }
}

impl Keyframes {
    /// Frames dropped, by reason.
    pub fn dropped(&self) -> Dropped {
        let count = |f: fn(&Verdict) -> bool| self.verdicts.iter().filter(|(_, v)| f(v)).count();
        Dropped {
            untextured: count(|v| matches!(v, Verdict::Untextured { .. })),
            blurry: count(|v| matches!(v, Verdict::Blurry { .. })),
            duplicates: count(|v| matches!(v, Verdict::Duplicate { .. })),
        }
    }
}

/// Variance of the 4-neighbour Laplacian over interior pixels.
pub fn laplacian_variance(p: &Plane) -> f64 {
    if p.w < 3 || p.h < 3 {
        return 0.0;
    }
    let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
    for y in 1..p.h - 1 {
        for x in 1..p.w - 1 {
            let l = f64::from(
                p.at(x - 1, y) + p.at(x + 1, y) + p.at(x, y - 1) + p.at(x, y + 1)
                    - 4.0 * p.at(x, y),
            );
            s += l;
            s2 += l * l;
            n += 1.0;
        }
    }
    let mean = s / n;
    (s2 / n - mean * mean).max(0.0)
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median flow magnitude from `a` to `b` over pixels where `keep` (if any)
/// is true.
fn parallax(dis: &Dis, a: &Plane, b: &Plane, keep: Option<&[bool]>) -> Result<f64> {
    let f = dis.compute(a, b)?;
    let mut mags: Vec<f64> =
        f.u.data
            .iter()
            .zip(&f.v.data)
            .enumerate()
            .filter(|(i, _)| keep.is_none_or(|k| k[*i]))
            .map(|(_, (u, v))| f64::from(u.hypot(*v)))
            .collect();
    if mags.is_empty() {
        // Everything is moving: no evidence of a duplicate, keep the frame.
        return Ok(f64::INFINITY);
    }
    Ok(median(&mut mags))
}

/// Select keyframes among `frames` (grey planes, same size, in order) with
/// optional static-pixel masks (true = static). Pure: no files.
pub fn select(
    names: &[String],
    frames: &[Plane],
    masks: &[Option<Vec<bool>>],
    opts: &KeyframeOptions,
) -> Result<Keyframes> {
    let n = frames.len();
    anyhow::ensure!(
        names.len() == n && masks.len() == n,
        "keyframes: {} names, {} frames, {} masks",
        names.len(),
        n,
        masks.len()
    );
    let sharp: Vec<f64> = frames.iter().map(laplacian_variance).collect();
    let mut verdicts: Vec<Option<Verdict>> = frames
        .iter()
        .map(|f| {
            let texture = f64::from(romo::pipeline::texture_fraction(f));
            (texture < opts.min_texture).then_some(Verdict::Untextured { texture })
        })
        .collect();
    anyhow::ensure!(
        n == 0 || verdicts.iter().any(Option::is_none),
        "none of the {n} frames has texture (under {:.0}% of each frame's pixels change by more than 2 grey levels: black, white or flat frames)",
        opts.min_texture * 100.0
    );
    for i in 0..n {
        if verdicts[i].is_some() {
            continue;
        }
        let lo = i.saturating_sub(opts.blur_window);
        let hi = (i + opts.blur_window + 1).min(n);
        let mut neigh: Vec<f64> = (lo..hi)
            .filter(|&j| j != i && !matches!(verdicts[j], Some(Verdict::Untextured { .. })))
            .map(|j| sharp[j])
            .collect();
        if neigh.is_empty() {
            continue;
        }
        let m = median(&mut neigh);
        if sharp[i] < opts.blur_ratio * m {
            verdicts[i] = Some(Verdict::Blurry {
                sharpness: sharp[i],
                neighbours: m,
            });
        }
    }
    let dis = Dis::new(DisOptions::opencv_medium());
    let (w, h) = frames.first().map_or((0, 0), |f| (f.w, f.h));
    let threshold = opts.min_parallax * ((w * w + h * h) as f64).sqrt();
    let mut last: Option<usize> = None;
    let mut kept = Vec::new();
    for i in 0..n {
        if verdicts[i].is_some() {
            continue;
        }
        let keep = match last {
            None => true,
            Some(l) if i - l >= opts.max_gap || i + 1 == n => true,
            Some(l) => {
                let static_px: Option<Vec<bool>> = match (&masks[l], &masks[i]) {
                    (Some(a), Some(b)) => Some(a.iter().zip(b).map(|(x, y)| *x && *y).collect()),
                    (Some(a), None) => Some(a.clone()),
                    (None, Some(b)) => Some(b.clone()),
                    (None, None) => None,
                };
                let p = parallax(&dis, &frames[l], &frames[i], static_px.as_deref())?;
                if p < threshold {
                    verdicts[i] = Some(Verdict::Duplicate { parallax_px: p });
                    false
                } else {
                    true
                }
            }
        };
        if keep {
            verdicts[i] = Some(Verdict::Kept);
            kept.push(names[i].clone());
            last = Some(i);
        }
    }
    Ok(Keyframes {
        kept,
        verdicts: names
            .iter()
            .cloned()
            .zip(verdicts.into_iter().map(|v| v.unwrap_or(Verdict::Kept)))
            .collect(),
    })
}

/// Read `images/<name>` (and `masks/<name>.png` when `masks` is given) at the
/// analysis size and select keyframes.
pub fn select_keyframes(
    images: &Path,
    masks: Option<&Path>,
    names: &[String],
    opts: &KeyframeOptions,
) -> Result<Keyframes> {
    let mut frames = Vec::with_capacity(names.len());
    let mut ms = Vec::with_capacity(names.len());
    for n in names {
        let p = images.join(n);
        let img = loader::io::read_rgb32f(&p)?;
        let (w, h) = (img.width(), img.height());
        let s = f64::from(opts.long_side) / f64::from(w.max(h));
        let (nw, nh) = if s < 1.0 {
            (
                ((f64::from(w) * s).round() as u32).max(8),
                ((f64::from(h) * s).round() as u32).max(8),
            )
        } else {
            (w, h)
        };
        let gray = Rgb::from_image(&img)
            .gray()
            .resize(nw as usize, nh as usize);
        frames.push(gray);
        let m = match masks {
            Some(dir) => {
                let mp = dir.join(format!("{n}.png"));
                let m = loader::io::read_gray8(&mp)?;
                let m = image::imageops::resize(&m, nw, nh, image::imageops::FilterType::Nearest);
                Some(m.as_raw().iter().map(|&v| v >= 128).collect())
            }
            None => None,
        };
        ms.push(m);
    }
    select(names, &frames, &ms, opts).with_context(|| images.display().to_string())
}

/// Make `out/images/<name>` (and `out/masks/<name>.png`) links to the kept
/// frames of `scene`, replacing whatever `out` held.
pub fn link_keyframes(scene: &Path, kept: &[String], out: &Path) -> Result<()> {
    for sub in ["images", "masks"] {
        let d = out.join(sub);
        if d.exists() {
            std::fs::remove_dir_all(&d)
                .with_context(|| format!("{}: cannot remove", d.display()))?;
        }
    }
    let has_masks = scene.join("masks").is_dir();
    for sub in ["images", "masks"] {
        if sub == "masks" && !has_masks {
            continue;
        }
        let d = out.join(sub);
        std::fs::create_dir_all(&d).with_context(|| format!("{}: cannot create", d.display()))?;
        for n in kept {
            let file = if sub == "masks" {
                format!("{n}.png")
            } else {
                n.clone()
            };
            let src = std::fs::canonicalize(scene.join(sub).join(&file))
                .with_context(|| format!("{}: missing", scene.join(sub).join(&file).display()))?;
            let dst = d.join(&file);
            #[cfg(unix)]
            std::os::unix::fs::symlink(&src, &dst)
                .with_context(|| format!("{}: cannot link", dst.display()))?;
            #[cfg(not(unix))]
            std::fs::copy(&src, &dst).with_context(|| format!("{}: cannot copy", dst.display()))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A textured frame shifted right by `dx` pixels.
    fn frame(dx: f32) -> Plane {
        Plane::from_fn(160, 120, |x, y| {
            let x = x as f32 - dx;
            let y = y as f32;
            0.5 + 0.2 * (x * 0.21).sin() * (y * 0.17).cos()
                + 0.15 * ((x * 0.053 + y * 0.071).sin())
                + 0.1 * (((x * 0.9).sin() * (y * 1.1).sin()) > 0.3) as u8 as f32
        })
    }

    #[test]
    fn drops_duplicates_and_blur() {
        // Camera panning 4 px per frame; frame 3 repeats frame 2, frame 5 is blurred.
        let shifts = [0.0, 4.0, 8.0, 8.0, 12.0, 16.0, 20.0, 24.0];
        let mut frames: Vec<Plane> = shifts.iter().map(|&d| frame(d)).collect();
        frames[5] = frames[5].gaussian(2.5);
        let names: Vec<String> = (0..frames.len()).map(|i| format!("{i:05}.png")).collect();
        let masks = vec![None; frames.len()];
        let k = select(
            &names,
            &frames,
            &masks,
            &KeyframeOptions {
                max_gap: 10,
                ..Default::default()
            },
        )
        .unwrap();
        let v: Vec<&Verdict> = k.verdicts.iter().map(|(_, v)| v).collect();
        assert!(matches!(v[3], Verdict::Duplicate { .. }), "{v:?}");
        assert!(matches!(v[5], Verdict::Blurry { .. }), "{v:?}");
        assert_eq!(
            k.kept,
            ["00000", "00001", "00002", "00004", "00006", "00007"].map(|s| format!("{s}.png"))
        );
    }

    #[test]
    fn moving_pixels_do_not_count_as_parallax() {
        // Static background; a bright block moves 20 px in the second frame.
        let bg = frame(0.0);
        let mut a = bg.clone();
        let mut b = bg.clone();
        for y in 30..80 {
            for x in 20..70 {
                a.data[y * 160 + x] = 0.9 + 0.05 * ((x + y) % 3) as f32;
                b.data[y * 160 + x + 20] = 0.9 + 0.05 * ((x + y) % 3) as f32;
            }
        }
        let c = frame(6.0);
        let names: Vec<String> = ["a", "b", "c"].map(String::from).to_vec();
        let mut moving = vec![true; 160 * 120];
        for y in 25..85 {
            for x in 15..95 {
                moving[y * 160 + x] = false;
            }
        }
        let masks = vec![Some(moving.clone()), Some(moving.clone()), Some(moving)];
        let opts = KeyframeOptions {
            max_gap: 10,
            ..Default::default()
        };
        let k = select(&names, &[a, b, c], &masks, &opts).unwrap();
        assert!(
            matches!(k.verdicts[1].1, Verdict::Duplicate { .. }),
            "{:?}",
            k.verdicts
        );
        // The last frame is always kept.
        assert_eq!(k.kept, ["a", "c"]);
    }

    #[test]
    fn flat_frames_are_dropped_and_do_not_judge_blur() {
        // A pan that fades to black: the black frames carry nothing, and the
        // last sharp frame is not called blurry against them.
        let mut frames: Vec<Plane> = (0..6).map(|i| frame(4.0 * i as f32)).collect();
        frames.extend((0..4).map(|_| Plane::filled(160, 120, 0.0)));
        let names: Vec<String> = (0..frames.len()).map(|i| format!("{i:05}.png")).collect();
        let masks = vec![None; frames.len()];
        let opts = KeyframeOptions {
            max_gap: 10,
            ..Default::default()
        };
        let k = select(&names, &frames, &masks, &opts).unwrap();
        let d = k.dropped();
        assert_eq!((d.untextured, d.blurry), (4, 0), "{:?}", k.verdicts);
        assert_eq!(k.kept.len(), 6, "{:?}", k.verdicts);
        assert_eq!(k.kept.last().map(String::as_str), Some("00005.png"));
        // Nothing but black frames: one clear error.
        let black = vec![Plane::filled(160, 120, 0.0); 3];
        let e = select(&names[..3], &black, &masks[..3], &opts).unwrap_err();
        assert!(
            e.to_string().contains("none of the 3 frames has texture"),
            "{e}"
        );
    }

    #[test]
    fn laplacian_variance_falls_with_blur() {
        let f = frame(0.0);
        assert!(laplacian_variance(&f.gaussian(2.0)) < 0.3 * laplacian_variance(&f));
        assert_eq!(laplacian_variance(&Plane::filled(10, 10, 0.3)), 0.0);
    }
}
