//! `olmap.FreeSpaceMap`: a log-odds voxel map with free space, at OctoMap's semantics
//! (unknown / free / occupied).

use std::path::PathBuf;
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

use nalgebra::Vector3;
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2};
use olmap::geometry::{Pose, VoxelKey};
use olmap::occupancy::{LogOddsMap, LogOddsModel, VoxelState};
use pyo3::prelude::*;

use crate::convert::{self, array_n3, cloud_arg, to_python};
use crate::errors::IntoPy;
use crate::map::as_stored;
use crate::threads::detached;

/// A voxel's state as a number in the arrays: 0 unknown, 1 free, 2 occupied.
fn code(s: VoxelState) -> u8 {
    match s {
        VoxelState::Unknown => 0,
        VoxelState::Free => 1,
        VoxelState::Occupied => 2,
    }
}

/// A 3D occupancy map that keeps free space too, at OctoMap's semantics: every voxel a
/// ray crosses before its endpoint's is observed free, the endpoint's occupied (once per
/// scan; an endpoint wins over a crossing), as log-odds clamped between ``clamp_min`` and
/// ``clamp_max``; a known voxel is occupied at or above ``occupancy_threshold``. The same
/// scans and model give the same classification as an OctoMap ``OcTree``
/// (``olmap voxelize --free-space``).
///
/// ``FreeSpaceMap(resolution=0.05, prob_hit=0.7, prob_miss=0.4, clamp_min=0.1192,
/// clamp_max=0.971, occupancy_threshold=0.5, max_range=None)``: an empty map; resolution
/// and ``max_range`` in metres (None: rays are never cut, as OctoMap's default).
///
/// States in arrays: ``FreeSpaceMap.UNKNOWN`` = 0, ``FREE`` = 1, ``OCCUPIED`` = 2.
/// Points are stored and looked up as float32, like every olmap cloud: ``states(p)`` finds
/// the voxels ``insert_scan(p)`` updated.
#[pyclass(frozen, module = "olmap", name = "FreeSpaceMap")]
pub struct PyFreeSpaceMap {
    map: RwLock<LogOddsMap>,
    resolution: f64,
}

