//! The convexifying diagonal shift `s` of `φ(x) = xᵀ(W + diag(s))x + (h − s)ᵀx`.
//!
//! Any `s` with `W + diag(s) ≻ 0` gives a valid convex relaxation; smaller `s` gives a
//! tighter one (`∂φ/∂s_i = −x_i(1 − x_i) ≤ 0` on the box). The best `s` is the dual of the
//! semidefinite relaxation (the QCR of Billionnet and Elloumi), which [`super::sdp`]
//! estimates by a low-rank first-order method; its estimate is repaired to positive
//! definiteness by a uniform shift to the smallest eigenvalue. We also try the problem's
//! own diagonal (shifted to the margin: positive semidefinite `Q`, as in the articulated
//! programs of Eq 4.12, often need no shift at all), keep the better root bound, and polish
//! it with a projected ascent along `−x(1 − x)` that keeps a step only if the matrix still
//! factorises and the root bound improves. Every stage watches the clock; if too little time
//! is left for an eigenvalue decomposition, the Gershgorin shift (diagonal dominance, no
//! factorisation) is used.

use super::boxqp::{cholesky_in_place, BoxQp};
use super::{sdp, Clock, Model, FREE};
use faer::{Mat, Side};

/// Mixing-method sweeps at the root: on Beasley instances (n = 100) the SDP value settles
/// to 1e-7 relative in 70–120 sweeps; articulated programs converge slowly and gain little.
const SDP_SWEEPS: usize = 300;

/// Up to this size eigenvalues are computed on one thread.
const SMALL: usize = 200;

/// Ascent steps on the shift (each costs one factorisation and one root relaxation).
const ASCENT_STEPS: usize = 40;

fn set_shift(model: &mut Model, s: &[f64]) {
    model.s.copy_from_slice(s);
}

fn root_bound(model: &Model, solver: &mut BoxQp, clock: &Clock) -> (f64, Vec<f64>) {
    let n = model.n;
    let fix = vec![FREE; n];
    let x0 = vec![0.5; n];
    let r = solver.solve(model, &model.s, &fix, &x0, f64::INFINITY, clock);
    (r.bound, r.x)
}

/// Smallest eigenvalue of `W + diag(d)`; `None` if the decomposition fails. Small
/// matrices on one thread (nalgebra), large ones with faer.
pub(crate) fn min_eigenvalue(model: &Model, d: &[f64]) -> Option<f64> {
    let n = model.n;
    if n <= SMALL {
        let mat =
            nalgebra::DMatrix::from_fn(n, n, |i, j| if i == j { d[i] } else { model.w[i * n + j] });
        let v = mat.symmetric_eigenvalues().min();
        return v.is_finite().then_some(v);
    }
    let mat = Mat::from_fn(n, n, |i, j| if i == j { d[i] } else { model.w[i * n + j] });
    let ev = mat.self_adjoint_eigenvalues(Side::Lower).ok()?;
    let v = ev.iter().copied().fold(f64::INFINITY, f64::min);
    v.is_finite().then_some(v)
}

/// Rough seconds for one dense eigenvalue decomposition of size `n` on a loaded machine.
pub(crate) fn eig_seconds(n: usize) -> f64 {
    let n = n as f64;
    2e-8 * n * n * n + 1e-4
}

