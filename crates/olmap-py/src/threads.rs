//! Running library work with the GIL released, on a bounded number of threads.

use pyo3::exceptions::PyRuntimeWarning;
use pyo3::prelude::*;

/// Runs `work` with the GIL released (other Python threads run meanwhile), on the global
/// rayon pool (`threads == 0`: one worker per core) or on a pool of `threads` workers,
/// capped at the machine's cores like the command line's `--threads` (a warning says so).
/// Everything `work` uses must be owned by Rust: it runs while Python may change or free
/// its own objects.
pub fn detached<T, F>(py: Python<'_>, threads: usize, work: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> T + Send,
{
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
