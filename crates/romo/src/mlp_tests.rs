//! Tests of the MLP: Geman–McClure and full-loss gradients against central
//! finite differences, and training on separable toy problems.
#![allow(clippy::needless_range_loop)]

use super::*;

#[test]
fn gm_gradient_matches_finite_difference() {
    for &x in &[-0.7, -0.05, 0.0, 0.03, 0.1, 0.5, 2.0] {
        let e = 1e-6;
        let fd = (gm(x + e, 0.01) - gm(x - e, 0.01)) / (2.0 * e);
        assert!(
            (fd - gm_grad(x, 0.01)).abs() < 1e-6 * (1.0 + fd.abs()),
            "x={x}"
        );
    }
    // Saturates: κ(∞) → 1, κ(τ) = 1/2.
    assert!((gm(0.1, 0.01) - 0.5).abs() < 1e-12);
    assert!(gm(100.0, 0.01) > 0.9999);
}

fn toy(n: usize, c: usize, seed: u64) -> (Vec<f32>, Vec<Label>) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut x = Vec::with_capacity(n * c);
    let mut l = Vec::with_capacity(n);
    for _ in 0..n {
        let row: Vec<f32> = (0..c).map(|_| rng.random_range(-1.0..1.0)).collect();
        // Moving when the first two features sum above 0.3; imbalanced
        // (about a fifth moving) on purpose.
        let moving = row[0] + row[1] > 0.6;
        x.extend_from_slice(&row);
        l.push(if moving { Label::Moving } else { Label::Static });
    }
    (x, l)
}

#[test]
fn loss_gradient_matches_finite_difference() {
    let c = 5;
    let (x, l) = toy(64, c, 1);
    // A weak Lipschitz bound so that normalisation is active on some rows,
    // and a strong penalty weight so its gradient matters.
    let mut m = Mlp::new(c, 3);
    let n = m.n_params();
    m.p[n - 2] -= 0.7;
    m.p[n - 1] -= 0.3;
    let o = MlpOptions {
        lipschitz_weight: 0.05,
        tau_sq: 0.25,
        ..Default::default()
    };
    let (_, g) = m.loss_grad(&x, &l, &o);
    let e = 1e-6;
    for i in 0..n {
        let mut a = m.clone();
        a.p[i] += e;
        let mut b = m.clone();
        b.p[i] -= e;
        let fd = (a.loss_grad(&x, &l, &o).0 - b.loss_grad(&x, &l, &o).0) / (2.0 * e);
        // Tolerance: f32 features, f64 arithmetic; measured differences are
        // ~1e-9, kinks (ReLU, |w|) are not hit at this seed.
        assert!(
            (fd - g[i]).abs() < 1e-5 * (1.0 + fd.abs()),
            "param {i}: analytic {} vs fd {fd}",
            g[i]
        );
    }
}

#[test]
fn separates_an_imbalanced_separable_toy_problem() {
    let c = 4;
    let (x, l) = toy(4000, c, 2);
    // The balanced loss (moving_weight 1) on a separable problem; the
    // default 0.35 trades moving recall for precision on real video.
    let o = MlpOptions {
        batch_size: 512,
        moving_weight: 1.0,
        ..Default::default()
    };
    let mut m = Mlp::new(c, 7);
    let rep = train(&mut m, &x, &l, 25, true, &o, 11);
    assert!(!rep.collapsed, "{rep:?}");
    assert!(rep.recall_moving > 0.9, "{rep:?}");
    assert!(rep.recall_static > 0.9, "{rep:?}");
    assert!(rep.loss.last().unwrap() < &rep.loss[0]);
}

#[test]
fn without_annealing_the_literal_kernel_collapses() {
    // Documents why `tau_sq_start` exists: the same problem, τ² = 0.01 from
    // the start, ends with (nearly) nothing called moving.
    let c = 4;
    let (x, l) = toy(4000, c, 2);
    let o = MlpOptions {
        batch_size: 512,
        ..Default::default()
    };
    let mut m = Mlp::new(c, 7);
    let rep = train(&mut m, &x, &l, 25, false, &o, 11);
    assert!(rep.recall_moving < 0.5, "{rep:?}");
}

#[test]
fn collapse_is_detected() {
    // A net with a huge negative output bias calls everything static.
    let c = 3;
    let (x, l) = toy(500, c, 4);
    let mut m = Mlp::new(c, 1);
    let nb = HIDDEN * c + 2 * HIDDEN;
    m.p[nb] = -50.0;
    let o = MlpOptions::default();
    let r = train(&mut m, &x, &l, 0, false, &o, 0);
    assert!(r.collapsed, "{r:?}");
}

