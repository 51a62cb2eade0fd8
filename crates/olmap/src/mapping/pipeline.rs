//! [`run_map_job`]: the whole `olmap map` pipeline — read the scan files with their
//! odometry, build the map, write the map, the poses, the scans' own lists and the
//! reports — for every front end to call.

use std::path::PathBuf;

use super::input::{odometry_for, read_scan_inputs, scan_index, OdometrySource};
use super::{build_map, MapBuild, MapParams, MapReport, ScanInput};
use crate::error::{Error, Result};
use crate::file::{html_path_beside, write_atomic, OutputSet};
use crate::geometry::PoseList;
use crate::io::ReadOptions;
use crate::occupancy::{self, MapFormat};
use crate::progress::{Progress, Stage};

/// What to map and where the results go.
#[derive(Debug, Clone)]
pub struct MapJob {
    /// The scan files, in input order (see [`crate::io::scan_files`]).
    pub scans: Vec<PathBuf>,
    /// Their odometry.
    pub odometry: OdometrySource,
    /// How the scan files are read.
    pub read: ReadOptions,
    /// The scan defining the map frame, by name (default: [`MapParams::first`]).
    pub first: Option<String>,
    /// The mapping parameters.
    pub params: MapParams,
    /// The map file (`.olm` or `.bt`).
    pub output: PathBuf,
    /// Where to write the scan poses `T_map_scan` as a pose list.
    pub poses_out: Option<PathBuf>,
    /// Where to write the placed scans ray traced at their poses into a map that keeps
    /// free space ([`occupancy::LogOddsMap`] with OctoMap's default sensor model, rays cut
    /// at the mapping's `max_range`), as an OctoMap `.bt` tree with free nodes: the map to
    /// localise in when a prior window may be wrong ([`crate::align::Localizer::with_free_space`]).
    pub free_space_out: Option<PathBuf>,
    /// A folder for each placed scan's own list (`NAME.olm`) and `poses.txt`; needs
    /// [`MapParams::keep_scan_maps`].
    pub scans_out: Option<PathBuf>,
    /// Where to write the JSON report; the HTML report goes beside it (with the `render`
    /// feature).
    pub report: Option<PathBuf>,
    /// Where to write the pose graph as g2o (nodes = placed scans by input index, edges =
    /// odometry, pairwise registrations and loop closures with their information); needs
    /// [`MapParams::graph`].
    pub graph_out: Option<PathBuf>,
}

/// What [`run_map_job`] built and reported.
#[derive(Debug, Clone)]
pub struct MapRun {
    /// The build.
    pub build: MapBuild,
    /// Its report (also written to [`MapJob::report`] when set).
    pub report: MapReport,
    /// The placed scans' poses.
    pub poses: PoseList,
}

/// Declares the outputs of a [`MapJob`] known before mapping (each checked now: see
/// [`OutputSet`]).
fn declare_outputs(job: &MapJob) -> Result<OutputSet> {
    let mut set = OutputSet::new();
    set.file(&job.output, "map")?;
    if let Some(p) = &job.poses_out {
        set.file(p, "pose list")?;
    }
    if let Some(p) = &job.free_space_out {
        if MapFormat::of_output(p)? != MapFormat::OctomapBt {
            return Err(Error::InvalidArgument(format!(
                "{}: a map with free space is written as an OctoMap tree (.bt)",
                p.display()
            )));
        }
        set.file(p, "OctoMap .bt with free space")?;
    }
    if let Some(dir) = &job.scans_out {
        set.folder(dir)?;
        set.file(&dir.join("poses.txt"), "pose list")?;
    }
    if let Some(p) = &job.graph_out {
        if job.params.graph.is_none() {
            return Err(Error::InvalidArgument(
                "a graph file needs the pose-graph refinement (MapParams::graph; --graph)".into(),
            ));
        }
        set.file(p, "g2o graph")?;
    }
    if let Some(p) = &job.report {
        set.file(p, "JSON report")?;
        let html = html_path_beside(p);
        if cfg!(feature = "render") {
            set.file(&html, "HTML report")?;
        } else {
            set.remove(&html)?;
        }
    }
    Ok(set)
}

/// Runs a [`MapJob`]: checks every output path (its folder exists and is writable, it is
/// not a folder, no two are the same file) and that the map output is a map file before
/// anything is read; reads the scans ([`Stage::Read`]), builds the map ([`Stage::Map`]),
/// then writes every requested output as one [`OutputSet`]: all of them appear, or (on an
/// error, or a kill before the end) none and the old files stay. Errors name the file or
/// scan at fault.
pub fn run_map_job(job: &MapJob, progress: Progress<'_>) -> Result<MapRun> {
    MapFormat::of_output(&job.output)?;
    job.params.validate()?;
    check_unique_names(&job.scans)?;
    // The outputs are checked before anything is read or computed.
    let set = declare_outputs(job)?;
    let odometry = odometry_for(&job.odometry, &job.scans)?;
    let scans = read_scan_inputs(&job.scans, odometry, &job.read, progress)?;
    map_and_write(job, set, scans, progress)
}

