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
    /// Row stride of `v`: the rank rounded up to a multiple of 4, the extra columns zero
    /// (they stay zero: same iterates as without them, in whole 4-wide vectors).
    pub(crate) k: usize,
    pub(crate) v: Vec<f64>,
    g: Vec<f64>,
    /// `C_0i` of the current node (zero for fixed `i`).
    lin: Vec<f64>,
    /// The free-free part of `C` of the current node, compressed by rows (`start`, then
    /// column and value `W_ij / 4`): built once per solve, so the sweeps run without
    /// testing which variables are fixed.
    start: Vec<usize>,
    col: Vec<u32>,
    val: Vec<f64>,
    /// The part of `val` from the rows `adj` of the last load (the extra entries added on
    /// top of it by [`Mixing::reweight`]).
    base_val: Vec<f64>,
    /// Per free row, from `adj` only: `W_ij` for every free `j`, `2 W_ij` for every `j`
    /// fixed to one (in row order, starting at `base_start[i]`), summed onto `h_i` by
    /// [`Mixing::reweight`] in the order a full load would.
    base_terms: Vec<f64>,
    base_start: Vec<usize>,
    /// Scratch of [`Mixing::load`]: position of a column in the row being built.
    pos: Vec<u32>,
    ext: Extra,
}

/// When [`Mixing::run`] stops: after `max_sweeps`, a relative change below `tol` over a
/// sweep, or the clock.
pub(crate) struct Stop<'a> {
    pub max_sweeps: usize,
    pub tol: f64,
    pub clock: &'a Clock,
}

/// Extra pair entries bucketed by row (scratch of [`Mixing::load`]), and where each one
/// lands in the compressed rows (for [`Mixing::reweight`]).
#[derive(Default)]
struct Extra {
    start: Vec<usize>,
    fill: Vec<usize>,
    /// Per row: (column, `2e` or `2e + 1` for the entry `e` read from its first or second
    /// variable's row).
    entries: Vec<(u32, u32)>,
    /// For `2e` (row `a` of the entry `(a, b, w)`) and `2e + 1` (row `b`): the slot in
    /// `col`/`val`, or [`ONE_SLOT`] (the other variable is fixed to one: the entry goes to
    /// the linear row), or [`NO_SLOT`] (this row is fixed or the other variable is zero).
    slot: Vec<u32>,
}

const NO_SLOT: u32 = u32::MAX;
const ONE_SLOT: u32 = u32::MAX - 1;

impl Mixing {
    /// Random unit rows (fixed seed), rank `⌈√(2(n+1))⌉ + 1`.
    pub fn new(n: usize) -> Self {
        let m = n + 1;
        let rank = ((2.0 * m as f64).sqrt().ceil() as usize + 1).min(m).max(2);
        Self::with_rank(n, rank)
    }

    /// Random unit rows (fixed seed) of the given rank.
    pub fn with_rank(n: usize, rank: usize) -> Self {
        let m = n + 1;
        let rank = rank.min(m).max(2);
        let k = rank.div_ceil(4) * 4;
        let mut rng = ChaCha8Rng::seed_from_u64(0x05ee_db0b);
        let mut v = vec![0.0; m * k];
        for r in v.chunks_mut(k) {
            let r = &mut r[..rank];
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
            start: Vec::with_capacity(n + 1),
            col: Vec::new(),
            val: Vec::new(),
            base_val: Vec::new(),
            base_terms: Vec::new(),
            base_start: Vec::new(),
            pos: Vec::new(),
            ext: Extra::default(),
        }
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
        debug_assert_eq!(
            model.adj.len(),
            model.n,
            "the model's sparse rows are built"
        );
        self.load(&model.h, &model.adj, &[], fix);
        self.run(
            fix,
            Stop {
                max_sweeps,
                tol,
                clock,
            },
            s,
        )
    }

