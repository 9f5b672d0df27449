//! Cameras and poses, in COLMAP's conventions: intrinsics as COLMAP camera
//! models, poses world-to-camera with OpenCV axes (x right, y down, z forward).
//! transforms.json's OpenGL camera-to-world is converted in `transforms.rs`
//! and nowhere else.

use serde::{Deserialize, Serialize};

/// Every COLMAP camera model, with COLMAP's numeric id and parameter order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[allow(non_camel_case_types)]
pub enum CameraModel {
    /// f, cx, cy
    SIMPLE_PINHOLE,
    /// fx, fy, cx, cy
    PINHOLE,
    /// f, cx, cy, k
    SIMPLE_RADIAL,
    /// f, cx, cy, k1, k2
    RADIAL,
    /// fx, fy, cx, cy, k1, k2, p1, p2
    OPENCV,
    /// fx, fy, cx, cy, k1, k2, k3, k4
    OPENCV_FISHEYE,
    /// fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6
    FULL_OPENCV,
    /// fx, fy, cx, cy, omega
    FOV,
    /// f, cx, cy, k
    SIMPLE_RADIAL_FISHEYE,
    /// f, cx, cy, k1, k2
    RADIAL_FISHEYE,
    /// fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1
    THIN_PRISM_FISHEYE,
    /// fx, fy, cx, cy, k0..k5, p0, p1, s0..s3 (COLMAP >= 3.11)
    RAD_TAN_THIN_PRISM_FISHEYE,
}

impl CameraModel {
    /// All models in COLMAP id order.
    pub const ALL: [CameraModel; 12] = [
        CameraModel::SIMPLE_PINHOLE,
        CameraModel::PINHOLE,
        CameraModel::SIMPLE_RADIAL,
        CameraModel::RADIAL,
        CameraModel::OPENCV,
        CameraModel::OPENCV_FISHEYE,
        CameraModel::FULL_OPENCV,
        CameraModel::FOV,
        CameraModel::SIMPLE_RADIAL_FISHEYE,
        CameraModel::RADIAL_FISHEYE,
        CameraModel::THIN_PRISM_FISHEYE,
        CameraModel::RAD_TAN_THIN_PRISM_FISHEYE,
    ];

    /// COLMAP's numeric model id.
    pub fn id(self) -> i32 {
        Self::ALL.iter().position(|m| *m == self).unwrap_or(0) as i32
    }

    /// Model from COLMAP's numeric id.
    pub fn from_id(id: i32) -> Option<Self> {
        usize::try_from(id)
            .ok()
            .and_then(|i| Self::ALL.get(i).copied())
    }

    /// COLMAP's model name (as in cameras.txt).
    pub fn name(self) -> &'static str {
        match self {
            CameraModel::SIMPLE_PINHOLE => "SIMPLE_PINHOLE",
            CameraModel::PINHOLE => "PINHOLE",
            CameraModel::SIMPLE_RADIAL => "SIMPLE_RADIAL",
            CameraModel::RADIAL => "RADIAL",
            CameraModel::OPENCV => "OPENCV",
            CameraModel::OPENCV_FISHEYE => "OPENCV_FISHEYE",
            CameraModel::FULL_OPENCV => "FULL_OPENCV",
            CameraModel::FOV => "FOV",
            CameraModel::SIMPLE_RADIAL_FISHEYE => "SIMPLE_RADIAL_FISHEYE",
            CameraModel::RADIAL_FISHEYE => "RADIAL_FISHEYE",
            CameraModel::THIN_PRISM_FISHEYE => "THIN_PRISM_FISHEYE",
            CameraModel::RAD_TAN_THIN_PRISM_FISHEYE => "RAD_TAN_THIN_PRISM_FISHEYE",
        }
    }

    /// Model from COLMAP's name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|m| m.name() == name)
    }

    /// Number of parameters COLMAP stores for this model.
    pub fn num_params(self) -> usize {
        match self {
            CameraModel::SIMPLE_PINHOLE => 3,
            CameraModel::PINHOLE => 4,
            CameraModel::SIMPLE_RADIAL => 4,
            CameraModel::RADIAL => 5,
            CameraModel::OPENCV => 8,
            CameraModel::OPENCV_FISHEYE => 8,
            CameraModel::FULL_OPENCV => 12,
            CameraModel::FOV => 5,
            CameraModel::SIMPLE_RADIAL_FISHEYE => 4,
            CameraModel::RADIAL_FISHEYE => 5,
            CameraModel::THIN_PRISM_FISHEYE => 12,
            CameraModel::RAD_TAN_THIN_PRISM_FISHEYE => 16,
        }
    }

    /// True when the model has a single focal length parameter.
    pub fn single_focal(self) -> bool {
        matches!(
            self,
            CameraModel::SIMPLE_PINHOLE
                | CameraModel::SIMPLE_RADIAL
                | CameraModel::RADIAL
                | CameraModel::SIMPLE_RADIAL_FISHEYE
                | CameraModel::RADIAL_FISHEYE
        )
    }
}

