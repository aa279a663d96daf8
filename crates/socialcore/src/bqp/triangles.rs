//! Triangle inequalities as Lagrangian cuts on the semidefinite bound.
//!
//! On binary points the products `p_ij = b_i b_j` satisfy the triangle inequalities
//! (the ±1 triangle inequalities of the max-cut polytope, read back in 0/1 variables, with
//! the homogenising variable giving the pair ones):
//!
//! * triples `i < j < k`: `b_i + b_j + b_k − p_ij − p_ik − p_jk ≤ 1` and, for each centre,
//!   `p_ij + p_ik − p_jk − b_i ≤ 0`;
//! * pairs: `p_ij ≥ 0`, `p_ij ≤ b_i`, `p_ij ≤ b_j`, `b_i + b_j − p_ij ≤ 1`.
//!
//! Writing each as `g_t(b) ≤ 0`, for multipliers `γ ≥ 0` the Lagrangian objective
//! `f_γ(b) = f(b) + Σ_t γ_t g_t(b)` is again a binary quadratic (a constant, a linear and a
//! pair term per cut) and `f_γ ≤ f` on every binary point: any valid bound on `f_γ` (its
//! QCR/SDP bound, at the root or at any node) bounds `f`. Maximising its SDP bound over `γ`
//! gives the SDP bound with triangle inequalities (the BiqMac/BiqCrunch bound), here by
//! projected subgradient ascent: the subgradient of the SDP value at `γ` is `g_t` at the
//! SDP's primal solution `Y = VVᵀ` (from the mixing method, warm-started), cuts are
//! separated from the same `Y`, and the step is Polyak's towards the incumbent. The
//! multipliers that gave the best *valid* bound (QCR shift repaired to positive
//! definiteness, box relaxation solved) are kept; the tree then works on `f_γ`.

use super::boxqp::BoxQp;
use super::sdp::{Mixing, Stop};
use super::{shift, Clock, Model, FREE};
use std::collections::HashMap;

/// Position of each active cut in the cut list. Hashed by FxHash: the index is rebuilt and
/// probed thousands of times per root ascent, where SipHash's collision resistance buys
/// nothing (only lookups: its order is never read).
type CutIndex = HashMap<Cut, usize, rustc_hash::FxBuildHasher>;

/// A triangle or pair inequality `g(b) ≤ 0`; `kind` 0–3 on the triple `i < j < k`, 4–7 on
/// the pair `i < j` (`k` unused).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub(crate) struct Cut {
    kind: u8,
    i: u32,
    j: u32,
    k: u32,
}

/// Linear terms `(variable, coefficient)`, pair terms `(a, b, coefficient)` and constant of
/// a cut (unused slots have coefficient 0).
type Terms = ([(usize, f64); 3], [(usize, usize, f64); 3], f64);

impl Cut {
    fn terms(&self) -> Terms {
        let (i, j, k) = (self.i as usize, self.j as usize, self.k as usize);
        match self.kind {
            0 => (
                [(i, 1.0), (j, 1.0), (k, 1.0)],
                [(i, j, -1.0), (i, k, -1.0), (j, k, -1.0)],
                -1.0,
            ),
            1 => (
                [(i, -1.0), (0, 0.0), (0, 0.0)],
                [(i, j, 1.0), (i, k, 1.0), (j, k, -1.0)],
                0.0,
            ),
            2 => (
                [(j, -1.0), (0, 0.0), (0, 0.0)],
                [(i, j, 1.0), (j, k, 1.0), (i, k, -1.0)],
                0.0,
            ),
            3 => (
                [(k, -1.0), (0, 0.0), (0, 0.0)],
                [(i, k, 1.0), (j, k, 1.0), (i, j, -1.0)],
                0.0,
            ),
            4 => ([(0, 0.0); 3], [(i, j, -1.0), (0, 0, 0.0), (0, 0, 0.0)], 0.0),
            5 => (
                [(i, -1.0), (0, 0.0), (0, 0.0)],
                [(i, j, 1.0), (0, 0, 0.0), (0, 0, 0.0)],
                0.0,
            ),
            6 => (
                [(j, -1.0), (0, 0.0), (0, 0.0)],
                [(i, j, 1.0), (0, 0, 0.0), (0, 0, 0.0)],
                0.0,
            ),
            _ => (
                [(i, 1.0), (j, 1.0), (0, 0.0)],
                [(i, j, -1.0), (0, 0, 0.0), (0, 0, 0.0)],
                -1.0,
            ),
        }
    }

    /// `g` at the fractional point `x̂`, `p̂` (`p̂` row-major `n × n`); the formulas of
    /// [`Cut::terms`] written out (this runs for every pooled cut at every root step).
    #[inline]
    fn value(&self, x: &[f64], p: &[f64], n: usize) -> f64 {
        let (i, j, k) = (self.i as usize, self.j as usize, self.k as usize);
        let pij = p[i * n + j];
        match self.kind {
            0..=3 => {
                let (pik, pjk) = (p[i * n + k], p[j * n + k]);
                match self.kind {
                    0 => x[i] + x[j] + x[k] - pij - pik - pjk - 1.0,
                    1 => pij + pik - pjk - x[i],
                    2 => pij + pjk - pik - x[j],
                    _ => pik + pjk - pij - x[k],
                }
            }
            4 => -pij,
            5 => pij - x[i],
            6 => pij - x[j],
            _ => x[i] + x[j] - pij - 1.0,
        }
    }
}

