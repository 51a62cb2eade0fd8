//! [`MapReport`]: the typed, serialisable report of one map build (`olmap map --report`
//! and `--json`), and the scan paths of a build that pictures draw.

use std::collections::BTreeMap;

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use super::posegraph::GraphRefineReport;
use super::{Evaluation, MapBuild};
use crate::geometry::PoseJson;

/// The JSON report of a map build. Field names and order are the schema of
/// `olmap map --report` (unchanged since wave 1; see `ARCHITECTURE.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapReport {
    /// The map file written.
    pub output: String,
    /// Scans given.
    pub scans: usize,
    /// The placed scans, in joining order.
    pub placed: Vec<PlacedReport>,
    /// The scans left out, with the failed trust tests.
    pub rejected: Vec<RejectedReport>,
    /// Registrations run.
    pub registrations: usize,
    /// Voxels in the map.
    pub voxels: usize,
    /// The resolution asked for, metres.
    pub resolution: f64,
    /// Wall time of the build, seconds.
    pub seconds: f64,
    /// The pose-graph refinement, when asked for (absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph: Option<GraphRefineReport>,
}

/// One placed scan in a [`MapReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlacedReport {
    /// The scan's name.
    pub name: String,
    /// When it joined (0 = the frame scan).
    pub order: usize,
    /// `T_map_scan`.
    #[serde(flatten)]
    pub pose: PoseJson,
    /// Overlap fraction of its search.
    pub overlap_fraction: f64,
    /// Significance of its search (`null` when not finite: the frame scan).
    pub significance: Option<f64>,
    /// ICP inlier fraction, if refined.
    pub inlier_fraction: Option<f64>,
    /// Whether its final search was global.
    pub global_search: bool,
}

/// A scan left out of a map, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RejectedReport {
    /// The scan's name.
    pub name: String,
    /// The failed trust tests of its best registration.
    pub reasons: Vec<String>,
}

/// A finite number, or `None` (JSON `null`).
pub(crate) fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

impl MapReport {
    /// The report of `build`, made from `scans` inputs at `resolution` and written to
    /// `output`.
    pub fn new(build: &MapBuild, scans: usize, resolution: f64, output: &str) -> Self {
        MapReport {
            output: output.to_string(),
            scans,
            placed: build
                .placed
                .iter()
                .map(|p| PlacedReport {
                    name: p.name.clone(),
                    order: p.order,
                    pose: PoseJson::from(&p.pose),
                    overlap_fraction: p.overlap_fraction,
                    significance: finite(p.significance),
                    inlier_fraction: p.inlier_fraction,
                    global_search: p.global,
                })
                .collect(),
            rejected: build
                .rejected
                .iter()
                .map(|r| RejectedReport {
                    name: r.name.clone(),
                    reasons: r.reasons.clone(),
                })
                .collect(),
            registrations: build.registrations,
            voxels: build.map.len(),
            resolution,
            seconds: build.seconds,
            graph: build.graph.as_ref().map(|g| g.report.clone()),
        }
    }
}

impl MapBuild {
    /// The scan positions, one path per robot: `robot_of` gives a placed scan's robot from
    /// its input index (paths follow the scans' names, which sort in capture order).
    pub fn robot_paths(&self, robot_of: impl Fn(usize) -> u32) -> Vec<Vec<Point3<f64>>> {
        let mut by_robot: BTreeMap<u32, Vec<(String, Point3<f64>)>> = BTreeMap::new();
        for p in &self.placed {
            by_robot
                .entry(robot_of(p.index))
                .or_default()
                .push((p.name.clone(), Point3::from(p.pose.translation())));
        }
        by_robot
            .into_values()
            .map(|mut v| {
                v.sort_by(|a, b| a.0.cmp(&b.0));
                v.into_iter().map(|(_, p)| p).collect()
            })
            .collect()
    }

    /// `(order, name)` of every placed scan, in joining order (the rows of the entropy
    /// table).
    pub fn joining_order(&self) -> Vec<(usize, &str)> {
        self.placed
            .iter()
            .map(|p| (p.order, p.name.as_str()))
            .collect()
    }
}

/// The JSON report of an evaluation (`olmap eval --json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// The scan both lists were expressed relative to.
    pub frame: String,
    /// Per-scan errors, in the estimate's order.
    pub scans: Vec<ScanErrorReport>,
    /// Names in the estimate without a reference pose.
    pub missing: Vec<String>,
    /// The summary.
    pub summary: EvalSummaryReport,
}

/// One scan's error in an [`EvalReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanErrorReport {
    /// The scan's name.
    pub name: String,
    /// Translation error, metres.
    pub translation_m: f64,
    /// Rotation error, degrees.
    pub rotation_deg: f64,
    /// Translation error per axis, metres.
    pub dxyz_m: [f64; 3],
    /// Euler-angle errors (ZYX), degrees.
    pub dyaw_pitch_roll_deg: [f64; 3],
}

/// Mean, median and largest of a set of errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MeanMedianMax {
    /// The mean.
    pub mean: f64,
    /// The median.
    pub median: f64,
    /// The largest.
    pub max: f64,
}

impl From<[f64; 3]> for MeanMedianMax {
    fn from([mean, median, max]: [f64; 3]) -> Self {
        MeanMedianMax { mean, median, max }
    }
}

/// The share of scans whose error exceeds a threshold.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ShareAbove {
    /// The threshold (metres or degrees).
    pub threshold: f64,
    /// The share of scans above it, 0 to 1.
    pub share: f64,
}

/// The summary of an [`EvalReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalSummaryReport {
    /// Scans compared.
    pub scans: usize,
    /// Translation errors, metres.
    pub translation_m: MeanMedianMax,
    /// Rotation errors, degrees.
    pub rotation_deg: MeanMedianMax,
    /// Shares above the translation thresholds, metres.
    pub share_above_m: Vec<ShareAbove>,
    /// Shares above the rotation thresholds, degrees.
    pub share_above_deg: Vec<ShareAbove>,
}

impl From<&Evaluation> for EvalReport {
    fn from(e: &Evaluation) -> Self {
        let s = &e.summary;
        let shares = |v: &[(f64, f64)]| {
            v.iter()
                .map(|&(threshold, share)| ShareAbove { threshold, share })
                .collect()
        };
        EvalReport {
            frame: e.frame.clone(),
            scans: e
                .scans
                .iter()
                .map(|x| ScanErrorReport {
                    name: x.name.clone(),
                    translation_m: x.error.translation_m,
                    rotation_deg: x.error.rotation_deg,
                    dxyz_m: [x.error.dx_m, x.error.dy_m, x.error.dz_m],
                    dyaw_pitch_roll_deg: [x.error.yaw_deg, x.error.pitch_deg, x.error.roll_deg],
                })
                .collect(),
            missing: e.missing.clone(),
            summary: EvalSummaryReport {
                scans: s.scans,
                translation_m: s.translation_m.into(),
                rotation_deg: s.rotation_deg.into(),
                share_above_m: shares(&s.share_above_m),
                share_above_deg: shares(&s.share_above_deg),
            },
        }
    }
}
