//! Pose metrics: how far a predicted camera trajectory is from the ground truth.
//!
//! Follows the conventions of the evo tool (Grupp, github.com/MichaelGrupp/evo)
//! so numbers are comparable with the literature:
//! - **Alignment**: Umeyama (IEEE PAMI 1991) least-squares similarity from the
//!   predicted camera centres onto the ground-truth centres, the same
//!   estimator as `evo.core.geometry.umeyama_alignment` (eqs. 34–43, with the
//!   Kabsch sign fix). Sim(3) by default, as `evo_ape -as` (SfM has no scale).
//! - **ATE**: the translation part of the absolute pose error after alignment,
//!   i.e. ‖s·R·c_pred + t − c_gt‖ per frame; reported as RMSE (plus evo's
//!   other statistics).
//! - **RPE**: evo's `RPE` with `delta = 1 (frames)` on consecutive pairs, in
//!   the TUM RGB-D notation: for camera-to-world poses Q (reference) and P
//!   (estimate), `E_i = (Q_i⁻¹ Q_{i+1})⁻¹ (P_i⁻¹ P_{i+1})`; RPE-T = ‖trans(E_i)‖,
//!   RPE-R = |angle(rot(E_i))| in degrees. As with `evo_rpe -as`, the estimate
//!   is first mapped by the Sim(3) alignment: the rotation and translation of
//!   the alignment cancel in relative poses, the scale does not (it makes
//!   RPE-T comparable with an up-to-scale SfM result).
//!
//! Frames are matched by image name (file name without directories and
//! extension, so `images/0001.jpg` matches `0001.png`). "Consecutive" means
//! consecutive among the matched frames in name order (capture order in the
//! scene convention), exactly as evo pairs poses after associating the two
//! trajectories. Ground-truth frames missing from the prediction are counted
//! and listed, never silently dropped.

use crate::error::{PoseError, Result};
use loader::Pose;
use nalgebra::{Matrix3, Matrix4, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// One camera of a trajectory: image name and world-to-camera pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedPose {
    /// Image name as stored by the source (COLMAP image name or
    /// transforms.json file path).
    pub name: String,
    /// World-to-camera pose (COLMAP convention).
    pub pose: Pose,
}

/// A similarity transform `x ↦ s·R·x + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sim3 {
    /// Scale s (> 0).
    pub scale: f64,
    /// Rotation R (proper, det +1).
    pub rotation: Matrix3<f64>,
    /// Translation t.
    pub translation: Vector3<f64>,
}

