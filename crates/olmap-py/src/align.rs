//! `olmap.align`, `olmap.localize` and their result, `olmap.Alignment`.

use numpy::PyArray2;
use olmap::align::icp::IcpParams;
use olmap::align::{
    self as library, AlignmentReport, Dof, Region, RegisterParams, Registration, SearchMode,
    SearchParams,
};
use olmap::geometry::Pose;
use pyo3::prelude::*;

use crate::convert::{self, cloud_arg, pose_array, to_python};
use crate::errors::{value_error, IntoPy};
use crate::free_space::PyFreeSpaceMap;
use crate::map::PyOccupancyMap;
use crate::threads::detached;

/// The degrees of freedom named `name` ("xy-yaw", "xyz-yaw", "6dof"), `max_tilt` in degrees.
pub fn dof(name: &str, max_tilt_deg: f64) -> PyResult<Dof> {
    match name {
        "xy-yaw" => Ok(Dof::XyYaw),
        "xyz-yaw" => Ok(Dof::XyzYaw),
        // The library checks the range (SearchParams::validate).
        "6dof" => Ok(Dof::SixDof {
            max_tilt: max_tilt_deg.to_radians(),
        }),
        other => Err(value_error(format!(
            "dof: expected \"xy-yaw\", \"xyz-yaw\" or \"6dof\", got {other:?}"
        ))),
    }
}

/// The registration parameters of `align`/`localize`, as the command line builds them.
#[allow(clippy::too_many_arguments)]
fn register_params(
    resolution: f64,
    levels: usize,
    dof_name: &str,
    max_tilt: f64,
    guess: Option<&Bound<'_, PyAny>>,
    window: Option<Vec<f64>>,
    search: &str,
    refine: bool,
    max_range: f64,
) -> PyResult<RegisterParams> {
    let prior = match guess {
        Some(g) => convert::pose(g, "guess")?,
        None => Pose::identity(),
    };
    let region = match window {
        Some(w) => {
            let [xy, z, yaw] = <[f64; 3]>::try_from(w.as_slice()).map_err(|_| {
                value_error(format!(
                    "window: expected 3 numbers (xy, z, yaw: metres, metres, degrees), got {}",
                    w.len()
                ))
            })?;
            if guess.is_none() {
                return Err(value_error("window needs guess (the window's centre)"));
            }
            Region::Window {
                xy,
                z,
                yaw: yaw.to_radians(),
            }
        }
        None => Region::Global,
    };
    let search = match search {
        "multires" => SearchMode::MultiResolution,
        "exact" => SearchMode::Exact,
        other => {
            return Err(value_error(format!(
                "search: expected \"multires\" or \"exact\", got {other:?}"
            )))
        }
    };
    Ok(RegisterParams {
        search: SearchParams {
            resolution,
            levels,
            dof: dof(dof_name, max_tilt)?,
            region,
            prior,
            max_range,
            search,
            exact_max_work: library::EXACT_MAX_WORK,
            ..Default::default()
        },
        refine: refine.then(IcpParams::default),
        trust: Default::default(),
    })
}

/// The result of ``olmap.align`` or ``olmap.localize``: the pose, the verdict and the
/// evidence.
///
/// Attributes:
///     T_target_source: (4, 4) float64 array mapping source points into the target frame
///         (``p_target = R p_source + t``; metres).
///     trusted: whether every trust test passed. An untrusted pose must not be acted on.
///     doubts: the failed trust tests, in words (empty when trusted).
///     significance: the search's significance z (best overlap against the distribution of
///         overlaps over all poses tried; larger is more distinct).
///     overlap: source voxels that meet occupied target voxels at the search's pose.
///     overlap_fraction: ``overlap`` over the source voxels searched (0..1).
///     ambiguity: distinct near-best solutions the search found (1 when unique).
///     weakly_constrained: axes the refinement could not fix (a corridor's length, a
///         floor's x, y, yaw), in words.
///     seconds: wall time of the whole registration.
///     report: a dict, the same schema as ``olmap align --json``.
#[pyclass(frozen, module = "olmap", name = "Alignment")]
pub struct PyAlignment {
    pose: Pose,
    /// Whether every trust test passed.
    #[pyo3(get)]
    trusted: bool,
    /// The failed trust tests, in words.
    #[pyo3(get)]
    doubts: Vec<String>,
    /// The search's significance z.
    #[pyo3(get)]
    significance: f64,
    /// Source voxels meeting occupied target voxels at the search's pose.
    #[pyo3(get)]
    overlap: u64,
    /// ``overlap`` over the source voxels searched.
    #[pyo3(get)]
    overlap_fraction: f64,
    /// Distinct near-best solutions of the search (1: unique).
    #[pyo3(get)]
    ambiguity: usize,
    /// Axes the refinement left weakly constrained, in words.
    #[pyo3(get)]
    weakly_constrained: Vec<String>,
    /// Wall time of the registration, seconds.
    #[pyo3(get)]
    seconds: f64,
    report: AlignmentReport,
}

