//! Evaluation of estimated scan poses against reference poses.

use crate::error::{Error, Result};
use crate::geometry::{PoseError, PoseList};

/// The error of one scan's pose.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanError {
    /// The scan's name.
    pub name: String,
    /// Estimate against reference, both relative to the common first scan.
    pub error: PoseError,
}

/// Summary statistics of a set of errors.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorSummary {
    /// Scans compared.
    pub scans: usize,
    /// Mean, median and largest translation error, metres.
    pub translation_m: [f64; 3],
    /// Mean, median and largest rotation error, degrees.
    pub rotation_deg: [f64; 3],
    /// Share of scans whose translation error exceeds each of [`EVAL_THRESHOLDS_M`].
    pub share_above_m: Vec<(f64, f64)>,
    /// Share of scans whose rotation error exceeds each of [`EVAL_THRESHOLDS_DEG`].
    pub share_above_deg: Vec<(f64, f64)>,
}

/// Translation thresholds of the summary, metres (the thesis reports shares above 0.3 m
/// and 1 m, §6.5).
pub const EVAL_THRESHOLDS_M: [f64; 4] = [0.05, 0.1, 0.3, 1.0];
/// Rotation thresholds of the summary, degrees.
pub const EVAL_THRESHOLDS_DEG: [f64; 3] = [1.0, 3.0, 10.0];

/// The evaluation of an estimate against a reference.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// The scan whose frame both lists were expressed in.
    pub frame: String,
    /// Per-scan errors, in the estimate's order.
    pub scans: Vec<ScanError>,
    /// Names in the estimate without a reference pose.
    pub missing: Vec<String>,
    /// The summary.
    pub summary: ErrorSummary,
}

/// The number at the end of a name (`scan007` -> 7), if any.
fn trailing_number(name: &str) -> Option<u64> {
    let digits: String = name
        .chars()
        .rev()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.chars().rev().collect::<String>().parse().ok()
}

/// Mean, median (the middle value, or the mean of the two middle ones) and largest of
/// `v`; zeros when empty.
///
/// ```
/// assert_eq!(olmap::mapping::mean_median_max(vec![3.0, 1.0, 2.0, 6.0]), [3.0, 2.5, 6.0]);
/// ```
pub fn mean_median_max(mut v: Vec<f64>) -> [f64; 3] {
    if v.is_empty() {
        return [0.0; 3];
    }
    v.sort_by(f64::total_cmp);
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let median = if v.len() % 2 == 1 {
        v[v.len() / 2]
    } else {
        0.5 * (v[v.len() / 2 - 1] + v[v.len() / 2])
    };
    [mean, median, *v.last().expect("non-empty")]
}