impl Sim3 {
    /// The identity transform.
    pub fn identity() -> Self {
        Sim3 {
            scale: 1.0,
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// Apply to a point.
    pub fn apply(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.scale * (self.rotation * p) + self.translation
    }

    /// Serializable form.
    pub fn report(&self) -> Sim3Report {
        let r = &self.rotation;
        Sim3Report {
            scale: self.scale,
            rotation: [
                [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
                [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
                [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
            ],
            translation: [self.translation.x, self.translation.y, self.translation.z],
        }
    }
}

/// A [`Sim3`] as plain arrays (rotation row-major).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sim3Report {
    pub scale: f64,
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
}

/// Least-squares similarity (Umeyama 1991) mapping `src[i]` onto `dst[i]`:
/// minimises Σ‖dst_i − (s·R·src_i + t)‖². With `with_scale = false` the scale
/// is fixed to 1 (SE(3) alignment). Needs ≥ 3 non-collinear points (a rank-2
/// cross-covariance at least), as evo requires.
pub fn umeyama(src: &[Vector3<f64>], dst: &[Vector3<f64>], with_scale: bool) -> Result<Sim3> {
    if src.len() != dst.len() {
        return Err(PoseError::Invalid(format!(
            "umeyama: {} source points but {} destination points",
            src.len(),
            dst.len()
        )));
    }
    let n = src.len();
    if n < 3 {
        return Err(PoseError::Degenerate(format!(
            "alignment needs at least 3 matched cameras, got {n}"
        )));
    }
    let nf = n as f64;
    let mean_x = src.iter().sum::<Vector3<f64>>() / nf;
    let mean_y = dst.iter().sum::<Vector3<f64>>() / nf;
    // eq. 36: variance of the source points.
    let sigma_x = src.iter().map(|x| (x - mean_x).norm_squared()).sum::<f64>() / nf;
    // eq. 38: cross-covariance.
    let mut cov = Matrix3::zeros();
    for (x, y) in src.iter().zip(dst) {
        cov += (y - mean_y) * (x - mean_x).transpose();
    }
    cov /= nf;
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(PoseError::Degenerate("umeyama: SVD failed".into()));
    };
    let d = svd.singular_values;
    let dmax = d.max();
    let rank = d.iter().filter(|s| **s > dmax * 1e-12 && **s > 0.0).count();
    // A trajectory whose centres do not move (pure rotation, or a single
    // repeated pose) has no shape to align: the cross-covariance is then
    // float noise and the scale would come out as ~0.
    let sigma_y = dst.iter().map(|y| (y - mean_y).norm_squared()).sum::<f64>() / nf;
    let still = |sigma: f64, mean: &Vector3<f64>| {
        !(sigma.is_finite() && sigma.sqrt() > 1e-9 * mean.norm().max(1e-3))
    };
    for (sigma, mean, which) in [(sigma_x, &mean_x, "source"), (sigma_y, &mean_y, "target")] {
        if still(sigma, mean) {
            return Err(PoseError::Degenerate(format!(
                "the {which} camera centres do not move (spread {:.1e}): no parallax, e.g. a pure rotation; a trajectory alignment and its scale are undefined",
                sigma.sqrt()
            )));
        }
    }
    if rank < 2 || !sigma_x.is_finite() || sigma_x <= 0.0 {
        return Err(PoseError::Degenerate(
            "camera centres are (nearly) collinear or coincident; alignment is not possible".into(),
        ));
    }
    // eq. 43: sign fix so that R is a proper rotation.
    let mut s = Matrix3::identity();
    if u.determinant() * v_t.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let rotation = u * s * v_t;
    let scale = if with_scale {
        (Matrix3::from_diagonal(&d) * s).trace() / sigma_x
    } else {
        1.0
    };
    if !(scale.is_finite() && scale > 0.0) {
        return Err(PoseError::Degenerate(format!(
            "alignment scale {scale} is not positive: the trajectories do not correspond"
        )));
    }
    let translation = mean_y - scale * (rotation * mean_x);
    Ok(Sim3 {
        scale,
        rotation,
        translation,
    })
}

/// Which alignment is estimated before computing errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Alignment {
    /// Sim(3): rotation, translation and scale (`evo_ape -as`). The default:
    /// SfM reconstructions have an arbitrary scale.
    #[default]
    Sim3,
    /// SE(3): rotation and translation only (`evo_ape -a`).
    Se3,
    /// No alignment (both trajectories already share a frame).
    None,
}

/// Options of [`evaluate`].
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct PoseMetricsOptions {
    /// Alignment estimated on camera centres before the errors. Default Sim(3).
    pub alignment: Alignment,
    /// RPE frame delta (evo `--delta`, unit frames). Default 1: consecutive
    /// matched frames.
    pub delta: usize,
}

impl Default for PoseMetricsOptions {
    fn default() -> Self {
        PoseMetricsOptions {
            alignment: Alignment::Sim3,
            delta: 1,
        }
    }
}

impl PoseMetricsOptions {
    /// Check the options.
    pub fn validate(&self) -> Result<()> {
        if self.delta == 0 {
            return Err(PoseError::Invalid("RPE delta must be ≥ 1 frame".into()));
        }
        Ok(())
    }
}

/// evo's statistics of an error array.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    pub rmse: f64,
    pub mean: f64,
    pub median: f64,
    pub std: f64,
    pub min: f64,
    pub max: f64,
    /// Number of values.
    pub count: usize,
}

impl ErrorStats {
    /// Statistics of `values` (None when empty). `std` is the population
    /// standard deviation (numpy's default, as evo).
    pub fn from_values(values: &[f64]) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let rmse = (values.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        let std = (values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n).sqrt();
        let mut sorted = values.to_vec();
        sorted.sort_by(|a, b| a.total_cmp(b));
        let m = sorted.len();
        let median = if m % 2 == 1 {
            sorted[m / 2]
        } else {
            0.5 * (sorted[m / 2 - 1] + sorted[m / 2])
        };
        Some(ErrorStats {
            rmse,
            mean,
            median,
            std,
            min: sorted[0],
            max: sorted[m - 1],
            count: m,
        })
    }
}

/// Result of [`evaluate`]. Units: ATE and RPE-T in the ground truth's units,
/// RPE-R in degrees.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PoseMetrics {
    /// Frames in the ground truth.
    pub total: usize,
    /// Ground-truth frames present in the prediction.
    pub registered: usize,
    /// Ground-truth frames absent from the prediction, in name order.
    pub missing: Vec<String>,
    /// Predicted frames with no ground truth (ignored by the metrics).
    pub unmatched_pred: Vec<String>,
    /// Alignment used.
    pub alignment: Alignment,
    /// The estimated transform from prediction to ground truth.
    pub sim3: Sim3Report,
    /// Absolute trajectory error of camera centres after alignment.
    pub ate: ErrorStats,
    /// Relative translation error over frame pairs `delta` apart.
    pub rpe_trans: Option<ErrorStats>,
    /// Relative rotation error in degrees over the same pairs.
    pub rpe_rot_deg: Option<ErrorStats>,
    /// RPE frame delta.
    pub delta: usize,
    /// Length of the ground-truth centre path over the matched frames (for
    /// scale: ATE / path length is unit-free).
    pub gt_path_length: f64,
}

