//! Geometry bindings. NumPy formats: cameras as `K (F,3,3)`, `R (F,3,3)` world→camera,
//! `C (F,3)` centres; points `(N,3)`; pixels `(F,N,2)` or `(N,V,2)` with NaN = unseen.

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use socialcore::geometry::{self as g, LmOptions};

use crate::convert::{cameras, rows, vec1, vec3};
use crate::errors::{detach, map};

/// Validates cameras; raises `ValueError` naming the first bad frame.
#[pyfunction]
fn validate_cameras(
    k: PyReadonlyArray3<'_, f64>,
    r: PyReadonlyArray3<'_, f64>,
    c: PyReadonlyArray2<'_, f64>,
) -> PyResult<()> {
    cameras(&k, &r, &c).map(|_| ())
}

/// `(F,3,4)` projection matrices `K R [I | −C]`.
#[pyfunction]
fn projection_matrices<'py>(
    py: Python<'py>,
    k: PyReadonlyArray3<'py, f64>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let cams = cameras(&k, &r, &c)?;
    let mut out = Array3::<f64>::zeros((cams.len(), 3, 4));
    for (f, cam) in cams.iter().enumerate() {
        let p = cam.projection_matrix();
        for i in 0..3 {
            for j in 0..4 {
                out[[f, i, j]] = p[(i, j)];
            }
        }
    }
    Ok(out.into_pyarray(py))
}

/// Projects `X (N,3)` into every camera: pixels `(F,N,2)` and depths `(F,N)`.
#[pyfunction]
fn project<'py>(
    py: Python<'py>,
    k: PyReadonlyArray3<'py, f64>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    x: PyReadonlyArray2<'py, f64>,
) -> PyResult<(Bound<'py, PyArray3<f64>>, Bound<'py, PyArray2<f64>>)> {
    let cams = cameras(&k, &r, &c)?;
    let (xf, n) = rows(&x, "points", 3)?;
    map(socialcore::error::ensure_finite("points", &xf))?;
    let f = cams.len();
    map(socialcore::error::ensure_alloc("points", &[f, n, 2], 8))?;
    let (px, depth) = py.detach(|| {
        let per: Vec<(Vec<f64>, Vec<f64>)> = cams
            .par_iter()
            .map(|cam| {
                let mut p = Vec::with_capacity(2 * n);
                let mut d = Vec::with_capacity(n);
                for i in 0..n {
                    let (u, z) = cam.project(&vec3(&xf[3 * i..]));
                    p.extend([u.x, u.y]);
                    d.push(z);
                }
                (p, d)
            })
            .collect();
        let mut px = Vec::with_capacity(2 * n * f);
        let mut depth = Vec::with_capacity(n * f);
        for (p, d) in per {
            px.extend(p);
            depth.extend(d);
        }
        (px, depth)
    });
    let px =
        Array3::from_shape_vec((f, n, 2), px).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let depth =
        Array2::from_shape_vec((f, n), depth).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((px.into_pyarray(py), depth.into_pyarray(py)))
}

/// Unit world directions `(F,N,3)` of the rays through pixels `x (F,N,2)`.
#[pyfunction]
fn back_project<'py>(
    py: Python<'py>,
    k: PyReadonlyArray3<'py, f64>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    x: PyReadonlyArray3<'py, f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let cams = cameras(&k, &r, &c)?;
    let xv = x.as_array();
    let s = xv.shape();
    if s[0] != cams.len() || s[2] != 2 {
        return Err(PyValueError::new_err(format!(
            "x: expected an (F, N, 2) array with F = {} cameras, got shape ({}, {}, {})",
            cams.len(),
            s[0],
            s[1],
            s[2]
        )));
    }
    let n = s[1];
    let mut out = Array3::<f64>::zeros((cams.len(), n, 3));
    for (f, cam) in cams.iter().enumerate() {
        for i in 0..n {
            let d = cam.ray_direction(&nalgebra::Vector2::new(xv[[f, i, 0]], xv[[f, i, 1]]));
            for j in 0..3 {
                out[[f, i, j]] = d[j];
            }
        }
    }
    Ok(out.into_pyarray(py))
}

type TriOut<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<bool>>,
    Vec<Option<String>>,
);

