//! Homography by the normalised direct linear transform (Hartley &
//! Zisserman, Alg. 4.2) and its one-sided transfer error `|x_b − H x_a|`.
//! Used for low-parallax pairs (see [`super::robust::select_model`]).

use super::{Pt, normalise, solve_nullspace};
use nalgebra::{Matrix3, SVector, Vector3};

/// Normalised DLT on ≥ 4 correspondences (`x_b ~ H x_a`).
pub fn dlt(a: &[Pt], b: &[Pt]) -> Option<Matrix3<f64>> {
    if a.len() < 4 || a.len() != b.len() {
        return None;
    }
    let (ta, na) = normalise(a);
    let (tb, nb) = normalise(b);
    let mut rows = Vec::with_capacity(2 * a.len());
    for (p, q) in na.iter().zip(&nb) {
        let (x, y, u, v) = (p[0], p[1], q[0], q[1]);
        rows.push(SVector::<f64, 9>::from_column_slice(&[
            -x,
            -y,
            -1.0,
            0.0,
            0.0,
            0.0,
            u * x,
            u * y,
            u,
        ]));
        rows.push(SVector::<f64, 9>::from_column_slice(&[
            0.0,
            0.0,
            0.0,
            -x,
            -y,
            -1.0,
            v * x,
            v * y,
            v,
        ]));
    }
    let (h, _) = solve_nullspace(&rows)?;
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let tbi = tb.try_inverse()?;
    let hm = tbi * hn * ta;
    let s = hm[(2, 2)];
    if !s.is_finite() || s.abs() < 1e-12 || !hm.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(hm / s)
}

/// Squared transfer error `|x_b − H x_a|²` in px².
#[inline]
pub fn transfer_sq(h: &Matrix3<f64>, a: Pt, b: Pt) -> f64 {
    let p = h * Vector3::new(a[0], a[1], 1.0);
    if p[2].abs() < 1e-12 {
        return f64::INFINITY;
    }
    let (x, y) = (p[0] / p[2], p[1] / p[2]);
    (x - b[0]).powi(2) + (y - b[1]).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dlt_recovers_a_known_homography() {
        let h = Matrix3::new(1.1, 0.05, 12.0, -0.03, 0.95, -7.0, 1e-4, -2e-4, 1.0);
        let a: Vec<Pt> = (0..20)
            .map(|i| [(i * 37 % 300) as f64, (i * 53 % 200) as f64])
            .collect();
        let b: Vec<Pt> = a
            .iter()
            .map(|p| {
                let q = h * Vector3::new(p[0], p[1], 1.0);
                [q[0] / q[2], q[1] / q[2]]
            })
            .collect();
        let e = dlt(&a, &b).unwrap();
        assert!((e - h).norm() < 1e-6, "{e}");
        assert!(transfer_sq(&e, a[3], b[3]) < 1e-12);
    }
}
