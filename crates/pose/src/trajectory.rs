//! Camera trajectories for the pose metrics, read from either a COLMAP model
//! (a model folder, or a scene folder holding `sparse/0`) or a
//! transforms.json (nerfstudio / instant-ngp; OpenGL camera-to-world, turned
//! into COLMAP world-to-camera by `loader::transforms`, the one place that
//! knows that convention).

use crate::error::{PoseError, Result};
use crate::metrics::NamedPose;
use loader::colmap::{find_model_dir, read_model};
use loader::transforms::{pose_from_c2w_opengl, read_transforms};
use nalgebra::Matrix4;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Where a trajectory came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "path", rename_all = "lowercase")]
pub enum TrajectorySource {
    /// A COLMAP model folder.
    Colmap(PathBuf),
    /// A transforms.json file.
    Transforms(PathBuf),
}

/// Read the poses of a COLMAP model folder.
pub fn from_colmap(dir: &Path) -> Result<Vec<NamedPose>> {
    let model = read_model(dir)?;
    Ok(model
        .images
        .values()
        .map(|im| NamedPose {
            name: im.name.clone(),
            pose: im.pose,
        })
        .collect())
}

/// Read the poses of a transforms.json. Images need not exist (a
/// ground-truth file can be evaluated without its images).
pub fn from_transforms(path: &Path) -> Result<Vec<NamedPose>> {
    let t = read_transforms(path)?;
    let mut out = Vec::with_capacity(t.frames.len());
    for (i, f) in t.frames.iter().enumerate() {
        let rows = &f.transform_matrix;
        let ok_shape = (rows.len() == 4 || rows.len() == 3) && rows.iter().all(|r| r.len() == 4);
        if !ok_shape || rows.iter().flatten().any(|v| !v.is_finite()) {
            return Err(PoseError::Invalid(format!(
                "{}: frame {i} ({}): transform_matrix must be 3×4 or 4×4 finite numbers",
                path.display(),
                f.file_path
            )));
        }
        let mut m = Matrix4::identity();
        for (r, row) in rows.iter().enumerate().take(3) {
            for (c, v) in row.iter().enumerate() {
                m[(r, c)] = *v;
            }
        }
        out.push(NamedPose {
            name: f.file_path.clone(),
            pose: pose_from_c2w_opengl(&m),
        });
    }
    Ok(out)
}

/// Read a trajectory from `path`: a `.json` file is a transforms.json; a
/// folder is a COLMAP model (itself, `sparse/0` or `sparse`), else a folder
/// holding `transforms.json`.
pub fn load_trajectory(path: &Path) -> Result<(Vec<NamedPose>, TrajectorySource)> {
    if path.is_file() {
        let is_json = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"));
        if !is_json {
            return Err(PoseError::Invalid(format!(
                "{}: expected a transforms.json or a COLMAP model folder",
                path.display()
            )));
        }
        return Ok((
            from_transforms(path)?,
            TrajectorySource::Transforms(path.to_path_buf()),
        ));
    }
    if !path.is_dir() {
        return Err(PoseError::Invalid(format!(
            "{}: no such file or folder",
            path.display()
        )));
    }
    if let Some(dir) = find_model_dir(path) {
        return Ok((from_colmap(&dir)?, TrajectorySource::Colmap(dir)));
    }
    let t = path.join("transforms.json");
    if t.is_file() {
        return Ok((from_transforms(&t)?, TrajectorySource::Transforms(t)));
    }
    Err(PoseError::Invalid(format!(
        "{}: neither a COLMAP model (cameras.bin/.txt, sparse/0) nor a folder with transforms.json",
        path.display()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use loader::colmap::{ColmapImage, ColmapModel, write_model_binary};
    use loader::transforms::c2w_opengl_from_pose;
    use loader::{Camera, CameraModel, Pose};
    use nalgebra::Vector3;

    #[test]
    fn colmap_and_transforms_give_the_same_trajectory() {
        let d = tempfile::tempdir().unwrap();
        let mut model = ColmapModel::default();
        model.cameras.insert(
            1,
            Camera {
                id: 1,
                model: CameraModel::PINHOLE,
                width: 64,
                height: 48,
                params: vec![50.0, 50.0, 32.0, 24.0],
            },
        );
        let mut frames = Vec::new();
        for i in 0..5u32 {
            let pose = Pose::look_at(
                Vector3::new(i as f64, 0.3 * (i * i) as f64, 1.0 + 0.2 * (i % 2) as f64),
                Vector3::new(0.0, 5.0, 0.0),
                Vector3::z(),
            );
            let name = format!("{i:04}.jpg");
            model
                .images
                .insert(i + 1, ColmapImage::new(i + 1, pose, 1, name.clone()));
            let m = c2w_opengl_from_pose(&pose);
            let rows: Vec<Vec<f64>> = (0..4)
                .map(|r| (0..4).map(|c| m[(r, c)]).collect())
                .collect();
            frames.push(serde_json::json!({"file_path": format!("images/{name}"), "transform_matrix": rows}));
        }
        write_model_binary(&model, d.path().join("scene/sparse/0")).unwrap();
        let tj = d.path().join("t.json");
        std::fs::write(
            &tj,
            serde_json::to_string(
                &serde_json::json!({"fl_x": 50.0, "w": 64, "h": 48, "frames": frames}),
            )
            .unwrap(),
        )
        .unwrap();
        let (a, sa) = load_trajectory(&d.path().join("scene")).unwrap();
        assert!(matches!(sa, TrajectorySource::Colmap(_)));
        let (b, sb) = load_trajectory(&tj).unwrap();
        assert!(matches!(sb, TrajectorySource::Transforms(_)));
        let m = crate::metrics::evaluate(&a, &b, &Default::default()).unwrap();
        assert_eq!(m.registered, 5);
        assert!(m.ate.rmse < 1e-9);
        assert!((m.sim3.scale - 1.0).abs() < 1e-9);
        assert!(m.rpe_rot_deg.unwrap().max < 1e-6);
        // Bad input names the file.
        std::fs::write(
            &tj,
            r#"{"frames":[{"file_path":"a.jpg","transform_matrix":[[1,0],[0,1]]}]}"#,
        )
        .unwrap();
        let e = load_trajectory(&tj).unwrap_err().to_string();
        assert!(e.contains("t.json"), "{e}");
        let e = load_trajectory(&d.path().join("nothing"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("nothing"), "{e}");
    }
}
