//! Social saliency and social charges (thesis Chapter 6). NumPy formats: a frame's rays as
//! `p (N,3)` eye centres, `v (N,3)` unit directions, `h (N,)` bandwidths, `ids (N,)` int64;
//! a sequence as the rays of all frames stacked (`(T,3)`, `(T,)`) with `offsets (F+1,)`
//! (frame `f` is rows `offsets[f]..offsets[f+1]`). Charges come back as flat arrays over
//! all charges `C`, with `frame (C,)` and ragged members/memberships as flat values plus
//! `(C+1,)` offsets.

use nalgebra::Vector3;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use socialcore::saliency::{
    self as sal, Charge, GazeRays, Grid, Membership, ModeOptions, TrackOptions,
};

use crate::convert::{rows, vec1};
use crate::errors::{detach, map};

fn ids_vec(ids: Option<PyReadonlyArray1<'_, i64>>) -> Option<Vec<i64>> {
    ids.map(|a| a.as_array().iter().copied().collect())
}

/// Validated rays of one frame.
fn gaze_rays(
    p: &PyReadonlyArray2<'_, f64>,
    v: &PyReadonlyArray2<'_, f64>,
    h: &PyReadonlyArray1<'_, f64>,
    ids: Option<PyReadonlyArray1<'_, i64>>,
) -> PyResult<GazeRays> {
    let (pf, _) = rows(p, "p", 3)?;
    let (vf, _) = rows(v, "v", 3)?;
    map(GazeRays::from_flat(&pf, &vf, &vec1(h), ids_vec(ids)))
}

/// The social saliency field (Eq 6.4) at `points (M,3)` → `(M,)`.
#[pyfunction]
#[pyo3(signature = (p, v, h, points))]
fn saliency_field<'py>(
    py: Python<'py>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    h: PyReadonlyArray1<'py, f64>,
    points: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let rays = gaze_rays(&p, &v, &h, None)?;
    let (xf, _) = rows(&points, "points", 3)?;
    let pts: Vec<Vector3<f64>> = xf
        .chunks_exact(3)
        .map(|c| Vector3::new(c[0], c[1], c[2]))
        .collect();
    let out = detach(py, || sal::saliency_at(&rays, &pts))?;
    Ok(Array1::from(out).into_pyarray(py))
}

/// The field on the grid `lo..hi` (inclusive) of `shape` points per axis → `shape` array.
#[pyfunction]
#[pyo3(signature = (p, v, h, lo, hi, shape))]
fn saliency_grid<'py>(
    py: Python<'py>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    h: PyReadonlyArray1<'py, f64>,
    lo: [f64; 3],
    hi: [f64; 3],
    shape: [usize; 3],
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let rays = gaze_rays(&p, &v, &h, None)?;
    let grid = map(Grid::new(lo, hi, shape))?;
    let out = detach(py, || sal::saliency_grid(&rays, &grid))?;
    let arr = Array3::from_shape_vec((shape[0], shape[1], shape[2]), out)
        .map_err(|e| PyValueError::new_err(format!("shape: {e}")))?;
    Ok(arr.into_pyarray(py))
}

type ChargeArrays<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray2<f64>>,
);

/// The fields of `socialcam.ChargeOptions` (the frozen dataclass validated in Python),
/// read by attribute so that the option list is written once.
#[derive(FromPyObject)]
pub struct PyChargeOptions {
    #[pyo3(attribute)]
    seeds_per_ray: usize,
    #[pyo3(attribute)]
    depth_range: (f64, f64),
    #[pyo3(attribute)]
    pair_seeds: bool,
    #[pyo3(attribute)]
    pair_candidates: bool,
    #[pyo3(attribute)]
    min_member_depth: f64,
    #[pyo3(attribute)]
    tol: f64,
    #[pyo3(attribute)]
    newton: bool,
    #[pyo3(attribute)]
    max_iter: usize,
    #[pyo3(attribute)]
    merge_radius: f64,
    #[pyo3(attribute)]
    member_sigma: f64,
    #[pyo3(attribute)]
    min_members: usize,
    #[pyo3(attribute)]
    membership: String,
    #[pyo3(attribute)]
    charge_penalty: f64,
    #[pyo3(attribute)]
    unattended: f64,
    #[pyo3(attribute)]
    min_magnitude: f64,
    #[pyo3(attribute)]
    bounds: Option<([f64; 3], [f64; 3])>,
    #[pyo3(attribute)]
    pool_frames: usize,
    #[pyo3(attribute)]
    drift: f64,
    #[pyo3(attribute)]
    joint_window: bool,
    #[pyo3(attribute)]
    switch_cost: f64,
    #[pyo3(attribute)]
    region_level: f64,
    #[pyo3(attribute)]
    region_max_radius: f64,
}