    /// Loads the SDP of the node `fix` of `f(b) = Σ h_i b_i + Σ_{i≠j} W_ij b_i b_j`, with
    /// `W` given by the rows `adj` plus `extra` entries `(a, b, w)`, each adding `w` to
    /// `W_ab` and `W_ba` (the pair terms of Lagrangian cuts: no dense matrix is built).
    /// The compressed rows keep a slot for every extra entry, so that
    /// [`Mixing::reweight`] can change `h` and the extra weights in place.
    pub(crate) fn load(
        &mut self,
        h: &[f64],
        adj: &[Vec<(usize, f64)>],
        extra: &[(usize, usize, f64)],
        fix: &[i8],
    ) {
        let n = h.len();
        // The extra entries bucketed by row (both directions), with their index.
        let ext = &mut self.ext;
        ext.start.clear();
        ext.start.resize(n + 1, 0);
        for &(a, b, _) in extra {
            ext.start[a + 1] += 1;
            ext.start[b + 1] += 1;
        }
        for i in 0..n {
            ext.start[i + 1] += ext.start[i];
        }
        ext.entries.resize(2 * extra.len(), (0, 0));
        ext.fill.clear();
        ext.fill.extend_from_slice(&ext.start[..n]);
        for (e, &(a, b, _)) in extra.iter().enumerate() {
            ext.entries[ext.fill[a]] = (b as u32, 2 * e as u32);
            ext.fill[a] += 1;
            ext.entries[ext.fill[b]] = (a as u32, 2 * e as u32 + 1);
            ext.fill[b] += 1;
        }
        ext.slot.clear();
        ext.slot.resize(2 * extra.len(), NO_SLOT);
        self.start.clear();
        self.col.clear();
        self.base_val.clear();
        self.base_terms.clear();
        self.base_start.clear();
        self.pos.resize(n, NO_SLOT);
        for i in 0..n {
            self.start.push(self.col.len());
            self.base_start.push(self.base_terms.len());
            if fix[i] != FREE {
                continue;
            }
            let row0 = self.col.len();
            let mut slot_of = |j: usize, col: &mut Vec<u32>, val: &mut Vec<f64>| {
                let p = self.pos[j];
                if p == NO_SLOT {
                    self.pos[j] = col.len() as u32;
                    col.push(j as u32);
                    val.push(0.0);
                    col.len() as u32 - 1
                } else {
                    p
                }
            };
            for &(j, w) in &adj[i] {
                match fix[j] {
                    FREE => {
                        self.base_terms.push(w);
                        let p = slot_of(j, &mut self.col, &mut self.base_val);
                        self.base_val[p as usize] += 0.25 * w;
                    }
                    1 => self.base_terms.push(2.0 * w),
                    _ => {}
                }
            }
            for &(j, code) in &ext.entries[ext.start[i]..ext.start[i + 1]] {
                ext.slot[code as usize] = match fix[j as usize] {
                    FREE => slot_of(j as usize, &mut self.col, &mut self.base_val),
                    1 => ONE_SLOT,
                    _ => NO_SLOT,
                };
            }
            for &j in &self.col[row0..] {
                self.pos[j as usize] = NO_SLOT;
            }
        }
        self.start.push(self.col.len());
        self.base_start.push(self.base_terms.len());
        self.reweight(h, extra, fix);
    }

    /// Changes the linear term to `h` and the extra weights to those of `extra` (the same
    /// pairs, in the same order, as at the last [`Mixing::load`], on the same node `fix`)
    /// without rebuilding the rows: O(nonzeros + extra entries).
    pub(crate) fn reweight(&mut self, h: &[f64], extra: &[(usize, usize, f64)], fix: &[i8]) {
        let n = h.len();
        debug_assert_eq!(2 * extra.len(), self.ext.slot.len());
        self.val.clear();
        self.val.extend_from_slice(&self.base_val);
        for i in 0..n {
            let terms = &self.base_terms[self.base_start[i]..self.base_start[i + 1]];
            self.lin[i] = if fix[i] == FREE {
                terms.iter().fold(h[i], |acc, t| acc + t)
            } else {
                0.0
            };
        }
        for (e, &(a, b, w)) in extra.iter().enumerate() {
            for (row, code) in [(a, self.ext.slot[2 * e]), (b, self.ext.slot[2 * e + 1])] {
                match code {
                    NO_SLOT => {}
                    ONE_SLOT => self.lin[row] += 2.0 * w,
                    p => {
                        self.val[p as usize] += 0.25 * w;
                        self.lin[row] += w;
                    }
                }
            }
        }
        for l in &mut self.lin {
            *l *= 0.25;
        }
    }

