//! Known-answer geometry: correspondences generated from known cameras must
//! give back the fundamental matrix (exact, noisy, 50% outliers), and a
//! pure rotation must be recognised as a homography.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use romo::geometry::Pt;
use romo::geometry::fundamental::{eight_point, sampson_px, seven_point};
use romo::geometry::robust::{
    ModelSelection, RobustOptions, TwoView, fit_two_view, fit_two_view_all,
};

fn k() -> Matrix3<f64> {
    Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0)
}

fn skew(t: Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -t[2], t[1], t[2], 0.0, -t[0], -t[1], t[0], 0.0)
}

/// Camera a = [I|0], camera b = [R|t]. Returns (a, b, F_true).
fn scene(n: usize, rot_only: bool, seed: u64) -> (Vec<Pt>, Vec<Pt>, Matrix3<f64>) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let r = Rotation3::from_euler_angles(0.02, -0.05, 0.01).into_inner();
    let t = if rot_only {
        Vector3::zeros()
    } else {
        Vector3::new(0.3, 0.05, 0.02)
    };
    let kk = k();
    let ki = kk.try_inverse().unwrap();
    let f = ki.transpose() * skew(t) * r * ki;
    let (mut a, mut b) = (vec![], vec![]);
    while a.len() < n {
        let x: f64 = rng.random_range(0.0..640.0);
        let y: f64 = rng.random_range(0.0..480.0);
        let z: f64 = rng.random_range(2.0..10.0);
        let p = ki * Vector3::new(x, y, 1.0) * z;
        let q = kk * (r * p + t);
        let (u, v) = (q[0] / q[2], q[1] / q[2]);
        if (0.0..640.0).contains(&u) && (0.0..480.0).contains(&v) {
            a.push([x, y]);
            b.push([u, v]);
        }
    }
    (a, b, f / f.norm())
}

fn same_up_to_scale(f: &Matrix3<f64>, g: &Matrix3<f64>) -> f64 {
    let (f, g) = (f / f.norm(), g / g.norm());
    (f - g).norm().min((f + g).norm())
}

#[test]
fn eight_point_recovers_exact_f() {
    let (a, b, ft) = scene(50, false, 1);
    let f = eight_point(&a, &b).unwrap();
    assert!(same_up_to_scale(&f, &ft) < 1e-6, "{f} vs {ft}");
    for (p, q) in a.iter().zip(&b) {
        assert!(sampson_px(&f, *p, *q) < 1e-6);
    }
}

#[test]
fn seven_point_has_the_true_solution() {
    let (a, b, ft) = scene(7, false, 2);
    let sols = seven_point(&a, &b);
    assert!(!sols.is_empty() && sols.len() <= 3);
    let best = sols
        .iter()
        .map(|f| same_up_to_scale(f, &ft))
        .fold(f64::INFINITY, f64::min);
    assert!(best < 1e-6, "best distance {best}");
    for f in &sols {
        assert!(f.determinant().abs() < 1e-8, "rank 2");
    }
}

#[test]
fn lmeds_with_noise_and_half_outliers() {
    let (mut a, mut b, ft) = scene(400, false, 3);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(9);
    for i in 0..a.len() {
        if i % 2 == 0 {
            // Outlier: random displacement up to 40 px.
            b[i][0] += rng.random_range(-40.0..40.0);
            b[i][1] += rng.random_range(-40.0..40.0);
        } else {
            a[i][0] += rng.random_range(-0.5..0.5);
            b[i][1] += rng.random_range(-0.5..0.5);
        }
    }
    let o = RobustOptions {
        selection: ModelSelection::Fundamental,
        ..Default::default()
    };
    let (m, rep) = fit_two_view(&a, &b, &o).unwrap();
    let TwoView::Fundamental(f) = m else {
        panic!("expected F")
    };
    // The F is close to the truth when measured on noise-free points.
    let (ca, cb, _) = scene(200, false, 3);
    let mut e: Vec<f64> = ca
        .iter()
        .zip(&cb)
        .map(|(p, q)| sampson_px(&f, *p, *q))
        .collect();
    e.sort_by(|x, y| x.total_cmp(y));
    assert!(
        e[e.len() / 2] < 0.3,
        "median Sampson on clean points {}",
        e[e.len() / 2]
    );
    assert!(same_up_to_scale(&f, &ft) < 0.05);
    assert!(
        rep.inliers >= 180 && rep.inliers <= 230,
        "inliers {}",
        rep.inliers
    );
    assert!(rep.median_residual_px < 5.0);
}

#[test]
fn pure_rotation_selects_homography_and_translation_selects_f() {
    // Both the default rule (inlier ratio) and GRIC: H for a pure rotation,
    // F for a translation with depth variation.
    let gric = RobustOptions {
        selection: ModelSelection::Gric,
        ..Default::default()
    };
    for o in [RobustOptions::default(), gric] {
        let (a, b, _) = scene(300, true, 4);
        let (m, rep) = fit_two_view(&a, &b, &o).unwrap();
        assert!(matches!(m, TwoView::Homography(_)), "rotation: {rep:?}");
        let (a, b, _) = scene(300, false, 5);
        let (m, rep) = fit_two_view(&a, &b, &o).unwrap();
        assert!(matches!(m, TwoView::Fundamental(_)), "translation: {rep:?}");
        if o.selection == ModelSelection::Gric {
            assert!(rep.gric_f < rep.gric_h, "{rep:?}");
        }
    }
    assert_eq!(
        RobustOptions::default().selection,
        ModelSelection::InlierRatio
    );
    let (a, b, _) = scene(300, true, 6);
    assert!(matches!(
        fit_two_view(&a, &b, &RobustOptions::default()).unwrap().0,
        TwoView::Homography(_)
    ));
    // A ratio above 1 is rejected.
    let bad = RobustOptions {
        h_inlier_ratio: 1.5,
        ..Default::default()
    };
    assert!(fit_two_view(&a, &b, &bad).is_err());
}

#[test]
fn fit_two_view_all_also_returns_the_fundamental_fit() {
    // Translation: F is chosen, and the returned F is the chosen model and
    // recovers the true F. Rotation: H is chosen, F is still returned and
    // fits the (degenerate) data; `Homography` forces H even with parallax.
    let o = RobustOptions::default();
    let (a, b, ft) = scene(300, false, 5);
    let fits = fit_two_view_all(&a, &b, &o).unwrap();
    assert_eq!(fits.chosen, fits.fundamental);
    let TwoView::Fundamental(f) = fits.fundamental else {
        panic!("not F")
    };
    assert!(same_up_to_scale(&f, &ft) < 1e-3, "{f} vs {ft}");
    assert_eq!(fits.fundamental_report.model, "F");
    let (a, b, _) = scene(300, true, 4);
    let fits = fit_two_view_all(&a, &b, &o).unwrap();
    assert!(matches!(fits.chosen, TwoView::Homography(_)));
    assert!(matches!(fits.fundamental, TwoView::Fundamental(_)));
    assert!(fits.fundamental_report.median_residual_px < 1e-3);
    let (a, b, _) = scene(300, false, 5);
    let forced = RobustOptions {
        selection: ModelSelection::Homography,
        ..Default::default()
    };
    let fits = fit_two_view_all(&a, &b, &forced).unwrap();
    assert!(matches!(fits.chosen, TwoView::Homography(_)));
    assert!(fits.report.median_residual_px > 0.5, "{:?}", fits.report);
}

#[test]
fn too_few_points_is_an_error() {
    let a = vec![[0.0, 0.0]; 5];
    assert!(fit_two_view(&a, &a, &RobustOptions::default()).is_err());
}
