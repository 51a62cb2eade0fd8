//! [`LogOddsModel`]: OctoMap's sensor model (hit and miss probabilities, clamping, the
//! occupancy threshold, maximum range) and its log-odds in `f32`, as OctoMap computes them.

use crate::error::{Error, Result};

/// The stored value of a voxel never observed (a NaN: no update ever makes one).
pub(super) const UNKNOWN: f32 = f32::NAN;

/// Whether a stored value is [`UNKNOWN`].
#[inline]
pub(super) fn is_unknown(v: f32) -> bool {
    v.is_nan()
}

/// The largest log-odds magnitude a model may use (clamping bounds and updates).
const MAX_LOG_ODDS: f64 = 30.0;

/// The probabilistic sensor model of a log-odds map, with OctoMap's defaults and
/// semantics (Hornung et al., "OctoMap", Autonomous Robots 2013, eq. (2)-(4)).
///
/// A voxel starts unknown. An observation adds `logit(prob_hit)` (the endpoint of a ray)
/// or `logit(prob_miss)` (a voxel the ray passed through) to its log-odds, starting from 0
/// (probability 0.5), and the result is clamped to `[logit(clamp_min), logit(clamp_max)]`.
/// A known voxel is occupied when its log-odds is at least `logit(occupancy_threshold)`,
/// free otherwise.
///
/// ```
/// use olmap::occupancy::LogOddsModel;
/// let m = LogOddsModel::default();
/// assert_eq!((m.prob_hit, m.prob_miss), (0.7, 0.4));
/// assert!(m.validate().is_ok());
/// assert!(LogOddsModel { prob_hit: 0.3, ..m }.validate().is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogOddsModel {
    /// Probability that a voxel holding a ray's endpoint is occupied, in (0.5, 1).
    /// Default 0.7 (OctoMap).
    pub prob_hit: f64,
    /// Probability that a voxel a ray passed through is occupied, in (0, 0.5). Default 0.4
    /// (OctoMap).
    pub prob_miss: f64,
    /// Lower clamping bound, in (0, occupancy_threshold]. Default 0.1192 (OctoMap).
    pub clamp_min: f64,
    /// Upper clamping bound, in [occupancy_threshold, 1). Default 0.971 (OctoMap).
    pub clamp_max: f64,
    /// Known voxels at or above this probability are occupied, in (0, 1). Default 0.5
    /// (OctoMap).
    pub occupancy_threshold: f64,
    /// Rays longer than this (metres) are cut here and give free space only, no hit.
    /// Default: no limit (OctoMap's `maxrange = -1`).
    pub max_range: f64,
}

impl Default for LogOddsModel {
    fn default() -> Self {
        LogOddsModel {
            prob_hit: 0.7,
            prob_miss: 0.4,
            clamp_min: 0.1192,
            clamp_max: 0.971,
            occupancy_threshold: 0.5,
            max_range: f64::INFINITY,
        }
    }
}

/// `ln(p / (1 - p))`.
pub fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

/// A model's log-odds in `f32`, as OctoMap holds them (`logodds(double)` returns a
/// float): what insertion and queries use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct F32Model {
    pub hit: f32,
    pub miss: f32,
    pub min: f32,
    pub max: f32,
    pub threshold: f32,
}

impl F32Model {
    /// A voxel's value after one observation (`delta` = `hit` or `miss`): OctoMap's
    /// `updateNodeLogOdds`, a new voxel starting from 0, the sum clamped.
    #[inline]
    pub fn update(&self, value: f32, delta: f32) -> f32 {
        let base = if is_unknown(value) { 0.0 } else { value };
        let v = base + delta;
        if v < self.min {
            self.min
        } else if v > self.max {
            self.max
        } else {
            v
        }
    }
}

fn to_f32(l: f64) -> f32 {
    l as f32
}

impl LogOddsModel {
    /// Checks the model: probabilities inside their ranges (see the fields), log-odds no
    /// larger than 30 in magnitude, `max_range > 0` (infinite allowed);
    /// [`Error::InvalidArgument`] names what is wrong.
    pub fn validate(&self) -> Result<()> {
        let open = |p: f64| p > 0.0 && p < 1.0;
        let problem = if !(open(self.prob_hit) && self.prob_hit > 0.5) {
            Some("prob_hit must be in (0.5, 1)")
        } else if !(open(self.prob_miss) && self.prob_miss < 0.5) {
            Some("prob_miss must be in (0, 0.5)")
        } else if !open(self.occupancy_threshold) {
            Some("occupancy_threshold must be in (0, 1)")
        } else if !(open(self.clamp_min) && self.clamp_min <= self.occupancy_threshold) {
            Some("clamp_min must be in (0, occupancy_threshold]")
        } else if !(open(self.clamp_max) && self.clamp_max >= self.occupancy_threshold) {
            Some("clamp_max must be in [occupancy_threshold, 1)")
        } else if [
            self.prob_hit,
            self.prob_miss,
            self.clamp_min,
            self.clamp_max,
            self.occupancy_threshold,
        ]
        .iter()
        .any(|&p| logit(p).abs() > MAX_LOG_ODDS)
        {
            Some("every probability must have a log-odds within +-30")
        } else if self.max_range.is_nan() || self.max_range <= 0.0 {
            Some("max_range must be > 0 metres")
        } else {
            None
        };
        match problem {
            Some(p) => Err(Error::InvalidArgument(format!(
                "log-odds sensor model: {p}, got {self:?}"
            ))),
            None => Ok(()),
        }
    }

    /// The model's log-odds in `f32` (call after [`LogOddsModel::validate`]).
    pub(super) fn f32_model(&self) -> F32Model {
        F32Model {
            hit: to_f32(logit(self.prob_hit)),
            miss: to_f32(logit(self.prob_miss)),
            min: to_f32(logit(self.clamp_min)),
            max: to_f32(logit(self.clamp_max)),
            threshold: to_f32(logit(self.occupancy_threshold)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octomap_defaults_as_floats() {
        let q = LogOddsModel::default().f32_model();
        // logit(0.7) = 0.8473, logit(0.4) = -0.4055, logit(0.1192) = -2.0000,
        // logit(0.971) = 3.5110.
        assert!((q.hit - 0.847_298).abs() < 1e-6 && (q.miss + 0.405_465).abs() < 1e-6);
        assert!((q.min + 2.000_028).abs() < 1e-6 && (q.max - 3.511_031).abs() < 1e-6);
        assert_eq!(q.threshold, 0.0);
        // Clamped both ways, and an unknown voxel starts from 0.
        assert_eq!(q.update(UNKNOWN, q.miss), q.miss);
        assert_eq!(q.update(3.0, q.hit), q.max);
        assert_eq!(q.update(-1.9, q.miss), q.min);
    }

    #[test]
    fn bad_models_are_refused() {
        let m = LogOddsModel::default();
        for bad in [
            LogOddsModel {
                prob_miss: 0.5,
                ..m
            },
            LogOddsModel {
                clamp_min: 0.6,
                ..m
            },
            LogOddsModel {
                clamp_max: 0.4,
                ..m
            },
            LogOddsModel {
                prob_hit: 1.0 - 1e-15,
                ..m
            },
            LogOddsModel {
                max_range: 0.0,
                ..m
            },
            LogOddsModel {
                max_range: f64::NAN,
                ..m
            },
            LogOddsModel {
                occupancy_threshold: f64::NAN,
                ..m
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }
}
