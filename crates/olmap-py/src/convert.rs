//! numpy and Python values in and out: point arrays, poses, reports.
//!
//! Inputs are copied into Rust-owned values before the GIL is released (numpy memory may
//! change or go while other Python threads run); an `olmap.PointCloud` is immutable and
//! shared without a copy.

use nalgebra::{Matrix4, Point3, Vector3};
use numpy::ndarray::{Array1, Array2, ArrayView2};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArrayLike1, PyArrayLike2};
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use pyo3::prelude::*;

use crate::cloud::PyPointCloud;
use crate::errors::value_error;

/// How far from a rotation a 4x4 pose's upper-left block may be (orthonormality error).
pub const POSE_TOLERANCE: f64 = 1e-6;

/// A point cloud argument: an `olmap.PointCloud` (shared, immutable) or points copied from
/// an array.
pub enum CloudArg {
    /// An `olmap.PointCloud`.
    Shared(Py<PyPointCloud>),
    /// Points from an `(N, 3)` array.
    Owned(PointCloud),
}

impl CloudArg {
    /// The cloud.
    pub fn get(&self) -> &PointCloud {
        match self {
            CloudArg::Shared(c) => &c.get().cloud,
            CloudArg::Owned(c) => c,
        }
    }

    /// The name reports give it: the file it was read from, or `<array>`.
    pub fn name(&self) -> String {
        match self {
            CloudArg::Shared(c) => c.get().source.clone(),
            CloudArg::Owned(_) => "<array>".to_string(),
        }
    }

    /// The cloud, owned (copied from a shared one).
    pub fn into_owned(self) -> PointCloud {
        match self {
            CloudArg::Shared(c) => c.get().cloud.clone(),
            CloudArg::Owned(c) => c,
        }
    }
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// An `(N, 3)` array of finite numbers as f64 rows (any dtype numpy can cast to float64
/// without loss of meaning, any memory order or strides), `what` naming the argument in
/// errors.
pub fn array_n3<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Array2<f64>> {
    let arr: PyArrayLike2<'py, f64, AllowTypeChange> = obj.extract().map_err(|_| {
        value_error(format!(
            "{what}: expected an olmap.PointCloud or an (N, 3) array of numbers, got {}",
            describe(obj)
        ))
    })?;
    let view: ArrayView2<'_, f64> = arr.as_array();
    if view.ncols() != 3 {
        return Err(value_error(format!(
            "{what}: expected an (N, 3) array of x, y, z in metres, got shape ({}, {})",
            view.nrows(),
            view.ncols()
        )));
    }
    // Points are stored as float32: a value beyond its range (3.4e38) would become inf.
    if let Some((i, row)) = view
        .rows()
        .into_iter()
        .enumerate()
        .find(|(_, r)| r.iter().any(|v| !(*v as f32).is_finite()))
    {
        return Err(value_error(format!(
            "{what}: row {i} is not finite in float32 ({}, {}, {}); drop such rows first, \
             e.g. points[np.isfinite(points).all(axis=1)]",
            row[0], row[1], row[2]
        )));
    }
    Ok(view.to_owned())
}

fn describe(obj: &Bound<'_, PyAny>) -> String {
    match obj.getattr("shape") {
        Ok(shape) => format!("{} of shape {}", type_name(obj), shape),
        Err(_) => type_name(obj),
    }
}

/// A cloud from rows of x, y, z (metres; stored as f32 like every olmap cloud).
pub fn cloud_of_rows(rows: &Array2<f64>) -> PointCloud {
    PointCloud::from_points(
        rows.rows()
            .into_iter()
            .map(|r| Point3::new(r[0] as f32, r[1] as f32, r[2] as f32))
            .collect(),
    )
}

/// A cloud argument: an `olmap.PointCloud` or an `(N, 3)` array-like.
pub fn cloud_arg(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<CloudArg> {
    if let Ok(c) = obj.extract::<Py<PyPointCloud>>() {
        return Ok(CloudArg::Shared(c));
    }
    Ok(CloudArg::Owned(cloud_of_rows(&array_n3(obj, what)?)))
}

/// A vector of 3 finite numbers.
pub fn vector3(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vector3<f64>> {
    let arr: PyArrayLike1<'_, f64, AllowTypeChange> = obj.extract().map_err(|_| {
        value_error(format!(
            "{what}: expected 3 numbers (x, y, z), got {}",
            describe(obj)
        ))
    })?;
    let v = arr.as_array();
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        return Err(value_error(format!(
            "{what}: expected 3 finite numbers (x, y, z), got {v}"
        )));
    }
    Ok(Vector3::new(v[0], v[1], v[2]))
}

/// A rigid transform from a 4x4 homogeneous matrix (rotation block orthonormal within
/// [`POSE_TOLERANCE`], last row 0 0 0 1).
pub fn pose(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Pose> {
    let arr: PyArrayLike2<'_, f64, AllowTypeChange> = obj.extract().map_err(|_| {
        value_error(format!(
            "{what}: expected a 4x4 homogeneous transform, got {}",
            describe(obj)
        ))
    })?;
    let v = arr.as_array();
    if v.dim() != (4, 4) {
        return Err(value_error(format!(
            "{what}: expected a 4x4 homogeneous transform, got shape {:?}",
            v.shape()
        )));
    }
    let m = Matrix4::from_fn(|r, c| v[[r, c]]);
    Pose::from_matrix4(&m, POSE_TOLERANCE).map_err(|e| value_error(format!("{what}: {e}")))
}

/// A pose as a 4x4 float64 array.
pub fn pose_array<'py>(py: Python<'py>, p: &Pose) -> Bound<'py, PyArray2<f64>> {
    let m = p.to_matrix4();
    Array2::from_shape_fn((4, 4), |(r, c)| m[(r, c)]).into_pyarray(py)
}

/// Points as an `(N, 3)` float64 array.
pub fn points_array<'py>(py: Python<'py>, points: &[Point3<f32>]) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((points.len(), 3), |(i, k)| f64::from(points[i][k])).into_pyarray(py)
}

/// A vector as a `(3,)` float64 array.
pub fn vector_array<'py>(py: Python<'py>, v: [f64; 3]) -> Bound<'py, PyArray1<f64>> {
    Array1::from(v.to_vec()).into_pyarray(py)
}

/// A serialisable report as Python values (dicts, lists, numbers, strings), through JSON:
/// the same schema as the command line's `--json`.
pub fn to_python<'py, T: serde::Serialize>(
    py: Python<'py>,
    value: &T,
) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("report: {e}")))?;
    py.import("json")?.call_method1("loads", (text,))
}