/// The key frames are matched by: the file name without directories and
/// without its extension.
pub fn match_key(name: &str) -> String {
    let base = name.rsplit(['/', '\\']).next().unwrap_or(name);
    match base.rfind('.') {
        Some(i) if i > 0 => base[..i].to_string(),
        _ => base.to_string(),
    }
}

fn index_by_key(traj: &[NamedPose], what: &str) -> Result<HashMap<String, usize>> {
    let mut map = HashMap::with_capacity(traj.len());
    for (i, f) in traj.iter().enumerate() {
        if let Some(j) = map.insert(match_key(&f.name), i) {
            return Err(PoseError::Invalid(format!(
                "{what} trajectory: images `{}` and `{}` have the same name once directories and extension are removed",
                traj[j].name, f.name
            )));
        }
    }
    Ok(map)
}

/// Camera-to-world 4×4 matrix of a world-to-camera pose.
fn c2w(p: &Pose) -> Matrix4<f64> {
    p.camera_to_world()
}

/// Rotation angle of a rotation matrix in radians, robust near 0 and π.
pub fn rotation_angle(r: &Matrix3<f64>) -> f64 {
    let sin2 = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    )
    .norm();
    let cos2 = r.trace() - 1.0;
    sin2.atan2(cos2).abs()
}

