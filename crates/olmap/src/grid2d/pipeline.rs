//! [`run_grid2d`]: the `olmap grid2d` pipeline — planar laser scans placed by their poses,
//! ray traced into a 2D occupancy grid, written as a ROS map (PGM + YAML).

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::report::{CellsReport, ExtentReport, Grid2dReport};
use super::ros_map::{declare_ros_map, write_ros_map_into};
use super::{OccupancyGrid2d, SensorModel2d, Thresholds, TrinaryGrid};
use crate::cloud::LaserScan;
use crate::error::{Error, Result};
use crate::file::OutputSet;
use crate::geometry::PoseList;
use crate::occupancy::PositionBuckets;

/// What to grid and where the map goes.
#[derive(Debug, Clone)]
pub struct Grid2dJob {
    /// Laser-scan CSV files; each takes the pose named by its file stem (or file name).
    pub scans: Vec<PathBuf>,
    /// The pose list `T_world_sensor` of the scans.
    pub poses: PathBuf,
    /// The `.pgm` image (the `.yaml` goes beside it).
    pub output: PathBuf,
    /// Cell edge, metres.
    pub resolution: f64,
    /// Position buckets: skip a scan within this distance of one already integrated,
    /// metres (0: keep every scan).
    pub bucket_radius: f64,
    /// The beam model.
    pub model: SensorModel2d,
}

/// What [`run_grid2d`] built.
#[derive(Debug, Clone)]
pub struct Grid2dRun {
    /// The log-odds grid.
    pub grid: OccupancyGrid2d,
    /// Its trinary map (as written).
    pub map: TrinaryGrid,
    /// The report.
    pub report: Grid2dReport,
}

/// Runs a [`Grid2dJob`]: an output that is not a `.pgm` image, or an image or YAML path
/// that cannot be written, is refused first; a scan without a pose is
/// [`Error::NotFound`]. The image and the YAML appear together or not at all.
pub fn run_grid2d(job: &Grid2dJob) -> Result<Grid2dRun> {
    let start = Instant::now();
    if job.output.extension().and_then(|e| e.to_str()) != Some("pgm") {
        return Err(Error::InvalidArgument(format!(
            "{}: the output must be a .pgm image (the .yaml is written beside it)",
            job.output.display()
        )));
    }
    let mut set = OutputSet::new();
    declare_ros_map(&mut set, &job.output)?;
    let list = PoseList::read_path(&job.poses)?;
    let stem = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().into_owned());
    let name = |p: &Path| p.file_name().map(|s| s.to_string_lossy().into_owned());
    let mut grid = OccupancyGrid2d::new(job.resolution)?;
    let mut buckets = PositionBuckets::new(job.bucket_radius)?;
    let (mut integrated, mut skipped) = (0usize, 0usize);
    let (mut beams, mut hits, mut cells_traversed) = (0usize, 0usize, 0usize);
    for path in &job.scans {
        let pose = stem(path)
            .and_then(|s| list.get(&s))
            .or_else(|| name(path).and_then(|n| list.get(&n)))
            .ok_or_else(|| Error::NotFound {
                what: format!(
                    "{}: a pose named '{}' in {}",
                    path.display(),
                    stem(path).unwrap_or_default(),
                    job.poses.display()
                ),
            })?;
        let scan = LaserScan::read_csv_path(path)?;
        let inserted = grid
            .insert_scan_bucketed(&scan, pose, &job.model, &mut buckets)
            .map_err(|e| Error::InvalidArgument(format!("{}: {e}", path.display())))?;
        match inserted {
            Some(s) => {
                integrated += 1;
                beams += s.beams;
                hits += s.hits;
                cells_traversed += s.cells_traversed;
            }
            None => skipped += 1,
        }
    }
    let map = grid.to_trinary(Thresholds::default());
    let yaml = write_ros_map_into(&mut set, &job.output, &map)?;
    set.commit()?;
    let ((x0, y0), (x1, y1)) = grid.extent();
    let report = Grid2dReport {
        output: job.output.display().to_string(),
        yaml: yaml.display().to_string(),
        scans: job.scans.len(),
        scans_integrated: integrated,
        scans_skipped_by_buckets: skipped,
        beams,
        hits,
        cells_traversed,
        resolution: job.resolution,
        width: map.width,
        height: map.height,
        origin: map.origin,
        extent: ExtentReport {
            min: [x0, y0],
            max: [x1, y1],
        },
        cells: CellsReport::from(map.counts()),
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok(Grid2dRun { grid, map, report })
}
