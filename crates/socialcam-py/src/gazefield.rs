//! Gaze-field bindings (thesis Chapter 7). NumPy formats:
//! - a sequence of frames as flat rays `p (N,3)`, `v (N,3)`, dense member indices
//!   `members (N,)` int64 in `0..J`, and `offsets (F+1,)` int64 (frame `f` is rays
//!   `offsets[f]..offsets[f+1]`);
//! - windows `(W,3)` int64 rows `[start, end, n_charges]` over frames;
//! - a time-varying field as `positions (F,I,3)` (NaN rows = no charge), `magnitudes (F,I)`
//!   and `kappa (F,)` (NaN = no field at that frame).

use nalgebra::Vector3;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use socialcore::gazefield::{
    self as gf, EmOptions, GazeField, GazeRay, Kappa, Membership, SocialCharge, TemporalFilter,
    WindowFrame,
};
use socialcore::Error;

use crate::convert::{rows, vec3};
use crate::errors::{detach, map};

fn ints(a: &PyReadonlyArray1<'_, i64>, name: &str) -> PyResult<Vec<usize>> {
    a.as_array()
        .iter()
        .map(|&x| {
            usize::try_from(x)
                .map_err(|_| PyValueError::new_err(format!("{name}: negative entry {x}")))
        })
        .collect()
}

fn points(a: &PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<Vec<Vector3<f64>>> {
    let (f, n) = rows(a, name, 3)?;
    Ok((0..n).map(|i| vec3(&f[3 * i..])).collect())
}

/// Frames of rays from the flat layout.
fn frames_of(
    p: &PyReadonlyArray2<'_, f64>,
    v: &PyReadonlyArray2<'_, f64>,
    members: Option<&PyReadonlyArray1<'_, i64>>,
    offsets: &PyReadonlyArray1<'_, i64>,
) -> PyResult<Vec<WindowFrame>> {
    let pp = points(p, "p")?;
    let vv = points(v, "v")?;
    if pp.len() != vv.len() {
        return Err(PyValueError::new_err(format!(
            "p, v: {} origins but {} directions",
            pp.len(),
            vv.len()
        )));
    }
    let mem = match members {
        Some(m) => ints(m, "members")?,
        None => (0..pp.len()).collect(),
    };
    if mem.len() != pp.len() {
        return Err(PyValueError::new_err(
            "members: need one member index per ray",
        ));
    }
    let off = ints(offsets, "offsets")?;
    if off.first() != Some(&0)
        || off.last() != Some(&pp.len())
        || off.windows(2).any(|w| w[0] > w[1])
    {
        return Err(PyValueError::new_err(
            "offsets: must start at 0, end at the number of rays and not decrease",
        ));
    }
    Ok(off
        .windows(2)
        .map(|w| WindowFrame {
            rays: (w[0]..w[1]).map(|k| GazeRay::new(pp[k], vv[k])).collect(),
            members: mem[w[0]..w[1]].to_vec(),
        })
        .collect())
}

fn windows_of(w: &PyReadonlyArray2<'_, i64>, n_frames: usize) -> PyResult<Vec<gf::Window>> {
    let a = w.as_array();
    if a.ncols() != 3 {
        return Err(PyValueError::new_err(
            "windows: expected a (W, 3) int64 array [start, end, n]",
        ));
    }
    let mut out = Vec::with_capacity(a.nrows());
    for (k, r) in a.rows().into_iter().enumerate() {
        let (s, e, n) = (r[0], r[1], r[2]);
        if s < 0 || e as usize > n_frames || s >= e || n < 0 {
            return Err(PyValueError::new_err(format!(
                "windows: row {k} = [{s}, {e}, {n}] is empty, negative or outside {n_frames} frames"
            )));
        }
        out.push(gf::Window {
            start: s as usize,
            end: e as usize,
            n_charges: n as usize,
        });
    }
    Ok(out)
}

/// Per-frame rows of the non-NaN positions of a `(F, I, 3)` array.
fn padded_rows(a: &PyReadonlyArray3<'_, f64>, name: &str) -> PyResult<Vec<Vec<Vector3<f64>>>> {
    let v = a.as_array();
    if v.shape()[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected an (F, I, 3) float64 array"
        )));
    }
    Ok(v.outer_iter()
        .map(|fr| {
            fr.outer_iter()
                .filter(|x| !x.iter().any(|c| c.is_nan()))
                .map(|x| Vector3::new(x[0], x[1], x[2]))
                .collect()
        })
        .collect())
}

