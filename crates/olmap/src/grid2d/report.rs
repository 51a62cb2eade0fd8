//! Typed summaries of the 2D grids the command line writes: [`Grid2dReport`] (`olmap
//! grid2d --json`) and [`NavgridReport`] (`olmap navgrid --json`).

use serde::{Deserialize, Serialize};

use super::{CellCounts, TrinaryGrid};

/// The box of the cells that received data, metres in the map plane.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExtentReport {
    /// Lower corner `[x, y]`.
    pub min: [f64; 2],
    /// Upper corner `[x, y]`.
    pub max: [f64; 2],
}

/// Cells of a trinary grid by state.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CellsReport {
    /// Free cells.
    pub free: usize,
    /// Occupied cells.
    pub occupied: usize,
    /// Unknown cells.
    pub unknown: usize,
}

impl From<CellCounts> for CellsReport {
    fn from(c: CellCounts) -> Self {
        CellsReport {
            free: c.free,
            occupied: c.occupied,
            unknown: c.unknown,
        }
    }
}

/// The summary of `olmap grid2d --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Grid2dReport {
    /// The PGM image written.
    pub output: String,
    /// The YAML file written beside it.
    pub yaml: String,
    /// Scans given.
    pub scans: usize,
    /// Scans integrated.
    pub scans_integrated: usize,
    /// Scans left out by the position buckets.
    pub scans_skipped_by_buckets: usize,
    /// Beams of the integrated scans.
    pub beams: usize,
    /// Beams with a return inside the range.
    pub hits: usize,
    /// Cells the beams passed through.
    pub cells_traversed: usize,
    /// Cell edge, metres.
    pub resolution: f64,
    /// Image width, cells.
    pub width: usize,
    /// Image height, cells.
    pub height: usize,
    /// The ROS origin of the lower-left cell `[x, y, yaw]`.
    pub origin: [f64; 3],
    /// The box of the cells with data.
    pub extent: ExtentReport,
    /// Cells by state.
    pub cells: CellsReport,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// The summary of `olmap navgrid --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NavgridReport {
    /// The PGM image written.
    pub pgm: String,
    /// The YAML file written beside it.
    pub yaml: String,
    /// Image width, cells.
    pub width: usize,
    /// Image height, cells.
    pub height: usize,
    /// Cell edge, metres.
    pub resolution_m: f64,
    /// The ROS origin of the lower-left cell `[x, y, yaw]`.
    pub origin: [f64; 3],
    /// Scan poses the rays were traced from.
    pub poses: usize,
    /// Free cells.
    pub free: usize,
    /// Occupied cells.
    pub occupied: usize,
    /// Unknown cells.
    pub unknown: usize,
}

impl NavgridReport {
    /// The summary of `grid`, traced from `poses` poses and written to `pgm` and `yaml`.
    pub fn new(grid: &TrinaryGrid, poses: usize, pgm: &str, yaml: &str) -> Self {
        let c = grid.counts();
        NavgridReport {
            pgm: pgm.to_string(),
            yaml: yaml.to_string(),
            width: grid.width,
            height: grid.height,
            resolution_m: grid.resolution,
            origin: grid.origin,
            poses,
            free: c.free,
            occupied: c.occupied,
            unknown: c.unknown,
        }
    }
}