/// `f_γ` as a [`Model`]: `base` plus `γ_t g_t` for every cut, without the sparse rows
/// (`adj` left empty: the tree loads their SDPs from the base rows and the cuts).
pub(crate) fn lagrangian_model(base: &Model, cuts: &[(Cut, f64)]) -> Model {
    let n = base.n;
    let mut m = Model {
        n,
        w: base.w.clone(),
        h: base.h.clone(),
        s: base.s.clone(),
        adj: Vec::new(),
        qdiag: base.qdiag.clone(),
        node_sdp: base.node_sdp,
        margin: base.margin,
        integral: base.integral,
        k0: base.k0,
    };
    for &(cut, gamma) in cuts {
        if gamma <= 0.0 {
            continue;
        }
        let (lin, pair, d) = cut.terms();
        for (v, c) in lin {
            m.h[v] += gamma * c;
        }
        for (a, b, c) in pair {
            let half = 0.5 * gamma * c;
            m.w[a * n + b] += half;
            m.w[b * n + a] += half;
        }
        m.k0 += gamma * d;
    }
    m
}

/// `model` with its sparse rows built (`adj`, read by [`Mixing::solve`]). The Lagrangian
/// models of the tree leave them out: their SDPs are loaded from the base rows and the
/// cuts' terms ([`load_lagrangian`]), and building them cost a few per cent of every node.
#[cfg(test)]
pub(crate) fn with_rows(mut m: Model) -> Model {
    let n = m.n;
    m.adj =
        m.w.chunks_exact(n)
            .enumerate()
            .map(|(i, row)| {
                row.iter()
                    .enumerate()
                    .filter(|&(j, v)| j != i && *v != 0.0)
                    .map(|(j, v)| (j, *v))
                    .collect()
            })
            .collect();
    m
}

/// The linear term `h` of `f_γ` and its extra pair entries `(a, b, γ_t c / 2)`, one for
/// every pair term of every cut, zero multipliers included (the same entries in the same
/// order for the same cuts, whatever their multipliers: see [`Mixing::reweight`]).
fn lagrangian_terms(
    base: &Model,
    cuts: &[(Cut, f64)],
    h: &mut Vec<f64>,
    extra: &mut Vec<(usize, usize, f64)>,
) {
    h.clear();
    h.extend_from_slice(&base.h);
    extra.clear();
    for &(cut, gamma) in cuts {
        let (lin, pair, _) = cut.terms();
        for (v, c) in lin {
            h[v] += gamma * c;
        }
        for (a, b, c) in pair {
            if c != 0.0 {
                extra.push((a, b, 0.5 * gamma * c));
            }
        }
    }
}

/// Loads the SDP of `f_γ` at the node `fix` into `mix` from `base`'s sparse rows and the
/// cuts' terms, without building `f_γ`'s dense matrix (the mixing sweeps read only rows).
fn load_lagrangian(mix: &mut Mixing, base: &Model, cuts: &[(Cut, f64)], fix: &[i8]) {
    let (mut h, mut extra) = (Vec::new(), Vec::new());
    lagrangian_terms(base, cuts, &mut h, &mut extra);
    mix.load(&h, &base.adj, &extra, fix);
}

/// The 0/1 reading of the mixing factor of the node `fix`: `x̂_i = (1 + y_i0)/2`,
/// `p̂_ij = (1 + y_i0 + y_j0 + y_ij)/4` for free `i, j`; fixed variables at their values
/// (`p̂_ij = x̂_i x̂_j` when one is fixed).
#[inline(always)]
fn primal(n: usize, mix: &Mixing, fix: &[i8], x: &mut [f64], p: &mut [f64]) {
    let k = mix.k;
    let v = &mix.v;
    let v0 = &v[n * k..(n + 1) * k];
    let dot = super::dot4;
    let y0: Vec<f64> = (0..n).map(|i| dot(&v[i * k..(i + 1) * k], v0)).collect();
    for i in 0..n {
        x[i] = if fix[i] == FREE {
            0.5 * (1.0 + y0[i])
        } else {
            f64::from(fix[i])
        };
    }
    for i in 0..n {
        p[i * n + i] = x[i];
        let vi = &v[i * k..(i + 1) * k];
        for j in (i + 1)..n {
            let pij = if fix[i] == FREE && fix[j] == FREE {
                let yij = dot(vi, &v[j * k..(j + 1) * k]);
                0.25 * (1.0 + y0[i] + y0[j] + yij)
            } else {
                x[i] * x[j]
            };
            p[i * n + j] = pij;
            p[j * n + i] = pij;
        }
    }
}

