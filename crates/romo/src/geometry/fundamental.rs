//! Fundamental matrix: Hartley-normalised 8-point (least squares, rank 2
//! enforced) and 7-point (cubic on the 2-D null space) solvers (Hartley &
//! Zisserman, *Multiple View Geometry*, §11.1–11.2), and the Sampson
//! distance (H&Z eq. 11.9).
//!
//! Convention: `x_bᵀ F x_a = 0` for a correspondence (x_a in the first
//! frame, x_b in the second), pixel coordinates.
//!
//! **Units of the Sampson distance.** [`sampson_sq`] is the first-order
//! approximation of the squared geometric error, in px². RoMo's thresholds
//! compare it with the mean flow magnitude `v` (px); romo compares
//! [`sampson_px`] = √(sampson_sq), in px, so that `S > 2v` is unit-consistent
//! and invariant to image scale (halving the resolution halves both sides;
//! with px² the left side would quarter while the threshold halved).

use super::{Pt, normalise, solve_nullspace};
use nalgebra::{Matrix3, SVector, Vector3};

/// Squared Sampson distance of (a, b) under F, in px².
#[inline]
pub fn sampson_sq(f: &Matrix3<f64>, a: Pt, b: Pt) -> f64 {
    let xa = Vector3::new(a[0], a[1], 1.0);
    let xb = Vector3::new(b[0], b[1], 1.0);
    let fa = f * xa;
    let ftb = f.transpose() * xb;
    let num = xb.dot(&fa);
    let den = fa[0] * fa[0] + fa[1] * fa[1] + ftb[0] * ftb[0] + ftb[1] * ftb[1];
    if den <= 1e-300 {
        return f64::INFINITY;
    }
    num * num / den
}

/// Sampson distance in px (square root of [`sampson_sq`]).
#[inline]
pub fn sampson_px(f: &Matrix3<f64>, a: Pt, b: Pt) -> f64 {
    sampson_sq(f, a, b).sqrt()
}

fn design_row(a: Pt, b: Pt) -> SVector<f64, 9> {
    SVector::<f64, 9>::from_column_slice(&[
        b[0] * a[0],
        b[0] * a[1],
        b[0],
        b[1] * a[0],
        b[1] * a[1],
        b[1],
        a[0],
        a[1],
        1.0,
    ])
}

fn to_matrix(v: &SVector<f64, 9>) -> Matrix3<f64> {
    Matrix3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8])
}

fn rank2(f: Matrix3<f64>) -> Matrix3<f64> {
    let svd = f.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => {
            let mut s = svd.singular_values;
            s[2] = 0.0;
            u * Matrix3::from_diagonal(&s) * vt
        }
        _ => f,
    }
}

fn unit(f: Matrix3<f64>) -> Matrix3<f64> {
    let n = f.norm();
    if n > 0.0 { f / n } else { f }
}

/// Hartley normalisations `ta`, `tb` of both point sets and the design
/// rows of the normalised correspondences.
fn normalised_design(a: &[Pt], b: &[Pt]) -> (Matrix3<f64>, Matrix3<f64>, Vec<SVector<f64, 9>>) {
    let (ta, na) = normalise(a);
    let (tb, nb) = normalise(b);
    let rows = na
        .iter()
        .zip(&nb)
        .map(|(p, q)| design_row(*p, *q))
        .collect();
    (ta, tb, rows)
}

/// Normalised 8-point algorithm on ≥ 8 correspondences; `None` when
/// degenerate.
pub fn eight_point(a: &[Pt], b: &[Pt]) -> Option<Matrix3<f64>> {
    if a.len() < 8 || a.len() != b.len() {
        return None;
    }
    let (ta, tb, rows) = normalised_design(a, b);
    let (v, _) = solve_nullspace(&rows)?;
    let f = rank2(to_matrix(&v));
    let f = tb.transpose() * f * ta;
    f.iter().all(|x| x.is_finite()).then(|| unit(f))
}