/// Compares `estimate` with `reference` scan by scan. Names match exactly, or else by their
/// trailing number (`scan001`, `001` and `1` are the same scan), so a map's poses (named
/// by file stem) compare with reference files that use bare numbers. Both lists are first
/// expressed in the frame of the first scan of `estimate` that the reference also has, so
/// lists in different world frames compare fairly.
///
/// ```
/// use olmap::geometry::{Pose, PoseList};
/// use olmap::mapping::evaluate;
/// let mut reference = PoseList::default();
/// reference.push("a", Pose::identity());
/// reference.push("b", Pose::from_xyz_ypr(1.0, 0.0, 0.0, 0.0, 0.0, 0.0));
/// // The same trajectory in another world frame, with b 3 cm off.
/// let shift = Pose::from_xyz_ypr(5.0, 5.0, 0.0, 1.0, 0.0, 0.0);
/// let mut estimate = PoseList::default();
/// estimate.push("a", shift);
/// estimate.push("b", shift * Pose::from_xyz_ypr(1.03, 0.0, 0.0, 0.0, 0.0, 0.0));
/// let e = evaluate(&estimate, &reference).unwrap();
/// assert!((e.summary.translation_m[2] - 0.03).abs() < 1e-9);
/// ```
pub fn evaluate(estimate: &PoseList, reference: &PoseList) -> Result<Evaluation> {
    let find = |name: &str| {
        reference.get(name).or_else(|| {
            let n = trailing_number(name)?;
            reference
                .poses
                .iter()
                .find(|r| trailing_number(&r.name) == Some(n))
                .map(|r| &r.pose)
        })
    };
    let common = estimate
        .poses
        .iter()
        .find(|p| find(&p.name).is_some())
        .ok_or_else(|| {
            Error::InvalidArgument("the estimate and the reference share no scan name".into())
        })?;
    let e0 = common.pose.inverse();
    let r0 = find(&common.name).expect("found above").inverse();
    let mut scans = Vec::new();
    let mut missing = Vec::new();
    for p in &estimate.poses {
        match find(&p.name) {
            Some(r) => scans.push(ScanError {
                name: p.name.clone(),
                error: PoseError::between(&(e0 * p.pose), &(r0 * *r)),
            }),
            None => missing.push(p.name.clone()),
        }
    }
    let t: Vec<f64> = scans.iter().map(|s| s.error.translation_m).collect();
    let r: Vec<f64> = scans.iter().map(|s| s.error.rotation_deg).collect();
    let share = |v: &[f64], th: f64| {
        if v.is_empty() {
            0.0
        } else {
            v.iter().filter(|x| **x > th).count() as f64 / v.len() as f64
        }
    };
    let summary = ErrorSummary {
        scans: scans.len(),
        translation_m: mean_median_max(t.clone()),
        rotation_deg: mean_median_max(r.clone()),
        share_above_m: EVAL_THRESHOLDS_M
            .iter()
            .map(|&th| (th, share(&t, th)))
            .collect(),
        share_above_deg: EVAL_THRESHOLDS_DEG
            .iter()
            .map(|&th| (th, share(&r, th)))
            .collect(),
    };
    Ok(Evaluation {
        frame: common.name.clone(),
        scans,
        missing,
        summary,
    })
}

/// One bar of an error histogram: the count of errors in `[from, to)` metres (the last
/// bar, `to = ∞`, holds everything beyond the range).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HistogramBin {
    /// Lower edge, metres.
    pub from: f64,
    /// Upper edge, metres (`f64::INFINITY` for the overflow bar).
    pub to: f64,
    /// Errors in the bar.
    pub count: usize,
}

/// The distribution of position errors as the thesis plots it (Figure 6.11): bars `bin`
/// metres wide from 0 to `max`, and one overflow bar beyond.
///
/// ```
/// use olmap::mapping::position_histogram;
/// let bars = position_histogram(&[0.02, 0.04, 0.15, 2.5], 0.1, 1.0);
/// assert_eq!(bars.len(), 11);
/// assert_eq!((bars[0].count, bars[1].count, bars[10].count), (2, 1, 1));
/// ```
pub fn position_histogram(errors_m: &[f64], bin: f64, max: f64) -> Vec<HistogramBin> {
    let bins = if bin > 0.0 && max > 0.0 {
        (max / bin).ceil() as usize
    } else {
        0
    };
    let mut out: Vec<HistogramBin> = (0..bins)
        .map(|k| HistogramBin {
            // Rounded to nanometres: 0.3, not 0.30000000000000004, in reports.
            from: round_nm(k as f64 * bin),
            to: round_nm(((k + 1) as f64 * bin).min(max)),
            count: 0,
        })
        .collect();
    out.push(HistogramBin {
        from: if bins > 0 { max } else { 0.0 },
        to: f64::INFINITY,
        count: 0,
    });
    for &e in errors_m {
        let k = if bins > 0 && e < max {
            ((e / bin).floor().max(0.0) as usize).min(bins - 1)
        } else {
            bins
        };
        out[k].count += 1;
    }
    out
}

fn round_nm(v: f64) -> f64 {
    (v * 1e9).round() / 1e9
}