impl PyAlignment {
    fn new(r: &Registration, source: &str, target: &str) -> Self {
        PyAlignment {
            pose: r.pose,
            trusted: r.trusted,
            doubts: r.doubts.clone(),
            significance: r.search.significance,
            overlap: r.search.overlap,
            overlap_fraction: r.search.overlap_fraction,
            ambiguity: r.search.ambiguity,
            weakly_constrained: r
                .refinement
                .as_ref()
                .map(|f| f.degeneracy.weak.clone())
                .unwrap_or_default(),
            seconds: r.seconds,
            report: AlignmentReport::new(r, source, target),
        }
    }
}

#[pymethods]
impl PyAlignment {
    /// (4, 4) float64 array ``T_target_source``.
    #[getter(T_target_source)]
    fn t_target_source<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        pose_array(py, &self.pose)
    }
    /// The report as a dict (the ``olmap align --json`` schema).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.report)
    }

    fn __repr__(&self) -> String {
        let t = self.pose.translation();
        let (yaw, _, _) = self.pose.yaw_pitch_roll();
        format!(
            "Alignment(translation=({:.4}, {:.4}, {:.4}) m, yaw={:.3} deg, trusted={}, \
             significance={:.1}, overlap_fraction={:.3}{})",
            t.x,
            t.y,
            t.z,
            yaw.to_degrees(),
            if self.trusted { "True" } else { "False" },
            self.significance,
            self.overlap_fraction,
            if self.trusted {
                String::new()
            } else {
                format!(", doubts={:?}", self.doubts)
            }
        )
    }
}

/// Registers ``source`` onto ``target`` with no initial guess: the multi-resolution search
/// over voxel overlap (thesis §5.3.3), point-to-plane ICP, then the trust tests. Same
/// inputs, same result as ``olmap align``, bit for bit, whatever the number of threads.
/// The GIL is released while it runs.
///
/// Args:
///     source: the scan to place, in its sensor frame: a PointCloud or an (N, 3)
///         array-like of metres (float32 or float64, any memory order).
///     target: the scan to place it in (same kinds).
///     resolution: finest voxel edge of the search, metres. Default 0.1.
///     dof: degrees of freedom searched: ``"xy-yaw"``, ``"xyz-yaw"`` (default; roll and
///         pitch from the prior: gravity-aligned robots) or ``"6dof"``.
///     max_tilt: ``"6dof"`` only: largest roll and pitch searched away from the prior,
///         degrees. Default 15.
///     guess: a prior pose ``T_target_source`` (4x4). Without ``window`` it only supplies
///         roll and pitch (and z for ``"xy-yaw"``). Default None (identity).
///     window: search only ``(xy, z, yaw)`` half-widths around ``guess`` (metres, metres,
///         degrees) instead of the whole target and every heading. Needs ``guess``.
///         Default None (global).
///     search: ``"multires"`` (the thesis' search, default) or ``"exact"`` (branch and
///         bound: the best pose of the finest lattice, guaranteed, slower).
///     refine: run the ICP refinement. Default True.
///     max_range: ignore source points farther than this from the sensor, metres.
///         Default 30.
///     threads: worker threads, 0 (default) for one per core; more than the machine's
///         cores are capped with a RuntimeWarning.
///     levels: pyramid levels, 0 (default) chooses.
///
/// Returns:
///     Alignment: ``T_target_source``, ``trusted``, ``doubts``, ``significance``,
///     ``overlap``, ``overlap_fraction``, ``ambiguity``, ``seconds``, ``report``.
///
/// Raises:
///     ValueError: a bad argument, or an empty target or no source point in range.
///     olmap.TooLargeError: the search would need more memory than olmap allows.
#[pyfunction]
#[pyo3(signature = (source, target, resolution=0.1, dof="xyz-yaw", max_tilt=15.0, guess=None,
                    window=None, search="multires", refine=true, max_range=30.0, threads=0,
                    levels=0))]