/// Multiplier steps at a node `fix`, from the inherited cuts: `steps` rounds of mixing
/// sweeps on the node's Lagrangian SDP (warm) and a projected subgradient step of Polyak
/// length `gap/(2‖g‖²)`. Returns the new cuts, zero multipliers included, and leaves `mix`
/// loaded with the SDP of their Lagrangian (ready for more sweeps; the caller validates
/// the bound with them). The rows are built once: each step only re-weights them.
#[allow(clippy::too_many_arguments)]
pub(crate) fn refine(
    base: &Model,
    cuts: &[(Cut, f64)],
    fix: &[i8],
    mix: &mut Mixing,
    steps: usize,
    gap: f64,
    clock: &Clock,
) -> Vec<(Cut, f64)> {
    let n = base.n;
    let mut cuts = cuts.to_vec();
    let (mut x, mut p) = (vec![0.0; n], vec![0.0; n * n]);
    let mut s = vec![0.0; n];
    let (mut h, mut extra) = (Vec::new(), Vec::new());
    lagrangian_terms(base, &cuts, &mut h, &mut extra);
    mix.load(&h, &base.adj, &extra, fix);
    for _ in 0..steps {
        mix.run(
            fix,
            Stop {
                max_sweeps: REFINE_SWEEPS,
                tol: 1e-6,
                clock,
            },
            &mut s,
        );
        // Only the pairs of the cuts are read: fill those, not all n² of them.
        super::with_avx2(|| primal_of_cuts(n, mix, fix, &cuts, &mut x, &mut p));
        subgradient_step(&mut cuts, &x, &p, n, 0.5 * gap, false);
        lagrangian_terms(base, &cuts, &mut h, &mut extra);
        mix.reweight(&h, &extra, fix);
    }
    cuts
}

/// [`primal`] restricted to `x̂` and the entries of `p̂` that the `cuts` read.
#[inline(always)]
fn primal_of_cuts(
    n: usize,
    mix: &Mixing,
    fix: &[i8],
    cuts: &[(Cut, f64)],
    x: &mut [f64],
    p: &mut [f64],
) {
    let k = mix.k;
    let v = &mix.v;
    let row = |i: usize| &v[i * k..(i + 1) * k];
    let dot = super::dot4;
    let y0: Vec<f64> = (0..n).map(|i| dot(row(i), row(n))).collect();
    for i in 0..n {
        x[i] = if fix[i] == FREE {
            0.5 * (1.0 + y0[i])
        } else {
            f64::from(fix[i])
        };
    }
    for (cut, _) in cuts {
        for (a, b, c) in cut.terms().1 {
            if c == 0.0 {
                continue;
            }
            let pab = if fix[a] == FREE && fix[b] == FREE {
                0.25 * (1.0 + y0[a] + y0[b] + dot(row(a), row(b)))
            } else {
                x[a] * x[b]
            };
            p[a * n + b] = pab;
            p[b * n + a] = pab;
        }
    }
}

/// `γ ← max(0, γ + step·g)` with Polyak's step `target/‖g‖²` (projected components left
/// out); with `drop`, removes the cuts whose multiplier is zero.
fn subgradient_step(
    cuts: &mut Vec<(Cut, f64)>,
    x: &[f64],
    p: &[f64],
    n: usize,
    target: f64,
    drop: bool,
) {
    let g: Vec<f64> = cuts.iter().map(|(c, _)| c.value(x, p, n)).collect();
    let norm2: f64 = cuts
        .iter()
        .zip(&g)
        .filter(|((_, gam), gt)| *gam > 0.0 || **gt > 0.0)
        .map(|(_, gt)| gt * gt)
        .sum();
    if norm2 > 1e-18 && target > 0.0 {
        let step = target / norm2;
        for ((_, gam), gt) in cuts.iter_mut().zip(&g) {
            *gam = (*gam + step * gt).max(0.0);
        }
    }
    if drop {
        cuts.retain(|(_, gam)| *gam > 0.0);
    }
}

fn key(c: &Cut) -> (u32, u32, u32, u8) {
    (c.i, c.j, c.k, c.kind)
}

/// `max(a, b)` without NaN handling (the values are finite): one vector instruction.
#[inline(always)]
fn fmax(a: f64, b: f64) -> f64 {
    if a > b {
        a
    } else {
        b
    }
}

/// Appends the cuts of `g` (their violations) above `t` to `found`, without a branch per cut.
#[inline(always)]
fn push_violated(found: &mut Vec<(f64, Cut)>, t: f64, g: [f64; 4], cuts: [Cut; 4]) {
    let mut buf = [(0.0, cuts[0]); 4];
    let mut cnt = 0;
    for d in 0..4 {
        buf[cnt] = (g[d], cuts[d]);
        cnt += usize::from(g[d] > t);
    }
    found.extend_from_slice(&buf[..cnt]);
}

