//! `olmap.detect_beacons` (circular beacons in a 2D laser scan) and
//! `olmap.mutual_localisation` (two robots' relative pose from a two-way sighting).

use numpy::{AllowTypeChange, PyArrayLike1};
use olmap::beacon::{
    detect_circles_lsq, detect_circles_reflective, detect_circles_rwht, BeaconsReport, LsqParams,
    ReflectiveParams, RwhtParams,
};
use olmap::cloud::LaserScan;
use olmap::team::{mutual_pose, MutualObservation, MutualParams, MutualReport};
use pyo3::prelude::*;

use crate::convert::to_python;
use crate::errors::{value_error, IntoPy};

fn floats(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<f64>> {
    let arr: PyArrayLike1<'_, f64, AllowTypeChange> = obj
        .extract()
        .map_err(|_| value_error(format!("{what}: expected a 1-D array of numbers")))?;
    Ok(arr.as_array().iter().copied().collect())
}

/// How far (as a fraction of the angle step) a beam's angle may be from the evenly spaced
/// sweep a laser scanner makes.
const ANGLE_SLACK: f64 = 1e-3;

/// The laser scan of `ranges` at evenly spaced `angles`.
fn laser_scan(
    ranges: Vec<f64>,
    angles: Vec<f64>,
    intensities: Option<Vec<f64>>,
) -> PyResult<LaserScan> {
    let n = ranges.len();
    if angles.len() != n {
        return Err(value_error(format!(
            "angles: {} angles for {n} ranges",
            angles.len()
        )));
    }
    if n < 2 {
        return Err(value_error(format!(
            "ranges: a scan needs at least 2 beams, got {n}"
        )));
    }
    if let Some(i) = &intensities {
        if i.len() != n {
            return Err(value_error(format!(
                "intensities: {} values for {n} ranges",
                i.len()
            )));
        }
    }
    let step = (angles[n - 1] - angles[0]) / (n - 1) as f64;
    if let Some(i) = (0..n).find(|&i| {
        !angles[i].is_finite()
            || (angles[i] - (angles[0] + i as f64 * step)).abs() > ANGLE_SLACK * step.abs()
    }) {
        return Err(value_error(format!(
            "angles: a laser scan's beams are evenly spaced; angle {i} is {} rad where the \
             sweep from {} rad in steps of {step} rad puts {} rad",
            angles[i],
            angles[0],
            angles[0] + i as f64 * step
        )));
    }
    let scan = LaserScan {
        angle_min: angles[0],
        angle_increment: step,
        range_min: 0.0,
        range_max: f64::INFINITY,
        ranges: ranges.iter().map(|r| *r as f32).collect(),
        intensities: intensities.map(|v| v.iter().map(|x| *x as f32).collect()),
        time: 0.0,
    };
    scan.validate()
        .map_err(|e| value_error(format!("ranges: {e}")))?;
    Ok(scan)
}

/// Finds circular beacons (poles) of a known radius in one 2D laser scan (thesis §3.1).
///
/// Args:
///     ranges: (N,) ranges in metres; ``inf`` or NaN for beams without a return.
///     angles: (N,) beam angles in radians from x toward y, evenly spaced (as a scanner
///         sweeps; ``angle_min + i * angle_increment``).
///     radius: the beacons' radius, metres. Default 0.125 (``olmap beacons``' default).
///     method: ``"lsq"`` (default: least-squares circle fits), ``"rwht"`` (randomised
///         windowed Hough transform) or ``"reflective"`` (bright returns; needs
///         ``intensities``).
///     intensities: (N,) intensities, for ``"reflective"``.
///     max_rms: the largest RMS fit residual accepted, metres (default: the method's).
///     intensity_threshold: ``"reflective"``: the least intensity of a beacon return
///         (default 1.0).
///
/// Returns:
///     list of dict: one per beacon, as ``olmap beacons --json`` lists them: ``x``, ``y``
///     (metres, scanner frame), ``range``, ``bearing_deg``, ``rms``, ``returns``,
///     ``confidence``.
#[pyfunction]
#[pyo3(signature = (ranges, angles, radius=0.125, method="lsq", intensities=None, max_rms=None,
                    intensity_threshold=1.0))]
