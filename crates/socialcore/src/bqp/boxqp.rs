//! The node relaxation: `min φ(x) = xᵀ(W + diag(s))x + (h − s)ᵀx` over the box
//! `0 ≤ x ≤ 1` with some coordinates fixed, for the node's shift `s` (`W_FF + diag(s_F)`
//! positive definite on the free set `F`). Projected Newton (Bertsekas 1982) on the free
//! coordinates, warm-started; the returned bound is the Frank–Wolfe bound, valid at any
//! feasible point because `φ` is convex.

use super::{Clock, Model, FREE};

pub(crate) struct Relaxation {
    /// Minimiser estimate over all `n` coordinates (fixed ones at their values).
    pub x: Vec<f64>,
    /// `∇φ(x)` over all `n` coordinates.
    pub grad: Vec<f64>,
    /// Valid lower bound on `φ` over the node's box (hence on `f` over its binaries).
    pub bound: f64,
    /// The Frank–Wolfe gap closed to the tolerance.
    pub converged: bool,
}

/// Reusable buffers.
pub(crate) struct BoxQp {
    free: Vec<usize>,
    a: Vec<f64>,
    p: Vec<f64>,
    y: Vec<f64>,
    g: Vec<f64>,
    d: Vec<f64>,
    trial: Vec<f64>,
    inactive: Vec<usize>,
    chol: Vec<f64>,
    rhs: Vec<f64>,
}

/// Newton iterations per node (each one a Cholesky factorisation).
const MAX_ITER: usize = 60;

impl BoxQp {
    pub fn new(n: usize) -> Self {
        BoxQp {
            free: Vec::with_capacity(n),
            a: vec![0.0; n * n],
            p: vec![0.0; n],
            y: vec![0.0; n],
            g: vec![0.0; n],
            d: vec![0.0; n],
            trial: vec![0.0; n],
            inactive: Vec::with_capacity(n),
            chol: vec![0.0; n * n],
            rhs: vec![0.0; n],
        }
    }

    /// Solves the relaxation of the node `fix` starting from `x0`; stops early once the
    /// bound reaches `cut` (the node will be pruned anyway) or the clock runs out (the
    /// bound is valid at whatever point it stopped).
    pub fn solve(
        &mut self,
        model: &Model,
        s: &[f64],
        fix: &[i8],
        x0: &[f64],
        cut: f64,
        clock: &Clock,
    ) -> Relaxation {
        let n = model.n;
        self.free.clear();
        self.free.extend((0..n).filter(|&i| fix[i] == FREE));
        let m = self.free.len();
        // Constant and linear term of the reduced problem.
        let mut constant = model.k0;
        // The shift of a fixed variable adds `s_i (x_i² − x_i) = 0`: only W and h matter.
        for i in 0..n {
            if fix[i] == 1 {
                constant += model.h[i];
                for j in 0..n {
                    if fix[j] == 1 {
                        constant += model.w[i * n + j];
                    }
                }
            }
        }
        for (a, &i) in self.free.iter().enumerate() {
            let row = &model.w[i * n..(i + 1) * n];
            let mut p = model.h[i] - s[i];
            for j in 0..n {
                if fix[j] == 1 {
                    p += 2.0 * row[j];
                }
            }
            self.p[a] = p;
            for (b, &j) in self.free.iter().enumerate() {
                self.a[a * m + b] = row[j];
            }
            self.a[a * m + a] = s[i];
            self.y[a] = x0[i].clamp(0.0, 1.0);
        }

        let mut best_bound = f64::NEG_INFINITY;
        let mut converged = false;
        let mut phi = self.value(m, constant);
        for _ in 0..MAX_ITER {
            self.gradient(m);
            let mut fw = 0.0;
            for k in 0..m {
                let (gk, yk) = (self.g[k], self.y[k]);
                fw += (-gk * yk).min(gk * (1.0 - yk));
            }
            let bound = phi + fw;
            if bound > best_bound {
                best_bound = bound;
            }
            let tol = 1e-11 * (1.0 + phi.abs());
            if -fw <= tol {
                converged = true;
                break;
            }
            if best_bound >= cut || clock.out() {
                break;
            }
            // Inactive set: coordinates that may move.
            self.inactive.clear();
            for k in 0..m {
                let at_lo = self.y[k] <= 0.0 && self.g[k] > 0.0;
                let at_hi = self.y[k] >= 1.0 && self.g[k] < 0.0;
                if !(at_lo || at_hi) {
                    self.inactive.push(k);
                }
            }
            let r = self.inactive.len();
            for a in 0..r {
                let ia = self.inactive[a];
                for b in 0..=a {
                    let ib = self.inactive[b];
                    self.chol[a * r + b] = 2.0 * self.a[ia * m + ib];
                }
                self.rhs[a] = -self.g[ia];
            }
            self.d[..m].fill(0.0);
            let newton_ok = cholesky_solve(&mut self.chol, r, &mut self.rhs, Some(clock));
            if newton_ok {
                for a in 0..r {
                    self.d[self.inactive[a]] = self.rhs[a];
                }
            } else if clock.out() {
                // The factorisation gave up on the clock: stop with the bound we have.
                break;
            } else {
                for &k in &self.inactive {
                    self.d[k] = -self.g[k];
                }
            }
            // Projected Armijo search along the direction.
            let mut alpha = 1.0;
            let mut moved = false;
            for _ in 0..40 {
                let mut decrease = 0.0;
                for k in 0..m {
                    let t = (self.y[k] + alpha * self.d[k]).clamp(0.0, 1.0);
                    self.trial[k] = t;
                    decrease += self.g[k] * (t - self.y[k]);
                }
                let new_phi = quad_value(&self.a, &self.p, &self.trial[..m], m, constant);
                if new_phi <= phi + 1e-4 * decrease && decrease < 0.0 {
                    self.y[..m].copy_from_slice(&self.trial[..m]);
                    phi = new_phi;
                    moved = true;
                    break;
                }
                alpha *= 0.5;
            }
            if !moved {
                break;
            }
        }
        if !converged {
            // Bound at the final point too.
            self.gradient(m);
            let mut fw = 0.0;
            for k in 0..m {
                let (gk, yk) = (self.g[k], self.y[k]);
                fw += (-gk * yk).min(gk * (1.0 - yk));
            }
            best_bound = best_bound.max(phi + fw);
        }

        // Back to full coordinates.
        let mut x = vec![0.0; n];
        for i in 0..n {
            if fix[i] != FREE {
                x[i] = f64::from(fix[i]);
            }
        }
        for (a, &i) in self.free.iter().enumerate() {
            x[i] = self.y[a];
        }
        // ∇φ_i = h_i − s_i + 2 (W x)_i + 2 s_i x_i.
        let mut grad = model.h.clone();
        for i in 0..n {
            let row = &model.w[i * n..(i + 1) * n];
            let mut acc = 0.0;
            for j in 0..n {
                acc += row[j] * x[j];
            }
            grad[i] += 2.0 * acc + s[i] * (2.0 * x[i] - 1.0);
        }
        Relaxation {
            x,
            grad,
            bound: best_bound,
            converged,
        }
    }