/// Appends to `found` the cuts with smallest index `i` violated by more than `t` at
/// `(x̂, p̂)`, in index order (`worst` is scratch).
#[inline(always)]
fn scan_row(
    n: usize,
    x: &[f64],
    p: &[f64],
    i: usize,
    t: f64,
    found: &mut Vec<(f64, Cut)>,
    worst: &mut Vec<f64>,
) {
    worst.resize(n, 0.0);
    let xi = x[i];
    for j in (i + 1)..n {
        let pij = p[i * n + j];
        let xj = x[j];
        let pair = |kind| Cut {
            kind,
            i: i as u32,
            j: j as u32,
            k: 0,
        };
        push_violated(
            found,
            t,
            [-pij, pij - xi, pij - xj, xi + xj - pij - 1.0],
            [pair(4), pair(5), pair(6), pair(7)],
        );
        // Largest of the four triangle violations for every k > j in one pass over
        // rows i and j (no branches: vectorisable); most triples violate nothing.
        let (pi, pj, xs) = (
            &p[i * n + j + 1..(i + 1) * n],
            &p[j * n + j + 1..(j + 1) * n],
            &x[j + 1..],
        );
        let w = &mut worst[..n - j - 1];
        let tri = |pik: f64, pjk: f64, xk: f64| {
            [
                xi + xj + xk - pij - pik - pjk - 1.0,
                pij + pik - pjk - xi,
                pij + pjk - pik - xj,
                pik + pjk - pij - xk,
            ]
        };
        for (((wk, &pik), &pjk), &xk) in w.iter_mut().zip(pi).zip(pj).zip(xs) {
            let g = tri(pik, pjk, xk);
            *wk = fmax(fmax(g[0], g[1]), fmax(g[2], g[3]));
        }
        for (d, &wk) in w.iter().enumerate() {
            if wk <= t {
                continue;
            }
            let k = (j + 1 + d) as u32;
            let cut = |kind| Cut {
                kind,
                i: i as u32,
                j: j as u32,
                k,
            };
            push_violated(
                found,
                t,
                tri(pi[d], pj[d], xs[d]),
                [cut(0), cut(1), cut(2), cut(3)],
            );
        }
    }
}

/// Most violated first, ties by index: a total order, so the cuts kept do not depend on
/// how the rows were split between threads.
fn by_violation(a: &(f64, Cut), b: &(f64, Cut)) -> std::cmp::Ordering {
    b.0.total_cmp(&a.0).then_with(|| key(&a.1).cmp(&key(&b.1)))
}

/// Keeps the `keep` first of `found` in [`by_violation`] order (unordered).
fn keep_most_violated(found: &mut Vec<(f64, Cut)>, keep: usize) {
    if found.len() > keep {
        found.select_nth_unstable_by(keep, by_violation);
        found.truncate(keep);
    }
}

/// Most violated cuts at `(x̂, p̂)` not already in `active`, at most `max_new`, violation
/// above `tol`, most violated first (ties by index order: deterministic). `tol` adapts
/// for the next call (never below [`SEPARATION_TOL`]): half the weakest violation kept when
/// many more were found than kept (so that few are collected next time), a quarter of it
/// when too few were found. `pool` receives the most violated [`POOL_ROOMS`] times as many
/// as are kept, for [`separate_pool`] until the next scan, grouped by kind (within a kind
/// in no set order: [`select`] orders what it returns).
///
/// Each scanning thread keeps only its most violated [`POOL_ROOMS`] rooms as it goes: a
/// first scan can find millions of violated triangles (Beasley n = 400: a tenth of a second
/// of reallocation and page faults with all of them gathered). The rows stop being scanned
/// once `clock` is out (then the caller stops too): Ctrl-C and the time limit are seen
/// within one row.
#[allow(clippy::too_many_arguments)]
fn separate(
    n: usize,
    x: &[f64],
    p: &[f64],
    active: &CutIndex,
    max_new: usize,
    tol: &mut f64,
    pool: &mut Vec<Cut>,
    parallel: bool,
    clock: &Clock,
) -> Vec<Cut> {
    let t = *tol;
    let keep = POOL_ROOMS * (max_new + active.len());
    // (violated cuts counted, the most violated kept, scratch)
    type Acc = (usize, Vec<(f64, Cut)>, Vec<f64>);
    let scan = |(mut total, mut found, mut worst): Acc, i: usize| -> Acc {
        if !clock.out() {
            let before = found.len();
            super::with_avx2(|| scan_row(n, x, p, i, t, &mut found, &mut worst));
            total += found.len() - before;
            if found.len() > 2 * keep {
                keep_most_violated(&mut found, keep);
            }
        }
        (total, found, worst)
    };
    let (total, mut found) = if parallel {
        use rayon::prelude::*;
        (0..n)
            .into_par_iter()
            .fold(|| (0, Vec::new(), Vec::new()), scan)
            .map(|(total, found, _)| (total, found))
            .reduce(
                || (0, Vec::new()),
                |(t1, mut f1), (t2, f2)| {
                    f1.extend(f2);
                    keep_most_violated(&mut f1, keep);
                    (t1 + t2, f1)
                },
            )
    } else {
        let (total, found, _) = (0..n).fold((0, Vec::new(), Vec::new()), scan);
        (total, found)
    };
    keep_most_violated(&mut found, keep);
    // The pool grouped by kind (stable): its re-checks then branch predictably.
    pool.clear();
    for kind in 0..8 {
        pool.extend(found.iter().map(|(_, c)| *c).filter(|c| c.kind == kind));
    }
    select(found, total, active, max_new, tol)
}

