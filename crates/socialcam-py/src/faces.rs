//! 3D faces (thesis Sec 3.2.2). NumPy formats: camera slots as `K (M,3,3)`, `R (M,3,3)`,
//! `C (M,3)` (one slot = one camera at one instant); detections as `slot (N,)` int64,
//! `landmarks (N,5,2)` pixels, `size (N,)` or `sigma (N,)` pixels; groups as int64 with −1
//! for "none".

use nalgebra::{Vector2, Vector3};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use socialcore::faces::{self as fc, Anchor, AssociationOptions, Detection, N_LANDMARKS};

use crate::convert::{blocks, cameras, rows, vec1, vec3};
use crate::errors::detach;

fn index_vec(
    a: &PyReadonlyArray1<'_, i64>,
    name: &str,
    n: usize,
    bound: usize,
) -> PyResult<Vec<usize>> {
    let v: Vec<i64> = a.as_array().iter().copied().collect();
    if v.len() != n {
        return Err(PyValueError::new_err(format!(
            "{name}: expected {n} indices, got {}",
            v.len()
        )));
    }
    v.into_iter()
        .map(|s| {
            if s < 0 || s as usize >= bound {
                Err(PyValueError::new_err(format!(
                    "{name}: index {s} out of range (0..{bound})"
                )))
            } else {
                Ok(s as usize)
            }
        })
        .collect()
}

fn landmarks_of(
    l: &PyReadonlyArray3<'_, f64>,
) -> PyResult<(Vec<[Vector2<f64>; N_LANDMARKS]>, usize)> {
    let (lf, n) = blocks(l, "landmarks", N_LANDMARKS, 2)?;
    let out = lf
        .chunks_exact(2 * N_LANDMARKS)
        .map(|c| std::array::from_fn(|p| Vector2::new(c[2 * p], c[2 * p + 1])))
        .collect();
    Ok((out, n))
}

fn per_row(a: &PyReadonlyArray1<'_, f64>, name: &str, n: usize) -> PyResult<Vec<f64>> {
    let v = vec1(a);
    if v.len() != n {
        return Err(PyValueError::new_err(format!(
            "{name}: expected {n} values, got {}",
            v.len()
        )));
    }
    Ok(v)
}

fn detections(
    slot: &PyReadonlyArray1<'_, i64>,
    landmarks: &PyReadonlyArray3<'_, f64>,
    size: &PyReadonlyArray1<'_, f64>,
    size_name: &str,
    n_slots: usize,
) -> PyResult<Vec<Detection>> {
    let (lms, n) = landmarks_of(landmarks)?;
    let slots = index_vec(slot, "slot", n, n_slots)?;
    let sizes = per_row(size, size_name, n)?;
    Ok(lms
        .into_iter()
        .zip(slots)
        .zip(sizes)
        .map(|((landmarks, slot), size)| Detection {
            slot,
            landmarks,
            size,
        })
        .collect())
}

/// Eq 3.2 over many instants at once → `group (N,)`, `group_anchor (G,)`,
/// `group_instant (G,)` (−1 = none). Slots are split into instants by `instant (M,)`;
/// anchors `(A,3)` with their own slot `anchor_slot (A,)`; group ids are global.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (k, r, c, instant, slot, landmarks, size, anchor_centre, anchor_slot,
    anchor_instant, anchor_gate, rel_threshold, min_threshold, interocular_min, interocular_max, shape_min=0.5, shape_max=1.6))]
