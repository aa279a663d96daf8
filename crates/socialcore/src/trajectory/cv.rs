//! Per-point choice of `K` by N-fold cross validation (Sec 5.1.2, Eq 5.8).
//!
//! The observations are ordered by time and dealt to the folds in turn, so each fold holds
//! about `F̂/N` samples spread uniformly over the sequence. For fold `j` the trajectory is
//! solved from the other folds and its reprojection error on `S_j` is summed; the `K` with
//! the least total held-out error wins (ties go to the smaller `K`).
//!
//! Cost: with unknowns ordered `3k + c`, the system for `K` is the leading `3K × 3K` block of
//! the normal equations `(QΘ)ᵀQΘ β = (QΘ)ᵀq` built with `k_hi` functions. One Cholesky
//! factorisation per fold gives every leading block's factor, and one forward substitution
//! every leading right-hand side, so each further `K` costs a back substitution and the
//! held-out evaluation. A numerically singular leading block stops the factorisation there:
//! larger `K` are then not admissible for that fold.

use super::dense::{backward_solve, cholesky_prefix, forward_solve, gram_raw, scatter_gram};
use super::linear::PointSystem;
use super::{BasisTable, CvRule, Frames};
use nalgebra::Vector3;

/// The outcome of cross validation.
#[derive(Debug, Clone)]
pub(crate) struct CvOutcome {
    /// The chosen `K`, or `None` when no `K` was admissible in every fold.
    pub k: Option<usize>,
    /// Held-out reprojection RMS (px per observation) for `K = 1 ..= k_hi`; infinite where
    /// not admissible (including `K < k_min`).
    pub errors: Vec<f64>,
}

/// Cross-validates `K = k_min ..= k_hi` (`k_hi ≤ table.kc`).
pub(crate) fn select_k(
    frames: &Frames,
    table: &BasisTable,
    sys: &PointSystem,
    folds: usize,
    k_min: usize,
    k_hi: usize,
    rule: CvRule,
) -> CvOutcome {
    let n = sys.len();
    let k_hi = k_hi.min(table.kc);
    let mut sum = vec![0.0; k_hi + 1];
    let mut ok = vec![0usize; k_hi + 1];
    // Per-fold mean squared held-out error, for the one-standard-error rule.
    let mut fold_mse = vec![Vec::new(); k_hi + 1];
    if k_hi < k_min || n < 2 {
        return CvOutcome {
            k: None,
            errors: vec![f64::INFINITY; k_hi],
        };
    }
    let nf = folds.min(n);
    // Time order (ties by frame index), dealt round-robin.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| {
        frames.times[sys.idx[a]]
            .total_cmp(&frames.times[sys.idx[b]])
            .then(a.cmp(&b))
    });
    let members: Vec<Vec<usize>> = (0..nf)
        .map(|j| order.iter().skip(j).step_by(nf).copied().collect())
        .collect();

    // Raw Gram products per fold, and their total.
    let raws: Vec<_> = members
        .iter()
        .map(|m| {
            let idx: Vec<usize> = m.iter().map(|&o| sys.idx[o]).collect();
            let theta = table.gather(&idx, k_hi);
            let g: Vec<[f64; 6]> = m.iter().map(|&o| sys.g[o]).collect();
            let h: Vec<[f64; 3]> = m.iter().map(|&o| sys.h[o]).collect();
            gram_raw(theta.as_ref(), &g, &h)
        })
        .collect();
    let mut total = raws[0].clone();
    for r in &raws[1..] {
        total += r;
    }

    let nu = 3 * k_hi;
    let (mut mat, mut rhs) = (Vec::new(), Vec::new());
    let mut beta = vec![0.0; nu];
    for (j, held) in members.iter().enumerate() {
        // Ctrl-C: stop between folds; the caller checks the flag and discards the result.
        if crate::interrupt::requested() {
            break;
        }
        let train = &total - &raws[j];
        scatter_gram(train.as_ref(), k_hi, &mut mat, &mut rhs);
        let n_train = n - held.len();
        let p = cholesky_prefix(&mut mat, nu);
        let k_fold = (p / 3).min((2 * n_train) / 3).min(k_hi);
        if k_fold < k_min {
            continue;
        }
        forward_solve(&mat, nu, 3 * k_fold, &mut rhs);
        for k in k_min..=k_fold {
            beta[..3 * k].copy_from_slice(&rhs[..3 * k]);
            backward_solve(&mat, nu, 3 * k, &mut beta);
            let mut e = 0.0;
            for &o in held {
                let i = sys.idx[o];
                let w = table.row(i);
                let x = (0..k).fold(Vector3::zeros(), |acc: Vector3<f64>, kk| {
                    acc + Vector3::new(beta[3 * kk], beta[3 * kk + 1], beta[3 * kk + 2]) * w[kk]
                });
                let hp = frames.project_h(i, &x);
                if hp.z <= 0.0 || hp.z.is_nan() {
                    e = f64::INFINITY;
                    break;
                }
                let dx = hp.x / hp.z - sys.px[o].x;
                let dy = hp.y / hp.z - sys.px[o].y;
                e += dx * dx + dy * dy;
            }
            if e.is_finite() {
                sum[k] += e;
                ok[k] += 1;
                fold_mse[k].push(e / held.len() as f64);
            }
        }
    }
    let mut errors = vec![f64::INFINITY; k_hi];
    let mut best: Option<(usize, f64)> = None;
    for k in k_min..=k_hi {
        if ok[k] == nf {
            let rms = (sum[k] / n as f64).sqrt();
            errors[k - 1] = rms;
            if best.map_or(true, |(_, b)| rms < b) {
                best = Some((k, rms));
            }
        }
    }
    let k = match (rule, best) {
        (CvRule::Min, _) | (_, None) => best.map(|(k, _)| k),
        (CvRule::OneStandardError, Some((kb, _))) => {
            // Breiman's rule: the smallest K whose mean held-out error is within one
            // standard error (across folds) of the minimum's.
            let m = &fold_mse[kb];
            let mean = m.iter().sum::<f64>() / m.len() as f64;
            let var = m.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>()
                / (m.len().max(2) - 1) as f64;
            let limit = sum[kb] / n as f64 + (var / m.len() as f64).sqrt();
            (k_min..=kb).find(|&k| ok[k] == nf && sum[k] / n as f64 <= limit)
        }
    };
    CvOutcome { k, errors }
}