/// A camera as COLMAP stores it: model, size in pixels and raw parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub id: u32,
    pub model: CameraModel,
    pub width: u64,
    pub height: u64,
    pub params: Vec<f64>,
}

impl Camera {
    /// A camera whose `params` has the model's count (see
    /// [`CameraModel::num_params`]); the error says the count otherwise.
    pub fn new(
        id: u32,
        model: CameraModel,
        width: u64,
        height: u64,
        params: Vec<f64>,
    ) -> std::result::Result<Self, String> {
        if params.len() != model.num_params() {
            return Err(format!(
                "model {} needs {} params, found {}",
                model.name(),
                model.num_params(),
                params.len()
            ));
        }
        Ok(Camera {
            id,
            model,
            width,
            height,
            params,
        })
    }

    /// Index of fy in `params`: 0 when the model has one focal length (fx = fy),
    /// else 1. The principal point follows it, then the distortion.
    fn fy_index(&self) -> usize {
        usize::from(!self.model.single_focal())
    }

    /// Focal lengths (fx, fy) in pixels.
    pub fn focal(&self) -> (f64, f64) {
        (self.params[0], self.params[self.fy_index()])
    }

    /// Principal point (cx, cy) in pixels.
    pub fn principal_point(&self) -> (f64, f64) {
        let c = self.fy_index() + 1;
        (self.params[c], self.params[c + 1])
    }

    /// Distortion parameters (everything after focal and principal point).
    pub fn distortion(&self) -> &[f64] {
        let n = self.fy_index() + 3;
        &self.params[n.min(self.params.len())..]
    }

    /// True when every distortion parameter is zero (or the model has none).
    pub fn is_pinhole(&self) -> bool {
        matches!(
            self.model,
            CameraModel::SIMPLE_PINHOLE | CameraModel::PINHOLE
        ) || (matches!(
            self.model,
            CameraModel::SIMPLE_RADIAL
                | CameraModel::RADIAL
                | CameraModel::OPENCV
                | CameraModel::FULL_OPENCV
        ) && self.distortion().iter().all(|d| *d == 0.0))
    }

    /// Pinhole intrinsics, ignoring distortion.
    pub fn intrinsics(&self) -> Intrinsics {
        let (fx, fy) = self.focal();
        let (cx, cy) = self.principal_point();
        Intrinsics {
            width: self.width as u32,
            height: self.height as u32,
            fx,
            fy,
            cx,
            cy,
        }
    }
}

/// Pinhole intrinsics in pixels for an image of `width`×`height`.
/// Pixel centres are at integer + 0.5 (COLMAP's convention).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    /// Intrinsics for the image resized to `new_w`×`new_h` (scales focal
    /// lengths and principal point by the per-axis size ratio).
    pub fn scaled_to(&self, new_w: u32, new_h: u32) -> Intrinsics {
        let sx = new_w as f64 / self.width as f64;
        let sy = new_h as f64 / self.height as f64;
        Intrinsics {
            width: new_w,
            height: new_h,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
        }
    }

    /// Project a camera-space point (OpenCV axes) to pixels.
    pub fn project(&self, p: nalgebra::Vector3<f64>) -> Option<(f64, f64)> {
        if p.z <= 1e-9 {
            return None;
        }
        Some((self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }
}

/// A world-to-camera rigid transform, `x_cam = R · x_world + t`, with R as a
/// unit quaternion (w, x, y, z) exactly as COLMAP stores `QW QX QY QZ TX TY TZ`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Quaternion (w, x, y, z).
    pub qvec: [f64; 4],
    /// Translation.
    pub tvec: [f64; 3],
}

impl Default for Pose {
    fn default() -> Self {
        Pose {
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [0.0; 3],
        }
    }
}