fn face_associate<'py>(
    py: Python<'py>,
    k: PyReadonlyArray3<'py, f64>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    instant: PyReadonlyArray1<'py, i64>,
    slot: PyReadonlyArray1<'py, i64>,
    landmarks: PyReadonlyArray3<'py, f64>,
    size: PyReadonlyArray1<'py, f64>,
    anchor_centre: PyReadonlyArray2<'py, f64>,
    anchor_slot: PyReadonlyArray1<'py, i64>,
    anchor_instant: PyReadonlyArray1<'py, i64>,
    anchor_gate: PyReadonlyArray1<'py, f64>,
    rel_threshold: f64,
    min_threshold: f64,
    interocular_min: f64,
    interocular_max: f64,
    shape_min: f64,
    shape_max: f64,
) -> PyResult<(
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
)> {
    let cams = cameras(&k, &r, &c)?;
    let m = cams.len();
    let inst = index_vec(&instant, "instant", m, usize::MAX)?;
    let dets = detections(&slot, &landmarks, &size, "size", m)?;
    let (af, na) = rows(&anchor_centre, "anchor_centre", 3)?;
    let a_raw: Vec<i64> = anchor_slot.as_array().iter().copied().collect();
    if a_raw.len() != na || a_raw.iter().any(|&s| s < -1 || s >= m as i64) {
        return Err(PyValueError::new_err(format!(
            "anchor_slot: expected {na} camera slots in 0..{m} or −1 (a tracked face)"
        )));
    }
    let aslot: Vec<usize> = a_raw
        .iter()
        .map(|&s| if s < 0 { usize::MAX } else { s as usize })
        .collect();
    let agate = per_row(&anchor_gate, "anchor_gate", na)?;
    if agate.iter().any(|g| !(g.is_finite() && *g >= 0.0)) {
        return Err(PyValueError::new_err("anchor_gate: must be finite and ≥ 0"));
    }
    let n_inst = inst.iter().copied().max().map_or(0, |x| x + 1);
    let ainst = index_vec(&anchor_instant, "anchor_instant", na, n_inst.max(1))?;
    if aslot
        .iter()
        .zip(&ainst)
        .any(|(&s, &t)| s != usize::MAX && inst[s] != t)
    {
        return Err(PyValueError::new_err(
            "anchor_instant: an anchor's own camera slot belongs to another instant",
        ));
    }
    let vals = [
        rel_threshold,
        min_threshold,
        interocular_min,
        interocular_max,
        shape_min,
        shape_max,
    ];
    if vals.iter().any(|v| !(v.is_finite() && *v >= 0.0))
        || interocular_min >= interocular_max
        || shape_min >= shape_max
    {
        return Err(PyValueError::new_err(
            "options: thresholds must be finite and ≥ 0, interocular_min < interocular_max, \
             shape_min < shape_max",
        ));
    }
    let opts = AssociationOptions {
        rel_threshold,
        min_threshold,
        interocular: (interocular_min, interocular_max),
        shape: (shape_min, shape_max),
    };
    let (group, gan, ginst) = detach(py, move || {
        socialcore::error::ensure_alloc("instant", &[n_inst], 64)?;
        // per instant: its slots (renumbered), detections and anchors
        let mut slots_of: Vec<Vec<usize>> = vec![Vec::new(); n_inst];
        let mut local = vec![0usize; m];
        for (s, &t) in inst.iter().enumerate() {
            local[s] = slots_of[t].len();
            slots_of[t].push(s);
        }
        let mut dets_of: Vec<Vec<usize>> = vec![Vec::new(); n_inst];
        for (i, d) in dets.iter().enumerate() {
            dets_of[inst[d.slot]].push(i);
        }
        let mut anchors_of: Vec<Vec<usize>> = vec![Vec::new(); n_inst];
        for (a, &t) in ainst.iter().enumerate() {
            anchors_of[t].push(a);
        }
        let results: Vec<socialcore::Result<fc::Association>> = (0..n_inst)
            .into_par_iter()
            .map(|t| {
                let cs: Vec<_> = slots_of[t].iter().map(|&s| cams[s]).collect();
                let ds: Vec<Detection> = dets_of[t]
                    .iter()
                    .map(|&i| Detection {
                        slot: local[dets[i].slot],
                        ..dets[i].clone()
                    })
                    .collect();
                let an: Vec<Anchor> = anchors_of[t]
                    .iter()
                    .map(|&a| Anchor {
                        centre: vec3(&af[3 * a..]),
                        slot: if aslot[a] == usize::MAX {
                            usize::MAX
                        } else {
                            local[aslot[a]]
                        },
                        gate: agate[a],
                    })
                    .collect();
                fc::associate(&cs, &ds, &an, &opts)
            })
            .collect();
        let mut group = vec![-1i64; dets.len()];
        let mut gan: Vec<i64> = Vec::new();
        let mut ginst: Vec<i64> = Vec::new();
        for (t, res) in results.into_iter().enumerate() {
            let a = res?;
            let base = gan.len();
            for g in &a.anchor {
                gan.push(g.map_or(-1, |x| anchors_of[t][x] as i64));
                ginst.push(t as i64);
            }
            for (j, &i) in dets_of[t].iter().enumerate() {
                if let Some(g) = a.label[j] {
                    group[i] = (base + g) as i64;
                }
            }
        }
        Ok((group, gan, ginst))
    })?;
    Ok((
        Array1::from_vec(group).into_pyarray(py),
        Array1::from_vec(gan).into_pyarray(py),
        Array1::from_vec(ginst).into_pyarray(py),
    ))
}

