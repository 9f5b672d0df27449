//! Known answers for the relocation formula and properties of relocation,
//! growth and the refinement schedule.

use super::*;
use crate::types::{AdamState, DensifyStats};

#[test]
fn relocation_single_copy_is_identity() {
    for o in [0.005, 0.3, 0.5, 0.99] {
        let (a, r) = relocation(o, 1);
        assert!((a - o).abs() < 1e-15, "{o}: {a}");
        assert!((r - 1.0).abs() < 1e-15, "{o}: {r}");
    }
}

#[test]
fn relocation_two_copies_hand_computed() {
    // o = 0.5, N = 2: α' = 1 − √0.5; denominator
    // (i=1: α') + (i=2: α' − α'²/√2) = 2α' − α'²/√2; ratio = 0.5 / that.
    let (a, r) = relocation(0.5, 2);
    let a_hand = 1.0 - 0.5f64.sqrt();
    assert!((a - a_hand).abs() < 1e-15);
    assert!((a - 0.292_893_218_813_452_4).abs() < 1e-15);
    let r_hand = 0.5 / (2.0 * a_hand - a_hand * a_hand / 2.0f64.sqrt());
    assert!((r - r_hand).abs() < 1e-14);
    assert!((r - 0.952_151_953_765_724_8).abs() < 1e-12, "{r}");
    // o = 0.8, N = 3 (by hand: α' = 1 − 0.2^(1/3); the 6-term sum).
    let (a, r) = relocation(0.8, 3);
    assert!((a - 0.415_196_452_357_426_86).abs() < 1e-14, "{a}");
    assert!((r - 0.868_410_996_819_837_6).abs() < 1e-12, "{r}");
}

#[test]
fn copies_composite_to_the_original_opacity() {
    for n in 1..=N_MAX {
        for o in [0.01, 0.3, 0.9, 0.999] {
            let (a, _) = relocation(o, n);
            let composite = 1.0 - (1.0 - a).powi(n as i32);
            assert!((composite - o).abs() < 1e-12, "n={n} o={o}: {composite}");
        }
    }
    // Beyond N_MAX the count is clamped (as gsplat).
    assert_eq!(relocation(0.5, 200), relocation(0.5, N_MAX));
}

/// The scale ratio preserves ∫ of the composited 1-D profile: N copies of
/// α'·g(x/σ') composited front to back integrate like o·g(x/σ).
#[test]
fn scale_ratio_preserves_integrated_profile() {
    for n in [1usize, 2, 3, 5, 10, 30] {
        for o in [0.1, 0.6, 0.95] {
            let (a, r) = relocation(o, n);
            let (sigma, sigma_new) = (1.0f64, r);
            let steps = 200_000;
            let lim = 12.0 * sigma.max(sigma_new);
            let dx = 2.0 * lim / steps as f64;
            let mut lhs = 0.0;
            let mut rhs = 0.0;
            for s in 0..=steps {
                let x = -lim + s as f64 * dx;
                let w = if s == 0 || s == steps { 0.5 } else { 1.0 };
                let g_new = (-0.5 * (x / sigma_new).powi(2)).exp();
                lhs += w * (1.0 - (1.0 - a * g_new).powi(n as i32)) * dx;
                rhs += w * o * (-0.5 * (x / sigma).powi(2)).exp() * dx;
            }
            assert!(
                ((lhs - rhs) / rhs).abs() < 1e-6,
                "n={n} o={o}: {lhs} vs {rhs}"
            );
        }
    }
}

fn state(opacities: &[f32]) -> ModelState {
    let n = opacities.len();
    let splats = Splats {
        means: (0..n).map(|i| [i as f32, 0.5 * i as f32, 1.0]).collect(),
        log_scales: (0..n).map(|i| [-2.0 - 0.01 * i as f32; 3]).collect(),
        rotations: (0..n).map(|i| [1.0, 0.1 * i as f32, 0.0, 0.0]).collect(),
        opacity_logits: opacities.iter().map(|&o| logit(o)).collect(),
        sh: (0..n * 12).map(|k| k as f32 * 0.01).collect(),
        sh_degree: 1,
    };
    let mut adam = AdamState::zeros_like(&splats);
    for m in [&mut adam.m, &mut adam.v] {
        m.means.iter_mut().for_each(|v| *v = [1.0; 3]);
        m.log_scales.iter_mut().for_each(|v| *v = [1.0; 3]);
        m.opacity_logits.iter_mut().for_each(|v| *v = 1.0);
        m.sh.iter_mut().for_each(|v| *v = 1.0);
    }
    ModelState {
        stats: DensifyStats::zeros(n),
        splats,
        adam,
    }
}

