//! `olmap.simulate` (multi-robot datasets with ground truth), `olmap.SimDataset`,
//! `olmap.map_team` and its result, `olmap.TeamResult`.

use std::path::PathBuf;

use numpy::PyArray2;
use olmap::geometry::{Pose, PoseList};
use olmap::mapping::posegraph::GraphRefineParams;
use olmap::sim::{
    simulate as library_simulate, MirrorScanner, OdometryNoise, RobotModel, Scanner3d, SimConfig,
    SimDataset, SpinningLidar, WorldKind,
};
use olmap::team::{
    run_team_in_memory, run_team_pipeline, ScanStore, TeamJob, TeamParams, TeamReport,
};
use pyo3::exceptions::PyUserWarning;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::cloud::PyPointCloud;
use crate::convert::{pose_array, to_python};
use crate::errors::{value_error, IntoPy};
use crate::map::PyOccupancyMap;
use crate::threads::{detached, PyProgress};

/// A simulated multi-robot run with ground truth (from ``olmap.simulate``).
///
/// Attributes:
///     robots: the robots' names (``robot0``, ``robot1``, ...).
///     world: the world's name; ``seed``: the seed.
///     sightings: how many beacon sightings were recorded.
#[pyclass(frozen, module = "olmap", name = "SimDataset")]
pub struct PySimDataset {
    data: SimDataset,
}

impl PySimDataset {
    fn robot(&self, robot: &Bound<'_, PyAny>) -> PyResult<usize> {
        let n = self.data.robots.len();
        if let Ok(i) = robot.extract::<usize>() {
            return if i < n {
                Ok(i)
            } else {
                Err(value_error(format!("robot: index {i} of {n} robots")))
            };
        }
        let name: String = robot
            .extract()
            .map_err(|_| value_error("robot: expected an index or a robot name"))?;
        self.data
            .robots
            .iter()
            .position(|r| r.name == name)
            .ok_or_else(|| value_error(format!("robot: no robot named {name:?}")))
    }
}

fn pose_list<'py>(py: Python<'py>, poses: &[Pose]) -> PyResult<Bound<'py, PyList>> {
    let items: Vec<Bound<'py, PyArray2<f64>>> = poses.iter().map(|p| pose_array(py, p)).collect();
    PyList::new(py, items)
}

#[pymethods]
impl PySimDataset {
    /// The robots' names.
    #[getter]
    fn robots(&self) -> Vec<String> {
        self.data.robots.iter().map(|r| r.name.clone()).collect()
    }
    /// The world's name.
    #[getter]
    fn world(&self) -> &'static str {
        self.data.config.world.name()
    }
    /// The seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.data.config.seed
    }
    /// How many beacon sightings were recorded.
    #[getter]
    fn sightings(&self) -> usize {
        self.data.sightings.len()
    }
    /// The 3D scans of ``robot`` (index or name), one PointCloud per stop, in the robot frame.
    fn scans(&self, robot: &Bound<'_, PyAny>) -> PyResult<Vec<PyPointCloud>> {
        let r = self.robot(robot)?;
        Ok(self.data.robots[r]
            .scans
            .iter()
            .map(|c| PyPointCloud::from_cloud(c.clone()))
            .collect())
    }
    /// The true ``T_world_robot`` of ``robot`` at each stop (4x4 arrays).
    fn truth<'py>(
        &self,
        py: Python<'py>,
        robot: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyList>> {
        let r = self.robot(robot)?;
        pose_list(py, &self.data.robots[r].truth)
    }
    /// The odometry ``T_odom_robot`` of ``robot`` at each stop (4x4 arrays; the first is the
    /// identity).
    fn odometry<'py>(
        &self,
        py: Python<'py>,
        robot: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyList>> {
        let r = self.robot(robot)?;
        pose_list(py, &self.data.robots[r].odometry)
    }
    /// Writes the dataset folder ``olmap simulate`` writes (manifest, PCD scans, poses,
    /// sightings), atomically; the folder must not hold another dataset's files.
    fn write(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let data = &self.data;
        py.detach(|| olmap::sim::write_dataset(&path, data))
            .py_err()
    }
    fn __repr__(&self) -> String {
        format!(
            "SimDataset({} robots x {} stops in the {} world, seed {}, {} sightings)",
            self.data.robots.len(),
            self.data.config.stops,
            self.data.config.world.name(),
            self.data.config.seed,
            self.data.sightings.len()
        )
    }
}

