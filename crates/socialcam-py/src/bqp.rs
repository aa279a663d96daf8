//! Binary quadratic programming and articulated reconstruction (thesis Chapter 4).
//! NumPy formats: `Q (n,n)` symmetric, `c (n,)`; cameras `K (F,3,3)`, `R (F,3,3)`,
//! `C (F,3)`; child pixels `x (F,2)` or skeleton pixels `x (F,J,2)` with NaN rows = missing;
//! parent / root trajectories `(F,3)` metres; `times (F,)` seconds; skeleton `parents (J,)`
//! (−1 for the root) and `lengths (J,)` metres.

use nalgebra::{Vector2, Vector3};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use socialcore::articulated::{
    self as art, ArticulatedMethod, ArticulatedOptions, ArticulatedResult, Skeleton,
};
use socialcore::bqp::{solve_bqp as core_solve, BqpOptions, BqpProblem, BqpSolution};
use socialcore::geometry::Camera;
use std::time::Duration;

use crate::convert::{cameras, rows, vec1};
use crate::errors::{detach, map};

/// Longest accepted `time_limit`, seconds (about 31 years): beyond it `Duration` overflows.
const MAX_TIME_LIMIT: f64 = 1e9;

fn time_limit_of(time_limit: Option<f64>) -> PyResult<Option<Duration>> {
    match time_limit {
        Some(t) if !(t.is_finite() && t > 0.0 && t <= MAX_TIME_LIMIT) => {
            Err(PyValueError::new_err(format!(
                "time_limit: expected seconds in (0, {MAX_TIME_LIMIT:e}], got {t}"
            )))
        }
        Some(t) => Ok(Some(Duration::from_secs_f64(t))),
        None => Ok(None),
    }
}

fn bqp_options(time_limit: Option<f64>, node_limit: Option<u64>) -> PyResult<BqpOptions> {
    Ok(BqpOptions {
        time_limit: time_limit_of(time_limit)?,
        node_limit,
        ..BqpOptions::default()
    })
}

/// The fields of the Python `socialcam.BqpOptions` dataclass (validated there; checked
/// again here so that no input reaches the core unchecked).
#[derive(FromPyObject)]
struct PyBqpOptions {
    #[pyo3(attribute)]
    time_limit: Option<f64>,
    #[pyo3(attribute)]
    node_limit: Option<u64>,
    #[pyo3(attribute)]
    parallel: bool,
    #[pyo3(attribute)]
    batch: usize,
    #[pyo3(attribute)]
    dive_depth: usize,
}

impl PyBqpOptions {
    fn core(&self) -> PyResult<BqpOptions> {
        for (name, v) in [("batch", self.batch), ("dive_depth", self.dive_depth)] {
            if v == 0 || v > 1 << 20 {
                return Err(PyValueError::new_err(format!(
                    "{name}: expected an integer in [1, {}], got {v}",
                    1 << 20
                )));
            }
        }
        Ok(BqpOptions {
            time_limit: time_limit_of(self.time_limit)?,
            node_limit: self.node_limit,
            parallel: self.parallel,
            batch: self.batch,
            dive_depth: self.dive_depth,
            ..BqpOptions::default()
        })
    }
}

type SolutionTuple<'py> = (Bound<'py, PyArray1<bool>>, f64, f64, f64, u64, bool, f64);

fn solution<'py>(py: Python<'py>, s: BqpSolution) -> SolutionTuple<'py> {
    (
        Array1::from(s.x).into_pyarray(py),
        s.objective,
        s.bound,
        s.gap,
        s.nodes,
        s.optimal,
        s.root_bound,
    )
}