/// The cuts of `pool` violated by more than `tol` at `(x̂, p̂)` and not in `active`, at most
/// `max_new`, most violated first (the cheap separation between full scans).
#[allow(clippy::too_many_arguments)]
fn separate_pool(
    x: &[f64],
    p: &[f64],
    n: usize,
    active: &CutIndex,
    max_new: usize,
    tol: f64,
    pool: &[Cut],
    parallel: bool,
) -> Vec<Cut> {
    let check = |c: &Cut| {
        let g = c.value(x, p, n);
        (g > tol).then_some((g, *c))
    };
    let found: Vec<(f64, Cut)> = if parallel {
        use rayon::prelude::*;
        pool.par_iter()
            .with_min_len(1024)
            .filter_map(check)
            .collect()
    } else {
        pool.iter().filter_map(check).collect()
    };
    let mut t = tol;
    let total = found.len();
    select(found, total, active, max_new, &mut t)
}

/// Keeps the `max_new` most violated of `found` not in `active` (ties by index order) and
/// adapts `tol` (see [`separate`]; `total` violated cuts were found, `found` may hold only
/// the most violated of them).
fn select(
    mut found: Vec<(f64, Cut)>,
    total: usize,
    active: &CutIndex,
    max_new: usize,
    tol: &mut f64,
) -> Vec<Cut> {
    {
        // Active cuts are kept apart from the new ones after the selection (fewer look-ups).
        let room = max_new + active.len();
        if found.len() > room {
            let crowded = total > 4 * room;
            keep_most_violated(&mut found, room);
            if crowded {
                let weakest = found.iter().map(|f| f.0).fold(f64::INFINITY, f64::min);
                *tol = (0.5 * weakest).max(SEPARATION_TOL);
            }
        } else {
            *tol = (0.25 * *tol).max(SEPARATION_TOL);
        }
        found.retain(|(_, c)| !active.contains_key(c));
        found.sort_by(by_violation);
        found.truncate(max_new);
        found.into_iter().map(|(_, c)| c).collect()
    }
}

/// Valid root bound of `model`: its mixing shift `s` repaired to positive definiteness with
/// the smallest eigenvalue, then the box relaxation, warm-started at `x0` (the last primal
/// `x̂` of the SDP, near its minimiser; `None` if the clock ran out).
fn valid_bound(
    model: &mut Model,
    s: &[f64],
    x0: &[f64],
    solver: &mut BoxQp,
    clock: &Clock,
) -> Option<f64> {
    let n = model.n;
    let lam = shift::min_eigenvalue(model, s)?;
    let margin = model.margin;
    model.s = s.iter().map(|v| v + margin - lam).collect();
    let r = solver.solve(model, &model.s, &vec![FREE; n], x0, f64::INFINITY, clock);
    (!clock.out()).then_some(r.bound)
}

/// What [`strengthen`] returns: the cuts with their multipliers, the valid bound of their
/// Lagrangian and the shift that proves it.
pub(crate) type Strengthened = (Vec<(Cut, f64)>, f64, Vec<f64>);

/// Root ascent iterations for `n` variables: `0.6 n` within [40, 150]. The ascent costs
/// O(n²)–O(n³) a step while the tree it saves grows exponentially with `n`, so the best
/// length grows with `n`. Measured (serial CPU, loaded machine; the bound is taken from
/// the best evaluation): Beasley n = 100 seeds 0–49, 50 / 60 / 70 / 80 / 100 steps gave
/// 3.08 / 3.04 / 3.16 / 3.35 / 3.78 s (2,413 nodes at 80, 2,916 at 60); n = 150 seeds 0–9,
/// 60 / 80 / 100 / 120 / 150 steps 5.77 / 4.67 / 4.30 / 4.25 / 4.38 s. On seeds not used
/// for the choice: n = 100 seeds 100–199, 80 → 60 steps 6.78 → 6.36 s; n = 150 seeds
/// 10–19, 80 → 90 steps 4.76 → 4.95 s (within the noise of the loaded machine).
fn root_iterations(n: usize) -> usize {
    ((0.6 * n as f64).round() as usize).clamp(40, 150)
}

