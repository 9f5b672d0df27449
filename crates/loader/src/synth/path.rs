//! The camera path of a synthetic scene: a uniform Catmull–Rom spline through
//! the spec's eye and target control points (smooth dolly / arc), plus a
//! seeded handheld jitter — a sum of a few sinusoids per axis with random
//! frequencies around `jitter_hz` and random phases, so it is smooth in time
//! and has the requested standard deviation. Held-out test views sit between
//! training positions, offset from the path, without jitter.

use super::spec::SceneSpec;
use super::texture::mix64;
use crate::camera::Pose;
use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

type V3 = Vector3<f64>;

/// Uniform Catmull–Rom interpolation through `pts` at `s` ∈ [0, 1].
pub fn catmull_rom(pts: &[[f64; 3]], s: f64) -> V3 {
    let n = pts.len();
    if n == 0 {
        return V3::zeros();
    }
    if n == 1 {
        return V3::from(pts[0]);
    }
    let u = s.clamp(0.0, 1.0) * (n - 1) as f64;
    let i = (u.floor() as usize).min(n - 2);
    let t = u - i as f64;
    let p = |k: isize| V3::from(pts[(i as isize + k).clamp(0, n as isize - 1) as usize]);
    let (p0, p1, p2, p3) = (p(-1), p(0), p(1), p(2));
    let (t2, t3) = (t * t, t * t * t);
    0.5 * ((2.0 * p1)
        + (p2 - p0) * t
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * t3)
}

/// Smooth zero-mean noise with standard deviation 1 per channel.
struct Wobble {
    /// Per channel: (frequency Hz, phase) of each sinusoid.
    waves: Vec<[(f64, f64); 3]>,
}

impl Wobble {
    fn new(rng: &mut Pcg64, channels: usize, hz: f64) -> Wobble {
        let waves = (0..channels)
            .map(|_| {
                [0, 1, 2].map(|_| {
                    (
                        hz * rng.random_range(0.4..1.6),
                        rng.random_range(0.0..std::f64::consts::TAU),
                    )
                })
            })
            .collect();
        Wobble { waves }
    }

    fn at(&self, ch: usize, t: f64) -> f64 {
        // Three sinusoids of amplitude a have variance 3a²/2 = 1.
        let a = (2.0f64 / 3.0).sqrt();
        self.waves[ch]
            .iter()
            .map(|(f, ph)| a * (std::f64::consts::TAU * f * t + ph).sin())
            .sum()
    }
}

/// A look-at pose with an extra rotation `rot` (camera frame) applied.
fn pose_at(eye: V3, target: V3, rot: Rotation3<f64>) -> Pose {
    let base = Pose::look_at(eye, target, V3::z());
    let r = rot.matrix() * base.rotation();
    Pose::from_rt(&r, &(-(r * eye)))
}

/// World-to-camera poses of the training frames.
pub fn training_poses(spec: &SceneSpec) -> Vec<Pose> {
    let c = &spec.camera;
    let mut rng = Pcg64::seed_from_u64(mix64(spec.seed ^ 0xCA11_0002));
    let wob = Wobble::new(&mut rng, 6, c.jitter_hz);
    let n = spec.frames.max(2);
    (0..n)
        .map(|i| {
            let s = i as f64 / (n - 1) as f64;
            let t = i as f64 / spec.fps;
            let jp = V3::new(wob.at(0, t), wob.at(1, t), wob.at(2, t)) * c.jitter_pos;
            let jr =
                V3::new(wob.at(3, t), wob.at(4, t), wob.at(5, t)) * c.jitter_rot_deg.to_radians();
            pose_at(
                catmull_rom(&c.eye, s) + jp,
                catmull_rom(&c.target, s),
                Rotation3::new(jr),
            )
        })
        .collect()
}

/// World-to-camera poses of the held-out test views: halfway between
/// training positions, offset by `test_offset` (camera frame, alternating
/// sign), no jitter.
pub fn test_poses(spec: &SceneSpec) -> Vec<Pose> {
    let c = &spec.camera;
    let n = spec.test_views;
    (0..n)
        .map(|k| {
            let s = (k as f64 + 0.5) / n as f64;
            let (eye, target) = (catmull_rom(&c.eye, s), catmull_rom(&c.target, s));
            let base = Pose::look_at(eye, target, V3::z());
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            let o = spec.test_offset;
            let off = base.rotation().transpose() * V3::new(sign * o[0], sign * o[1], o[2]);
            pose_at(eye + off, target + off, Rotation3::identity())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catmull_rom_interpolates_control_points() {
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 2.0, 0.0],
            [3.0, 2.0, 1.0],
            [4.0, 0.0, 1.0],
        ];
        for (i, p) in pts.iter().enumerate() {
            let q = catmull_rom(&pts, i as f64 / 3.0);
            assert!((q - V3::from(*p)).norm() < 1e-12, "{i}: {q:?}");
        }
    }

    #[test]
    fn jitter_free_path_follows_the_spline_and_looks_at_target() {
        let mut spec = SceneSpec::default();
        spec.camera.jitter_pos = 0.0;
        spec.camera.jitter_rot_deg = 0.0;
        let poses = training_poses(&spec);
        assert_eq!(poses.len(), spec.frames as usize);
        for (i, p) in poses.iter().enumerate() {
            let s = i as f64 / (poses.len() - 1) as f64;
            assert!((p.center() - catmull_rom(&spec.camera.eye, s)).norm() < 1e-9);
            let tc = p.transform(catmull_rom(&spec.camera.target, s));
            assert!(tc.x.abs() < 1e-9 && tc.y.abs() < 1e-9 && tc.z > 0.0);
        }
        // Jitter moves the camera by about jitter_pos, not more than a few σ.
        spec.camera.jitter_pos = 0.02;
        let jit = training_poses(&spec);
        let max = jit
            .iter()
            .zip(&poses)
            .map(|(a, b)| (a.center() - b.center()).norm())
            .fold(0.0, f64::max);
        assert!(max > 0.005 && max < 0.15, "{max}");
    }
}
