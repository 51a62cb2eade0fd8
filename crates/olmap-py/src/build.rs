//! `olmap.build_map` and its result, `olmap.MapBuild`.

use numpy::PyArray2;
use olmap::align::icp::IcpParams;
use olmap::align::{RegisterParams, SearchParams};
use olmap::geometry::Pose;
use olmap::mapping::posegraph::GraphRefineParams;
use olmap::mapping::{MapMode, MapParams, MapReport, ScanInput};
use olmap::occupancy::SensorModel;
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::align::dof as parse_dof;
use crate::convert::{self, cloud_arg, pose_array, to_python};
use crate::errors::{value_error, IntoPy};
use crate::map::PyOccupancyMap;
use crate::threads::{detached, PyProgress};

/// The result of ``olmap.build_map``.
///
/// Attributes:
///     poses: one entry per input scan, in input order: its ``T_map_scan`` (4x4 float64
///         array, the map frame is the first scan's), or None when the scan was rejected.
///     names: the scans' names (``names`` argument, or ``scan000``, ``scan001``, ...).
///     map: the fused OccupancyMap.
///     report: a dict, the same schema as ``olmap map --report`` (placed scans with their
///         evidence, rejected scans with the failed trust tests, voxels, timings).
#[pyclass(frozen, module = "olmap", name = "MapBuild")]
pub struct PyMapBuild {
    poses: Vec<Option<Pose>>,
    names: Vec<String>,
    map: Py<PyOccupancyMap>,
    report: MapReport,
}

#[pymethods]
impl PyMapBuild {
    /// ``T_map_scan`` per input scan (None: rejected).
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let items: Vec<Option<Bound<'py, PyArray2<f64>>>> = self
            .poses
            .iter()
            .map(|p| p.as_ref().map(|p| pose_array(py, p)))
            .collect();
        PyList::new(py, items)
    }
    /// The scans' names, in input order.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.names.clone()
    }
    /// The fused map.
    #[getter]
    fn map(&self, py: Python<'_>) -> Py<PyOccupancyMap> {
        self.map.clone_ref(py)
    }
    /// The report as a dict (the ``olmap map --report`` schema).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.report)
    }
    fn __repr__(&self) -> String {
        format!(
            "MapBuild({} of {} scans placed, {} voxels at {} m)",
            self.poses.iter().filter(|p| p.is_some()).count(),
            self.poses.len(),
            self.report.voxels,
            self.report.resolution
        )
    }
}

