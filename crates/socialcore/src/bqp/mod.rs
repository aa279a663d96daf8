//! Exact binary quadratic programming (thesis Sec 4.2.2, Eq 4.12).
//!
//! Minimise `f(b) = bᵀQb + cᵀb` over `b ∈ {0,1}ⁿ` for a symmetric `Q`, by branch-and-bound:
//!
//! * **Bound: quadratic convex reformulation (QCR) of the semidefinite relaxation.** Because
//!   `b_i² = b_i` on binary points, `f(b) = bᵀ(W + diag(s))b + (h − s)ᵀb` for every shift
//!   `s` (`W` the off-diagonal part of `Q`, `h = diag Q + c`). At the root a low-rank
//!   first-order solve of the basic SDP relaxation ([`sdp`], the mixing method) gives the
//!   dual multipliers, i.e. the QCR shift of Billionnet and Elloumi, repaired to positive
//!   definiteness with the smallest eigenvalue; with it the root relaxation attains the SDP
//!   bound. The problem's own diagonal (positive semidefinite articulated programs) is kept
//!   when better (tried first: when it already closes the root the SDP is skipped), and a
//!   projected ascent polishes the shift ([`shift`]). When the SDP shift won at the root,
//!   every node recomputes it from the SDP of its own subproblem (fixed variables
//!   substituted; mixing sweeps warm-started from the worker's last factor, repaired to
//!   positive definiteness by trial Cholesky factorisations): the node bound is then the
//!   node's SDP bound rather than the root shift's, which cut the nodes on Beasley n = 100
//!   instances 5–50×. Each node solves the convex relaxation of its shifted problem over
//!   its box by projected Newton, warm-started from its parent; the bound is the Frank–Wolfe bound `φ(x) + Σ_i min(−g_i x_i,
//!   g_i (1 − x_i))`, valid at any feasible `x`, so an inexact solve never gives an invalid
//!   bound.
//! * **Triangle cuts** ([`triangles`]): when the SDP bound does not close the root and `Q`
//!   is not positive semidefinite — at the root from n = 64 on, below that once the plain
//!   tree passes `2n` nodes (the search then restarts from the root) —, the
//!   triangle inequalities enter as Lagrangian terms `γ_t g_t(b) ≤ 0` added to `f` (still a
//!   binary quadratic, below `f` on binary points), their multipliers fitted at the root
//!   by subgradient ascent on the SDP bound with separation (a full scan of the triples
//!   every 8 steps, a pool of the most violated ones re-checked in between), and re-fitted at every node by
//!   a few warm-started steps (kept only when they beat the parent's). On Beasley n = 100
//!   instances this cut the trees 5–40× against the SDP bound alone.
//! * **Variable fixing**: first-order dominance (a persistency argument: a variable whose
//!   marginal cost has a fixed sign whatever the other free variables do) and reduced-cost
//!   fixing from the linearisation behind the bound.
//! * **Search**: best-first over open nodes, each expansion a depth-first dive (into the
//!   child nearer the relaxation, up to `dive_depth` nodes, the far children left open).
//!   Each round expands the `batch` best open nodes; with `parallel` their dives run on the
//!   rayon pool, all against the incumbent known at the start of the round, and the round's
//!   results are merged in a fixed order, so the answer and node count are the same on any
//!   number of threads. Branching on the free variable maximising `min(x_i, 1 − x_i) · Qs_ii`.
//! * **Incumbents**: rounding plus one-flip descent at every node, and a deterministic
//!   one-flip tabu search at the root.
//! * **Limits**: every stage (tabu, SDP sweeps, eigenvalue repair — skipped for the
//!   Gershgorin shift when too little time is left —, Newton iterations and factorisations,
//!   rounds) watches the wall clock and the interrupt flag ([`crate::interrupt`]). A stopped
//!   solve returns the incumbent, a finite bound (the smallest over open nodes, never below
//!   the trivial bound `Σ min(0, h_i) + Σ_{i≠j} min(0, W_ij)`) and the gap; Ctrl-C returns
//!   [`Error::Interrupted`].

// Index loops mirror the equations in these dense numeric kernels.
#![allow(clippy::needless_range_loop)]

mod boxqp;
mod heuristic;
mod sdp;
mod shift;
mod triangles;

