//! [`Membership::Partition`](super::Membership::Partition): every ray belongs to at most
//! one charge, and the set of charges is the partition of the rays that the gaze model of
//! Sec 3.1 explains best.
//!
//! The model: a member of a charge at `x` misses it by a perspective distance `d` (Eq 6.2)
//! drawn from `N(0, h² I₂)`; a ray that belongs to no charge points anywhere (uniform on
//! the sphere); a ray attends one of the `K` charges with prior `(1 − u)/K` (the mixture
//! weights of the gaze model, Eq 7.7, taken equal). A ray therefore gains
//! `ln(2/h²) + ln((1 − u)/u) − ln K − ½‖d/h‖²` (nats) by joining a charge instead of
//! being left out: splitting a group costs every attending ray `ln((K+1)/K)`. A charge costs the Occam factor of its position, uniform
//! over a prior volume `V` (the `bounds` box, else a cube of side `depth_max`):
//! `ln V − 3/2 ln 2π + ½ ln det A`, with `A = Σᵢ (I − vᵢvᵢᵀ)/(sᵢ²hᵢ²)` the information
//! of its members about `x` (Laplace approximation of the evidence). Both scale with the
//! bandwidths and with the distances, so a pair of wide rays far away is accepted on the
//! same terms as a tight group of six near by.
//!
//! In a sequence ([`ModeOptions::pool_frames`](super::ModeOptions::pool_frames)) the
//! uniform prior of a charge's position is replaced by a mixture: half of the mass stays
//! uniform (a new charge), half sits on the charges the frame-by-frame pass found in the
//! neighbouring frames, each a Gaussian of its own uncertainty plus a random-walk drift;
//! the Laplace evidence then uses that density convolved with the members' posterior.
//!
//! The search starts from the modes of the mean-shift (Eq 6.7) and the pooled charges,
//! and adds or removes one
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

/// One Gaussian term of a charge's position prior: a charge of a neighbouring frame
/// ([`ModeOptions::pool_frames`]) at `centre` with covariance `cov` (its own uncertainty
/// plus the drift allowed since), carrying prior mass `weight`.
#[derive(Debug, Clone)]
pub(super) struct PriorTerm {
    pub centre: Vector3<f64>,
    pub cov: Matrix3<f64>,
    pub weight: f64,
}

/// The prior over the position of one charge: mass `uniform` spread evenly over the prior
/// volume, the rest on the [`PriorTerm`]s. Without terms it is the uniform prior alone.
#[derive(Debug, Clone, Default)]
pub(super) struct Prior {
    pub terms: Vec<PriorTerm>,
}

/// Share of the prior mass on "a charge that was not there in the neighbouring frames":
/// a new charge and a persisting one are a priori equally likely.
const NEW_CHARGE_MASS: f64 = 0.5;

impl Prior {
    /// `ln p(x)` of the Laplace evidence: the prior density convolved with the posterior
    /// of the charge's members (information `info`), `ln[(u/V) + Σ w N(x; c, C + info⁻¹)]`,
    /// with `u` = 1 when there are no terms.
    fn ln_density(&self, x: &Vector3<f64>, info: &Matrix3<f64>, ln_volume: f64) -> f64 {
        if self.terms.is_empty() {
            return -ln_volume;
        }
        let post = info.try_inverse().unwrap_or_else(Matrix3::zeros);
        let mut logs = vec![NEW_CHARGE_MASS.ln() - ln_volume];
        for t in &self.terms {
            let c = t.cov + post;
            let (Some(chol), true) = (c.cholesky(), t.weight > 0.0) else {
                continue;
            };
            let r = x - t.centre;
            let m = r.dot(&chol.solve(&r));
            let ln_det = 2.0 * chol.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
            logs.push(t.weight.ln() - 0.5 * (m + ln_det) - 1.5 * std::f64::consts::TAU.ln());
        }
        let top = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        top + logs.iter().map(|l| (l - top).exp()).sum::<f64>().ln()
    }
}

/// The information `Σᵢ (I − vᵢvᵢᵀ)/(sᵢ²hᵢ²)` of rays `members` about a point `x`, `None`
/// if `x` is behind one of their eyes.
pub(super) fn information(
    rays: &GazeRays,
    x: &Vector3<f64>,
    members: &[usize],
) -> Option<Matrix3<f64>> {
    let mut info = Matrix3::zeros();
    for &i in members {
        let v = &rays.v[i];
        let s = (x - rays.p[i]).dot(v);
        if s <= 0.0 {
            return None;
        }
        info += (Matrix3::identity() - v * v.transpose()) * (rays.inv_h2[i] / (s * s));
    }
    Some(info)
}

