//! The trust benchmark (`olmap bench --trust`): every pair of the simulator's trust suite
//! ([`crate::sim::trust_cases`]) registered with the default parameters, each verdict
//! judged against the truth, tabulated per kind of scene.
//!
//! A trusted pose is **right** within 0.3 m and 3° of the truth ([`crate::sim::RIGHT_TRANSLATION`],
//! [`crate::sim::RIGHT_ROTATION`]); a trusted wrong pose is an **alias** when the source
//! scan is what the robot would have seen there ([`crate::sim::TrustCase::is_alias`]: two
//! identical rooms, the two halves of a symmetric hall), and **wrong** otherwise. An alias
//! cannot be told from the truth by any verdict on the two scans (only priors can: the
//! odometry windows of map building); a wrong trusted pose is a failure of the verdict.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::align::{register, RegisterParams};
use crate::error::Result;
use crate::sim::{pose_error, trust_cases, Answer, TrustScene};

/// Format name of the report.
pub const TRUST_REPORT_FORMAT: &str = "olmap-trust-report";
/// Version of the report.
pub const TRUST_REPORT_VERSION: u32 = 1;

/// What [`run_trust`] runs.
#[derive(Debug, Clone)]
pub struct TrustOptions {
    /// Seed of the suite.
    pub seed: u64,
    /// Pairs per kind of scene (14 kinds).
    pub per_scene: usize,
    /// The registration under test.
    pub register: RegisterParams,
}

impl Default for TrustOptions {
    fn default() -> Self {
        TrustOptions {
            seed: 1,
            per_scene: 17,
            register: RegisterParams::default(),
        }
    }
}

/// How one pair came out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// Trusted, and within the tolerance of the truth.
    TrustedRight,
    /// Trusted, wrong, and the source scan is what the robot would have seen at the wrong
    /// pose.
    TrustedAlias,
    /// Trusted and wrong (or trusted with no right answer, and not an alias).
    TrustedWrong,
    /// Not trusted.
    Untrusted,
}

/// One pair's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrustRow {
    /// The pair's name (`kind-NN`).
    pub name: String,
    /// Its kind.
    pub scene: String,
    /// What its answer can be (`unique`, `scarce`, `ambiguous`, `none`).
    pub answer: String,
    /// The outcome.
    pub outcome: Outcome,
    /// Whether the pose (trusted or not) is right; `None` without a truth.
    pub right: Option<bool>,
    /// Translation error, metres (`None` without a truth).
    pub error_m: Option<f64>,
    /// Rotation error, degrees (`None` without a truth).
    pub error_deg: Option<f64>,
    /// Share of the source's voxels the target has at the truth.
    pub true_overlap: f64,
    /// Overlap fraction of the search.
    pub overlap_fraction: f64,
    /// Significance of the search.
    pub significance: f64,
    /// The verified runner-up's fit over the winner's (0 without one).
    pub runner_up_ratio: f64,
    /// The two scans' agreement at the final pose (when refined).
    pub agreement: Option<f64>,
    /// The search's distinct near-best poses ([`crate::align::Alignment::ambiguity`]).
    #[serde(default)]
    pub ambiguity: usize,
    /// Of those, the ones no refined hypothesis covers
    /// ([`crate::align::verify::unverified_look_alikes`]).
    #[serde(default)]
    pub unverified: usize,
    /// How many standard deviations fewer contradicted voxels the cleanest distinct rival
    /// supported at least half as well has than the winner
    /// ([`crate::align::verify::Verification::cleaner_rival`]; `None` without one).
    #[serde(default)]
    pub cleaner_rival_sigma: Option<f64>,
    /// That rival's supported voxels over the winner's (`None` without one).
    #[serde(default)]
    pub cleaner_rival_support: Option<f64>,
    /// The verdict's doubts.
    pub doubts: Vec<String>,
    /// Seconds of the registration.
    pub seconds: f64,
}

/// The counts of one kind of scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrustSceneRow {
    /// The kind.
    pub scene: String,
    /// What its answer can be.
    pub answer: String,
    /// Pairs.
    pub pairs: usize,
    /// Trusted and right.
    pub trusted_right: usize,
    /// Trusted aliases.
    pub trusted_alias: usize,
    /// Trusted and wrong.
    pub trusted_wrong: usize,
    /// Not trusted.
    pub untrusted: usize,
    /// Right poses, trusted or not (how often the search and verification found the
    /// truth).
    pub right: usize,
}

