//! [`PoseJson`]: how a pose appears in olmap's JSON reports.

use serde::{Deserialize, Serialize};

use super::pose::Pose;

/// A pose in a JSON report: the translation in metres and the ZYX Euler angles in
/// degrees, `{"xyz_m": [x, y, z], "yaw_pitch_roll_deg": [yaw, pitch, roll]}`.
///
/// ```
/// use olmap::geometry::{Pose, PoseJson};
/// let p = Pose::from_xyz_ypr(1.0, 2.0, 0.5, 90f64.to_radians(), 0.0, 0.0);
/// let j = PoseJson::from(&p);
/// assert_eq!(j.xyz_m, [1.0, 2.0, 0.5]);
/// assert!((j.yaw_pitch_roll_deg[0] - 90.0).abs() < 1e-9);
/// let back = j.to_pose();
/// assert!((back.translation() - p.translation()).norm() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseJson {
    /// Translation, metres.
    pub xyz_m: [f64; 3],
    /// Yaw, pitch, roll (ZYX), degrees.
    pub yaw_pitch_roll_deg: [f64; 3],
}

impl From<&Pose> for PoseJson {
    fn from(p: &Pose) -> Self {
        let t = p.translation();
        let (y, pi, r) = p.yaw_pitch_roll();
        PoseJson {
            xyz_m: [t.x, t.y, t.z],
            yaw_pitch_roll_deg: [y.to_degrees(), pi.to_degrees(), r.to_degrees()],
        }
    }
}

impl PoseJson {
    /// The pose back (angles converted to radians).
    pub fn to_pose(&self) -> Pose {
        let [x, y, z] = self.xyz_m;
        let [yaw, pitch, roll] = self.yaw_pitch_roll_deg.map(f64::to_radians);
        Pose::from_xyz_ypr(x, y, z, yaw, pitch, roll)
    }
}

/// A named pose in full, as `olmap poses --json` lists it: the name, [`PoseJson`]'s
/// fields and the row-major 4x4 matrix of the transform.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedPoseJson {
    /// The pose's name (scan name or file stem).
    pub name: String,
    /// Translation and angles.
    #[serde(flatten)]
    pub pose: PoseJson,
    /// The 4x4 homogeneous matrix, row by row.
    pub matrix: [[f64; 4]; 4],
}

impl NamedPoseJson {
    /// The named pose `p`.
    pub fn new(name: &str, p: &Pose) -> Self {
        let m = p.to_matrix4();
        NamedPoseJson {
            name: name.to_string(),
            pose: PoseJson::from(p),
            matrix: std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)])),
        }
    }
}