fn groups(group: &PyReadonlyArray1<'_, i64>, n: usize) -> PyResult<(Vec<Option<usize>>, usize)> {
    let g: Vec<i64> = group.as_array().iter().copied().collect();
    if g.len() != n {
        return Err(PyValueError::new_err(format!(
            "group: expected {n} labels, got {}",
            g.len()
        )));
    }
    if g.iter().any(|&x| x < -1) {
        return Err(PyValueError::new_err(
            "group: labels are ≥ 0, or −1 for none",
        ));
    }
    let n_groups = g
        .iter()
        .copied()
        .max()
        .map_or(0, |x| (x + 1).max(0) as usize);
    Ok((
        g.into_iter()
            .map(|x| (x >= 0).then_some(x as usize))
            .collect(),
        n_groups,
    ))
}

/// Eq 3.3 per group → `x (G,5,3)`, `std (G,5)` metres, `rms (G,)` pixels, `views (G,)`;
/// NaN (and 0 views) for groups that could not be triangulated.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn face_triangulate<'py>(
    py: Python<'py>,
    k: PyReadonlyArray3<'py, f64>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    slot: PyReadonlyArray1<'py, i64>,
    landmarks: PyReadonlyArray3<'py, f64>,
    sigma: PyReadonlyArray1<'py, f64>,
    group: PyReadonlyArray1<'py, i64>,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<i64>>,
)> {
    let cams = cameras(&k, &r, &c)?;
    let dets = detections(&slot, &landmarks, &sigma, "sigma", cams.len())?;
    let (label, n_groups) = groups(&group, dets.len())?;
    let sig: Vec<f64> = dets.iter().map(|d| d.size).collect();
    let faces = detach(py, move || {
        fc::triangulate_faces(&cams, &dets, &sig, &label, n_groups)
    })?;
    let g = faces.len();
    let mut x = Array3::<f64>::from_elem((g, N_LANDMARKS, 3), f64::NAN);
    let mut std = Array2::<f64>::from_elem((g, N_LANDMARKS), f64::NAN);
    let mut rms = Array1::<f64>::from_elem(g, f64::NAN);
    let mut views = Array1::<i64>::zeros(g);
    for (i, f) in faces.iter().enumerate() {
        if let Some(f) = f {
            for p in 0..N_LANDMARKS {
                for j in 0..3 {
                    x[[i, p, j]] = f.x[p][j];
                }
                std[[i, p]] = f.std[p];
            }
            rms[i] = f.rms;
            views[i] = f.views as i64;
        }
    }
    Ok((
        x.into_pyarray(py),
        std.into_pyarray(py),
        rms.into_pyarray(py),
        views.into_pyarray(py),
    ))
}

fn faces_of(
    x: &PyReadonlyArray3<'_, f64>,
    name: &str,
) -> PyResult<Vec<[Vector3<f64>; N_LANDMARKS]>> {
    let (xf, _) = blocks(x, name, N_LANDMARKS, 3)?;
    Ok(xf
        .chunks_exact(3 * N_LANDMARKS)
        .map(|c| std::array::from_fn(|p| vec3(&c[3 * p..])))
        .collect())
}