/// The trust benchmark's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrustReport {
    /// [`TRUST_REPORT_FORMAT`].
    pub format: String,
    /// [`TRUST_REPORT_VERSION`].
    pub version: u32,
    /// Seed of the suite.
    pub seed: u64,
    /// Pairs per kind.
    pub per_scene: usize,
    /// Per kind, in the suite's order.
    pub scenes: Vec<TrustSceneRow>,
    /// Every pair.
    pub rows: Vec<TrustRow>,
    /// Trusted-and-wrong pairs over the whole suite (aliases not included).
    pub trusted_wrong: usize,
    /// Trusted aliases over the whole suite.
    pub trusted_alias: usize,
    /// Pairs with a unique right answer.
    pub unique_pairs: usize,
    /// Of those, trusted and right.
    pub unique_trusted_right: usize,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Runs the trust suite. `progress(done, total)` counts pairs.
pub fn run_trust(
    options: &TrustOptions,
    mut progress: impl FnMut(usize, usize),
) -> Result<TrustReport> {
    let start = Instant::now();
    let cases = trust_cases(options.seed, options.per_scene, |_, _| {})?;
    let mut rows = Vec::with_capacity(cases.len());
    for (i, c) in cases.iter().enumerate() {
        let r = register(&c.source, &c.target, &options.register)?;
        let right = c.is_right(&r.pose);
        let outcome = match (r.trusted, right) {
            (false, _) => Outcome::Untrusted,
            (true, Some(true)) => Outcome::TrustedRight,
            (true, _) if c.is_alias(&r.pose)? => Outcome::TrustedAlias,
            (true, _) => Outcome::TrustedWrong,
        };
        let errors = c.truth.map(|t| pose_error(&r.pose, &t));
        // The cleanest rival supported half as well: its σ, and its support over the winner's.
        let cleaner = r.verification.as_ref().and_then(|v| {
            let w = v.winner().supported() as f64;
            v.cleaner_rival().map(|(i, z)| {
                let support = (w > 0.0).then(|| v.hypotheses[i].supported() as f64 / w);
                (z, support)
            })
        });
        rows.push(TrustRow {
            name: c.name.clone(),
            scene: c.scene.name().into(),
            answer: answer_name(c.scene.answer()).into(),
            outcome,
            right,
            error_m: errors.map(|e| e.0),
            error_deg: errors.map(|e| e.1.to_degrees()),
            true_overlap: c.true_overlap,
            overlap_fraction: r.search.overlap_fraction,
            significance: r.search.significance,
            runner_up_ratio: r.verification.as_ref().map_or(0.0, |v| v.runner_up_ratio()),
            agreement: r.consistency.map(|c| c.agreement()),
            ambiguity: r.search.ambiguity,
            unverified: r.verification.as_ref().map_or(0, |v| v.unverified.total()),
            cleaner_rival_sigma: cleaner.map(|c| c.0),
            cleaner_rival_support: cleaner.and_then(|c| c.1),
            doubts: r.doubts.clone(),
            seconds: r.seconds,
        });
        progress(i + 1, cases.len());
    }
    let scenes: Vec<TrustSceneRow> = TrustScene::ALL
        .iter()
        .map(|s| scene_row(*s, &rows))
        .collect();
    let count = |o: Outcome| rows.iter().filter(|r| r.outcome == o).count();
    let unique: Vec<&TrustRow> = rows.iter().filter(|r| r.answer == "unique").collect();
    Ok(TrustReport {
        format: TRUST_REPORT_FORMAT.into(),
        version: TRUST_REPORT_VERSION,
        seed: options.seed,
        per_scene: options.per_scene,
        trusted_wrong: count(Outcome::TrustedWrong),
        trusted_alias: count(Outcome::TrustedAlias),
        unique_pairs: unique.len(),
        unique_trusted_right: unique
            .iter()
            .filter(|r| r.outcome == Outcome::TrustedRight)
            .count(),
        scenes,
        rows,
        seconds: start.elapsed().as_secs_f64(),
    })
}

fn answer_name(a: Answer) -> &'static str {
    match a {
        Answer::Unique => "unique",
        Answer::Scarce => "scarce",
        Answer::Ambiguous => "ambiguous",
        Answer::None => "none",
    }
}

fn scene_row(scene: TrustScene, rows: &[TrustRow]) -> TrustSceneRow {
    let mine: Vec<&TrustRow> = rows.iter().filter(|r| r.scene == scene.name()).collect();
    let count = |o: Outcome| mine.iter().filter(|r| r.outcome == o).count();
    TrustSceneRow {
        scene: scene.name().into(),
        answer: answer_name(scene.answer()).into(),
        pairs: mine.len(),
        trusted_right: count(Outcome::TrustedRight),
        trusted_alias: count(Outcome::TrustedAlias),
        trusted_wrong: count(Outcome::TrustedWrong),
        untrusted: count(Outcome::Untrusted),
        right: mine.iter().filter(|r| r.right == Some(true)).count(),
    }
}