/// Exact `min bᵀQb + cᵀb` over `b ∈ {0,1}ⁿ`:
/// `(x, objective, bound, gap, nodes, optimal, root_bound)`.
#[pyfunction]
#[pyo3(signature = (q, c, options))]
fn solve_bqp<'py>(
    py: Python<'py>,
    q: PyReadonlyArray2<'py, f64>,
    c: Option<PyReadonlyArray1<'py, f64>>,
    options: Bound<'py, PyAny>,
) -> PyResult<SolutionTuple<'py>> {
    let options: PyBqpOptions = crate::convert::options(&options, "BqpOptions")?;
    let qv = q.as_array();
    let n = qv.nrows();
    if qv.ncols() != n {
        return Err(PyValueError::new_err(format!(
            "Q: expected a square (n, n) float64 array, got shape ({}, {})",
            n,
            qv.ncols()
        )));
    }
    let qf: Vec<f64> = qv.iter().copied().collect();
    let cf = match &c {
        Some(c) => vec1(c),
        None => vec![0.0; n],
    };
    let opts = options.core()?;
    let problem = map(BqpProblem::from_row_major(n, qf, cf))?;
    let s = detach(py, || core_solve(&problem, &opts))?;
    Ok(solution(py, s))
}

fn pixels_2d(x: &PyReadonlyArray2<'_, f64>, f: usize) -> PyResult<Vec<Option<Vector2<f64>>>> {
    let (xf, nx) = rows(x, "x", 2)?;
    if nx != f {
        return Err(PyValueError::new_err(format!(
            "x: expected ({f}, 2) pixels (one row per camera frame), got ({nx}, 2)"
        )));
    }
    (0..f)
        .map(|i| {
            let (u, v) = (xf[2 * i], xf[2 * i + 1]);
            match (u.is_nan(), v.is_nan()) {
                (true, true) => Ok(None),
                (false, false) if u.is_finite() && v.is_finite() => Ok(Some(Vector2::new(u, v))),
                _ => Err(PyValueError::new_err(format!(
                    "x: frame {i} must be finite or entirely NaN (missing)"
                ))),
            }
        })
        .collect()
}

fn points(a: &PyReadonlyArray2<'_, f64>, name: &str, f: usize) -> PyResult<Vec<Vector3<f64>>> {
    let (v, n) = rows(a, name, 3)?;
    if n != f {
        return Err(PyValueError::new_err(format!(
            "{name}: expected ({f}, 3), one row per camera frame, got ({n}, 3)"
        )));
    }
    map(socialcore::error::ensure_finite(name, &v))?;
    Ok((0..n)
        .map(|i| Vector3::new(v[3 * i], v[3 * i + 1], v[3 * i + 2]))
        .collect())
}

fn times_of(t: &PyReadonlyArray1<'_, f64>, f: usize) -> PyResult<Vec<f64>> {
    let v = vec1(t);
    if v.len() != f {
        return Err(PyValueError::new_err(format!(
            "times: expected ({f},), got ({},)",
            v.len()
        )));
    }
    Ok(v)
}

/// The fields of the Python `ArticulatedOptions` dataclass (validated there; the core
/// validates again and returns errors, never panics).
#[derive(FromPyObject)]
struct PyArticulatedOptions {
    #[pyo3(attribute)]
    k: usize,
    #[pyo3(attribute)]
    refine: bool,
    #[pyo3(attribute)]
    method: String,
    #[pyo3(attribute)]
    fit_radius: bool,
    #[pyo3(attribute)]
    tangent_quantile: f64,
    #[pyo3(attribute)]
    length_tol: f64,
    #[pyo3(attribute)]
    grazing_separation: f64,
    #[pyo3(attribute)]
    flip_rounds: usize,
    #[pyo3(attribute)]
    smooth_weight: f64,
    #[pyo3(attribute)]
    motion_weight: f64,
    #[pyo3(attribute)]
    refine_k_max: usize,
    #[pyo3(attribute)]
    child_slack: f64,
    #[pyo3(attribute)]
    length_weight: f64,
    #[pyo3(attribute)]
    average_starts: bool,
    #[pyo3(attribute)]
    angle_weight: f64,
    #[pyo3(attribute)]
    angle_tolerance: f64,
    #[pyo3(attribute)]
    prior_start: bool,
    #[pyo3(attribute)]
    angle_refine: f64,
    #[pyo3(attribute)]
    angle_cap: Option<f64>,
    #[pyo3(attribute)]
    max_iter: usize,
    #[pyo3(attribute)]
    time_limit: Option<f64>,
    #[pyo3(attribute)]
    node_limit: Option<u64>,
}