impl PyChargeOptions {
    fn to_core(&self) -> PyResult<ModeOptions> {
        let membership = match self.membership.as_str() {
            "partition" => Membership::Partition,
            "cover" => Membership::Cover,
            "strongest" => Membership::Strongest,
            "all" => Membership::All,
            other => {
                return Err(PyValueError::new_err(format!(
                    "membership: expected 'partition', 'cover', 'strongest' or 'all', got {other:?}"
                )))
            }
        };
        Ok(ModeOptions {
            seeds_per_ray: self.seeds_per_ray,
            depth_min: self.depth_range.0,
            depth_max: self.depth_range.1,
            pair_seeds: self.pair_seeds,
            pair_candidates: self.pair_candidates,
            min_member_depth: self.min_member_depth,
            tol: self.tol,
            newton: self.newton,
            max_iter: self.max_iter,
            merge_radius: self.merge_radius,
            member_sigma: self.member_sigma,
            min_members: self.min_members,
            membership,
            charge_penalty: self.charge_penalty,
            unattended: self.unattended,
            min_magnitude: self.min_magnitude,
            bounds: self
                .bounds
                .map(|(lo, hi)| (Vector3::from(lo), Vector3::from(hi))),
            pool_frames: self.pool_frames,
            drift: self.drift,
            joint_window: self.joint_window,
            switch_cost: self.switch_cost,
            region_level: self.region_level,
            region_max_radius: self.region_max_radius,
        })
    }
}

/// The validated frames of stacked rays `p (T,3)`, `v (T,3)`, `h (T,)` split by `offsets
/// (F+1,)`, with person `ids (T,)`.
fn sequence_frames(
    p: &PyReadonlyArray2<'_, f64>,
    v: &PyReadonlyArray2<'_, f64>,
    h: &PyReadonlyArray1<'_, f64>,
    offsets: &PyReadonlyArray1<'_, i64>,
    ids: Option<PyReadonlyArray1<'_, i64>>,
) -> PyResult<Vec<GazeRays>> {
    let (pf, n) = rows(p, "p", 3)?;
    let (vf, nv) = rows(v, "v", 3)?;
    let hf = vec1(h);
    if nv != n || hf.len() != n {
        return Err(PyValueError::new_err(format!(
            "p, v, h: need the same number of rays, got {n}, {nv}, {}",
            hf.len()
        )));
    }
    let off: Vec<i64> = offsets.as_array().iter().copied().collect();
    if off.len() < 2
        || off[0] != 0
        || *off.last().unwrap_or(&-1) != n as i64
        || off.windows(2).any(|w| w[1] < w[0])
    {
        return Err(PyValueError::new_err(format!(
            "offsets: expected a non-decreasing (F+1,) array from 0 to {n}"
        )));
    }
    let idf = ids_vec(ids);
    if idf.as_ref().is_some_and(|i| i.len() != n) {
        return Err(PyValueError::new_err(format!(
            "ids: need one id per ray ({n}), got {}",
            idf.as_ref().map_or(0, Vec::len)
        )));
    }
    let frames: Vec<GazeRays> =
        off.windows(2)
            .enumerate()
            .map(|(f, w)| {
                let (a, b) = (w[0] as usize, w[1] as usize);
                let frame_ids = idf.as_ref().map(|i| i[a..b].to_vec());
                GazeRays::from_flat(&pf[3 * a..3 * b], &vf[3 * a..3 * b], &hf[a..b], frame_ids)
                    .map_err(|e| match e {
                        socialcore::Error::InvalidInput { arg, msg } => {
                            socialcore::Error::invalid(arg, format!("frame {f}: {msg}"))
                        }
                        other => other,
                    })
            })
            .collect::<socialcore::Result<_>>()
            .map_err(|e| PyErr::from(crate::errors::PyCoreError(e)))?;
    Ok(frames)
}