use crate::error::{Error, Result};
use nalgebra::{DMatrix, DVector};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A validated problem `min bᵀQb + cᵀb, b ∈ {0,1}ⁿ` with dense symmetric `Q`.
#[derive(Debug, Clone, PartialEq)]
pub struct BqpProblem {
    n: usize,
    /// Row-major `n × n`, exactly symmetric (the mean of `Q` and `Qᵀ`).
    q: Vec<f64>,
    c: Vec<f64>,
}

impl BqpProblem {
    /// Validates and stores `Q` (`n × n`, symmetric up to `1e-9 · max|Q|`, finite) and the
    /// optional linear term `c` (`n`, finite; zero when `None`).
    pub fn new(q: &DMatrix<f64>, c: Option<&DVector<f64>>) -> Result<Self> {
        let n = q.nrows();
        if q.ncols() != n {
            return Err(Error::invalid(
                "Q",
                format!("must be square, got {}x{}", q.nrows(), q.ncols()),
            ));
        }
        let mut flat = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                flat[i * n + j] = q[(i, j)];
            }
        }
        let c = match c {
            Some(c) => c.iter().copied().collect(),
            None => vec![0.0; n],
        };
        Self::from_row_major(n, flat, c)
    }

    /// Like [`BqpProblem::new`] from a row-major `n × n` slice and a length-`n` linear term.
    pub fn from_row_major(n: usize, q: Vec<f64>, c: Vec<f64>) -> Result<Self> {
        if q.len() != n * n {
            return Err(Error::invalid(
                "Q",
                format!("expected {} entries for n = {n}, got {}", n * n, q.len()),
            ));
        }
        if c.len() != n {
            return Err(Error::invalid(
                "c",
                format!("expected length {n}, got {}", c.len()),
            ));
        }
        crate::error::ensure_finite("Q", &q)?;
        crate::error::ensure_finite("c", &c)?;
        let scale = q.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut q = q;
        for i in 0..n {
            for j in (i + 1)..n {
                let (a, b) = (q[i * n + j], q[j * n + i]);
                if (a - b).abs() > 1e-9 * scale {
                    return Err(Error::invalid(
                        "Q",
                        format!("must be symmetric: Q[{i},{j}] = {a} but Q[{j},{i}] = {b}"),
                    ));
                }
                let m = 0.5 * (a + b);
                q[i * n + j] = m;
                q[j * n + i] = m;
            }
        }
        Ok(BqpProblem { n, q, c })
    }

    /// The stored (symmetrised) row-major `Q` and the linear term `c`.
    pub fn coefficients(&self) -> (&[f64], &[f64]) {
        (&self.q, &self.c)
    }

    /// Number of binary variables.
    pub fn n(&self) -> usize {
        self.n
    }

    /// `f(b) = bᵀQb + cᵀb`.
    pub fn objective(&self, b: &[bool]) -> f64 {
        let n = self.n;
        let mut f = 0.0;
        for i in 0..n {
            if !b[i] {
                continue;
            }
            f += self.c[i];
            let row = &self.q[i * n..(i + 1) * n];
            for j in 0..n {
                if b[j] {
                    f += row[j];
                }
            }
        }
        f
    }
}

/// Limits and tolerances of [`solve_bqp`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BqpOptions {
    /// Wall-clock limit; `None` = no limit.
    pub time_limit: Option<Duration>,
    /// Maximum number of branch-and-bound nodes; `None` = no limit.
    pub node_limit: Option<u64>,
    /// A node is pruned when its bound is within `max(abs_tol, rel_tol·|incumbent|)` of the
    /// incumbent (when all coefficients are integers, within 1 of it).
    pub abs_tol: f64,
    /// See `abs_tol`.
    pub rel_tol: f64,
    /// Open nodes expanded per round (best bounds first); each starts a dive.
    pub batch: usize,
    /// Nodes per dive (a node and then its nearer child, and so on).
    pub dive_depth: usize,
    /// Run the dives of a round on the rayon pool. The rounds are merged in a fixed order,
    /// so the answer and the node count do not depend on the number of threads.
    pub parallel: bool,
}

impl Default for BqpOptions {
    fn default() -> Self {
        BqpOptions {
            time_limit: None,
            node_limit: None,
            abs_tol: 1e-12,
            rel_tol: 1e-9,
            batch: 4,
            dive_depth: 16,
            parallel: true,
        }
    }
}

