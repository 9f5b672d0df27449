//! Cheirality test for moving points (ours, not in the paper): a point
//! whose flow lies on its epipolar line can still be impossible for a
//! static point, because the only static point that explains it lies
//! behind the cameras. This is the case of a pedestrian walking the way a
//! sideways-dollying camera moves, faster than it: the image motion
//! reverses, as for a static point at negative depth. Two-view projective
//! geometry (F, Sampson, even the oriented epipolar constraint of Werner &
//! Pajdla 2001, which is blind to points behind *both* cameras) cannot see
//! it; a metric reconstruction can.
//!
//! With a focal length (from the scene's intrinsics, else COLMAP's prior
//! 1.2 × the long side) and the principal point at the image centre, the
//! essential matrix `E = Kᵀ F K` is decomposed into its four (R, t)
//! (Hartley & Zisserman §9.6.2) and the one that puts the most fit points
//! in front of both cameras is kept. Each correspondence is then
//! triangulated in closed form: with rays `a = K⁻¹x`, `b = K⁻¹x'`,
//! `r = R a` and `c = b × r`, the depths are
//! `Z = −(b × t)·c / |c|²` (camera 1) and `Z' = (t × r)·c / |c|²`
//! (camera 2). A point with `Z < 0` or `Z' < 0` violates cheirality by
//! `f · sin∠(b, r)` px — its parallax, the distance its flow would have to
//! shrink for the point to sit at infinity, the nearest valid static point.
//! The sign of a depth does not depend on the focal length when the
//! rotation is small, so a guessed focal length serves.

use super::Pt;
use nalgebra::{Matrix3, Vector3};

/// A metric two-view geometry for cheirality tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oriented {
    r: Matrix3<f64>,
    t: Vector3<f64>,
    k_inv: Matrix3<f64>,
    focal_px: f64,
    /// Fraction of the voting fit points in front of both cameras under
    /// the chosen (R, t).
    pub support: f64,
}

/// Intrinsics with focal `f` px and principal point `(cx, cy)`.
pub fn intrinsics(f: f64, cx: f64, cy: f64) -> Matrix3<f64> {
    Matrix3::new(f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0)
}

impl Oriented {
    /// Decompose `F` with intrinsics `k` and pick (R, t) by cheirality
    /// votes of `a ↔ b` (the fit points; points with less than
    /// `min_parallax_px` of parallax do not vote). None when fewer than
    /// `min_votes` points vote or no decomposition puts at least
    /// `min_support` of the voters in front of both cameras (little
    /// translation: pure rotation, a distant scene).
    pub fn from_fundamental(
        f: &Matrix3<f64>,
        k: &Matrix3<f64>,
        a: &[Pt],
        b: &[Pt],
        vote: &VoteOptions,
    ) -> Option<Self> {
        let k_inv = k.try_inverse()?;
        let focal_px = 0.5 * (k[(0, 0)] + k[(1, 1)]);
        let e = k.transpose() * f * k;
        if !e.iter().all(|v| v.is_finite()) {
            return None;
        }
        let svd = e.svd(true, true);
        let (mut u, mut vt) = (svd.u?, svd.v_t?);
        if u.determinant() < 0.0 {
            u = -u;
        }
        if vt.determinant() < 0.0 {
            vt = -vt;
        }
        let w = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let t0: Vector3<f64> = u.column(2).into_owned();
        let mut best: Option<(usize, usize, Oriented)> = None;
        for r in [u * w * vt, u * w.transpose() * vt] {
            for t in [t0, -t0] {
                let cand = Oriented {
                    r,
                    t,
                    k_inv,
                    focal_px,
                    support: 0.0,
                };
                let (mut front, mut n) = (0, 0);
                for (p, q) in a.iter().zip(b) {
                    let d = cand.depths(*p, *q);
                    if d.parallax_px < vote.min_parallax_px {
                        continue;
                    }
                    n += 1;
                    front += usize::from(d.z1 > 0.0 && d.z2 > 0.0);
                }
                if best.as_ref().is_none_or(|(bf, _, _)| front > *bf) {
                    best = Some((front, n, cand));
                }
            }
        }
        let (front, voters, mut o) = best?;
        if voters < vote.min_votes {
            return None;
        }
        o.support = front as f64 / voters as f64;
        (o.support >= vote.min_support).then_some(o)
    }

    /// Depths of the triangulated point in both cameras and its parallax
    /// `f · sin∠(b, R a)` in px.
    pub fn depths(&self, a: Pt, b: Pt) -> Depths {
        let ra = self.r * (self.k_inv * Vector3::new(a[0], a[1], 1.0));
        let rb = self.k_inv * Vector3::new(b[0], b[1], 1.0);
        let c = rb.cross(&ra);
        let c2 = c.norm_squared();
        let norms = ra.norm() * rb.norm();
        if c2 <= 0.0 || norms <= 0.0 {
            return Depths {
                z1: f64::INFINITY,
                z2: f64::INFINITY,
                parallax_px: 0.0,
            };
        }
        Depths {
            z1: -rb.cross(&self.t).dot(&c) / c2,
            z2: self.t.cross(&ra).dot(&c) / c2,
            parallax_px: self.focal_px * c2.sqrt() / norms,
        }
    }