/// Fields per frame from `positions (F,I,3)`, `magnitudes (F,I)`, `kappa (F,)`.
fn fields_of(
    positions: &PyReadonlyArray3<'_, f64>,
    magnitudes: &PyReadonlyArray2<'_, f64>,
    kappa: &PyReadonlyArray1<'_, f64>,
) -> PyResult<Vec<Option<GazeField>>> {
    let pos = positions.as_array();
    let mag = magnitudes.as_array();
    let kap = kappa.as_array();
    let (f, i) = (pos.shape()[0], pos.shape()[1]);
    if pos.shape()[2] != 3 || mag.shape() != [f, i] || kap.len() != f {
        return Err(PyValueError::new_err(
            "positions, magnitudes, kappa: expected shapes (F, I, 3), (F, I), (F,)",
        ));
    }
    (0..f)
        .map(|t| {
            if kap[t].is_nan() {
                return Ok(None);
            }
            let charges: Vec<SocialCharge> = (0..i)
                .filter(|&c| !pos[[t, c, 0]].is_nan())
                .map(|c| {
                    SocialCharge::new(
                        Vector3::new(pos[[t, c, 0]], pos[[t, c, 1]], pos[[t, c, 2]]),
                        mag[[t, c]],
                    )
                })
                .collect();
            if charges.is_empty() {
                return Ok(None);
            }
            map(GazeField::new(charges, kap[t]).map_err(|e| match e {
                Error::InvalidInput { arg, msg } => {
                    Error::invalid(arg, format!("frame {t}: {msg}"))
                }
                other => other,
            }))
            .map(Some)
        })
        .collect()
}

/// Windows `(W,3)` of constant charge count (Sec 7.3.1), short runs absorbed.
#[pyfunction]
fn gaze_split_windows<'py>(
    py: Python<'py>,
    counts: PyReadonlyArray1<'py, i64>,
    min_len: usize,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let c = ints(&counts, "counts")?;
    let w = gf::split_windows(&c, min_len);
    let mut out = Array2::<i64>::zeros((w.len(), 3));
    for (k, x) in w.iter().enumerate() {
        out[[k, 0]] = x.start as i64;
        out[[k, 1]] = x.end as i64;
        out[[k, 2]] = x.n_charges as i64;
    }
    Ok(out.into_pyarray(py))
}

/// Initial charge tracks `(F, I, 3)` (NaN outside windows / beyond a window's count): from
/// `candidates (F, C, 3)` (NaN-padded, strongest first) when given, else from pairwise ray
/// intersections scored by the cone kernel of bandwidth `sigma`.
#[pyfunction]
#[pyo3(signature = (p, v, offsets, windows, sigma, candidates=None))]
fn gaze_init<'py>(
    py: Python<'py>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    offsets: PyReadonlyArray1<'py, i64>,
    windows: PyReadonlyArray2<'py, i64>,
    sigma: f64,
    candidates: Option<PyReadonlyArray3<'py, f64>>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let frames = frames_of(&p, &v, None, &offsets)?;
    let wins = windows_of(&windows, frames.len())?;
    let cands = candidates
        .as_ref()
        .map(|c| padded_rows(c, "candidates"))
        .transpose()?;
    if let Some(c) = &cands {
        if c.len() != frames.len() {
            return Err(PyValueError::new_err("candidates: need one row per frame"));
        }
    }
    let imax = wins.iter().map(|w| w.n_charges).max().unwrap_or(0);
    let nf = frames.len();
    map(socialcore::error::ensure_alloc(
        "windows",
        &[nf, imax, 3],
        8,
    ))?;
    let rows_w = detach(py, || {
        wins.par_iter()
            .map(|w| {
                if w.n_charges == 0 {
                    return Ok(Vec::new());
                }
                match &cands {
                    Some(c) => gf::init_window_from_candidates(&c[w.start..w.end], w.n_charges),
                    None => gf::init_window(&frames[w.start..w.end], w.n_charges, sigma),
                }
            })
            .collect::<socialcore::Result<Vec<_>>>()
    })?;
    let mut out = Array3::<f64>::from_elem((nf, imax, 3), f64::NAN);
    for (w, rws) in wins.iter().zip(rows_w) {
        for (t, row) in rws.iter().enumerate() {
            for (i, x) in row.iter().enumerate() {
                for a in 0..3 {
                    out[[w.start + t, i, a]] = x[a];
                }
            }
        }
    }
    Ok(out.into_pyarray(py))
}

type EmOut<'py> = (
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<bool>>,
);

/// The EM fields of `socialcam.GazeFieldOptions` (the frozen dataclass validated in
/// Python), read by attribute so the option list is written once. Angles in radians.
#[derive(FromPyObject)]
pub struct PyGazeEmOptions {
    #[pyo3(attribute)]
    kappa: Option<f64>,
    #[pyo3(attribute)]
    kappa_init: Option<f64>,
    #[pyo3(attribute)]
    max_iter: usize,
    #[pyo3(attribute)]
    tol: f64,
    #[pyo3(attribute)]
    max_angle: f64,
    #[pyo3(attribute)]
    inner_iterations: usize,
    #[pyo3(attribute)]
    lambda_g: f64,
    #[pyo3(attribute)]
    temporal_filter: String,
    #[pyo3(attribute)]
    membership: String,
}