/// How often the root ascent evaluates the valid bound (an eigenvalue decomposition and a
/// box relaxation each) and separates new cuts (an O(n³) scan). Many cheap steps
/// (warm-started, few sweeps each) beat few accurate ones: on Beasley n = 100, seeds 0–9, 80 steps of 8 sweeps (separating every
/// other step, evaluating every tenth) gave 1,191 nodes in 2.1 s CPU against 1,275 nodes in
/// 4.9 s with 60 steps of 30 sweeps (separating and evaluating every fifth).
///
/// Separation runs at every step, but the full O(n³) scan only every [`FULL_SCAN_EVERY`]
/// steps; in between, the pool of the most violated cuts of the last scan (a few thousand)
/// is re-checked. Measured (CPU, loaded) against the full scan every other step: Beasley
/// n = 100 seeds 0–9, 554 nodes in 1.4–1.5 s against 948 nodes in 1.9 s; seeds 10–19, 441
/// against 610 nodes; n = 150 seeds 0–2, 2,741 nodes in 10.1 s against 9,773 in 33.8 s. A
/// full scan every 4 steps gave 548 / 410 / 3,519 nodes (1.5 / 13.2 s CPU); every 16, 1,255
/// nodes on n = 100 seeds 0–9 (the pool goes stale). (All with a pool of 4×, see
/// [`POOL_ROOMS`].)
const EVAL_EVERY: usize = 10;
const FULL_SCAN_EVERY: usize = 8;
/// Smallest violation for which a cut is separated.
const SEPARATION_TOL: f64 = 1e-3;
/// Pool size of [`separate`], in multiples of the cuts kept per scan (about n plus the
/// active cuts). Beasley n = 100 seeds 0–19: 1,000 nodes with 4, 860 with 8, 817 with 16;
/// n = 150 seeds 0–2: 2,741 / 2,855 / 1,321 nodes (5.7 s CPU with 16 against 10.1 s with 4).
const POOL_ROOMS: usize = 16;
/// Mixing sweeps per iteration (warm-started), and at the first (from a random factor).
const SWEEPS: usize = 8;
const FIRST_SWEEPS: usize = 100;
/// Mixing sweeps per multiplier step at a node (warm-started).
const REFINE_SWEEPS: usize = 8;
/// Multiplier steps per node. Beasley n = 100, seeds 0–9: 25–277 nodes with 3 steps of 12
/// sweeps, against 39–11,941 with the root multipliers kept unchanged (0 steps); 4 steps of
/// 8 sweeps (fewer sweeps, one more step) gave 948 nodes against 1,002 in 7 % less CPU, while
/// 2 × 12 (1,194 nodes) and 5 × 6 (1,040) lost.
pub(crate) const NODE_STEPS: usize = 4;

/// Multipliers for the triangle cuts of `base` (see the module docs), ascending from
/// `γ = 0` towards the incumbent value `upper`; `start` is the valid bound without cuts,
/// `mix` the SDP factor of `base` (warm start; left at the last iterate's). With `parallel`
/// the separation runs on the rayon pool (same cuts).
/// Returns the best multipliers found, their valid bound and the shift that proves it (the
/// mixing shift of that iterate repaired to positive definiteness), or `None` if no
/// multipliers beat `start` (or the clock ran out first).
pub(crate) fn strengthen(
    base: &Model,
    clock: &Clock,
    upper: f64,
    start: f64,
    mix: &mut Mixing,
    parallel: bool,
) -> Option<Strengthened> {
    let n = base.n;
    if n < 3 || !start.is_finite() || upper <= start {
        return None;
    }
    let mut solver = BoxQp::new(n);
    let mut cuts: Vec<(Cut, f64)> = Vec::new();
    let mut index = CutIndex::default();
    let mut best: Option<Strengthened> = None;
    let mut best_bound = start;
    let mut theta = 1.0;
    let mut stall = 0;
    let (mut x, mut p) = (vec![0.0; n], vec![0.0; n * n]);
    let mut s = vec![0.0; n];
    let free = vec![FREE; n];
    let mut tol = SEPARATION_TOL;
    let mut pool = Vec::new();
    let iters = root_iterations(n);
    for it in 0..iters {
        if clock.out() {
            break;
        }
        load_lagrangian(mix, base, &cuts, &free);
        // The first solve may start from a random factor: converge it (the first
        // subgradient must come from the SDP optimum); later ones are warm.
        let evaluate = it % EVAL_EVERY == EVAL_EVERY - 1 || it + 1 == iters;
        let sweeps = if it == 0 { FIRST_SWEEPS } else { SWEEPS };
        mix.run(
            &free,
            Stop {
                max_sweeps: sweeps,
                tol: 1e-7,
                clock,
            },
            &mut s,
        );
        if evaluate {
            let mut model = lagrangian_model(base, &cuts);
            let Some(b) = valid_bound(&mut model, &s, &x, &mut solver, clock) else {
                break;
            };
            if b > best_bound + 1e-9 * b.abs().max(1.0) {
                best_bound = b;
                best = Some((cuts.clone(), b, model.s));
                stall = 0;
            } else {
                stall += 1;
                if stall >= 2 {
                    theta *= 0.5;
                    stall = 0;
                }
            }
            if best_bound >= upper {
                break;
            }
        }
        super::with_avx2(|| primal(n, mix, &free, &mut x, &mut p));
        let sep = if it % FULL_SCAN_EVERY == 0 {
            separate(n, &x, &p, &index, n, &mut tol, &mut pool, parallel, clock)
        } else {
            separate_pool(&x, &p, n, &index, n, tol, &pool, parallel)
        };
        for c in sep {
            index.insert(c, cuts.len());
            cuts.push((c, 0.0));
        }
        subgradient_step(&mut cuts, &x, &p, n, theta * (upper - best_bound), true);
        index.clear();
        for (t, (c, _)) in cuts.iter().enumerate() {
            index.insert(*c, t);
        }
    }
    best
}

