//! Simulated scanners: a multi-beam spinning lidar, a 2D scanner and the rotating-mirror 3D
//! scanner of thesis §4.3, all casting rays through a [`World`](super::World) (and extra
//! moving objects such as the other robots) from a sensor pose `T_world_sensor`, and all
//! returning their data in the sensor frame.
//!
//! Every scanner shares the noise model [`RangeNoise`] (Gaussian range noise, dropouts,
//! mixed pixels at depth edges, thesis §4.4.1) and the intensity model: a diffuse surface
//! returns `reflectivity cos(incidence)`, retroreflective tape returns
//! [`RETRO_INTENSITY`] (about 2) while the incidence is below 50° (thesis §3.2). Each scan
//! takes a `seed` and a `stream` (e.g. the scan number); every beam draws its noise from its
//! own generator `SimRng::for_item(seed, stream, beam)`, so the same inputs give bit-identical
//! output whatever the number of threads casting the rays.

mod lidar;
mod mirror;
mod noise;
mod planar;

pub use lidar::SpinningLidar;
pub use mirror::MirrorScanner;
pub use noise::{RangeNoise, RETRO_INTENSITY, RETRO_MAX_INCIDENCE};
pub use planar::PlanarScanner;
