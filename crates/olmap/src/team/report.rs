//! [`TeamReport`]: the typed, serialisable report of a team mapping run (`report.json` of
//! `olmap team` and `olmap demo`), with its evaluation against the ground truth when there
//! is one. Schema: [`TEAM_REPORT_FORMAT`], version [`TEAM_REPORT_VERSION`]; the field
//! order below is the order in the file.

use serde::{Deserialize, Serialize};

use super::{ScanStore, TeamMap};
use crate::geometry::Pose;
use crate::mapping::{mean_median_max, position_histogram, Evaluation};

/// The `format` field of a team report.
pub const TEAM_REPORT_FORMAT: &str = "olmap-team-report";
/// The `version` field of a team report; bumped when a field changes meaning or goes.
pub const TEAM_REPORT_VERSION: u32 = 1;

/// Position error above which a scan counts as grossly wrong, metres (thesis §6.5).
pub const GROSS_ERROR_M: f64 = 0.3;
/// The second error threshold of the summaries, metres.
pub const LARGE_ERROR_M: f64 = 1.0;
/// Bar width of the error histograms, metres (thesis Figure 6.11).
pub const HISTOGRAM_BIN_M: f64 = 0.1;
/// The end of the error histograms' closed bars, metres; one open bar holds the rest.
pub const HISTOGRAM_MAX_M: f64 = 2.0;

/// The report of a team mapping run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TeamReport {
    /// Always [`TEAM_REPORT_FORMAT`].
    pub format: String,
    /// Always [`TEAM_REPORT_VERSION`].
    pub version: u32,
    /// Scans in the store.
    pub scans: usize,
    /// The robots' names, by robot id.
    pub robots: Vec<String>,
    /// Links found per thesis equation.
    pub links: Vec<LinkCount>,
    /// Mutual sightings rejected by the distractor test.
    pub rejected_mutual_sightings: usize,
    /// Points of seen robots cleared from the scans.
    pub cleared_points: usize,
    /// Registrations run by the team mapping.
    pub registrations: usize,
    /// Wall time of the team mapping, seconds.
    pub seconds: f64,
    /// Map entropy after each placed scan (thesis (7.4), nats).
    pub entropy_after_scan: Vec<f64>,
    /// Voxels in the joint map.
    pub voxels: usize,
    /// The joint map's resolution, metres.
    pub resolution_m: f64,
    /// Every robot's frame in the joint map.
    pub frames: Vec<FrameReport>,
    /// `T_from_to` of every pair of robots both in the joint map.
    pub relative_frames: Vec<RelativeFrame>,
    /// The placed scans, in joining order.
    pub placements: Vec<PlacementReport>,
    /// The scans left out.
    pub rejected: Vec<RejectedScanReport>,
    /// Robots no sighting tied to the team, with how many of their scans they placed alone.
    pub alone: Vec<AloneReport>,
    /// The comparison with the ground truth.
    pub evaluation: EvaluationReport,
    /// The files written beside the report.
    pub files: TeamFiles,
    /// The pose-graph refinement of the joint map, when asked for (absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph: Option<crate::mapping::posegraph::GraphRefineReport>,
}

/// How many links one thesis equation made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkCount {
    /// `(6.2)` seen, `(6.3)` saw, `(6.4)` mutual.
    pub equation: String,
    /// Links made.
    pub count: usize,
}

/// A pose in a team report: metres and ZYX degrees, one field each.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TeamPoseJson {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// z, metres.
    pub z: f64,
    /// Yaw, degrees.
    pub yaw_deg: f64,
    /// Pitch, degrees.
    pub pitch_deg: f64,
    /// Roll, degrees.
    pub roll_deg: f64,
}

impl From<&Pose> for TeamPoseJson {
    fn from(p: &Pose) -> Self {
        let t = p.translation();
        let (yaw, pitch, roll) = p.yaw_pitch_roll();
        TeamPoseJson {
            x: t.x,
            y: t.y,
            z: t.z,
            yaw_deg: yaw.to_degrees(),
            pitch_deg: pitch.to_degrees(),
            roll_deg: roll.to_degrees(),
        }
    }
}

/// One robot's frame in the joint map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameReport {
    /// The robot's name.
    pub robot: String,
    /// Its scans placed in the joint map.
    pub placed: usize,
    /// Its scans in the store.
    pub scans: usize,
    /// What first tied it to the map (`null`: nothing, mapped alone).
    pub linked_by: Option<String>,
    /// `T_map_odom`, when any of its scans was placed.
    pub t_map_odom: Option<TeamPoseJson>,
}

/// The relative pose of two robots' odometry frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RelativeFrame {
    /// The first robot.
    pub from: String,
    /// The second robot.
    pub to: String,
    /// `T_from_to`.
    pub t_from_to: TeamPoseJson,
}

