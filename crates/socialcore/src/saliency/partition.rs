//! [`Membership::Partition`](super::Membership::Partition): every ray belongs to at most
//! one charge, and the set of charges is the partition of the rays that the gaze model of
//! Sec 3.1 explains best.
//!
//! The model: a member of a charge at `x` misses it by a perspective distance `d` (Eq 6.2)
//! drawn from `N(0, h² I₂)`; a ray that belongs to no charge points anywhere (uniform on
//! the sphere). A ray therefore gains `ln(2/h²) − ½‖d/h‖²` (nats) by joining a charge
//! instead of being left out. A charge costs the Occam factor of its position, uniform
//! over a prior volume `V` (the `bounds` box, else a cube of side `depth_max`):
//! `ln V − 3/2 ln 2π + ½ ln det A`, with `A = Σᵢ (I − vᵢvᵢᵀ)/(sᵢ²hᵢ²)` the information
//! of its members about `x` (Laplace approximation of the evidence). Both scale with the
//! bandwidths and with the distances, so a pair of wide rays far away is accepted on the
//! same terms as a tight group of six near by.
//!
//! The search starts from the modes of the mean-shift (Eq 6.7) and adds or removes one
//! candidate at a time while the score grows. For a candidate set, hard EM runs to a
//! fixed point: every ray goes to the charge where it gains most (or to none), a charge
//! left with fewer than `min_members` rays is dropped, and every charge is re-estimated as
//! the intersection of its members' rays that minimises `Σ‖d/h‖²` (least squares with
//! weights `1/h²`, the oracle form, then reweighted by `1/s²` at the current depths).

use super::modes::{q_of, Charge, ModeOptions};
use super::GazeRays;
use crate::error::Result;
use nalgebra::{Matrix3, Vector3};

/// Iterations of the hard EM of one candidate set.
const EM_ITERATIONS: usize = 20;
/// Most reweighting iterations of the intersection (`1/(s²h²)` weights); they stop
/// earlier when the estimate moves less than [`FIT_TOL`] metres.
const REWEIGHTINGS: usize = 20;
const FIT_TOL: f64 = 1e-9;
/// Smallest depth (metres) used for a ray's weight when the starting point is closer to
/// its eye or behind it.
const MIN_FIT_DEPTH: f64 = 0.1;
/// Condition number above which the members' rays have no single intersection.
const MAX_CONDITION: f64 = 1e10;

/// The intersection of rays `members` minimising `Σ ‖perp‖²/(s²h²)`, the depths `s`
/// taken from `start` (at least [`MIN_FIT_DEPTH`]) and then from each new estimate, or
/// `None` if the rays are (nearly) parallel.
pub(super) fn intersection(
    rays: &GazeRays,
    members: &[usize],
    start: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    // Weighted least squares: `Σ wₖ (I − vvᵀ)(x − p) = 0`, `wₖ` aligned with `members`.
    let solve = |w: &[f64]| -> Option<Vector3<f64>> {
        let mut a = Matrix3::zeros();
        let mut b = Vector3::zeros();
        for (&i, &wk) in members.iter().zip(w) {
            let v = &rays.v[i];
            let proj = (Matrix3::identity() - v * v.transpose()) * wk;
            a += proj;
            b += proj * rays.p[i];
        }
        let eig = a.symmetric_eigenvalues();
        let (lo, hi) = (eig.min(), eig.max());
        if !(lo > 0.0 && hi <= MAX_CONDITION * lo) {
            return None;
        }
        a.cholesky().map(|c| c.solve(&b))
    };
    let w: Vec<f64> = members
        .iter()
        .map(|&i| {
            let s = (start - rays.p[i]).dot(&rays.v[i]).max(MIN_FIT_DEPTH);
            rays.inv_h2[i] / (s * s)
        })
        .collect();
    let mut x = solve(&w)?;
    for _ in 0..REWEIGHTINGS {
        let w: Option<Vec<f64>> = members
            .iter()
            .map(|&i| {
                let s = (x - rays.p[i]).dot(&rays.v[i]);
                (s > 0.0).then(|| rays.inv_h2[i] / (s * s))
            })
            .collect();
        match w.and_then(|w| solve(&w)) {
            Some(xn) => {
                let moved = (xn - x).norm();
                x = xn;
                if moved < FIT_TOL {
                    break;
                }
            }
            None => break,
        }
    }
    Some(x)
}

