//! `olmap.OccupancyMap`: a sparse voxel map of integer log-odds counts (an occupancy
//! list, thesis §5.3.1).

use std::path::PathBuf;
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

use nalgebra::{Point3, Vector3};
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2};
use olmap::geometry::Pose;
use olmap::occupancy::{self, OccupancyList, SensorModel};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, array_n3, cloud_arg, vector_array};
use crate::errors::IntoPy;
use crate::threads::detached;

/// A sparse 3D occupancy map: a hashed list of voxels (edge ``resolution`` metres, keys
/// ``floor(coord / resolution)``) each holding an integer count (hits add, rays passing
/// through subtract; 0 is unknown or free and not stored). Reads and writes ``.olm``
/// (olmap's format) and ``.bt`` (OctoMap's binary tree).
///
/// ``OccupancyMap(resolution=0.05)``: an empty map, ``resolution`` in metres.
///
/// Points are stored and looked up as float32, like every olmap cloud: ``counts(p)`` finds
/// the voxels ``insert_scan(p)`` filled. A map may be used from several Python threads:
/// queries run at the same time, an insertion or merge waits for them (and they for it),
/// all with the GIL released.
#[pyclass(frozen, module = "olmap", name = "OccupancyMap")]
pub struct PyOccupancyMap {
    list: RwLock<OccupancyList>,
    resolution: f64,
    source: String,
}

impl PyOccupancyMap {
    /// A map made in memory.
    pub fn from_list(list: OccupancyList) -> Self {
        Self::with_source(list, "<map>".into())
    }

    fn with_source(list: OccupancyList, source: String) -> Self {
        PyOccupancyMap {
            resolution: list.resolution(),
            list: RwLock::new(list),
            source,
        }
    }

    /// The list, for reading (other readers may hold it too; a writer waits). Call with the
    /// GIL released: a writer may hold the lock for a whole insertion.
    pub fn read(&self) -> RwLockReadGuard<'_, OccupancyList> {
        self.list.read().unwrap_or_else(|e| e.into_inner())
    }

    /// The list, for writing (waits for every reader). Call with the GIL released.
    fn write(&self) -> RwLockWriteGuard<'_, OccupancyList> {
        self.list.write().unwrap_or_else(|e| e.into_inner())
    }

    /// Voxel edge, metres.
    pub fn resolution_m(&self) -> f64 {
        self.resolution
    }

    /// The file the map was loaded from, or `<map>`.
    pub fn source_name(&self) -> String {
        self.source.clone()
    }
}

fn stats_dict<'py>(py: Python<'py>, s: &occupancy::InsertStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("rays", s.rays)?;
    d.set_item("truncated", s.truncated)?;
    d.set_item("skipped", s.skipped)?;
    d.set_item("voxels_traversed", s.voxels_traversed)?;
    d.set_item("hit_voxels", s.hit_voxels)?;
    d.set_item("missed_voxels", s.missed_voxels)?;
    d.set_item("removed_voxels", s.removed_voxels)?;
    Ok(d)
}

#[pymethods]
impl PyOccupancyMap {
    #[new]
    #[pyo3(signature = (resolution=0.05))]
    fn new(resolution: f64) -> PyResult<Self> {
        Ok(PyOccupancyMap::from_list(
            OccupancyList::new(resolution).py_err()?,
        ))
    }

    /// Voxel edge, metres.
    #[getter]
    fn resolution(&self) -> f64 {
        self.resolution
    }

    /// The file the map was loaded from, or ``"<map>"``.
    #[getter]
    fn source(&self) -> String {
        self.source.clone()
    }