/// A placed scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlacementReport {
    /// `ROBOT/scanNNN`.
    pub scan: String,
    /// When it joined.
    pub order: usize,
    /// What placed it (`frame`, `odometry`, `global`, `sighting (6.x)`).
    pub placed_by: String,
    /// The scan a sighting linked it to.
    pub linked_scan: Option<String>,
    /// Overlap fraction of its search.
    pub overlap_fraction: f64,
    /// Significance of its search (`null` when not finite).
    pub significance: Option<f64>,
    /// `T_map_scan`.
    pub pose: TeamPoseJson,
    /// Its error against the ground truth, when there is one.
    pub error: Option<PlacementError>,
}

/// A placed scan's error against the ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlacementError {
    /// Position error, metres.
    pub position_m: f64,
    /// Rotation error, degrees.
    pub rotation_deg: f64,
}

/// A scan left out, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RejectedScanReport {
    /// `ROBOT/scanNNN`.
    pub scan: String,
    /// The failed trust tests.
    pub reasons: Vec<String>,
}

/// A robot mapped alone because no sighting tied it to the team.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AloneReport {
    /// The robot's name.
    pub robot: String,
    /// Its scans placed in its own map.
    pub placed: usize,
}

/// Position errors of one map against the truth, pooled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorSummaryReport {
    /// Scans that could have been placed.
    pub scans: usize,
    /// Scans placed.
    pub placed: usize,
    /// Scans compared with the truth.
    pub compared: usize,
    /// Mean position error, metres.
    pub mean_m: f64,
    /// Median position error, metres.
    pub median_m: f64,
    /// Largest position error, metres.
    pub max_m: f64,
    /// Share of compared scans more than [`GROSS_ERROR_M`] off.
    #[serde(rename = "share_above_0.3_m")]
    pub share_above_gross: f64,
    /// Share of compared scans more than [`LARGE_ERROR_M`] off.
    #[serde(rename = "share_above_1_m")]
    pub share_above_large: f64,
    /// The thesis' Figure 6.11: bars of [`HISTOGRAM_BIN_M`] up to [`HISTOGRAM_MAX_M`],
    /// then everything beyond.
    pub histogram: Vec<HistogramBar>,
}

/// One bar of an error histogram.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HistogramBar {
    /// Lower edge, metres.
    pub from_m: f64,
    /// Upper edge, metres (`null`: the open last bar).
    pub to_m: Option<f64>,
    /// Scans in the bar.
    pub count: usize,
}

impl ErrorSummaryReport {
    /// The summary of `errors` (metres) of a map that placed `placed` of `scans` scans.
    pub fn new(errors: &[f64], placed: usize, scans: usize) -> Self {
        let n = errors.len().max(1) as f64;
        let share = |th: f64| errors.iter().filter(|e| **e > th).count() as f64 / n;
        let [mean, median, max] = mean_median_max(errors.to_vec());
        ErrorSummaryReport {
            scans,
            placed,
            compared: errors.len(),
            mean_m: mean,
            median_m: median,
            max_m: max,
            share_above_gross: share(GROSS_ERROR_M),
            share_above_large: share(LARGE_ERROR_M),
            histogram: position_histogram(errors, HISTOGRAM_BIN_M, HISTOGRAM_MAX_M)
                .iter()
                .map(|b| HistogramBar {
                    from_m: b.from,
                    to_m: b.to.is_finite().then_some(b.to),
                    count: b.count,
                })
                .collect(),
        }
    }
}

/// The team and solo runs against the ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvaluationReport {
    /// The joint map's errors (`null` without a truth).
    pub team: Option<ErrorSummaryReport>,
    /// Every robot alone, pooled (`null` without solo runs or a truth).
    pub solo: Option<ErrorSummaryReport>,
    /// Every robot alone, one by one.
    pub solo_per_robot: Vec<SoloRobotReport>,
    /// Share of gross errors alone over the team's (`null` when the team has none).
    pub gross_error_ratio_solo_over_team: Option<f64>,
    /// What the errors are relative to.
    pub note: String,
}

/// One robot mapping alone.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SoloRobotReport {
    /// The robot's name.
    pub robot: String,
    /// Its scans placed.
    pub placed: usize,
    /// Its errors against the truth.
    pub summary: Option<ErrorSummaryReport>,
}

/// The files a team run writes beside its report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TeamFiles {
    /// The joint map in its three forms.
    pub map: Vec<String>,
    /// The scan poses.
    pub poses: String,
    /// The merged store.
    pub store: String,
}

/// What the evaluation note says.
const EVALUATION_NOTE: &str = "errors relative to each map's first scan (team: the first robot's first scan; solo: each robot's own first scan); gross = position error > 0.3 m";

/// A robot mapping alone: its map and, with a truth, its evaluation.
#[derive(Debug, Clone)]
pub struct SoloRun {
    /// The robot.
    pub robot: u32,
    /// Its own map.
    pub map: TeamMap,
    /// Its errors against the truth.
    pub evaluation: Option<Evaluation>,
}

/// Position errors in metres.
fn errors_m(e: &Evaluation) -> Vec<f64> {
    e.scans.iter().map(|s| s.error.translation_m).collect()
}