/// Mode seeking on every frame (Eq 6.5–6.8) with the options of a
/// `socialcam.ChargeOptions`. Returns, over all charges `C`: `frame (C,)`,
/// `position (C,3)`, `magnitude (C,)`, `support (C,)`, `members` (flat ray indices within
/// the frame) with `member_offsets (C+1,)`, `membership` (flat, `N_f` values per charge),
/// `region_centre (C,3)`, `region_axes (C,3,3)` (columns are the axes), `region_radii (C,3)`.
/// `ids (T,)`: person ids of the rays (default: the row within the frame), which follow
/// people across frames.
#[pyfunction]
#[pyo3(signature = (p, v, h, offsets, seed, options, ids=None))]
#[allow(clippy::too_many_arguments)]
fn find_charges<'py>(
    py: Python<'py>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    h: PyReadonlyArray1<'py, f64>,
    offsets: PyReadonlyArray1<'py, i64>,
    seed: u64,
    options: Bound<'py, PyAny>,
    ids: Option<PyReadonlyArray1<'py, i64>>,
) -> PyResult<ChargeArrays<'py>> {
    let options: PyChargeOptions = crate::convert::options(&options, "ChargeOptions")?;
    let opts = options.to_core()?;
    map(opts.validate())?;
    let frames = sequence_frames(&p, &v, &h, &offsets, ids)?;
    let per_frame: Vec<Vec<Charge>> = detach(py, || {
        if frames.len() == 1 {
            Ok(vec![sal::find_charges(&frames[0], &opts, seed)?])
        } else {
            sal::find_charges_sequence(&frames, &opts, seed)
        }
    })?;
    let c = per_frame.iter().map(|f| f.len()).sum::<usize>();
    let mut frame = Vec::with_capacity(c);
    let mut position = Array2::<f64>::zeros((c, 3));
    let mut magnitude = Vec::with_capacity(c);
    let mut support = Vec::with_capacity(c);
    let mut members = Vec::new();
    let mut member_offsets = vec![0i64];
    let mut membership = Vec::new();
    let mut centre = Array2::<f64>::zeros((c, 3));
    let mut axes = Array3::<f64>::zeros((c, 3, 3));
    let mut radii = Array2::<f64>::zeros((c, 3));
    let mut k = 0;
    for (f, charges) in per_frame.iter().enumerate() {
        for ch in charges {
            frame.push(f as i64);
            magnitude.push(ch.magnitude);
            support.push(ch.support as i64);
            members.extend(ch.members.iter().map(|&i| i as i64));
            member_offsets.push(members.len() as i64);
            membership.extend_from_slice(&ch.membership);
            for a in 0..3 {
                position[[k, a]] = ch.position[a];
                centre[[k, a]] = ch.region.centre[a];
                radii[[k, a]] = ch.region.radii[a];
                for b in 0..3 {
                    axes[[k, a, b]] = ch.region.axes[(a, b)];
                }
            }
            k += 1;
        }
    }
    Ok((
        Array1::from(frame).into_pyarray(py),
        position.into_pyarray(py),
        Array1::from(magnitude).into_pyarray(py),
        Array1::from(support).into_pyarray(py),
        Array1::from(members).into_pyarray(py),
        Array1::from(member_offsets).into_pyarray(py),
        Array1::from(membership).into_pyarray(py),
        centre.into_pyarray(py),
        axes.into_pyarray(py),
        radii.into_pyarray(py),
    ))
}

