//! Small dense kernels shared by cross validation and refinement: a row-oriented Cholesky
//! factorisation whose leading blocks are the factors of the leading blocks of the input
//! (so one factorisation serves every `K` of Eq 5.8), triangular solves on a leading block,
//! and the Gram products `Σ_i kron(θ_i θ_iᵀ, G_i)` that both the normal equations of Eq 5.7
//! and the Gauss–Newton matrix of Eq 5.9 reduce to.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};

/// Relative pivot floor: a Cholesky pivot `d_i` with `d_i ≤ PIVOT_TOL · A_ii` is treated as
/// zero (the leading block is numerically singular from column `i` on).
pub(crate) const PIVOT_TOL: f64 = 1e-13;

/// Factors the symmetric positive definite `n × n` row-major matrix `a` in place into its
/// lower Cholesky factor `L` (the strict upper triangle is left untouched and never read).
///
/// Row `i` of `L` depends only on rows `0..=i` of `a`, so the factorisation stops at the
/// first pivot that is not safely positive and returns its index `p`: `L[..p, ..p]` is then
/// the exact factor of `a[..p, ..p]`. Returns `n` when the whole matrix was factored.
pub(crate) fn cholesky_prefix(a: &mut [f64], n: usize) -> usize {
    debug_assert!(a.len() >= n * n);
    for i in 0..n {
        let (done, rest) = a.split_at_mut(i * n);
        let row_i = &mut rest[..n];
        for j in 0..i {
            let row_j = &done[j * n..j * n + j + 1];
            let s: f64 = row_i[..j].iter().zip(&row_j[..j]).map(|(x, y)| x * y).sum();
            row_i[j] = (row_i[j] - s) / row_j[j];
        }
        let aii = row_i[i];
        let d = aii - row_i[..i].iter().map(|x| x * x).sum::<f64>();
        if d.is_nan() || d <= PIVOT_TOL * aii.abs() || !d.is_finite() {
            return i;
        }
        row_i[i] = d.sqrt();
    }
    n
}

/// Solves `L y = b` in place on the leading `k` entries, `L` the row-major lower factor of
/// stride `n` returned by [`cholesky_prefix`].
pub(crate) fn forward_solve(l: &[f64], n: usize, k: usize, b: &mut [f64]) {
    for i in 0..k {
        let row = &l[i * n..i * n + i];
        let s: f64 = row.iter().zip(&b[..i]).map(|(x, y)| x * y).sum();
        b[i] = (b[i] - s) / l[i * n + i];
    }
}

/// Solves `Lᵀ x = y` in place on the leading `k` entries (see [`forward_solve`]).
pub(crate) fn backward_solve(l: &[f64], n: usize, k: usize, y: &mut [f64]) {
    for i in (0..k).rev() {
        let xi = y[i] / l[i * n + i];
        y[i] = xi;
        // Subtract column i of Lᵀ (= row i of L) from the entries above.
        let row = &l[i * n..i * n + i];
        for (yj, lij) in y[..i].iter_mut().zip(row) {
            *yj -= lij * xi;
        }
    }
}

/// The inverse of `L Lᵀ` (dense, row-major `k × k`) from its factor `L` of stride `n`.
pub(crate) fn cholesky_inverse(l: &[f64], n: usize, k: usize) -> Vec<f64> {
    let mut inv = vec![0.0; k * k];
    let mut e = vec![0.0; k];
    for c in 0..k {
        e.iter_mut().for_each(|v| *v = 0.0);
        e[c] = 1.0;
        forward_solve(l, n, k, &mut e);
        backward_solve(l, n, k, &mut e);
        for r in 0..k {
            inv[r * k + c] = e[r];
        }
    }
    // Symmetrise away round-off.
    for r in 0..k {
        for c in 0..r {
            let m = 0.5 * (inv[r * k + c] + inv[c * k + r]);
            inv[r * k + c] = m;
            inv[c * k + r] = m;
        }
    }
    inv
}

/// Index of the entry `(c, d)` of a symmetric 3×3 matrix stored as its upper triangle
/// `[00, 01, 02, 11, 12, 22]`.
#[inline]
pub(crate) const fn sym3(c: usize, d: usize) -> usize {
    let (a, b) = if c <= d { (c, d) } else { (d, c) };
    match (a, b) {
        (0, 0) => 0,
        (0, 1) => 1,
        (0, 2) => 2,
        (1, 1) => 3,
        (1, 2) => 4,
        _ => 5,
    }
}

/// Accumulates the Gram products of a Kronecker-structured least-squares system.
///
/// Each observation `i` contributes rows `kron(θ_i, a_r)` (`θ_i` the `kc` basis values at its
/// time, `a_r ∈ ℝ³`) with right-hand sides `b_r`. With `G_i = Σ_r a_r a_rᵀ` (packed as
/// [`sym3`]) and `h_i = Σ_r a_r b_r`, the normal matrix is `Σ_i kron(θ_i θ_iᵀ, G_i)` and the
/// right-hand side `Σ_i kron(θ_i, h_i)`, in the interleaved unknown order `3k + c`.
///
/// One matrix product `Θᵀ [G_0∘Θ … G_5∘Θ  H]` computes all of them; the result is the raw
/// `kc × (6 kc + 3)` product, which [`scatter_gram`] unpacks (sums of raw products unpack to
/// sums of systems, so cross-validation folds can be added and subtracted before).
pub(crate) fn gram_raw(theta: MatRef<'_, f64>, g: &[[f64; 6]], h: &[[f64; 3]]) -> Mat<f64> {
    let n = theta.nrows();
    let kc = theta.ncols();
    debug_assert!(g.len() == n && h.len() == n);
    let mut w = Mat::<f64>::zeros(n, 6 * kc + 3);
    for e in 0..6 {
        for k in 0..kc {
            let src = theta.col(k);
            let mut dst = w.col_mut(e * kc + k);
            for (i, gi) in g.iter().enumerate() {
                dst[i] = gi[e] * src[i];
            }
        }
    }
    for c in 0..3 {
        let mut dst = w.col_mut(6 * kc + c);
        for (i, hi) in h.iter().enumerate() {
            dst[i] = hi[c];
        }
    }
    let mut p = Mat::<f64>::zeros(kc, 6 * kc + 3);
    matmul(
        p.as_mut(),
        Accum::Replace,
        theta.transpose(),
        w.as_ref(),
        1.0,
        Par::Seq,
    );
    p
}

