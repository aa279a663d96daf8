//! Mapping of core errors to Python exceptions, and the one place where the GIL is
//! released around core calls.
//!
//! `socialcore::Error::InvalidInput` → `ValueError` naming the argument;
//! `Degenerate` → `socialcam.DegenerateError` (a `ValueError`);
//! `NotConverged` → `socialcam.ConvergenceError` (a `RuntimeError`).

use pyo3::create_exception;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

create_exception!(
    socialcam,
    DegenerateError,
    PyValueError,
    "The input is well formed but geometrically degenerate (rank deficiency, parallel rays, too few observations)."
);
create_exception!(
    socialcam,
    ConvergenceError,
    PyRuntimeError,
    "An iterative solver reached its cap without converging."
);

/// Newtype so that `?` turns a core error into the right Python exception (orphan rule).
pub struct PyCoreError(pub socialcore::Error);

impl From<socialcore::Error> for PyCoreError {
    fn from(e: socialcore::Error) -> Self {
        PyCoreError(e)
    }
}

impl From<PyCoreError> for PyErr {
    fn from(e: PyCoreError) -> PyErr {
        let msg = e.0.to_string();
        match e.0 {
            socialcore::Error::InvalidInput { .. } => PyValueError::new_err(msg),
            socialcore::Error::Degenerate(_) => DegenerateError::new_err(msg),
            socialcore::Error::NotConverged { .. } => ConvergenceError::new_err(msg),
        }
    }
}

/// Runs `f` with the GIL released and maps its error. Rayon runs only inside here.
pub fn detach<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> socialcore::Result<T> + Send,
{
    py.detach(f).map_err(|e| PyErr::from(PyCoreError(e)))
}

/// Maps a core result without releasing the GIL (for cheap calls).
pub fn map<T>(r: socialcore::Result<T>) -> PyResult<T> {
    r.map_err(|e| PyErr::from(PyCoreError(e)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("DegenerateError", py.get_type::<DegenerateError>())?;
    m.add("ConvergenceError", py.get_type::<ConvergenceError>())?;
    Ok(())
}