/// Outcome of [`solve_bqp`].
#[derive(Debug, Clone, PartialEq)]
pub struct BqpSolution {
    /// Best binary point found.
    pub x: Vec<bool>,
    /// `f(x)`.
    pub objective: f64,
    /// Proven lower bound on the minimum (equal to `objective` when `optimal`).
    pub bound: f64,
    /// Relative gap `(objective − bound) / max(|objective|, |bound|)`, zero when optimal.
    pub gap: f64,
    /// Branch-and-bound nodes processed.
    pub nodes: u64,
    /// Whether the search finished, proving `x` optimal (within the tolerances).
    pub optimal: bool,
    /// Bound proven at the root, before branching (the QCR/SDP bound; the trivial bound
    /// `Σ min(0, ·)` if the clock stopped the root work).
    pub root_bound: f64,
}

/// Internal form: `f(b) = Σ h_i b_i + Σ_{i≠j} W_ij b_i b_j` and its convex reformulation
/// `φ(x) = xᵀ(W + diag(s))x + (h − s)ᵀx` (equal to `f` on binary points).
struct Model {
    n: usize,
    /// Off-diagonal part of `Q` (zero diagonal), row-major.
    w: Vec<f64>,
    /// `Q_ii + c_i`.
    h: Vec<f64>,
    /// Root shift `s`: `W + diag(s)` positive definite.
    s: Vec<f64>,
    /// Nonzeros of each row of `W` (column, value), for the sparse SDP sweeps.
    adj: Vec<Vec<(usize, f64)>>,
    /// Diagonal of the user's `Q`.
    qdiag: Vec<f64>,
    /// Recompute the SDP shift at the nodes (when it won at the root).
    node_sdp: bool,
    /// Positive-definiteness margin of the shifts.
    margin: f64,
    /// All `h_i` and `2 W_ij` are integers, so `f` takes integer values on binary points.
    integral: bool,
    /// Constant term (non-zero in the Lagrangian models of [`triangles`]).
    k0: f64,
}

impl Model {
    fn f(&self, b: &[bool]) -> f64 {
        let n = self.n;
        let mut f = 0.0;
        for i in 0..n {
            if b[i] {
                f += self.h[i];
                let row = &self.w[i * n..(i + 1) * n];
                for j in 0..n {
                    if b[j] {
                        f += row[j];
                    }
                }
            }
        }
        f
    }
}

/// Runs `f` in a function compiled for AVX2 and FMA when the CPU has them (the dense
/// kernels — SDP sweeps, Cholesky, separation — inline into it and vectorise 4-wide:
/// 1.5–2× faster than the baseline x86-64 build), else as it is.
#[inline(always)]
pub(crate) fn with_avx2<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        #[target_feature(enable = "avx2,fma")]
        unsafe fn run<R>(f: impl FnOnce() -> R) -> R {
            f()
        }
        // SAFETY: the CPU supports the features `run` is compiled for.
        return unsafe { run(f) };
    }
    f()
}

/// `Σ a_i b_i` in four partial sums, a dot product the compiler vectorises (inside
/// [`with_avx2`], 4-wide with FMA); the rows of the mixing factor have a stride that is a
/// multiple of 4, so their products have no tail.
#[inline(always)]
pub(crate) fn dot4(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for t in 0..4 {
            acc[t] += x[t] * y[t];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Wall clock and interrupt flag shared by every stage of a solve.
pub(crate) struct Clock {
    start: Instant,
    limit: Option<Duration>,
}

impl Clock {
    fn new(limit: Option<Duration>) -> Self {
        Clock {
            start: Instant::now(),
            limit,
        }
    }

    /// The time limit has passed or the user asked to stop (Ctrl-C).
    pub(crate) fn out(&self) -> bool {
        crate::interrupt::requested() || self.limit.is_some_and(|t| self.start.elapsed() >= t)
    }

    /// Seconds left before the limit (`∞` without one).
    pub(crate) fn remaining_secs(&self) -> f64 {
        match self.limit {
            None => f64::INFINITY,
            Some(t) => (t.as_secs_f64() - self.start.elapsed().as_secs_f64()).max(0.0),
        }
    }
}

/// Plain nodes per variable before the triangle cuts are fitted, below [`CUTS_AT_ROOT_N`]
/// variables (see [`solve_bqp`]).
const CUTS_AFTER: u64 = 2;

/// From this size on the triangle cuts are fitted at the root, before any plain node:
/// on Beasley n = 100 instances the plain trees pass 120–1,000 nodes and are thrown away at
/// the restart (they cost a quarter of the solve), while the OR-Library bqp50 plain trees
/// finish in 5–43 nodes, 20× cheaper than fitting the cuts.
const CUTS_AT_ROOT_N: usize = 64;

/// Below this size the rounds run on the calling thread (same results either way).
const PARALLEL_MIN_N: usize = 64;

/// Free / fixed-to-0 / fixed-to-1 state of a variable in a node.
const FREE: i8 = -1;

#[derive(Clone)]
struct Node {
    fix: Vec<i8>,
    /// Warm start for the relaxation (length `n`, fixed entries equal their values).
    x: Vec<f64>,
    /// Valid lower bound of the node (from its parent until processed).
    bound: f64,
    /// Convexifying shift the node inherits (the root's or an ancestor's SDP shift).
    shift: Arc<Vec<f64>>,
    /// Variables fixed by branching since `shift` was computed.
    stale: u32,
    /// Triangle cuts and multipliers the node inherits (empty: bound on `f` itself).
    cuts: Arc<Vec<(triangles::Cut, f64)>>,
    /// Creation number, for a deterministic order among equal bounds.
    seq: u64,
}

/// Open nodes ordered best (smallest) bound first.
struct Open(Node);

impl PartialEq for Open {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == std::cmp::Ordering::Equal
    }
}
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Open {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        // BinaryHeap is a max-heap: reverse on the bound, then on the creation number.
        o.0.bound
            .total_cmp(&self.0.bound)
            .then_with(|| o.0.seq.cmp(&self.0.seq))
    }
}

