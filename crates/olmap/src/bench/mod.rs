//! The standard benchmark set (`olmap bench`): insertion, overlap evaluations, alignment
//! and localisation in both search modes, map building, thread scaling and peak memory,
//! on the shared data when present and on the simulator, as a typed [`BenchReport`].
//!
//! Built with the `test-support` feature (it uses [`crate::fixtures`] and the simulator).

mod measures;
mod trust;

pub use trust::{
    run_trust, Outcome, TrustOptions, TrustReport, TrustRow, TrustSceneRow, TRUST_REPORT_FORMAT,
    TRUST_REPORT_VERSION,
};

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::Result;

/// What [`run`] measures.
#[derive(Debug, Clone, Default)]
pub struct BenchOptions {
    /// The shared data folder; its 3DTK pair (`3dtk_dat/scan000.3d`, `scan001.3d`) is
    /// aligned when present (and not `quick`), a simulated pair otherwise.
    pub data: Option<PathBuf>,
    /// A small, fast set: the simulated pair only, a smaller thesis map, fewer scans.
    pub quick: bool,
    /// Largest thread count of the scaling run (at least 1; at most
    /// [`crate::limits::max_threads`], larger counts are capped).
    pub max_threads: usize,
    /// Runs of every timed measure; the median is reported (at least 1).
    pub repeat: usize,
}

/// The errors of a pose against the truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorBench {
    /// Translation error, metres.
    pub translation_error_m: f64,
    /// Rotation error, degrees.
    pub rotation_error_deg: f64,
}

/// Ray-traced insertion of simulated scans.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InsertionBench {
    /// Voxel edge, metres.
    pub resolution: f64,
    /// Points inserted.
    pub points: usize,
    /// Median seconds.
    pub seconds: f64,
    /// Points per second.
    pub points_per_second: f64,
    /// Voxels of the map.
    pub map_voxels: usize,
}

/// Overlap evaluations of the alignment search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OverlapBench {
    /// Poses scored per second.
    pub poses_per_second: f64,
    /// Voxel lookups (poses x scan voxels) per second.
    pub voxel_lookups_per_second: f64,
}

/// One search of an alignment problem (the `alignment` and `modes` rows).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchBench {
    /// The problem.
    pub name: String,
    /// The search mode (`multires`, `exact`, `exhaustive`).
    pub mode: String,
    /// Median seconds of the search.
    pub seconds: f64,
    /// Median seconds of the whole call.
    pub total_seconds: f64,
    /// Poses evaluated.
    pub evaluated: usize,
    /// The best score.
    pub score: i64,
    /// The best overlap fraction (alignment rows only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overlap_fraction: Option<f64>,
    /// Whether the result is guaranteed optimal.
    pub exact: bool,
    /// The error against the truth.
    #[serde(flatten)]
    pub error: ErrorBench,
}

/// Localisation in the thesis map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalisationBench {
    /// The problem.
    pub name: String,
    /// The search mode.
    pub mode: String,
    /// Median seconds of the search.
    pub seconds: f64,
    /// Median seconds of the whole call.
    pub total_seconds: f64,
    /// Poses evaluated.
    pub evaluated: usize,
    /// The best score.
    pub score: i64,
    /// Map resolution, metres.
    pub resolution: f64,
    /// Voxels of the map.
    pub map_voxels: usize,
    /// Voxels of the scan.
    pub scan_voxels: u64,
    /// Area searched, square metres.
    pub area_m2: f64,
    /// Whether the result is guaranteed optimal.
    pub exact: bool,
    /// The error against the truth.
    #[serde(flatten)]
    pub error: ErrorBench,
}

/// Batch map building.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MappingBench {
    /// Scans mapped.
    pub scans: usize,
    /// Median seconds.
    pub seconds: f64,
    /// Seconds per scan.
    pub seconds_per_scan: f64,
    /// Voxels of the map.
    pub map_voxels: usize,
}

/// Alignment on a number of threads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThreadsBench {
    /// Threads.
    pub threads: usize,
    /// Median seconds of the search.
    pub seconds: f64,
    /// Seconds on one thread over these seconds.
    pub speedup: f64,
}

/// The result of [`run`]; field order is the JSON schema of `olmap bench --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchReport {
    /// Whether the quick set ran.
    pub quick: bool,
    /// Runs per measure.
    pub repeat: usize,
    /// Insertion.
    pub insertion: InsertionBench,
    /// Overlap evaluations.
    pub overlap: OverlapBench,
    /// The alignment pair (one row).
    pub alignment: Vec<SearchBench>,
    /// Localisation (one row).
    pub localisation: Vec<LocalisationBench>,
    /// The search modes on a small problem.
    pub modes: Vec<SearchBench>,
    /// Exact over multi-resolution search time on that problem (`null` when unknown).
    pub exact_over_multires_time: Option<f64>,
    /// Map building.
    pub mapping: MappingBench,
    /// Thread scaling.
    pub threads: Vec<ThreadsBench>,
    /// Peak resident memory (VmHWM), bytes; `null` off Linux.
    pub peak_memory_bytes: Option<u64>,
}

/// Runs the benchmark set; `progress(done, total)` after each of its 5 steps.
pub fn run(options: &BenchOptions, mut progress: impl FnMut(usize, usize)) -> Result<BenchReport> {
    let repeat = options.repeat.max(1);
    let quick = options.quick;
    let modes = measures::modes(repeat)?;
    let insertion = measures::insertion(quick, repeat)?;
    progress(1, 5);
    let data = if quick { None } else { options.data.as_deref() };
    let pair = measures::alignment_pair(data)?;
    let (alignment, overlap) = measures::alignment(&pair, repeat)?;
    progress(2, 5);
    let localisation = measures::localisation(quick, repeat)?;
    progress(3, 5);
    let mapping = measures::mapping(quick, repeat)?;
    progress(4, 5);
    let threads = measures::scaling(&pair, options.max_threads, repeat)?;
    progress(5, 5);
    let exact_over_multires_time = exact_over_multires(&modes);
    Ok(BenchReport {
        quick,
        repeat,
        insertion,
        overlap,
        alignment: vec![alignment],
        localisation,
        modes,
        exact_over_multires_time,
        mapping,
        threads,
        peak_memory_bytes: peak_memory(),
    })
}

/// Exact over multi-resolution seconds, when both rows are there and the latter is
/// positive.
fn exact_over_multires(rows: &[SearchBench]) -> Option<f64> {
    let t = |m: &str| rows.iter().find(|r| r.mode == m).map(|r| r.seconds);
    match (t("exact"), t("multires")) {
        (Some(e), Some(m)) if m > 0.0 => Some(e / m),
        _ => None,
    }
}

/// Peak resident memory of this process (VmHWM), bytes; `None` off Linux.
fn peak_memory() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
