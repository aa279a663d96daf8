//! Orthonormal DCT trajectory basis evaluated at continuous, possibly non-uniform times.
//!
//! A trajectory coordinate is `x(t) = Θ(t) β` (thesis Eq 4.2 and 5.6). We use the DCT-II
//! family `φ_k(u) = c_k cos(π k u)` on the normalised time `u = (t − t0)/(t1 − t0) ∈ [0, 1]`.
//! With `F` uniform samples at the cell centres `u_n = (n + ½)/F` and `c_0 = √(1/F)`,
//! `c_k = √(2/F)`, the `F × K` matrix Θ has orthonormal columns, and `K = F` gives the full
//! orthonormal DCT. Any other times simply evaluate the same continuous functions, which is
//! what lets cameras with unsynchronised clocks share one trajectory (Sec 5.1).

use crate::error::{Error, Result};
use nalgebra::DMatrix;

/// The time span and normalisation that fix a DCT basis, so that it can be evaluated again
/// later at other times (for example to resample a reconstructed trajectory).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DctSpan {
    /// Time mapped to `u = 0`.
    pub t0: f64,
    /// Time mapped to `u = 1`.
    pub t1: f64,
    /// The `F` of the normalisation `c_k`: the columns are orthonormal on `n_norm`
    /// uniform samples of `[t0, t1]`.
    pub n_norm: f64,
}

impl DctSpan {
    /// The span implied by a set of sample times: if the times were uniform with spacing
    /// `dt`, the cells `[t − dt/2, t + dt/2]` tile `[t0, t1]` exactly. For non-uniform times
    /// `dt` is the mean spacing. A single time gets a unit-length span.
    pub fn from_times(times: &[f64]) -> Result<Self> {
        crate::error::ensure_finite("times", times)?;
        if times.is_empty() {
            return Err(Error::invalid("times", "is empty"));
        }
        let lo = times.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = times.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let n = times.len();
        let dt = if n > 1 && hi > lo {
            (hi - lo) / (n as f64 - 1.0)
        } else {
            1.0
        };
        Ok(DctSpan {
            t0: lo - 0.5 * dt,
            t1: hi + 0.5 * dt,
            n_norm: n as f64,
        })
    }

    /// Checks that the span is usable.
    pub fn validate(&self) -> Result<()> {
        if !(self.t0.is_finite() && self.t1.is_finite()) || self.t1 <= self.t0 {
            return Err(Error::invalid(
                "t0/t1",
                format!("need finite t0 < t1, got t0={}, t1={}", self.t0, self.t1),
            ));
        }
        if !(self.n_norm.is_finite() && self.n_norm > 0.0) {
            return Err(Error::invalid("n_norm", "must be positive"));
        }
        Ok(())
    }

    /// Value of basis function `k` at time `t`.
    #[inline]
    pub fn eval(&self, k: usize, t: f64) -> f64 {
        let u = (t - self.t0) / (self.t1 - self.t0);
        let c = if k == 0 {
            (1.0 / self.n_norm).sqrt()
        } else {
            (2.0 / self.n_norm).sqrt()
        };
        c * (std::f64::consts::PI * k as f64 * u).cos()
    }

    /// Fills `out[0..k]` with the first `k` basis values at time `t`, using the Chebyshev
    /// recurrence `cos((k+1)a) = 2 cos(a) cos(ka) − cos((k−1)a)` (no per-term `cos`).
    #[inline]
    pub fn eval_row(&self, t: f64, out: &mut [f64]) {
        let k = out.len();
        if k == 0 {
            return;
        }
        let u = (t - self.t0) / (self.t1 - self.t0);
        let a = std::f64::consts::PI * u;
        let c0 = (1.0 / self.n_norm).sqrt();
        let c = (2.0 / self.n_norm).sqrt();
        out[0] = c0;
        if k == 1 {
            return;
        }
        let ca = a.cos();
        let (mut prev, mut cur) = (1.0, ca);
        out[1] = c * cur;
        for o in out.iter_mut().skip(2) {
            let next = 2.0 * ca * cur - prev;
            prev = cur;
            cur = next;
            *o = c * cur;
        }
    }

    /// The `len(times) × k` basis matrix.
    pub fn matrix(&self, times: &[f64], k: usize) -> Result<DMatrix<f64>> {
        self.validate()?;
        crate::error::ensure_finite("times", times)?;
        if k == 0 {
            return Err(Error::invalid("k", "must be at least 1"));
        }
        crate::error::ensure_alloc("k", &[times.len(), k], std::mem::size_of::<f64>())?;
        let mut m = DMatrix::zeros(times.len(), k);
        let mut row = vec![0.0; k];
        for (i, &t) in times.iter().enumerate() {
            self.eval_row(t, &mut row);
            for (j, v) in row.iter().enumerate() {
                m[(i, j)] = *v;
            }
        }
        Ok(m)
    }
}

/// The `F × k` DCT basis at `times`, on the span `[t0, t1]` (defaults from
/// [`DctSpan::from_times`]) and normalised to be orthonormal on `F = len(times)` uniform
/// samples.
pub fn dct_basis(
    times: &[f64],
    k: usize,
    t0: Option<f64>,
    t1: Option<f64>,
) -> Result<DMatrix<f64>> {
    let mut span = DctSpan::from_times(times)?;
    if let Some(a) = t0 {
        span.t0 = a;
    }
    if let Some(b) = t1 {
        span.t1 = b;
    }
    span.matrix(times, k)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn orthonormal_on_uniform_samples() {
        let times: Vec<f64> = (0..50).map(|i| 0.1 * i as f64).collect();
        let b = dct_basis(&times, 50, None, None).unwrap();
        let g = b.transpose() * &b;
        assert_relative_eq!(g, DMatrix::identity(50, 50), epsilon = 1e-10);
    }

    #[test]
    fn recurrence_matches_direct_cos() {
        let span = DctSpan {
            t0: -1.0,
            t1: 3.0,
            n_norm: 17.0,
        };
        let mut row = vec![0.0; 40];
        for &t in &[-1.0, 0.123, 2.5, 3.0, 4.2] {
            span.eval_row(t, &mut row);
            for (k, v) in row.iter().enumerate() {
                assert_relative_eq!(*v, span.eval(k, t), epsilon = 1e-11);
            }
        }
    }

    #[test]
    fn first_column_is_constant_and_rejects_bad_input() {
        let b = dct_basis(&[0.0, 0.3, 2.0, 7.0], 2, None, None).unwrap();
        for i in 1..4 {
            assert_relative_eq!(b[(i, 0)], b[(0, 0)]);
        }
        assert!(dct_basis(&[], 2, None, None).is_err());
        assert!(dct_basis(&[0.0, f64::NAN], 2, None, None).is_err());
        assert!(dct_basis(&[0.0, 1.0], 0, None, None).is_err());
        assert!(dct_basis(&[0.0, 1.0], 2, Some(2.0), Some(1.0)).is_err());
    }
}
