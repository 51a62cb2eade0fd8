//! Map building from many scans (thesis §6.4.1, §5.4, Algorithm 8) and evaluation against
//! reference poses.

mod builder;
mod eval;

pub use builder::{
    build_map, fuse_scan_maps, MapBuild, MapMode, MapParams, PlacedScan, RejectedScan, ScanInput,
    ScanMap,
};
pub use eval::{
    evaluate, ErrorSummary, Evaluation, ScanError, EVAL_THRESHOLDS_DEG, EVAL_THRESHOLDS_M,
};