/// Every cut of `n` variables (all kinds, all pairs and triples), for tests.
#[cfg(test)]
pub(crate) fn all_cuts(n: usize) -> Vec<Cut> {
    let mut out = Vec::new();
    for i in 0..n as u32 {
        for j in (i + 1)..n as u32 {
            for kind in 4..8 {
                out.push(Cut { kind, i, j, k: 0 });
            }
            for k in (j + 1)..n as u32 {
                for kind in 0..4 {
                    out.push(Cut { kind, i, j, k });
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod kernel_tests {
    use super::super::tests::{beasley, model_of};
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Random multipliers on every cut of `n` variables, a third of them zero.
    fn random_cuts(n: usize, rng: &mut ChaCha8Rng) -> Vec<(Cut, f64)> {
        all_cuts(n)
            .into_iter()
            .map(|c| (c, (rng.random_range(-0.5..1.0f64)).max(0.0) * 20.0))
            .collect()
    }

    /// A Beasley-like model of `n` variables (density 0.3, seed 4), random multipliers on
    /// every cut (generator `seed`, returned for more draws), and a node fixing `fixed`.
    fn case(
        n: usize,
        seed: u64,
        fixed: &[(usize, i8)],
    ) -> (Model, Vec<(Cut, f64)>, Vec<i8>, ChaCha8Rng) {
        let base = model_of(&beasley(n, 0.3, 4));
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let cuts = random_cuts(n, &mut rng);
        let mut node = vec![FREE; n];
        for &(i, f) in fixed {
            node[i] = f;
        }
        (base, cuts, node, rng)
    }

    #[test]
    fn cut_value_matches_its_terms() {
        // The written-out `value` against the generic terms, at random fractional points.
        let n = 6;
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..20 {
            let x: Vec<f64> = (0..n).map(|_| rng.random_range(0.0..1.0)).collect();
            let mut p = vec![0.0; n * n];
            for i in 0..n {
                for j in i..n {
                    let v = rng.random_range(0.0..1.0);
                    p[i * n + j] = v;
                    p[j * n + i] = v;
                }
            }
            for c in all_cuts(n) {
                let (lin, pair, d) = c.terms();
                let mut g = d;
                for (v, a) in lin {
                    g += a * x[v];
                }
                for (a, b, w) in pair {
                    g += w * p[a * n + b];
                }
                assert!((c.value(&x, &p, n) - g).abs() < 1e-12, "{c:?}");
            }
        }
    }

    #[test]
    fn sparse_lagrangian_sdp_matches_the_dense_model() {
        // The mixing sweeps on `f_γ` loaded from the base rows plus the cuts' pair entries
        // (no dense matrix) against the same sweeps on the dense Lagrangian model, from the
        // same factor, at the root and at a node with variables fixed to 0 and 1: the same
        // shift up to rounding. n = 30 (rank 9, stride 12: the padding stays zero).
        let n = 30;
        let (base, cuts, node, _) = case(n, 2, &[(3, 1), (7, 0), (11, 1), (20, 0), (21, 1)]);
        let lm = with_rows(lagrangian_model(&base, &cuts));
        let clock = Clock::new(None);
        for fix in [vec![FREE; n], node] {
            let (mut dense, mut sparse) = (Mixing::new(n), Mixing::new(n));
            assert_eq!((dense.k, sparse.k), (12, 12));
            let (mut s1, mut s2) = (vec![0.0; n], vec![0.0; n]);
            let sw1 = dense.solve(&lm, &fix, 30, 0.0, &clock, &mut s1);
            load_lagrangian(&mut sparse, &base, &cuts, &fix);
            let stop = Stop {
                max_sweeps: 30,
                tol: 0.0,
                clock: &clock,
            };
            let sw2 = sparse.run(&fix, stop, &mut s2);
            assert_eq!(sw1, sw2);
            let scale = s1.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for i in 0..n {
                assert!(
                    (s1[i] - s2[i]).abs() <= 1e-9 * scale,
                    "s[{i}]: dense {} sparse {}",
                    s1[i],
                    s2[i]
                );
                if fix[i] != FREE {
                    assert_eq!(s2[i], 0.0);
                }
            }
            for row in sparse.v.chunks(sparse.k) {
                assert!(row[9..].iter().all(|&v| v == 0.0), "padding moved");
            }
        }
    }

    #[test]
    fn reweighted_rows_match_a_fresh_load() {
        // Rows loaded for other multipliers (a third of them zero) and re-weighted in
        // place to `γ` against rows loaded for `γ` directly, at the root and at a node with
        // variables fixed to 0 and 1: the same sweeps bit for bit (a re-weight that kept
        // the old weights, or dropped the entries of variables fixed to one, differs).
        let n = 30;
        let (base, cuts, node, mut rng) = case(n, 5, &[(2, 1), (8, 0), (13, 1), (19, 1), (25, 0)]);
        let other: Vec<(Cut, f64)> = random_cuts(n, &mut rng)
            .into_iter()
            .zip(&cuts)
            .map(|((_, g), (c, _))| (*c, g))
            .collect();
        let clock = Clock::new(None);
        for fix in [vec![FREE; n], node] {
            let (mut fresh, mut moved) = (Mixing::new(n), Mixing::new(n));
            let (mut h, mut extra) = (Vec::new(), Vec::new());
            lagrangian_terms(&base, &other, &mut h, &mut extra);
            moved.load(&h, &base.adj, &extra, &fix);
            lagrangian_terms(&base, &cuts, &mut h, &mut extra);
            moved.reweight(&h, &extra, &fix);
            load_lagrangian(&mut fresh, &base, &cuts, &fix);
            let (mut s1, mut s2) = (vec![0.0; n], vec![0.0; n]);
            for (mix, s) in [(&mut fresh, &mut s1), (&mut moved, &mut s2)] {
                let stop = Stop {
                    max_sweeps: 20,
                    tol: 0.0,
                    clock: &clock,
                };
                mix.run(&fix, stop, s);
            }
            assert_eq!(s1, s2);
            assert!(s1.iter().any(|&v| v > 0.0));
        }
    }

    /// The SDP primal of a Beasley instance of `n` variables (seed 3), for separation tests.
    fn sdp_primal(n: usize) -> (Vec<f64>, Vec<f64>) {
        let base = model_of(&beasley(n, 0.1, 3));
        let clock = Clock::new(None);
        let mut mix = Mixing::new(n);
        let free = vec![FREE; n];
        mix.solve(&base, &free, 100, 1e-7, &clock, &mut vec![0.0; n]);
        let (mut x, mut p) = (vec![0.0; n], vec![0.0; n * n]);
        primal(n, &mix, &free, &mut x, &mut p);
        (x, p)
    }

    /// One full separation with nothing active: `(cuts, pool, tol)`.
    fn scan_all(
        n: usize,
        (x, p): (&[f64], &[f64]),
        max_new: usize,
        parallel: bool,
        clock: &Clock,
    ) -> (Vec<Cut>, Vec<Cut>, f64) {
        let (mut tol, mut pool) = (SEPARATION_TOL, Vec::new());
        let cuts = separate(
            n,
            x,
            p,
            &CutIndex::default(),
            max_new,
            &mut tol,
            &mut pool,
            parallel,
            clock,
        );
        (cuts, pool, tol)
    }

    #[test]
    fn separation_keeps_the_most_violated_while_scanning() {
        // Few cuts kept per scan (`max_new` = 2: a pool of 32), so every thread trims what
        // it found many times over: the pool must still be the 32 most violated cuts of
        // all (ties by index), grouped by kind, and the same serial and parallel.
        let n = 70;
        let (x, p) = sdp_primal(n);
        let mut all = Vec::new();
        let mut worst = Vec::new();
        for i in 0..n {
            scan_row(n, &x, &p, i, SEPARATION_TOL, &mut all, &mut worst);
        }
        let keep = POOL_ROOMS * 2;
        assert!(all.len() > 20 * keep, "{} violated cuts only", all.len());
        all.sort_by(by_violation);
        all.truncate(keep);
        let mut expected: Vec<Cut> = all.iter().map(|(_, c)| *c).collect();
        expected.sort_by_key(key);
        for parallel in [false, true] {
            let (cuts, mut pool, tol) = scan_all(n, (&x, &p), 2, parallel, &Clock::new(None));
            assert!(
                pool.windows(2).all(|w| w[0].kind <= w[1].kind),
                "grouped by kind"
            );
            pool.sort_by_key(key);
            assert_eq!(pool, expected);
            assert_eq!(cuts, vec![all[0].1, all[1].1]);
            // many more found than kept: the tolerance rises to half the weakest kept
            assert!(tol > SEPARATION_TOL);
        }
    }

    #[test]
    fn separation_stops_when_the_clock_is_out() {
        // A full scan costs O(n³): with the time limit passed (or Ctrl-C) no row is
        // scanned, so a root ascent stops within one row of the request.
        let n = 70;
        let (x, p) = sdp_primal(n);
        for (limit, some) in [
            (None, true),
            (Some(std::time::Duration::from_nanos(1)), false),
        ] {
            let clock = Clock::new(limit);
            std::thread::sleep(std::time::Duration::from_millis(1));
            for parallel in [false, true] {
                let (cuts, pool, _) = scan_all(n, (&x, &p), n, parallel, &clock);
                assert_eq!(!cuts.is_empty(), some);
                assert_eq!(!pool.is_empty(), some);
            }
        }
    }

    #[test]
    fn parallel_separation_finds_the_serial_cuts() {
        // The scan of all triples on the rayon pool against the serial scan, at the SDP
        // primal of a Beasley n = 70 instance: the same cuts in the same order, and the
        // same pool (as a set) and the same cuts from it.
        let n = 70;
        let (x, p) = sdp_primal(n);
        let mut out = Vec::new();
        for parallel in [false, true] {
            let (cuts, mut pool, tol) = scan_all(n, (&x, &p), n, parallel, &Clock::new(None));
            let again = separate_pool(&x, &p, n, &CutIndex::default(), n, tol, &pool, parallel);
            pool.sort_by_key(key);
            out.push((cuts, pool, again));
        }
        assert!(!out[0].0.is_empty());
        assert_eq!(out[0], out[1]);
    }
}
