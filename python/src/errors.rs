//! Library errors as Python exceptions: which exception each [`Error`] raises, and
//! `meniscus.FormatError` for malformed or unsupported files.

use meniscus::Error;
use pyo3::create_exception;
use pyo3::exceptions::{
    PyFileExistsError, PyKeyboardInterrupt, PyOSError, PyRuntimeError, PyValueError,
};
use pyo3::prelude::*;

create_exception!(
    meniscus,
    FormatError,
    PyValueError,
    "A particle, mesh or archive file whose content is malformed or whose format is not supported."
);

/// The Python exception for a library error.
pub(crate) fn to_py(e: Error) -> PyErr {
    let message = e.to_string();
    match e {
        Error::InvalidOption { .. }
        | Error::ImplausibleRadius { .. }
        | Error::ParticleOutOfRange { .. }
        | Error::MemoryBudget { .. } => PyValueError::new_err(message),
        Error::Io { path, source } | Error::Spill { path, source } => match source.raw_os_error() {
            // OSError(errno, strerror, filename) becomes FileNotFoundError, PermissionError, ...
            Some(errno) => PyOSError::new_err((errno, source.to_string(), path)),
            None => PyOSError::new_err(message),
        },
        Error::NoSpace { .. } => PyOSError::new_err(message),
        Error::Parse { .. }
        | Error::UnsupportedFormat { .. }
        | Error::Attribute { .. }
        | Error::InvalidRadius { .. }
        | Error::EmptyInput { .. } => FormatError::new_err(message),
        Error::FramesExist { .. } => PyFileExistsError::new_err(message),
        Error::Interrupted => PyKeyboardInterrupt::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}
