//! Trajectory-reconstruction bindings (thesis Chapter 5). NumPy formats: cameras as
//! `K (F,3,3)`, `R (F,3,3)` world→camera, `C (F,3)` centres, `times (F,)` seconds; pixels
//! `x (N,F,2)` with NaN rows where a point was not seen. Results come back as a dict of
//! arrays (wrapped into dataclasses by `socialcam.trajectory`): `points (N,F,3)`,
//! `std (N,F,3)`, `coeffs (N,Kmax,3)` (zero beyond each point's `k`), `k`, `rms`,
//! `rms_linear`, `converged`, `iterations`, `rank`, `cond`, `sigma`, `n_observed` (all `(N,)`),
//! `cv_error (N,Kcv)` (NaN padded), `covariance` (list of `(3k,3k)` arrays or `None`),
//! `failures` (per point `None` or the reason), `span (t0, t1, n_norm)`.

use nalgebra::Vector3;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use socialcore::geometry::LmOptions;
use socialcore::trajectory::{
    self as tr, CvRule, Frames, KSelection, TrajectoryFit, TrajectoryOptions,
};

use crate::convert::{cameras, rows, vec1, vec3};
use crate::errors::{detach, map};

/// `K` as the options hold it: a positive integer or `"auto"`.
#[derive(FromPyObject)]
enum KArg {
    Fixed(usize),
    Auto(String),
}

/// The fields of `socialcam.TrajectoryOptions` (the frozen dataclass validated in Python),
/// read by attribute so the option list is written once.
#[derive(FromPyObject)]
pub struct PyTrajectoryOptions {
    #[pyo3(attribute)]
    k: KArg,
    #[pyo3(attribute)]
    folds: usize,
    #[pyo3(attribute)]
    k_min: usize,
    #[pyo3(attribute)]
    k_max: Option<usize>,
    #[pyo3(attribute)]
    cv_rule: String,
    #[pyo3(attribute)]
    refine: bool,
    #[pyo3(attribute)]
    max_iter: usize,
}

fn options(o: &PyTrajectoryOptions, keep_covariance: bool) -> PyResult<TrajectoryOptions> {
    let rule = match o.cv_rule.as_str() {
        "min" => CvRule::Min,
        "1se" => CvRule::OneStandardError,
        other => {
            return Err(PyValueError::new_err(format!(
                "cv_rule: expected 'min' or '1se', got {other:?}"
            )))
        }
    };
    let sel = match &o.k {
        KArg::Fixed(k) => KSelection::Fixed(*k),
        KArg::Auto(s) if s == "auto" => KSelection::CrossValidation {
            folds: o.folds,
            k_min: o.k_min,
            k_max: o.k_max,
            rule,
        },
        KArg::Auto(s) => {
            return Err(PyValueError::new_err(format!(
                "k: expected a positive integer or 'auto', got {s:?}"
            )))
        }
    };
    let opts = TrajectoryOptions {
        k: sel,
        refine: o.refine,
        lm: LmOptions {
            max_iterations: o.max_iter,
            rel_tol: 1e-10,
        },
        keep_covariance,
    };
    map(opts.validate())?;
    Ok(opts)
}

fn frames(
    k: &PyReadonlyArray3<'_, f64>,
    r: &PyReadonlyArray3<'_, f64>,
    c: &PyReadonlyArray2<'_, f64>,
    times: &PyReadonlyArray1<'_, f64>,
) -> PyResult<Frames> {
    let cams = cameras(k, r, c)?;
    let t = vec1(times);
    map(Frames::new(cams, t))
}

fn pixels(x: &PyReadonlyArray3<'_, f64>, f: usize) -> PyResult<(Vec<f64>, usize)> {
    let v = x.as_array();
    let s = v.shape();
    if s[1] != f || s[2] != 2 {
        return Err(PyValueError::new_err(format!(
            "x: expected an (N, F, 2) float64 array with F = {f} frames, got shape ({}, {}, {})",
            s[0], s[1], s[2]
        )));
    }
    Ok((v.iter().copied().collect(), s[0]))
}