/// The joint window's objective (see `socialcore::saliency::diagnose_window`) of the
/// assignment `find_charges` finds on a sequence, of the true groups `truth (T,)` (each
/// ray's group, −1 for none) with their positions fitted, and of the search started from
/// them → `(found, truth, searched)`. A bench's debug path (`benches/charges_diagnose.py`).
#[pyfunction]
#[pyo3(signature = (p, v, h, offsets, seed, options, truth, ids=None))]
#[allow(clippy::too_many_arguments)]
fn diagnose_window<'py>(
    py: Python<'py>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    h: PyReadonlyArray1<'py, f64>,
    offsets: PyReadonlyArray1<'py, i64>,
    seed: u64,
    options: Bound<'py, PyAny>,
    truth: PyReadonlyArray1<'py, i64>,
    ids: Option<PyReadonlyArray1<'py, i64>>,
) -> PyResult<(f64, f64, f64)> {
    let options: PyChargeOptions = crate::convert::options(&options, "ChargeOptions")?;
    let opts = options.to_core()?;
    let frames = sequence_frames(&p, &v, &h, &offsets, ids)?;
    let flat: Vec<i64> = truth.as_array().iter().copied().collect();
    let n: usize = frames.iter().map(GazeRays::len).sum();
    if flat.len() != n {
        return Err(PyValueError::new_err(format!(
            "truth: need one group per ray ({n}), got {}",
            flat.len()
        )));
    }
    if let Some(g) = flat.iter().find(|&&g| g < -1) {
        return Err(PyValueError::new_err(format!(
            "truth: a group is an index >= 0 or -1 (no charge), got {g}"
        )));
    }
    let mut rest = flat.as_slice();
    let truth: Vec<Vec<Option<usize>>> = frames
        .iter()
        .map(|r| {
            let (now, after) = rest.split_at(r.len());
            rest = after;
            now.iter().map(|&g| usize::try_from(g).ok()).collect()
        })
        .collect();
    let [a, b, c] = detach(py, || sal::diagnose_window(&frames, &opts, seed, &truth))?;
    Ok((a, b, c))
}

/// Classic mean-shift tracking of membership features `(n, J)` with frames `(n,)`
/// (Sec 6.1.3) → track id per charge `(n,)` (−1 = dropped: a duplicate in its frame, or
/// part of a run shorter than `min_length`) and centres `(K, J)`.
#[pyfunction]
#[pyo3(signature = (features, frames, bandwidth=0.3, max_iter=300, bin_seeding=true,
    max_gap=5, min_length=10))]
#[allow(clippy::too_many_arguments)]
fn track_charges<'py>(
    py: Python<'py>,
    features: PyReadonlyArray2<'py, f64>,
    frames: PyReadonlyArray1<'py, i64>,
    bandwidth: f64,
    max_iter: usize,
    bin_seeding: bool,
    max_gap: usize,
    min_length: usize,
) -> PyResult<(Bound<'py, PyArray1<i64>>, Bound<'py, PyArray2<f64>>)> {
    let fa = features.as_array();
    let j = fa.ncols();
    let feats: Vec<Vec<f64>> = fa.rows().into_iter().map(|r| r.to_vec()).collect();
    let fr: Vec<usize> = frames
        .as_array()
        .iter()
        .map(|&f| usize::try_from(f))
        .collect::<Result<_, _>>()
        .map_err(|_| PyValueError::new_err("frames: must be non-negative"))?;
    let opts = TrackOptions {
        bandwidth,
        max_iter,
        bin_seeding,
        max_gap,
        min_length,
    };
    let tr = detach(py, || sal::track_charges(&feats, &fr, &opts))?;
    let mut centres = Array2::<f64>::zeros((tr.centres.len(), j));
    for (k, c) in tr.centres.iter().enumerate() {
        for (a, x) in c.iter().enumerate() {
            centres[[k, a]] = *x;
        }
    }
    Ok((
        Array1::from(tr.track).into_pyarray(py),
        centres.into_pyarray(py),
    ))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(saliency_field, m)?)?;
    m.add_function(wrap_pyfunction!(saliency_grid, m)?)?;
    m.add_function(wrap_pyfunction!(find_charges, m)?)?;
    m.add_function(wrap_pyfunction!(track_charges, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose_window, m)?)?;
    Ok(())
}