#[allow(clippy::too_many_arguments)]
pub fn align(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    resolution: f64,
    dof: &str,
    max_tilt: f64,
    guess: Option<&Bound<'_, PyAny>>,
    window: Option<Vec<f64>>,
    search: &str,
    refine: bool,
    max_range: f64,
    threads: i64,
    levels: usize,
) -> PyResult<PyAlignment> {
    let params = register_params(
        resolution, levels, dof, max_tilt, guess, window, search, refine, max_range,
    )?;
    let (s, t) = (cloud_arg(source, "source")?, cloud_arg(target, "target")?);
    let r = detached(py, threads, || library::register(s.get(), t.get(), &params))?.py_err()?;
    Ok(PyAlignment::new(&r, &s.name(), &t.name()))
}

/// Localises a scan in a map: ``align`` against an OccupancyMap (the score is the plain
/// overlap, as it stores no free space) or a FreeSpaceMap (its occupied voxels, and scans
/// checked against its free space too, as ``align`` checks two scans against each other's
/// rays: what keeps a ``window`` that leaves out the true pose from being trusted at a
/// look-alike inside it; globally a match is trusted only where the map's surfaces alone
/// single it out), then ICP against the map's voxel centres. Same result as ``olmap
/// localize`` (a FreeSpaceMap as the ``.bt`` tree it writes).
///
/// Args:
///     scan: a PointCloud or an (N, 3) array-like of metres, in its sensor frame.
///     map: an OccupancyMap or a FreeSpaceMap.
///     dof, max_tilt, guess, window, search, refine, max_range, threads, levels: as for
///         ``align``.
///     resolution: finest voxel edge of the search, metres. Default 0.1. A map finer than
///         this is read at its pyramid level closest to it without exceeding it (its voxel
///         edge doubled as often as that allows: a 0.025 m map at 0.1 m, a 0.03 m map at
///         0.06 m); a map at or above it at its own.
///
/// Returns:
///     Alignment: ``T_target_source`` is ``T_map_scan``.
#[pyfunction]
#[pyo3(signature = (scan, map, dof="xyz-yaw", max_tilt=15.0, guess=None, window=None,
                    search="multires", refine=true, max_range=30.0, threads=0, levels=0,
                    resolution=0.1))]
#[allow(clippy::too_many_arguments)]
pub fn localize(
    py: Python<'_>,
    scan: &Bound<'_, PyAny>,
    map: &Bound<'_, PyAny>,
    dof: &str,
    max_tilt: f64,
    guess: Option<&Bound<'_, PyAny>>,
    window: Option<Vec<f64>>,
    search: &str,
    refine: bool,
    max_range: f64,
    threads: i64,
    levels: usize,
    resolution: f64,
) -> PyResult<PyAlignment> {
    let params = register_params(
        resolution, levels, dof, max_tilt, guess, window, search, refine, max_range,
    )?;
    let s = cloud_arg(scan, "scan")?;
    let (r, name) = match map_arg(map)? {
        MapArg::Occupancy(m) => {
            let m = m.get();
            let r = detached(py, threads, || {
                library::localize(s.get(), &m.read(), &params)
            })?;
            (r, m.source_name())
        }
        MapArg::FreeSpace(m) => {
            let m = m.get();
            let r = detached(py, threads, || {
                let (occupied, free) = m.read().occupancy_and_free()?;
                library::localize_in(s.get(), &occupied, Some(&free), &params)
            })?;
            (r, "FreeSpaceMap".to_owned())
        }
    };
    Ok(PyAlignment::new(&r.py_err()?, &s.name(), &name))
}

/// A map argument of ``localize`` and ``Localizer``.
enum MapArg<'a, 'py> {
    Occupancy(&'a Bound<'py, PyOccupancyMap>),
    FreeSpace(&'a Bound<'py, PyFreeSpaceMap>),
}

fn map_arg<'a, 'py>(map: &'a Bound<'py, PyAny>) -> PyResult<MapArg<'a, 'py>> {
    if let Ok(m) = map.cast::<PyOccupancyMap>() {
        Ok(MapArg::Occupancy(m))
    } else if let Ok(m) = map.cast::<PyFreeSpaceMap>() {
        Ok(MapArg::FreeSpace(m))
    } else {
        Err(pyo3::exceptions::PyTypeError::new_err(format!(
            "map must be an OccupancyMap or a FreeSpaceMap, not {}",
            map.get_type().name()?
        )))
    }
}

