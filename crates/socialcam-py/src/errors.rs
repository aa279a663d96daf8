//! Mapping of core errors to Python exceptions, and the one place where the GIL is
//! released around core calls.
//!
//! `socialcore::Error::InvalidInput` → `ValueError` naming the argument;
//! `Degenerate` → `socialcam.DegenerateError` (a `ValueError`);
//! `NotConverged` → `socialcam.ConvergenceError` (a `RuntimeError`);
//! `Interrupted` → `KeyboardInterrupt` (the user pressed Ctrl-C).
//!
//! Every heavy call goes through [`detach`], which runs the core on a worker thread with
//! the GIL released while the calling thread polls for signals every 20 ms: Ctrl-C asks
//! the core to stop ([`socialcore::interrupt`]) and raises `KeyboardInterrupt` as soon as
//! the core has returned. A panic in the core (a bug) becomes a `RuntimeError`, never an
//! abort or a `PanicException`.

use pyo3::create_exception;
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::sync::{Condvar, Mutex};
use std::time::Duration;

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
            socialcore::Error::Interrupted => PyKeyboardInterrupt::new_err(msg),
        }
    }
}

/// How often the calling thread looks for Ctrl-C while the core runs.
const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// Runs `f` with the GIL released and maps its error. Rayon runs only inside here.
///
/// `f` runs on a scoped worker thread; this thread waits for it with the GIL released
/// and every [`SIGNAL_POLL`] re-attaches to run Python's signal handlers. On Ctrl-C it
/// raises the core's interrupt flag, waits for `f` to return (every long core loop checks
/// the flag), clears the flag and raises `KeyboardInterrupt`. A panic inside `f` is caught
/// at the join and raised as `RuntimeError` naming it an internal error.
pub fn detach<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> socialcore::Result<T> + Send,
{
    // `done` is set by the worker when `f` returns (or unwinds: see `Done`).
    let done = (Mutex::new(false), Condvar::new());
    let done = &done;
    std::thread::scope(|scope| {
        let worker = scope.spawn(move || {
            let _signal = Done(done);
            f()
        });
        let mut interrupt: Option<PyErr> = None;
        loop {
            let finished = py.detach(|| {
                let (lock, cvar) = done;
                let Ok(guard) = lock.lock() else {
                    return true; // poisoned: the worker is gone
                };
                if *guard {
                    return true;
                }
                match cvar.wait_timeout(guard, SIGNAL_POLL) {
                    Ok((g, _)) => *g,
                    Err(_) => true,
                }
            });
            if finished {
                break;
            }
            if interrupt.is_none() {
                if let Err(e) = py.check_signals() {
                    socialcore::interrupt::request();
                    interrupt = Some(e);
                }
            }
        }
        let joined = py.detach(|| worker.join());
        if interrupt.is_some() {
            socialcore::interrupt::clear();
        }
        match joined {
            Err(payload) => {
                let what = payload
                    .downcast_ref::<&str>()
                    .map(|s| (*s).to_string())
                    .or_else(|| payload.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".to_string());
                Err(PyRuntimeError::new_err(format!(
                    "internal error in socialcam's core (please report it): {what}"
                )))
            }
            Ok(Ok(v)) => match interrupt {
                // Interrupted after the work was done: still honour Ctrl-C.
                Some(e) => Err(e),
                None => Ok(v),
            },
            Ok(Err(e)) => match interrupt {
                Some(k) => Err(k),
                None => Err(PyErr::from(PyCoreError(e))),
            },
        }
    })
}

/// Marks the worker finished when dropped, so a panic also wakes the waiting thread.
struct Done<'a>(&'a (Mutex<bool>, Condvar));

impl Drop for Done<'_> {
    fn drop(&mut self) {
        let (lock, cvar) = self.0;
        if let Ok(mut g) = lock.lock() {
            *g = true;
        }
        cvar.notify_all();
    }
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
