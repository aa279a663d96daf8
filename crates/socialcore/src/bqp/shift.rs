//! The convexifying diagonal shift `s` of `φ(x) = xᵀ(W + diag(s))x + (h − s)ᵀx`.
//!
//! Any `s` with `W + diag(s) ≻ 0` gives a valid convex relaxation; smaller `s` gives a
//! tighter one (`∂φ/∂s_i = −x_i(1 − x_i) ≤ 0` on the box). The best `s` is the dual of a
//! semidefinite program (the "QCR" of Billionnet and Elloumi); instead of solving it we
//! take the better of two eigenvalue shifts and then run a projected ascent: step along
//! `−x(1 − x)` at the root minimiser, keeping a step only if the shifted matrix still
//! factorises (positive definite with a margin) and the root bound improves.

use super::boxqp::{cholesky_in_place, BoxQp};
use super::{Model, FREE};
use crate::error::{Error, Result};
use nalgebra::DMatrix;

/// Ascent steps on the shift (each costs one factorisation and one root relaxation).
const ASCENT_STEPS: usize = 40;

fn set_shift(model: &mut Model, s: &[f64]) {
    let n = model.n;
    model.qs.copy_from_slice(&model.w);
    for i in 0..n {
        model.qs[i * n + i] = s[i];
        model.lin[i] = model.h[i] - s[i];
    }
}

fn root_bound(model: &Model, solver: &mut BoxQp) -> (f64, Vec<f64>) {
    let n = model.n;
    let fix = vec![FREE; n];
    let x0 = vec![0.5; n];
    let r = solver.solve(model, &fix, &x0, f64::INFINITY);
    (r.bound, r.x)
}

fn min_eigenvalue(n: usize, m: &[f64]) -> Result<f64> {
    let mat = DMatrix::from_row_slice(n, n, m);
    let ev = mat.symmetric_eigenvalues();
    let v = ev.iter().copied().fold(f64::INFINITY, f64::min);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::degenerate("eigenvalue computation of Q failed"))
    }
}

pub(crate) fn choose_shift(model: &mut Model) -> Result<()> {
    let n = model.n;
    let fro = model.w.iter().map(|v| v * v).sum::<f64>().sqrt()
        + model.h.iter().map(|v| v * v).sum::<f64>().sqrt();
    let scale = if fro > 0.0 { fro } else { 1.0 };
    let margin = 1e-9 * scale;

    // Candidate A: uniform shift of W alone.
    let lam_w = min_eigenvalue(n, &model.w)?;
    let s_a = vec![margin - lam_w; n];
    // Candidate B: keep the problem's own diagonal (W + diag(d) = Q) and shift uniformly
    // to the margin (down for a positive definite Q, as in the articulated problems).
    let mut solver = BoxQp::new(n);
    set_shift(model, &s_a);
    let (mut best, mut x) = root_bound(model, &mut solver);
    let mut s = s_a;
    {
        let d = model.qdiag.clone();
        let mut qd = model.w.clone();
        for i in 0..n {
            qd[i * n + i] = d[i];
        }
        let lam = min_eigenvalue(n, &qd)?;
        let s_b: Vec<f64> = d.iter().map(|v| v + margin - lam).collect();
        set_shift(model, &s_b);
        let (b, xb) = root_bound(model, &mut solver);
        if b > best {
            best = b;
            x = xb;
            s = s_b;
        } else {
            set_shift(model, &s);
        }
    }

    // Projected ascent on s.
    let mut tau = s.iter().map(|v| v.abs()).fold(0.0, f64::max).max(margin) * 4.0;
    let tau_min = tau * 1e-4;
    let mut trial = vec![0.0; n];
    let mut chol = vec![0.0; n * n];
    for _ in 0..ASCENT_STEPS {
        if tau < tau_min {
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
        if !cholesky_in_place(&mut chol, n) {
            tau *= 0.5;
            continue;
        }
        set_shift(model, &trial);
        let (b, xb) = root_bound(model, &mut solver);
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
    Ok(())
}