/// The trivial bound `Σ min(0, h_i) + Σ_{i≠j} min(0, W_ij)`: finite, needs no work beyond
/// reading the coefficients, and is reported if the clock stops the solve before the root.
fn trivial_bound(model: &Model) -> f64 {
    let neg = |v: &f64| v.min(0.0);
    model.h.iter().map(neg).sum::<f64>() + model.w.iter().map(neg).sum::<f64>()
}

/// What one dive from a node produced.
struct DiveOut {
    /// Nodes left open (the far children along the dive, and the last node if the dive was
    /// cut short), with their bounds.
    open: Vec<Node>,
    /// Best binary point found in the dive.
    best: Option<(f64, Vec<bool>)>,
    nodes: u64,
}

/// Pruning threshold for an incumbent value `u`.
fn cutoff(model: &Model, options: &BqpOptions, u: f64) -> f64 {
    if model.integral {
        u - 1.0 + 1e-6 * u.abs().max(1.0)
    } else {
        u - options.abs_tol.max(options.rel_tol * u.abs())
    }
}

/// Processes `node`, then keeps diving into its nearer child for at most `max_depth`
/// nodes; the incumbent value it prunes against starts at `best_f` and improves with what
/// the dive finds.
fn dive(
    model: &Model,
    options: &BqpOptions,
    clock: &Clock,
    worker: &mut Worker,
    node: Node,
    mut best_f: f64,
    max_depth: usize,
) -> DiveOut {
    let n = model.n;
    let mut out = DiveOut {
        open: Vec::new(),
        best: None,
        nodes: 0,
    };
    let mut scratch_b = vec![false; n];
    let mut current = Some(node);
    let offer = |f: f64, b: &[bool], best_f: &mut f64, out: &mut DiveOut| {
        if f < *best_f {
            *best_f = f;
            out.best = Some((f, b.to_vec()));
        }
    };
    while let Some(node) = current.take() {
        if node.bound >= cutoff(model, options, best_f) {
            break;
        }
        if out.nodes as usize >= max_depth || (out.nodes > 0 && clock.out()) {
            out.open.push(node);
            break;
        }
        out.nodes += 1;
        let Node {
            mut fix,
            x,
            bound,
            seq,
            shift,
            stale,
            cuts,
        } = node;
        heuristic::dominance_fix(model, &mut fix);
        if fix.iter().all(|&v| v != FREE) {
            for i in 0..n {
                scratch_b[i] = fix[i] == 1;
            }
            offer(model.f(&scratch_b), &scratch_b, &mut best_f, &mut out);
            break;
        }
        let lagrangian;
        let parent = (cuts.clone(), shift.clone());
        let (mut bm, mut shift, stale, mut cuts) = if cuts.is_empty() {
            let (shift, stale) = node_shift(model, worker, &fix, shift, stale, clock, false);
            (model, shift, stale, cuts)
        } else {
            // Multipliers re-fitted to the node, kept if its shift can be repaired.
            let fresh = if stale > 0 {
                // New cuts at the nodes cost more than they save (measured: 4× the CPU
                // for similar node counts); the root's cuts are re-weighted only.
                let gap = (best_f - bound).max(0.0);
                let c = triangles::refine(
                    model,
                    &cuts,
                    &fix,
                    &mut worker.mix,
                    triangles::NODE_STEPS,
                    gap,
                    clock,
                );
                let lm = triangles::lagrangian_model(model, &c);
                // `refine` left the node's Lagrangian SDP loaded: sweep on.
                let (sh, st) = node_shift(&lm, worker, &fix, shift.clone(), stale, clock, true);
                let mut c = c;
                c.retain(|(_, gam)| *gam > 0.0);
                (st == 0).then_some((lm, sh, Arc::new(c)))
            } else {
                None
            };
            match fresh {
                Some((lm, sh, c)) => {
                    lagrangian = lm;
                    (&lagrangian, sh, 0, c)
                }
                None => {
                    lagrangian = triangles::lagrangian_model(model, &cuts);
                    (&lagrangian, shift, stale, cuts)
                }
            }
        };
        let mut relax =
            worker
                .qp
                .solve(bm, &shift, &fix, &x, cutoff(model, options, best_f), clock);
        let fallback;
        if !Arc::ptr_eq(&cuts, &parent.0) && relax.bound < bound {
            // The re-fitted multipliers lost against the parent's: bound the node with the
            // parent's (its shift stays valid on the free block) and pass those on.
            fallback = triangles::lagrangian_model(model, &parent.0);
            let again = worker.qp.solve(
                &fallback,
                &parent.1,
                &fix,
                &x,
                cutoff(model, options, best_f),
                clock,
            );
            if again.bound > relax.bound {
                relax = again;
                bm = &fallback;
                (cuts, shift) = parent;
            }
        }
        let node_bound = relax.bound.max(bound);
        if node_bound >= cutoff(model, options, best_f) {
            break;
        }
        // Incumbent: round and descend (cheap compared with the relaxation).
        for i in 0..n {
            scratch_b[i] = relax.x[i] > 0.5;
        }
        heuristic::one_flip_descent(model, &mut scratch_b);
        offer(model.f(&scratch_b), &scratch_b, &mut best_f, &mut out);
        let integral_relax =
            (0..n).all(|i| fix[i] != FREE || (relax.x[i] - relax.x[i].round()).abs() < 1e-9);
        if integral_relax && relax.converged {
            // The relaxation of this node has a binary minimiser: the node is solved when
            // the bounding objective equals `f` there (always without cuts; with them the
            // pruning test below decides).
            for i in 0..n {
                scratch_b[i] = if fix[i] == FREE {
                    relax.x[i] > 0.5
                } else {
                    fix[i] == 1
                };
            }
            offer(model.f(&scratch_b), &scratch_b, &mut best_f, &mut out);
        }
        if clock.out() && !relax.converged {
            // Stopped inside the relaxation: keep the node open with what we know.
            out.open.push(Node {
                fix,
                x: relax.x,
                bound: node_bound,
                seq,
                shift,
                stale,
                cuts,
            });
            break;
        }
        let cut = cutoff(model, options, best_f);
        if node_bound >= cut {
            break;
        }
        // Reduced-cost fixing from the linearisation behind the bound.
        let mut child_lb = vec![[node_bound; 2]; n];
        for i in 0..n {
            if fix[i] != FREE {
                continue;
            }
            let g = relax.grad[i];
            let xi = relax.x[i];
            let term = (-g * xi).min(g * (1.0 - xi));
            let lb0 = relax.bound - term - g * xi;
            let lb1 = relax.bound - term + g * (1.0 - xi);
            child_lb[i] = [lb0.max(node_bound), lb1.max(node_bound)];
        }
        let mut pruned = false;
        for i in 0..n {
            if fix[i] != FREE {
                continue;
            }
            let [l0, l1] = child_lb[i];
            match (l0 >= cut, l1 >= cut) {
                (true, true) => {
                    pruned = true;
                    break;
                }
                (true, false) => fix[i] = 1,
                (false, true) => fix[i] = 0,
                _ => {}
            }
        }
        if pruned {
            break;
        }
        let Some(i) = branch_variable(bm, &shift, &fix, &relax, &child_lb, node_bound) else {
            for k in 0..n {
                scratch_b[k] = fix[k] == 1;
            }
            offer(model.f(&scratch_b), &scratch_b, &mut best_f, &mut out);
            break;
        };
        let mut xw = relax.x;
        for k in 0..n {
            if fix[k] != FREE {
                xw[k] = f64::from(fix[k]);
            }
        }
        let near: i8 = if xw[i] > 0.5 { 1 } else { 0 };
        let child = |v: i8| {
            let mut fx = fix.clone();
            fx[i] = v;
            let mut xc = xw.clone();
            xc[i] = f64::from(v);
            Node {
                fix: fx,
                x: xc,
                bound: child_lb[i][v as usize],
                seq: 0,
                shift: shift.clone(),
                stale: stale + 1,
                cuts: cuts.clone(),
            }
        };
        out.open.push(child(1 - near));
        current = Some(child(near));
    }
    out
}