fn art_options(o: &PyArticulatedOptions) -> PyResult<ArticulatedOptions> {
    let method = match o.method.as_str() {
        "robust" => ArticulatedMethod::Robust,
        "thesis" => ArticulatedMethod::Thesis,
        other => {
            return Err(PyValueError::new_err(format!(
                "method: expected 'robust' or 'thesis', got {other:?}"
            )))
        }
    };
    let defaults = ArticulatedOptions::default();
    Ok(ArticulatedOptions {
        k: o.k,
        refine: o.refine,
        fit_radius: o.fit_radius,
        method,
        tangent_quantile: o.tangent_quantile,
        length_tol: o.length_tol,
        grazing_separation: o.grazing_separation,
        flip_rounds: o.flip_rounds,
        smooth_weight: o.smooth_weight,
        motion_weight: o.motion_weight,
        refine_k_max: o.refine_k_max,
        child_slack: o.child_slack,
        length_weight: o.length_weight,
        average_starts: o.average_starts,
        angle_weight: o.angle_weight,
        angle_tolerance: o.angle_tolerance,
        prior_start: o.prior_start,
        angle_refine: o.angle_refine,
        angle_cap: o.angle_cap.unwrap_or(f64::INFINITY),
        lm: socialcore::geometry::LmOptions {
            max_iterations: o.max_iter,
            ..defaults.lm
        },
        bqp: bqp_options(o.time_limit, o.node_limit)?,
    })
}

/// Result of one joint as a dict of arrays and numbers.
fn result_dict<'py>(
    py: Python<'py>,
    r: ArticulatedResult,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let d = pyo3::types::PyDict::new(py);
    d.set_item("X", points_array(&r.points).into_pyarray(py))?;
    d.set_item("radius", r.radius)?;
    d.set_item("bqp_radius", r.bqp_radius)?;
    d.set_item(
        "coeffs_theta",
        Array1::from(r.coeffs_theta).into_pyarray(py),
    )?;
    d.set_item("coeffs_phi", Array1::from(r.coeffs_phi).into_pyarray(py))?;
    d.set_item("bqp_size", r.bqp_size)?;
    d.set_item("bqp_objective", r.bqp.objective)?;
    d.set_item("bqp_gap", r.bqp.gap)?;
    d.set_item("bqp_nodes", r.bqp.nodes)?;
    d.set_item("bqp_optimal", r.bqp.optimal)?;
    d.set_item("n_observed", r.n_observed)?;
    d.set_item("reprojection_rms", r.reprojection_rms)?;
    d.set_item("lm_iterations", r.lm_iterations)?;
    d.set_item("converged", r.converged)?;
    d.set_item("selection_margin", r.selection_margin)?;
    match r.alternative {
        Some(alt) => d.set_item("alternative", points_array(&alt).into_pyarray(py))?,
        None => d.set_item("alternative", py.None())?,
    }
    Ok(d)
}

/// `(F, 3)` rows of points.
fn points_array(points: &[nalgebra::Vector3<f64>]) -> Array2<f64> {
    Array2::from_shape_fn((points.len(), 3), |(i, j)| points[i][j])
}