/// A choice by name, made by calling the constructor chosen.
type Named<T> = (&'static str, fn() -> T);

fn choice<T: Copy>(what: &str, value: &str, options: &[(&str, T)]) -> PyResult<T> {
    options
        .iter()
        .find(|(name, _)| *name == value)
        .map(|(_, v)| *v)
        .ok_or_else(|| {
            let names: Vec<String> = options.iter().map(|(n, _)| format!("{n:?}")).collect();
            value_error(format!(
                "{what}: expected one of {}, got {value:?}",
                names.join(", ")
            ))
        })
}

/// Simulates robots with 3D scanners and beacons driving through a world, with ground
/// truth (the same as ``olmap simulate``; seeded: the same arguments give the same data).
///
/// Args:
///     world: ``"office"``, ``"lab"`` (default: a furnished 20 x 20 x 3 m room),
///         ``"corridor"``, ``"box-room"``, ``"twin-rooms"``, ``"desk-hall"``,
///         ``"symmetric-hall"``, ``"corridor-ring"`` (a 72 m corridor loop the robots drive
///         round), ``"warehouse"`` (200 x 200 m of rack rows, a serpentine route).
///     robots: number of robots (default 4).
///     scans_per_robot: stops (3D scans) per robot (default 20).
///     seed: seed of everything random (default 1).
///     odometry: odometry error: ``"none"``, ``"typical"`` (default), ``"degraded"``
///         (about 0.5 m and 10 degrees per move, thesis §6.5) or ``"drifting"`` (5 % scale
///         and 2 degrees per metre of drift, 7.5 cm and 3 degrees per move).
///     scanner: ``"mirror"`` (default: the thesis' enhanced rotating-mirror scanner),
///         ``"mirror-standard"`` or ``"lidar"`` (a multi-beam spinning lidar).
///     range_noise: standard deviation of the range noise, metres (default 0.02).
///     beacon: ``"above"`` (default) or ``"front"`` (a beacon 0.1 m ahead, 180° field of view).
///     progress: None (default), or a callable ``progress("simulate", done, total)`` called
///         as scans are simulated, with the GIL held for the call.
///
/// Returns:
///     SimDataset.
///
/// Raises:
///     ValueError: a bad argument. olmap.TooLargeError: more than olmap's memory limit.
#[pyfunction]
#[pyo3(signature = (world="lab", robots=4, scans_per_robot=20, seed=1, odometry="typical",
                    scanner="mirror", range_noise=0.02, beacon="above", progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn simulate(
    py: Python<'_>,
    world: &str,
    robots: usize,
    scans_per_robot: usize,
    seed: u64,
    odometry: &str,
    scanner: &str,
    range_noise: f64,
    beacon: &str,
    progress: Option<&Bound<'_, PyAny>>,
) -> PyResult<PySimDataset> {
    let mut reports = PyProgress::new(progress)?;
    let worlds: Vec<(&str, WorldKind)> = WorldKind::ALL.iter().map(|w| (w.name(), *w)).collect();
    let world = choice("world", world, &worlds)?;
    if !(range_noise.is_finite() && range_noise >= 0.0) {
        return Err(value_error(format!(
            "range_noise: expected a finite number >= 0 (metres), got {range_noise}"
        )));
    }
    let scanners: [Named<Scanner3d>; 3] = [
        ("mirror", || Scanner3d::Mirror(MirrorScanner::enhanced())),
        ("mirror-standard", || {
            Scanner3d::Mirror(MirrorScanner::standard())
        }),
        ("lidar", || Scanner3d::Lidar(SpinningLidar::default())),
    ];
    let mut scanner = choice("scanner", scanner, &scanners)?();
    match &mut scanner {
        Scanner3d::Mirror(m) => m.noise.sigma = range_noise,
        Scanner3d::Lidar(l) => l.noise.sigma = range_noise,
    }
    let noises: [Named<OdometryNoise>; 4] = [
        ("none", OdometryNoise::none),
        ("typical", OdometryNoise::typical),
        ("degraded", OdometryNoise::degraded),
        ("drifting", OdometryNoise::drifting),
    ];
    let odometry = choice("odometry", odometry, &noises)?();
    let mut config = SimConfig {
        world,
        seed,
        robots,
        stops: scans_per_robot,
        scanner,
        odometry,
        ..Default::default()
    };
    if choice("beacon", beacon, &[("above", false), ("front", true)])? {
        config.robot = RobotModel::front_beacon(0.1);
        config.sighting.fov = 180f64.to_radians();
    }
    let data = py
        .detach(|| {
            library_simulate(&config, |done, total| {
                reports.report(olmap::progress::Stage::Simulate, done, total)
            })
        })
        .py_err()?;
    reports.finish()?;
    Ok(PySimDataset { data })
}

/// The result of ``olmap.map_team``.
///
/// Attributes:
///     poses: dict of scan name (``ROBOT/scanNNN``) to ``T_map_scan`` (4x4 float64 array) for
///         every placed scan; the map frame is the first robot's first scan.
///     map: the joint OccupancyMap.
///     report: a dict, the same schema as ``olmap team --json`` (placements, robot frames,
///         links by equation, errors against the truth when known).
#[pyclass(frozen, module = "olmap", name = "TeamResult")]
pub struct PyTeamResult {
    poses: PoseList,
    map: Py<PyOccupancyMap>,
    report: TeamReport,
}

#[pymethods]
impl PyTeamResult {
    /// ``T_map_scan`` of every placed scan, by name.
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for p in &self.poses.poses {
            d.set_item(&p.name, pose_array(py, &p.pose))?;
        }
        Ok(d)
    }
    /// The joint map.
    #[getter]
    fn map(&self, py: Python<'_>) -> Py<PyOccupancyMap> {
        self.map.clone_ref(py)
    }
    /// The report as a dict (the ``olmap team --json`` schema).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.report)
    }
    fn __repr__(&self) -> String {
        format!(
            "TeamResult({} of {} scans placed)",
            self.poses.len(),
            self.report.scans
        )
    }
}

