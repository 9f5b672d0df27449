//! Region completion (ours, part of stage 9): the MLP's probability is
//! completed over segments of the optical-flow field.
//!
//! The paper completes its coarse masks with SAM2's mask decoder, which
//! turns "the legs of a pedestrian move" into "the pedestrian moves". The
//! classical stand-in here: a rigid object moves with one (locally smooth)
//! flow that differs from the static background behind it, so the flow
//! field, segmented with Felzenszwalb & Huttenlocher's graph method
//! ("Efficient Graph-Based Image Segmentation", IJCV 2004) on flow
//! differences normalised by the frame's mean flow magnitude, falls apart
//! into regions that are each one object (or one part of the background).
//! A region whose mean moving probability exceeds the threshold is moving
//! as a whole: its pixels' probabilities are raised to that mean, except
//! where the last round's labels are L (confidently static by the epipolar
//! test). Regions below it are left as they are, so completion only adds
//! recall where the MLP already saw most of an object.

use crate::flow::Flow;
use crate::plane::{Plane, Rgb};
use serde::{Deserialize, Serialize};

/// Region-completion options.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(default)]
pub struct RegionOptions {
    /// Complete the probability over flow segments (default true; see the
    /// README for what it gains and costs).
    #[cfg_attr(feature = "cli", arg(id = "region_completion", long = "no-region-completion", action = clap::ArgAction::SetFalse, help = "Turn off region completion (a segment of the flow field mostly called moving becomes moving as a whole, except its confidently static pixels)"))]
    pub enabled: bool,
    /// Felzenszwalb–Huttenlocher scale `k` (in units of the normalised flow
    /// difference × pixels; larger merges more; default 4).
    #[cfg_attr(feature = "cli", arg(long = "region-k", required = false))]
    pub k: f32,
    /// Regions smaller than this many grid pixels are merged into their
    /// most similar neighbour (default 20).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub min_size: usize,
    /// A region is completed when its mean probability is above this
    /// (default 0.5, the mask threshold).
    #[cfg_attr(feature = "cli", arg(skip))]
    pub threshold: f32,
}

impl Default for RegionOptions {
    fn default() -> Self {
        Self {
            enabled: true,
            k: 4.0,
            min_size: 20,
            threshold: 0.5,
        }
    }
}

impl RegionOptions {
    /// Check the options.
    pub fn validate(&self) -> crate::Result<()> {
        let ok = self.k.is_finite() && self.k > 0.0 && (0.0..1.0).contains(&self.threshold);
        if !ok {
            return Err(crate::RomoError::Options(
                "regions: k > 0 and threshold in [0, 1) required".into(),
            ));
        }
        Ok(())
    }
}

/// Union–find with per-set size and internal difference.
struct Forest {
    parent: Vec<u32>,
    size: Vec<u32>,
    internal: Vec<f32>,
}

impl Forest {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
            internal: vec![0.0; n],
        }
    }
    fn find(&mut self, mut i: u32) -> u32 {
        while self.parent[i as usize] != i {
            let p = self.parent[i as usize];
            self.parent[i as usize] = self.parent[p as usize];
            i = p;
        }
        i
    }
    fn union(&mut self, a: u32, b: u32, w: f32) -> u32 {
        let (big, small) = if self.size[a as usize] >= self.size[b as usize] {
            (a, b)
        } else {
            (b, a)
        };
        self.parent[small as usize] = big;
        self.size[big as usize] += self.size[small as usize];
        self.internal[big as usize] = w;
        big
    }
}

/// Segment a flow field: a region label per pixel (labels are arbitrary
/// pixel indices, equal within a region). Edges join 8-neighbours with
/// weight |Δflow| / scale.
pub fn flow_segments(flow: &Flow, scale: f32, k: f32, min_size: usize) -> Vec<u32> {
    let s = scale.max(1e-6);
    let (fu, fv) = (&flow.u.data, &flow.v.data);
    segment(
        flow.w(),
        flow.h(),
        |a, b| {
            let du = fu[a] - fu[b];
            let dv = fv[a] - fv[b];
            (du * du + dv * dv).sqrt() / s
        },
        k,
        min_size,
    )
}

