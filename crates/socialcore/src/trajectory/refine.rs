//! Refinement of the trajectory coefficients on the reprojection error (Eq 5.9) by
//! Levenberg–Marquardt with the analytic Jacobian, and the Gauss–Newton uncertainty at the
//! optimum.
//!
//! For observation `i` at time `t_i`, `X_i = Σ_k θ_k(t_i) β_k` and `h = K R (X_i − C)`; the
//! residual is `(h₁/h₃ − x_i, h₂/h₃ − y_i)`. Its derivative with respect to `X_i` is
//! `j_u = (m₁ − u m₃)/h₃`, `j_v = (m₂ − v m₃)/h₃` (`m_r` the rows of `K R`), and with respect
//! to `β_{3k+c}` it is `θ_k(t_i)` times the `c`-th entry. So `JᵀJ = Σ_i kron(θ_iθ_iᵀ, j_u j_uᵀ +
//! j_v j_vᵀ)`: the same Kronecker structure as the normal equations of the linear system,
//! built by the same matrix product ([`gram_raw`]).

use super::dense::{
    backward_solve, cholesky_inverse, cholesky_prefix, forward_solve, gram_raw, scatter_gram, sym3,
};
use super::linear::PointSystem;
use super::{BasisTable, Frames};
use crate::geometry::LmOptions;
use faer::Mat;
use nalgebra::Vector3;

/// Positions `X_i` at the observed frames.
fn positions(theta: &Mat<f64>, beta: &[f64]) -> Vec<Vector3<f64>> {
    let k = theta.ncols();
    (0..theta.nrows())
        .map(|i| {
            (0..k).fold(Vector3::zeros(), |acc: Vector3<f64>, kk| {
                acc + Vector3::new(beta[3 * kk], beta[3 * kk + 1], beta[3 * kk + 2])
                    * theta[(i, kk)]
            })
        })
        .collect()
}

/// Summed squared reprojection error (px²); infinite if a point falls on a camera plane.
fn cost(frames: &Frames, theta: &Mat<f64>, sys: &PointSystem, beta: &[f64]) -> f64 {
    positions(theta, beta)
        .iter()
        .zip(&sys.idx)
        .zip(&sys.px)
        .map(|((x, &i), p)| {
            let h = frames.project_h(i, x);
            if h.z == 0.0 {
                return f64::INFINITY;
            }
            let (du, dv) = (h.x / h.z - p.x, h.y / h.z - p.y);
            du * du + dv * dv
        })
        .sum()
}

/// Reprojection RMS in pixels per observation.
pub(crate) fn rms(frames: &Frames, theta: &Mat<f64>, sys: &PointSystem, beta: &[f64]) -> f64 {
    (cost(frames, theta, sys, beta) / sys.len() as f64).sqrt()
}

/// `JᵀJ` (row-major `3K × 3K`) and `Jᵀr` at `beta`.
fn normal(
    frames: &Frames,
    theta: &Mat<f64>,
    sys: &PointSystem,
    beta: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let k = theta.ncols();
    let xs = positions(theta, beta);
    let mut g = Vec::with_capacity(xs.len());
    let mut h = Vec::with_capacity(xs.len());
    for ((x, &i), p) in xs.iter().zip(&sys.idx).zip(&sys.px) {
        let m = &frames.kr[i];
        let hp = frames.project_h(i, x);
        let iz = 1.0 / hp.z;
        let (u, v) = (hp.x * iz, hp.y * iz);
        let ju = [
            (m[(0, 0)] - u * m[(2, 0)]) * iz,
            (m[(0, 1)] - u * m[(2, 1)]) * iz,
            (m[(0, 2)] - u * m[(2, 2)]) * iz,
        ];
        let jv = [
            (m[(1, 0)] - v * m[(2, 0)]) * iz,
            (m[(1, 1)] - v * m[(2, 1)]) * iz,
            (m[(1, 2)] - v * m[(2, 2)]) * iz,
        ];
        let (ru, rv) = (u - p.x, v - p.y);
        let mut gi = [0.0; 6];
        let mut hi = [0.0; 3];
        for c in 0..3 {
            for d in c..3 {
                gi[sym3(c, d)] = ju[c] * ju[d] + jv[c] * jv[d];
            }
            hi[c] = ju[c] * ru + jv[c] * rv;
        }
        g.push(gi);
        h.push(hi);
    }
    let raw = gram_raw(theta.as_ref(), &g, &h);
    let (mut jtj, mut jtr) = (Vec::new(), Vec::new());
    scatter_gram(raw.as_ref(), k, &mut jtj, &mut jtr);
    (jtj, jtr)
}

/// Outcome of the refinement.
pub(crate) struct Refined {
    pub beta: Vec<f64>,
    pub converged: bool,
    pub iterations: usize,
}

/// Largest damping before we conclude that no step can lower the cost.
const LAMBDA_MAX: f64 = 1e16;

