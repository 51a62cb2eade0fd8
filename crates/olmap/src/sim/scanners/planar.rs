//! A 2D laser scanner (SICK LMS 200-like).

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::noise::{measure, Beam, RangeNoise};
use crate::cloud::LaserScan;
use crate::geometry::Pose;
use crate::sim::{Object, SimRng, World};

/// A 2D scanner sweeping `fov` in steps of `step` in the sensor's xy plane, centred on the
/// sensor's x axis: beam `i` of `round(fov / step) + 1` points at `-fov/2 + i step` from x
/// toward y.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarScanner {
    /// Field of view, radians.
    pub fov: f64,
    /// Angle between beams, radians.
    pub step: f64,
    /// Range noise; its `max_range` is the scan's `range_max`.
    pub noise: RangeNoise,
}

impl PlanarScanner {
    /// SICK LMS 200 at 180° and 0.5° (361 beams), 8 m range (millimetre mode), default
    /// noise (2 cm).
    pub fn sick_180_half_degree() -> Self {
        PlanarScanner {
            fov: 180f64.to_radians(),
            step: 0.5f64.to_radians(),
            noise: RangeNoise::default().with_max_range(8.0),
        }
    }

    /// SICK LMS 200 at 100° and 0.25° (401 beams), 8 m range, default noise (2 cm).
    pub fn sick_100_quarter_degree() -> Self {
        PlanarScanner {
            fov: 100f64.to_radians(),
            step: 0.25f64.to_radians(),
            noise: RangeNoise::default().with_max_range(8.0),
        }
    }

    /// Number of beams, `round(fov / step) + 1`.
    pub fn beams(&self) -> usize {
        (self.fov / self.step).round() as usize + 1
    }

    /// One sweep in the sensor frame: ranges (`f32::INFINITY` for no return) and
    /// intensities (0 for no return), `range_min` 0, `range_max` the noise's `max_range`,
    /// `time` 0 (set it to the scan's time). Beam `i` draws its noise from
    /// `SimRng::for_item(seed, stream, i)`; its mixed-pixel sub-ray is offset by half a
    /// step.
    pub fn scan(
        &self,
        world: &World,
        extra: &[Object],
        t_world_sensor: &Pose,
        seed: u64,
        stream: u64,
    ) -> LaserScan {
        let n = self.beams();
        let angle_min = -0.5 * self.fov;
        let origin = Point3::from(t_world_sensor.translation());
        let rot = t_world_sensor.rotation();
        let dir = |a: f64| rot * Vector3::new(a.cos(), a.sin(), 0.0);
        let results: Vec<Option<(f32, f32)>> = (0..n)
            .into_par_iter()
            .with_min_len(64)
            .map(|i| {
                let a = angle_min + i as f64 * self.step;
                let main = Beam {
                    origin,
                    dir: dir(a),
                    before: 0.0,
                };
                let sub = Beam {
                    dir: dir(a + 0.5 * self.step),
                    ..main
                };
                let mut rng = SimRng::for_item(seed, stream, i as u64);
                measure(world, extra, &main, Some(&sub), &self.noise, &mut rng)
                    .map(|r| (r.range as f32, r.intensity))
            })
            .collect();
        let (ranges, intensities) = results
            .into_iter()
            .map(|r| r.unwrap_or((f32::INFINITY, 0.0)))
            .unzip();
        LaserScan {
            angle_min,
            angle_increment: self.step,
            range_min: 0.0,
            range_max: self.noise.max_range,
            ranges,
            intensities: Some(intensities),
            time: 0.0,
        }
    }
}
