//! `olmap.read_poses`: pose files as numpy transforms.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::pose_array;
use crate::errors::IntoPy;

/// Reads a pose file of any kind olmap reads: an olmap pose list (``name x y z yaw pitch
/// roll`` in metres and degrees), a CSV pose table, 3DTK ``.pose`` or ``.frames``.
///
/// Args:
///     path: the file (str or os.PathLike).
///
/// Returns:
///     dict: pose name (a scan's file stem) to its 4x4 float64 transform, in file order.
///
/// Raises:
///     FileNotFoundError, PermissionError: the file cannot be opened.
///     olmap.FormatError: the file is not a valid pose file (the message names the line).
#[pyfunction]
pub fn read_poses<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let list = py.detach(|| olmap::io::read_poses(&path)).py_err()?;
    let d = PyDict::new(py);
    for p in &list.poses {
        d.set_item(&p.name, pose_array(py, &p.pose))?;
    }
    Ok(d)
}
