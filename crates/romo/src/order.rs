//! The order in which a folder of photos is segmented.
//!
//! RoMo pairs each frame with the next one, so the frames must be in
//! capture order: neighbours in the list must overlap. A video's frames are;
//! a folder of photos is only when its file names sort in capture order.
//! Photos renamed, merged from two phones, or numbered past a counter's
//! wrap (`IMG_9999` → `IMG_0001`) pair views that hardly overlap, whose flow
//! and masks are poor (on 12 frames of `lady-running` in a shuffled name
//! order, COLMAP with those masks registered 6 of 12 against 12 of 12).
//!
//! [`FrameOrder::Auto`] compares the name order with a similarity order: a
//! short path through the frames under a distance between tiny grey
//! thumbnails (greedy nearest neighbour, then 2-opt). The name order is kept
//! unless its median step between neighbours is more than [`RENAME_FACTOR`]
//! times the similarity path's.

use crate::plane::Rgb;
use crate::{Result, pipeline::FrameSource};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How the frames of a folder are ordered for segmentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum FrameOrder {
    /// File-name order, unless it is clearly not the capture order: then
    /// the similarity order (default). Over 4000 frames (`MAX_FRAMES`) the
    /// names' order is kept.
    #[default]
    Auto,
    /// File-name order (a video's frames).
    Names,
    /// Always the similarity order.
    Similarity,
}

/// The name order is replaced when its median step is over this factor
/// times the similarity path's. Measured (`docs/results.md`): videos and
/// photo sequences in their own order 0.97–1.49 (1.32 on car-roundabout
/// and 1.49 on `scenes/follow.toml`, where frames two apart look as alike
/// as neighbours), shuffled names 2.8–60.
pub const RENAME_FACTOR: f64 = 2.0;

/// Thumbnails are this many pixels wide and [`THUMB_H`] high, whatever the
/// frame's aspect ratio (only frames of one size are segmented together).
const THUMB_W: usize = 32;
const THUMB_H: usize = 24;

/// Above this many frames the distance matrix (4 bytes a pair) is not
/// built and the names' order is kept.
pub const MAX_FRAMES: usize = 4000;

/// A frame's thumbnail: the grey image averaged over `THUMB_W × THUMB_H`
/// blocks.
pub fn thumbnail(frame: &Rgb) -> Vec<f32> {
    let g = frame.gray();
    let mut t = vec![0f32; THUMB_W * THUMB_H];
    let mut n = vec![0f32; THUMB_W * THUMB_H];
    // Each column's thumbnail column, once (not a division per pixel).
    let tx: Vec<usize> = (0..g.w).map(|x| x * THUMB_W / g.w.max(1)).collect();
    for y in 0..g.h {
        let row = y * THUMB_H / g.h.max(1) * THUMB_W;
        for (v, &c) in g.data[y * g.w..(y + 1) * g.w].iter().zip(&tx) {
            t[row + c] += v;
            n[row + c] += 1.0;
        }
    }
    for (v, c) in t.iter_mut().zip(&n) {
        *v /= c.max(1.0);
    }
    t
}

/// Thumbnails are compared at shifts up to this many thumbnail pixels
/// (6% of the width): a camera that moved between two photos shifts their
/// content. On the fox + DAVIS composite (67 photos) a frame's nearest
/// thumbnail is its capture neighbour for 87% of frames without shifts and
/// 93% with ±2.
const MAX_SHIFT: isize = 2;

/// Shifts are tried for each frame's this many nearest thumbnails at zero
/// shift; other pairs keep their zero-shift distance (never smaller).
const SHIFT_CANDIDATES: usize = 16;

