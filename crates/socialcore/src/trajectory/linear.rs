//! The linear system of Eq 5.1–5.7 for one point, its least-squares solution (faer QR),
//! rank and condition (singular values of the `R` factor), and the Theorem 2 diagnosis of a
//! rank-deficient system.

use super::dense::sym3;
use super::Frames;
use crate::error::{Error, Result};
use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::{factor, solve as qr_solve};
use faer::linalg::svd;
use faer::{Mat, Par};
use nalgebra::{Vector2, Vector3};

/// One point's observations and its rows of `Q X = q` (Eq 5.2), built on normalised
/// measurements.
#[derive(Debug, Clone)]
pub(crate) struct PointSystem {
    /// Observed frame indices, ascending.
    pub idx: Vec<usize>,
    /// Observed pixels (original coordinates).
    pub px: Vec<Vector2<f64>>,
    /// Rows `[a | b]` with `a · X_i = b`, two per observation.
    pub rows: Vec<[[f64; 4]; 2]>,
    /// `Σ_r a_r a_rᵀ` per observation, packed as [`sym3`].
    pub g: Vec<[f64; 6]>,
    /// `Σ_r a_r b_r` per observation.
    pub h: Vec<[f64; 3]>,
}

impl PointSystem {
    /// Builds the rows. The measurements are first normalised, `x' = s (x − m)` with `m`
    /// their mean and `s` such that their mean distance from `m` is √2 (Sec 5.3, after
    /// Hartley), and each camera becomes `P' = T P`. Rows `(·)_{1:2}` of `[x']_× P'` are then
    /// `s (y P³ − P²)` and `s (P¹ − x P³)`: the translation cancels and the normalisation
    /// rescales the whole system by `s`, which keeps its entries O(1) whatever the pixel
    /// units, without changing the least-squares solution.
    pub fn new(frames: &Frames, idx: Vec<usize>, px: Vec<Vector2<f64>>) -> Self {
        let n = px.len() as f64;
        let mean = px.iter().sum::<Vector2<f64>>() / n;
        let spread = px.iter().map(|p| (p - mean).norm()).sum::<f64>() / n;
        let s = if spread > 0.0 && spread.is_finite() {
            std::f64::consts::SQRT_2 / spread
        } else {
            1.0
        };
        let mut rows = Vec::with_capacity(idx.len());
        let mut g = Vec::with_capacity(idx.len());
        let mut h = Vec::with_capacity(idx.len());
        for (&i, p) in idx.iter().zip(&px) {
            let kr = &frames.kr[i];
            let kt = &frames.kt[i];
            // P' = T P, row by row.
            let p1 = [
                s * (kr[(0, 0)] - mean.x * kr[(2, 0)]),
                s * (kr[(0, 1)] - mean.x * kr[(2, 1)]),
                s * (kr[(0, 2)] - mean.x * kr[(2, 2)]),
                s * (kt.x - mean.x * kt.z),
            ];
            let p2 = [
                s * (kr[(1, 0)] - mean.y * kr[(2, 0)]),
                s * (kr[(1, 1)] - mean.y * kr[(2, 1)]),
                s * (kr[(1, 2)] - mean.y * kr[(2, 2)]),
                s * (kt.y - mean.y * kt.z),
            ];
            let p3 = [kr[(2, 0)], kr[(2, 1)], kr[(2, 2)], kt.z];
            let xn = s * (p.x - mean.x);
            let yn = s * (p.y - mean.y);
            // [x']_× rows 1 and 2: (0, −1, y') and (1, 0, −x').
            let mut r = [[0.0; 4]; 2];
            for c in 0..4 {
                r[0][c] = yn * p3[c] - p2[c];
                r[1][c] = p1[c] - xn * p3[c];
            }
            // Inhomogeneous form: a·X = −(last column).
            r[0][3] = -r[0][3];
            r[1][3] = -r[1][3];
            let mut gi = [0.0; 6];
            let mut hi = [0.0; 3];
            for row in &r {
                for c in 0..3 {
                    for d in c..3 {
                        gi[sym3(c, d)] += row[c] * row[d];
                    }
                    hi[c] += row[c] * row[3];
                }
            }
            rows.push(r);
            g.push(gi);
            h.push(hi);
        }
        PointSystem {
            idx,
            px,
            rows,
            g,
            h,
        }
    }