    fn __len__(&self, py: Python<'_>) -> usize {
        py.detach(|| self.read().len())
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "OccupancyMap({} voxels at {} m, source={:?})",
            self.__len__(py),
            self.resolution,
            self.source
        )
    }

    /// Adds one scan.
    ///
    /// Args:
    ///     points: the scan in its sensor frame: a PointCloud (its origin is where rays
    ///         start) or an (N, 3) array-like of metres (origin 0, 0, 0).
    ///     pose: ``T_map_sensor``, a 4x4 transform placing the scan in the map. Default
    ///         identity.
    ///     ray_trace: True (default): the thesis' ray-trace sensor model: each endpoint
    ///         voxel gains 1 and every stored voxel a ray passes through before it loses 1
    ///         (removed at 0), once per scan; rays longer than ``max_range`` give free space
    ///         only. False: endpoints only, each point adds 1 (as ``olmap voxelize``
    ///         without ``--ray-trace``; ``max_range`` does not apply).
    ///     max_range: ray tracing: where rays are cut, metres (default 30).
    ///     threads: worker threads, 0 (default) for one per core.
    ///
    /// Returns:
    ///     dict: ``rays``, ``truncated``, ``skipped``, ``voxels_traversed``, ``hit_voxels``,
    ///     ``missed_voxels``, ``removed_voxels`` (endpoints only: ``rays`` and ``skipped``).
    ///
    /// Raises:
    ///     ValueError: a bad pose or range, or a sensor origin outside the map's range.
    ///     olmap.TooLargeError: a point whose voxel key is outside the representable range.
    #[pyo3(signature = (points, pose=None, ray_trace=true, max_range=30.0, threads=0))]
    fn insert_scan<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        pose: Option<&Bound<'py, PyAny>>,
        ray_trace: bool,
        max_range: f64,
        threads: i64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let cloud = cloud_arg(points, "points")?;
        let pose = match pose {
            Some(p) => convert::pose(p, "pose")?,
            None => Pose::identity(),
        };
        let model = SensorModel {
            max_range,
            ..Default::default()
        };
        if ray_trace {
            model.validate().py_err()?;
        }
        let stats = detached(py, threads, || -> olmap::Result<occupancy::InsertStats> {
            let c = cloud.get();
            let mut list = self.write();
            list.check_keys(c, &pose, "points")?;
            if ray_trace {
                list.insert_scan(c, &pose, &model)
            } else {
                let skipped = list.add_points(c, &pose, model.hit) as u64;
                list.clamp_counts(model.max_count);
                Ok(occupancy::InsertStats {
                    rays: c.len() as u64 - skipped,
                    skipped,
                    ..Default::default()
                })
            }
        })?
        .py_err()?;
        stats_dict(py, &stats)
    }

    /// The count of the voxel holding ``xyz`` (3 numbers, metres, rounded to float32 as
    /// stored points are); 0 when not stored.
    fn count_at(&self, py: Python<'_>, xyz: &Bound<'_, PyAny>) -> PyResult<u16> {
        let p = as_stored(convert::vector3(xyz, "xyz")?);
        Ok(py.detach(|| self.read().count_at(&p)))
    }

    /// The counts of the voxels holding each point of an (N, 3) array-like (metres, rounded
    /// to float32 as stored points are), as an (N,) int64 array.
    fn counts<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let rows = array_n3(points, "points")?;
        let counts: Vec<i64> = py.detach(|| {
            let list = self.read();
            rows.rows()
                .into_iter()
                .map(|r| i64::from(list.count_at(&as_stored(Vector3::new(r[0], r[1], r[2])))))
                .collect()
        });
        Ok(counts.into_pyarray(py))
    }

    /// Every stored voxel: ``(centres, counts)``, an (M, 3) float64 array of voxel centres
    /// in metres and an (M,) int64 array, sorted by voxel key (x, then y, then z).
    fn voxels<'py>(
        &self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<i64>>) {
        let (centres, counts) = py.detach(|| {
            let list = self.read();
            let sorted = list.sorted();
            let centres =
                Array2::from_shape_fn((sorted.len(), 3), |(i, k)| list.center(sorted[i].0)[k]);
            let counts = Array1::from_iter(sorted.iter().map(|(_, c)| i64::from(*c)));
            (centres, counts)
        });
        (centres.into_pyarray(py), counts.into_pyarray(py))
    }

    /// Casts a ray through the map.
    ///
    /// Args:
    ///     origin: 3 numbers, metres.
    ///     direction: 3 numbers, any non-zero length.
    ///     max_range: how far to look, metres (default 30).
    ///     min_count: the least count that stops the ray (default 1).
    ///
    /// Returns:
    ///     ``(centre, distance)``: the first voxel with at least ``min_count`` met by the
    ///     ray (its centre, a (3,) array in metres) and the distance from ``origin`` to
    ///     where the ray enters it (metres, 0 when ``origin`` is inside it); or None when
    ///     nothing is met within ``max_range``.
    #[pyo3(signature = (origin, direction, max_range=30.0, min_count=1))]
    fn cast_ray<'py>(
        &self,
        py: Python<'py>,
        origin: &Bound<'py, PyAny>,
        direction: &Bound<'py, PyAny>,
        max_range: f64,
        min_count: u16,
    ) -> PyResult<Option<(Bound<'py, PyArray1<f64>>, f64)>> {
        let o = Point3::from(convert::vector3(origin, "origin")?);
        let d = convert::vector3(direction, "direction")?;
        let hit = py
            .detach(|| {
                let list = self.read();
                list.cast_ray(&o, &d, max_range, min_count.max(1))
                    .map(|h| h.map(|h| (list.center(h.key), h.distance)))
            })
            .py_err()?;
        Ok(hit.map(|(c, distance)| (vector_array(py, [c.x, c.y, c.z]), distance)))
    }

    /// Adds ``other``'s counts voxel by voxel (both maps must have the same resolution);
    /// counts are clamped at the sensor model's maximum (1023). ``m.merge(m)`` doubles
    /// every count.
    fn merge(&self, py: Python<'_>, other: &Bound<'_, PyOccupancyMap>) -> PyResult<()> {
        let other = other.get();
        py.detach(|| {
            if std::ptr::eq(self, other) {
                let copy = self.read().clone();
                self.write().merge(&copy)
            } else {
                let theirs = other.read();
                self.write().merge(&theirs)
            }
        })
        .py_err()
    }

    /// A new map holding only the voxels with a count of at least ``min_count``.
    fn threshold(&self, py: Python<'_>, min_count: u16) -> Self {
        py.detach(|| PyOccupancyMap::from_list(self.read().threshold(min_count)))
    }

    /// Writes the map, as ``.olm`` or ``.bt`` (OctoMap) by the file name, atomically.
    ///
    /// Raises:
    ///     olmap.FormatError: the name is neither ``.olm`` nor ``.bt``.
    ///     OSError: the file cannot be written (the message names it).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| occupancy::write_map(&path, &self.read()))
            .py_err()?;
        Ok(())
    }

    /// Reads a map from ``.olm`` or ``.bt`` (OctoMap binary tree; occupied leaves become
    /// voxels at the tree's resolution).
    ///
    /// Raises:
    ///     FileNotFoundError, PermissionError, IsADirectoryError: the file cannot be opened.
    ///     olmap.FormatError: the file is not a valid map (or not named .olm or .bt).
    ///     olmap.TooLargeError: the tree expands beyond olmap's voxel limit.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let loaded = py.detach(|| occupancy::read_map(&path)).py_err()?;
        Ok(PyOccupancyMap::with_source(
            loaded.map,
            path.display().to_string(),
        ))
    }
}

/// A query point as the map stores points: rounded to float32 (the precision of every
/// olmap cloud), so that a point looks up the voxel its insertion filled.
pub(crate) fn as_stored(p: Vector3<f64>) -> Point3<f64> {
    Point3::new(
        f64::from(p.x as f32),
        f64::from(p.y as f32),
        f64::from(p.z as f32),
    )
}
