//! A multi-beam spinning lidar (Velodyne-like).

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::noise::{measure, Beam, RangeNoise};
use crate::cloud::PointCloud;
use crate::geometry::Pose;
use crate::sim::{Object, SimRng, World};

/// A spinning lidar: `beams` lasers fanned evenly in elevation from `elevation_min` to
/// `elevation_max`, turning a full circle about the sensor's z axis in steps of
/// `azimuth_step` (azimuth 0 along the sensor's x axis, positive toward y).
///
/// ```
/// use nalgebra::{Point3, Vector3};
/// use olmap::geometry::Pose;
/// use olmap::sim::{room_shell, Material, Object, SpinningLidar, World};
/// let objects = room_shell(Point3::origin(), Vector3::new(8.0, 6.0, 3.0), 0.2, true)
///     .into_iter()
///     .map(|shape| Object { shape, material: Material::WALL, id: 0 })
///     .collect();
/// let world = World::new("room", objects);
/// let lidar = SpinningLidar { azimuth_step: 4f64.to_radians(), ..SpinningLidar::default() };
/// let pose = Pose::from_xyz_ypr(4.0, 3.0, 1.0, 0.0, 0.0, 0.0);
/// let cloud = lidar.scan(&world, &[], &pose, 1, 0);
/// assert_eq!(cloud.len(), 32 * 90); // a closed room returns every beam
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct SpinningLidar {
    /// Number of lasers (default 32).
    pub beams: usize,
    /// Elevation of the lowest laser, radians (default -30°).
    pub elevation_min: f64,
    /// Elevation of the highest laser, radians (default +10°).
    pub elevation_max: f64,
    /// Azimuth between firings, radians (default 0.4°).
    pub azimuth_step: f64,
    /// Range noise.
    pub noise: RangeNoise,
}

impl Default for SpinningLidar {
    fn default() -> Self {
        SpinningLidar {
            beams: 32,
            elevation_min: (-30f64).to_radians(),
            elevation_max: 10f64.to_radians(),
            azimuth_step: 0.4f64.to_radians(),
            noise: RangeNoise::default(),
        }
    }
}

impl SpinningLidar {
    /// Firings per revolution: `round(2 pi / azimuth_step)`, at least 1; they are spread
    /// evenly over the circle.
    pub fn azimuths(&self) -> usize {
        ((std::f64::consts::TAU / self.azimuth_step).round() as usize).max(1)
    }

    /// Elevation of laser `b`, radians.
    pub fn elevation(&self, b: usize) -> f64 {
        if self.beams > 1 {
            self.elevation_min
                + (self.elevation_max - self.elevation_min) * b as f64 / (self.beams - 1) as f64
        } else {
            0.5 * (self.elevation_min + self.elevation_max)
        }
    }

    /// Unit direction (sensor frame) at azimuth `azimuth` and elevation `elevation`.
    fn direction(azimuth: f64, elevation: f64) -> Vector3<f64> {
        let (sa, ca) = azimuth.sin_cos();
        let (se, ce) = elevation.sin_cos();
        Vector3::new(ce * ca, ce * sa, se)
    }

    /// One revolution: the returns as points in the sensor frame (origin zero) with their
    /// intensities, in firing order (azimuth by azimuth, lowest laser first). Beam
    /// `a * beams + b` (azimuth `a`, laser `b`) draws its noise from
    /// `SimRng::for_item(seed, stream, a * beams + b)`.
    pub fn scan(
        &self,
        world: &World,
        extra: &[Object],
        t_world_sensor: &Pose,
        seed: u64,
        stream: u64,
    ) -> PointCloud {
        let n_az = self.azimuths();
        let step = std::f64::consts::TAU / n_az as f64;
        let elevations: Vec<f64> = (0..self.beams).map(|b| self.elevation(b)).collect();
        let origin = Point3::from(t_world_sensor.translation());
        let rot = t_world_sensor.rotation();
        let results: Vec<Option<(Point3<f32>, f32)>> = (0..n_az * self.beams)
            .into_par_iter()
            .with_min_len(256)
            .map(|i| {
                let (a, b) = (i / self.beams, i % self.beams);
                let az = a as f64 * step;
                let dir = Self::direction(az, elevations[b]);
                let main = Beam {
                    origin,
                    dir: rot * dir,
                    before: 0.0,
                };
                let sub = Beam {
                    dir: rot * Self::direction(az + 0.5 * step, elevations[b]),
                    ..main
                };
                let mut rng = SimRng::for_item(seed, stream, i as u64);
                measure(world, extra, &main, Some(&sub), &self.noise, &mut rng).map(|r| {
                    let p = dir * r.range;
                    (Point3::new(p.x as f32, p.y as f32, p.z as f32), r.intensity)
                })
            })
            .collect();
        collect_cloud(results)
    }
}

/// Packs the returns into a cloud with intensities (sensor at the origin).
pub(super) fn collect_cloud(results: Vec<Option<(Point3<f32>, f32)>>) -> PointCloud {
    let (pts, ints): (Vec<_>, Vec<_>) = results.into_iter().flatten().unzip();
    let mut cloud = PointCloud::from_points(pts);
    cloud
        .set_intensity(Some(ints))
        .expect("one intensity per point");
    cloud
}