#[allow(clippy::too_many_arguments)]
pub fn detect_beacons<'py>(
    py: Python<'py>,
    ranges: &Bound<'py, PyAny>,
    angles: &Bound<'py, PyAny>,
    radius: f64,
    method: &str,
    intensities: Option<&Bound<'py, PyAny>>,
    max_rms: Option<f64>,
    intensity_threshold: f64,
) -> PyResult<Bound<'py, PyAny>> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(value_error(format!(
            "radius: expected a positive number of metres, got {radius}"
        )));
    }
    let intensities = intensities.map(|i| floats(i, "intensities")).transpose()?;
    let scan = laser_scan(
        floats(ranges, "ranges")?,
        floats(angles, "angles")?,
        intensities,
    )?;
    #[derive(Clone, Copy)]
    enum Method {
        Lsq,
        Reflective,
        Rwht,
    }
    let m = match method {
        "lsq" => Method::Lsq,
        "reflective" => Method::Reflective,
        "rwht" => Method::Rwht,
        other => {
            return Err(value_error(format!(
                "method: expected \"lsq\", \"rwht\" or \"reflective\", got {other:?}"
            )))
        }
    };
    if matches!(m, Method::Reflective) && scan.intensities.is_none() {
        return Err(value_error(
            "method \"reflective\" needs intensities (bright returns mark beacons)",
        ));
    }
    let found = py.detach(|| match m {
        Method::Lsq => {
            let mut p = LsqParams::default();
            if let Some(r) = max_rms {
                p.max_rms = r;
            }
            detect_circles_lsq(&scan, radius, &p)
        }
        Method::Reflective => {
            let mut p = ReflectiveParams {
                intensity_threshold,
                ..Default::default()
            };
            if let Some(r) = max_rms {
                p.max_rms = r;
            }
            detect_circles_reflective(&scan, radius, &p)
        }
        Method::Rwht => detect_circles_rwht(&scan, radius, &RwhtParams::default()),
    });
    let report = BeaconsReport::new("<array>", method, radius, scan.len(), &found);
    to_python(py, &report.detections)
}

/// The relative pose of two robots that see each other's beacons (thesis §6.3.3, (6.4)):
/// robot A sees B's beacon at range ``a`` and bearing ``alpha``, B sees A's at ``b`` and
/// ``beta``; each beacon stands ``offset`` metres straight ahead of its scanner (thesis
/// Figure 3.5). The same as ``olmap mutual``.
///
/// Args:
///     a, b: ranges, metres.
///     alpha, beta: bearings, degrees (as on the command line).
///     offset: beacon offset ahead of the scanner, metres (default 0.07).
///     max_mismatch: the largest disagreement of the two separations, metres (default 0.02):
///         beyond it the sighting is refused (a distractor, not the robot).
///     range_error: range error for the expected position error, metres (default 0.02).
///     beacon_width: apparent beacon width for the expected error, metres (default 0.1).
///
/// Returns:
///     dict: ``x_m``, ``y_m``, ``heading_deg`` (B in A's frame), ``s1_m``, ``s2_m`` (the
///     two separations), ``expected_error_m``, as ``olmap mutual --json``.
///
/// Raises:
///     ValueError: a bad value, or the sighting is refused (the message says why).
#[pyfunction]
#[pyo3(signature = (a, alpha, b, beta, offset=0.07, max_mismatch=0.02, range_error=0.02,
                    beacon_width=0.1))]
#[allow(clippy::too_many_arguments)]
pub fn mutual_localisation<'py>(
    py: Python<'py>,
    a: f64,
    alpha: f64,
    b: f64,
    beta: f64,
    offset: f64,
    max_mismatch: f64,
    range_error: f64,
    beacon_width: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let o = MutualObservation {
        a,
        alpha: alpha.to_radians(),
        b,
        beta: beta.to_radians(),
        d: offset,
    };
    let params = MutualParams {
        max_separation_mismatch: max_mismatch,
    };
    let fix =
        mutual_pose(&o, &params).map_err(|e| value_error(format!("mutual localisation: {e}")))?;
    let report = MutualReport::new(&fix, &o, range_error, beacon_width).py_err()?;
    to_python(py, &report)
}