/// Superpixels of a colour image (channels in [0, 1]): Felzenszwalb &
/// Huttenlocher's segmentation with the Euclidean RGB distance of
/// 8-neighbours as edge weight, after the Gaussian blur (σ = 0.8) their
/// paper applies first. Labels as in [`flow_segments`].
pub fn colour_segments(rgb: &Rgb, k: f32, min_size: usize) -> Vec<u32> {
    let c: [Plane; 3] = std::array::from_fn(|i| rgb.c[i].gaussian(0.8));
    segment(
        rgb.w(),
        rgb.h(),
        |a, b| {
            c.iter()
                .map(|p| {
                    let d = p.data[a] - p.data[b];
                    d * d
                })
                .sum::<f32>()
                .sqrt()
        },
        k,
        min_size,
    )
}

/// Felzenszwalb & Huttenlocher's graph segmentation of a `w × h` grid with
/// 8-neighbour edge weights `diff(a, b)`: edges in increasing weight merge
/// two components when the weight is at most both components' internal
/// difference plus `k / size`; components smaller than `min_size` are then
/// merged along their cheapest edges.
fn segment(
    w: usize,
    h: usize,
    diff: impl Fn(usize, usize) -> f32,
    k: f32,
    min_size: usize,
) -> Vec<u32> {
    let n = w * h;
    let mut edges: Vec<(f32, u32, u32)> = Vec::with_capacity(4 * n);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut push = |j: usize| {
                let d = diff(i, j);
                if d.is_finite() {
                    edges.push((d, i as u32, j as u32));
                }
            };
            if x + 1 < w {
                push(i + 1);
            }
            if y + 1 < h {
                push(i + w);
                if x + 1 < w {
                    push(i + w + 1);
                }
                if x > 0 {
                    push(i + w - 1);
                }
            }
        }
    }
    edges.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut f = Forest::new(n);
    for &(d, a, b) in &edges {
        let (ra, rb) = (f.find(a), f.find(b));
        if ra == rb {
            continue;
        }
        let ta = f.internal[ra as usize] + k / f.size[ra as usize] as f32;
        let tb = f.internal[rb as usize] + k / f.size[rb as usize] as f32;
        if d <= ta.min(tb) {
            f.union(ra, rb, d);
        }
    }
    for &(d, a, b) in &edges {
        let (ra, rb) = (f.find(a), f.find(b));
        if ra != rb
            && ((f.size[ra as usize] as usize) < min_size
                || (f.size[rb as usize] as usize) < min_size)
        {
            f.union(
                ra,
                rb,
                d.max(f.internal[ra as usize]).max(f.internal[rb as usize]),
            );
        }
    }
    (0..n as u32).map(|i| f.find(i)).collect()
}

