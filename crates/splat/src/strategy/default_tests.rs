//! Known answers for INRIA adaptive density control: what is cloned, split,
//! pruned and reset, with which parameters and Adam moments, and the cap.

use super::*;
use crate::strategy::opacities;
use crate::types::{AdamState, DensifyStats, Splats};

const EXTENT: f32 = 10.0;

/// Splat i: mean (i, 0, 0), isotropic scale `scales[i]`, opacity 0.5,
/// SH degree 0 with DC (i, 2i, 3i); gradient statistic `grads[i]` over 4
/// views, screen radius `radii[i]`; Adam moments all 1.
fn state(scales: &[f32], grads: &[f32], radii: &[f32]) -> ModelState {
    let n = scales.len();
    let splats = Splats {
        means: (0..n).map(|i| [i as f32, 0.0, 0.0]).collect(),
        log_scales: scales.iter().map(|s| [s.ln(); 3]).collect(),
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacity_logits: vec![0.0; n],
        sh: (0..n)
            .flat_map(|i| [i as f32, 2.0 * i as f32, 3.0 * i as f32])
            .collect(),
        sh_degree: 0,
    };
    let mut adam = AdamState::zeros_like(&splats);
    for m in [&mut adam.m, &mut adam.v] {
        m.means.iter_mut().for_each(|v| *v = [1.0; 3]);
        m.opacity_logits.iter_mut().for_each(|v| *v = 1.0);
    }
    let stats = DensifyStats {
        grad_accum: grads.iter().map(|g| 4.0 * g).collect(),
        count: vec![4; n],
        max_radius: radii.to_vec(),
    };
    ModelState {
        splats,
        adam,
        stats,
    }
}

fn refine(opts: DefaultStrategyOptions, step: u32, st: &mut ModelState) -> RefineReport {
    let mut s = DefaultStrategy::new(opts);
    assert!(s.wants_refine(step));
    s.refine(step, st, &SceneInfo::extent_only(EXTENT), 7)
}

#[test]
fn clones_small_and_splits_large_above_the_threshold() {
    // 0: small, gradient above 2e-4 → cloned; 1: large (0.5 > 0.01·10),
    // above → split into 2 and removed; 2: below the threshold → untouched.
    let mut st = state(&[0.05, 0.5, 0.5], &[3e-4, 2e-4, 1.9e-4], &[1.0; 3]);
    let rep = refine(DefaultStrategyOptions::default(), 600, &mut st);
    assert_eq!((rep.cloned, rep.split, rep.pruned), (1, 1, 0));
    assert!(!rep.opacity_reset);
    let s = &st.splats;
    // Kept in order 0, 2, then the clone of 0, then the two halves of 1.
    assert_eq!(s.len(), 5);
    assert_eq!(s.means[0], [0.0, 0.0, 0.0]);
    assert_eq!(s.means[1], [2.0, 0.0, 0.0]);
    assert_eq!(s.means[2], [0.0, 0.0, 0.0]);
    assert_eq!(s.log_scales[2], [0.05f32.ln(); 3]);
    assert_eq!(&s.sh[6..9], &[0.0, 0.0, 0.0]);
    for k in [3, 4] {
        // Scale / (0.8 · 2); mean drawn from the parent's Gaussian.
        for a in 0..3 {
            assert!((s.log_scales[k][a] - (0.5f32 / 1.6).ln()).abs() < 1e-6);
        }
        let d = s.means[k]
            .iter()
            .zip([1.0, 0.0, 0.0])
            .map(|(a, b)| (a - b) * (a - b));
        assert!(d.sum::<f32>().sqrt() < 0.5 * 6.0, "sample within 6σ");
        assert_eq!(&s.sh[3 * k..3 * k + 3], &[1.0, 2.0, 3.0]);
        assert_eq!(s.opacity_logits[k], 0.0);
    }
    assert_ne!(s.means[3], s.means[4]);
    // Survivors keep their moments; new splats start at zero.
    assert_eq!(st.adam.m.means[..2], [[1.0; 3], [1.0; 3]]);
    assert_eq!(st.adam.m.means[2..], [[0.0; 3]; 3]);
    assert_eq!(st.adam.v.opacity_logits, vec![1.0, 1.0, 0.0, 0.0, 0.0]);
    assert_eq!(st.stats.count.len(), 5);
}

#[test]
fn prunes_transparent_and_world_oversized_but_not_screen_wide_by_default() {
    // 0: transparent; 1: 1.5 > 0.1·10 in the world; 2: 50 px on screen;
    // 3: ordinary. Before the first reset (step 600) only 0 goes.
    let mut st = state(&[0.05, 1.5, 0.05, 0.05], &[0.0; 4], &[1.0, 1.0, 50.0, 1.0]);
    st.splats.opacity_logits[0] = logit(0.004);
    let mut early = st.clone();
    let rep = refine(DefaultStrategyOptions::default(), 600, &mut early);
    assert_eq!(rep.pruned, 1);
    assert_eq!(early.splats.means.len(), 3);
    // After it (step 3100): the world-oversized one too; the screen-wide
    // one stays because screen pruning is off by default (gsplat).
    let rep = refine(DefaultStrategyOptions::default(), 3100, &mut st.clone());
    assert_eq!(rep.pruned, 2);
    let mut inria = st.clone();
    let opts = DefaultStrategyOptions {
        prune_screen_px: 20.0,
        ..Default::default()
    };
    let rep = refine(opts, 3100, &mut inria);
    assert_eq!(rep.pruned, 3);
    assert_eq!(inria.splats.means, vec![[3.0, 0.0, 0.0]]);
}