/// One articulated trajectory (Eq 4.5–4.12); returns a dict (see `_core.pyi`).
#[pyfunction]
#[pyo3(signature = (k_mat, r_mat, c_mat, x, parent, times, length, options, children=Vec::new(), angle_priors=Vec::new()))]
#[allow(clippy::too_many_arguments)]
fn reconstruct_articulated<'py>(
    py: Python<'py>,
    k_mat: PyReadonlyArray3<'py, f64>,
    r_mat: PyReadonlyArray3<'py, f64>,
    c_mat: PyReadonlyArray2<'py, f64>,
    x: PyReadonlyArray2<'py, f64>,
    parent: PyReadonlyArray2<'py, f64>,
    times: PyReadonlyArray1<'py, f64>,
    length: f64,
    options: Bound<'py, PyAny>,
    children: Vec<(PyReadonlyArray2<'py, f64>, f64)>,
    angle_priors: Vec<(PyReadonlyArray2<'py, f64>, f64, f64)>,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let options: PyArticulatedOptions = crate::convert::options(&options, "ArticulatedOptions")?;
    let cams = cameras(&k_mat, &r_mat, &c_mat)?;
    let f = cams.len();
    let px = pixels_2d(&x, f)?;
    let par = points(&parent, "parent", f)?;
    let t = times_of(&times, f)?;
    let opts = art_options(&options)?;
    let kids = children
        .iter()
        .map(|(xc, length)| {
            Ok(art::ChildObservations {
                pixels: pixels_2d(xc, f)
                    .map_err(|e| PyValueError::new_err(format!("children: {e}")))?,
                length: *length,
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    // (reference bones (F, 3), lo, hi), the range in radians.
    let priors = angle_priors
        .iter()
        .enumerate()
        .map(|(i, (b, lo, hi))| {
            Ok(art::AnglePrior {
                reference: points(b, &format!("angle_priors[{i}] reference"), f)?,
                range: (*lo, *hi),
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let r = detach(py, || {
        art::reconstruct_articulated_prior(&cams, &px, &par, &t, length, &kids, &priors, &opts)
    })?;
    result_dict(py, r)
}

/// Whole skeleton from its root (Eq 4.6): `(X (F,J,3), [dict or None per joint])`.
#[pyfunction]
#[pyo3(signature = (k_mat, r_mat, c_mat, x, parents, lengths, root, times, options))]
#[allow(clippy::too_many_arguments)]
fn reconstruct_skeleton<'py>(
    py: Python<'py>,
    k_mat: PyReadonlyArray3<'py, f64>,
    r_mat: PyReadonlyArray3<'py, f64>,
    c_mat: PyReadonlyArray2<'py, f64>,
    x: PyReadonlyArray3<'py, f64>,
    parents: Vec<i64>,
    lengths: Vec<f64>,
    root: PyReadonlyArray2<'py, f64>,
    times: PyReadonlyArray1<'py, f64>,
    options: Bound<'py, PyAny>,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Vec<Option<Bound<'py, pyo3::types::PyDict>>>,
)> {
    let options: PyArticulatedOptions = crate::convert::options(&options, "ArticulatedOptions")?;
    let sk = skeleton(parents, lengths)?;
    let cams = cameras(&k_mat, &r_mat, &c_mat)?;
    let f = cams.len();
    let nj = sk.n_joints();
    let xv = x.as_array();
    let s = xv.shape();
    if s[0] != f || s[1] != nj || s[2] != 2 {
        return Err(PyValueError::new_err(format!(
            "x: expected ({f}, {nj}, 2) pixels, got ({}, {}, {})",
            s[0], s[1], s[2]
        )));
    }
    let mut px = vec![vec![None; nj]; f];
    for i in 0..f {
        for j in 0..nj {
            let (u, v) = (xv[[i, j, 0]], xv[[i, j, 1]]);
            px[i][j] = match (u.is_nan(), v.is_nan()) {
                (true, true) => None,
                (false, false) if u.is_finite() && v.is_finite() => Some(Vector2::new(u, v)),
                _ => {
                    return Err(PyValueError::new_err(format!(
                        "x: frame {i}, joint {j} must be finite or entirely NaN (missing)"
                    )))
                }
            };
        }
    }
    let rt = points(&root, "root", f)?;
    let t = times_of(&times, f)?;
    let opts = art_options(&options)?;
    let (pos, res) = detach(py, || {
        art::reconstruct_skeleton(&cams, &px, &sk, &rt, &t, &opts)
    })?;
    let mut out = Array3::<f64>::zeros((f, nj, 3));
    for i in 0..f {
        for j in 0..nj {
            for c in 0..3 {
                out[[i, j, c]] = pos[i][j][c];
            }
        }
    }
    let dicts = res
        .into_iter()
        .map(|r| r.map(|r| result_dict(py, r)).transpose())
        .collect::<PyResult<Vec<_>>>()?;
    Ok((out.into_pyarray(py), dicts))
}

fn skeleton(parents: Vec<i64>, lengths: Vec<f64>) -> PyResult<Skeleton> {
    let j = parents.len() as i64;
    let p = parents
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            if p == -1 {
                Ok(None)
            } else if p < 0 || p >= j {
                Err(PyValueError::new_err(format!(
                    "parents: joint {i} has parent {p}, out of range (−1 for the root, else 0..{j})"
                )))
            } else {
                Ok(Some(p as usize))
            }
        })
        .collect::<PyResult<Vec<_>>>()?;
    map(Skeleton::new(p, lengths))
}

/// Validates a skeleton (tree) and returns its parents-first joint order.
#[pyfunction]
fn skeleton_order(parents: Vec<i64>, lengths: Vec<f64>) -> PyResult<Vec<usize>> {
    Ok(skeleton(parents, lengths)?.order().to_vec())
}

/// Reconstructability η_a (Eq 4.13) of a known child trajectory.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn articulated_reconstructability(
    k_mat: PyReadonlyArray3<'_, f64>,
    r_mat: PyReadonlyArray3<'_, f64>,
    c_mat: PyReadonlyArray2<'_, f64>,
    parent: PyReadonlyArray2<'_, f64>,
    child: PyReadonlyArray2<'_, f64>,
    times: PyReadonlyArray1<'_, f64>,
    k: usize,
) -> PyResult<f64> {
    let cams: Vec<Camera> = cameras(&k_mat, &r_mat, &c_mat)?;
    let f = cams.len();
    let par = points(&parent, "parent", f)?;
    let ch = points(&child, "child", f)?;
    let t = times_of(&times, f)?;
    map(art::reconstructability(&cams, &par, &ch, &t, k))
}

/// The BQP of Eq 4.12 for one joint: `(Q (n,n), c (n,), constant)`.
#[pyfunction]
#[pyo3(signature = (k_mat, r_mat, c_mat, x, parent, times, length, k, fit_radius=false))]
#[allow(clippy::too_many_arguments)]
fn articulated_bqp<'py>(
    py: Python<'py>,
    k_mat: PyReadonlyArray3<'py, f64>,
    r_mat: PyReadonlyArray3<'py, f64>,
    c_mat: PyReadonlyArray2<'py, f64>,
    x: PyReadonlyArray2<'py, f64>,
    parent: PyReadonlyArray2<'py, f64>,
    times: PyReadonlyArray1<'py, f64>,
    length: f64,
    k: usize,
    fit_radius: bool,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>, f64)> {
    let cams = cameras(&k_mat, &r_mat, &c_mat)?;
    let f = cams.len();
    let px = pixels_2d(&x, f)?;
    let par = points(&parent, "parent", f)?;
    let t = times_of(&times, f)?;
    if !(length.is_finite() && length > 0.0) {
        return Err(PyValueError::new_err(format!(
            "length: must be positive, got {length}"
        )));
    }
    if k == 0 {
        return Err(PyValueError::new_err("k: must be at least 1"));
    }
    let span = map(socialcore::basis::DctSpan::from_times(&t))?;
    let theta = map(span.matrix(&t, k))?;
    let cand = map(art::candidates(&cams, &px, &par, length, fit_radius))?;
    let (p, constant, _) = map(art::articulated_qp(&cand, &theta))?;
    let n = p.n();
    let mut q = Array2::<f64>::zeros((n, n));
    let mut c = Array1::<f64>::zeros(n);
    let (qf, cf) = p.coefficients();
    for i in 0..n {
        c[i] = cf[i];
        for j in 0..n {
            q[[i, j]] = qf[i * n + j];
        }
    }
    Ok((q.into_pyarray(py), c.into_pyarray(py), constant))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(solve_bqp, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct_articulated, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct_skeleton, m)?)?;
    m.add_function(wrap_pyfunction!(skeleton_order, m)?)?;
    m.add_function(wrap_pyfunction!(articulated_reconstructability, m)?)?;
    m.add_function(wrap_pyfunction!(articulated_bqp, m)?)?;
    Ok(())
}