/// Compare a predicted trajectory with the ground truth (both world-to-camera,
/// matched by [`match_key`]).
pub fn evaluate(
    pred: &[NamedPose],
    gt: &[NamedPose],
    opts: &PoseMetricsOptions,
) -> Result<PoseMetrics> {
    opts.validate()?;
    let pred_idx = index_by_key(pred, "predicted")?;
    let gt_idx = index_by_key(gt, "ground-truth")?;

    let mut gt_order: Vec<usize> = (0..gt.len()).collect();
    gt_order.sort_by(|a, b| gt[*a].name.cmp(&gt[*b].name));
    let mut pairs = Vec::new(); // (gt index, pred index) in name order
    let mut missing = Vec::new();
    for gi in gt_order {
        match pred_idx.get(&match_key(&gt[gi].name)) {
            Some(pi) => pairs.push((gi, *pi)),
            None => missing.push(gt[gi].name.clone()),
        }
    }
    let mut unmatched_pred: Vec<String> = pred
        .iter()
        .filter(|p| !gt_idx.contains_key(&match_key(&p.name)))
        .map(|p| p.name.clone())
        .collect();
    unmatched_pred.sort();

    let gt_c: Vec<Vector3<f64>> = pairs.iter().map(|(g, _)| gt[*g].pose.center()).collect();
    let pr_c: Vec<Vector3<f64>> = pairs.iter().map(|(_, p)| pred[*p].pose.center()).collect();
    if pairs.len() < 3 && opts.alignment != Alignment::None {
        return Err(PoseError::Degenerate(format!(
            "only {} of {} ground-truth frames are in the prediction; alignment needs at least 3",
            pairs.len(),
            gt.len()
        )));
    }
    if pairs.is_empty() {
        return Err(PoseError::Degenerate(
            "no frame of the prediction matches the ground truth by name".into(),
        ));
    }
    let sim = match opts.alignment {
        Alignment::Sim3 => umeyama(&pr_c, &gt_c, true)?,
        Alignment::Se3 => umeyama(&pr_c, &gt_c, false)?,
        Alignment::None => Sim3::identity(),
    };

    let ate_values: Vec<f64> = pr_c
        .iter()
        .zip(&gt_c)
        .map(|(p, g)| (sim.apply(p) - g).norm())
        .collect();
    let ate = ErrorStats::from_values(&ate_values)
        .ok_or_else(|| PoseError::Degenerate("no matched frames".into()))?;

    // RPE on consecutive matched frames, `delta` apart (evo: ids 0, δ, 2δ, …).
    let ids: Vec<usize> = (0..pairs.len()).step_by(opts.delta).collect();
    let mut rpe_t = Vec::new();
    let mut rpe_r = Vec::new();
    for w in ids.windows(2) {
        let (gi, pi) = pairs[w[0]];
        let (gj, pj) = pairs[w[1]];
        let q_rel = c2w(&gt[gi].pose)
            .try_inverse()
            .unwrap_or_else(Matrix4::identity)
            * c2w(&gt[gj].pose);
        // Scale only: the alignment's rotation and translation cancel.
        let mut p_i = c2w(&pred[pi].pose);
        let mut p_j = c2w(&pred[pj].pose);
        for m in [&mut p_i, &mut p_j] {
            for r in 0..3 {
                m[(r, 3)] *= sim.scale;
            }
        }
        let p_rel = p_i.try_inverse().unwrap_or_else(Matrix4::identity) * p_j;
        let e = q_rel.try_inverse().unwrap_or_else(Matrix4::identity) * p_rel;
        rpe_t.push(Vector3::new(e[(0, 3)], e[(1, 3)], e[(2, 3)]).norm());
        let r: Matrix3<f64> = e.fixed_view::<3, 3>(0, 0).into_owned();
        rpe_r.push(rotation_angle(&r).to_degrees());
    }
    let gt_path_length = gt_c.windows(2).map(|w| (w[1] - w[0]).norm()).sum();

    Ok(PoseMetrics {
        total: gt.len(),
        registered: pairs.len(),
        missing,
        unmatched_pred,
        alignment: opts.alignment,
        sim3: sim.report(),
        ate,
        rpe_trans: ErrorStats::from_values(&rpe_t),
        rpe_rot_deg: ErrorStats::from_values(&rpe_r),
        delta: opts.delta,
        gt_path_length,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};

    fn pose_at(center: Vector3<f64>, r_w2c: Matrix3<f64>) -> Pose {
        Pose::from_rt(&r_w2c, &(-(r_w2c * center)))
    }

    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 11) as f64) / ((1u64 << 53) as f64) * 2.0 - 1.0
    }

    fn spiral(n: usize) -> Vec<NamedPose> {
        (0..n)
            .map(|i| {
                let a = i as f64 * 0.3;
                let c = Vector3::new(3.0 * a.cos(), 0.2 * i as f64, 3.0 * a.sin());
                let r = Rotation3::from_euler_angles(0.1 * a, a, 0.05 * i as f64).into_inner();
                NamedPose {
                    name: format!("images/{i:04}.jpg"),
                    pose: pose_at(c, r),
                }
            })
            .collect()
    }

    /// Map a w2c trajectory through the similarity x ↦ s·R·x + t.
    fn transform_traj(traj: &[NamedPose], sim: &Sim3) -> Vec<NamedPose> {
        traj.iter()
            .map(|f| {
                let c = sim.apply(&f.pose.center());
                // camera orientation in world: R_c2w' = R_sim · R_c2w
                let r_w2c = f.pose.rotation() * sim.rotation.transpose();
                NamedPose {
                    name: f.name.clone(),
                    pose: pose_at(c, r_w2c),
                }
            })
            .collect()
    }

    #[test]
    fn umeyama_recovers_known_similarity() {
        let mut st = 7u64;
        let src: Vec<Vector3<f64>> = (0..20)
            .map(|_| Vector3::new(lcg(&mut st), lcg(&mut st), lcg(&mut st)) * 5.0)
            .collect();
        let axis = Unit::new_normalize(Vector3::new(0.3, -1.0, 0.5));
        let truth = Sim3 {
            scale: 2.7,
            rotation: Rotation3::from_axis_angle(&axis, 2.1).into_inner(),
            translation: Vector3::new(-4.0, 1.5, 10.0),
        };
        let dst: Vec<Vector3<f64>> = src.iter().map(|p| truth.apply(p)).collect();
        let est = umeyama(&src, &dst, true).unwrap();
        assert!((est.scale - truth.scale).abs() < 1e-10, "{}", est.scale);
        assert!((est.rotation - truth.rotation).norm() < 1e-10);
        assert!((est.translation - truth.translation).norm() < 1e-9);
        assert!((est.rotation.determinant() - 1.0).abs() < 1e-12);
        // Without scale the rotation is still recovered exactly.
        let dst1: Vec<Vector3<f64>> = src
            .iter()
            .map(|p| truth.rotation * p + truth.translation)
            .collect();
        let est1 = umeyama(&src, &dst1, false).unwrap();
        assert_eq!(est1.scale, 1.0);
        assert!((est1.rotation - truth.rotation).norm() < 1e-10);
        assert!((est1.translation - truth.translation).norm() < 1e-9);
    }

    #[test]
    fn umeyama_handles_reflection_and_degenerate_input() {
        // A planar set mapped by a rotation: rank-2 covariance still works,
        // and R stays a proper rotation (Kabsch sign fix).
        let src = vec![
            Vector3::new(1.0, 1.0, 0.0),
            Vector3::new(-1.0, 1.0, 0.0),
            Vector3::new(-1.0, -1.0, 0.0),
            Vector3::new(1.0, -1.0, 0.0),
        ];
        let rot = Rotation3::from_euler_angles(0.4, -0.2, 1.0).into_inner();
        let dst: Vec<_> = src.iter().map(|p| rot * p).collect();
        let est = umeyama(&src, &dst, true).unwrap();
        assert!((est.rotation - rot).norm() < 1e-10);
        assert!((est.scale - 1.0).abs() < 1e-12);
        // Collinear points cannot be aligned.
        let line: Vec<_> = (0..5).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        assert!(matches!(
            umeyama(&line, &line, true),
            Err(PoseError::Degenerate(_))
        ));
        assert!(umeyama(&src[..2], &dst[..2], true).is_err());
        // A pure rotation: the target centres sit at one point (up to float
        // noise) while the estimate has jitter. The alignment is refused
        // with "no parallax" instead of a scale of ~0.
        let still: Vec<_> = (0..6)
            .map(|i| Vector3::new(1e-17 * i as f64, 0.0, 2.0))
            .collect();
        let jitter: Vec<_> = src.iter().chain(&src[..2]).map(|p| p * 1e-3).collect();
        for (a, b) in [(&jitter, &still), (&still, &jitter)] {
            match umeyama(a, b, true) {
                Err(PoseError::Degenerate(m)) => assert!(m.contains("no parallax"), "{m}"),
                other => panic!("expected a degenerate-trajectory error, got {other:?}"),
            }
        }
    }

    #[test]
    fn metrics_are_zero_on_identical_and_similar_trajectories() {
        let gt = spiral(15);
        let m = evaluate(&gt, &gt, &PoseMetricsOptions::default()).unwrap();
        assert_eq!((m.total, m.registered), (15, 15));
        assert!(m.missing.is_empty() && m.unmatched_pred.is_empty());
        assert!(m.ate.rmse < 1e-12);
        assert!(m.rpe_trans.as_ref().unwrap().rmse < 1e-12);
        assert!(m.rpe_rot_deg.as_ref().unwrap().max < 1e-6);
        assert_eq!(m.rpe_trans.as_ref().unwrap().count, 14);
        // A prediction in another similarity frame (as SfM gives) and with
        // other file extensions scores zero too.
        let sim = Sim3 {
            scale: 0.31,
            rotation: Rotation3::from_euler_angles(1.0, 2.0, -0.5).into_inner(),
            translation: Vector3::new(5.0, -2.0, 0.7),
        };
        let mut pred = transform_traj(&gt, &sim);
        for f in &mut pred {
            f.name = f.name.replace("images/", "").replace(".jpg", ".png");
        }
        let m = evaluate(&pred, &gt, &PoseMetricsOptions::default()).unwrap();
        assert_eq!(m.registered, 15);
        assert!(m.ate.rmse < 1e-9, "{}", m.ate.rmse);
        assert!(m.rpe_trans.as_ref().unwrap().rmse < 1e-9);
        assert!(m.rpe_rot_deg.as_ref().unwrap().max < 1e-5);
        assert!((m.sim3.scale - 1.0 / 0.31).abs() < 1e-9);
    }

    #[test]
    fn metrics_match_hand_computed_values() {
        // GT: identity-oriented cameras on a square; prediction: centres
        // pushed ±e along z in a saddle pattern (orthogonal to every
        // similarity), and the last frame rotated 3° about its optical axis
        // (the last, so no relative translation is expressed in its frame).
        // By hand: cross-covariance diag(1,1,0) ⇒ R = I, t = 0,
        // s = 2 / (2 + e²); each aligned centre is off by
        // (s−1, s−1, s·e) ⇒ ATE = √(2(s−1)² + s²e²) for every frame;
        // each consecutive relative translation is off by 2√((1−s)² + s²e²);
        // relative rotations are off by 0°, 0°, 3°.
        let e = 0.1;
        let sq = [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)];
        let gt: Vec<NamedPose> = sq
            .iter()
            .enumerate()
            .map(|(i, (x, y))| NamedPose {
                name: format!("{i}.jpg"),
                pose: pose_at(Vector3::new(*x, *y, 0.0), Matrix3::identity()),
            })
            .collect();
        let zs = [e, -e, e, -e];
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), 3f64.to_radians()).into_inner();
        let pred: Vec<NamedPose> = sq
            .iter()
            .enumerate()
            .map(|(i, (x, y))| NamedPose {
                name: format!("{i}.jpg"),
                pose: pose_at(
                    Vector3::new(*x, *y, zs[i]),
                    if i == 3 { rz } else { Matrix3::identity() },
                ),
            })
            .collect();
        let m = evaluate(&pred, &gt, &PoseMetricsOptions::default()).unwrap();
        let s = 2.0 / (2.0 + e * e);
        assert!((m.sim3.scale - s).abs() < 1e-12);
        let ate = (2.0 * (s - 1.0).powi(2) + s * s * e * e).sqrt();
        assert!((m.ate.rmse - ate).abs() < 1e-12, "{} vs {ate}", m.ate.rmse);
        assert!((m.ate.max - m.ate.min).abs() < 1e-12);
        let rpe = 2.0 * ((1.0 - s).powi(2) + s * s * e * e).sqrt();
        let rt = m.rpe_trans.unwrap();
        assert_eq!(rt.count, 3);
        assert!((rt.rmse - rpe).abs() < 1e-12, "{} vs {rpe}", rt.rmse);
        let rr = m.rpe_rot_deg.unwrap();
        assert!((rr.rmse - 3f64.sqrt()).abs() < 1e-9, "{}", rr.rmse);
        assert!((rr.mean - 1.0).abs() < 1e-9 && rr.min.abs() < 1e-9);
        assert!((rr.max - 3.0).abs() < 1e-9);
    }

    #[test]
    fn missing_frames_are_listed_and_rpe_skips_over_them() {
        let gt = spiral(10);
        let pred: Vec<NamedPose> = gt
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != 3 && *i != 7)
            .map(|(_, f)| f.clone())
            .chain(std::iter::once(NamedPose {
                name: "extra.jpg".into(),
                pose: Pose::identity(),
            }))
            .collect();
        let m = evaluate(&pred, &gt, &PoseMetricsOptions::default()).unwrap();
        assert_eq!((m.total, m.registered), (10, 8));
        assert_eq!(m.missing, vec!["images/0003.jpg", "images/0007.jpg"]);
        assert_eq!(m.unmatched_pred, vec!["extra.jpg"]);
        assert_eq!(m.rpe_trans.unwrap().count, 7);
        assert!(m.ate.rmse < 1e-12);
        // delta 2: ids 0, 2, 4, 6 of the 8 matched frames → 3 pairs.
        let opts = PoseMetricsOptions {
            delta: 2,
            ..Default::default()
        };
        assert_eq!(
            evaluate(&pred, &gt, &opts)
                .unwrap()
                .rpe_trans
                .unwrap()
                .count,
            3
        );
        // Too few matches is an error naming the counts.
        let e = evaluate(&pred[..2], &gt, &PoseMetricsOptions::default()).unwrap_err();
        assert!(e.to_string().contains("2 of 10"), "{e}");
    }

    #[test]
    fn stats_follow_numpy_conventions() {
        let s = ErrorStats::from_values(&[3.0, 1.0, 2.0, 4.0]).unwrap();
        assert_eq!(s.median, 2.5);
        assert_eq!(s.mean, 2.5);
        assert!((s.rmse - 7.5f64.sqrt()).abs() < 1e-12);
        assert!((s.std - 1.25f64.sqrt()).abs() < 1e-12);
        assert_eq!((s.min, s.max, s.count), (1.0, 4.0, 4));
        assert!(ErrorStats::from_values(&[]).is_none());
        assert_eq!(match_key("images/0001.jpg"), "0001");
        assert_eq!(match_key("0001"), "0001");
        assert_eq!(match_key(".hidden"), ".hidden");
    }
}
