//! Rigid-body geometry: poses, Euler angles, pose errors, bounding boxes and pose files.
//!
//! Conventions (the same everywhere in olmap):
//! * units are metres and radians; degrees appear only where a name says so (`_deg`);
//! * frames are right-handed, x forward, y left, z up;
//! * a pose `T_a_b` maps points of frame `b` into frame `a`: `p_a = R p_b + t`;
//! * Euler angles are ZYX: `R = Rz(yaw) Ry(pitch) Rx(roll)`.

mod aabb;
mod euler;
mod frames_3dtk;
mod metrics;
mod pose;
pub mod pose_file;
mod pose_json;

pub use aabb::Aabb;
pub use euler::{rotation_from_yaw_pitch_roll, wrap_angle, yaw_pitch_roll_from_rotation};
pub use frames_3dtk::{
    point_3dtk_cm_from_rh_m, point_rh_m_from_3dtk_cm, pose_3dtk_cm_from_rh_m,
    pose_rh_m_from_3dtk_cm,
};
pub use metrics::PoseError;
pub use pose::Pose;
pub use pose_file::{NamedPose, PoseList};
pub use pose_json::{NamedPoseJson, PoseJson};

mod voxel;
pub use voxel::{key_range_error, VoxelKey};