/// Sets the shift of `model` (see the module docs). Returns the root bound of the chosen
/// shift (`−∞` if the clock ran out before a root relaxation finished) and whether the SDP
/// shift won (then the nodes recompute it too). `cut` is the pruning threshold of the
/// incumbent: a root bound reaching it ends the work early. The SDP runs on `mix` (warm
/// when it already holds a nearby factor; left there for the caller). With `sdp_only` the
/// problem's own diagonal is not tried (the caller knows the SDP shift wins).
pub(crate) fn choose_shift(
    model: &mut Model,
    clock: &Clock,
    cut: f64,
    mix: &mut sdp::Mixing,
    sdp_only: bool,
) -> (f64, bool) {
    let n = model.n;
    let margin = model.margin;

    // Always-valid fallback: Gershgorin (W + diag(s) diagonally dominant).
    let gersh: Vec<f64> = (0..n)
        .map(|i| {
            model.w[i * n..(i + 1) * n]
                .iter()
                .map(|v| v.abs())
                .sum::<f64>()
                + margin
        })
        .collect();
    set_shift(model, &gersh);
    if clock.remaining_secs() < 3.0 * eig_seconds(n) {
        return (f64::NEG_INFINITY, false);
    }
    let mut solver = BoxQp::new(n);
    let repaired = |model: &Model, mut s: Vec<f64>| -> Option<Vec<f64>> {
        let lam = min_eigenvalue(model, &s)?;
        for v in s.iter_mut() {
            *v += margin - lam;
        }
        Some(s)
    };
    let mut best = f64::NEG_INFINITY;
    let mut s = gersh;
    let mut x = vec![0.5; n];
    // Candidate B first: the problem's own diagonal, shifted to the margin (one eigenvalue
    // decomposition). When its root bound already reaches `cut` the root is solved and the
    // SDP (tens of milliseconds) is skipped.
    if let Some(cand) = (!sdp_only)
        .then(|| repaired(model, model.qdiag.clone()))
        .flatten()
    {
        set_shift(model, &cand);
        let (b, xb) = root_bound(model, &mut solver, clock);
        if b > best {
            (best, x, s) = (b, xb, cand);
        }
    }
    if best >= cut {
        set_shift(model, &s);
        return (best, false);
    }
    // Candidate A: the SDP (QCR) shift.
    let mut sdp_won = false;
    if !clock.out() {
        let mut sdp = vec![0.0; n];
        mix.solve(model, &vec![FREE; n], SDP_SWEEPS, 1e-8, clock, &mut sdp);
        if let Some(cand) = repaired(model, sdp) {
            if !clock.out() {
                set_shift(model, &cand);
                let (b, xb) = root_bound(model, &mut solver, clock);
                if b > best {
                    (best, x, s) = (b, xb, cand);
                    sdp_won = true;
                }
            }
        }
    }
    set_shift(model, &s);
    if sdp_won {
        // The QCR shift is already the best diagonal shift for the root relaxation (up to
        // the inexact SDP): on Beasley n = 100, seeds 0–9, the ascent below changed no node
        // count and cost 10 % of the CPU (it ran twice: on `f` and on the cut model).
        return (best, true);
    }

    // Projected ascent on s (the problem's own diagonal or the Gershgorin shift won).
    let mut tau = s.iter().map(|v| v.abs()).fold(0.0, f64::max).max(margin) * 0.1;
    let tau_min = tau * 1e-4;
    let mut trial = vec![0.0; n];
    let mut chol = vec![0.0; n * n];
    for _ in 0..ASCENT_STEPS {
        if tau < tau_min || clock.out() || best == f64::NEG_INFINITY {
            break;
        }
        let mut any = false;
        for i in 0..n {
            let step = tau * x[i] * (1.0 - x[i]);
            any |= step > 0.0;
            trial[i] = s[i] - step;
        }
        if !any {
            break;
        }
        chol.copy_from_slice(&model.w);
        for i in 0..n {
            chol[i * n + i] = trial[i] - margin;
        }
        if !cholesky_in_place(&mut chol, n, Some(clock)) {
            tau *= 0.5;
            continue;
        }
        set_shift(model, &trial);
        let (b, xb) = root_bound(model, &mut solver, clock);
        if b > best {
            best = b;
            x = xb;
            s.copy_from_slice(&trial);
            tau *= 1.5;
        } else {
            set_shift(model, &s);
            tau *= 0.5;
        }
    }
    set_shift(model, &s);
    (best, sdp_won)
}

/// Repairs the node shift `s` (free entries) so that `W_FF + diag(s_F)` is positive
/// definite: a uniform raise `δ + margin`, with `δ` the smallest trial value (starting from
/// `guess`, the worker's last one, times 0.7; ×4 on failure) for which the matrix
/// factorises — a Cholesky costs a sixth of an eigenvalue decomposition, and the raise
/// stays within 4× of the needed one. Falls back to the smallest eigenvalue. False if that
/// also fails (the caller keeps its previous shift).
pub(crate) fn repair_free(
    model: &Model,
    s: &mut [f64],
    fix: &[i8],
    guess: &mut f64,
    chol: &mut Vec<f64>,
) -> bool {
    let n = model.n;
    let margin = model.margin;
    let free: Vec<usize> = (0..n).filter(|&i| fix[i] == FREE).collect();
    let m = free.len();
    chol.resize(m * m, 0.0);
    let mut delta = (0.7 * *guess).max(margin);
    for _ in 0..8 {
        for (a, &i) in free.iter().enumerate() {
            for (b, &j) in free[..=a].iter().enumerate() {
                chol[a * m + b] = model.w[i * n + j];
            }
            chol[a * m + a] = s[i] + delta;
        }
        if cholesky_in_place(chol, m, None) {
            *guess = delta;
            for &i in &free {
                s[i] += delta + margin;
            }
            return true;
        }
        delta *= 4.0;
    }
    let mat = nalgebra::DMatrix::from_fn(m, m, |a, b| {
        let (i, j) = (free[a], free[b]);
        if a == b {
            s[i]
        } else {
            model.w[i * n + j]
        }
    });
    let lam = mat.symmetric_eigenvalues().min();
    if !lam.is_finite() {
        return false;
    }
    *guess = (-lam).max(margin);
    for &i in &free {
        s[i] += margin - lam;
    }
    true
}