/// Normalised cross-correlation of `a` and `b` over their overlap when `b`
/// is moved by (`dx`, `dy`) thumbnail pixels: exposure does not count.
fn correlation(a: &[f32], b: &[f32], dx: isize, dy: isize) -> f32 {
    let (w, h) = (THUMB_W as isize, THUMB_H as isize);
    let (mut sa, mut sb, mut saa, mut sbb, mut sab, mut n) = (0f64, 0f64, 0f64, 0f64, 0f64, 0f64);
    for y in dy.max(0)..(h + dy.min(0)) {
        for x in dx.max(0)..(w + dx.min(0)) {
            let va = f64::from(a[(y * w + x) as usize]);
            let vb = f64::from(b[((y - dy) * w + (x - dx)) as usize]);
            sa += va;
            sb += vb;
            saa += va * va;
            sbb += vb * vb;
            sab += va * vb;
            n += 1.0;
        }
    }
    let n = n.max(1.0);
    let cov = sab - sa * sb / n;
    let var = (saa - sa * sa / n) * (sbb - sb * sb / n);
    if var <= 1e-18 {
        return 0.0;
    }
    (cov / var.sqrt()) as f32
}

/// Distance of two thumbnails: 1 − their correlation, in [0, 2], at the
/// best shift within ±`shift` thumbnail pixels.
fn distance(a: &[f32], b: &[f32], shift: isize) -> f32 {
    let mut best = f32::MIN;
    for dy in -shift..=shift {
        for dx in -shift..=shift {
            best = best.max(correlation(a, b, dx, dy));
        }
    }
    1.0 - best
}

/// The distance matrix, row-major: zero-shift distances, lowered to the
/// shifted one for each frame's nearest candidates (both directions).
fn distances(thumbs: &[Vec<f32>]) -> Vec<f32> {
    let n = thumbs.len();
    let mut d = vec![0f32; n * n];
    d.par_chunks_mut(n).enumerate().for_each(|(i, row)| {
        for (j, v) in row.iter_mut().enumerate() {
            *v = if i == j {
                0.0
            } else {
                distance(&thumbs[i], &thumbs[j], 0)
            };
        }
    });
    let refined: Vec<(usize, usize, f32)> = (0..n)
        .into_par_iter()
        .flat_map_iter(|i| {
            let row = &d[i * n..(i + 1) * n];
            let mut near: Vec<usize> = (0..n).filter(|&j| j != i).collect();
            near.sort_by(|&a, &b| row[a].total_cmp(&row[b]));
            near.truncate(SHIFT_CANDIDATES);
            near.into_iter()
                .map(move |j| (i, j, distance(&thumbs[i], &thumbs[j], MAX_SHIFT)))
                .collect::<Vec<_>>()
        })
        .collect();
    for (i, j, v) in refined {
        let v = v.min(d[i * n + j]);
        d[i * n + j] = v;
        d[j * n + i] = v;
    }
    d
}

/// Median distance between consecutive frames of `order`: a few frames
/// unlike all others (a black frame, a flash, a blurred photo) do not
/// change it, while a shuffled order raises it to a random pair's.
pub fn median_step(d: &[f32], n: usize, order: &[usize]) -> f64 {
    let mut steps: Vec<f32> = order.windows(2).map(|w| d[w[0] * n + w[1]]).collect();
    if steps.is_empty() {
        return 0.0;
    }
    let mid = steps.len() / 2;
    let (_, m, _) = steps.select_nth_unstable_by(mid, f32::total_cmp);
    f64::from(*m)
}

/// A short open path through all `n` frames: greedy nearest neighbour from
/// frame 0, then 2-opt (segment reversals, either end free) until no
/// reversal shortens it, then the runs between its long steps re-joined in
/// their best order and directions ([`stitch_runs`]).
pub fn short_path(d: &[f32], n: usize) -> Vec<usize> {
    if n < 3 {
        return (0..n).collect();
    }
    let mut seen = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut cur = 0;
    seen[0] = true;
    order.push(0);
    for _ in 1..n {
        let next = (0..n)
            .filter(|&j| !seen[j])
            .min_by(|&a, &b| d[cur * n + a].total_cmp(&d[cur * n + b]))
            .unwrap_or(cur);
        seen[next] = true;
        order.push(next);
        cur = next;
    }
    two_opt(d, n, &mut order);
    let mut order = stitch_runs(d, n, order);
    two_opt(d, n, &mut order);
    order
}

