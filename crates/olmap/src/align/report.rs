//! [`AlignmentReport`]: the typed, serialisable report of one registration (`olmap align
//! --json`, `olmap localize --json`): the pose as a 4x4 matrix and as metres and degrees,
//! the search's figures level by level, the refinement and the verdict.

use serde::{Deserialize, Serialize};

use super::icp::IcpResult;
use super::{LevelReport, Registration};
use crate::geometry::{Pose, PoseJson};

/// A row-major 4x4 homogeneous matrix.
pub type Matrix4Rows = [[f64; 4]; 4];

/// The rows of `p`'s 4x4 matrix.
pub fn matrix_rows(p: &Pose) -> Matrix4Rows {
    let m = p.to_matrix4();
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

/// The report of a registration of `source` onto `target`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlignmentReport {
    /// The scan placed.
    pub source: String,
    /// What it was placed in (a cloud or a map).
    pub target: String,
    /// The final `T_target_source` (after the refinement when there was one).
    #[serde(rename = "T_target_source")]
    pub t_target_source: Matrix4Rows,
    /// Its translation, metres.
    pub translation: [f64; 3],
    /// Its ZYX angles, degrees.
    pub yaw_pitch_roll_deg: [f64; 3],
    /// Voxels of the scan that hit the target at the search's pose (finest level).
    pub overlap: u64,
    /// `overlap` over the scan's voxels.
    pub overlap_fraction: f64,
    /// The significance of the overlap (standard deviations above the lattice's mean).
    pub significance: f64,
    /// Distinct near-best solutions.
    pub ambiguity: usize,
    /// How unique the answer is: the best distinct rival of the search and of the
    /// verification, and the spread of near-best poses.
    pub uniqueness: UniquenessReport,
    /// How well the two scans agree at the final pose where both looked (when refined).
    pub agreement: Option<AgreementJson>,
    /// Whether every test of the verdict passed.
    pub trusted: bool,
    /// The failed tests, in words.
    pub doubts: Vec<String>,
    /// The global search.
    pub search: SearchReport,
    /// The refinement, when run.
    pub refinement: Option<RefinementReport>,
    /// Wall time of the whole registration, seconds.
    pub seconds: f64,
}

/// The uniqueness part of an [`AlignmentReport`] ([`super::verify`], [`super::verdict`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UniquenessReport {
    /// The search's best distinct solution's score over the best's (0 without one).
    pub search_runner_up_ratio: f64,
    /// The search's best distinct solution, when there is one.
    pub search_runner_up: Option<PoseJson>,
    /// Half the range of near-best poses around the best along x, y, z (metres).
    pub spread_m: [f64; 3],
    /// The same along the heading, degrees.
    pub spread_yaw_deg: f64,
    /// The hypotheses refined and compared by fit (the search's best first), when the
    /// search passed its tests.
    pub hypotheses: Vec<HypothesisJson>,
    /// Index of the chosen hypothesis in `hypotheses`.
    pub chosen: Option<usize>,
    /// The best distinct refined rival's fit over the chosen one's (0 without one).
    pub verified_runner_up_ratio: f64,
    /// The distinct rival contradicted least against the chosen one (index in
    /// `hypotheses`; [`super::verify::Verification::cleaner_rival`]), when one is supported
    /// at least half as well.
    #[serde(default)]
    pub cleaner_rival: Option<usize>,
    /// How many standard deviations fewer contradicted voxels it has than the chosen one
    /// (the verdict doubts the match at 4 or more).
    #[serde(default)]
    pub cleaner_rival_sigma: Option<f64>,
    /// The search's distinct near-best poses that no refined hypothesis covers
    /// ([`super::verify::unverified_look_alikes`]): listed ones (reported only) and ones
    /// beyond the search's list (a global match with any of these is doubted).
    #[serde(default)]
    pub unverified_look_alikes: usize,
}

/// One refined hypothesis ([`super::verify::Hypothesis`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HypothesisJson {
    /// Its final pose (refined when the refinement converged).
    pub pose: PoseJson,
    /// Its search score (0 for a position the search did not propose: a slide along a
    /// weakly held direction, [`super::verify::weak_axis`]).
    pub search_score: i64,
    /// Whether its refinement converged.
    pub converged: bool,
    /// Its fit: supported minus weighted contradicted surface voxels of both scans.
    pub fit: f64,
    /// The smaller of the two scans' agreements at its pose.
    pub agreement: f64,
    /// Surface voxels of either scan that stand where the other saw through, at its pose.
    #[serde(default)]
    pub contradicted: u64,
    /// Where its start came from: `search`, `upright-look` (the search on upright
    /// structure, [`super::verify::Origin::UprightLook`]), `slide`
    /// ([`super::verify::weak_axis`]) or `screened` ([`super::verify::Origin::Screened`]).
    #[serde(default = "search_origin")]
    pub origin: String,
}

fn search_origin() -> String {
    "search".into()
}

/// The agreement of two scans where both looked ([`super::consistency`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AgreementJson {
    /// Share of the scan's observed surface voxels supported by the target.
    pub source: f64,
    /// Share of the target's observed surface voxels supported by the scan (when known).
    pub target: Option<f64>,
    /// The smaller of the two (what the verdict tests).
    pub agreement: f64,
}

/// The search part of an [`AlignmentReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchReport {
    /// The search's `T_target_source`.
    #[serde(rename = "T_target_source")]
    pub t_target_source: Matrix4Rows,
    /// Poses scored.
    pub evaluated: usize,
    /// Whether the survivor cap cut a level.
    pub guard_acted: bool,
    /// Wall time, seconds.
    pub seconds: f64,
    /// The levels, coarse to fine.
    pub levels: Vec<LevelJson>,
    /// Whether the exact search ran.
    pub exact: bool,
    /// The best score.
    pub score: i64,
}

