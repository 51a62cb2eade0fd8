//! Running library work with the GIL released, on a bounded number of threads.

use pyo3::exceptions::PyRuntimeWarning;
use pyo3::prelude::*;

/// Runs `work` with the GIL released (other Python threads run meanwhile), on the global
/// rayon pool (`threads == 0`: one worker per core) or on a pool of `threads` workers,
/// capped at the machine's cores like the command line's `--threads` (a warning says so).
/// Everything `work` uses must be owned by Rust: it runs while Python may change or free
/// its own objects.
pub fn detached<T, F>(py: Python<'_>, threads: i64, work: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> T + Send,
{
    let threads = usize::try_from(threads).map_err(|_| {
        crate::errors::value_error(format!(
            "threads: expected 0 (one per core) or a positive count, got {threads}"
        ))
    })?;
    let count = olmap::limits::thread_count(threads);
    if let Some(note) = count.note() {
        let message = std::ffi::CString::new(format!("threads: {note}"))
            .unwrap_or_else(|_| c"threads: capped at the machine's cores".to_owned());
        PyErr::warn(py, &py.get_type::<PyRuntimeWarning>(), &message, 1)?;
    }
    if count.threads == 0 {
        return Ok(py.detach(work));
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(count.threads)
        .build()
        .map_err(|e| {
            pyo3::exceptions::PyRuntimeError::new_err(format!("cannot start worker threads: {e}"))
        })?;
    Ok(py.detach(|| pool.install(work)))
}

/// A Python progress callback for the library's long pipelines: `progress(stage, done,
/// total)` (stage a label such as `"map"`), called from the worker with the GIL taken back
/// for the call. An exception it raises is kept and raised once the work ends; the work
/// itself runs to its end (the library's pipelines cannot be cancelled midway).
pub struct PyProgress {
    callback: Option<Py<PyAny>>,
    error: Option<PyErr>,
}

impl PyProgress {
    /// The callback `progress` (None: no reports); a value that is not callable is a
    /// `TypeError`.
    pub fn new(progress: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let callback = match progress {
            Some(p) if !p.is_none() => {
                if !p.is_callable() {
                    return Err(pyo3::exceptions::PyTypeError::new_err(
                        "progress: expected a callable progress(stage, done, total) or None",
                    ));
                }
                Some(p.clone().unbind())
            }
            _ => None,
        };
        Ok(PyProgress {
            callback,
            error: None,
        })
    }

    /// Reports `done` of `total` in `stage`.
    pub fn report(&mut self, stage: olmap::progress::Stage, done: usize, total: usize) {
        let (Some(cb), None) = (&self.callback, &self.error) else {
            return;
        };
        if let Err(e) = Python::attach(|py| cb.call1(py, (stage.label(), done, total)).map(drop)) {
            self.error = Some(e);
        }
    }

    /// The callback's exception, if it raised one.
    pub fn finish(self) -> PyResult<()> {
        self.error.map_or(Ok(()), Err)
    }
}
