// PyO3 signatures return tuples of arrays; naming each tuple type adds nothing.
#![allow(clippy::type_complexity)]

//! `socialcam._core`: the thin PyO3 layer over `socialcore`. Each module converts NumPy
//! inputs (checking shapes and naming arguments), calls the core once with the GIL
//! released, and converts the result. No algorithm lives here.

use pyo3::prelude::*;

mod bqp;
mod convert;
mod errors;
// issue 11: 3D faces
mod faces;
// issue 10: ego-motion gaze calibration
mod gaze;
mod geometry;
mod saliency;
mod trajectory;
// issue 6: gaze field
mod gazefield;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    geometry::register(m)?;
    trajectory::register(m)?;
    saliency::register(m)?;
    gazefield::register(m)?;
    bqp::register(m)?;
    gaze::register(m)?;
    faces::register(m)?;
    Ok(())
}
