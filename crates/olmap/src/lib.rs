//! # olmap: 3D mapping and localisation for one or many mobile robots
//!
//! olmap implements the system of J. Ryde's thesis *Cooperative 3D Mapping and Localisation
//! of Multiple Mobile Robots*: sparse hashed voxel maps ("occupancy lists"), global scan
//! alignment with no initial guess, batch and cooperative map building. This crate holds all
//! the computation; the `olmap` command-line program (crate `olmap-cli`) is a thin shell
//! around it. The library never prints and never exits the process.
//!
//! ## The pieces so far
//! * [`geometry`]: the rigid transform [`geometry::Pose`], ZYX Euler angles, pose errors,
//!   voxel keys and the pose list file format;
//! * [`cloud`]: [`cloud::PointCloud`] and its filters;
//! * [`io`]: readers and writers for the scan formats robots produce (PCD, PLY, XYZ text,
//!   3DTK, CSV tables, KITTI `.bin`, OctoMap ScanGraph, LAS/LAZ), chosen by file name and
//!   content.
//!
//! ## Conventions
//! Metres, seconds and radians; right-handed frames with x forward, y left, z up; `T_a_b`
//! maps points of frame b into frame a (`p_a = R p_b + t`); Euler angles are ZYX
//! (`R = Rz(yaw) Ry(pitch) Rx(roll)`); voxel keys are `floor(coord / resolution)`.
//!
//! ## Quick start
//! ```
//! use olmap::cloud::PointCloud;
//! use olmap::io::{self, CloudFormat, WriteOptions};
//! use nalgebra::Point3;
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("scan.pcd");
//! let cloud = PointCloud::from_points(vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0)]);
//! io::write_cloud(&path, &cloud, &WriteOptions::default()).unwrap();
//! let loaded = io::read_cloud(&path).unwrap();
//! assert_eq!(loaded.report.format, CloudFormat::Pcd);
//! assert_eq!(loaded.cloud.points(), cloud.points());
//! ```

#![warn(missing_docs)]

pub mod align;
pub mod beacon;
#[cfg(feature = "test-support")]
pub mod bench;
pub mod cloud;
pub mod error;
pub mod file;
#[cfg(any(test, feature = "test-support"))]
pub mod fixtures;
#[cfg(any(test, feature = "test-support"))]
pub mod fuzz;
pub mod geometry;
pub mod graph;
pub mod grid2d;
pub mod guard;
pub mod io;
pub mod limits;
pub mod mapping;
pub mod occupancy;
pub mod progress;
#[cfg(feature = "render")]
pub mod render;
#[cfg(feature = "render")]
pub mod report;
pub mod scanner;
pub mod sim;
pub mod team;
#[cfg(any(test, feature = "test-support"))]
pub mod test_data;

pub use error::{Error, ParseError, Result};