/// The loss and gradient are the same bits whatever the thread count, so a
/// seeded run is reproducible (the partial sums are over fixed chunks,
/// added in order; rayon's adaptive split of a plain parallel reduction
/// made repeated DAVIS runs differ by up to 0.04 J per sequence).
#[test]
fn loss_gradient_does_not_depend_on_the_thread_count() {
    let c = 16;
    let (x, y) = toy(5 * GRAD_CHUNK + 123, c, 11);
    let m = Mlp::new(c, 5);
    let o = MlpOptions::default();
    let in_pool = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| m.loss_grad(&x, &y, &o))
    };
    let (l1, g1) = in_pool(1);
    for threads in [2, 3, 5] {
        let (l, g) = in_pool(threads);
        assert_eq!(l.to_bits(), l1.to_bits(), "{threads} threads");
        assert!(
            g.iter().zip(&g1).all(|(a, b)| a.to_bits() == b.to_bits()),
            "{threads} threads"
        );
    }
}

/// The hidden layer computed for all units at once gives the bits of each
/// unit's row summed on its own, as the network's forward pass defines it.
#[test]
fn hidden_pre_equals_row_sums() {
    let c = 16;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    let w1: Vec<f64> = (0..HIDDEN * c)
        .map(|_| rng.random_range(-2.0..2.0))
        .collect();
    let b1: Vec<f64> = (0..HIDDEN).map(|_| rng.random_range(-1.0..1.0)).collect();
    let w1t = transpose_hidden(&w1, c);
    for _ in 0..200 {
        let xi: Vec<f32> = (0..c).map(|_| rng.random_range(-3.0..3.0)).collect();
        let z = hidden_pre(&w1t, &b1, &xi);
        for j in 0..HIDDEN {
            let row = &w1[j * c..(j + 1) * c];
            let want = b1[j] + row.iter().zip(&xi).map(|(w, v)| w * *v as f64).sum::<f64>();
            assert_eq!(z[j].to_bits(), want.to_bits(), "unit {j}");
        }
    }
}

/// One start is plain training of `Mlp::new(c, init_seed)`; several keep
/// the start whose last epoch has the lowest loss, and that is the lowest
/// of the starts trained one by one.
#[test]
fn restarts_keep_the_start_with_the_lowest_final_loss() {
    let c = 4;
    let (x, l) = toy(1500, c, 5);
    // Every start fits, so the choice is by loss alone.
    let mut o = MlpOptions {
        batch_size: 256,
        min_fit_recall: 0.0,
        // The raised-weight trial has its own test.
        raised_moving_weight: 0.0,
        ..Default::default()
    };
    let (one, r1) = train_restarts(c, &x, &l, 6, &o, 3, 9);
    let mut plain = Mlp::new(c, 3);
    let rp = train(&mut plain, &x, &l, 6, true, &o, 9);
    assert_eq!(one.p, plain.p);
    assert_eq!(r1.loss, rp.loss);

    o.restarts = 4;
    let (best, rb) = train_restarts(c, &x, &l, 6, &o, 3, 9);
    let finals: Vec<f64> = (0..4u64)
        .map(|j| {
            let mut m = Mlp::new(c, 3 ^ (j << 40));
            *train(&mut m, &x, &l, 6, true, &o, 9 ^ (j << 40))
                .loss
                .last()
                .unwrap()
        })
        .collect();
    let min = finals.iter().copied().fold(f64::INFINITY, f64::min);
    assert_eq!(*rb.loss.last().unwrap(), min, "{finals:?}");
    // The starts differ, so the choice is a real one.
    assert!(finals.iter().any(|f| *f != finals[0]), "{finals:?}");
    assert_eq!(best.predict(&x), {
        let j = finals.iter().position(|f| *f == min).unwrap() as u64;
        let mut m = Mlp::new(c, 3 ^ (j << 40));
        train(&mut m, &x, &l, 6, true, &o, 9 ^ (j << 40));
        m.predict(&x)
    });
    o.restarts = 0;
    assert!(o.validate().is_err());
}