/// Batched triangulation of `x (N,V,2)` seen by `V` cameras. Returns points `(N,3)` (NaN
/// where a point could not be triangulated), reprojection RMS after and before refinement
/// `(N,)` in pixels, the number of views `(N,)`, `converged (N,)` and, per point, `None` or
/// the reason it failed.
#[pyfunction]
#[pyo3(signature = (k, r, c, x, refine=true, max_iter=50))]
fn triangulate<'py>(
    py: Python<'py>,
    k: PyReadonlyArray3<'py, f64>,
    r: PyReadonlyArray3<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    x: PyReadonlyArray3<'py, f64>,
    refine: bool,
    max_iter: usize,
) -> PyResult<TriOut<'py>> {
    let cams = cameras(&k, &r, &c)?;
    let xv = x.as_array();
    let s = xv.shape();
    if s[1] != cams.len() || s[2] != 2 {
        return Err(PyValueError::new_err(format!(
            "x: expected an (N, V, 2) array with V = {} cameras, got shape ({}, {}, {})",
            cams.len(),
            s[0],
            s[1],
            s[2]
        )));
    }
    let n = s[0];
    let flat: Vec<f64> = xv.iter().copied().collect();
    if flat.iter().any(|v| v.is_infinite()) {
        return Err(PyValueError::new_err(
            "x: contains an infinite value (use NaN for a missing view)",
        ));
    }
    let opts = LmOptions {
        max_iterations: max_iter,
        ..LmOptions::default()
    };
    let results = detach(py, || g::triangulate_batch(&cams, &flat, n, refine, &opts))?;
    let mut pts = Array2::<f64>::from_elem((n, 3), f64::NAN);
    let mut rms = Array1::<f64>::from_elem(n, f64::NAN);
    let mut rms0 = Array1::<f64>::from_elem(n, f64::NAN);
    let mut views = Array1::<i64>::zeros(n);
    let mut conv = Array1::<bool>::from_elem(n, false);
    let mut why = Vec::with_capacity(n);
    for (i, res) in results.into_iter().enumerate() {
        match res {
            Ok(t) => {
                for j in 0..3 {
                    pts[[i, j]] = t.x[j];
                }
                rms[i] = t.rms;
                rms0[i] = t.rms_linear;
                views[i] = t.views as i64;
                conv[i] = t.converged;
                why.push(None);
            }
            Err(e) => {
                views[i] = (0..cams.len())
                    .filter(|&v| flat[(i * cams.len() + v) * 2].is_finite())
                    .count() as i64;
                why.push(Some(e.to_string()));
            }
        }
    }
    Ok((
        pts.into_pyarray(py),
        rms.into_pyarray(py),
        rms0.into_pyarray(py),
        views.into_pyarray(py),
        conv.into_pyarray(py),
        why,
    ))
}

/// The `(F,k)` orthonormal DCT trajectory basis at `times`.
#[pyfunction]
#[pyo3(signature = (times, k, t0=None, t1=None))]
fn dct_basis<'py>(
    py: Python<'py>,
    times: PyReadonlyArray1<'py, f64>,
    k: usize,
    t0: Option<f64>,
    t1: Option<f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let t = vec1(&times);
    let m = map(socialcore::basis::dct_basis(&t, k, t0, t1))?;
    let out = Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)]);
    Ok(out.into_pyarray(py))
}

/// Umeyama similarity `dst ≈ s R src + t`; returns `(s, R (3,3), t (3,))`.
#[pyfunction]
fn align_similarity<'py>(
    py: Python<'py>,
    src: PyReadonlyArray2<'py, f64>,
    dst: PyReadonlyArray2<'py, f64>,
) -> PyResult<(f64, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
    let (a, na) = rows(&src, "src", 3)?;
    let (b, nb) = rows(&dst, "dst", 3)?;
    let pa: Vec<_> = (0..na).map(|i| vec3(&a[3 * i..])).collect();
    let pb: Vec<_> = (0..nb).map(|i| vec3(&b[3 * i..])).collect();
    let s = map(g::align_similarity(&pa, &pb))?;
    let r = Array2::from_shape_fn((3, 3), |(i, j)| s.rotation[(i, j)]);
    let t = Array1::from_iter(s.translation.iter().copied());
    Ok((s.scale, r.into_pyarray(py), t.into_pyarray(py)))
}

