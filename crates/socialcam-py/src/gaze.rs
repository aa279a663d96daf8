//! Ego-motion gaze calibration (thesis Sec 3.2.1, Eq 3.1). NumPy formats: a wearer's
//! segment as `R (F,3,3)` world→camera rotations and `C (F,3)` camera centres.

use nalgebra::{Matrix3, Vector3};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use socialcore::gaze::{self as gz, CalibrationOptions};

use crate::convert::{blocks, mat3, rows, vec1, vec3};
use crate::errors::detach;

fn poses(
    r: &PyReadonlyArray3<'_, f64>,
    c: &PyReadonlyArray2<'_, f64>,
) -> PyResult<(Vec<Matrix3<f64>>, Vec<Vector3<f64>>)> {
    let (rf, nr) = blocks(r, "R", 3, 3)?;
    let (cf, nc) = rows(c, "C", 3)?;
    if nr != nc {
        return Err(PyValueError::new_err(format!(
            "C: {nc} centres for {nr} rotations"
        )));
    }
    Ok((
        rf.chunks_exact(9).map(mat3).collect(),
        cf.chunks_exact(3).map(vec3).collect(),
    ))
}

fn vec3_arg(a: &PyReadonlyArray1<'_, f64>, name: &str) -> PyResult<Vector3<f64>> {
    let v = vec1(a);
    if v.len() != 3 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected a (3,) float64 array, got length {}",
            v.len()
        )));
    }
    Ok(vec3(&v))
}

/// Eq 3.1 on one fixation segment → dict of `p, v, y (3,)`, `h`, `p_std, y_std (3,)`,
/// `v_std`, `h_rel_std`, `residuals (F,)`, `iterations`, `converged`.
#[pyfunction]
#[pyo3(signature = (r, c, lambda_c, lambda_axis, max_iter, tol))]
fn calibrate_gaze<'py>(
    py: Python<'py>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    lambda_c: f64,
    lambda_axis: f64,
    max_iter: usize,
    tol: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let (rs, cs) = poses(&r, &c)?;
    let opts = CalibrationOptions {
        lambda_c,
        lambda_axis,
        max_iter,
        tol,
    };
    let cal = detach(py, || gz::calibrate_gaze(&rs, &cs, &opts))?;
    let d = PyDict::new(py);
    let v3 = |x: &Vector3<f64>| x.iter().copied().collect::<Vec<f64>>().into_pyarray(py);
    d.set_item("p", v3(&cal.p))?;
    d.set_item("v", v3(&cal.v))?;
    d.set_item("y", v3(&cal.y))?;
    d.set_item("h", cal.h)?;
    d.set_item("p_std", v3(&cal.p_std))?;
    d.set_item("y_std", v3(&cal.y_std))?;
    d.set_item("v_std", cal.v_std)?;
    d.set_item("h_rel_std", cal.h_rel_std)?;
    d.set_item("residuals", cal.residuals.into_pyarray(py))?;
    d.set_item("iterations", cal.iterations)?;
    d.set_item("converged", cal.converged)?;
    Ok(d)
}

/// World gaze rays `p_i = R_iᵀ p + C_i`, `v_i = R_iᵀ v` → `(p (F,3), v (F,3))`.
#[pyfunction]
#[pyo3(signature = (r, c, p, v))]
fn gaze_rays<'py>(
    py: Python<'py>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    p: PyReadonlyArray1<'py, f64>,
    v: PyReadonlyArray1<'py, f64>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>)> {
    let (rs, cs) = poses(&r, &c)?;
    let (p, v) = (vec3_arg(&p, "p")?, vec3_arg(&v, "v")?);
    let (pw, vw) = gz::gaze_rays(&rs, &cs, &p, &v);
    let to2 = |xs: Vec<Vector3<f64>>| -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = xs.len();
        let flat: Vec<f64> = xs.iter().flat_map(|x| x.iter().copied()).collect();
        Array2::from_shape_vec((n, 3), flat)
            .map(|a| a.into_pyarray(py))
            .map_err(|e| PyValueError::new_err(format!("internal shape error: {e}")))
    };
    Ok((to2(pw)?, to2(vw)?))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(calibrate_gaze, m)?)?;
    m.add_function(wrap_pyfunction!(gaze_rays, m)?)?;
    Ok(())
}