/// Per-thread state of the dives: relaxation buffers and the SDP factor (warm start).
struct Worker {
    qp: boxqp::BoxQp,
    mix: sdp::Mixing,
    /// Last positive-definite repair of a node shift (first trial of the next).
    repair: f64,
    chol: Vec<f64>,
}

impl Worker {
    fn new(n: usize) -> Self {
        Worker {
            qp: boxqp::BoxQp::new(n),
            mix: sdp::Mixing::with_rank(n, NODE_RANK),
            repair: 0.0,
            chol: Vec::new(),
        }
    }
}

/// Rank of the nodes' mixing factors (the root uses `√(2n)`, the rank at which the
/// low-rank SDP has no spurious local minima). The nodes only polish a warm start and
/// their shifts are validated by the box relaxation, so a lower rank only weakens the node
/// bound a little, and each sweep costs in proportion to the rank. Measured (CPU, loaded,
/// serial) against `√(2n)`: Beasley n = 100 seeds 0–19 and 100–109 plus one permutation
/// of each, 6.51 s / 2,886 nodes against 7.12 s / 2,808 nodes (rank 12: 6.87 s; rank 4:
/// 7.98 s, 4,711 nodes); n = 150 seeds 0–2, 1.56 s against 2.53 s.
const NODE_RANK: usize = 8;