/// 2-opt on an open path: reverse segments while that shortens it.
fn two_opt(d: &[f32], n: usize, order: &mut [usize]) {
    // Edge k joins order[k] and order[k + 1]; the virtual edges before the
    // first and after the last frame cost nothing, so either end may move.
    let edge = |o: &[usize], k: isize| -> f32 {
        if k < 0 || k as usize + 1 >= o.len() {
            0.0
        } else {
            d[o[k as usize] * n + o[k as usize + 1]]
        }
    };
    for _ in 0..100 {
        let mut improved = false;
        for i in -1..(n as isize - 1) {
            for j in (i + 1)..(n as isize) {
                // Reverse order[i+1 ..= j]: edges i and j are replaced by
                // (order[i], order[j]) and (order[i+1], order[j+1]).
                let a = if i < 0 { None } else { Some(order[i as usize]) };
                let b = order[(i + 1) as usize];
                let c = order[j as usize];
                let e = order.get(j as usize + 1).copied();
                let before = edge(order, i) + edge(order, j);
                let after = a.map_or(0.0, |a| d[a * n + c]) + e.map_or(0.0, |e| d[b * n + e]);
                if after + 1e-6 < before {
                    order[(i + 1) as usize..=j as usize].reverse();
                    improved = true;
                }
            }
        }
        if !improved {
            break;
        }
    }
}

/// Most runs [`stitch_runs`] re-joins (the exact search is exponential).
const MAX_RUNS: usize = 12;

/// 2-opt leaves paths made of correct runs joined at a few long steps where
/// no single reversal helps (runs A, B, C needing all three reversed). Cut
/// the path at steps over twice its median, and join the runs in the order
/// and directions that make the joins shortest: an exact search over
/// subsets (Held–Karp) when there are at most [`MAX_RUNS`] runs.
fn stitch_runs(d: &[f32], n: usize, order: Vec<usize>) -> Vec<usize> {
    let cut = 2.0 * median_step(d, n, &order) as f32;
    let mut runs: Vec<Vec<usize>> = vec![];
    for (k, &f) in order.iter().enumerate() {
        match runs.last_mut() {
            Some(run) if k > 0 && d[order[k - 1] * n + f] <= cut => run.push(f),
            _ => runs.push(vec![f]),
        }
    }
    let k = runs.len();
    if !(2..=MAX_RUNS).contains(&k) {
        return order;
    }
    // Run r in direction o (0 forward, 1 reversed): its first and last frame.
    let ends = |r: usize, o: usize| {
        let (a, b) = (runs[r][0], runs[r][runs[r].len() - 1]);
        if o == 0 { (a, b) } else { (b, a) }
    };
    let full = (1usize << k) - 1;
    let idx = |mask: usize, r: usize, o: usize| (mask * k + r) * 2 + o;
    let mut cost = vec![f32::INFINITY; (full + 1) * k * 2];
    let mut from = vec![usize::MAX; cost.len()];
    for r in 0..k {
        for o in 0..2 {
            cost[idx(1 << r, r, o)] = 0.0;
        }
    }
    for mask in 1..=full {
        for r in (0..k).filter(|r| mask & (1 << r) != 0) {
            for o in 0..2 {
                let c = cost[idx(mask, r, o)];
                if !c.is_finite() {
                    continue;
                }
                let last = ends(r, o).1;
                for q in (0..k).filter(|q| mask & (1 << q) == 0) {
                    for p in 0..2 {
                        let next = mask | (1 << q);
                        let v = c + d[last * n + ends(q, p).0];
                        if v < cost[idx(next, q, p)] {
                            cost[idx(next, q, p)] = v;
                            from[idx(next, q, p)] = idx(mask, r, o);
                        }
                    }
                }
            }
        }
    }
    let Some(mut at) = (0..k * 2)
        .map(|ro| idx(full, ro / 2, ro % 2))
        .min_by(|&a, &b| cost[a].total_cmp(&cost[b]))
    else {
        return order;
    };
    let mut chosen = vec![];
    while at != usize::MAX {
        let (r, o) = ((at / 2) % k, at % 2);
        chosen.push((r, o));
        at = from[at];
    }
    chosen.reverse();
    chosen
        .into_iter()
        .flat_map(|(r, o)| {
            let mut run = runs[r].clone();
            if o == 1 {
                run.reverse();
            }
            run
        })
        .collect()
}

