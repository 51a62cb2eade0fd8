//! The ray-trace sensor model of a 2D laser scanner, in log odds (thesis (3.14)-(3.28)).
//!
//! ## From the thesis' probabilities to log odds
//! The update of one cell `m` by one reading `l` is Bayes' rule (3.22),
//! `p(m|l) = (1 + p(l|¬m) p(¬m) / (p(l|m) p(m)))^-1`. In odds (3.23)-(3.26) it is a
//! product, `o(m|l) = p(l|m) / p(l|¬m) · o(m)`, and in log odds (3.27)-(3.28) a sum:
//!
//! `log o(m|l) = log p(l|m) - log p(l|¬m) + log o(m)`.
//!
//! So each kind of reading adds a constant, the log of its likelihood ratio:
//! * a beam **ending** in the cell adds `l_occ = ln(p(hit|m) / p(hit|¬m))`;
//! * a beam **passing through** the cell adds `l_free = ln(p(pass|m) / p(pass|¬m))`.
//!
//! (3.16) writes the same update with one number, the reading's "likelihood" `L`, as
//! `P = (1 + (1 - L)(1 - prior) / (L prior))^-1`, i.e. `logit P = logit L + logit prior`:
//! `L` is the occupancy the reading alone would give a cell of prior 0.5, and
//! `L / (1 - L)` is the likelihood ratio above. The defaults take `L = 0.7` for a hit (a
//! return is 7/3 times as likely from an occupied cell as from a free one, which allows
//! for mixed pixels and the 2 cm range noise of thesis §4.4.1 at 5 cm cells) and `L = 0.3`
//! for a pass (symmetric: a beam crossing a cell is 7/3 times as likely when it is free):
//! `l_occ = ln(0.7/0.3) = 0.847`, `l_free = ln(0.3/0.7) = -0.847`. One hit makes a cell
//! occupied for the ROS thresholds (`p = 0.7 > 0.65`), two passes make it free
//! (`p = 0.155 < 0.196`), and a hit and a pass cancel.
//!
//! The thesis warns that successive readings from one place are not independent, so
//! certainty must not grow without bound: log odds are clamped to
//! `[l_min, l_max] = [logit 0.12, logit 0.97] = [-1.99, 3.48]`, which lets a changed cell
//! be revised by a few contrary readings. The thesis truncates ranges at 8 m (§4.4.1),
//! the default `max_range`.

use crate::error::{Error, Result};

/// The log-odds ray-trace sensor model (see the module documentation for the derivation).
///
/// ```
/// use olmap::grid2d::SensorModel2d;
/// let m = SensorModel2d::default();
/// assert!((m.l_occ - (0.7f32 / 0.3).ln()).abs() < 1e-6);
/// assert!((SensorModel2d::probability(m.l_occ) - 0.7).abs() < 1e-6);
/// let strict = SensorModel2d::from_probabilities(0.9, 0.2, 0.1, 0.99, 5.0).unwrap();
/// assert!(strict.l_free < m.l_free);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorModel2d {
    /// Log odds added to the cell where a beam ends (> 0).
    pub l_occ: f32,
    /// Log odds added to each cell a beam passes through (< 0).
    pub l_free: f32,
    /// Lower clamp of a cell's log odds (< 0).
    pub l_min: f32,
    /// Upper clamp of a cell's log odds (> 0).
    pub l_max: f32,
    /// Longest range used, metres: farther returns and beams with no return only clear
    /// free space up to this range.
    pub max_range: f64,
}

impl Default for SensorModel2d {
    fn default() -> Self {
        SensorModel2d {
            l_occ: Self::logit(0.7),
            l_free: Self::logit(0.3),
            l_min: Self::logit(0.12),
            l_max: Self::logit(0.97),
            max_range: 8.0,
        }
    }
}

impl SensorModel2d {
    /// The model from probabilities: `hit` and `pass` are the occupancies a single hit or
    /// pass gives a cell of prior 0.5 (the "likelihood" of (3.16)), `clamp_min` and
    /// `clamp_max` the extreme probabilities a cell may reach.
    pub fn from_probabilities(
        hit: f64,
        pass: f64,
        clamp_min: f64,
        clamp_max: f64,
        max_range: f64,
    ) -> Result<Self> {
        for (name, p) in [
            ("hit", hit),
            ("pass", pass),
            ("clamp_min", clamp_min),
            ("clamp_max", clamp_max),
        ] {
            if !(p > 0.0 && p < 1.0) {
                return Err(Error::InvalidArgument(format!(
                    "sensor model probability {name} must be in (0, 1), got {p}"
                )));
            }
        }
        let m = SensorModel2d {
            l_occ: Self::logit(hit),
            l_free: Self::logit(pass),
            l_min: Self::logit(clamp_min),
            l_max: Self::logit(clamp_max),
            max_range,
        };
        m.validate()?;
        Ok(m)
    }

    /// Checks `l_occ > 0 > l_free`, `l_min < 0 < l_max` and a finite positive `max_range`.
    pub fn validate(&self) -> Result<()> {
        let ok = self.l_occ > 0.0
            && self.l_free < 0.0
            && self.l_min < 0.0
            && self.l_max > 0.0
            && self.l_occ.is_finite()
            && self.l_free.is_finite()
            && self.l_min.is_finite()
            && self.l_max.is_finite()
            && self.max_range.is_finite()
            && self.max_range > 0.0;
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidArgument(format!(
                "sensor model needs l_occ > 0 > l_free, l_min < 0 < l_max (all finite) and \
                 max_range > 0 m, got {self:?}"
            )))
        }
    }

    /// Log odds of a probability, `ln(p / (1 - p))` (3.23).
    pub fn logit(p: f64) -> f32 {
        (p / (1.0 - p)).ln() as f32
    }

    /// Probability of log odds `l`, `1 / (1 + e^-l)` (3.24).
    pub fn probability(l: f32) -> f64 {
        1.0 / (1.0 + (-(l as f64)).exp())
    }
}