impl TeamReport {
    /// The report of a team run over `store`: the joint map `team`, its evaluation
    /// `team_eval`, and the robots alone `solo` (`solo_asked`: whether they were run, so a
    /// run without solo maps reports `null` rather than an empty summary).
    pub fn new(
        store: &ScanStore,
        team: &TeamMap,
        team_eval: Option<&Evaluation>,
        solo: &[SoloRun],
        solo_asked: bool,
    ) -> Self {
        let placed_team = team.build.placed.len();
        let team_summary =
            team_eval.map(|e| ErrorSummaryReport::new(&errors_m(e), placed_team, store.len()));
        let solo_errors: Vec<f64> = solo
            .iter()
            .filter_map(|r| r.evaluation.as_ref())
            .flat_map(errors_m)
            .collect();
        let solo_placed: usize = solo.iter().map(|r| r.map.build.placed.len()).sum();
        let solo_summary = (solo_asked && team_eval.is_some())
            .then(|| ErrorSummaryReport::new(&solo_errors, solo_placed, store.len()));
        let ratio = match (&team_summary, &solo_summary) {
            (Some(t), Some(s)) if t.share_above_gross > 0.0 => {
                Some(s.share_above_gross / t.share_above_gross)
            }
            _ => None,
        };
        TeamReport {
            format: TEAM_REPORT_FORMAT.into(),
            version: TEAM_REPORT_VERSION,
            scans: store.len(),
            robots: store
                .robots()
                .iter()
                .map(|&r| store.robot_name(r))
                .collect(),
            links: team
                .links
                .iter()
                .map(|(eq, n)| LinkCount {
                    equation: eq.to_string(),
                    count: *n,
                })
                .collect(),
            rejected_mutual_sightings: team.rejected_mutual,
            cleared_points: team.cleared_points,
            registrations: team.build.registrations,
            seconds: team.build.seconds,
            entropy_after_scan: team.build.entropy_after_scan.clone(),
            voxels: team.build.map.len(),
            resolution_m: team.build.map.resolution(),
            frames: frames(team),
            relative_frames: relative_frames(team),
            placements: placements(store, team, team_eval),
            rejected: team
                .build
                .rejected
                .iter()
                .map(|r| RejectedScanReport {
                    scan: r.name.clone(),
                    reasons: r.reasons.clone(),
                })
                .collect(),
            alone: team
                .alone
                .iter()
                .map(|(r, m)| AloneReport {
                    robot: store.robot_name(*r),
                    placed: m.placed.len(),
                })
                .collect(),
            evaluation: EvaluationReport {
                team: team_summary,
                solo: solo_summary,
                solo_per_robot: solo
                    .iter()
                    .map(|r| SoloRobotReport {
                        robot: store.robot_name(r.robot),
                        placed: r.map.build.placed.len(),
                        summary: r.evaluation.as_ref().map(|e| {
                            ErrorSummaryReport::new(
                                &errors_m(e),
                                r.map.build.placed.len(),
                                r.map.keys.len(),
                            )
                        }),
                    })
                    .collect(),
                gross_error_ratio_solo_over_team: ratio,
                note: EVALUATION_NOTE.into(),
            },
            files: TeamFiles {
                map: vec!["team.olm".into(), "team.ply".into(), "team.bt".into()],
                poses: "team_poses.txt".into(),
                store: "team.store".into(),
            },
            graph: team.build.graph.as_ref().map(|g| g.report.clone()),
        }
    }
}

fn frames(team: &TeamMap) -> Vec<FrameReport> {
    team.frames
        .iter()
        .map(|f| FrameReport {
            robot: f.name.clone(),
            placed: f.placed,
            scans: f.scans,
            linked_by: f.linked_by.clone(),
            t_map_odom: f.pose.as_ref().map(TeamPoseJson::from),
        })
        .collect()
}

fn relative_frames(team: &TeamMap) -> Vec<RelativeFrame> {
    let mut relative = Vec::new();
    for a in &team.frames {
        for b in team.frames.iter().filter(|b| b.robot > a.robot) {
            if let Some(t) = team.relative(a.robot, b.robot) {
                relative.push(RelativeFrame {
                    from: a.name.clone(),
                    to: b.name.clone(),
                    t_from_to: TeamPoseJson::from(&t),
                });
            }
        }
    }
    relative
}

fn placements(
    store: &ScanStore,
    team: &TeamMap,
    team_eval: Option<&Evaluation>,
) -> Vec<PlacementReport> {
    let name_of = |i: usize| {
        let (r, s) = team.keys[i];
        super::scan_name(store, r, s)
    };
    team.build
        .placed
        .iter()
        .map(|p| {
            let linked_scan = p.via.linked_scan().map(name_of);
            let error = team_eval
                .and_then(|e| e.scans.iter().find(|s| s.name == p.name))
                .map(|s| PlacementError {
                    position_m: s.error.translation_m,
                    rotation_deg: s.error.rotation_deg,
                });
            PlacementReport {
                scan: p.name.clone(),
                order: p.order,
                placed_by: p.via.label(),
                linked_scan,
                overlap_fraction: p.overlap_fraction,
                significance: p.significance.is_finite().then_some(p.significance),
                pose: TeamPoseJson::from(&p.pose),
                error,
            }
        })
        .collect()
}