/// A map prepared once for localising many scans in it (a localisation service): its
/// search pyramid, its voxel centres indexed for ICP, and its surface for the agreement
/// checks are made here, so that each ``localize`` pays only for its own search,
/// refinement and checks. A snapshot: later changes to the OccupancyMap are not seen.
///
/// Args:
///     map: an OccupancyMap, or a FreeSpaceMap (its free space checked too: see
///         ``olmap.localize``).
///     dof, max_tilt, search, refine, max_range, levels, resolution: as for
///         ``olmap.localize``, kept for every query (a map finer than ``resolution`` is
///         prepared at its pyramid level within it).
///     threads: threads for the preparation (0: one per core).
///
/// Each result is the one ``olmap.localize`` gives for that scan.
#[pyclass(frozen, module = "olmap", name = "Localizer")]
pub struct PyLocalizer {
    inner: library::Localizer,
    settings: QuerySettings,
    map_name: String,
}

/// The parameters a [`PyLocalizer`] keeps for its queries.
struct QuerySettings {
    resolution: f64,
    levels: usize,
    dof: String,
    max_tilt: f64,
    search: String,
    refine: bool,
    max_range: f64,
}

impl QuerySettings {
    fn params(
        &self,
        guess: Option<&Bound<'_, PyAny>>,
        window: Option<Vec<f64>>,
    ) -> PyResult<RegisterParams> {
        register_params(
            self.resolution,
            self.levels,
            &self.dof,
            self.max_tilt,
            guess,
            window,
            &self.search,
            self.refine,
            self.max_range,
        )
    }
}

#[pymethods]
impl PyLocalizer {
    #[new]
    #[pyo3(signature = (map, dof="xyz-yaw", max_tilt=15.0, search="multires", refine=true,
                        max_range=30.0, threads=0, levels=0, resolution=0.1))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        map: &Bound<'_, PyAny>,
        dof: &str,
        max_tilt: f64,
        search: &str,
        refine: bool,
        max_range: f64,
        threads: i64,
        levels: usize,
        resolution: f64,
    ) -> PyResult<Self> {
        let settings = QuerySettings {
            resolution,
            levels,
            dof: dof.to_owned(),
            max_tilt,
            search: search.to_owned(),
            refine,
            max_range,
        };
        let params = settings.params(None, None)?;
        let (inner, map_name) = match map_arg(map)? {
            MapArg::Occupancy(m) => {
                let m = m.get();
                let inner = detached(py, threads, || {
                    library::Localizer::new(m.read().clone(), &params)
                })?;
                (inner, m.source_name())
            }
            MapArg::FreeSpace(m) => {
                let m = m.get();
                let inner = detached(py, threads, || {
                    let (occupied, free) = m.read().occupancy_and_free()?;
                    library::Localizer::with_free_space(occupied, free, &params)
                })?;
                (inner, "FreeSpaceMap".to_owned())
            }
        };
        Ok(PyLocalizer {
            inner: inner.py_err()?,
            settings,
            map_name,
        })
    }

    /// Localises a scan in the prepared map, as ``olmap.localize`` does.
    ///
    /// Args:
    ///     scan: a PointCloud or an (N, 3) array-like of metres, in its sensor frame.
    ///     guess, window: as for ``olmap.localize`` (a window around the guess instead of
    ///         the whole map and every heading).
    ///     threads: threads for this query (0: one per core).
    ///
    /// Returns:
    ///     Alignment: ``T_target_source`` is ``T_map_scan``; ``seconds`` counts this query
    ///     alone.
    #[pyo3(signature = (scan, guess=None, window=None, threads=0))]
    fn localize(
        &self,
        py: Python<'_>,
        scan: &Bound<'_, PyAny>,
        guess: Option<&Bound<'_, PyAny>>,
        window: Option<Vec<f64>>,
        threads: i64,
    ) -> PyResult<PyAlignment> {
        let params = self.settings.params(guess, window)?;
        let s = cloud_arg(scan, "scan")?;
        let r = detached(py, threads, || self.inner.localize(s.get(), &params))?.py_err()?;
        Ok(PyAlignment::new(&r, &s.name(), &self.map_name))
    }

    /// Voxels in the map as given (at ``map_resolution``).
    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// The voxel edge scans are placed at, metres: the map's own, or its pyramid level
    /// within the search's resolution for a finer map.
    #[getter]
    fn resolution(&self) -> f64 {
        self.inner.resolution()
    }

    /// The map's own voxel edge, metres.
    #[getter]
    fn map_resolution(&self) -> f64 {
        self.inner.map_resolution()
    }

    /// Whether the map's free space is known (prepared from a FreeSpaceMap).
    #[getter]
    fn free_space(&self) -> bool {
        self.inner.has_free_space()
    }

    fn __repr__(&self) -> String {
        format!(
            "Localizer({} voxels at {} m, read at {} m, {})",
            self.inner.len(),
            self.inner.map_resolution(),
            self.inner.resolution(),
            self.map_name
        )
    }
}