    fn value(&self, m: usize, constant: f64) -> f64 {
        quad_value(&self.a, &self.p, &self.y[..m], m, constant)
    }

    fn gradient(&mut self, m: usize) {
        for k in 0..m {
            let row = &self.a[k * m..(k + 1) * m];
            let mut s = 0.0;
            for (r, y) in row.iter().zip(&self.y[..m]) {
                s += r * y;
            }
            self.g[k] = 2.0 * s + self.p[k];
        }
    }
}

fn quad_value(a: &[f64], p: &[f64], y: &[f64], m: usize, constant: f64) -> f64 {
    let mut v = constant;
    for k in 0..m {
        let row = &a[k * m..(k + 1) * m];
        let mut s = 0.0;
        for (r, yj) in row.iter().zip(y) {
            s += r * yj;
        }
        v += y[k] * (s + p[k]);
    }
    v
}

/// In-place Cholesky of the lower triangle of the row-major `r × r` matrix in `l`, then
/// solves `L Lᵀ z = rhs` into `rhs`. Returns false if a pivot is not positive.
/// Gives up (false) if `clock` runs out during the factorisation.
pub(crate) fn cholesky_solve(
    l: &mut [f64],
    r: usize,
    rhs: &mut [f64],
    clock: Option<&Clock>,
) -> bool {
    if !cholesky_in_place(l, r, clock) {
        return false;
    }
    for i in 0..r {
        let mut s = rhs[i];
        for k in 0..i {
            s -= l[i * r + k] * rhs[k];
        }
        rhs[i] = s / l[i * r + i];
    }
    for i in (0..r).rev() {
        let mut s = rhs[i];
        for k in (i + 1)..r {
            s -= l[k * r + i] * rhs[k];
        }
        rhs[i] = s / l[i * r + i];
    }
    true
}

/// Lower Cholesky factor in place (row-major, lower triangle read and written). False if a
/// pivot is not positive or `clock` runs out (checked every 32 rows).
pub(crate) fn cholesky_in_place(l: &mut [f64], r: usize, clock: Option<&Clock>) -> bool {
    super::with_avx2(|| cholesky_generic(l, r, clock))
}

#[inline(always)]
fn cholesky_generic(l: &mut [f64], r: usize, clock: Option<&Clock>) -> bool {
    for i in 0..r {
        if i % 32 == 31 && clock.is_some_and(Clock::out) {
            return false;
        }
        let (done, rest) = l.split_at_mut(i * r);
        let row_i = &mut rest[..r];
        for j in 0..=i {
            if i == j {
                let s = row_i[i] - super::dot4(&row_i[..i], &row_i[..i]);
                if s <= 0.0 || !s.is_finite() {
                    return false;
                }
                row_i[i] = s.sqrt();
            } else {
                let row_j = &done[j * r..j * r + j + 1];
                let s = row_i[j] - super::dot4(&row_i[..j], &row_j[..j]);
                row_i[j] = s / row_j[j];
            }
        }
    }
    true
}
