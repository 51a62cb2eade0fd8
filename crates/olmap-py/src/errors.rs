//! The library's typed errors as Python exceptions.
//!
//! | olmap error | Python exception |
//! |---|---|
//! | `Io` | `OSError` subclass by cause (`FileNotFoundError`, `PermissionError`, ...) |
//! | `IsDirectory` | `IsADirectoryError` |
//! | `UnknownFormat`, `Read` | [`FormatError`] (an `OSError`): the file is not what it claims |
//! | `Write` | `OSError` |
//! | `InvalidArgument`, `EmptyInput`, `Unsupported` | `ValueError` |
//! | `TooLarge` | [`TooLargeError`] (a `ValueError`): ask for less |
//! | `NotFound` | `LookupError` |
//!
//! Every message is the library's own, which names the file (and line or byte) at fault.

use pyo3::exceptions::{
    PyFileExistsError, PyFileNotFoundError, PyIsADirectoryError, PyLookupError, PyOSError,
    PyPermissionError, PyValueError,
};
use pyo3::PyErr;

pyo3::create_exception!(
    olmap,
    FormatError,
    PyOSError,
    "A file is not what its name or content claims: an unknown format, or a parse error \
     (the message names the file and the line or byte)."
);

pyo3::create_exception!(
    olmap,
    TooLargeError,
    PyValueError,
    "A request beyond a limit olmap enforces (memory estimate, voxel key range, a file that \
     claims or decompresses to too much): retry with less."
);

/// The Python exception for a library error.
pub fn to_py(e: olmap::Error) -> PyErr {
    use olmap::Error as E;
    let message = e.to_string();
    match e {
        E::Io { source, .. } => match source.kind() {
            std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
            std::io::ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
            std::io::ErrorKind::AlreadyExists => PyFileExistsError::new_err(message),
            std::io::ErrorKind::IsADirectory => PyIsADirectoryError::new_err(message),
            _ => PyOSError::new_err(message),
        },
        E::IsDirectory { .. } => PyIsADirectoryError::new_err(message),
        E::UnknownFormat { .. } | E::Read { .. } => FormatError::new_err(message),
        E::Write { .. } => PyOSError::new_err(message),
        E::TooLarge { .. } => TooLargeError::new_err(message),
        E::NotFound { .. } => PyLookupError::new_err(message),
        E::InvalidArgument(_) | E::EmptyInput { .. } | E::Unsupported { .. } => {
            PyValueError::new_err(message)
        }
    }
}

/// `Result<T, olmap::Error>` to `PyResult<T>`.
pub trait IntoPy<T> {
    /// The value, or the error as a Python exception.
    fn py_err(self) -> pyo3::PyResult<T>;
}

impl<T> IntoPy<T> for olmap::Result<T> {
    fn py_err(self) -> pyo3::PyResult<T> {
        self.map_err(to_py)
    }
}

/// A `ValueError` with `message`.
pub fn value_error(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}
