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

use super::{Clock, Model};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Result of the low-rank SDP solve.
pub(crate) struct Sdp {
    /// QCR shift `s` (length `n`), before positive-definite repair.
    pub s: Vec<f64>,
    /// Sweeps done.
    pub sweeps: usize,
}

/// Mixing-method sweeps on the SDP of `model`, at most `max_sweeps` and until the objective
/// changes by less than `tol` relatively over a sweep, or the clock runs out (then the
/// current estimate is returned; it is still a usable shift after repair).
pub(crate) fn qcr_shift(model: &Model, clock: &Clock, max_sweeps: usize, tol: f64) -> Sdp {
    let n = model.n;
    let m = n + 1;
    // C as sparse rows (the Beasley instances are 10 % dense; dense ones lose little).
    let mut row_start = Vec::with_capacity(m + 1);
    let mut cols: Vec<usize> = Vec::new();
    let mut vals: Vec<f64> = Vec::new();
    let lin: Vec<f64> = (0..n)
        .map(|i| 0.25 * (model.h[i] + model.w[i * n..(i + 1) * n].iter().sum::<f64>()))
        .collect();
    row_start.push(0);
    for (j, &l) in lin.iter().enumerate() {
        if l != 0.0 {
            cols.push(j + 1);
            vals.push(l);
        }
    }
    row_start.push(cols.len());
    for i in 0..n {
        if lin[i] != 0.0 {
            cols.push(0);
            vals.push(lin[i]);
        }
        let row = &model.w[i * n..(i + 1) * n];
        for (j, &v) in row.iter().enumerate() {
            if v != 0.0 && j != i {
                cols.push(j + 1);
                vals.push(0.25 * v);
            }
        }
        row_start.push(cols.len());
    }
    let k = ((2.0 * m as f64).sqrt().ceil() as usize + 1).min(m).max(2);
    let mut rng = ChaCha8Rng::seed_from_u64(0x05ee_db0b);
    let mut v = vec![0.0; m * k];
    for i in 0..m {
        let r = &mut v[i * k..(i + 1) * k];
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
    let mut g = vec![0.0; k];
    let mut gnorm = vec![0.0; m];
    let mut prev = f64::INFINITY;
    let mut sweeps = 0;
    while sweeps < max_sweeps {
        sweeps += 1;
        let mut obj = 0.0;
        for i in 0..m {
            g.fill(0.0);
            for p in row_start[i]..row_start[i + 1] {
                let (j, c) = (cols[p], vals[p]);
                let vj = &v[j * k..(j + 1) * k];
                for (ga, va) in g.iter_mut().zip(vj) {
                    *ga += c * va;
                }
            }
            let norm = g.iter().map(|a| a * a).sum::<f64>().sqrt();
            gnorm[i] = norm;
            if norm > 0.0 {
                let vi = &mut v[i * k..(i + 1) * k];
                for (va, ga) in vi.iter_mut().zip(&g) {
                    *va = -ga / norm;
                }
            }
            // ⟨C, VVᵀ⟩ = Σ_i v_i·g_i, and v_i·g_i = −|g_i| after the update (approximately:
            // the g_j of earlier rows are stale, which is fine for a stopping test).
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
    for i in 1..m {
        g.fill(0.0);
        for p in row_start[i]..row_start[i + 1] {
            let (j, c) = (cols[p], vals[p]);
            let vj = &v[j * k..(j + 1) * k];
            for (ga, va) in g.iter_mut().zip(vj) {
                *ga += c * va;
            }
        }
        gnorm[i] = g.iter().map(|a| a * a).sum::<f64>().sqrt();
    }
    let s = (1..m).map(|i| 4.0 * gnorm[i]).collect();
    Sdp { s, sweeps }
}