/// Eq 3.4 over one track of `T` instants → refined `x (T,5,3)` and `std (T,5)`; `lam`
/// weighs the motion of the face's centre, `lam_shape` (default `lam`) its turning.
/// Observations: `step (N,)` instant of each detection, `slot (N,)` its camera slot.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (k, r, c, step, slot, landmarks, sigma, x0, lam, iterations, lam_shape=None))]
fn face_refine_track<'py>(
    py: Python<'py>,
    k: PyReadonlyArray3<'py, f64>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    step: PyReadonlyArray1<'py, i64>,
    slot: PyReadonlyArray1<'py, i64>,
    landmarks: PyReadonlyArray3<'py, f64>,
    sigma: PyReadonlyArray1<'py, f64>,
    x0: PyReadonlyArray3<'py, f64>,
    lam: f64,
    iterations: usize,
    lam_shape: Option<f64>,
) -> PyResult<(Bound<'py, PyArray3<f64>>, Bound<'py, PyArray2<f64>>)> {
    let cams = cameras(&k, &r, &c)?;
    let dets = detections(&slot, &landmarks, &sigma, "sigma", cams.len())?;
    let init = faces_of(&x0, "x0")?;
    let steps = index_vec(&step, "step", dets.len(), init.len())?;
    let obs: Vec<_> = dets
        .iter()
        .zip(&steps)
        .map(|(d, &t)| (t, d.slot, d.landmarks, d.size))
        .collect();
    let iters = iterations.clamp(1, 100);
    let lam_s = lam_shape.unwrap_or(lam);
    let (x, std) = detach(py, move || {
        fc::refine_track(&cams, &obs, &init, lam, lam_s, iters)
    })?;
    let t_len = x.len();
    let mut xo = Array3::<f64>::zeros((t_len, N_LANDMARKS, 3));
    let mut so = Array2::<f64>::zeros((t_len, N_LANDMARKS));
    for t in 0..t_len {
        for p in 0..N_LANDMARKS {
            for j in 0..3 {
                xo[[t, p, j]] = x[t][p][j];
            }
            so[[t, p]] = std[t][p];
        }
    }
    Ok((xo.into_pyarray(py), so.into_pyarray(py)))
}

/// Primary gaze rays of faces `x (G,5,3)` with landmark std `(G,5)` → `p (G,3)`,
/// `v (G,3)` unit, `sigma (G,)` radians; NaN rows where a face is missing or degenerate.
#[pyfunction]
fn face_gaze<'py>(
    py: Python<'py>,
    x: PyReadonlyArray3<'py, f64>,
    std: PyReadonlyArray2<'py, f64>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    let faces = faces_of(&x, "x")?;
    let (sf, ns) = rows(&std, "std", N_LANDMARKS)?;
    if ns != faces.len() {
        return Err(PyValueError::new_err(format!(
            "std: {ns} rows for {} faces",
            faces.len()
        )));
    }
    let g = faces.len();
    let mut p = Array2::<f64>::from_elem((g, 3), f64::NAN);
    let mut v = Array2::<f64>::from_elem((g, 3), f64::NAN);
    let mut s = Array1::<f64>::from_elem(g, f64::NAN);
    for (i, f) in faces.iter().enumerate() {
        let st: [f64; N_LANDMARKS] = std::array::from_fn(|q| sf[N_LANDMARKS * i + q]);
        let finite = f.iter().all(|y| y.iter().all(|z| z.is_finite()));
        if !finite {
            continue;
        }
        if let Ok((o, d, sig)) = fc::gaze_from_landmarks(f, &st) {
            for j in 0..3 {
                p[[i, j]] = o[j];
                v[[i, j]] = d[j];
            }
            s[i] = sig;
        }
    }
    Ok((p.into_pyarray(py), v.into_pyarray(py), s.into_pyarray(py)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(face_associate, m)?)?;
    m.add_function(wrap_pyfunction!(face_triangulate, m)?)?;
    m.add_function(wrap_pyfunction!(face_refine_track, m)?)?;
    m.add_function(wrap_pyfunction!(face_gaze, m)?)?;
    Ok(())
}