/// Packs per-point results into the dict described in the module header.
fn pack<'py>(
    py: Python<'py>,
    frames: &Frames,
    results: Vec<socialcore::Result<TrajectoryFit>>,
) -> PyResult<Bound<'py, PyDict>> {
    let n = results.len();
    let f = frames.len();
    let k_max = results
        .iter()
        .filter_map(|r| r.as_ref().ok().map(|t| t.k))
        .max()
        .unwrap_or(0);
    let cv_len = results
        .iter()
        .filter_map(|r| r.as_ref().ok().map(|t| t.cv_error.len()))
        .max()
        .unwrap_or(0);
    let mut points = Array3::<f64>::from_elem((n, f, 3), f64::NAN);
    let mut std = Array3::<f64>::from_elem((n, f, 3), f64::NAN);
    let mut coeffs = Array3::<f64>::zeros((n, k_max, 3));
    let mut cv = Array2::<f64>::from_elem((n, cv_len), f64::NAN);
    let mut kk = Array1::<i64>::zeros(n);
    let mut rms = Array1::<f64>::from_elem(n, f64::NAN);
    let mut rms0 = Array1::<f64>::from_elem(n, f64::NAN);
    let mut conv = Array1::<bool>::from_elem(n, false);
    let mut iters = Array1::<i64>::zeros(n);
    let mut rank = Array1::<i64>::zeros(n);
    let mut cond = Array1::<f64>::from_elem(n, f64::NAN);
    let mut sigma = Array1::<f64>::from_elem(n, f64::NAN);
    let mut observed = Array1::<i64>::zeros(n);
    let mut covs: Vec<Option<Bound<'py, numpy::PyArray2<f64>>>> = Vec::with_capacity(n);
    let mut failures: Vec<Option<String>> = Vec::with_capacity(n);
    for (i, res) in results.into_iter().enumerate() {
        match res {
            Ok(t) => {
                for (j, (p, s)) in t.points.iter().zip(&t.std).enumerate() {
                    for c in 0..3 {
                        points[[i, j, c]] = p[c];
                        std[[i, j, c]] = s[c];
                    }
                }
                for (j, b) in t.coeffs.iter().enumerate() {
                    for c in 0..3 {
                        coeffs[[i, j, c]] = b[c];
                    }
                }
                for (j, e) in t.cv_error.iter().enumerate() {
                    cv[[i, j]] = *e;
                }
                kk[i] = t.k as i64;
                rms[i] = t.rms;
                rms0[i] = t.rms_linear;
                conv[i] = t.converged;
                iters[i] = t.iterations as i64;
                rank[i] = t.rank as i64;
                cond[i] = t.cond;
                sigma[i] = t.sigma;
                observed[i] = t.observed as i64;
                let nu = 3 * t.k;
                covs.push(match t.covariance {
                    Some(c) => Some(
                        Array2::from_shape_vec((nu, nu), c)
                            .map_err(|e| PyValueError::new_err(e.to_string()))?
                            .into_pyarray(py),
                    ),
                    None => None,
                });
                failures.push(None);
            }
            Err(e) => {
                covs.push(None);
                failures.push(Some(e.to_string()));
            }
        }
    }
    let span = frames.span();
    let d = PyDict::new(py);
    d.set_item("points", points.into_pyarray(py))?;
    d.set_item("std", std.into_pyarray(py))?;
    d.set_item("coeffs", coeffs.into_pyarray(py))?;
    d.set_item("cv_error", cv.into_pyarray(py))?;
    d.set_item("k", kk.into_pyarray(py))?;
    d.set_item("rms", rms.into_pyarray(py))?;
    d.set_item("rms_linear", rms0.into_pyarray(py))?;
    d.set_item("converged", conv.into_pyarray(py))?;
    d.set_item("iterations", iters.into_pyarray(py))?;
    d.set_item("rank", rank.into_pyarray(py))?;
    d.set_item("cond", cond.into_pyarray(py))?;
    d.set_item("sigma", sigma.into_pyarray(py))?;
    d.set_item("n_observed", observed.into_pyarray(py))?;
    d.set_item("covariance", covs)?;
    d.set_item("failures", failures)?;
    d.set_item("span", (span.t0, span.t1, span.n_norm))?;
    Ok(d)
}

/// Reconstructs `N` point trajectories `x (N,F,2)` from cameras with capture times, with
/// the options of a `socialcam.TrajectoryOptions`. A point that cannot be reconstructed
/// gets NaN rows and its reason in `failures`; with `strict=True` the first failure is
/// raised instead (`DegenerateError` or `ValueError`).
#[pyfunction]
#[pyo3(signature = (k_intr, r, c, times, x, options, keep_covariance=false, strict=false))]
#[allow(clippy::too_many_arguments)]
fn reconstruct_trajectories<'py>(
    py: Python<'py>,
    k_intr: PyReadonlyArray3<'py, f64>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    times: PyReadonlyArray1<'py, f64>,
    x: PyReadonlyArray3<'py, f64>,
    options: Bound<'py, PyAny>,
    keep_covariance: bool,
    strict: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let o: PyTrajectoryOptions = crate::convert::options(&options, "TrajectoryOptions")?;
    let opts = self::options(&o, keep_covariance)?;
    let fr = frames(&k_intr, &r, &c, &times)?;
    let (flat, n) = pixels(&x, fr.len())?;
    let results = detach(py, || {
        let res = tr::reconstruct_trajectories(&fr, &flat, n, &opts)?;
        if strict {
            if let Some(Err(e)) = res.iter().find(|r| r.is_err()) {
                return Err(e.clone());
            }
        }
        Ok(res)
    })?;
    pack(py, &fr, results)
}

fn points3(a: &PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<Vec<Vector3<f64>>> {
    let (flat, n) = rows(a, name, 3)?;
    Ok((0..n).map(|i| vec3(&flat[3 * i..])).collect())
}

/// Reconstructability η (Eq 5.16) of `points (F,3)` seen from `centres (F,3)` with `k`
/// basis functions; `times (F,)` or uniform.
#[pyfunction]
#[pyo3(signature = (points, centres, k, times=None))]
fn reconstructability(
    points: PyReadonlyArray2<'_, f64>,
    centres: PyReadonlyArray2<'_, f64>,
    k: usize,
    times: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<f64> {
    let p = points3(&points, "points_true")?;
    let c = points3(&centres, "camera_centres")?;
    let t = times.as_ref().map(vec1);
    map(tr::reconstructability(&p, &c, t.as_deref(), k))
}

/// `‖Θ^⊥ β^⊥‖` of a trajectory `(F,3)`: what `k` DCT functions cannot describe.
#[pyfunction]
#[pyo3(signature = (trajectory, k, times=None))]
fn null_residual(
    trajectory: PyReadonlyArray2<'_, f64>,
    k: usize,
    times: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<f64> {
    let p = points3(&trajectory, "trajectory")?;
    let t = times.as_ref().map(vec1);
    map(tr::null_residual(&p, t.as_deref(), k))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(reconstruct_trajectories, m)?)?;
    m.add_function(wrap_pyfunction!(reconstructability, m)?)?;
    m.add_function(wrap_pyfunction!(null_residual, m)?)?;
    Ok(())
}