    /// Cheirality violation in px: the parallax of a correspondence whose
    /// triangulation lies behind either camera, 0 otherwise.
    pub fn violation_px(&self, a: Pt, b: Pt) -> f64 {
        let d = self.depths(a, b);
        if d.z1 < 0.0 || d.z2 < 0.0 {
            d.parallax_px
        } else {
            0.0
        }
    }
}

/// Triangulation of one correspondence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Depths {
    /// Depth in camera 1 (world units of |t| = 1).
    pub z1: f64,
    /// Depth in camera 2.
    pub z2: f64,
    /// Parallax angle × focal length (px).
    pub parallax_px: f64,
}

/// How the decomposition is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoteOptions {
    /// Points with less parallax do not vote (px).
    pub min_parallax_px: f64,
    /// Fewest voters for a decision.
    pub min_votes: usize,
    /// Least fraction of voters in front of both cameras.
    pub min_support: f64,
}

impl Default for VoteOptions {
    fn default() -> Self {
        VoteOptions {
            min_parallax_px: 0.5,
            min_votes: 50,
            min_support: 0.7,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// F = K⁻ᵀ [t]ₓ R K⁻¹ for x₂ = R x₁ + t.
    fn fundamental_from_rt(k: &Matrix3<f64>, r: &Matrix3<f64>, t: &Vector3<f64>) -> Matrix3<f64> {
        let ki = k.try_inverse().unwrap();
        ki.transpose() * t.cross_matrix() * r * ki
    }

    fn project(k: &Matrix3<f64>, r: &Matrix3<f64>, t: &Vector3<f64>, x: Vector3<f64>) -> Pt {
        let c = k * (r * x + t);
        [c[0] / c[2], c[1] / c[2]]
    }

    fn rot_y(a: f64) -> Matrix3<f64> {
        Matrix3::new(a.cos(), 0.0, a.sin(), 0.0, 1.0, 0.0, -a.sin(), 0.0, a.cos())
    }

    /// A sideways dolly with a small yaw; static points at 3–15 m; a
    /// "pedestrian" walking with the camera, faster than it.
    #[test]
    fn flags_points_moving_faster_than_the_camera_along_epipolar_lines() {
        let k = intrinsics(300.0, 160.0, 120.0);
        let (r, t) = (rot_y(0.01), Vector3::new(-0.1, 0.0, 0.0));
        let mut a = vec![];
        let mut b = vec![];
        let mut s = 1u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..400 {
            let z = 3.0 + 12.0 * rnd();
            let x = Vector3::new((rnd() - 0.5) * z, (rnd() - 0.5) * 0.75 * z, z);
            a.push(project(&k, &Matrix3::identity(), &Vector3::zeros(), x));
            b.push(project(&k, &r, &t, x));
        }
        let f = fundamental_from_rt(&k, &r, &t);
        // Any focal length in a wide range decides the same way.
        for focal in [200.0, 300.0, 500.0] {
            let kk = intrinsics(focal, 160.0, 120.0);
            let o = Oriented::from_fundamental(&f, &kk, &a, &b, &VoteOptions::default())
                .expect("decided");
            assert!(o.support > 0.99, "{focal}: {}", o.support);
            for (p, q) in a.iter().zip(&b) {
                assert_eq!(o.violation_px(*p, *q), 0.0);
            }
            // The walker: at 4 m, moves +0.2 m along x between the frames
            // while the camera moves +0.1 m: its image motion reverses.
            for y in [-0.5, 0.0, 0.4] {
                let x1 = Vector3::new(0.3, y, 4.0);
                let x2 = x1 + Vector3::new(0.2, 0.0, 0.0);
                let p = project(&k, &Matrix3::identity(), &Vector3::zeros(), x1);
                let q = project(&k, &r, &t, x2);
                // On its epipolar line (Sampson ≈ 0) ...
                let s = crate::geometry::fundamental::sampson_sq(&f, p, q).sqrt();
                assert!(s < 0.5, "sampson {s}");
                // ... but behind the cameras, by about its reversed motion
                // (0.1 m at 4 m × 300 px = 7.5 px, minus the yaw) with the
                // true focal length; with a wrong one the size is off but
                // the sign holds.
                let v = o.violation_px(p, q);
                let lo = if focal == 300.0 { 3.0 } else { 1.5 };
                assert!(v > lo && v < 12.0, "{focal}: violation {v}");
            }
        }
    }

    #[test]
    fn pure_rotation_is_undecided() {
        let k = intrinsics(300.0, 160.0, 120.0);
        let r = rot_y(0.05);
        let mut a = vec![];
        let mut b = vec![];
        for i in 0..20 {
            for j in 0..15 {
                let x = Vector3::new(i as f64 - 10.0, j as f64 - 7.0, 12.0);
                a.push(project(&k, &Matrix3::identity(), &Vector3::zeros(), x));
                b.push(project(&k, &r, &Vector3::zeros(), x));
            }
        }
        // Any F consistent with the rotation: [e]ₓ H for an arbitrary e.
        let h = k * r * k.try_inverse().unwrap();
        let e = Vector3::new(1.0, 0.3, 0.002);
        let f = e.cross_matrix() * h;
        assert!(Oriented::from_fundamental(&f, &k, &a, &b, &VoteOptions::default()).is_none());
    }
}
