//! Degraded odometry: the reference poses of a log with seeded noise on every relative
//! motion, and the matching information (inverse covariance) for odometry edges.
//!
//! The model (the one issue 23 and the data README suggest): for each step between
//! consecutive scans, with `d` the distance travelled and `a` the angle turned (radians),
//! the step's x and y are perturbed with σ = `distance_fraction · d` each and its heading
//! with σ = `degrees_per_unit · (d + a)` degrees. Steps are perturbed independently, so the
//! odometry pose drifts like a random walk; there is no systematic bias.

use crate::graph::Se2;
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// The smallest standard deviations the odometry information uses (a robot standing
/// still still has some uncertainty): 1 cm and 0.25°.
pub const ODOMETRY_SIGMA_FLOOR: (f64, f64) = (0.01, 0.25);

/// Seeded noise on relative motions.
///
/// ```
/// use olmap::graph::Se2;
/// use olmap::mapping::planar::OdometryNoise;
/// let truth: Vec<Se2> = (0..50).map(|i| Se2::new(0.1 * i as f64, 0.0, 0.0)).collect();
/// let noise = OdometryNoise { distance_fraction: 0.05, degrees_per_unit: 2.0 };
/// let a = noise.degrade(&truth, 7);
/// assert_eq!(a, noise.degrade(&truth, 7)); // seeded
/// assert_eq!(a[0], truth[0]); // the first pose is kept
/// assert!((a[49].x - truth[49].x).abs() > 1e-6); // the rest drift
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OdometryNoise {
    /// σ of x and y per step as a fraction of the distance travelled (0.05 = 5 %).
    pub distance_fraction: f64,
    /// σ of the heading per step, degrees per metre travelled and per radian turned.
    pub degrees_per_unit: f64,
}

impl OdometryNoise {
    /// No noise: the odometry is the reference.
    pub const NONE: OdometryNoise = OdometryNoise {
        distance_fraction: 0.0,
        degrees_per_unit: 0.0,
    };

    /// The standard deviations `(σ_xy metres, σ_theta radians)` of one step `step`.
    pub fn sigmas(&self, step: &Se2) -> (f64, f64) {
        let d = step.x.hypot(step.y);
        let a = step.theta.abs();
        (
            self.distance_fraction * d,
            (self.degrees_per_unit * (d + a)).to_radians(),
        )
    }

    /// Odometry from reference poses: the first pose kept, every relative motion perturbed
    /// with this model, the perturbed motions chained. Deterministic for a seed.
    pub fn degrade(&self, reference: &[Se2], seed: u64) -> Vec<Se2> {
        let mut out = Vec::with_capacity(reference.len());
        let Some(first) = reference.first() else {
            return out;
        };
        out.push(*first);
        let mut current = *first;
        for (k, w) in reference.windows(2).enumerate() {
            let step = w[0].inverse().compose(&w[1]);
            let (s_xy, s_th) = self.sigmas(&step);
            let k = k as u64;
            let noisy = Se2::new(
                step.x + s_xy * normal(seed, 3 * k),
                step.y + s_xy * normal(seed, 3 * k + 1),
                step.theta + s_th * normal(seed, 3 * k + 2),
            );
            current = current.compose(&noisy);
            out.push(current);
        }
        out
    }

    /// The information matrix over `(x, y, theta)` of an odometry step under this model,
    /// with the standard deviations floored at [`ODOMETRY_SIGMA_FLOOR`].
    pub fn information(&self, step: &Se2) -> Matrix3<f64> {
        let (s_xy, s_th) = self.sigmas(step);
        let s_xy = s_xy.max(ODOMETRY_SIGMA_FLOOR.0);
        let s_th = s_th.max(ODOMETRY_SIGMA_FLOOR.1.to_radians());
        Matrix3::from_diagonal(&nalgebra::Vector3::new(
            1.0 / (s_xy * s_xy),
            1.0 / (s_xy * s_xy),
            1.0 / (s_th * s_th),
        ))
    }
}

/// A standard normal number for `(seed, counter)`: counter-based (each step's noise depends
/// only on the seed and the step's index, never on how many numbers were drawn before), from
/// two SplitMix64 hashes through Box-Muller. The mapping layer keeps its own generator: the
/// simulator's lives in a layer above it.
fn normal(seed: u64, counter: u64) -> f64 {
    let u1 = uniform(seed, 2 * counter) + 0.5 / (1u64 << 53) as f64;
    let u2 = uniform(seed, 2 * counter + 1);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A uniform number in `[0, 1)` for `(seed, counter)` (counter-based, see [`normal`]).
pub(crate) fn uniform(seed: u64, counter: u64) -> f64 {
    fn mix(mut z: u64) -> u64 {
        z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    (mix(seed ^ mix(counter)) >> 11) as f64 / (1u64 << 53) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_noise_has_the_stated_spread() {
        // 2000 steps of 1 m straight ahead: the x errors of the steps have σ ≈ 5 cm and the
        // heading errors σ ≈ 2°.
        let truth: Vec<Se2> = (0..2001).map(|i| Se2::new(i as f64, 0.0, 0.0)).collect();
        let noise = OdometryNoise {
            distance_fraction: 0.05,
            degrees_per_unit: 2.0,
        };
        let odo = noise.degrade(&truth, 3);
        let (mut sx, mut st) = (0.0, 0.0);
        for w in odo.windows(2) {
            let step = w[0].inverse().compose(&w[1]);
            sx += (step.x - 1.0).powi(2);
            st += step.theta.powi(2);
        }
        let sx = (sx / 2000.0).sqrt();
        let st = (st / 2000.0).sqrt().to_degrees();
        assert!((sx - 0.05).abs() < 0.005, "σx {sx}");
        assert!((st - 2.0).abs() < 0.2, "σθ {st}");
    }
}