    pub fn len(&self) -> usize {
        self.idx.len()
    }
}

/// The linear least-squares solution at one `K`.
#[derive(Debug, Clone)]
pub(crate) struct LinearSolution {
    /// Coefficients in the order `3k + c` (empty when rank deficient).
    pub beta: Vec<f64>,
    pub rank: usize,
    pub cond: f64,
}

/// Solves `QΘ β = q` (Eq 5.7) by Householder QR; `theta` holds the `n × K` basis values at
/// the observed frames. The rank counts singular values of `R` (those of `QΘ`) above
/// `σ_max · max(2n, 3K) · ε`, as numpy's `matrix_rank` does.
pub(crate) fn solve(theta: &Mat<f64>, sys: &PointSystem) -> Result<LinearSolution> {
    let n = sys.len();
    let k = theta.ncols();
    let m = 2 * n;
    let u = 3 * k;
    if m < u {
        return Err(Error::degenerate(format!(
            "too few observations for K = {k}: {n} observed frames give {m} equations for {u} unknowns"
        )));
    }
    let mut a = Mat::<f64>::zeros(m, u);
    let mut b = Mat::<f64>::zeros(m, 1);
    for i in 0..n {
        for (r, row) in sys.rows[i].iter().enumerate() {
            for kk in 0..k {
                let w = theta[(i, kk)];
                for c in 0..3 {
                    a[(2 * i + r, 3 * kk + c)] = w * row[c];
                }
            }
            b[(2 * i + r, 0)] = row[3];
        }
    }
    let par = Par::Seq;
    let bs = factor::recommended_block_size::<f64>(m, u);
    let mut q_coeff = Mat::<f64>::zeros(bs, u);
    {
        let req = factor::qr_in_place_scratch::<f64>(m, u, bs, par, Default::default());
        let mut buf = MemBuffer::new(req);
        factor::qr_in_place(
            a.as_mut(),
            q_coeff.as_mut(),
            par,
            MemStack::new(&mut buf),
            Default::default(),
        );
    }
    // R is the upper triangle of the packed factor.
    let r = Mat::<f64>::from_fn(u, u, |i, j| if i <= j { a[(i, j)] } else { 0.0 });
    let mut s = Diag::<f64>::zeros(u);
    {
        let req = svd::svd_scratch::<f64>(
            u,
            u,
            svd::ComputeSvdVectors::No,
            svd::ComputeSvdVectors::No,
            par,
            Default::default(),
        );
        let mut buf = MemBuffer::new(req);
        svd::svd(
            r.as_ref(),
            s.as_mut(),
            None,
            None,
            par,
            MemStack::new(&mut buf),
            Default::default(),
        )
        .map_err(|_| Error::degenerate("the SVD of QΘ did not converge"))?;
    }
    let sv: Vec<f64> = s.column_vector().iter().copied().collect();
    let smax = sv.iter().copied().fold(0.0, f64::max);
    let smin = sv.iter().copied().fold(f64::INFINITY, f64::min);
    let tol = smax * (m.max(u) as f64) * f64::EPSILON;
    let rank = sv.iter().filter(|&&v| v > tol).count();
    let cond = if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    };
    if rank < u || !smax.is_finite() {
        return Ok(LinearSolution {
            beta: Vec::new(),
            rank,
            cond,
        });
    }
    // Householder vectors below the diagonal with an implicit unit diagonal.
    for j in 0..u {
        a[(j, j)] = 1.0;
        for i in 0..j {
            a[(i, j)] = 0.0;
        }
    }
    {
        let req = qr_solve::solve_lstsq_in_place_scratch::<f64>(m, u, bs, 1, par);
        let mut buf = MemBuffer::new(req);
        qr_solve::solve_lstsq_in_place(
            a.as_ref(),
            q_coeff.as_ref(),
            r.as_ref(),
            b.as_mut(),
            par,
            MemStack::new(&mut buf),
        );
    }
    let beta: Vec<f64> = (0..u).map(|i| b[(i, 0)]).collect();
    if beta.iter().any(|v| !v.is_finite()) {
        return Ok(LinearSolution {
            beta: Vec::new(),
            rank: rank.min(u - 1),
            cond,
        });
    }
    Ok(LinearSolution { beta, rank, cond })
}

