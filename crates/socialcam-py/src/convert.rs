//! NumPy ⇄ core conversions with shape checks that name the argument.
//! NumPy arrays are row-major; nalgebra matrices are column-major, so 3×3 blocks are read
//! element by element, never reinterpreted.

use nalgebra::{Matrix3, Vector3};
use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use socialcore::geometry::Camera;

use crate::errors::map;

/// A contiguous row-major copy of a 1-D array.
pub fn vec1(a: &PyReadonlyArray1<'_, f64>) -> Vec<f64> {
    a.as_array().iter().copied().collect()
}

/// Checks `a` is `(N, cols)` and returns its rows flattened row-major with `N`.
pub fn rows(a: &PyReadonlyArray2<'_, f64>, name: &str, cols: usize) -> PyResult<(Vec<f64>, usize)> {
    let v = a.as_array();
    if v.ncols() != cols {
        return Err(PyValueError::new_err(format!(
            "{name}: expected an (N, {cols}) float64 array, got shape ({}, {})",
            v.nrows(),
            v.ncols()
        )));
    }
    Ok((v.iter().copied().collect(), v.nrows()))
}

/// Checks `a` is `(N, d1, d2)` and returns it flattened row-major with `N`.
pub fn blocks(
    a: &PyReadonlyArray3<'_, f64>,
    name: &str,
    d1: usize,
    d2: usize,
) -> PyResult<(Vec<f64>, usize)> {
    let v = a.as_array();
    let s = v.shape();
    if s[1] != d1 || s[2] != d2 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected an (N, {d1}, {d2}) float64 array, got shape ({}, {}, {})",
            s[0], s[1], s[2]
        )));
    }
    Ok((v.iter().copied().collect(), s[0]))
}

pub fn mat3(flat: &[f64]) -> Matrix3<f64> {
    Matrix3::from_row_slice(&flat[..9])
}

pub fn vec3(flat: &[f64]) -> Vector3<f64> {
    Vector3::new(flat[0], flat[1], flat[2])
}

/// Builds validated cameras from `K (F,3,3)`, `R (F,3,3)`, `C (F,3)`.
pub fn cameras(
    k: &PyReadonlyArray3<'_, f64>,
    r: &PyReadonlyArray3<'_, f64>,
    c: &PyReadonlyArray2<'_, f64>,
) -> PyResult<Vec<Camera>> {
    let (kf, nk) = blocks(k, "K", 3, 3)?;
    let (rf, nr) = blocks(r, "R", 3, 3)?;
    let (cf, nc) = rows(c, "C", 3)?;
    if nk != nr || nr != nc {
        return Err(PyValueError::new_err(format!(
            "K, R, C: need the same number of frames, got {nk}, {nr}, {nc}"
        )));
    }
    (0..nr)
        .map(|i| {
            map(Camera::new(
                mat3(&kf[9 * i..]),
                mat3(&rf[9 * i..]),
                vec3(&cf[3 * i..]),
                i,
            ))
        })
        .collect()
}

/// Reads an options dataclass (`socialcam.TrajectoryOptions`, `GazeFieldOptions`) by its
/// attributes; anything else (None, a missing field, a field of the wrong type) is a
/// `TypeError` naming `options` rather than a bare `AttributeError`.
pub fn options<'py, T: FromPyObject<'py>>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<T> {
    obj.extract::<T>()
        .map_err(|e| PyTypeError::new_err(format!("options: expected a {what}: {e}")))
}