/// Score of one charge at `x` with `members`: what the members gain over being left out
/// minus the Occam cost of the charge (see the module docs): `−ln p(x) − 3/2 ln 2π +
/// ½ ln det A`, `p` the position prior.
fn charge_score(search: &Search<'_>, x: &Vector3<f64>, members: &[usize], n_charges: usize) -> f64 {
    let rays = search.rays;
    let choice = (n_charges as f64).ln();
    let gain: f64 = members
        .iter()
        .map(|&i| bonus(rays, i, search.prior) - choice - 0.5 * q_of(rays, i, x))
        .sum();
    let Some(info) = information(rays, x, members) else {
        return f64::NEG_INFINITY;
    };
    let det = info.determinant();
    if !(det > 0.0 && gain.is_finite()) {
        return f64::NEG_INFINITY;
    }
    let ln_p = search.position_prior.ln_density(x, &info, search.ln_volume);
    gain + ln_p + 1.5 * std::f64::consts::TAU.ln() - 0.5 * det.ln()
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
    /// The rays within `member_sigma` of each candidate (its own members).
    claims: Vec<Vec<usize>>,
    opts: &'a ModeOptions,
    /// `ln V` of the prior volume.
    ln_volume: f64,
    /// `ln((1 − u)/u)`.
    prior: f64,
    position_prior: &'a Prior,
}

impl Search<'_> {
    fn inside(&self, x: &Vector3<f64>) -> bool {
        self.opts.bounds.as_ref().map_or(true, |(lo, hi)| {
            (0..3).all(|a| x[a] >= lo[a] && x[a] <= hi[a])
        })
    }

    /// Hard EM from the candidates `alive` twice, and the better of the two fixed
    /// points: once with every ray first going where it fits best, once with every
    /// candidate first claiming its own members, the candidates with fewer members first.
    /// The first start lets a ray that fits two charges well leave a small group with too
    /// few rays (which is then dropped), although the partition that keeps the small
    /// group explains the rays better; the second start keeps it.
    fn evaluate(&self, alive: &[bool]) -> State {
        let a = self.evaluate_from(alive, false);
        let b = self.evaluate_from(alive, true);
        if b.score > a.score {
            b
        } else {
            a
        }
    }

    /// The first assignment of [`Search::evaluate`]'s second start, over the charges `xs`.
    fn claimed(&self, xs: &[(usize, Vector3<f64>)]) -> Vec<Option<usize>> {
        let mut order: Vec<usize> = (0..xs.len()).collect();
        order.sort_by_key(|&k| (self.claims[xs[k].0].len(), k));
        let mut owner = vec![None; self.rays.len()];
        for k in order {
            for &i in &self.claims[xs[k].0] {
                if owner[i].is_none() && q_of(self.rays, i, &xs[k].1).is_finite() {
                    owner[i] = Some(k);
                }
            }
        }
        owner
    }

    /// Every ray to the charge of `xs` where it gains most, or to none.
    fn assign(&self, xs: &[(usize, Vector3<f64>)]) -> Vec<Option<usize>> {
        let rays = self.rays;
        (0..rays.len())
            .map(|i| {
                let mut best: Option<(usize, f64)> = None;
                let choice = (xs.len() as f64).ln();
                for (k, (_, x)) in xs.iter().enumerate() {
                    let l = bonus(rays, i, self.prior) - choice - 0.5 * q_of(rays, i, x);
                    if l > 0.0 && best.map_or(true, |(_, b)| l > b) {
                        best = Some((k, l));
                    }
                }
                best.map(|(k, _)| k)
            })
            .collect()
    }

    fn evaluate_from(&self, alive: &[bool], claim: bool) -> State {
        let rays = self.rays;
        let n = rays.len();
        let mut xs: Vec<(usize, Vector3<f64>)> = (0..alive.len())
            .filter(|&c| alive[c])
            .map(|c| (c, self.start[c]))
            .collect();
        let mut owner: Option<Vec<Option<usize>>> = None;
        for it in 0..EM_ITERATIONS {
            if xs.is_empty() {
                owner = None;
                break;
            }
            let assign: Vec<Option<usize>> = if claim && it == 0 {
                self.claimed(&xs)
            } else {
                self.assign(&xs)
            };
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
                score += charge_score(self, x, &members, xs.len());
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
    position_prior: &Prior,
) -> Result<Vec<Charge>> {
    let volume = match &opts.bounds {
        Some((lo, hi)) => (hi - lo).iter().map(|e| e.max(1e-3)).product::<f64>(),
        None => opts.depth_max.powi(3),
    };
    let search = Search {
        rays,
        start: candidates.iter().map(|c| c.position).collect(),
        claims: candidates.iter().map(|c| c.members.clone()).collect(),
        opts,
        ln_volume: volume.ln(),
        prior: ((1.0 - opts.unattended) / opts.unattended).ln(),
        position_prior,
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