/// Recompute the SDP shift of a node after this many branchings since its shift.
const NODE_SDP_EVERY: u32 = 1;
/// Mixing sweeps per node (warm-started from the worker's last factor).
const NODE_SWEEPS: usize = 40;

/// The shift for a node: its inherited one, or (every [`NODE_SDP_EVERY`] branchings) the
/// QCR shift of the node's own SDP, which accounts for the fixed variables. With `loaded`
/// the worker's mixing factor already holds the SDP of `model` at `fix` (else it is loaded
/// from `model`'s rows).
fn node_shift(
    model: &Model,
    worker: &mut Worker,
    fix: &[i8],
    shift: Arc<Vec<f64>>,
    stale: u32,
    clock: &Clock,
    loaded: bool,
) -> (Arc<Vec<f64>>, u32) {
    let free = fix.iter().filter(|&&v| v == FREE).count();
    if !model.node_sdp || stale < NODE_SDP_EVERY || free < 2 || clock.out() {
        return (shift, stale);
    }
    let mut s = vec![0.0; model.n];
    if loaded {
        let stop = sdp::Stop {
            max_sweeps: NODE_SWEEPS,
            tol: 1e-6,
            clock,
        };
        worker.mix.run(fix, stop, &mut s)
    } else {
        worker
            .mix
            .solve(model, fix, NODE_SWEEPS, 1e-6, clock, &mut s)
    };
    if shift::repair_free(model, &mut s, fix, &mut worker.repair, &mut worker.chol) {
        (Arc::new(s), 0)
    } else {
        (shift, stale)
    }
}

/// Branching variable: the free variable with the largest curvature-weighted fractionality.
fn branch_variable(
    model: &Model,
    shift: &[f64],
    fix: &[i8],
    relax: &boxqp::Relaxation,
    child_lb: &[[f64; 2]],
    node_bound: f64,
) -> Option<usize> {
    let n = model.n;
    let mut pick = None;
    let mut pick_score = f64::NEG_INFINITY;
    for i in 0..n {
        if fix[i] != FREE {
            continue;
        }
        let xi = relax.x[i];
        let frac = xi.min(1.0 - xi).max(0.0);
        let [l0, l1] = child_lb[i];
        // Weight by the variable's own curvature: in Eq 4.12 it is the squared chord
        // between the two candidates, so near-tangent frames (short chords, little effect
        // on the cost) are branched on last. This cut the nodes on articulated programs
        // from real mocap by 10–1000× against plain most-fractional.
        let weight = shift[i].abs().max(f64::MIN_POSITIVE);
        let score = frac * weight + 1e-12 * (l0.min(l1) - node_bound);
        if score > pick_score {
            pick_score = score;
            pick = Some(i);
        }
    }
    pick
}