/// Maps a team of robots together (thesis §6.4-6.5): one batch map of every robot's scans,
/// where sightings of each other confine the searches and seen robots are cleared from the
/// scans. The same as ``olmap team``; the GIL is released while it runs.
///
/// Args:
///     dataset: a SimDataset, or the path of a dataset folder (``olmap simulate -o DIR``, or
///         ``olmap-demo/dataset``).
///     solo: also map every robot alone and compare (default False).
///     clearing: clear seen robots from the scans (default True).
///     graph: refine with a pose graph (default False).
///     out: a folder to write the run's files into as ``olmap team -o`` does (maps, poses,
///         store, report.json); default None writes nothing.
///     threads: worker threads, 0 (default) for one per core.
///     progress: None (default), or a callable ``progress(stage, done, total)`` called as
///         scans are placed (stages ``"team map"``, ``"solo maps"``), with the GIL held for
///         the call; an exception it raises is raised when the mapping ends.
///
/// Returns:
///     TeamResult: ``poses``, ``map``, ``report``.
#[pyfunction]
#[pyo3(signature = (dataset, solo=false, clearing=true, graph=false, out=None, threads=0,
                    progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn map_team(
    py: Python<'_>,
    dataset: &Bound<'_, PyAny>,
    solo: bool,
    clearing: bool,
    graph: bool,
    out: Option<PathBuf>,
    threads: i64,
    progress: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyTeamResult> {
    let mut reports = PyProgress::new(progress)?;
    let (store, truth): (ScanStore, Option<PoseList>) =
        if let Ok(ds) = dataset.extract::<PyRef<'_, PySimDataset>>() {
            let data = &ds.data;
            let store = py.detach(|| data.to_store()).py_err()?;
            let truth = data.truth_list(&store);
            (store, Some(truth))
        } else {
            let dir: PathBuf = dataset.extract().map_err(|_| {
                value_error("dataset: expected an olmap.SimDataset or a dataset folder path")
            })?;
            let data = py.detach(|| olmap::sim::read_dataset(&dir)).py_err()?;
            let (store, skipped) = py.detach(|| data.to_store_skipping()).py_err()?;
            for s in data.skipped.iter().chain(&skipped) {
                let message = std::ffi::CString::new(format!("skipped {}: {}", s.path, s.reason))
                    .unwrap_or_else(|_| c"skipped an unreadable input".to_owned());
                PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)?;
            }
            let truth = data.has_truth().then(|| data.truth_list(&store));
            (store, truth)
        };
    let mut params = TeamParams::default();
    if !clearing {
        params.clearing = None;
    }
    if graph {
        params.map.graph = Some(GraphRefineParams::default());
    }
    let (report, team) = detached(py, threads, || -> olmap::Result<_> {
        let progress = &mut |stage: olmap::progress::Stage, done: usize, total: usize| {
            reports.report(stage, done, total)
        };
        match &out {
            Some(dir) => {
                let run = run_team_pipeline(
                    &TeamJob {
                        store: &store,
                        truth: truth.as_ref(),
                        params: &params,
                        out: dir,
                        solo,
                    },
                    progress,
                )?;
                Ok((run.report, run.team))
            }
            None => {
                let run = run_team_in_memory(&store, truth.as_ref(), &params, solo, progress)?;
                Ok((run.report, run.team))
            }
        }
    })?
    .py_err()?;
    reports.finish()?;
    Ok(PyTeamResult {
        poses: team.poses(),
        map: Py::new(py, PyOccupancyMap::from_list(team.build.map))?,
        report,
    })
}