/// Relative tolerances of the Theorem 2 diagnosis.
const PARALLEL_RAY_TOL: f64 = 1e-9;
const IN_SPAN_TOL: f64 = 1e-8;

/// Explains why `rank(QΘ) < 3K` by the case of Theorem 2 (Sec 5.2.2.1, App B.2) the data
/// resemble.
pub(crate) fn diagnose(
    frames: &Frames,
    sys: &PointSystem,
    theta: &Mat<f64>,
    k: usize,
    rank: usize,
) -> Error {
    let n = sys.len();
    let head = format!("rank(QΘ) = {rank} < 3K = {} with {n} observations", 3 * k);
    // Distinct observation times: Θ itself is rank deficient when there are fewer than K.
    let mut t: Vec<f64> = sys.idx.iter().map(|&i| frames.times[i]).collect();
    t.sort_by(f64::total_cmp);
    let span = (frames.span.t1 - frames.span.t0).abs();
    let distinct = 1 + t.windows(2).filter(|w| w[1] - w[0] > 1e-12 * span).count();
    if distinct < k {
        return Error::degenerate(format!(
            "{head}: too few observations for K: they fall at only {distinct} distinct times, \
             fewer than the K = {k} basis functions"
        ));
    }
    // World directions of the rays. All parallel ⇔ X − C constant: the camera is still
    // relative to the point (Theorem 2.ii with c = 1, rank(QΘ) = 2K).
    let dirs: Vec<Vector3<f64>> = sys
        .idx
        .iter()
        .zip(&sys.px)
        .map(|(&i, p)| frames.cameras[i].ray_direction(p))
        .collect();
    let max_angle = dirs
        .iter()
        .map(|d| d.cross(&dirs[0]).norm().atan2(d.dot(&dirs[0])))
        .fold(0.0, f64::max);
    if max_angle <= PARALLEL_RAY_TOL {
        return Error::degenerate(format!(
            "{head}: the camera is still relative to the point — every ray has the same \
             direction, so X − C is constant (Theorem 2.ii with c = 1)"
        ));
    }
    // Is the camera trajectory itself spanned by the K basis functions at the observed
    // times? Then X and C both lie in col(Θ) (Theorem 2.i).
    let centres: Vec<Vector3<f64>> = sys.idx.iter().map(|&i| frames.cameras[i].c).collect();
    let rel = span_residual(theta, &centres);
    if rel <= IN_SPAN_TOL {
        return Error::degenerate(format!(
            "{head}: the camera moves like the point — the camera trajectory lies in the span \
             of the K = {k} basis functions, as the point's does (Theorem 2.i); its depth along \
             the rays is ambiguous"
        ));
    }
    Error::degenerate(format!(
        "{head}: the camera moves like the point — the point trajectory is a scaled, shifted \
         copy of the camera trajectory, X = cC + 1⊗d (Theorem 2.ii)"
    ))
}

/// Relative residual `‖C − Π_Θ C‖ / ‖C − mean C‖` of projecting a 3D trajectory onto
/// `col(Θ)` coordinate-wise (0 when the trajectory does not move).
fn span_residual(theta: &Mat<f64>, x: &[Vector3<f64>]) -> f64 {
    let n = theta.nrows();
    let k = theta.ncols();
    if n <= k {
        return 0.0;
    }
    let mut rhs = Mat::<f64>::from_fn(n, 3, |i, c| x[i][c]);
    let mean = x.iter().sum::<Vector3<f64>>() / n as f64;
    let total: f64 = x
        .iter()
        .map(|p| (p - mean).norm_squared())
        .sum::<f64>()
        .sqrt();
    if total == 0.0 {
        return 0.0;
    }
    let qr = theta.qr();
    let q = qr.compute_thin_Q();
    let proj = q.as_ref() * (q.transpose() * rhs.as_ref());
    rhs -= proj;
    let res: f64 = (0..n)
        .flat_map(|i| (0..3).map(move |c| (i, c)))
        .map(|(i, c)| rhs[(i, c)] * rhs[(i, c)])
        .sum::<f64>()
        .sqrt();
    res / total
}
