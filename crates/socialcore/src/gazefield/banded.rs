//! A symmetric positive definite banded matrix with an in-place Cholesky solve: the normal
//! equations of the time-windowed M-step (Eq 7.14) couple a frame only with its neighbours
//! through the temporal filter, so the system is block tri- or pentadiagonal.

/// Lower band of a symmetric `n × n` matrix with half bandwidth `b`:
/// `data[i * (b + 1) + (i − j)] = A[i][j]` for `i − b ≤ j ≤ i`.
#[derive(Debug, Clone)]
pub struct Banded {
    n: usize,
    b: usize,
    data: Vec<f64>,
}

impl Banded {
    /// A zero matrix.
    pub fn zeros(n: usize, b: usize) -> Self {
        Self {
            n,
            b,
            data: vec![0.0; n * (b + 1)],
        }
    }

    /// Size `n`.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Sets every entry to zero.
    pub fn clear(&mut self) {
        self.data.iter_mut().for_each(|x| *x = 0.0);
    }

    /// Adds `val` to `A[i][j]` (and implicitly `A[j][i]`); needs `|i − j| ≤ b`.
    #[inline]
    pub fn add(&mut self, i: usize, j: usize, val: f64) {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        debug_assert!(i - j <= self.b);
        self.data[i * (self.b + 1) + (i - j)] += val;
    }

    /// `A[i][i]`.
    #[inline]
    pub fn diag(&self, i: usize) -> f64 {
        self.data[i * (self.b + 1)]
    }

    /// Adds `val` to `A[i][i]`.
    #[inline]
    pub fn add_diag(&mut self, i: usize, val: f64) {
        self.data[i * (self.b + 1)] += val;
    }

    #[inline]
    fn at(&self, i: usize, j: usize) -> f64 {
        self.data[i * (self.b + 1) + (i - j)]
    }

    /// Solves `A x = rhs` in place (`rhs` becomes `x`), destroying `A` (it holds `L` after).
    /// Returns `false` when `A` is not numerically positive definite.
    #[allow(clippy::needless_range_loop)]
    pub fn cholesky_solve(&mut self, rhs: &mut [f64]) -> bool {
        let (n, b) = (self.n, self.b);
        let w = b + 1;
        for i in 0..n {
            let j0 = i.saturating_sub(b);
            for j in j0..=i {
                let m0 = j0.max(j.saturating_sub(b));
                let mut s = self.at(i, j);
                for m in m0..j {
                    s -= self.at(i, m) * self.at(j, m);
                }
                if i == j {
                    if s <= 0.0 || !s.is_finite() {
                        return false;
                    }
                    self.data[i * w] = s.sqrt();
                } else {
                    self.data[i * w + (i - j)] = s / self.at(j, j);
                }
            }
        }
        // L y = rhs.
        for i in 0..n {
            let mut s = rhs[i];
            for m in i.saturating_sub(b)..i {
                s -= self.at(i, m) * rhs[m];
            }
            rhs[i] = s / self.at(i, i);
        }
        // Lᵀ x = y.
        for i in (0..n).rev() {
            let mut s = rhs[i];
            for m in (i + 1)..n.min(i + b + 1) {
                s -= self.at(m, i) * rhs[m];
            }
            rhs[i] = s / self.at(i, i);
        }
        true
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    #[test]
    fn matches_dense_solve() {
        let (n, b) = (17, 4);
        let mut dense = DMatrix::<f64>::zeros(n, n);
        let mut band = Banded::zeros(n, b);
        for i in 0..n {
            for j in i.saturating_sub(b)..=i {
                let v = if i == j {
                    10.0 + i as f64
                } else {
                    ((i * 7 + j * 3) % 5) as f64 * 0.3 - 0.6
                };
                dense[(i, j)] = v;
                dense[(j, i)] = v;
                band.add(i, j, v);
            }
        }
        let rhs: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut x = rhs.clone();
        assert!(band.cholesky_solve(&mut x));
        let r = &dense * DVector::from_vec(x) - DVector::from_vec(rhs);
        assert!(r.norm() < 1e-12);
        let mut neg = Banded::zeros(2, 1);
        neg.add(0, 0, -1.0);
        assert!(!neg.cholesky_solve(&mut [1.0, 1.0]));
    }
}