/// A first start that fits too little of U is replaced: the extra starts
/// are trained, and the kept one is the lowest-loss start among those that
/// fit, or among all when none fits. A first start that fits is kept
/// without training any other.
#[test]
fn a_first_start_that_does_not_fit_u_is_replaced() {
    let c = 4;
    let (x, l) = toy(1500, c, 5);
    let mut o = MlpOptions {
        batch_size: 256,
        refit_starts: 3,
        // The raised-weight trial has its own test.
        raised_moving_weight: 0.0,
        ..Default::default()
    };
    // Two epochs leave the starts at different recalls of U.
    let reports: Vec<TrainReport> = (0..4u64)
        .map(|j| {
            train(
                &mut Mlp::new(c, 3 ^ (j << 40)),
                &x,
                &l,
                2,
                true,
                &o,
                9 ^ (j << 40),
            )
        })
        .collect();
    let recall: Vec<f64> = reports.iter().map(|r| r.recall_moving).collect();
    let last = |j: usize| *reports[j].loss.last().unwrap();
    let top = recall[1..].iter().copied().fold(0.0, f64::max);
    assert!(top > recall[0], "no later start fits more of U: {recall:?}");

    // Start 0 fits: it is kept as plain training would leave it.
    o.min_fit_recall = recall[0];
    let (kept, r) = train_restarts(c, &x, &l, 2, &o, 3, 9);
    assert_eq!((&r.loss, r.starts), (&reports[0].loss, 1));
    let mut plain = Mlp::new(c, 3);
    train(&mut plain, &x, &l, 2, true, &o, 9);
    assert_eq!(kept.p, plain.p);

    // Start 0 does not fit: the lowest loss among the starts that do.
    o.min_fit_recall = (recall[0] + top) / 2.0;
    let fitting: Vec<usize> = (1..4).filter(|j| recall[*j] >= o.min_fit_recall).collect();
    let want = fitting
        .iter()
        .copied()
        .min_by(|a, b| last(*a).total_cmp(&last(*b)))
        .unwrap();
    let (_, r) = train_restarts(c, &x, &l, 2, &o, 3, 9);
    assert_eq!(r.loss, reports[want].loss, "recalls {recall:?}");
    assert_eq!(r.starts, 4);

    // None fits: the lowest loss among all four.
    o.min_fit_recall = 1.0;
    assert!(recall.iter().all(|r| *r < 1.0), "{recall:?}");
    let want = (0..4).min_by(|a, b| last(*a).total_cmp(&last(*b))).unwrap();
    let (_, r) = train_restarts(c, &x, &l, 2, &o, 3, 9);
    assert_eq!(r.loss, reports[want].loss);
    o.min_fit_recall = 1.5;
    assert!(o.validate().is_err());
}

/// The AVX2 copies of the training and prediction kernels
/// (`simd::multiversion!`) compute the same bits as the baseline ones. On
/// a CPU without AVX2 both runs take the baseline path.
#[test]
fn avx2_and_baseline_kernels_agree_bit_for_bit() {
    let c = 16;
    let (x, l) = toy(3000, c, 8);
    let o = MlpOptions {
        batch_size: 256,
        moving_weight: 1.0,
        ..Default::default()
    };
    let run = |baseline: bool| {
        crate::flow::simd::force_baseline(baseline);
        let mut m = Mlp::new(c, 4);
        let r = train(&mut m, &x, &l, 25, true, &o, 2);
        let h = m.predict(&x);
        crate::flow::simd::force_baseline(false);
        (m, r, h)
    };
    let (mb, rb, hb) = run(true);
    let (mf, rf, hf) = run(false);
    let bits = |v: &[f64]| v.iter().map(|a| a.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&mb.p), bits(&mf.p));
    assert_eq!(bits(&rb.loss), bits(&rf.loss));
    assert!(hb.iter().zip(&hf).all(|(a, b)| a.to_bits() == b.to_bits()));
    // Not a trivial net: it has learnt the toy rule.
    assert!(rf.recall_moving > 0.8 && rf.recall_static > 0.8, "{rf:?}");
}

/// Toy samples whose U is relabelled static samples far from the toy's
/// boundary (`x0 < −0.5`, half of them): U in two clusters.
fn two_cluster_u(n: usize, c: usize, seed: u64) -> (Vec<f32>, Vec<Label>) {
    let (x, mut l) = toy(n, c, seed);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    for i in 0..l.len() {
        if l[i] == Label::Static && x[i * c] < -0.5 && rng.random_range(0.0..1.0) < 0.5 {
            l[i] = Label::Moving;
        }
    }
    (x, l)
}