/// Time-windowed EM (Eq 7.10–7.14) on every window in parallel, with the options of a
/// `socialcam.GazeFieldOptions`. Returns positions `(F,I,3)`, magnitudes `(F,I)` (NaN
/// where no charge), κ per window `(W,)`, window memberships `(W,J,I)`, responsibilities
/// `(N,I)`, log-likelihood `(W,)`, iterations `(W,)`, converged `(W,)`. Windows with
/// `n = 0` are skipped (NaN, 0 iterations).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn gaze_em<'py>(
    py: Python<'py>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    members: PyReadonlyArray1<'py, i64>,
    offsets: PyReadonlyArray1<'py, i64>,
    windows: PyReadonlyArray2<'py, i64>,
    init: PyReadonlyArray3<'py, f64>,
    options: Bound<'py, PyAny>,
) -> PyResult<EmOut<'py>> {
    let options: PyGazeEmOptions = crate::convert::options(&options, "GazeFieldOptions")?;
    let frames = frames_of(&p, &v, Some(&members), &offsets)?;
    let wins = windows_of(&windows, frames.len())?;
    let init_rows = padded_rows(&init, "init")?;
    if init_rows.len() != frames.len() {
        return Err(PyValueError::new_err(
            "init: need one (I, 3) row block per frame",
        ));
    }
    let o = options;
    let filter = match o.temporal_filter.as_str() {
        "velocity" => TemporalFilter::Velocity,
        "acceleration" => TemporalFilter::Acceleration,
        other => {
            return Err(PyValueError::new_err(format!(
                "temporal_filter: expected 'velocity' or 'acceleration', got {other:?}"
            )))
        }
    };
    let membership = match o.membership.as_str() {
        "window" => Membership::PerWindow,
        "frame" => Membership::PerFrame,
        other => {
            return Err(PyValueError::new_err(format!(
                "membership: expected 'window' or 'frame', got {other:?}"
            )))
        }
    };
    let opts = EmOptions {
        kappa: match o.kappa {
            Some(k) => Kappa::Fixed(k),
            None => Kappa::Estimate {
                initial: o.kappa_init.unwrap_or(10.0),
            },
        },
        max_iterations: o.max_iter,
        tolerance: o.tol,
        max_angle: o.max_angle,
        inner_iterations: o.inner_iterations,
        lambda_g: o.lambda_g,
        filter,
        membership,
    };
    map(opts.validate())?;
    let mut jobs = Vec::new();
    for (k, w) in wins.iter().enumerate() {
        if w.n_charges == 0 {
            continue;
        }
        let rows: Vec<Vec<Vector3<f64>>> = init_rows[w.start..w.end].to_vec();
        if let Some(t) = rows.iter().position(|r| r.len() != w.n_charges) {
            return Err(PyValueError::new_err(format!(
                "init: frame {} of window {k} has {} charge positions, the window has {}",
                w.start + t,
                rows[t].len(),
                w.n_charges
            )));
        }
        jobs.push((
            k,
            gf::WindowJob {
                start: w.start,
                end: w.end,
                init: rows,
            },
        ));
    }
    let imax = wins.iter().map(|w| w.n_charges).max().unwrap_or(0);
    let n_members = frames
        .iter()
        .flat_map(|f| f.members.iter())
        .map(|m| m + 1)
        .max()
        .unwrap_or(0);
    map(socialcore::error::ensure_alloc(
        "windows",
        &[frames.len(), imax, 3],
        8,
    ))?;
    map(socialcore::error::ensure_alloc(
        "members",
        &[wins.len(), n_members, imax],
        8,
    ))?;
    let job_list: Vec<gf::WindowJob> = jobs.iter().map(|(_, j)| j.clone()).collect();
    let fits = detach(py, || gf::em_windows(&frames, &job_list, &opts))?;
    let nf = frames.len();
    let n_rays: usize = frames.iter().map(|f| f.rays.len()).sum();
    let nw = wins.len();
    let mut pos = Array3::<f64>::from_elem((nf, imax, 3), f64::NAN);
    let mut mag = Array2::<f64>::from_elem((nf, imax), f64::NAN);
    let mut kap = Array1::<f64>::from_elem(nw, f64::NAN);
    let mut memb = Array3::<f64>::from_elem((nw, n_members, imax), f64::NAN);
    let mut resp = Array2::<f64>::from_elem((n_rays, imax), f64::NAN);
    let mut ll = Array1::<f64>::from_elem(nw, f64::NAN);
    let mut iters = Array1::<i64>::zeros(nw);
    let mut conv = Array1::<bool>::from_elem(nw, false);
    let off = ints(&offsets, "offsets")?;
    for ((k, job), fit) in jobs.iter().zip(&fits) {
        let ni = wins[*k].n_charges;
        kap[*k] = fit.kappa;
        ll[*k] = fit.log_likelihood;
        iters[*k] = fit.iterations as i64;
        conv[*k] = fit.converged;
        let jw = fit.membership.len() / ni;
        for m in 0..jw {
            for i in 0..ni {
                memb[[*k, m, i]] = fit.membership[m * ni + i];
            }
        }
        for (t, row) in fit.charges.iter().enumerate() {
            let f = job.start + t;
            for (i, c) in row.iter().enumerate() {
                for a in 0..3 {
                    pos[[f, i, a]] = c.position[a];
                }
                mag[[f, i]] = c.magnitude;
            }
            for (r, g) in fit.responsibilities[t].chunks(ni).enumerate() {
                for i in 0..ni {
                    resp[[off[f] + r, i]] = g[i];
                }
            }
        }
    }
    Ok((
        pos.into_pyarray(py),
        mag.into_pyarray(py),
        kap.into_pyarray(py),
        memb.into_pyarray(py),
        resp.into_pyarray(py),
        ll.into_pyarray(py),
        iters.into_pyarray(py),
        conv.into_pyarray(py),
    ))
}