/// Raise the probabilities of every region whose mean probability exceeds
/// `threshold` to that mean (see the module docs), except at pixels where
/// `fixed` is true (the pipeline passes L, the geometrically confident
/// static pixels, so a region that leaks across a blurred flow boundary
/// does not take the background with it). `labels` come from
/// [`flow_segments`] and index pixels of `prob`.
pub fn complete(prob: &mut [f32], labels: &[u32], threshold: f32, fixed: Option<&[bool]>) {
    let n = prob.len().min(labels.len());
    let m = labels.iter().map(|r| *r as usize + 1).max().unwrap_or(0);
    let mut sum = vec![0.0f64; m];
    let mut cnt = vec![0u32; m];
    for i in 0..n {
        let r = labels[i] as usize;
        sum[r] += prob[i] as f64;
        cnt[r] += 1;
    }
    for i in 0..n {
        let r = labels[i] as usize;
        let mean = (sum[r] / cnt[r].max(1) as f64) as f32;
        let is_fixed = fixed.is_some_and(|f| f.get(i) == Some(&true));
        if mean > threshold && prob[i] < mean && !is_fixed {
            prob[i] = mean;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Background flow: a smooth depth ramp (1.0–2.0 px); a 12×10 object
    /// moving with (−3, 0.5) px, its upper quarter ("head") unseen by the
    /// MLP.
    fn scene() -> (Flow, Vec<bool>) {
        let (w, h) = (48, 32);
        let inside = |x: usize, y: usize| (18..30).contains(&x) && (10..20).contains(&y);
        let f = Flow {
            u: Plane::from_fn(w, h, |x, y| {
                if inside(x, y) {
                    -3.0
                } else {
                    1.0 + x as f32 / w as f32
                }
            }),
            v: Plane::from_fn(w, h, |x, y| if inside(x, y) { 0.5 } else { 0.0 }),
        };
        let obj = (0..w * h).map(|i| inside(i % w, i / w)).collect();
        (f, obj)
    }

    #[test]
    fn segments_separate_an_object_from_a_smooth_background() {
        let (f, obj) = scene();
        let lab = flow_segments(&f, 1.5, 60.0, 20);
        let first_obj = obj.iter().position(|b| *b).unwrap();
        let first_bg = obj.iter().position(|b| !*b).unwrap();
        for (i, o) in obj.iter().enumerate() {
            let want = if *o { lab[first_obj] } else { lab[first_bg] };
            assert_eq!(lab[i], want, "pixel {i} (object {o})");
        }
        assert_ne!(lab[first_obj], lab[first_bg]);
    }

    /// Two textured colour regions meeting along a diagonal: no
    /// superpixel crosses the edge, and each side falls into few
    /// superpixels.
    #[test]
    fn colour_superpixels_stop_at_a_colour_edge() {
        let (w, h) = (48, 32);
        let side = |x: usize, y: usize| x + y / 2 >= 28;
        let tex = |x: usize, y: usize| 0.03 * ((x * 5 + y * 3) % 4) as f32;
        let rgb = Rgb {
            c: std::array::from_fn(|k| {
                Plane::from_fn(w, h, move |x, y| {
                    let base = if side(x, y) {
                        [0.7, 0.3, 0.2]
                    } else {
                        [0.2, 0.4, 0.6]
                    };
                    base[k] + tex(x, y)
                })
            }),
        };
        let lab = colour_segments(&rgb, 1.0, 20);
        let mut per_side = [
            std::collections::BTreeSet::new(),
            std::collections::BTreeSet::new(),
        ];
        for (i, l) in lab.iter().enumerate() {
            per_side[usize::from(side(i % w, i / w))].insert(*l);
        }
        assert!(per_side[0].is_disjoint(&per_side[1]), "{per_side:?}");
        assert!(
            per_side[0].len() <= 3 && per_side[1].len() <= 3,
            "{per_side:?}"
        );
    }

    #[test]
    fn completion_fills_the_unseen_part_of_a_mostly_moving_region() {
        let (f, obj) = scene();
        let w = f.w();
        // MLP: 0.9 on the object's lower 3/4, 0.1 on its top rows and on
        // the background, with a spurious 0.9 blob in the background.
        let mut p: Vec<f32> = (0..obj.len())
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if (obj[i] && y >= 13) || ((2..5).contains(&x) && (2..5).contains(&y)) {
                    0.9
                } else {
                    0.1
                }
            })
            .collect();
        let lab = flow_segments(&f, 1.5, 60.0, 20);
        let before = p.clone();
        complete(&mut p, &lab, 0.5, None);
        for (i, o) in obj.iter().enumerate() {
            if *o {
                assert!(p[i] > 0.5, "object pixel {i}: {}", p[i]);
            } else if !((2..5).contains(&(i % w)) && (2..5).contains(&(i / w))) {
                assert!(p[i] < 0.5, "background pixel {i}: {}", p[i]);
            }
        }
        // Fixed pixels (the object's top row) keep their probability.
        let fixed: Vec<bool> = (0..obj.len()).map(|i| obj[i] && i / w == 10).collect();
        let mut q = before.clone();
        complete(&mut q, &lab, 0.5, Some(&fixed));
        for i in 0..obj.len() {
            if fixed[i] {
                assert_eq!(q[i], before[i]);
            } else {
                assert_eq!(q[i], p[i]);
            }
        }
    }
}