/// [`run_map_job`] on scans already in memory (from a ROS 2 bag, say): `job.scans`,
/// `job.odometry` and `job.read` are not used; every other field is.
pub fn run_map_job_on(
    job: &MapJob,
    scans: Vec<ScanInput>,
    progress: Progress<'_>,
) -> Result<MapRun> {
    MapFormat::of_output(&job.output)?;
    job.params.validate()?;
    let mut seen = std::collections::HashSet::new();
    if let Some(s) = scans.iter().find(|s| !seen.insert(s.name.as_str())) {
        return Err(Error::InvalidArgument(format!(
            "two scans are named {}: scan names must be unique",
            s.name
        )));
    }
    let set = declare_outputs(job)?;
    map_and_write(job, set, scans, progress)
}

/// The mapping step of [`run_map_job`], in memory: checks that every point has a voxel key
/// at the map's resolution (an error naming the scan and the point, not one deep in the
/// mapper), builds the map ([`Stage::Map`] progress) and its report, naming the map
/// `output` in it. For callers that keep the results (the Python package).
pub fn map_scans(
    scans: &[ScanInput],
    params: &MapParams,
    output: &str,
    progress: Progress<'_>,
) -> Result<(MapBuild, MapReport)> {
    params.validate()?;
    let keys = occupancy::OccupancyList::new(params.register.search.resolution)?;
    for s in scans {
        keys.check_keys(&s.cloud, &crate::geometry::Pose::identity(), &s.name)?;
    }
    let build = build_map(scans, params, |done, total| {
        progress(Stage::Map, done, total)
    })?;
    let report = MapReport::new(
        &build,
        scans.len(),
        params.register.search.resolution,
        output,
    );
    Ok((build, report))
}

/// Builds the map of `scans` and writes every output of `job` through `set`.
fn map_and_write(
    job: &MapJob,
    mut set: OutputSet,
    scans: Vec<ScanInput>,
    progress: Progress<'_>,
) -> Result<MapRun> {
    let mut params = job.params.clone();
    if let Some(name) = &job.first {
        params.first = scan_index(&scans, name)?;
    }
    let (build, report) = map_scans(&scans, &params, &job.output.display().to_string(), progress)?;
    occupancy::write_map(set.path(&job.output)?, &build.map)?;
    let mut poses = PoseList::default();
    for p in &build.placed {
        poses.push(p.name.clone(), p.pose);
    }
    if let Some(out) = &job.poses_out {
        poses.write_path(set.path(out)?)?;
    }
    if let Some(out) = &job.free_space_out {
        occupancy::LogOddsMap::of_placed_scans(
            params.register.search.resolution,
            params.sensor.max_range,
            build
                .placed
                .iter()
                .map(|p| (&scans[p.index].cloud, &p.pose)),
        )?
        .write_bt(&set.path(out)?)?;
    }
    if let (Some(out), Some(g)) = (&job.graph_out, &build.graph) {
        crate::graph::write_g2o(&set.path(out)?, &g.graph)?;
    }
    if let Some(dir) = &job.scans_out {
        for s in &build.scan_maps {
            let path = dir.join(format!("{}.olm", s.name));
            set.file(&path, "olmap .olm")?;
            s.voxels.write_olm_path(set.path(&path)?)?;
        }
        poses.write_path(set.path(&dir.join("poses.txt"))?)?;
    }
    if let Some(path) = &job.report {
        write_atomic(&set.path(path)?, "JSON report", |w| {
            serde_json::to_writer_pretty(&mut *w, &report).map_err(std::io::Error::other)
        })?;
        #[cfg(feature = "render")]
        super::html::write_map_html(
            &build,
            &report,
            params.sensor.max_range,
            &set.path(&html_path_beside(path))?,
        )?;
    }
    set.commit()?;
    Ok(MapRun {
        build,
        report,
        poses,
    })
}

/// Scans are named by their file stems ([`crate::io::file_stem_name`]) in the poses, the
/// scan maps and the reports: two files of one name (the same scan folder given twice, two
/// robots' `scan002`) would be written under one name, one over the other. Refused,
/// naming both files.
fn check_unique_names(scans: &[PathBuf]) -> Result<()> {
    let mut seen: std::collections::HashMap<String, &PathBuf> = std::collections::HashMap::new();
    for p in scans {
        if let Some(first) = seen.insert(crate::io::file_stem_name(p), p) {
            return Err(Error::InvalidArgument(format!(
                "two scans are named {}: {} and {}; scan names (file stems) must be unique, \
                 as the poses and scan maps are written by name (map each folder on its own, \
                 or rename the files)",
                crate::io::file_stem_name(p),
                first.display(),
                p.display()
            )));
        }
    }
    Ok(())
}
