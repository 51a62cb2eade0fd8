//! `olmap.PointCloud`, `olmap.read_cloud` and `olmap.write_cloud`.

use std::path::PathBuf;

use nalgebra::Point3;
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArrayLike1};
use olmap::cloud::PointCloud;
use olmap::io::{self, CloudFormat, ReadOptions, WriteOptions};
use pyo3::prelude::*;

use crate::convert::{self, cloud_arg, points_array, vector_array};
use crate::errors::{value_error, IntoPy};

/// A point cloud in its sensor frame: points in metres (stored as float32), optional
/// per-point intensity, and the sensor origin (where rays start when the cloud is ray
/// traced into a map). Immutable: the methods return new clouds.
///
/// ``PointCloud(points, intensity=None, origin=None)``: ``points`` is any (N, 3) array-like
/// of x, y, z in metres (float32 or float64, any memory order; ``np.asarray(o3d_cloud.points)``
/// for an Open3D cloud), ``intensity`` an (N,) array-like, ``origin`` 3 numbers (default
/// 0, 0, 0). Rows that are not finite are refused (ValueError naming the row).
#[pyclass(frozen, module = "olmap", name = "PointCloud")]
pub struct PyPointCloud {
    /// The cloud.
    pub cloud: PointCloud,
    /// The file it was read from, or `<array>`.
    pub source: String,
}

impl PyPointCloud {
    /// A cloud made in memory.
    pub fn from_cloud(cloud: PointCloud) -> Self {
        PyPointCloud {
            cloud,
            source: "<array>".into(),
        }
    }
}

fn intensity_of(obj: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<f32>> {
    let arr: PyArrayLike1<'_, f64, AllowTypeChange> = obj
        .extract()
        .map_err(|_| value_error("intensity: expected an (N,) array of numbers"))?;
    let v = arr.as_array();
    if v.len() != n {
        return Err(value_error(format!(
            "intensity: {} values for {n} points",
            v.len()
        )));
    }
    Ok(v.iter().map(|x| *x as f32).collect())
}

#[pymethods]
impl PyPointCloud {
    #[new]
    #[pyo3(signature = (points, intensity=None, origin=None))]
    fn new(
        points: &Bound<'_, PyAny>,
        intensity: Option<&Bound<'_, PyAny>>,
        origin: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let mut cloud = cloud_arg(points, "points")?.into_owned();
        if let Some(i) = intensity {
            let values = intensity_of(i, cloud.len())?;
            cloud.set_intensity(Some(values)).py_err()?;
        }
        if let Some(o) = origin {
            cloud.set_origin(Point3::from(convert::vector3(o, "origin")?));
        }
        Ok(PyPointCloud::from_cloud(cloud))
    }

    /// The points, an (N, 3) float64 array in metres (a new copy on every access).
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        points_array(py, self.cloud.points())
    }

    /// Per-point intensity, an (N,) float32 array, or None when the cloud has none.
    #[getter]
    fn intensity<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f32>>> {
        self.cloud.intensity().map(|i| i.to_vec().into_pyarray(py))
    }

    /// The sensor origin in the cloud's frame, a (3,) float64 array in metres.
    #[getter]
    fn origin<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let o = self.cloud.origin();
        vector_array(py, [o.x, o.y, o.z])
    }

    /// The file the cloud was read from, or ``"<array>"``.
    #[getter]
    fn source(&self) -> String {
        self.source.clone()
    }

    /// The cloud moved by ``pose`` (a 4x4 homogeneous transform ``T_new_old``): points and
    /// origin transformed, intensity kept.
    fn transformed(&self, pose: &Bound<'_, PyAny>) -> PyResult<Self> {
        let p = convert::pose(pose, "pose")?;
        Ok(PyPointCloud::from_cloud(
            pose.py().detach(|| self.cloud.transformed(&p)),
        ))
    }

    fn __len__(&self) -> usize {
        self.cloud.len()
    }

    fn __repr__(&self) -> String {
        let o = self.cloud.origin();
        format!(
            "PointCloud({} points{}, origin=({}, {}, {}), source={:?})",
            self.cloud.len(),
            if self.cloud.intensity().is_some() {
                " with intensity"
            } else {
                ""
            },
            o.x,
            o.y,
            o.z,
            self.source
        )
    }
}