/// One search level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LevelJson {
    /// Level index (0 = finest).
    pub level: usize,
    /// Voxel edge, metres.
    pub resolution: f64,
    /// Angular step, degrees.
    pub angular_step_deg: f64,
    /// Scan voxels at the level.
    pub scan_voxels: usize,
    /// Poses scored.
    pub evaluated: usize,
    /// Poses that passed the level's threshold.
    pub passed: usize,
    /// Survivors carried to the next level.
    pub survivors: usize,
    /// The level's best overlap.
    pub best_overlap: u64,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl From<&LevelReport> for LevelJson {
    fn from(l: &LevelReport) -> Self {
        LevelJson {
            level: l.level,
            resolution: l.resolution,
            angular_step_deg: l.angular_step.to_degrees(),
            scan_voxels: l.scan_voxels,
            evaluated: l.evaluated,
            passed: l.passed,
            survivors: l.survivors,
            best_overlap: l.best_overlap,
            seconds: l.seconds,
        }
    }
}

/// The refinement part of an [`AlignmentReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefinementReport {
    /// The refined `T_target_source`.
    #[serde(rename = "T_target_source")]
    pub t_target_source: Matrix4Rows,
    /// Whether it converged.
    pub converged: bool,
    /// Iterations run.
    pub iterations: usize,
    /// RMS distance of the inliers, metres.
    pub inlier_rms: f64,
    /// Share of source points with an inlier correspondence.
    pub inlier_fraction: f64,
    /// How well each direction was constrained.
    pub degeneracy: DegeneracyJson,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// The degeneracy of the refinement's normal equations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DegeneracyJson {
    /// Eigenvalues, ascending.
    pub eigenvalues: [f64; 6],
    /// Largest over smallest eigenvalue.
    pub condition: f64,
    /// The weakly constrained directions, named.
    pub weak: Vec<String>,
}

impl From<&IcpResult> for RefinementReport {
    fn from(f: &IcpResult) -> Self {
        RefinementReport {
            t_target_source: matrix_rows(&f.pose),
            converged: f.converged,
            iterations: f.iterations,
            inlier_rms: f.inlier_rms,
            inlier_fraction: f.inlier_fraction,
            degeneracy: DegeneracyJson {
                eigenvalues: f.degeneracy.eigenvalues,
                condition: f.degeneracy.condition,
                weak: f.degeneracy.weak.clone(),
            },
            seconds: f.seconds,
        }
    }
}

impl AlignmentReport {
    /// The report of `r`, a registration of `source` onto `target` (as the caller names
    /// them: file paths for the CLI).
    pub fn new(r: &Registration, source: &str, target: &str) -> Self {
        let s = &r.search;
        let t = r.pose.translation();
        let (y, p, ro) = r.pose.yaw_pitch_roll();
        let cleaner = r.verification.as_ref().and_then(|v| v.cleaner_rival());
        AlignmentReport {
            source: source.to_string(),
            target: target.to_string(),
            t_target_source: matrix_rows(&r.pose),
            translation: [t.x, t.y, t.z],
            yaw_pitch_roll_deg: [y.to_degrees(), p.to_degrees(), ro.to_degrees()],
            overlap: s.overlap,
            overlap_fraction: s.overlap_fraction,
            significance: s.significance,
            ambiguity: s.ambiguity,
            uniqueness: UniquenessReport {
                search_runner_up_ratio: s.runner_up_ratio(),
                search_runner_up: s.runner_up.as_ref().map(|c| PoseJson::from(&c.pose)),
                spread_m: [s.spread[0], s.spread[1], s.spread[2]],
                spread_yaw_deg: s.spread[3].to_degrees(),
                hypotheses: r.verification.as_ref().map_or_else(Vec::new, |v| {
                    v.hypotheses
                        .iter()
                        .map(|h| HypothesisJson {
                            pose: PoseJson::from(&h.pose()),
                            search_score: h.start.score,
                            converged: h.refinement.converged,
                            fit: h.fit,
                            agreement: h.consistency.agreement(),
                            contradicted: h.contradicted(),
                            origin: h.origin.name().into(),
                        })
                        .collect()
                }),
                chosen: r.verification.as_ref().map(|v| v.chosen),
                verified_runner_up_ratio: r
                    .verification
                    .as_ref()
                    .map_or(0.0, |v| v.runner_up_ratio()),
                cleaner_rival: cleaner.map(|c| c.0),
                cleaner_rival_sigma: cleaner.map(|c| c.1),
                unverified_look_alikes: r.verification.as_ref().map_or(0, |v| v.unverified.total()),
            },
            agreement: r.consistency.as_ref().map(|c| AgreementJson {
                source: c.source.agreement(),
                target: c.target.map(|t| t.agreement()),
                agreement: c.agreement(),
            }),
            trusted: r.trusted,
            doubts: r.doubts.clone(),
            search: SearchReport {
                t_target_source: matrix_rows(&s.pose),
                evaluated: s.evaluated,
                guard_acted: s.guard_acted,
                seconds: s.seconds,
                levels: s.levels.iter().map(LevelJson::from).collect(),
                exact: s.exact,
                score: s.score,
            },
            refinement: r.refinement.as_ref().map(RefinementReport::from),
            seconds: r.seconds,
        }
    }
}
