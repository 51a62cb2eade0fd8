//! Circular beacons in 2D laser scans, and localisation from them (thesis §2.4-2.5).
//!
//! A beacon is a vertical cylinder of known radius `R` (0.125 m in the thesis), mounted on
//! a robot or standing in the room. Three detectors find such circles in one
//! [`LaserScan`](crate::cloud::LaserScan) and report their centres in the sensor frame:
//!
//! * [`detect_circles_lsq`]: the thesis' least-squares detector (§2.4.2), which uses what
//!   is special about range data (one viewpoint, beams in angle order): a circle is
//!   hypothesised behind every return, scored against its neighbouring returns, and the
//!   best hypotheses are refined by a quadratic fit of range against bearing;
//! * [`detect_circles_reflective`]: for beacons wrapped in retroreflective tape (§2.4.3):
//!   runs of bright returns, each refined by the same polar fit;
//! * [`detect_circles_rwht`]: the range-weighted Hough transform baseline (§2.4.1).
//!
//! The shared pieces are the [`Detection`] record, the polar quadratic fit
//! [`fit_circle_polar`] (2.13)-(2.15) and the known-radius geometric refinement
//! [`refine_circle`]. [`landmark`] turns beacons seen from two poses into the robot's pose
//! change (§2.5, Algorithm 1), with the thesis' ambiguity rules, speed limits and error
//! estimates.
//!
//! All quantities are metres and radians; the sensor frame has x forward and y left, and a
//! bearing is measured from x toward y.
//!
//! ```
//! use olmap::beacon::{detect_circles_lsq, LsqParams};
//! use olmap::cloud::LaserScan;
//!
//! // A 0.125 m cylinder 3 m ahead, seen by a noise-free 0.5° scanner, in front of a wall.
//! let (radius, center_x) = (0.125, 3.0);
//! let step = 0.5f64.to_radians();
//! let ranges = (0..121)
//!     .map(|i| {
//!         let a = -30f64.to_radians() + i as f64 * step;
//!         // Where the beam meets the circle, if it does; else the wall at x = 6.
//!         let b = center_x * a.cos();
//!         let disc = radius * radius - (center_x * a.sin()).powi(2);
//!         let r = if disc >= 0.0 { b - disc.sqrt() } else { 6.0 / a.cos() };
//!         r as f32
//!     })
//!     .collect();
//! let scan = LaserScan {
//!     angle_min: -30f64.to_radians(),
//!     angle_increment: step,
//!     range_min: 0.0,
//!     range_max: 8.0,
//!     ranges,
//!     intensities: None,
//!     time: 0.0,
//! };
//! let found = detect_circles_lsq(&scan, radius, &LsqParams::default());
//! assert_eq!(found.len(), 1);
//! assert!((found[0].center.x - center_x).abs() < 0.005);
//! assert!(found[0].center.y.abs() < 0.005);
//! ```

mod detection;
mod fit;
pub mod landmark;
mod lsq;
mod reflective;
mod report;
mod rwht;

pub use detection::Detection;
pub use fit::{
    circle_residual, fit_circle_polar, fit_circle_polar_or_flat, refine_circle, PolarFit,
};
pub use landmark::{pose_change_from_landmarks, LandmarkPose, Pose2};
pub use lsq::{detect_circles_lsq, LsqParams};
pub use reflective::{detect_circles_reflective, ReflectiveParams};
pub use report::{BeaconsReport, DetectionReport};
pub use rwht::{detect_circles_rwht, RwhtParams};