/// Score of one charge at `x` with `members`: what the members gain over being left out
/// minus the Occam cost of the charge (see the module docs).
fn charge_score(
    rays: &GazeRays,
    x: &Vector3<f64>,
    members: &[usize],
    occam0: f64,
    prior: f64,
) -> f64 {
    let mut gain = 0.0;
    let mut info = Matrix3::zeros();
    for &i in members {
        let v = &rays.v[i];
        let s = (x - rays.p[i]).dot(v);
        gain += bonus(rays, i, prior) - 0.5 * q_of(rays, i, x);
        info += (Matrix3::identity() - v * v.transpose()) * (rays.inv_h2[i] / (s * s));
    }
    let det = info.determinant();
    if !(det > 0.0 && gain.is_finite()) {
        return f64::NEG_INFINITY;
    }
    gain - occam0 - 0.5 * det.ln()
}

/// `ln(2/h²) + ln((1 − u)/u)` (`u` = [`ModeOptions::unattended`]): log posterior ratio of
/// a ray pointing exactly at a charge against a ray pointing anywhere.
fn bonus(rays: &GazeRays, i: usize, prior: f64) -> f64 {
    (2.0 * rays.inv_h2[i]).ln() + prior
}

/// A partition of the rays among some of the candidates.
#[derive(Clone)]
struct State {
    score: f64,
    /// `(candidate, position)` of each charge.
    charges: Vec<(usize, Vector3<f64>)>,
    /// The charge (index into `charges`) of every ray, `None` if it belongs to none.
    owner: Vec<Option<usize>>,
}

struct Search<'a> {
    rays: &'a GazeRays,
    start: Vec<Vector3<f64>>,
    opts: &'a ModeOptions,
    occam0: f64,
    /// `ln((1 − u)/u)`.
    prior: f64,
}

impl Search<'_> {
    fn inside(&self, x: &Vector3<f64>) -> bool {
        self.opts.bounds.as_ref().map_or(true, |(lo, hi)| {
            (0..3).all(|a| x[a] >= lo[a] && x[a] <= hi[a])
        })
    }

    /// Hard EM from the candidates `alive` to a fixed point, and its score.
    fn evaluate(&self, alive: &[bool]) -> State {
        let rays = self.rays;
        let n = rays.len();
        let mut xs: Vec<(usize, Vector3<f64>)> = (0..alive.len())
            .filter(|&c| alive[c])
            .map(|c| (c, self.start[c]))
            .collect();
        let mut owner: Option<Vec<Option<usize>>> = None;
        for _ in 0..EM_ITERATIONS {
            if xs.is_empty() {
                owner = None;
                break;
            }
            let assign: Vec<Option<usize>> = (0..n)
                .map(|i| {
                    let mut best: Option<(usize, f64)> = None;
                    for (k, (_, x)) in xs.iter().enumerate() {
                        let l = bonus(rays, i, self.prior) - 0.5 * q_of(rays, i, x);
                        if l > 0.0 && best.map_or(true, |(_, b)| l > b) {
                            best = Some((k, l));
                        }
                    }
                    best.map(|(k, _)| k)
                })
                .collect();
            let mut count = vec![0usize; xs.len()];
            assign.iter().flatten().for_each(|&k| count[k] += 1);
            // Drop the charge with the fewest rays (the first of them) and reassign.
            if let Some(k) = (0..xs.len())
                .filter(|&k| count[k] < self.opts.min_members)
                .min_by_key(|&k| count[k])
            {
                xs.remove(k);
                continue;
            }
            if owner.as_ref() == Some(&assign) {
                break;
            }
            let mut refit = Vec::with_capacity(xs.len());
            let mut failed = None;
            for (k, &(c, x0)) in xs.iter().enumerate() {
                let members: Vec<usize> = (0..n).filter(|&i| assign[i] == Some(k)).collect();
                match intersection(rays, &members, &x0) {
                    Some(x)
                        if self.inside(&x)
                            && members
                                .iter()
                                .all(|&i| (x - rays.p[i]).dot(&rays.v[i]) > 0.0) =>
                    {
                        refit.push((c, x))
                    }
                    _ => {
                        failed = Some(k);
                        break;
                    }
                }
            }
            match failed {
                Some(k) => {
                    xs.remove(k);
                    owner = None;
                }
                None => {
                    xs = refit;
                    owner = Some(assign);
                }
            }
        }
        let owner = owner.unwrap_or_else(|| vec![None; n]);
        let mut score = 0.0;
        for (k, (_, x)) in xs.iter().enumerate() {
            let members: Vec<usize> = (0..n).filter(|&i| owner[i] == Some(k)).collect();
            if members.len() >= self.opts.min_members {
                score += charge_score(rays, x, &members, self.occam0, self.prior);
            }
        }
        State {
            score,
            charges: xs,
            owner,
        }
    }
}