impl PyFreeSpaceMap {
    pub(crate) fn read(&self) -> RwLockReadGuard<'_, LogOddsMap> {
        self.map.read().unwrap_or_else(|e| e.into_inner())
    }

    fn write(&self) -> RwLockWriteGuard<'_, LogOddsMap> {
        self.map.write().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl PyFreeSpaceMap {
    /// Never observed.
    #[classattr]
    const UNKNOWN: u8 = 0;
    /// Observed, below the occupancy threshold.
    #[classattr]
    const FREE: u8 = 1;
    /// Observed, at or above the occupancy threshold.
    #[classattr]
    const OCCUPIED: u8 = 2;

    #[new]
    #[pyo3(signature = (resolution=0.05, prob_hit=0.7, prob_miss=0.4, clamp_min=0.1192,
                        clamp_max=0.971, occupancy_threshold=0.5, max_range=None))]
    fn new(
        resolution: f64,
        prob_hit: f64,
        prob_miss: f64,
        clamp_min: f64,
        clamp_max: f64,
        occupancy_threshold: f64,
        max_range: Option<f64>,
    ) -> PyResult<Self> {
        let model = LogOddsModel {
            prob_hit,
            prob_miss,
            clamp_min,
            clamp_max,
            occupancy_threshold,
            max_range: max_range.unwrap_or(f64::INFINITY),
        };
        Ok(PyFreeSpaceMap {
            map: RwLock::new(LogOddsMap::new(resolution, model).py_err()?),
            resolution,
        })
    }

    /// Voxel edge, metres.
    #[getter]
    fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Known (observed) voxels.
    fn __len__(&self, py: Python<'_>) -> usize {
        py.detach(|| self.read().len())
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "FreeSpaceMap({} known voxels at {} m)",
            self.__len__(py),
            self.resolution
        )
    }

    /// Adds one scan.
    ///
    /// Args:
    ///     points: the scan in its sensor frame: a PointCloud (its origin is where rays
    ///         start) or an (N, 3) array-like of metres (origin 0, 0, 0).
    ///     pose: ``T_map_sensor``, a 4x4 transform placing the scan in the map. Default
    ///         identity.
    ///     threads: worker threads, 0 (default) for one per core. The map is the same for
    ///         any count.
    ///
    /// Returns:
    ///     dict: ``rays``, ``truncated``, ``skipped``, ``voxels_traversed``,
    ///     ``occupied_updates``, ``free_updates``, ``new_voxels``.
    ///
    /// Raises:
    ///     ValueError: a bad pose, or a sensor origin outside the map's range.
    ///     olmap.TooLargeError: the scan would take the map beyond its brick limit (use a
    ///         coarser resolution or a max_range); the map is unchanged.
    #[pyo3(signature = (points, pose=None, threads=0))]
    fn insert_scan<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        pose: Option<&Bound<'py, PyAny>>,
        threads: i64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let cloud = cloud_arg(points, "points")?;
        let pose = match pose {
            Some(p) => convert::pose(p, "pose")?,
            None => Pose::identity(),
        };
        let stats =
            detached(py, threads, || self.write().insert_scan(cloud.get(), &pose))?.py_err()?;
        to_python(py, &stats)
    }

    /// The state of the voxel holding each point of an (N, 3) array-like (metres), as an
    /// (N,) uint8 array: 0 unknown, 1 free, 2 occupied.
    fn states<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<u8>>> {
        let rows = array_n3(points, "points")?;
        let states: Vec<u8> = py.detach(|| {
            let map = self.read();
            rows.rows()
                .into_iter()
                .map(|r| code(map.state_at(&as_stored(Vector3::new(r[0], r[1], r[2])))))
                .collect()
        });
        Ok(states.into_pyarray(py))
    }

    /// The occupancy probability of the voxel holding each point of an (N, 3) array-like
    /// (metres), as an (N,) float64 array; NaN for unknown voxels.
    fn probabilities<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let rows = array_n3(points, "points")?;
        let res = self.resolution;
        let p: Vec<f64> = py.detach(|| {
            let map = self.read();
            rows.rows()
                .into_iter()
                .map(|r| {
                    VoxelKey::from_point(&as_stored(Vector3::new(r[0], r[1], r[2])), res)
                        .and_then(|k| map.probability(&k))
                        .unwrap_or(f64::NAN)
                })
                .collect()
        });
        Ok(p.into_pyarray(py))
    }

    /// Every known voxel: ``(centres, states)``, an (M, 3) float64 array of voxel centres
    /// in metres and an (M,) uint8 array (1 free, 2 occupied), sorted by voxel key (x,
    /// then y, then z).
    fn voxels<'py>(
        &self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<u8>>) {
        let res = self.resolution;
        let (centres, states) = py.detach(|| {
            let map = self.read();
            let mut all: Vec<(VoxelKey, VoxelState)> = map.voxels().collect();
            all.sort_unstable_by_key(|(k, _)| (k.x, k.y, k.z));
            let centres = Array2::from_shape_fn((all.len(), 3), |(i, j)| all[i].0.center(res)[j]);
            let states = Array1::from_iter(all.iter().map(|(_, s)| code(*s)));
            (centres, states)
        });
        (centres.into_pyarray(py), states.into_pyarray(py))
    }

    /// What the map holds: ``voxels``, ``occupied``, ``free``, ``bricks``,
    /// ``memory_bytes``.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let s = py.detach(|| self.read().stats());
        to_python(py, &s)
    }

    /// Writes the map as an OctoMap ``.bt`` tree with free and occupied nodes (OctoMap's
    /// tools and octovis read it), atomically.
    ///
    /// Raises:
    ///     ValueError: a voxel outside OctoMap's key range (±32768 voxels).
    ///     OSError: the file cannot be written (the message names it).
    fn save_bt(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| self.read().write_bt(&path)).py_err()?;
        Ok(())
    }
}