#[test]
fn opacity_reset_caps_opacity_and_zeroes_its_moments() {
    let mut st = state(&[0.05, 0.05], &[0.0; 2], &[1.0; 2]);
    st.splats.opacity_logits = vec![logit(0.9), logit(0.006)];
    let rep = refine(DefaultStrategyOptions::default(), 3000, &mut st);
    assert!(rep.opacity_reset);
    let o = opacities(&st.splats);
    assert!(
        (o[0] - 0.01).abs() < 1e-6 && (o[1] - 0.006).abs() < 1e-6,
        "{o:?}"
    );
    assert_eq!(st.adam.m.opacity_logits, vec![0.0, 0.0]);
    assert_eq!(st.adam.v.opacity_logits, vec![0.0, 0.0]);
    // Other groups keep their moments.
    assert_eq!(st.adam.m.means, vec![[1.0; 3]; 2]);
    // No reset once densification has ended.
    assert!(!DefaultStrategy::default().wants_refine(15_000));
}

#[test]
fn the_cap_keeps_the_largest_gradients() {
    // Four small candidates, room for two clones: the two largest win.
    let grads = [3e-4, 9e-4, 5e-4, 8e-4];
    let mut st = state(&[0.05; 4], &grads, &[1.0; 4]);
    let opts = DefaultStrategyOptions {
        max_splats: 6,
        ..Default::default()
    };
    let rep = refine(opts, 600, &mut st);
    assert_eq!(rep.cloned, 2);
    assert_eq!(st.splats.len(), 6);
    assert_eq!(st.splats.means[4], [1.0, 0.0, 0.0]);
    assert_eq!(st.splats.means[5], [3.0, 0.0, 0.0]);
}

#[test]
fn validate_rejects_bad_screen_threshold() {
    for bad in [-1.0, f32::NAN, f32::INFINITY] {
        let o = DefaultStrategyOptions {
            prune_screen_px: bad,
            ..Default::default()
        };
        assert!(o.validate().is_err(), "{bad}");
    }
}

/// A 64×64 camera at the origin looking down +z (near 0.1, far 100).
fn front_camera() -> crate::types::RenderCamera {
    crate::types::RenderCamera {
        near: 0.1,
        ..crate::types::RenderCamera::at_origin(64, 64, 64.0)
    }
}

#[test]
fn prunes_splats_culled_in_every_training_view() {
    // Small splats at z = 5 (0: on axis, seen), z = -5 (1: behind the
    // camera), x = 50 (2: far outside the image), z = 500 (3: beyond far).
    let mut st = state(&[0.05; 4], &[0.0; 4], &[1.0; 4]);
    st.splats.means = vec![
        [0.0, 0.0, 5.0],
        [0.0, 0.0, -5.0],
        [50.0, 0.0, 5.0],
        [0.0, 0.0, 500.0],
    ];
    let cams = [front_camera()];
    let scene = SceneInfo {
        extent: EXTENT,
        cameras: &cams,
        low_pass: 0.3,
    };
    let mut s = DefaultStrategy::new(DefaultStrategyOptions::default());
    let mut pre = st.clone();
    assert_eq!(s.prepare(&mut pre, &scene).pruned, 3);
    assert_eq!(pre.splats.means, vec![[0.0, 0.0, 5.0]]);
    assert_eq!(pre.adam.m.len(), 1);
    // At a densification only splats not visible since the last one are
    // checked: splat 1 was (count 4), so it stays; 2 and 3 go.
    st.stats.count = vec![4, 4, 0, 0];
    let rep = s.refine(600, &mut st, &scene, 7);
    assert_eq!(rep.pruned, 2);
    assert_eq!(st.splats.means, vec![[0.0, 0.0, 5.0], [0.0, 0.0, -5.0]]);
    // A second camera looking down −z sees splat 1; without cameras nothing
    // is judged unseen; off, nothing is pruned.
    let mut back = front_camera();
    back.rotation = [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]];
    let two = [front_camera(), back];
    let mut pre = state(&[0.05; 2], &[0.0; 2], &[1.0; 2]);
    pre.splats.means = vec![[0.0, 0.0, 5.0], [0.0, 0.0, -5.0]];
    let both = SceneInfo {
        cameras: &two,
        ..scene
    };
    assert_eq!(s.prepare(&mut pre.clone(), &both).pruned, 0);
    assert_eq!(
        s.prepare(&mut pre.clone(), &SceneInfo::extent_only(EXTENT))
            .pruned,
        0
    );
    let mut off = DefaultStrategy::new(DefaultStrategyOptions {
        prune_unseen: false,
        ..Default::default()
    });
    assert_eq!(off.prepare(&mut pre, &scene).pruned, 0);
}