/// Real roots of `c3 t³ + c2 t² + c1 t + c0` (handles lower degree).
fn cubic_roots(c3: f64, c2: f64, c1: f64, c0: f64) -> Vec<f64> {
    let scale = c3.abs().max(c2.abs()).max(c1.abs()).max(c0.abs());
    if scale == 0.0 {
        return vec![];
    }
    if c3.abs() < 1e-12 * scale {
        if c2.abs() < 1e-12 * scale {
            return if c1.abs() > 0.0 {
                vec![-c0 / c1]
            } else {
                vec![]
            };
        }
        let d = c1 * c1 - 4.0 * c2 * c0;
        if d < 0.0 {
            return vec![];
        }
        let s = d.sqrt();
        return vec![(-c1 + s) / (2.0 * c2), (-c1 - s) / (2.0 * c2)];
    }
    let (a, b, c) = (c2 / c3, c1 / c3, c0 / c3);
    // Depressed cubic t = y − a/3: y³ + p y + q = 0.
    let p = b - a * a / 3.0;
    let q = 2.0 * a * a * a / 27.0 - a * b / 3.0 + c;
    let disc = q * q / 4.0 + p * p * p / 27.0;
    let shift = -a / 3.0;
    if disc > 0.0 {
        let s = disc.sqrt();
        vec![(-q / 2.0 + s).cbrt() + (-q / 2.0 - s).cbrt() + shift]
    } else {
        let r = (-p / 3.0).max(0.0).sqrt();
        if r == 0.0 {
            return vec![shift];
        }
        let phi = (-q / (2.0 * r * r * r)).clamp(-1.0, 1.0).acos();
        (0..3)
            .map(|k| 2.0 * r * ((phi + 2.0 * std::f64::consts::PI * k as f64) / 3.0).cos() + shift)
            .collect()
    }
}

/// Normalised 7-point algorithm on exactly 7 correspondences: up to three
/// rank-2 solutions.
pub fn seven_point(a: &[Pt], b: &[Pt]) -> Vec<Matrix3<f64>> {
    if a.len() != 7 || b.len() != 7 {
        return vec![];
    }
    let (ta, tb, rows) = normalised_design(a, b);
    let Some((v1, v2)) = solve_nullspace(&rows) else {
        return vec![];
    };
    let (f1, f2) = (to_matrix(&v1), to_matrix(&v2));
    // det(t F1 + (1 − t) F2) is a cubic in t: fit it through 4 samples.
    let d = |t: f64| (f1 * t + f2 * (1.0 - t)).determinant();
    let (d0, d1, dm, d2) = (d(0.0), d(1.0), d(-1.0), d(2.0));
    // d(0) = c0, d(±1) = c0 + c2 ± (c1 + c3), d(2) = c0 + 4c2 + 2c1 + 8c3.
    let c0 = d0;
    let c2 = (d1 + dm) / 2.0 - c0;
    let c13 = (d1 - dm) / 2.0;
    let c3 = (d2 - 4.0 * c2 - c0 - 2.0 * c13) / 6.0;
    let c1 = c13 - c3;
    cubic_roots(c3, c2, c1, c0)
        .into_iter()
        .filter_map(|t| {
            let f = f1 * t + f2 * (1.0 - t);
            let f = tb.transpose() * f * ta;
            f.iter().all(|x| x.is_finite()).then(|| unit(f))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_roots_known() {
        // (t − 1)(t + 2)(t − 3) = t³ − 2t² − 5t + 6
        let mut r = cubic_roots(1.0, -2.0, -5.0, 6.0);
        r.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert!(
            (r[0] + 2.0).abs() < 1e-9 && (r[1] - 1.0).abs() < 1e-9 && (r[2] - 3.0).abs() < 1e-9
        );
        assert_eq!(cubic_roots(1.0, 0.0, 1.0, 0.0).len(), 1);
    }

    #[test]
    fn sampson_matches_hand_computation() {
        // F for a pure horizontal translation (x_b = x_a + t): F = [e']x with
        // e' = (1, 0, 0) → F = [[0,0,0],[0,0,-1],[0,1,0]].
        let f = Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
        // a = (10, 20), b = (15, 23): x_bᵀ F x_a = −y_b + y_a = −3.
        // F x_a = (0, −1, 20); Fᵀ x_b = (0, 1, −23)... den = 1 + 1 = 2.
        let s2 = sampson_sq(&f, [10.0, 20.0], [15.0, 23.0]);
        assert!((s2 - 9.0 / 2.0).abs() < 1e-12, "{s2}");
        assert!((sampson_px(&f, [10.0, 20.0], [15.0, 23.0]) - (4.5f64).sqrt()).abs() < 1e-12);
    }
}