/// What [`choose`] decided.
#[derive(Debug, Clone)]
pub struct Ordering {
    /// Frame indices in the order to segment them.
    pub order: Vec<usize>,
    /// Median step of the name order over the similarity order's (NaN
    /// when not measured).
    pub ratio: f64,
    /// True when the similarity order replaced the names'.
    pub reordered: bool,
}

/// The order to segment `src`'s frames in (see the module text).
pub fn choose<S: FrameSource + ?Sized>(src: &S, how: FrameOrder) -> Result<Ordering> {
    let n = src.len();
    let names = Ordering {
        order: (0..n).collect(),
        ratio: f64::NAN,
        reordered: false,
    };
    if how == FrameOrder::Similarity && n > MAX_FRAMES {
        return Err(crate::RomoError::Input(format!(
            "frame order `similarity`: {n} frames, at most {MAX_FRAMES} can be ordered (use `names`)"
        )));
    }
    if how == FrameOrder::Names || !(3..=MAX_FRAMES).contains(&n) {
        return Ok(names);
    }
    let thumbs = (0..n)
        .into_par_iter()
        .map(|i| Ok(thumbnail(&src.frame(i)?)))
        .collect::<Result<Vec<_>>>()?;
    let d = distances(&thumbs);
    let path = short_path(&d, n);
    let ratio = median_step(&d, n, &names.order) / median_step(&d, n, &path).max(1e-9);
    // Similarity order that only reverses the names' is no change.
    let reordered = (how == FrameOrder::Similarity || ratio > RENAME_FACTOR)
        && path != names.order
        && !path.iter().rev().copied().eq(0..n);
    Ok(Ordering {
        order: if reordered { path } else { names.order },
        ratio,
        reordered,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Length of the path visiting `order` in turn.
    fn path_length(d: &[f32], n: usize, order: &[usize]) -> f64 {
        order
            .windows(2)
            .map(|w| f64::from(d[w[0] * n + w[1]]))
            .sum()
    }

    /// Frames of a pan over a smooth random texture, three pixels a frame
    /// (more than the shift search absorbs).
    fn pan(n: usize) -> Vec<Vec<f32>> {
        let wide = THUMB_W + 3 * n + 12;
        let mut s = 99u64;
        let mut noise = vec![0f32; wide * THUMB_H];
        for v in &mut noise {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *v = (s >> 40) as f32 / (1u64 << 24) as f32;
        }
        (0..n)
            .map(|k| {
                (0..THUMB_W * THUMB_H)
                    .map(|p| {
                        let (x, y) = (p % THUMB_W + 3 * k, p / THUMB_W);
                        (0..12).map(|dx| noise[y * wide + x + dx]).sum()
                    })
                    .collect()
            })
            .collect()
    }

    /// Grey frames of thumbnail size from thumbnails.
    fn frames(thumbs: &[Vec<f32>]) -> Vec<Rgb> {
        thumbs
            .iter()
            .map(|t| {
                let top = t.iter().fold(1e-6f32, |a, v| a.max(*v));
                let rgb: Vec<f32> = t.iter().flat_map(|v| [v / top; 3]).collect();
                Rgb::from_interleaved(THUMB_W, THUMB_H, &rgb)
            })
            .collect()
    }

    #[test]
    fn a_shuffled_pan_is_put_back_in_order() {
        let n = 30;
        let thumbs = pan(n);
        // A fixed shuffle.
        let mut perm: Vec<usize> = (0..n).map(|i| (i * 7 + 3) % n).collect();
        perm.rotate_left(5);
        let shuffled: Vec<Vec<f32>> = perm.iter().map(|&i| thumbs[i].clone()).collect();
        let got = choose(frames(&shuffled).as_slice(), FrameOrder::Auto).unwrap();
        assert!(got.reordered && got.ratio > RENAME_FACTOR, "{}", got.ratio);
        let recovered: Vec<usize> = got.order.iter().map(|&k| perm[k]).collect();
        let forward: Vec<usize> = (0..n).collect();
        let backward: Vec<usize> = (0..n).rev().collect();
        assert!(
            recovered == forward || recovered == backward,
            "{recovered:?}"
        );
        // The pan in its own order: names kept, the path is the same.
        let got = choose(frames(&thumbs).as_slice(), FrameOrder::Auto).unwrap();
        assert!(
            !got.reordered && (got.ratio - 1.0).abs() < 1e-6,
            "{}",
            got.ratio
        );
        // `names` is not measured; `similarity` that only reverses is no change.
        let got = choose(frames(&thumbs).as_slice(), FrameOrder::Names).unwrap();
        assert!(!got.reordered && got.ratio.is_nan());
        let got = choose(frames(&thumbs).as_slice(), FrameOrder::Similarity).unwrap();
        assert_eq!(got.order, forward);
    }

    /// A black frame in a short video is unlike every other frame, so any
    /// path has a long step at it, and the names' order two: the path
    /// length grows by 31% in the names' order, the median step does not
    /// move, and the names' order stays.
    #[test]
    fn a_black_frame_does_not_reorder_a_video() {
        let mut thumbs = pan(14);
        thumbs[10] = vec![0.0; THUMB_W * THUMB_H];
        let d = distances(&thumbs);
        let names: Vec<usize> = (0..14).collect();
        let path = short_path(&d, 14);
        let by_length = path_length(&d, 14, &names) / path_length(&d, 14, &path);
        let by_median = median_step(&d, 14, &names) / median_step(&d, 14, &path);
        assert!(by_length > 1.25, "{by_length}");
        assert!((by_median - 1.0).abs() < 0.1, "{by_median}");
        let got = choose(frames(&thumbs).as_slice(), FrameOrder::Auto).unwrap();
        assert!(!got.reordered, "ratio {}", got.ratio);
        assert_eq!(got.order, names);
    }

    #[test]
    fn two_opt_never_lengthens_the_greedy_path() {
        // Random symmetric distances.
        let n = 25;
        let mut s = 12345u64;
        let mut d = vec![0f32; n * n];
        for i in 0..n {
            for j in (i + 1)..n {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let v = (s >> 40) as f32 / (1u64 << 24) as f32;
                d[i * n + j] = v;
                d[j * n + i] = v;
            }
        }
        let path = short_path(&d, n);
        let mut sorted = path.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..n).collect::<Vec<_>>());
        // 2-opt optimal: no single reversal shortens it.
        let len = path_length(&d, n, &path);
        for i in 0..n {
            for j in (i + 1)..n {
                let mut p = path.clone();
                p[i..=j].reverse();
                assert!(path_length(&d, n, &p) >= len - 1e-4, "{i} {j}");
            }
        }
    }

    #[test]
    fn thumbnails_ignore_exposure() {
        let (w, h) = (64, 48);
        let mut a = Vec::new();
        let mut b = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let v = ((x as f32 * 0.2).sin() + (y as f32 * 0.3).cos()) * 0.2 + 0.5;
                for c in [v, v * 0.9, v * 0.8] {
                    a.push(c);
                    b.push(c * 1.3 + 0.05);
                }
            }
        }
        let f = Rgb::from_interleaved(w, h, &a);
        let brighter = Rgb::from_interleaved(w, h, &b);
        let d = distance(&thumbnail(&f), &thumbnail(&brighter), MAX_SHIFT);
        assert!(d.abs() < 1e-4, "{d}");
    }
}