/// Both ray–sphere intersections for `N` rays (Eq 4.8–4.9). Returns `s (N,2)` (larger root
/// first; NaN where the ray misses) and the miss distance `(N,)` (the radius at which the
/// line would touch the sphere; 0 where it hits).
#[pyfunction]
fn ray_sphere<'py>(
    py: Python<'py>,
    origins: PyReadonlyArray2<'py, f64>,
    directions: PyReadonlyArray2<'py, f64>,
    centres: PyReadonlyArray2<'py, f64>,
    radii: PyReadonlyArray1<'py, f64>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
    let (o, n) = rows(&origins, "origins", 3)?;
    let (d, nd) = rows(&directions, "directions", 3)?;
    let (c, nc) = rows(&centres, "centres", 3)?;
    let r = vec1(&radii);
    if nd != n || nc != n || r.len() != n {
        return Err(PyValueError::new_err(format!(
            "origins, directions, centres, radii: need equal lengths, got {n}, {nd}, {nc}, {}",
            r.len()
        )));
    }
    for (name, v) in [
        ("origins", &o),
        ("directions", &d),
        ("centres", &c),
        ("radii", &r),
    ] {
        map(socialcore::error::ensure_finite(name, v))?;
    }
    if let Some(i) = r.iter().position(|&x| x <= 0.0) {
        return Err(PyValueError::new_err(format!(
            "radii: must be positive, radii[{i}] = {}",
            r[i]
        )));
    }
    if let Some(i) = (0..n).find(|&i| vec3(&d[3 * i..]).norm_squared() == 0.0) {
        return Err(PyValueError::new_err(format!(
            "directions: row {i} is the zero vector"
        )));
    }
    let mut s = Array2::<f64>::from_elem((n, 2), f64::NAN);
    let mut miss = Array1::<f64>::zeros(n);
    for i in 0..n {
        let (oi, di, ci) = (vec3(&o[3 * i..]), vec3(&d[3 * i..]), vec3(&c[3 * i..]));
        match g::ray_sphere(&oi, &di, &ci, r[i]) {
            Some((a, b)) => {
                s[[i, 0]] = a;
                s[[i, 1]] = b;
            }
            None => miss[i] = g::line_point_distance(&oi, &di, &ci),
        }
    }
    Ok((s.into_pyarray(py), miss.into_pyarray(py)))
}

/// Perspective distance vectors of Eq 6.2 from each ray `(p_i, v_i)` to each point `x_i`:
/// `(N,3)`, with `inf` rows for points behind the eye.
#[pyfunction]
fn perspective_distance<'py>(
    py: Python<'py>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    x: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let (pf, n) = rows(&p, "p", 3)?;
    let (vf, nv) = rows(&v, "v", 3)?;
    let (xf, nx) = rows(&x, "x", 3)?;
    if nv != n || nx != n {
        return Err(PyValueError::new_err(format!(
            "p, v, x: need equal lengths, got {n}, {nv}, {nx}"
        )));
    }
    for (name, a) in [("p", &pf), ("v", &vf), ("x", &xf)] {
        map(socialcore::error::ensure_finite(name, a))?;
    }
    let mut out = Array2::<f64>::zeros((n, 3));
    for i in 0..n {
        let d = g::perspective_distance(
            &vec3(&pf[3 * i..]),
            &vec3(&vf[3 * i..]),
            &vec3(&xf[3 * i..]),
        );
        for j in 0..3 {
            out[[i, j]] = d.map_or(f64::INFINITY, |d| d[j]);
        }
    }
    Ok(out.into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(validate_cameras, m)?)?;
    m.add_function(wrap_pyfunction!(projection_matrices, m)?)?;
    m.add_function(wrap_pyfunction!(project, m)?)?;
    m.add_function(wrap_pyfunction!(back_project, m)?)?;
    m.add_function(wrap_pyfunction!(triangulate, m)?)?;
    m.add_function(wrap_pyfunction!(dct_basis, m)?)?;
    m.add_function(wrap_pyfunction!(align_similarity, m)?)?;
    m.add_function(wrap_pyfunction!(ray_sphere, m)?)?;
    m.add_function(wrap_pyfunction!(perspective_distance, m)?)?;
    Ok(())
}