/// The first round trains start 0 again at `raised_moving_weight` and keeps
/// it only when its error rate under the base weight is lower. Two U
/// clusters: the base weight gives up U, the raised one fits it and is
/// kept. One cluster: the base weight fits most of U, the raised one buys
/// the rest with more L than the base weight pays for, and is not kept.
#[test]
fn a_raised_u_weight_is_kept_only_when_it_errs_less_under_the_base_weight() {
    let c = 4;
    let o = MlpOptions {
        batch_size: 256,
        ..Default::default()
    };
    let raised = MlpOptions {
        moving_weight: o.raised_moving_weight,
        ..o.clone()
    };
    for (data, want_kept) in [(two_cluster_u(3000, c, 5), true), (toy(3000, c, 5), false)] {
        let (x, l) = data;
        let (kept, r) = train_restarts(c, &x, &l, 10, &o, 3, 9);
        let mut by_hand = Mlp::new(c, 3);
        let rr = train(&mut by_hand, &x, &l, 10, true, &raised, 9);
        let t = r.weight_trial.clone().expect("the trial runs");
        assert_eq!(t.raised_recall, (rr.recall_moving, rr.recall_static));
        assert_eq!(t.raised_error, error_rate(&rr, o.moving_weight));
        assert_eq!(t.raised_kept, want_kept, "{t:?}");
        assert_eq!(
            t.raised_kept,
            t.raised_error < t.base_error && t.z >= o.trial_significance
        );

        if want_kept {
            assert_eq!(kept.p, by_hand.p);
            assert_eq!(r.moving_weight, o.raised_moving_weight);
            assert!(t.raised_recall.0 > t.base_recall.0 + 0.3, "{t:?}");
        } else {
            assert_eq!(r.moving_weight, o.moving_weight);
            assert!(t.raised_recall.1 < t.base_recall.1, "{t:?}");
        }
        // The base weight's starts (refits when start 0 does not fit U)
        // and the trial.
        let base_starts = if t.base_recall.0 >= o.min_fit_recall {
            1
        } else {
            1 + o.refit_starts
        };
        assert_eq!(r.starts, base_starts + 1);
    }
    // 0 turns the trial off.
    let (x, l) = toy(3000, c, 5);
    let off = MlpOptions {
        raised_moving_weight: 0.0,
        ..o
    };
    let (_, r) = train_restarts(c, &x, &l, 10, &off, 3, 9);
    assert!(r.weight_trial.is_none());
    assert_eq!(r.starts, 1);
}

/// A lower error within the sampling noise is a tie, and a tie keeps the
/// base weight: DAVIS parkour's near-tie (0.1364 against 0.1361 over 45 030
/// U and 159 770 L samples) is not a reason to switch.
#[test]
fn a_raised_u_weight_within_the_noise_is_not_kept() {
    let o = MlpOptions::default();
    let report = |u: f64, l: f64, n: usize| TrainReport {
        samples_moving: n,
        samples_static: 4 * n,
        recall_moving: u,
        recall_static: l,
        ..Default::default()
    };
    // error = 0.35·(1 − U) + (1 − L).
    let base = report(0.70, 0.970, 45_000);
    let near = report(0.71, 0.967, 45_000);
    let t = weight_trial(&base, &near, &o);
    assert!(t.raised_error < t.base_error, "{t:?}");
    assert!(t.z > 0.0 && t.z < 1.0, "{t:?}");
    assert!(!t.raised_kept);
    // The same gap over 100 times the samples is significant.
    let t = weight_trial(
        &report(0.70, 0.970, 4_500_000),
        &report(0.71, 0.967, 4_500_000),
        &o,
    );
    assert!(t.z > 2.0 && t.raised_kept, "{t:?}");
    // 0 keeps any lower error, as before.
    let any = MlpOptions {
        trial_significance: 0.0,
        ..o.clone()
    };
    assert!(weight_trial(&base, &near, &any).raised_kept);
    // A clear gain (the composites': U 0.59 → 0.77 for L 0.966 → 0.925).
    let t = weight_trial(
        &report(0.59, 0.966, 30_000),
        &report(0.77, 0.925, 30_000),
        &o,
    );
    assert!(t.z > 5.0 && t.raised_kept, "{t:?}");
    // Perfect fits on both sides: no noise, finite z.
    let t = weight_trial(&report(1.0, 1.0, 10), &report(1.0, 1.0, 10), &o);
    assert!(t.z == 0.0 && !t.raised_kept, "{t:?}");
}