    /// Sweeps on the loaded SDP (see [`Mixing::solve`]).
    pub(crate) fn run(&mut self, fix: &[i8], stop: Stop, s: &mut [f64]) -> usize {
        let n = self.lin.len();
        // The sweeps are k-wide axpys: vectorised by `with_avx2`, with the gradient held in
        // registers for the usual ranks.
        super::with_avx2(|| match self.k {
            4 => self.sweeps::<4>(n, fix, &stop, s),
            8 => self.sweeps::<8>(n, fix, &stop, s),
            12 => self.sweeps::<12>(n, fix, &stop, s),
            16 => self.sweeps::<16>(n, fix, &stop, s),
            20 => self.sweeps::<20>(n, fix, &stop, s),
            24 => self.sweeps::<24>(n, fix, &stop, s),
            28 => self.sweeps::<28>(n, fix, &stop, s),
            32 => self.sweeps::<32>(n, fix, &stop, s),
            _ => self.sweeps::<0>(n, fix, &stop, s),
        })
    }

    /// Calls `axpy(C_ij, j)` for every nonzero `C_ij` of the free row `i` (or the
    /// homogenising row `i = n`), the homogenising column first.
    #[inline(always)]
    fn for_row(&self, n: usize, i: usize, mut axpy: impl FnMut(f64, usize)) {
        if i == n {
            for (j, &c) in self.lin.iter().enumerate() {
                if c != 0.0 {
                    axpy(c, j);
                }
            }
        } else {
            axpy(self.lin[i], n);
            let (a, b) = (self.start[i], self.start[i + 1]);
            for (&j, &c) in self.col[a..b].iter().zip(&self.val[a..b]) {
                axpy(c, j as usize);
            }
        }
    }

    /// `g = Σ_j C_ij v_j` for the free row `i` (or the homogenising row `i = n`) into
    /// `self.g`; returns `|g|`. `K` is the row stride (the gradient then lives in
    /// registers), or 0 for the run-time `self.k`.
    #[inline(always)]
    fn row_gradient<const K: usize>(&mut self, n: usize, i: usize) -> f64 {
        let v = &self.v;
        if K == 0 {
            let k = self.k;
            let mut g = std::mem::take(&mut self.g);
            g.fill(0.0);
            self.for_row(n, i, |c, j| {
                for (ga, va) in g.iter_mut().zip(&v[j * k..(j + 1) * k]) {
                    *ga += c * va;
                }
            });
            let norm = g.iter().map(|a| a * a).sum::<f64>().sqrt();
            self.g = g;
            return norm;
        }
        let mut g = [0.0f64; K];
        self.for_row(n, i, |c, j| {
            let vj: &[f64; K] = v[j * K..(j + 1) * K].try_into().expect("stride K");
            for t in 0..K {
                g[t] += c * vj[t];
            }
        });
        self.g[..K].copy_from_slice(&g);
        g.iter().map(|a| a * a).sum::<f64>().sqrt()
    }

    #[inline(always)]
    fn sweeps<const K: usize>(
        &mut self,
        n: usize,
        fix: &[i8],
        stop: &Stop,
        s: &mut [f64],
    ) -> usize {
        let Stop {
            max_sweeps,
            tol,
            clock,
        } = *stop;
        let k = self.k;
        let mut prev = f64::INFINITY;
        let mut sweeps = 0;
        while sweeps < max_sweeps {
            sweeps += 1;
            let mut obj = 0.0;
            for i in 0..=n {
                if i < n && fix[i] != FREE {
                    continue;
                }
                let norm = self.row_gradient::<K>(n, i);
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
                4.0 * self.row_gradient::<K>(n, i)
            } else {
                0.0
            };
        }
        sweeps
    }
}
