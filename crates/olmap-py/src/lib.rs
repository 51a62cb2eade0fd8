//! # `olmap` for Python
//!
//! The extension module `olmap._olmap`, re-exported by the Python package `olmap`
//! (`python/olmap/__init__.py`): a thin layer over the library's typed results. No
//! algorithm lives here; every function parses its arguments into the library's
//! parameters (with the command line's defaults), copies array inputs into Rust-owned
//! values, releases the GIL, calls the library, and returns numpy arrays, small classes and
//! the library's reports as dicts (the schemas of the command line's `--json`).
//!
//! One file per part of the API: [`cloud`] (PointCloud, read/write), [`align`] (align,
//! localize, Alignment, Localizer), [`map`] (OccupancyMap), [`free_space`] (FreeSpaceMap), [`poses`] (read_poses), [`build`] (build_map), [`sim`] (simulate,
//! map_team), [`beacon`] (detect_beacons, mutual_localisation); [`convert`] (numpy in and
//! out), [`errors`] (exceptions) and [`threads`] (GIL release, thread counts).
//!
//! Build and install with `pip install ./crates/olmap-py` (maturin, one abi3 wheel for
//! CPython >= 3.9), or `maturin develop --release` inside a virtual environment.

use pyo3::prelude::*;

mod align;
mod beacon;
mod build;
mod cloud;
mod convert;
mod errors;
mod free_space;
mod map;
mod poses;
mod sim;
mod threads;

/// olmap: 3D mapping and localisation for one or many mobile robots (see the package
/// docstring of `olmap`).
#[pymodule]
fn _olmap(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // A decoder panicking on a damaged file raises olmap's error, without a panic message.
    olmap::guard::quiet_guarded_panics();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("FormatError", m.py().get_type::<errors::FormatError>())?;
    m.add("TooLargeError", m.py().get_type::<errors::TooLargeError>())?;
    m.add_class::<cloud::PyPointCloud>()?;
    m.add_class::<align::PyAlignment>()?;
    m.add_class::<align::PyLocalizer>()?;
    m.add_class::<map::PyOccupancyMap>()?;
    m.add_class::<free_space::PyFreeSpaceMap>()?;
    m.add_class::<build::PyMapBuild>()?;
    m.add_class::<sim::PySimDataset>()?;
    m.add_class::<sim::PyTeamResult>()?;
    m.add_function(wrap_pyfunction!(cloud::read_cloud, m)?)?;
    m.add_function(wrap_pyfunction!(cloud::write_cloud, m)?)?;
    m.add_function(wrap_pyfunction!(poses::read_poses, m)?)?;
    m.add_function(wrap_pyfunction!(align::align, m)?)?;
    m.add_function(wrap_pyfunction!(align::localize, m)?)?;
    m.add_function(wrap_pyfunction!(build::build_map, m)?)?;
    m.add_function(wrap_pyfunction!(sim::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(sim::map_team, m)?)?;
    m.add_function(wrap_pyfunction!(beacon::detect_beacons, m)?)?;
    m.add_function(wrap_pyfunction!(beacon::mutual_localisation, m)?)?;
    Ok(())
}