/// Most likely directions `(M,3)` (Eq 7.3) at `points (M,3)` under the field of frame
/// `frame[m]`; NaN rows where undefined.
#[pyfunction]
fn gaze_predict<'py>(
    py: Python<'py>,
    positions: PyReadonlyArray3<'py, f64>,
    magnitudes: PyReadonlyArray2<'py, f64>,
    kappa: PyReadonlyArray1<'py, f64>,
    frame: PyReadonlyArray1<'py, i64>,
    points: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let fields = fields_of(&positions, &magnitudes, &kappa)?;
    let fr = ints(&frame, "frame")?;
    let pts = self::points(&points, "points")?;
    let out = detach(py, || gf::batch::predict(&fields, &fr, &pts))?;
    let mut a = Array2::<f64>::from_elem((out.len(), 3), f64::NAN);
    for (m, d) in out.iter().enumerate() {
        if let Some(d) = d {
            for k in 0..3 {
                a[[m, k]] = d[k];
            }
        }
    }
    Ok(a.into_pyarray(py))
}

/// `ln p(v | p)` (Eq 7.7) `(M,)` under the field of frame `frame[m]`; NaN where no field.
#[pyfunction]
fn gaze_log_density<'py>(
    py: Python<'py>,
    positions: PyReadonlyArray3<'py, f64>,
    magnitudes: PyReadonlyArray2<'py, f64>,
    kappa: PyReadonlyArray1<'py, f64>,
    frame: PyReadonlyArray1<'py, i64>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let fields = fields_of(&positions, &magnitudes, &kappa)?;
    let fr = ints(&frame, "frame")?;
    let (pp, vv) = (points(&p, "p")?, points(&v, "v")?);
    let out = detach(py, || gf::batch::log_density(&fields, &fr, &pp, &vv))?;
    Ok(Array1::from_vec(out).into_pyarray(py))
}

/// Angle (radians) from `v` to the closest charge direction, ignoring charges within
/// `self_radius` of `p`; NaN where none qualifies.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn gaze_angle_to_charges<'py>(
    py: Python<'py>,
    positions: PyReadonlyArray3<'py, f64>,
    magnitudes: PyReadonlyArray2<'py, f64>,
    kappa: PyReadonlyArray1<'py, f64>,
    frame: PyReadonlyArray1<'py, i64>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    self_radius: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let fields = fields_of(&positions, &magnitudes, &kappa)?;
    let fr = ints(&frame, "frame")?;
    let (pp, vv) = (points(&p, "p")?, points(&v, "v")?);
    let out = detach(py, || {
        gf::batch::angle_to_charges(&fields, &fr, &pp, &vv, self_radius)
    })?;
    Ok(Array1::from_vec(out).into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(gaze_split_windows, m)?)?;
    m.add_function(wrap_pyfunction!(gaze_init, m)?)?;
    m.add_function(wrap_pyfunction!(gaze_em, m)?)?;
    m.add_function(wrap_pyfunction!(gaze_predict, m)?)?;
    m.add_function(wrap_pyfunction!(gaze_log_density, m)?)?;
    m.add_function(wrap_pyfunction!(gaze_angle_to_charges, m)?)?;
    Ok(())
}