#[test]
fn relocation_moves_dead_onto_live_and_keeps_opacity() {
    let ops = [0.9, 0.001, 0.6, 0.004, 0.002, 0.3, 0.0045];
    let mut st = state(&ops);
    let before = st.splats.clone();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    let moved = relocate(&mut st, 0.005, &mut rng);
    assert_eq!(moved, 4);
    let live = [0usize, 2, 5];
    // Every dead slot now holds an exact copy of a (corrected) live source.
    let mut copies = [0usize; 7];
    for d in [1usize, 3, 4, 6] {
        let s = *live
            .iter()
            .find(|&&s| st.splats.means[s] == st.splats.means[d])
            .expect("dead splat not moved onto a live one");
        assert_eq!(st.splats.log_scales[d], st.splats.log_scales[s]);
        assert_eq!(st.splats.rotations[d], st.splats.rotations[s]);
        assert_eq!(st.splats.opacity_logits[d], st.splats.opacity_logits[s]);
        assert_eq!(
            st.splats.sh[d * 12..d * 12 + 12],
            st.splats.sh[s * 12..s * 12 + 12]
        );
        copies[s] += 1;
        assert_eq!(st.adam.m.means[d], [0.0; 3]);
        assert_eq!(st.adam.v.opacity_logits[d], 0.0);
        assert!(st.adam.m.sh[d * 12..d * 12 + 12].iter().all(|&v| v == 0.0));
    }
    for &s in &live {
        if copies[s] == 0 {
            assert_eq!(st.splats.opacity_logits[s], before.opacity_logits[s]);
            assert_eq!(st.adam.m.means[s], [1.0; 3], "untouched moments kept");
            continue;
        }
        // The source and its copies composite to the source's old opacity,
        // and their scales shrank by the formula's ratio.
        let n = copies[s] + 1;
        let a = sigmoid(st.splats.opacity_logits[s]) as f64;
        let composite = 1.0 - (1.0 - a).powi(n as i32);
        assert!(
            (composite - ops[s] as f64).abs() < 1e-5,
            "{composite} vs {}",
            ops[s]
        );
        let (_, ratio) = relocation(ops[s] as f64, n);
        let got = (st.splats.log_scales[s][0] - before.log_scales[s][0]).exp() as f64;
        assert!((got - ratio).abs() < 1e-5, "{got} vs {ratio}");
        assert_eq!(st.adam.m.means[s], [0.0; 3]);
        assert_eq!(st.adam.v.log_scales[s], [0.0; 3]);
    }
    // Same seed, same result.
    let mut again = state(&ops);
    relocate(&mut again, 0.005, &mut rand_pcg::Pcg64::seed_from_u64(5));
    assert_eq!(again.splats, st.splats);
}

#[test]
fn relocation_samples_proportional_to_opacity() {
    let mut ops = vec![0.001f32; 4000];
    ops[0] = 0.8;
    ops[1] = 0.2;
    let st0 = state(&ops);
    let mut st = st0.clone();
    relocate(&mut st, 0.005, &mut rand_pcg::Pcg64::seed_from_u64(9));
    let on0 = (2..4000)
        .filter(|&i| st.splats.means[i] == st0.splats.means[0])
        .count();
    let frac = on0 as f64 / 3998.0;
    assert!((frac - 0.8).abs() < 0.03, "{frac}");
}

#[test]
fn growth_is_five_percent_up_to_the_cap() {
    let ops: Vec<f32> = (0..100).map(|i| 0.1 + 0.008 * i as f32).collect();
    for (cap, want) in [(1_000, 105), (102, 102), (100, 100), (50, 100)] {
        let mut st = state(&ops);
        let added = grow(
            &mut st,
            cap,
            0.05,
            0.005,
            &mut rand_pcg::Pcg64::seed_from_u64(1),
        );
        assert_eq!(st.splats.len(), want, "cap {cap}");
        assert_eq!(added, want - 100);
        assert_eq!(st.adam.m.len(), want);
        assert_eq!(st.stats.count.len(), want);
        for i in 100..want {
            assert_eq!(st.adam.m.means[i], [0.0; 3]);
            assert_eq!(st.adam.v.opacity_logits[i], 0.0);
            let src = (0..100)
                .find(|&s| st.splats.means[s] == st.splats.means[i])
                .expect("new splat is a copy");
            assert_eq!(st.splats.opacity_logits[i], st.splats.opacity_logits[src]);
            assert_eq!(st.adam.m.means[src], [0.0; 3], "source moments reset");
        }
    }
}

#[test]
fn schedule_and_noise_follow_the_options() {
    let s = McmcStrategy::default();
    assert!(!s.wants_refine(500));
    assert!(s.wants_refine(600));
    assert!(!s.wants_refine(650));
    assert!(s.wants_refine(24_900));
    assert!(!s.wants_refine(25_000));
    let n = s.means_noise(10, 1.6e-4, 77).unwrap();
    assert!((n.scale - 5e5 * 1.6e-4).abs() < 1e-3);
    assert_eq!((n.k, n.t), (100.0, 0.005));
    assert_eq!(
        s.regularization(),
        Regularization {
            opacity: 0.01,
            scale: 0.01
        }
    );
    assert!(McmcStrategyOptions::default().validate().is_ok());
    let bad = McmcStrategyOptions {
        min_opacity: 0.0,
        ..Default::default()
    };
    assert!(bad.validate().is_err());
}