/// Builds a map from scans (thesis chapter 5): every scan is registered against the map of
/// those already placed (global search, ICP, trust tests) and fused by ray tracing. The same
/// computation and result as ``olmap map``; the GIL is released while it runs.
///
/// Args:
///     scans: a list of PointCloud or (N, 3) array-likes (metres, each in its sensor frame).
///     odometry: None, or one 4x4 ``T_world_scan`` per scan (any fixed world frame; only the
///         motion between scans is used, as a search window that widens, then goes global,
///         when the match there is not trusted).
///     resolution: voxel edge of the map and of the finest search level, metres
///         (default 0.1).
///     mode: ``"batch"`` (default: the best-overlapping scan joins next),
///         ``"sequential"`` (input order, each scan tried once) or ``"incremental"``
///         (input order, a scan that cannot be placed yet is retried as the map grows;
///         ``first`` must be 0).
///     dof: ``"xy-yaw"``, ``"xyz-yaw"`` (default) or ``"6dof"``.
///     max_tilt: ``"6dof"`` only: largest roll and pitch searched, degrees (default 15).
///     max_range: ignore points farther than this from their sensor, metres (default 30).
///     names: the scans' names in the report (default ``scan000``, ``scan001``, ...).
///     first: index of the scan that defines the map frame (default 0).
///     bucket_radius: skip fusing scans taken within this distance of a fused one, metres
///         (default 0: off).
///     min_count: drop fused voxels with a count below this (default 1: keep all).
///     register_band: ``(z_min, z_max)``: register with only the points between these
///         heights in each scan's own frame (metres; the map keeps every point). Default None.
///     graph: refine the poses with a pose graph of pairwise registrations and odometry
///         (default False).
///     threads: worker threads, 0 (default) for one per core.
///     progress: None (default), or a callable ``progress(stage, done, total)`` called as
///         scans are placed (stage ``"map"``), with the GIL held for the call; an exception
///         it raises is raised when the mapping ends.
///
/// Returns:
///     MapBuild: ``poses``, ``names``, ``map``, ``report``.
///
/// Raises:
///     ValueError: bad arguments, no scans, odometry of another length.
#[pyfunction]
#[pyo3(signature = (scans, odometry=None, resolution=0.1, mode="batch", dof="xyz-yaw",
                    max_tilt=15.0, max_range=30.0, names=None, first=0, bucket_radius=0.0,
                    min_count=1, register_band=None, graph=false, threads=0,
                    progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn build_map(
    py: Python<'_>,
    scans: &Bound<'_, PyAny>,
    odometry: Option<&Bound<'_, PyAny>>,
    resolution: f64,
    mode: &str,
    dof: &str,
    max_tilt: f64,
    max_range: f64,
    names: Option<Vec<String>>,
    first: usize,
    bucket_radius: f64,
    min_count: u16,
    register_band: Option<Vec<f64>>,
    graph: bool,
    threads: i64,
    progress: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyMapBuild> {
    let mut progress = PyProgress::new(progress)?;
    let mut inputs = Vec::new();
    for (i, item) in scans.try_iter()?.enumerate() {
        let cloud = cloud_arg(&item?, &format!("scans[{i}]"))?.into_owned();
        inputs.push(ScanInput {
            name: format!("scan{i:03}"),
            cloud,
            odometry: None,
        });
    }
    if let Some(names) = names {
        if names.len() != inputs.len() {
            return Err(value_error(format!(
                "names: {} names for {} scans",
                names.len(),
                inputs.len()
            )));
        }
        for (s, n) in inputs.iter_mut().zip(names) {
            s.name = n;
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(s) = inputs.iter().find(|s| !seen.insert(s.name.as_str())) {
            return Err(value_error(format!(
                "names: two scans are named {:?}; names must be unique",
                s.name
            )));
        }
    }
    if let Some(odometry) = odometry {
        let poses: Vec<Bound<'_, PyAny>> = odometry.try_iter()?.collect::<PyResult<_>>()?;
        if poses.len() != inputs.len() {
            return Err(value_error(format!(
                "odometry: {} poses for {} scans",
                poses.len(),
                inputs.len()
            )));
        }
        for (i, (s, p)) in inputs.iter_mut().zip(&poses).enumerate() {
            s.odometry = Some(convert::pose(p, &format!("odometry[{i}]"))?);
        }
    }
    if first >= inputs.len().max(1) {
        return Err(value_error(format!(
            "first: index {first} for {} scans",
            inputs.len()
        )));
    }
    let params = MapParams {
        register: RegisterParams {
            search: SearchParams {
                resolution,
                dof: parse_dof(dof, max_tilt)?,
                max_range,
                ..Default::default()
            },
            refine: Some(IcpParams::default()),
            trust: Default::default(),
        },
        mode: match mode {
            "batch" => MapMode::Batch,
            "sequential" => MapMode::Sequential,
            "incremental" => MapMode::Incremental,
            other => {
                return Err(value_error(format!(
                    "mode: expected \"batch\", \"sequential\" or \"incremental\", got {other:?}"
                )))
            }
        },
        first,
        sensor: SensorModel {
            max_range,
            ..Default::default()
        },
        bucket_radius,
        min_count,
        keep_scan_maps: false,
        register_band: match register_band {
            Some(b) => {
                let [lo, hi] = <[f64; 2]>::try_from(b.as_slice()).map_err(|_| {
                    value_error(format!(
                        "register_band: expected 2 numbers (z_min, z_max in metres), got {}",
                        b.len()
                    ))
                })?;
                Some((lo, hi))
            }
            None => None,
        },
        graph: graph.then(GraphRefineParams::default),
        ..Default::default()
    };
    let (build, report) = detached(py, threads, || {
        olmap::mapping::map_scans(&inputs, &params, "<memory>", &mut |stage, done, total| {
            progress.report(stage, done, total)
        })
    })?
    .py_err()?;
    progress.finish()?;
    let mut poses = vec![None; inputs.len()];
    for p in &build.placed {
        poses[p.index] = Some(p.pose);
    }
    let names = inputs.into_iter().map(|s| s.name).collect();
    Ok(PyMapBuild {
        poses,
        names,
        map: Py::new(py, PyOccupancyMap::from_list(build.map))?,
        report,
    })
}