/// The cloud format named by `name`: a file extension olmap knows ("pcd", "ply", "xyz",
/// "3d", "csv", "bin", "graph", "las", ...).
fn format_named(name: &str) -> PyResult<CloudFormat> {
    let lower = name.trim_start_matches('.').to_ascii_lowercase();
    CloudFormat::ALL
        .into_iter()
        .find(|f| {
            f.extensions()
                .iter()
                .any(|e| e.eq_ignore_ascii_case(&lower))
        })
        .ok_or_else(|| {
            let known: Vec<&str> = CloudFormat::ALL
                .iter()
                .flat_map(|f| f.extensions().iter().copied())
                .collect();
            value_error(format!(
                "format: unknown point-cloud format {name:?}; known: {}",
                known.join(", ")
            ))
        })
}

/// Reads a point cloud from any format olmap reads: PCD (ascii, binary, compressed), PLY,
/// XYZ text, 3DTK ``.3d``, CSV tables, KITTI ``.bin``, OctoMap scan graphs, LAS/LAZ, a scan
/// message of a ROS 2 bag (``"BAG#TOPIC@INDEX"``), ``.bz2``-compressed files.
///
/// Args:
///     path: the file (str or os.PathLike).
///     format: read as this format whatever the name says: a file extension such as
///         ``"pcd"``, ``"xyz"``, ``"3d"`` (default None: from the name and content).
///     valid_3dtk: 3DTK ``.3d`` only: keep only returns between 0.2 m and 32.7 m (drops the
///         near-sensor echoes and the maximum-range sentinel). Default False.
///
/// Returns:
///     PointCloud: points in metres in the sensor frame; ``source`` is the path.
///
/// Raises:
///     FileNotFoundError, PermissionError, IsADirectoryError: the file cannot be opened.
///     olmap.FormatError: the file is not a valid cloud (the message names the line or byte).
///     olmap.TooLargeError: the file claims or decompresses to more than olmap allows.
#[pyfunction]
#[pyo3(signature = (path, format=None, valid_3dtk=false))]
pub fn read_cloud(
    py: Python<'_>,
    path: PathBuf,
    format: Option<&str>,
    valid_3dtk: bool,
) -> PyResult<PyPointCloud> {
    let options = ReadOptions {
        format: format.map(format_named).transpose()?,
        uos_valid_only: valid_3dtk,
        ..Default::default()
    };
    let loaded = py
        .detach(|| io::read_cloud_with(&path, &options))
        .py_err()?;
    Ok(PyPointCloud {
        cloud: loaded.cloud,
        source: path.display().to_string(),
    })
}

/// Writes a point cloud, in the format its name says (``.pcd``, ``.ply``, ``.xyz``,
/// ``.csv``, ``.las``/``.laz``, ...), atomically: the file appears whole or not at all.
///
/// Args:
///     path: the file to write (str or os.PathLike); its folder must exist.
///     points: a PointCloud, or an (N, 3) array-like of x, y, z in metres.
///     format: write this format whatever the name says (an extension such as ``"pcd"``).
///     intensity: an (N,) array-like of intensities for array points (a PointCloud
///         brings its own). Default None.
///
/// Raises:
///     ValueError: bad points or intensity.
///     OSError: the file cannot be written (the message names it).
#[pyfunction]
#[pyo3(signature = (path, points, format=None, intensity=None))]
pub fn write_cloud(
    py: Python<'_>,
    path: PathBuf,
    points: &Bound<'_, PyAny>,
    format: Option<&str>,
    intensity: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    let arg = cloud_arg(points, "points")?;
    let options = WriteOptions {
        format: format.map(format_named).transpose()?,
        ..Default::default()
    };
    let owned;
    let cloud = match intensity {
        Some(i) => {
            let mut c = arg.get().clone();
            c.set_intensity(Some(intensity_of(i, c.len())?)).py_err()?;
            owned = c;
            &owned
        }
        None => arg.get(),
    };
    py.detach(|| io::write_cloud(&path, cloud, &options))
        .py_err()
}