/// [`Membership::Partition`](super::Membership::Partition) on the candidate modes
/// (strongest first): stepwise selection of the candidates, then the charges of the best
/// partition at the intersections of their members.
pub(super) fn partition(
    rays: &GazeRays,
    candidates: Vec<Charge>,
    opts: &ModeOptions,
) -> Result<Vec<Charge>> {
    let volume = match &opts.bounds {
        Some((lo, hi)) => (hi - lo).iter().map(|e| e.max(1e-3)).product::<f64>(),
        None => opts.depth_max.powi(3),
    };
    let search = Search {
        rays,
        start: candidates.iter().map(|c| c.position).collect(),
        opts,
        occam0: volume.ln() - 1.5 * std::f64::consts::TAU.ln(),
        prior: ((1.0 - opts.unattended) / opts.unattended).ln(),
    };
    let mut alive = vec![false; candidates.len()];
    let mut state = State {
        score: 0.0,
        charges: Vec::new(),
        owner: vec![None; rays.len()],
    };
    // Each step strictly raises the score, so this ends; the cap is a guard. Single
    // toggles first; when none helps, pairs of toggles (a swap of one charge for another,
    // or two charges that only pay off together).
    for _ in 0..4 * candidates.len() + 4 {
        crate::interrupt::check()?;
        let mut best: Option<(Vec<usize>, State)> = None;
        let consider =
            |alive: &mut Vec<bool>, flip: &[usize], best: &mut Option<(Vec<usize>, State)>| {
                flip.iter().for_each(|&c| alive[c] = !alive[c]);
                let st = search.evaluate(alive);
                flip.iter().for_each(|&c| alive[c] = !alive[c]);
                if best.as_ref().map_or(true, |(_, b)| st.score > b.score) {
                    *best = Some((flip.to_vec(), st));
                }
            };
        for c in 0..alive.len() {
            consider(&mut alive, &[c], &mut best);
        }
        if !best
            .as_ref()
            .is_some_and(|(_, st)| st.score > state.score + 1e-9)
        {
            for a in 0..alive.len() {
                crate::interrupt::check()?;
                for b in a + 1..alive.len() {
                    consider(&mut alive, &[a, b], &mut best);
                }
            }
        }
        match best {
            Some((flip, st)) if st.score > state.score + 1e-9 => {
                flip.iter().for_each(|&c| alive[c] = !alive[c]);
                state = st;
            }
            _ => break,
        }
    }
    let n = rays.len();
    let mut out = Vec::with_capacity(state.charges.len());
    for (k, (c, x)) in state.charges.iter().enumerate() {
        let members: Vec<usize> = (0..n).filter(|&i| state.owner[i] == Some(k)).collect();
        if members.len() < opts.min_members {
            continue;
        }
        let mut ch = candidates[*c].clone();
        ch.position = *x;
        ch.members = members;
        super::modes::refresh_field_terms(rays, &mut ch);
        out.push(ch);
    }
    Ok(out)
}
