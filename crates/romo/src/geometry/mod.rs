//! Stages 3–5 of RoMo: robust two-view geometry per adjacent frame pair.
//!
//! - [`fundamental`]: 7- and 8-point solvers and the Sampson distance;
//! - [`homography`]: the normalised DLT and its transfer error, for pairs
//!   with little parallax (pure rotation, distant scenes), where F is
//!   ill-conditioned and absorbs moving objects (our addition to the paper);
//! - [`oriented`]: a cheirality test that flags points moving along their
//!   epipolar lines in a way only a point behind the cameras could (ours);
//! - [`robust`]: Least-Median-of-Squares search over minimal samples (the
//!   paper's choice, which beat RANSAC in our prototype), seeded, with a
//!   report struct, and GRIC model selection (Torr 1998) between F and H.

pub mod fundamental;
pub mod homography;
pub mod oriented;
pub mod robust;

use nalgebra::{Matrix3, SMatrix, SVector};

/// A 2-D point in pixels.
pub type Pt = [f64; 2];

/// Hartley normalisation: a similarity moving the centroid to the origin
/// and the mean distance to √2. Returns the transform and the moved points.
pub fn normalise(p: &[Pt]) -> (Matrix3<f64>, Vec<Pt>) {
    let n = p.len().max(1) as f64;
    let cx = p.iter().map(|q| q[0]).sum::<f64>() / n;
    let cy = p.iter().map(|q| q[1]).sum::<f64>() / n;
    let md = p
        .iter()
        .map(|q| ((q[0] - cx).powi(2) + (q[1] - cy).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    let s = if md > 1e-12 {
        std::f64::consts::SQRT_2 / md
    } else {
        1.0
    };
    let t = Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0);
    let q = p
        .iter()
        .map(|q| [s * (q[0] - cx), s * (q[1] - cy)])
        .collect();
    (t, q)
}

/// The two eigenvectors of `AᵀA` with the smallest eigenvalues (the best
/// and second-best null vectors of A), from the rows of A.
pub fn solve_nullspace(rows: &[SVector<f64, 9>]) -> Option<(SVector<f64, 9>, SVector<f64, 9>)> {
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for r in rows {
        ata += r * r.transpose();
    }
    if !ata.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eig = ata.symmetric_eigen();
    let mut idx: Vec<usize> = (0..9).collect();
    idx.sort_by(|a, b| eig.eigenvalues[*a].total_cmp(&eig.eigenvalues[*b]));
    Some((
        eig.eigenvectors.column(idx[0]).into_owned(),
        eig.eigenvectors.column(idx[1]).into_owned(),
    ))
}