/// Solves `min bᵀQb + cᵀb` over `b ∈ {0,1}ⁿ` exactly by branch-and-bound (see the module
/// docs), or up to the limits in `options`.
pub fn solve_bqp(problem: &BqpProblem, options: &BqpOptions) -> Result<BqpSolution> {
    if let Some(t) = options.time_limit {
        if t.is_zero() {
            return Err(Error::invalid("time_limit", "must be positive"));
        }
    }
    if !(options.abs_tol >= 0.0 && options.rel_tol >= 0.0) {
        return Err(Error::invalid("abs_tol/rel_tol", "must be non-negative"));
    }
    if options.batch == 0 || options.dive_depth == 0 {
        return Err(Error::invalid("batch/dive_depth", "must be at least 1"));
    }
    let clock = Clock::new(options.time_limit);
    let n = problem.n;
    if n == 0 {
        return Ok(BqpSolution {
            x: vec![],
            objective: 0.0,
            bound: 0.0,
            gap: 0.0,
            nodes: 0,
            optimal: true,
            root_bound: 0.0,
        });
    }
    let mut w = problem.q.clone();
    let mut h = problem.c.clone();
    let qdiag: Vec<f64> = (0..n).map(|i| w[i * n + i]).collect();
    for i in 0..n {
        h[i] += w[i * n + i];
        w[i * n + i] = 0.0;
    }
    let is_int = |v: f64| (v - v.round()).abs() <= 1e-12 * v.abs().max(1.0);
    let integral = h.iter().all(|&v| is_int(v)) && w.iter().all(|&v| is_int(2.0 * v));
    let mut model = Model {
        n,
        s: vec![0.0; n],
        margin: 0.0,
        node_sdp: false,
        k0: 0.0,
        adj: (0..n)
            .map(|i| {
                (0..n)
                    .filter(|&j| w[i * n + j] != 0.0)
                    .map(|j| (j, w[i * n + j]))
                    .collect()
            })
            .collect(),
        w,
        h,
        qdiag,
        integral,
    };
    let trivial = trivial_bound(&model);
    let fro = model.w.iter().map(|v| v * v).sum::<f64>().sqrt()
        + model.h.iter().map(|v| v * v).sum::<f64>().sqrt();
    model.margin = 1e-7 * if fro > 0.0 { fro } else { 1.0 };

    // Incumbent from the root: tabu search from zero (deterministic).
    let mut best_x = vec![false; n];
    let mut best_f = model.f(&best_x);
    let tabu = heuristic::tabu_search(&model, &best_x, 20 * n + 200, &clock);
    let tf = model.f(&tabu);
    if tf < best_f {
        best_f = tf;
        best_x = tabu;
    }
    crate::interrupt::check()?;

    // Convexifying shift (QCR from the SDP), tuned on the root relaxation.
    let root_cut = cutoff(&model, options, best_f);
    let mut mix = sdp::Mixing::new(n);
    let (mut root_bound, node_sdp) =
        shift::choose_shift(&mut model, &clock, root_cut, &mut mix, false);
    model.node_sdp = node_sdp;
    crate::interrupt::check()?;
    // Triangle cuts (Lagrangian) when the SDP bound does not close the root and `Q` is
    // not positive semidefinite. On convex programs (Eq 4.12 is a least-squares cost) the
    // plain trees are small and the cuts cost more than they save: measured on the
    // articulated bench instances, 0.90 s CPU with cuts against 0.33 s without.
    // Below `CUTS_AT_ROOT_N` variables they are fitted only once the plain tree has used
    // `CUTS_AFTER · n` nodes (then the search restarts from the root with them): small
    // trees (OR-Library bqp50, 5–43 nodes) finish first, at a twentieth of the cost of
    // fitting the cuts.
    let convex = || {
        clock.remaining_secs() < 3.0 * shift::eig_seconds(n)
            || shift::min_eigenvalue(&model, &model.qdiag).map_or(true, |l| l >= -model.margin)
    };
    let plain_root = root_bound;
    let cuts_after = if n >= CUTS_AT_ROOT_N {
        0
    } else {
        CUTS_AFTER * n as u64
    };
    let mut cuts_pending = node_sdp && root_bound < root_cut && !clock.out() && !convex();
    root_bound = root_bound.max(trivial);

    let mut heap = std::collections::BinaryHeap::new();
    let mut seq: u64 = 0;
    heap.push(Open(Node {
        fix: vec![FREE; n],
        x: vec![0.5; n],
        bound: trivial,
        seq,
        shift: Arc::new(model.s.clone()),
        stale: 0,
        cuts: Arc::new(Vec::new()),
    }));
    let mut nodes: u64 = 0;
    let mut solvers: Vec<Worker> = Vec::new();
    let mut interrupted = false;
    loop {
        if cuts_pending && nodes >= cuts_after && !clock.out() {
            cuts_pending = false;
            if let Some((cuts, b, shift)) = triangles::strengthen(
                &model,
                &clock,
                best_f,
                plain_root,
                &mut mix,
                options.parallel && n >= PARALLEL_MIN_N,
            ) {
                // The shift of the ascent's best evaluation (already repaired and bounded:
                // `b` is valid). Re-solving the SDP of the final multipliers from a fresh
                // factor (up to 300 sweeps) cost a quarter of the root's sweeps for no fewer
                // nodes: Beasley n = 100 seeds 0–19 and 100–109, 1,573 → 1,379 nodes and
                // 14 % less CPU; n = 150 seeds 0–5, 1,767 → 1,634 nodes.
                let mut lm = triangles::lagrangian_model(&model, &cuts);
                lm.s = shift;
                if b > plain_root {
                    root_bound = root_bound.max(b);
                    heap.clear();
                    seq += 1;
                    heap.push(Open(Node {
                        fix: vec![FREE; n],
                        x: vec![0.5; n],
                        bound: plain_root.max(trivial),
                        seq,
                        shift: Arc::new(lm.s),
                        stale: 0,
                        cuts: Arc::new(cuts),
                    }));
                }
            }
            crate::interrupt::check()?;
        }
        // Drop what the incumbent prunes; stop when nothing is left.
        let cut = cutoff(&model, options, best_f);
        let mut batch = Vec::with_capacity(options.batch);
        while batch.len() < options.batch {
            match heap.pop() {
                Some(Open(nd)) if nd.bound < cut => batch.push(nd),
                Some(_) => continue,
                None => break,
            }
        }
        if batch.is_empty() {
            break;
        }
        let over_nodes = options.node_limit.is_some_and(|m| nodes >= m);
        if over_nodes || (nodes > 0 && clock.out()) {
            heap.extend(batch.into_iter().map(Open));
            interrupted = true;
            break;
        }
        let depth = match options.node_limit {
            Some(m) => (options.dive_depth as u64).min((m - nodes).max(1)) as usize,
            None => options.dive_depth,
        };
        while solvers.len() < batch.len() {
            solvers.push(Worker::new(n));
        }
        let incumbent = best_f;
        let run = |(nd, solver): (Node, &mut Worker)| {
            dive(&model, options, &clock, solver, nd, incumbent, depth)
        };
        // Small problems: a dive takes microseconds, less than handing it to another thread.
        let outs: Vec<DiveOut> = if options.parallel && batch.len() > 1 && n >= PARALLEL_MIN_N {
            use rayon::prelude::*;
            batch
                .into_par_iter()
                .zip(solvers.par_iter_mut())
                .map(run)
                .collect()
        } else {
            batch.into_iter().zip(solvers.iter_mut()).map(run).collect()
        };
        // Merge in batch order: the result does not depend on thread timing.
        for o in outs {
            nodes += o.nodes;
            if let Some((f, b)) = o.best {
                if f < best_f {
                    best_f = f;
                    best_x = b;
                }
            }
            for mut nd in o.open {
                seq += 1;
                nd.seq = seq;
                heap.push(Open(nd));
            }
        }
        if crate::interrupt::requested() {
            return Err(Error::Interrupted);
        }
    }

    let (bound, optimal) = if interrupted {
        let open = heap
            .iter()
            .map(|nd| nd.0.bound)
            .fold(f64::INFINITY, f64::min);
        (open.max(trivial).min(best_f), false)
    } else {
        (best_f, true)
    };
    let objective = problem.objective(&best_x);
    // `best_f` and `objective` may differ in the last bits (summation order).
    let bound = if optimal {
        objective
    } else {
        bound.min(objective)
    };
    let gap = if objective <= bound {
        0.0
    } else {
        (objective - bound) / objective.abs().max(bound.abs()).max(f64::MIN_POSITIVE)
    };
    Ok(BqpSolution {
        x: best_x,
        objective,
        bound,
        gap,
        nodes,
        optimal,
        root_bound: root_bound.min(objective),
    })
}

#[cfg(test)]
mod tests;