impl Pose {
    /// Identity pose.
    pub fn identity() -> Self {
        Self::default()
    }

    /// Rotation matrix R (world to camera).
    pub fn rotation(&self) -> nalgebra::Matrix3<f64> {
        let [w, x, y, z] = self.qvec;
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        q.to_rotation_matrix().into_inner()
    }

    /// Translation vector t.
    pub fn translation(&self) -> nalgebra::Vector3<f64> {
        nalgebra::Vector3::from(self.tvec)
    }

    /// Build from a rotation matrix and translation (world to camera).
    pub fn from_rt(r: &nalgebra::Matrix3<f64>, t: &nalgebra::Vector3<f64>) -> Self {
        let rot = nalgebra::Rotation3::from_matrix_unchecked(*r);
        let q = nalgebra::UnitQuaternion::from_rotation_matrix(&rot);
        let mut qvec = [q.w, q.i, q.j, q.k];
        // COLMAP keeps w >= 0.
        if qvec[0] < 0.0 {
            qvec.iter_mut().for_each(|v| *v = -*v);
        }
        Pose {
            qvec,
            tvec: [t.x, t.y, t.z],
        }
    }

    /// Camera centre in world coordinates, `C = -Rᵀ t`.
    pub fn center(&self) -> nalgebra::Vector3<f64> {
        -(self.rotation().transpose() * self.translation())
    }

    /// 4×4 world-to-camera matrix.
    pub fn world_to_camera(&self) -> nalgebra::Matrix4<f64> {
        let mut m = nalgebra::Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rotation());
        m.fixed_view_mut::<3, 1>(0, 3)
            .copy_from(&self.translation());
        m
    }

    /// 4×4 camera-to-world matrix (OpenCV axes).
    pub fn camera_to_world(&self) -> nalgebra::Matrix4<f64> {
        let rt = self.rotation().transpose();
        let mut m = nalgebra::Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&rt);
        m.fixed_view_mut::<3, 1>(0, 3)
            .copy_from(&(-(rt * self.translation())));
        m
    }

    /// Transform a world point into camera coordinates.
    pub fn transform(&self, p: nalgebra::Vector3<f64>) -> nalgebra::Vector3<f64> {
        self.rotation() * p + self.translation()
    }

    /// A camera at `eye` looking at `target` with image "up" roughly `up`
    /// (world vector). OpenCV axes: camera y points down in the image.
    pub fn look_at(
        eye: nalgebra::Vector3<f64>,
        target: nalgebra::Vector3<f64>,
        up: nalgebra::Vector3<f64>,
    ) -> Self {
        let z = (target - eye).normalize();
        let x = z.cross(&up).normalize();
        let x = if x.iter().all(|v| v.is_finite()) {
            x
        } else {
            nalgebra::Vector3::x()
        };
        let y = z.cross(&x);
        // Rows of R are the camera axes expressed in world coordinates.
        let r = nalgebra::Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        let t = -(r * eye);
        Pose::from_rt(&r, &t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn model_ids_and_names_round_trip() {
        for (i, m) in CameraModel::ALL.iter().enumerate() {
            assert_eq!(m.id(), i as i32);
            assert_eq!(CameraModel::from_id(i as i32), Some(*m));
            assert_eq!(CameraModel::from_name(m.name()), Some(*m));
        }
        assert_eq!(CameraModel::from_id(99), None);
    }

    #[test]
    fn look_at_puts_target_on_optical_axis() {
        let eye = Vector3::new(1.0, -2.0, 3.0);
        let target = Vector3::new(0.5, 0.0, 0.0);
        let pose = Pose::look_at(eye, target, Vector3::new(0.0, 0.0, 1.0));
        let pc = pose.transform(target);
        assert!(pc.x.abs() < 1e-12 && pc.y.abs() < 1e-12 && pc.z > 0.0);
        assert!((pose.center() - eye).norm() < 1e-12);
        // World up (+z) appears above the centre: negative image y.
        let above = pose.transform(target + Vector3::new(0.0, 0.0, 0.1));
        assert!(above.y < 0.0);
    }

    #[test]
    fn camera_to_world_inverts_world_to_camera() {
        let pose = Pose::look_at(Vector3::new(2.0, 1.0, 0.5), Vector3::zeros(), Vector3::z());
        let prod = pose.camera_to_world() * pose.world_to_camera();
        assert!((prod - nalgebra::Matrix4::identity()).norm() < 1e-12);
    }
}
