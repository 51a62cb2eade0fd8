//! [`LogOddsModel`]: OctoMap's sensor model (hit and miss probabilities, clamping, the
//! occupancy threshold, maximum range) and its fixed-point log-odds.

use crate::error::{Error, Result};

/// Log-odds are stored as `i16` in units of `1 / LOG_ODDS_SCALE`: exact integer additions
/// and clamping, so a map does not depend on the order of updates or the thread count.
pub const LOG_ODDS_SCALE: f32 = 1024.0;

/// The stored value of a voxel never observed.
pub(super) const UNKNOWN: i16 = i16::MIN;

/// The largest log-odds magnitude a model may use (clamping bounds and updates): the
/// fixed-point range less a margin.
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

/// A model in fixed point: what insertion and queries use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Quantised {
    pub hit: i16,
    pub miss: i16,
    pub min: i16,
    pub max: i16,
    pub threshold: i16,
}

impl Quantised {
    /// A voxel's value after one observation (`delta` = `hit` or `miss`).
    #[inline]
    pub fn update(&self, value: i16, delta: i16) -> i16 {
        let base = if value == UNKNOWN { 0 } else { value };
        base.saturating_add(delta).clamp(self.min, self.max)
    }
}

fn quantise(l: f64) -> i16 {
    (l * f64::from(LOG_ODDS_SCALE)).round() as i16
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

    /// The model in fixed point (call after [`LogOddsModel::validate`]).
    pub(super) fn quantised(&self) -> Quantised {
        Quantised {
            hit: quantise(logit(self.prob_hit)),
            miss: quantise(logit(self.prob_miss)),
            min: quantise(logit(self.clamp_min)),
            max: quantise(logit(self.clamp_max)),
            threshold: quantise(logit(self.occupancy_threshold)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octomap_defaults_in_fixed_point() {
        let q = LogOddsModel::default().quantised();
        // logit(0.7) = 0.8473, logit(0.4) = -0.4055, logit(0.1192) = -1.9996,
        // logit(0.971) = 3.5110: within half a unit of the scale.
        assert_eq!((q.hit, q.miss, q.threshold), (868, -415, 0));
        assert_eq!((q.min, q.max), (-2048, 3595));
        // Clamped both ways, and an unknown voxel starts from 0.
        assert_eq!(q.update(UNKNOWN, q.miss), -415);
        assert_eq!(q.update(3500, q.hit), 3595);
        assert_eq!(q.update(-2000, q.miss), -2048);
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
