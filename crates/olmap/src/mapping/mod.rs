//! Map building from many scans (thesis §6.4.1, §5.4, Algorithm 8), evaluation against
//! reference poses, and the `olmap map` pipeline from files to map and report
//! ([`run_map_job`], [`MapReport`]).

mod builder;
mod eval;
#[cfg(feature = "render")]
mod html;
mod input;
mod links;
mod pipeline;
pub mod planar;
pub mod posegraph;
mod report;

pub use builder::{
    build_map, build_map_linked, fuse_scan_maps, IncrementalMapper, MapBuild, MapMode, MapParams,
    PlacedScan, RejectedScan, ScanInput, ScanMap, ScanOutcome,
};
pub use eval::{
    evaluate, mean_median_max, position_histogram, ErrorSummary, Evaluation, HistogramBin,
    ScanError, EVAL_THRESHOLDS_DEG, EVAL_THRESHOLDS_M,
};
#[cfg(feature = "render")]
pub use html::write_map_html;
#[cfg(feature = "bag")]
pub use input::bag_scan_inputs;
pub use input::{odometry_for, read_scan_inputs, scan_index, OdometrySource};
pub use links::{Placement, ScanLink, TeamLinks};
pub use pipeline::{map_scans, run_map_job, run_map_job_on, MapJob, MapRun};
pub use report::{
    EvalReport, EvalSummaryReport, MapReport, MeanMedianMax, PlacedReport, RejectedReport,
    ScanErrorReport, ShareAbove,
};