/// Levenberg–Marquardt on Eq 5.9 from `beta0`, with Marquardt's diagonal scaling.
pub(crate) fn refine(
    frames: &Frames,
    theta: &Mat<f64>,
    sys: &PointSystem,
    beta0: &[f64],
    opts: &LmOptions,
) -> Refined {
    let nu = beta0.len();
    let mut beta = beta0.to_vec();
    let mut c = cost(frames, theta, sys, &beta);
    if !c.is_finite() {
        return Refined {
            beta,
            converged: false,
            iterations: 0,
        };
    }
    let mut lambda = 1e-4;
    let mut trial = vec![0.0; nu];
    let mut a = vec![0.0; nu * nu];
    let mut step = vec![0.0; nu];
    for it in 0..opts.max_iterations {
        // Ctrl-C: stop here; the caller checks the flag and discards this partial answer.
        if crate::interrupt::requested() {
            break;
        }
        if c == 0.0 {
            return Refined {
                beta,
                converged: true,
                iterations: it,
            };
        }
        let (jtj, jtr) = normal(frames, theta, sys, &beta);
        loop {
            a.copy_from_slice(&jtj);
            for d in 0..nu {
                a[d * nu + d] += lambda * jtj[d * nu + d].max(1e-300);
            }
            if cholesky_prefix(&mut a, nu) < nu {
                lambda *= 10.0;
                if lambda > LAMBDA_MAX {
                    return Refined {
                        beta,
                        converged: true,
                        iterations: it + 1,
                    };
                }
                continue;
            }
            for (s, g) in step.iter_mut().zip(&jtr) {
                *s = -g;
            }
            forward_solve(&a, nu, nu, &mut step);
            backward_solve(&a, nu, nu, &mut step);
            for ((t, b), s) in trial.iter_mut().zip(&beta).zip(&step) {
                *t = b + s;
            }
            let cn = cost(frames, theta, sys, &trial);
            if cn.is_finite() && cn < c {
                let rel = (c - cn) / c;
                let step_norm = step.iter().map(|v| v * v).sum::<f64>().sqrt();
                let beta_norm = beta.iter().map(|v| v * v).sum::<f64>().sqrt();
                std::mem::swap(&mut beta, &mut trial);
                c = cn;
                lambda = (lambda * 0.2).max(1e-15);
                if rel < opts.rel_tol || step_norm <= 1e-14 * (beta_norm + 1e-300) {
                    return Refined {
                        beta,
                        converged: true,
                        iterations: it + 1,
                    };
                }
                break;
            }
            lambda *= 10.0;
            if lambda > LAMBDA_MAX {
                // No step lowers the cost: a (numerical) minimum.
                return Refined {
                    beta,
                    converged: true,
                    iterations: it + 1,
                };
            }
        }
    }
    Refined {
        beta,
        converged: false,
        iterations: opts.max_iterations,
    }
}

/// Uncertainty of a fit.
pub(crate) struct Uncertainty {
    pub std: Vec<Vector3<f64>>,
    pub covariance: Option<Vec<f64>>,
    pub sigma: f64,
}

/// Gauss–Newton covariance of the coefficients at `beta`, `σ² (JᵀJ)⁻¹` with the residual
/// variance `σ² = Σ r² / (2F̂ − 3K)`, and the per-frame standard deviation of each
/// coordinate, `Var X_c(t) = Σ_kl θ_k(t) θ_l(t) Cov(β_{3k+c}, β_{3l+c})`, at every frame.
pub(crate) fn uncertainty(
    frames: &Frames,
    table: &BasisTable,
    theta: &Mat<f64>,
    sys: &PointSystem,
    beta: &[f64],
    k: usize,
) -> Uncertainty {
    let nu = 3 * k;
    let dof = 2 * sys.len() as i64 - nu as i64;
    let f = frames.len();
    let nan = || Uncertainty {
        std: vec![Vector3::repeat(f64::NAN); f],
        covariance: None,
        sigma: f64::NAN,
    };
    if dof <= 0 {
        return nan();
    }
    let sigma2 = cost(frames, theta, sys, beta) / dof as f64;
    if !sigma2.is_finite() {
        return nan();
    }
    let (mut jtj, _) = normal(frames, theta, sys, beta);
    if cholesky_prefix(&mut jtj, nu) < nu {
        return nan();
    }
    let mut cov = cholesky_inverse(&jtj, nu, nu);
    cov.iter_mut().for_each(|v| *v *= sigma2);
    let std = (0..f)
        .map(|i| {
            let w = &table.row(i)[..k];
            let mut var = [0.0; 3];
            for (a, wa) in w.iter().enumerate() {
                for (b, wb) in w.iter().enumerate() {
                    let ww = wa * wb;
                    for (c, v) in var.iter_mut().enumerate() {
                        *v += ww * cov[(3 * a + c) * nu + 3 * b + c];
                    }
                }
            }
            Vector3::new(
                var[0].max(0.0).sqrt(),
                var[1].max(0.0).sqrt(),
                var[2].max(0.0).sqrt(),
            )
        })
        .collect();
    Uncertainty {
        std,
        covariance: Some(cov),
        sigma: sigma2.sqrt(),
    }
}