/// Unpacks the leading `k` basis functions of a raw Gram product (see [`gram_raw`]) into the
/// row-major `3k × 3k` normal matrix and the `3k` right-hand side.
pub(crate) fn scatter_gram(p: MatRef<'_, f64>, k: usize, m: &mut Vec<f64>, rhs: &mut Vec<f64>) {
    let kc = p.nrows();
    let n = 3 * k;
    m.clear();
    m.resize(n * n, 0.0);
    rhs.clear();
    rhs.resize(n, 0.0);
    for a in 0..k {
        for c in 0..3 {
            let row = 3 * a + c;
            for b in 0..k {
                for d in 0..3 {
                    m[row * n + 3 * b + d] = p[(a, sym3(c, d) * kc + b)];
                }
            }
            rhs[row] = p[(a, 6 * kc + c)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd(n: usize) -> Vec<f64> {
        // B Bᵀ + n I with a deterministic B.
        let b: Vec<f64> = (0..n * n)
            .map(|i| ((i as f64) * 0.731).sin() + 0.1)
            .collect();
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = (0..n).map(|k| b[i * n + k] * b[j * n + k]).sum::<f64>();
            }
            a[i * n + i] += n as f64;
        }
        a
    }

    #[test]
    fn prefix_factor_solves_every_leading_block() {
        let n = 9;
        let a = spd(n);
        let mut l = a.clone();
        assert_eq!(cholesky_prefix(&mut l, n), n);
        let rhs: Vec<f64> = (0..n).map(|i| 1.0 + i as f64).collect();
        for k in 1..=n {
            let mut x = rhs.clone();
            forward_solve(&l, n, k, &mut x);
            backward_solve(&l, n, k, &mut x);
            for i in 0..k {
                let r: f64 = (0..k).map(|j| a[i * n + j] * x[j]).sum::<f64>() - rhs[i];
                assert!(r.abs() < 1e-10, "k={k} i={i} r={r}");
            }
        }
        let inv = cholesky_inverse(&l, n, n);
        for i in 0..n {
            for j in 0..n {
                let v: f64 = (0..n).map(|k| a[i * n + k] * inv[k * n + j]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 1e-10);
            }
        }
    }

    #[test]
    fn prefix_stops_at_singular_column() {
        // Column 2 is the sum of columns 0 and 1: the leading 3×3 block has rank 2.
        let n = 4;
        let v = [
            [1.0, 0.0, 1.0, 0.3],
            [0.0, 1.0, 1.0, -0.2],
            [0.5, 0.2, 0.7, 1.0],
        ];
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = v.iter().map(|r| r[i] * r[j]).sum();
            }
        }
        let mut l = a.clone();
        assert_eq!(cholesky_prefix(&mut l, n), 2);
    }

    #[test]
    fn gram_matches_dense_normal_equations() {
        let n = 7;
        let kc = 3;
        let theta = Mat::from_fn(n, kc, |i, k| ((i * 3 + k) as f64 * 0.37).cos());
        let rows: Vec<[[f64; 4]; 2]> = (0..n)
            .map(|i| {
                let f = i as f64;
                [
                    [f.sin(), 0.3 * f, 1.0, f.cos()],
                    [0.2, -f.cos(), 0.5 * f, 1.0 - f],
                ]
            })
            .collect();
        let mut g = vec![[0.0; 6]; n];
        let mut h = vec![[0.0; 3]; n];
        for i in 0..n {
            for r in &rows[i] {
                for c in 0..3 {
                    for d in c..3 {
                        g[i][sym3(c, d)] += r[c] * r[d];
                    }
                    h[i][c] += r[c] * r[3];
                }
            }
        }
        let p = gram_raw(theta.as_ref(), &g, &h);
        let (mut m, mut rhs) = (Vec::new(), Vec::new());
        scatter_gram(p.as_ref(), kc, &mut m, &mut rhs);
        // Dense A and b.
        let nu = 3 * kc;
        let mut a = vec![0.0; 2 * n * nu];
        let mut b = vec![0.0; 2 * n];
        for i in 0..n {
            for (r, row) in rows[i].iter().enumerate() {
                for k in 0..kc {
                    for c in 0..3 {
                        a[(2 * i + r) * nu + 3 * k + c] = theta[(i, k)] * row[c];
                    }
                }
                b[2 * i + r] = row[3];
            }
        }
        for u in 0..nu {
            for v in 0..nu {
                let want: f64 = (0..2 * n).map(|r| a[r * nu + u] * a[r * nu + v]).sum();
                assert!((m[u * nu + v] - want).abs() < 1e-12);
            }
            let want: f64 = (0..2 * n).map(|r| a[r * nu + u] * b[r]).sum();
            assert!((rhs[u] - want).abs() < 1e-12);
        }
    }
}
