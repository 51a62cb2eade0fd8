//! Map building from many scans (thesis §6.4.1, §5.4, Algorithm 8) and evaluation against
//! reference poses.

mod builder;
mod eval;
mod links;

pub use builder::{
    build_map, build_map_linked, fuse_scan_maps, MapBuild, MapMode, MapParams, PlacedScan,
    RejectedScan, ScanInput, ScanMap,
};
pub use eval::{
    evaluate, mean_median_max, position_histogram, ErrorSummary, Evaluation, HistogramBin,
    ScanError, EVAL_THRESHOLDS_DEG, EVAL_THRESHOLDS_M,
};
pub use links::{Placement, ScanLink, TeamLinks};
