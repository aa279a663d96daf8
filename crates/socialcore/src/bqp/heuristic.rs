//! Primal heuristics and dominance fixing on the original objective
//! `f(b) = Σ h_i b_i + Σ_{i≠j} W_ij b_i b_j`.

use super::{Clock, Model, FREE};

/// `field_i = h_i + 2 Σ_j W_ij b_j`: flipping `b_i` changes `f` by `±field_i`.
fn fields(model: &Model, b: &[bool]) -> Vec<f64> {
    let n = model.n;
    let mut field = model.h.clone();
    for j in 0..n {
        if b[j] {
            for i in 0..n {
                field[i] += 2.0 * model.w[i * n + j];
            }
        }
    }
    field
}

fn flip(model: &Model, b: &mut [bool], field: &mut [f64], i: usize) {
    let n = model.n;
    let sign = if b[i] { -2.0 } else { 2.0 };
    b[i] = !b[i];
    let row = &model.w[i * n..(i + 1) * n];
    for (f, w) in field.iter_mut().zip(row) {
        *f += sign * w;
    }
}

fn delta(b: bool, field: f64) -> f64 {
    if b {
        -field
    } else {
        field
    }
}

/// Best-improvement one-flip descent to a local minimum.
pub(crate) fn one_flip_descent(model: &Model, b: &mut [bool]) {
    let n = model.n;
    let mut field = fields(model, b);
    for _ in 0..(10 * n + 10) {
        let mut best = (0.0, usize::MAX);
        for i in 0..n {
            let d = delta(b[i], field[i]);
            if d < best.0 - 1e-12 * (1.0 + d.abs()) {
                best = (d, i);
            }
        }
        if best.1 == usize::MAX {
            return;
        }
        flip(model, b, &mut field, best.1);
    }
}

/// Deterministic one-flip tabu search (best admissible move each step, aspiration when a
/// tabu move beats the best value found); returns the best point visited.
/// Stops early when `clock` runs out.
pub(crate) fn tabu_search(
    model: &Model,
    start: &[bool],
    iterations: usize,
    clock: &Clock,
) -> Vec<bool> {
    let n = model.n;
    let mut b = start.to_vec();
    let mut field = fields(model, &b);
    let mut f = model.f(&b);
    let mut best_b = b.clone();
    let mut best_f = f;
    let tenure = (n / 4).clamp(1, 20);
    let mut tabu_until = vec![0usize; n];
    for it in 1..=iterations {
        if it % 64 == 0 && clock.out() {
            break;
        }
        let mut pick = usize::MAX;
        let mut pick_d = f64::INFINITY;
        for i in 0..n {
            let d = delta(b[i], field[i]);
            let allowed = tabu_until[i] < it || f + d < best_f - 1e-12 * (1.0 + best_f.abs());
            if allowed && d < pick_d {
                pick_d = d;
                pick = i;
            }
        }
        if pick == usize::MAX {
            break;
        }
        flip(model, &mut b, &mut field, pick);
        f += pick_d;
        tabu_until[pick] = it + tenure;
        if f < best_f - 1e-12 * (1.0 + best_f.abs()) {
            best_f = f;
            best_b.copy_from_slice(&b);
        }
    }
    best_b
}

/// First-order dominance: if the marginal cost of `b_i = 1` is `≥ 0` whatever the free
/// variables do, some optimum of the node has `b_i = 0` (and symmetrically for `≤ 0`).
/// Fixings are applied one at a time, so each is valid given the previous ones.
pub(crate) fn dominance_fix(model: &Model, fix: &mut [i8]) {
    let n = model.n;
    loop {
        let mut changed = false;
        for i in 0..n {
            if fix[i] != FREE {
                continue;
            }
            let row = &model.w[i * n..(i + 1) * n];
            let (mut base, mut neg, mut pos) = (model.h[i], 0.0, 0.0);
            for j in 0..n {
                let w2 = 2.0 * row[j];
                match fix[j] {
                    1 => base += w2,
                    FREE if j != i => {
                        if w2 < 0.0 {
                            neg += w2;
                        } else {
                            pos += w2;
                        }
                    }
                    _ => {}
                }
            }
            if base + neg >= 0.0 {
                fix[i] = 0;
                changed = true;
            } else if base + pos <= 0.0 {
                fix[i] = 1;
                changed = true;
            }
        }
        if !changed {
            return;
        }
    }
}
