//! The semidefinite bound and the QCR diagonal shift derived from it.
//!
//! With `z = 2b − 1 ∈ {±1}ⁿ` and a homogenising `z₀ = 1`, `f(b) = κ + zᵀCz` for the
//! `(n+1) × (n+1)` matrix with zero diagonal
//! `C_ij = W_ij / 4` (`i, j ≥ 1`), `C_0i = C_i0 = (h_i + Σ_j W_ij) / 4`,
//! and `κ = Σ h_i / 2 + Σ_{i≠j} W_ij / 4`. The basic semidefinite relaxation is
//! `min ⟨C, Y⟩, diag Y = 1, Y ⪰ 0`, with dual `max Σ y_i` s.t. `C − Diag(y) ⪰ 0`.
//!
//! We solve the primal in low-rank form `Y = VVᵀ` (unit rows `v_i ∈ ℝᵏ`, `k ≈ √(2n)`) by
//! block-coordinate descent (`v_i ← −g_i / |g_i|`, `g_i = Σ_j C_ij v_j`: the "mixing
//! method" of Wang, Chang and Kolter 2018). At a stationary point `CV = Diag(y)V` with
//! `y_i = −|g_i|`, which gives the dual estimate. Back in the 0/1 variables the dual matrix
//! `C − Diag(y)` is `Mᵀ(W + diag(s))M / 4` plus a rank-one term, with `s_i = 4|g_i|`: this
//! `s` is the quadratic convex reformulation (QCR, Billionnet and Elloumi 2007) shift. Since
//! the low-rank solve is inexact, the caller repairs `W + diag(s)` to positive definiteness
//! with its smallest eigenvalue; the box relaxation of the shifted problem is then a valid
//! bound at least as strong as the dual objective at the repaired `y`.

use super::{Clock, Model, FREE};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Low-rank factor `V` of the SDP of a node (rows `0..n` the variables, row `n` the
/// homogenising `z₀`), kept between solves as a warm start; fixed variables' rows are
/// ignored and folded into the linear row.
pub(crate) struct Mixing {
    pub(crate) k: usize,
    pub(crate) v: Vec<f64>,
    g: Vec<f64>,
    /// `C_0i` of the current node (zero for fixed `i`).
    lin: Vec<f64>,
    /// `|g_i|` at the last sweep.
    gnorm: Vec<f64>,
}

impl Mixing {
    /// Random unit rows (fixed seed), rank `⌈√(2(n+1))⌉ + 1`.
    pub fn new(n: usize) -> Self {
        let m = n + 1;
        let k = ((2.0 * m as f64).sqrt().ceil() as usize + 1).min(m).max(2);
        let mut rng = ChaCha8Rng::seed_from_u64(0x05ee_db0b);
        let mut v = vec![0.0; m * k];
        for r in v.chunks_mut(k) {
            let mut norm = 0.0f64;
            for x in r.iter_mut() {
                *x = rng.random_range(-1.0..1.0);
                norm += *x * *x;
            }
            let norm = norm.sqrt().max(1e-300);
            for x in r.iter_mut() {
                *x /= norm;
            }
        }
        Mixing {
            k,
            v,
            g: vec![0.0; k],
            lin: vec![0.0; n],
            gnorm: vec![0.0; m],
        }
    }

    /// `g = Σ_j C_ij v_j` for the free row `i` (or the homogenising row `i = n`).
    #[inline(always)]
    fn row_gradient(&mut self, model: &Model, fix: &[i8], i: usize) -> f64 {
        let (n, k) = (model.n, self.k);
        self.g.fill(0.0);
        if i == n {
            for j in 0..n {
                let c = self.lin[j];
                if c != 0.0 {
                    let vj = &self.v[j * k..(j + 1) * k];
                    for (ga, va) in self.g.iter_mut().zip(vj) {
                        *ga += c * va;
                    }
                }
            }
        } else {
            let c = self.lin[i];
            let v0 = &self.v[n * k..(n + 1) * k];
            for (ga, va) in self.g.iter_mut().zip(v0) {
                *ga += c * va;
            }
            for &(j, w) in &model.adj[i] {
                if fix[j] == FREE {
                    let c = 0.25 * w;
                    let vj = &self.v[j * k..(j + 1) * k];
                    for (ga, va) in self.g.iter_mut().zip(vj) {
                        *ga += c * va;
                    }
                }
            }
        }
        self.g.iter().map(|a| a * a).sum::<f64>().sqrt()
    }

    /// Mixing-method sweeps on the SDP of the node `fix` (fixed variables substituted),
    /// from the current factor, at most `max_sweeps` and until the objective changes by
    /// less than `tol` relatively over a sweep, or the clock runs out. Writes the QCR shift
    /// `s_i = 4|g_i|` of the free variables into `s` (before positive-definite repair) and
    /// returns the sweeps done.
    pub fn solve(
        &mut self,
        model: &Model,
        fix: &[i8],
        max_sweeps: usize,
        tol: f64,
        clock: &Clock,
        s: &mut [f64],
    ) -> usize {
        // The sweeps are k-wide axpys: vectorised by `with_avx2`.
        super::with_avx2(|| {
            let (n, k) = (model.n, self.k);
            for i in 0..n {
                self.lin[i] = if fix[i] == FREE {
                    let mut acc = model.h[i];
                    for &(j, w) in &model.adj[i] {
                        match fix[j] {
                            FREE => acc += w,
                            1 => acc += 2.0 * w,
                            _ => {}
                        }
                    }
                    0.25 * acc
                } else {
                    0.0
                };
            }
            let mut prev = f64::INFINITY;
            let mut sweeps = 0;
            while sweeps < max_sweeps {
                sweeps += 1;
                let mut obj = 0.0;
                for i in 0..=n {
                    if i < n && fix[i] != FREE {
                        continue;
                    }
                    let norm = self.row_gradient(model, fix, i);
                    self.gnorm[i] = norm;
                    if norm > 0.0 {
                        let vi = &mut self.v[i * k..(i + 1) * k];
                        for (va, ga) in vi.iter_mut().zip(&self.g) {
                            *va = -ga / norm;
                        }
                    }
                    // ⟨C, VVᵀ⟩ = Σ_i v_i·g_i, and v_i·g_i = −|g_i| after the update
                    // (approximately: earlier rows' g are stale; fine for a stopping test).
                    obj -= norm;
                }
                if (prev - obj).abs() <= tol * obj.abs().max(1.0) {
                    break;
                }
                prev = obj;
                if sweeps % 4 == 0 && clock.out() {
                    break;
                }
            }
            // Final multipliers from the converged (or last) V.
            for i in 0..n {
                s[i] = if fix[i] == FREE {
                    4.0 * self.row_gradient(model, fix, i)
                } else {
                    0.0
                };
            }
            sweeps
        })
    }
}

/// The QCR shift (before positive-definite repair) from mixing-method sweeps on the SDP of
/// the whole problem from a random start (see [`Mixing::solve`]).
pub(crate) fn qcr_shift(model: &Model, clock: &Clock, max_sweeps: usize, tol: f64) -> Vec<f64> {
    let n = model.n;
    let mut mix = Mixing::new(n);
    let mut s = vec![0.0; n];
    mix.solve(model, &vec![FREE; n], max_sweeps, tol, clock, &mut s);
    s
}
