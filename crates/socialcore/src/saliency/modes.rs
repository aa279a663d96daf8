//! Social charges: the modes of the saliency field, found by the ray mean-shift of
//! Eq 6.5–6.7 from seeds sampled along every gaze ray (Sec 6.2).

use super::field::{ray_hessian, saliency, INV_SQRT_2PI, Q_CUTOFF};
use super::partition::{Prior, PriorTerm};
use super::GazeRays;
use crate::error::{Error, Result};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Settings of [`find_charges`]. The defaults suit people in a room (metres).
#[derive(Debug, Clone, PartialEq)]
pub struct ModeOptions {
    /// Seeds per ray, stratified in depth along the ray (Sec 6.2: "we sample several points
    /// on the primary gaze rays").
    pub seeds_per_ray: usize,
    /// Depth range `[depth_min, depth_max]` (metres from the eye) of the seeds.
    pub depth_min: f64,
    pub depth_max: f64,
    /// A seed has converged when an iteration moves it less than `tol` metres.
    pub tol: f64,
    /// Accelerate Eq 6.7 with Newton steps inside a mode's basin and over-relaxed steps
    /// elsewhere (see `climb`); `false` runs the plain update of Eq 6.7 (slow along
    /// elongated modes and along the rays' ridges).
    pub newton: bool,
    /// Iteration cap per seed; seeds that reach it (slow drift along a lone ray's ridge)
    /// are dropped.
    pub max_iter: usize,
    /// Converged seeds closer than this (metres) to an earlier mode, in seed order, are the
    /// same mode; the mode keeps the position with the higher field value.
    pub merge_radius: f64,
    /// A ray is a member of a charge when the charge lies within `member_sigma` bandwidths
    /// of it (`‖d/h‖ ≤ member_sigma`, Eq 6.2).
    pub member_sigma: f64,
    /// Charges with fewer member rays are rejected (Sec 6.2: more than one gaze ray must
    /// contribute), so the default is 2.
    pub min_members: usize,
    /// How rays are shared among candidate modes and which candidates are accepted (see
    /// [`Membership`]).
    pub membership: Membership,
    /// [`Membership::Cover`] only: the price of one more charge, in units of the rays'
    /// log-likelihood `½‖d/h‖²`. A candidate is kept only if the rays it explains fit it
    /// better, in total, than this price (plus what they would cost elsewhere).
    pub charge_penalty: f64,
    /// [`Membership::Partition`] only: the prior probability that a ray attends no charge
    /// (it then points anywhere). A ray joins a charge when that is likelier than this.
    pub unattended: f64,
    /// Also start one climb at the near-intersection of every pair of rays that pass
    /// within `member_sigma` bandwidths of each other (Sec 6.2 samples seeds along the
    /// rays only; with narrow bandwidths the stratified seeds then often miss a mode's
    /// basin, which is only about `member_sigma·h·depth / sin(angle)` long on each ray).
    pub pair_seeds: bool,
    /// Also make a candidate charge (`support` 0) at the weighted closest approach of every
    /// pair of rays that pass within `member_sigma` bandwidths of it (both, in front of
    /// both eyes) and that no mode, nor a closer pair's candidate, already holds as
    /// members (an extension of Sec 6.2, which takes only the modes). The field has a joint mode only where two rays pass within about two
    /// bandwidths of each other; two rays of one group each 1–3 bandwidths off their
    /// target on opposite sides (eyes off the head's primary direction: the cone of
    /// Sec 3.1) leave one ridge along each ray and no mode, so no charge holds both,
    /// although each is within `member_sigma` of the point (Eq 6.2's membership). The
    /// candidate sits where Sec 6.2 would put a charge whose members are known: at their
    /// least-squares intersection (weights `1/(s²h²)`). It then goes through the same
    /// acceptance and membership rule as the modes.
    pub pair_candidates: bool,
    /// A ray is no member of a candidate charge (a mode or a pair's candidate) closer than
    /// this (metres) to its eye; a candidate left with fewer than `min_members` is rejected
    /// (every ray passes through its own eye, so any two rays "meet" right in front of one
    /// of them). [`Membership::Partition`] then decides its members itself. `0`: no limit.
    pub min_member_depth: f64,
    /// Charges whose field value is below this are rejected.
    pub min_magnitude: f64,
    /// Optional box `(lo, hi)` outside of which modes are rejected (for example a room).
    pub bounds: Option<(Vector3<f64>, Vector3<f64>)>,
    /// [`Membership::Partition`] in [`find_charges_sequence`] only: pool evidence over
    /// the `pool_frames` frames before and after each frame. A first pass finds every
    /// frame's charges alone; the second pass gives each charge of frame `t` a position
    /// prior made of the first pass's charges of those neighbours (half the prior mass;
    /// the other half stays uniform over the prior volume, for a charge that is new), and
    /// their positions as extra candidates. `0`: every frame alone.
    pub pool_frames: usize,
    /// How far (metres) a charge may move per frame, as the standard deviation of a random
    /// walk: a neighbour `k` frames away contributes with its uncertainty plus
    /// `(drift·k)²` per axis.
    pub drift: f64,
    /// [`Membership::Partition`] in [`find_charges_sequence`] with `pool_frames > 0`: a
    /// third pass decides the charges of all frames jointly (see the `window` module):
    /// targets persist as sources, each person's attention changes rarely, and a frame the
    /// gaze model cannot resolve alone is resolved with its neighbours.
    pub joint_window: bool,
    /// Cost (nats) of a person changing target in [`ModeOptions::joint_window`]: `ln(1/q)`
    /// for a change probability `q` per frame.
    pub switch_cost: f64,
    /// The confidence region is where the field exceeds `region_level` times the mode
    /// value (Sec 6.2.1 uses 0.8).
    pub region_level: f64,
    /// The region's semi-axes are capped at this many metres.
    pub region_max_radius: f64,
}

/// Default [`ModeOptions::switch_cost`]: `ln 30`, a change of target every 30 frames (3 s
/// at 10 fps) a priori.
pub const SWITCH_COST: f64 = 3.401_197_381_662_155;

impl Default for ModeOptions {
    fn default() -> Self {
        ModeOptions {
            seeds_per_ray: 20,
            depth_min: 0.3,
            depth_max: 10.0,
            tol: 1e-5,
            newton: true,
            max_iter: 100,
            merge_radius: 0.2,
            member_sigma: 2.5,
            min_members: 2,
            membership: Membership::Partition,
            charge_penalty: 2.0,
            unattended: 0.05,
            pair_seeds: true,
            pair_candidates: false,
            min_member_depth: 0.0,
            min_magnitude: 0.0,
            bounds: None,
            pool_frames: 10,
            drift: 0.05,
            joint_window: true,
            switch_cost: SWITCH_COST,
            region_level: 0.8,
            region_max_radius: 10.0,
        }
    }
}

impl ModeOptions {
    /// Checks every setting, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        let bad = |arg: &str, msg: String| Err(Error::invalid(arg, msg));
        if !(self.min_member_depth.is_finite() && self.min_member_depth >= 0.0) {
            let msg = format!("{} must be finite and >= 0", self.min_member_depth);
            return bad("min_member_depth", msg);
        }
        if self.seeds_per_ray == 0 {
            return bad("seeds_per_ray", "must be at least 1".into());
        }
        if !(self.depth_min.is_finite() && self.depth_min > 0.0) {
            return bad(
                "depth_min",
                format!("{} must be finite and > 0", self.depth_min),
            );
        }
        if !(self.depth_max.is_finite() && self.depth_max >= self.depth_min) {
            return bad(
                "depth_max",
                format!(
                    "{} must be finite and ≥ depth_min {}",
                    self.depth_max, self.depth_min
                ),
            );
        }
        if !(self.tol.is_finite() && self.tol > 0.0) {
            return bad("tol", format!("{} must be finite and > 0", self.tol));
        }
        if self.max_iter == 0 {
            return bad("max_iter", "must be at least 1".into());
        }
        if !(self.merge_radius.is_finite() && self.merge_radius >= 0.0) {
            return bad(
                "merge_radius",
                format!("{} must be finite and ≥ 0", self.merge_radius),
            );
        }
        if !(self.member_sigma.is_finite() && self.member_sigma > 0.0) {
            return bad(
                "member_sigma",
                format!("{} must be finite and > 0", self.member_sigma),
            );
        }
        if self.min_members == 0 {
            return bad("min_members", "must be at least 1".into());
        }
        if !(self.charge_penalty.is_finite() && self.charge_penalty >= 0.0) {
            return bad(
                "charge_penalty",
                format!("{} must be finite and ≥ 0", self.charge_penalty),
            );
        }
        if !(self.unattended > 0.0 && self.unattended < 1.0) {
            return bad(
                "unattended",
                format!("{} must lie in (0, 1)", self.unattended),
            );
        }
        if !self.min_magnitude.is_finite() {
            return bad("min_magnitude", "must be finite".into());
        }
        if let Some((lo, hi)) = &self.bounds {
            if !(lo.iter().chain(hi.iter()).all(|x| x.is_finite())
                && (0..3).all(|a| lo[a] <= hi[a]))
            {
                return bad("bounds", "must be finite with lo ≤ hi on every axis".into());
            }
        }
        if !(self.drift.is_finite() && self.drift >= 0.0) {
            return bad("drift", format!("{} must be finite and ≥ 0", self.drift));
        }
        if !(self.switch_cost.is_finite() && self.switch_cost >= 0.0) {
            return bad(
                "switch_cost",
                format!("{} must be finite and ≥ 0", self.switch_cost),
            );
        }
        if !(self.region_level > 0.0 && self.region_level < 1.0) {
            return bad(
                "region_level",
                format!("{} must lie in (0, 1)", self.region_level),
            );
        }
        if !(self.region_max_radius.is_finite() && self.region_max_radius > 0.0) {
            return bad(
                "region_max_radius",
                format!("{} must be finite and > 0", self.region_max_radius),
            );
        }
        Ok(())
    }
}

/// How [`find_charges`] decides which rays belong to which charge, and so which modes
/// are charges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Membership {
    /// The thesis' rule (Sec 6.2): every mode with at least `min_members` rays within
    /// `member_sigma` bandwidths is a charge, and a ray may belong to several. Crossings of
    /// rays of different groups, and the several modes a noisy group can make, all count.
    All,
    /// Winner-take-all, strongest first: a ray belongs only to the strongest
    /// charge it is within `member_sigma` of; `min_members` applies to the rays still
    /// free. This rejects most crossings of rays of different groups behind their targets,
    /// but drops real charges whose rays pass near a stronger one (wide bandwidths) or that
    /// such a crossing outbids.
    Strongest,
    /// A set cover (experimental; on the held-out marker scenes it splits noisy groups
    /// into sub-modes more often than `Strongest`): choose the set of candidate modes that best explains
    /// the rays. Every ray belongs to the candidate it fits best (smallest `‖d/h‖`), if it
    /// is within `member_sigma` of one; the score is
    /// `−½ Σ‖d/h‖² (members) − ½ member_sigma² (rays left out) − charge_penalty · #charges`,
    /// every charge needs `min_members` rays. Candidates are removed one at a time (the
    /// removal that gives the best score; forced while a charge has too few members)
    /// until no removal raises the score. Each accepted charge is then moved to the mode
    /// of its own members' field (Eq 6.7 on the members only), so that other groups' rays
    /// passing nearby do not pull it.
    Cover,
    /// A partition of the rays (the default; see the `partition` module): every ray
    /// belongs to at most one charge, by likelihood under each charge's perspective-
    /// distance kernel (Eq 6.2); each charge sits at the least-squares intersection of its
    /// members (weights `1/(s²h²)`), not at a mode of the field; the set of charges is the
    /// one whose likelihood under the gaze model (Sec 3.1), minus an Occam cost per charge
    /// that scales with the bandwidths and distances, is highest. Candidates are the
    /// mean-shift modes (Eq 6.7) with `min_members` rays within `member_sigma`.
    Partition,
}

/// An ellipsoid `{x : Σₖ ((x − c)ᵀaₖ / rₖ)² ≤ 1}` with unit axes `aₖ` (columns of
/// `axes`) and semi-axes `rₖ`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    pub centre: Vector3<f64>,
    pub axes: Matrix3<f64>,
    pub radii: Vector3<f64>,
}

impl Ellipsoid {
    /// Whether `x` lies inside (or on) the ellipsoid.
    pub fn contains(&self, x: &Vector3<f64>) -> bool {
        let d = self.axes.transpose() * (x - self.centre);
        (0..3).map(|k| (d[k] / self.radii[k]).powi(2)).sum::<f64>() <= 1.0
    }
}

/// One social charge of a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Charge {
    /// The mode of the saliency field (metres); with [`Membership::Partition`] the
    /// intersection of the member rays (see [`Membership::Partition`]).
    pub position: Vector3<f64>,
    /// The field value there, `f(x)` of Eq 6.4: the charge's strength.
    pub magnitude: f64,
    /// Indices (into the frame's rays, ascending) of the member rays.
    pub members: Vec<usize>,
    /// The membership feature of Eq 6.8: `fᵢ(x)` over all rays of the frame, unit norm.
    pub membership: Vec<f64>,
    /// How many seeds converged to this charge.
    pub support: usize,
    /// The region where the field exceeds `region_level · magnitude`, as an ellipsoid:
    /// axes along the eigenvectors of the field's Hessian at the mode, extents found by
    /// bisection of the actual field along each of them (both ways).
    pub region: Ellipsoid,
}

/// What one evaluation gives the iteration: `Σ fᵢ` (times `N`, the field), and the
/// numerator and denominator of Eq 6.7.
struct ShiftTerms {
    field_sum: f64,
    num: Vector3<f64>,
    den: f64,
}

/// Below this depth (metres) a ray's weight `1/s²` of Eq 6.6 is not used (the eye itself).
const MIN_DEPTH: f64 = 1e-12;

/// Evaluates the terms of Eq 6.6–6.7 at `x`: for each ray with `s = (x − p)ᵀv > 0`,
/// `wᵢ = g(‖d/h‖²)/(h³ s²)` with `g(u) ∝ e^{−u/2}` and `x̃ᵢ = x̂ᵢ + (‖x − x̂ᵢ‖²/s) v`.
#[inline]
fn shift_terms(rays: &GazeRays, x: &Vector3<f64>) -> ShiftTerms {
    let mut t = ShiftTerms {
        field_sum: 0.0,
        num: Vector3::zeros(),
        den: 0.0,
    };
    for i in 0..rays.len() {
        let (p, v) = (&rays.p[i], &rays.v[i]);
        let w = x - p;
        let s = w.dot(v);
        if s < 0.0 {
            continue; // behind the eye: d = ∞ (Eq 6.2)
        }
        let perp = w - v * s;
        let pp = perp.norm_squared();
        if s < MIN_DEPTH {
            if pp == 0.0 {
                t.field_sum += rays.peak[i];
            }
            continue;
        }
        // q = ‖d/h‖² = pp/(s²h²); the cutoff test needs no division.
        let pp_h = pp * rays.inv_h2[i];
        let s2 = s * s;
        if pp_h > Q_CUTOFF * s2 {
            continue;
        }
        let inv_s2 = 1.0 / s2;
        let e = (-0.5 * pp_h * inv_s2).exp();
        t.field_sum += e * rays.peak[i];
        let wi = e * rays.inv_h3[i] * inv_s2;
        // x̃ − x = −(x − x̂) + (‖x − x̂‖²/s) v; Σ wᵢ x̃ᵢ is formed as x Σ wᵢ + Σ wᵢ (x̃ᵢ − x).
        t.num += (v * (pp * s * inv_s2) - perp) * wi;
        t.den += wi;
    }
    t.num += x * t.den;
    t
}

/// Outcome of one seed's climb.
struct Climb {
    x: Vector3<f64>,
    value: f64,
    converged: bool,
}

/// Largest over-relaxation factor of an accelerated climb.
const MAX_ALPHA: f64 = 1024.0;

/// A climb that wanders farther than this many `depth_max` from its seed is abandoned.
const ESCAPE_FACTOR: f64 = 2.0;

/// Relative field gain per iteration below which a climb counts as converged.
const STALL_GAIN: f64 = 1e-10;

/// Largest number of step halvings when an update of Eq 6.7 would lower the field.
const MAX_HALVINGS: usize = 30;

/// [`ShiftTerms`] plus `N·∇f(x)` and `N·∇²f(x)` in closed form (see [`ray_hessian`] for
/// the terms), in one pass over the rays.
struct FullTerms {
    shift: ShiftTerms,
    grad: Vector3<f64>,
    hess: Matrix3<f64>,
}

fn full_terms(rays: &GazeRays, x: &Vector3<f64>) -> FullTerms {
    let mut t = FullTerms {
        shift: ShiftTerms {
            field_sum: 0.0,
            num: Vector3::zeros(),
            den: 0.0,
        },
        grad: Vector3::zeros(),
        hess: Matrix3::zeros(),
    };
    for i in 0..rays.len() {
        let (p, v, h) = (&rays.p[i], &rays.v[i], rays.h[i]);
        let w = x - p;
        let s = w.dot(v);
        if s < 0.0 {
            continue;
        }
        let perp = w - v * s;
        let pp = perp.norm_squared();
        if s < MIN_DEPTH {
            if pp == 0.0 {
                t.shift.field_sum += INV_SQRT_2PI / h;
            }
            continue;
        }
        let h2 = h * h;
        let s2 = s * s;
        let q = pp / (s2 * h2);
        if q > Q_CUTOFF {
            continue;
        }
        let e = (-0.5 * q).exp();
        let fi = e * INV_SQRT_2PI / h;
        t.shift.field_sum += fi;
        let wi = e / (h2 * h * s2);
        t.shift.num += (x - perp + v * (pp / s)) * wi;
        t.shift.den += wi;
        let ww = pp + s2;
        let grad_q = (w - v * (ww / s)) * (2.0 / (h2 * s2));
        let hess_q = (Matrix3::identity() / s2
            - (w * v.transpose() + v * w.transpose()) * (2.0 / (s2 * s))
            + v * v.transpose() * (3.0 * ww / (s2 * s2)))
            * (2.0 / h2);
        t.grad -= grad_q * (0.5 * fi);
        t.hess += (grad_q * grad_q.transpose() * 0.25 - hess_q * 0.5) * fi;
    }
    t
}

/// Climbs from `x0` with the mean-shift update of Eq 6.7.
///
/// Eq 6.7 converges only linearly: very slowly along the long axis of the elongated
/// modes that nearly parallel rays make, and along a ray's own ridge near the eye, where
/// its weight `1/s²` dominates. With `opts.newton` each iteration first tries the Newton
/// step `−(∇²f)⁻¹∇f` where the Hessian is negative definite (inside a mode's basin) and
/// takes it if it raises the field; otherwise it tries an over-relaxed Eq 6.7 step
/// (factor doubling after each success). The fallback is always the Eq 6.7 step, halved
/// until it does not lower the field (the ray kernel is not a classic mean-shift kernel,
/// so ascent is not guaranteed by theory). If no halving helps, `x` is a numerical
/// maximum. Without `opts.newton` this is the plain Eq 6.7 iteration with that safeguard.
fn climb(rays: &GazeRays, x0: Vector3<f64>, opts: &ModeOptions) -> Climb {
    let n = rays.len() as f64;
    let eval = |x: &Vector3<f64>| {
        if opts.newton {
            full_terms(rays, x)
        } else {
            FullTerms {
                shift: shift_terms(rays, x),
                grad: Vector3::zeros(),
                hess: Matrix3::zeros(),
            }
        }
    };
    let mut x = x0;
    let mut terms = eval(&x);
    let mut alpha = 1.0f64;
    for _ in 0..opts.max_iter {
        let here = &terms.shift;
        if here.den <= 0.0 {
            return Climb {
                x,
                value: here.field_sum / n,
                converged: false,
            };
        }
        let mut next = None;
        let mut moved = 0.0;
        if opts.newton {
            if let Some(chol) = (-terms.hess).cholesky() {
                let step = chol.solve(&terms.grad);
                let xn = x + step;
                let tn = eval(&xn);
                if tn.shift.field_sum >= here.field_sum {
                    moved = step.norm();
                    next = Some((xn, tn));
                }
            }
        }
        if next.is_none() {
            let base = here.num / here.den - x;
            // Over-relaxation (accelerated climbs only): try `alpha` times the Eq 6.7
            // step, doubling `alpha` after each success, so a seed crawling along a ray's
            // ridge (its own ray's weight 1/s² dominates the update) speeds up
            // geometrically; on failure `alpha` falls back to 1 and then halves.
            if opts.newton && alpha > 1.0 {
                let xn = x + base * alpha;
                let tn = eval(&xn);
                if tn.shift.field_sum > here.field_sum {
                    moved = base.norm() * alpha;
                    next = Some((xn, tn));
                    alpha = (alpha * 2.0).min(MAX_ALPHA);
                } else {
                    alpha = 1.0;
                }
            }
            if next.is_none() {
                let mut step = base;
                for k in 0..MAX_HALVINGS {
                    let xn = x + step;
                    let tn = eval(&xn);
                    if tn.shift.field_sum >= here.field_sum * (1.0 - 1e-12) {
                        moved = step.norm();
                        next = Some((xn, tn));
                        if k == 0 && opts.newton {
                            alpha = 2.0;
                        }
                        break;
                    }
                    step *= 0.5;
                }
            }
        }
        let Some((xn, tn)) = next else {
            return Climb {
                x,
                value: here.field_sum / n,
                converged: true,
            };
        };
        // Converged when the step is below `tol`, or when the field no longer grows
        // (relative gain ≤ STALL_GAIN): a seed stalled on a lone ray's ridge, far from
        // every other ray, creeps by steps above `tol` for ever.
        let gain = tn.shift.field_sum - here.field_sum;
        let stalled = gain <= STALL_GAIN * here.field_sum;
        x = xn;
        terms = tn;
        if (x - x0).norm() > ESCAPE_FACTOR * opts.depth_max {
            // Nearly parallel rays overlap for ever: the field creeps up towards infinity.
            return Climb {
                x,
                value: terms.shift.field_sum / n,
                converged: false,
            };
        }
        if moved < opts.tol || stalled {
            return Climb {
                x,
                value: terms.shift.field_sum / n,
                converged: true,
            };
        }
    }
    Climb {
        x,
        value: terms.shift.field_sum / n,
        converged: false,
    }
}

/// The seeds of ray `i`: `seeds_per_ray` depths, one uniform draw in each of as many equal
/// strata of `[depth_min, depth_max]`, from a ChaCha8 stream of its own (`seed`, stream
/// `i`), so seeds never depend on the thread count or on the other rays.
fn seeds_of_ray(rays: &GazeRays, i: usize, opts: &ModeOptions, seed: u64) -> Vec<Vector3<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(i as u64);
    let n = opts.seeds_per_ray;
    let span = opts.depth_max - opts.depth_min;
    (0..n)
        .map(|j| {
            let u: f64 = rng.random();
            let depth = opts.depth_min + span * (j as f64 + u) / n as f64;
            rays.p[i] + rays.v[i] * depth
        })
        .collect()
}

/// The finished charge at a mode `x` (field value `value`), or `None` if it is rejected.
fn make_charge(
    rays: &GazeRays,
    x: Vector3<f64>,
    value: f64,
    support: usize,
    opts: &ModeOptions,
) -> Option<Charge> {
    if value < opts.min_magnitude || value <= 0.0 {
        return None;
    }
    if let Some((lo, hi)) = &opts.bounds {
        if (0..3).any(|a| x[a] < lo[a] || x[a] > hi[a]) {
            return None;
        }
    }
    let n = rays.len();
    let mut members = Vec::new();
    let mut fi = Vec::with_capacity(n);
    for i in 0..n {
        fi.push(super::field::ray_density(rays, i, &x));
        if (x - rays.p[i]).norm() < opts.min_member_depth {
            continue;
        }
        if let Some(d) = crate::geometry::perspective_distance(&rays.p[i], &rays.v[i], &x) {
            if d.norm() <= opts.member_sigma * rays.h[i] {
                members.push(i);
            }
        }
    }
    if members.len() < opts.min_members {
        return None;
    }
    let norm = fi.iter().map(|f| f * f).sum::<f64>().sqrt();
    let membership = fi.iter().map(|f| f / norm).collect();
    Some(Charge {
        position: x,
        magnitude: value,
        members,
        membership,
        support,
        // Filled in once the charge is accepted (see `charges_of_frame`).
        region: Ellipsoid {
            centre: x,
            axes: Matrix3::identity(),
            radii: Vector3::zeros(),
        },
    })
}

/// Distance from `x` along unit `u` at which the field first falls to `level`, found by
/// doubling from `guess` and then bisection; capped at `cap`.
fn crossing(
    rays: &GazeRays,
    x: &Vector3<f64>,
    u: &Vector3<f64>,
    level: f64,
    guess: f64,
    cap: f64,
) -> f64 {
    let above = |t: f64| saliency(rays, &(x + u * t)) >= level;
    let mut lo = 0.0;
    let mut hi = guess.min(cap);
    while above(hi) {
        if hi >= cap {
            return cap;
        }
        lo = hi;
        hi = (hi * 2.0).min(cap);
    }
    for _ in 0..60 {
        if hi - lo <= 1e-6 * hi {
            break;
        }
        let mid = 0.5 * (lo + hi);
        if above(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The confidence region `{f ≥ level · f(mode)}` summarised as an ellipsoid (see
/// [`Charge::region`]).
fn confidence_region(
    rays: &GazeRays,
    x: &Vector3<f64>,
    value: f64,
    opts: &ModeOptions,
) -> Ellipsoid {
    let eig = SymmetricEigen::new(-ray_hessian(rays, x));
    let level = opts.region_level * value;
    let cap = opts.region_max_radius;
    let mut centre = *x;
    let mut radii = Vector3::zeros();
    for k in 0..3 {
        let u: Vector3<f64> = eig.eigenvectors.column(k).into_owned();
        let lam = eig.eigenvalues[k];
        // Quadratic model f(x + tu) ≈ f − ½λt² gives the first guess.
        let guess = if lam > 0.0 {
            (2.0 * (1.0 - opts.region_level) * value / lam).sqrt()
        } else {
            cap / 16.0
        };
        let guess = if guess.is_finite() && guess > 0.0 {
            guess
        } else {
            cap / 16.0
        };
        let plus = crossing(rays, x, &u, level, guess, cap);
        let minus = crossing(rays, x, &(-u), level, guess, cap);
        radii[k] = 0.5 * (plus + minus);
        centre += u * (0.5 * (plus - minus));
    }
    Ellipsoid {
        centre,
        axes: eig.eigenvectors,
        radii,
    }
}

fn charges_of_frame(
    rays: &GazeRays,
    opts: &ModeOptions,
    seed: u64,
    parallel: bool,
    prior: &Prior,
) -> Result<Vec<Charge>> {
    let mut seeds: Vec<Vector3<f64>> = (0..rays.len())
        .flat_map(|i| seeds_of_ray(rays, i, opts, seed))
        .collect();
    if opts.pair_seeds {
        seeds.extend(pair_seeds(rays, opts));
    }
    // One interrupt check per climb (at most `max_iter` field evaluations).
    let climb_checked = |s: &Vector3<f64>| -> Result<Climb> {
        crate::interrupt::check()?;
        Ok(climb(rays, *s, opts))
    };
    let climbs: Vec<Climb> = if parallel {
        seeds.par_iter().map(climb_checked).collect::<Result<_>>()?
    } else {
        seeds.iter().map(climb_checked).collect::<Result<_>>()?
    };
    // Merge in seed order: the result never depends on how the climbs were scheduled.
    let mut modes: Vec<(Vector3<f64>, f64, usize)> = Vec::new();
    for c in climbs.iter().filter(|c| c.converged) {
        match modes
            .iter_mut()
            .find(|m| (m.0 - c.x).norm() <= opts.merge_radius)
        {
            Some(m) => {
                m.2 += 1;
                if c.value > m.1 {
                    m.0 = c.x;
                    m.1 = c.value;
                }
            }
            None => modes.push((c.x, c.value, 1)),
        }
    }
    let candidates: Vec<Charge> = modes
        .into_iter()
        .filter_map(|(x, value, support)| make_charge(rays, x, value, support, opts))
        .collect();
    let mut candidates = candidates;
    if opts.pair_candidates {
        // The closest pairs first; a pair that a candidate already holds has its charge.
        for (i, j, x) in pair_candidates(rays, opts) {
            let holds = |c: &Charge| c.members.contains(&i) && c.members.contains(&j);
            if !candidates.iter().any(holds) {
                let value = saliency(rays, &x);
                // (`None`, or without the pair: near an eye, see `min_member_depth`)
                candidates.extend(make_charge(rays, x, value, 0, opts).filter(holds));
            }
        }
    }
    // Strongest first; exact ties broken by position so the order is total.
    candidates.sort_by(|a, b| {
        b.magnitude
            .total_cmp(&a.magnitude)
            .then_with(|| a.position.x.total_cmp(&b.position.x))
            .then_with(|| a.position.y.total_cmp(&b.position.y))
            .then_with(|| a.position.z.total_cmp(&b.position.z))
    });
    let mut charges = match opts.membership {
        Membership::All => candidates,
        Membership::Strongest => {
            let mut taken = vec![false; rays.len()];
            let mut kept = Vec::with_capacity(candidates.len());
            for mut c in candidates {
                c.members.retain(|&i| !taken[i]);
                if c.members.len() >= opts.min_members {
                    c.members.iter().for_each(|&i| taken[i] = true);
                    kept.push(c);
                }
            }
            kept
        }
        Membership::Cover => cover(rays, candidates, opts)?,
        Membership::Partition => {
            // The pooled charges of the neighbouring frames are candidates too: a small
            // group next to a larger one often has no mode of its own in this frame (the
            // larger group's mode absorbs its climbs). (The near-intersections of ray
            // pairs were candidates once; with the joint window they changed no scene's
            // verdict on the held-out and development families and cost half the time.)
            let mut candidates = candidates;
            let mut extra: Vec<Charge> = Vec::new();
            for x in prior.terms.iter().map(|t| t.centre) {
                let near = |c: &Charge| (c.position - x).norm() <= opts.merge_radius;
                if candidates.iter().chain(extra.iter()).any(near) {
                    continue;
                }
                let value = saliency(rays, &x);
                extra.extend(make_charge(rays, x, value, 0, opts));
            }
            candidates.extend(extra);
            let mut kept = super::partition::partition(rays, candidates, opts, prior)?;
            kept.sort_by(|a, b| {
                b.magnitude
                    .total_cmp(&a.magnitude)
                    .then_with(|| a.position.x.total_cmp(&b.position.x))
            });
            kept
        }
    };
    for c in charges.iter_mut() {
        c.region = confidence_region(rays, &c.position, c.magnitude, opts);
    }
    Ok(charges)
}

/// The closest points `(pᵢ + vᵢsᵢ, pⱼ + vⱼsⱼ)` of rays `i` and `j` and their depths
/// `(sᵢ, sⱼ)`, if the rays are not parallel and the points lie in front of both eyes.
fn closest_approach(
    rays: &GazeRays,
    i: usize,
    j: usize,
) -> Option<(Vector3<f64>, Vector3<f64>, f64, f64)> {
    let (pi, vi, pj, vj) = (&rays.p[i], &rays.v[i], &rays.p[j], &rays.v[j]);
    let b = vi.dot(vj);
    let denom = 1.0 - b * b;
    if denom < 1e-12 {
        return None; // parallel: no single closest point
    }
    let w0 = pi - pj;
    let (d, e) = (vi.dot(&w0), vj.dot(&w0));
    let si = (b * e - d) / denom;
    let sj = (e - b * d) / denom;
    if si <= 0.0 || sj <= 0.0 {
        return None;
    }
    Some((pi + vi * si, pj + vj * sj, si, sj))
}

/// Seeds at the near-intersections of ray pairs ([`ModeOptions::pair_seeds`]): for every
/// pair `i < j` of non-parallel rays, the midpoint of the shortest segment between the two
/// lines, if it lies in front of both eyes and within `member_sigma` bandwidths of both.
fn pair_seeds(rays: &GazeRays, opts: &ModeOptions) -> Vec<Vector3<f64>> {
    let n = rays.len();
    let m2 = opts.member_sigma * opts.member_sigma;
    let mut out = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            if let Some((xi, xj, _, _)) = closest_approach(rays, i, j) {
                let x = (xi + xj) * 0.5;
                if q_of(rays, i, &x) <= m2 && q_of(rays, j, &x) <= m2 {
                    out.push(x);
                }
            }
        }
    }
    out
}

/// The candidates of [`ModeOptions::pair_candidates`]: for every pair `i < j`, the point
/// of the shortest segment between the two rays that minimises `‖dᵢ/hᵢ‖² + ‖dⱼ/hⱼ‖²`
/// (Eq 6.2; `‖d‖` is the distance over the depth `s`, so the weights are `1/(s²h²)`: the
/// least-squares intersection of the pair), if it lies within `member_sigma` bandwidths
/// of both rays.
fn pair_candidates(rays: &GazeRays, opts: &ModeOptions) -> Vec<(usize, usize, Vector3<f64>)> {
    let n = rays.len();
    let m2 = opts.member_sigma * opts.member_sigma;
    let mut out = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            let Some((xi, xj, si, sj)) = closest_approach(rays, i, j) else {
                continue;
            };
            let wi = rays.inv_h2[i] / (si * si);
            let wj = rays.inv_h2[j] / (sj * sj);
            // At xi + t(xj − xi) ray i is about t·g off and ray j (1 − t)·g.
            let x = xi + (xj - xi) * (wj / (wi + wj));
            let (qi, qj) = (q_of(rays, i, &x), q_of(rays, j, &x));
            if qi <= m2 && qj <= m2 {
                out.push((qi + qj, i, j, x));
            }
        }
    }
    // Closest first; ties in pair order, so the result never depends on scheduling.
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out.into_iter().map(|(_, i, j, x)| (i, j, x)).collect()
}

/// `‖d/h‖²` of ray `i` at `x` (Eq 6.2), infinite behind the eye.
pub(super) fn q_of(rays: &GazeRays, i: usize, x: &Vector3<f64>) -> f64 {
    match crate::geometry::perspective_distance(&rays.p[i], &rays.v[i], x) {
        Some(d) => d.norm_squared() * rays.inv_h2[i],
        None => f64::INFINITY,
    }
}

/// Assignment of every ray to its best-fitting live candidate (`None`: none within
/// `member_sigma`), and the score of [`Membership::Cover`] with whether every live
/// candidate has `min_members` rays.
struct CoverState {
    owner: Vec<Option<usize>>,
    count: Vec<usize>,
    score: f64,
    feasible: bool,
}

fn cover_state(q: &[Vec<f64>], alive: &[bool], opts: &ModeOptions) -> CoverState {
    let m2 = opts.member_sigma * opts.member_sigma;
    let n = q.first().map_or(0, Vec::len);
    let mut owner = vec![None; n];
    let mut count = vec![0usize; q.len()];
    let mut score = 0.0;
    for (i, o) in owner.iter_mut().enumerate() {
        let mut best: Option<(usize, f64)> = None;
        for (c, qc) in q.iter().enumerate() {
            // Ties go to the earlier (stronger) candidate.
            if alive[c] && qc[i] <= m2 && best.map_or(true, |(_, b)| qc[i] < b) {
                best = Some((c, qc[i]));
            }
        }
        match best {
            Some((c, qi)) => {
                *o = Some(c);
                count[c] += 1;
                score -= 0.5 * qi;
            }
            None => score -= 0.5 * m2,
        }
    }
    let live = alive.iter().filter(|&&a| a).count();
    score -= opts.charge_penalty * live as f64;
    let feasible = (0..q.len()).all(|c| !alive[c] || count[c] >= opts.min_members);
    CoverState {
        owner,
        count,
        score,
        feasible,
    }
}

/// [`Membership::Cover`]: backward elimination over the candidates (strongest first),
/// then each kept charge moved to the mode of its members' own field.
fn cover(rays: &GazeRays, candidates: Vec<Charge>, opts: &ModeOptions) -> Result<Vec<Charge>> {
    let n = rays.len();
    let q: Vec<Vec<f64>> = candidates
        .iter()
        .map(|c| (0..n).map(|i| q_of(rays, i, &c.position)).collect())
        .collect();
    let mut alive = vec![true; candidates.len()];
    let mut state = cover_state(&q, &alive, opts);
    while alive.iter().any(|&a| a) {
        crate::interrupt::check()?;
        // Forced: while a live candidate has too few rays, one of those must go.
        let forced = !state.feasible;
        let mut best: Option<(usize, CoverState)> = None;
        for c in 0..candidates.len() {
            if !alive[c] || (forced && state.count[c] >= opts.min_members) {
                continue;
            }
            alive[c] = false;
            let st = cover_state(&q, &alive, opts);
            alive[c] = true;
            // Strictly better only, so ties keep the earlier (stronger) removal choice.
            if best.as_ref().map_or(true, |(_, b)| st.score > b.score) {
                best = Some((c, st));
            }
        }
        let Some((c, st)) = best else { break };
        if !forced && st.score <= state.score {
            break;
        }
        alive[c] = false;
        state = st;
    }
    let mut kept = Vec::new();
    for (c, mut ch) in candidates.into_iter().enumerate() {
        if !alive[c] {
            continue;
        }
        ch.members = (0..n).filter(|&i| state.owner[i] == Some(c)).collect();
        // Mode of the members' own field, climbed from the candidate.
        let sub = GazeRays::new(
            ch.members.iter().map(|&i| rays.p[i]).collect(),
            ch.members.iter().map(|&i| rays.v[i]).collect(),
            ch.members.iter().map(|&i| rays.h[i]).collect(),
            None,
        )?;
        let own = climb(&sub, ch.position, opts);
        if own.converged {
            ch.position = own.x;
        }
        refresh_field_terms(rays, &mut ch);
        kept.push(ch);
    }
    kept.sort_by(|a, b| {
        b.magnitude
            .total_cmp(&a.magnitude)
            .then_with(|| a.position.x.total_cmp(&b.position.x))
    });
    Ok(kept)
}

/// Recomputes a moved charge's magnitude (the field there) and membership feature (Eq 6.8).
pub(super) fn refresh_field_terms(rays: &GazeRays, ch: &mut Charge) {
    ch.magnitude = saliency(rays, &ch.position);
    let fi: Vec<f64> = (0..rays.len())
        .map(|i| super::field::ray_density(rays, i, &ch.position))
        .collect();
    let norm = fi.iter().map(|f| f * f).sum::<f64>().sqrt();
    if norm > 0.0 {
        ch.membership = fi.iter().map(|f| f / norm).collect();
    }
}

/// The social charges of one frame (Sec 6.1.2): mean-shift (Eq 6.7) from seeds along every
/// ray, parallel over seeds; modes merged within `merge_radius` in seed order; modes with
/// fewer than `min_members` member rays, below `min_magnitude` or outside `bounds`
/// rejected. Sorted by magnitude, strongest first. A single ray, or rays that never meet,
/// give an empty list. Same `seed`, same result, whatever the thread count.
pub fn find_charges(rays: &GazeRays, opts: &ModeOptions, seed: u64) -> Result<Vec<Charge>> {
    opts.validate()?;
    check_seed_memory(rays.len(), opts)?;
    charges_of_frame(rays, opts, seed, true, &Prior::default())
}

/// The charges of every frame of a sequence.
type PerFrame = Vec<Vec<Charge>>;

/// The first pass and, with [`Membership::Partition`] and [`ModeOptions::pool_frames`] > 0,
/// the pooled second pass of [`find_charges_sequence`]; `Err(first)` when there is no
/// second pass (its frames are the result).
fn pooled_passes(
    frames: &[GazeRays],
    opts: &ModeOptions,
    seed: u64,
) -> Result<std::result::Result<PerFrame, PerFrame>> {
    opts.validate()?;
    let widest = frames.iter().map(GazeRays::len).max().unwrap_or(0);
    // Frames run in parallel: each worker holds one frame's seeds at a time.
    check_seed_memory(widest.saturating_mul(rayon::current_num_threads()), opts)?;
    let alone = Prior::default();
    let first: Vec<Vec<Charge>> = frames
        .par_iter()
        .map(|rays| charges_of_frame(rays, opts, seed, false, &alone))
        .collect::<Result<_>>()?;
    if opts.pool_frames == 0 || opts.membership != Membership::Partition {
        return Ok(Err(first));
    }
    // Each first-pass charge as (position, covariance of its position).
    let found: Vec<Vec<(Vector3<f64>, Matrix3<f64>)>> = first
        .iter()
        .zip(frames)
        .map(|(cs, rays)| {
            cs.iter()
                .filter_map(|c| {
                    let info = super::partition::information(rays, &c.position, &c.members)?;
                    Some((c.position, info.try_inverse()?))
                })
                .collect()
        })
        .collect();
    let pooled: Vec<Vec<Charge>> = frames
        .par_iter()
        .enumerate()
        .map(|(t, rays)| {
            let prior = pooled_prior(&found, t, opts);
            charges_of_frame(rays, opts, seed, false, &prior)
        })
        .collect::<Result<_>>()?;
    Ok(Ok(pooled))
}

/// [`find_charges`] on every frame of a sequence, parallel over frames. With
/// [`Membership::Partition`] and [`ModeOptions::pool_frames`] > 0, a second pass pools
/// the first pass's charges of the neighbouring frames into each frame's position prior
/// (see [`ModeOptions::pool_frames`]); otherwise frame `t` gives exactly what
/// `find_charges(&frames[t], opts, seed)` gives.
pub fn find_charges_sequence(
    frames: &[GazeRays],
    opts: &ModeOptions,
    seed: u64,
) -> Result<Vec<Vec<Charge>>> {
    let pooled = match pooled_passes(frames, opts, seed)? {
        Ok(pooled) => pooled,
        Err(first) => return Ok(first),
    };
    if !opts.joint_window {
        return Ok(pooled);
    }
    let joint = super::window::joint_window(frames, &window_stage(&pooled), opts)?;
    frames
        .par_iter()
        .zip(joint)
        .map(|(rays, found)| {
            let mut out: Vec<Charge> = found
                .into_iter()
                .map(|(x, members)| charge_at(rays, x, members, opts))
                .collect();
            out.sort_by(|a, b| {
                b.magnitude
                    .total_cmp(&a.magnitude)
                    .then_with(|| a.position.x.total_cmp(&b.position.x))
            });
            Ok(out)
        })
        .collect()
}

/// The pooled pass's charges as the joint window's stage (position, member rows).
fn window_stage(pooled: &[Vec<Charge>]) -> Vec<Vec<super::window::Found>> {
    pooled
        .iter()
        .map(|cs| cs.iter().map(|c| (c.position, c.members.clone())).collect())
        .collect()
}

/// A diagnosis of the joint window's search on a sequence whose true groups are known (a
/// bench's debug path, `benches/charges_diagnose.py`; no pipeline uses it): the window's
/// objective (log likelihood minus the sources' Occam costs) of the assignment
/// [`find_charges_sequence`] finds, of `truth` with its sources' positions fitted from
/// nothing, and of the search started from `truth`. `truth[t][i]`: the true group (a
/// source index) of row `i` of frame `t`, `None` for a ray that attends no charge. A
/// found objective below the search from the truth is a search failure; the truth above
/// both, where the answer is wrong, a model one.
pub fn diagnose_window(
    frames: &[GazeRays],
    opts: &ModeOptions,
    seed: u64,
    truth: &[Vec<Option<usize>>],
) -> Result<[f64; 3]> {
    opts.validate()?;
    if truth.len() != frames.len() || truth.iter().zip(frames).any(|(z, r)| z.len() != r.len()) {
        return Err(crate::Error::invalid(
            "truth",
            "need one entry per ray of every frame",
        ));
    }
    let n_rays: usize = frames.iter().map(GazeRays::len).sum();
    if truth.iter().flatten().flatten().any(|&g| g >= n_rays) {
        return Err(crate::Error::invalid(
            "truth",
            format!("group indices must be below the number of rays ({n_rays})"),
        ));
    }
    if opts.pool_frames == 0 || opts.membership != Membership::Partition || !opts.joint_window {
        return Err(crate::Error::invalid(
            "options",
            "the joint window needs membership partition, pool_frames > 0 and joint_window",
        ));
    }
    let pooled = pooled_passes(frames, opts, seed)?.unwrap_or_default();
    super::window::diagnose(frames, &window_stage(&pooled), opts, truth)
}

/// The charge at `x` with member rows `members` (decided elsewhere): field value,
/// membership feature and confidence region at `x`.
fn charge_at(rays: &GazeRays, x: Vector3<f64>, members: Vec<usize>, opts: &ModeOptions) -> Charge {
    let mut ch = Charge {
        position: x,
        magnitude: 0.0,
        members,
        membership: vec![0.0; rays.len()],
        support: 0,
        region: Ellipsoid {
            centre: x,
            axes: Matrix3::identity(),
            radii: Vector3::zeros(),
        },
    };
    refresh_field_terms(rays, &mut ch);
    ch.region = confidence_region(rays, &x, ch.magnitude, opts);
    ch
}

/// The position prior of frame `t`'s charges from the first-pass charges of the frames
/// within `pool_frames` of it (not `t` itself): each neighbouring frame that has charges
/// gets an equal share of the pooled half of the prior mass, split evenly among its
/// charges.
fn pooled_prior(
    found: &[Vec<(Vector3<f64>, Matrix3<f64>)>],
    t: usize,
    opts: &ModeOptions,
) -> Prior {
    let lo = t.saturating_sub(opts.pool_frames);
    let hi = (t + opts.pool_frames).min(found.len().saturating_sub(1));
    let with: Vec<usize> = (lo..=hi)
        .filter(|&k| k != t && !found[k].is_empty())
        .collect();
    let mut terms = Vec::new();
    for &k in &with {
        let lag = k.abs_diff(t) as f64 * opts.drift;
        let weight = 0.5 / (with.len() * found[k].len()) as f64;
        for (centre, cov) in &found[k] {
            terms.push(PriorTerm {
                centre: *centre,
                cov: cov + Matrix3::identity() * (lag * lag),
                weight,
            });
        }
    }
    Prior { terms }
}

/// The most memory the seeds and climbs of one call may take (2 GiB).
const MAX_SEED_BYTES: usize = 1 << 31;

/// Refuses `seeds_per_ray` (with `n_rays` rays at once) whose seeds and climbs would not
/// fit in [`MAX_SEED_BYTES`], before anything is allocated.
fn check_seed_memory(n_rays: usize, opts: &ModeOptions) -> Result<()> {
    let per_seed = std::mem::size_of::<Vector3<f64>>() + std::mem::size_of::<Climb>();
    let pairs = n_rays.saturating_mul(n_rays.saturating_sub(1)) / 2;
    let bytes = n_rays
        .saturating_mul(opts.seeds_per_ray)
        .saturating_add(pairs)
        .saturating_mul(per_seed);
    if bytes > MAX_SEED_BYTES {
        return Err(Error::invalid(
            "seeds_per_ray",
            format!(
                "{} seeds per ray on {n_rays} rays need {} MiB (more than {} MiB)",
                opts.seeds_per_ray,
                bytes >> 20,
                MAX_SEED_BYTES >> 20
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Rays from eyes `eyes` towards `target`, each turned by a small known angle.
    fn rays_at(eyes: &[Vector3<f64>], target: Vector3<f64>, h: f64, id0: i64) -> GazeRays {
        let v = eyes.iter().map(|p| (target - p).normalize()).collect();
        let ids = (0..eyes.len() as i64).map(|i| i + id0).collect();
        GazeRays::new(eyes.to_vec(), v, vec![h; eyes.len()], Some(ids)).unwrap()
    }

    fn circle(n: usize, r: f64, centre: Vector3<f64>, z: f64, phase: f64) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|i| {
                let a = phase + i as f64 * std::f64::consts::TAU / n as f64;
                centre + Vector3::new(r * a.cos(), r * a.sin(), z)
            })
            .collect()
    }

    fn concat(a: &GazeRays, b: &GazeRays) -> GazeRays {
        GazeRays::new(
            [a.p.clone(), b.p.clone()].concat(),
            [a.v.clone(), b.v.clone()].concat(),
            [a.h.clone(), b.h.clone()].concat(),
            Some([a.ids.clone(), b.ids.clone()].concat()),
        )
        .unwrap()
    }

    #[test]
    fn exact_rays_give_their_meeting_point() {
        let t = Vector3::new(1.0, 2.0, 1.0);
        let rays = rays_at(&circle(5, 2.5, t, 0.6, 0.3), t, 0.1, 0);
        let charges = find_charges(&rays, &ModeOptions::default(), 1).unwrap();
        assert_eq!(charges.len(), 1);
        let c = &charges[0];
        assert!((c.position - t).norm() < 1e-4, "{:?}", c.position);
        assert_eq!(c.members, vec![0, 1, 2, 3, 4]);
        assert_relative_eq!(c.magnitude, INV_SQRT_2PI / 0.1, epsilon = 1e-6);
        assert_relative_eq!(
            c.membership.iter().map(|m| m * m).sum::<f64>(),
            1.0,
            epsilon = 1e-12
        );
        assert!(c.region.contains(&t));
        assert!(!c.region.contains(&(t + Vector3::new(0.0, 0.0, 1.0))));
        // The region boundary really is at 80 % of the peak along each axis.
        for k in 0..3 {
            let u: Vector3<f64> = c.region.axes.column(k).into_owned();
            let b = c.region.centre + u * c.region.radii[k];
            let ratio = saliency(&rays, &b) / c.magnitude;
            assert!((ratio - 0.8).abs() < 0.05, "axis {k}: {ratio}");
        }
    }

    #[test]
    fn two_groups_give_two_charges_with_their_members() {
        let ta = Vector3::new(0.0, 0.0, 1.0);
        let tb = Vector3::new(6.0, 1.0, 1.2);
        let a = rays_at(&circle(4, 1.5, ta, 0.6, 0.1), ta, 0.08, 0);
        let b = rays_at(&circle(3, 1.2, tb, 0.5, 0.4), tb, 0.08, 10);
        let rays = concat(&a, &b);
        let charges = find_charges(&rays, &ModeOptions::default(), 3).unwrap();
        assert_eq!(charges.len(), 2);
        let ca = charges
            .iter()
            .find(|c| (c.position - ta).norm() < 1e-3)
            .unwrap();
        let cb = charges
            .iter()
            .find(|c| (c.position - tb).norm() < 1e-3)
            .unwrap();
        assert_eq!(ca.members, vec![0, 1, 2, 3]);
        assert_eq!(cb.members, vec![4, 5, 6]);
        // Stronger group first: 4 of 7 rays against 3 of 7.
        assert!(ca.magnitude > cb.magnitude);
        assert_eq!(charges[0], *ca);
        // Membership: large on members, negligible on the others.
        assert!(ca.membership[..4].iter().all(|&m| m > 0.45));
        assert!(ca.membership[4..].iter().all(|&m| m < 0.05));
        // Ray 2 (group A) and ray 4 (group B) cross below the floor, behind their targets:
        // a mode fed by two rays. Winner-take-all membership rejects it (both rays belong to
        // stronger charges); the thesis' rule keeps it; so does a box that excludes it.
        let o = ModeOptions {
            membership: Membership::All,
            ..Default::default()
        };
        let all = find_charges(&rays, &o, 3).unwrap();
        assert_eq!(all.len(), 3);
        assert_eq!(all[2].members, vec![2, 4]);
        assert!(all[2].position.z < 0.0);
        let o = ModeOptions {
            bounds: Some((Vector3::new(-9.0, -9.0, 0.0), Vector3::new(9.0, 9.0, 3.0))),
            ..o
        };
        assert_eq!(find_charges(&rays, &o, 3).unwrap().len(), 2);
    }

    /// Pairs A = {a, a'} and B = {b, b'} meeting exactly at `ta` = (0, 0, 1) and `tb` =
    /// (3, −1, 1); a and b also cross exactly at X = (3, 0, 1), behind both targets.
    fn two_pairs_and_a_crossing(ta: Vector3<f64>, tb: Vector3<f64>) -> GazeRays {
        let p = vec![
            Vector3::new(-4.0, 0.0, 1.0), // a: through A, on to X
            Vector3::new(0.0, -3.0, 1.0), // a'
            Vector3::new(3.0, -4.0, 1.0), // b: through B, on to X
            Vector3::new(3.0, -1.0, 4.0), // b'
        ];
        let v = vec![
            (ta - p[0]).normalize(),
            (ta - p[1]).normalize(),
            (tb - p[2]).normalize(),
            (tb - p[3]).normalize(),
        ];
        GazeRays::new(p, v, vec![0.02; 4], None).unwrap()
    }

    #[test]
    fn cover_keeps_both_pairs_that_a_crossing_would_split() {
        // Pairs A = {a, a'} and B = {b, b'} meet exactly at their targets; a and b also
        // cross exactly at X, behind both targets. Three exact two-ray modes of equal
        // strength: the thesis' rule keeps all three, the set cover keeps A and B.
        let (ta, tb, x) = (
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(3.0, -1.0, 1.0),
            Vector3::new(3.0, 0.0, 1.0),
        );
        let rays = two_pairs_and_a_crossing(ta, tb);
        let all = ModeOptions {
            membership: Membership::All,
            ..Default::default()
        };
        let thesis = find_charges(&rays, &all, 1).unwrap();
        assert_eq!(thesis.len(), 3);
        assert!(thesis.iter().any(|c| (c.position - x).norm() < 1e-4));
        let cover = ModeOptions {
            membership: Membership::Cover,
            ..Default::default()
        };
        let charges = find_charges(&rays, &cover, 1).unwrap();
        assert_eq!(charges.len(), 2, "{charges:?}");
        let ca = charges
            .iter()
            .find(|c| (c.position - ta).norm() < 1e-4)
            .unwrap();
        let cb = charges
            .iter()
            .find(|c| (c.position - tb).norm() < 1e-4)
            .unwrap();
        assert_eq!(ca.members, vec![0, 1]);
        assert_eq!(cb.members, vec![2, 3]);
    }

    #[test]
    fn partition_keeps_both_pairs_and_places_them_at_their_intersections() {
        // Same three exact two-ray modes as above: the partition keeps A and B.
        let (ta, tb) = (Vector3::new(0.0, 0.0, 1.0), Vector3::new(3.0, -1.0, 1.0));
        let rays = two_pairs_and_a_crossing(ta, tb);
        let charges = find_charges(&rays, &ModeOptions::default(), 1).unwrap();
        assert_eq!(charges.len(), 2, "{charges:?}");
        let ca = charges.iter().find(|c| c.members == vec![0, 1]).unwrap();
        let cb = charges.iter().find(|c| c.members == vec![2, 3]).unwrap();
        assert!((ca.position - ta).norm() < 1e-9, "{:?}", ca.position);
        assert!((cb.position - tb).norm() < 1e-9, "{:?}", cb.position);
    }

    #[test]
    fn partition_keeps_a_near_ray_that_pins_a_wide_pair() {
        // Two rays from 6 m meet at the target at a shallow angle; a third person 1.2 m
        // away looks at it too. All three rays miss by fixed small angles. The partition
        // puts all three in one charge, at their weighted intersection, and does not
        // leave the near ray out (which would move the charge along the pair's rays).
        let t = Vector3::new(0.0, 0.0, 1.2);
        let p = vec![
            Vector3::new(-6.0, 0.4, 1.6),
            Vector3::new(-5.9, -0.6, 1.7),
            Vector3::new(0.8, 0.9, 1.6),
        ];
        let turn = [0.01, -0.012, 0.015];
        let v: Vec<Vector3<f64>> = p
            .iter()
            .zip(turn)
            .map(|(p, a)| {
                let d = (t - p).normalize();
                (d + d.cross(&Vector3::z()).normalize() * a).normalize()
            })
            .collect();
        let rays = GazeRays::new(p, v, vec![0.05; 3], None).unwrap();
        let charges = find_charges(&rays, &ModeOptions::default(), 2).unwrap();
        assert_eq!(charges.len(), 1, "{charges:?}");
        assert_eq!(charges[0].members, vec![0, 1, 2]);
        let x = super::super::partition::intersection(&rays, &[0, 1, 2], &t).unwrap();
        assert!((charges[0].position - x).norm() < 1e-6);
        assert!(
            (charges[0].position - t).norm() < 0.05,
            "{:?}",
            charges[0].position
        );
    }

    #[test]
    fn pair_seeds_find_a_narrow_mode_the_stratified_seeds_miss() {
        // Two narrow rays (h = 0.002) meeting at right angles 7.3 m away: the mode's basin
        // on each ray is a few centimetres long, shorter than the spacing of 3 seeds.
        let t = Vector3::new(0.0, 0.0, 1.0);
        let p = vec![Vector3::new(-7.3, 0.0, 1.0), Vector3::new(0.0, -7.3, 1.0)];
        let v = p.iter().map(|p| (t - p).normalize()).collect();
        let rays = GazeRays::new(p, v, vec![0.002; 2], None).unwrap();
        let few = ModeOptions {
            seeds_per_ray: 3,
            pair_seeds: false,
            ..Default::default()
        };
        assert!(find_charges(&rays, &few, 0).unwrap().is_empty());
        let with_pairs = ModeOptions {
            pair_seeds: true,
            ..few
        };
        let c = find_charges(&rays, &with_pairs, 0).unwrap();
        assert_eq!(c.len(), 1);
        assert!((c[0].position - t).norm() < 1e-4);
    }

    #[test]
    fn pair_candidates_join_two_rays_off_target_on_opposite_sides() {
        // Two wearers 2 m and 3 m from a target look at it with their eyes 2 h off the
        // head's primary ray, one above it and one below: the rays pass 0.3 m apart, the
        // field has one ridge along each ray and no joint mode, yet the target is within
        // 2 h of both. The pair's candidate holds both, near the target.
        let t = Vector3::new(0.0, 0.0, 1.5);
        let h = 0.03;
        let p = vec![Vector3::new(-2.0, 0.0, 1.5), Vector3::new(0.0, -3.0, 1.5)];
        let off = |a: f64| -> Vec<Vector3<f64>> {
            p.iter()
                .zip([a, -a])
                .map(|(p, a)| ((t - p).normalize() + Vector3::z() * a).normalize())
                .collect()
        };
        let rays = GazeRays::new(p.clone(), off(2.0 * h), vec![h; 2], None).unwrap();
        let modes = ModeOptions {
            membership: Membership::All,
            ..Default::default()
        };
        assert!(find_charges(&rays, &modes, 0).unwrap().is_empty());
        let pairs = ModeOptions {
            pair_candidates: true,
            ..modes
        };
        let c = find_charges(&rays, &pairs, 0).unwrap();
        assert_eq!(c.len(), 1, "{c:?}");
        assert_eq!(c[0].members, vec![0, 1]);
        assert!((c[0].position - t).norm() < 0.05, "{:?}", c[0].position);
        // at the pair's least-squares intersection (the midpoint would be 6 cm off)
        let x = super::super::partition::intersection(&rays, &[0, 1], &t).unwrap();
        assert!(
            (c[0].position - x).norm() < 1e-3,
            "{:?} vs {x:?}",
            c[0].position
        );
        // Rays that meet have their mode: no second charge for the same pair.
        let exact = GazeRays::new(p.clone(), off(0.0), vec![h; 2], None).unwrap();
        let c = find_charges(&exact, &pairs, 0).unwrap();
        assert_eq!(c.len(), 1, "{c:?}");
        assert!(c[0].support > 0 && (c[0].position - t).norm() < 1e-4);
        // Rays 4 h off each are not within `member_sigma` (3) of any one point.
        let far = GazeRays::new(p.clone(), off(4.0 * h), vec![h; 2], None).unwrap();
        assert!(find_charges(&far, &pairs, 0).unwrap().is_empty());
    }

    #[test]
    fn huge_seed_counts_are_refused_before_allocating() {
        let rays = rays_at(
            &circle(3, 2.0, Vector3::zeros(), 0.5, 0.0),
            Vector3::zeros(),
            0.1,
            0,
        );
        let o = ModeOptions {
            seeds_per_ray: 1_000_000_000_000,
            ..Default::default()
        };
        assert!(matches!(
            find_charges(&rays, &o, 0),
            Err(Error::InvalidInput { arg, .. }) if arg == "seeds_per_ray"
        ));
    }

    #[test]
    fn lone_ray_and_rays_that_never_meet_give_nothing() {
        let one = rays_at(&[Vector3::zeros()], Vector3::x(), 0.1, 0);
        assert!(find_charges(&one, &ModeOptions::default(), 0)
            .unwrap()
            .is_empty());
        // Parallel rays, far apart, and rays pointing away from each other.
        let p = vec![
            Vector3::zeros(),
            Vector3::new(0.0, 5.0, 0.0),
            Vector3::new(9.0, -3.0, 0.0),
        ];
        let v = vec![Vector3::x(), Vector3::x(), Vector3::x()];
        let rays = GazeRays::new(p, v, vec![0.05; 3], None).unwrap();
        assert!(find_charges(&rays, &ModeOptions::default(), 0)
            .unwrap()
            .is_empty());
        let p = vec![Vector3::zeros(), Vector3::new(1.0, 0.0, 0.0)];
        let v = vec![-Vector3::x(), Vector3::x()];
        let rays = GazeRays::new(p, v, vec![0.1; 2], None).unwrap();
        assert!(find_charges(&rays, &ModeOptions::default(), 0)
            .unwrap()
            .is_empty());
    }

    #[test]
    fn min_members_and_bounds_filter() {
        let t = Vector3::new(0.0, 0.0, 1.0);
        let rays = rays_at(&circle(3, 2.0, t, 0.5, 0.0), t, 0.1, 0);
        let mut o = ModeOptions {
            min_members: 4,
            ..Default::default()
        };
        assert!(find_charges(&rays, &o, 0).unwrap().is_empty());
        o.min_members = 3;
        assert_eq!(find_charges(&rays, &o, 0).unwrap().len(), 1);
        o.bounds = Some((Vector3::new(1.0, -5.0, -5.0), Vector3::new(5.0, 5.0, 5.0)));
        assert!(find_charges(&rays, &o, 0).unwrap().is_empty());
    }

    #[test]
    fn deterministic_and_sequence_matches_frames() {
        let t = Vector3::new(0.3, -0.2, 1.1);
        // Noisy directions: turn each ray by a fixed small angle.
        let mut rays = rays_at(&circle(6, 3.0, t, 0.5, 0.2), t, 0.1, 0);
        for (k, v) in rays.v.iter_mut().enumerate() {
            let e = v.cross(&Vector3::z()).normalize();
            *v = (*v + e * (0.05 * ((k as f64) - 2.5))).normalize();
        }
        let o = ModeOptions::default();
        let a = find_charges(&rays, &o, 11).unwrap();
        let b = find_charges(&rays, &o, 11).unwrap();
        assert_eq!(a, b);
        let one_thread = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| find_charges(&rays, &o, 11).unwrap());
        assert_eq!(a, one_thread);
        let frame_only = ModeOptions {
            joint_window: false,
            ..o.clone()
        };
        let seq = find_charges_sequence(&[rays.clone(), rays.clone()], &frame_only, 11).unwrap();
        assert_eq!(seq, vec![a.clone(), a.clone()]);
        // The joint window over two copies of the frame: the same charge, at the
        // intersection of the same rays (its fit reweighted to convergence).
        let o = ModeOptions {
            joint_window: true,
            ..o
        };
        let joint = find_charges_sequence(&[rays.clone(), rays.clone()], &o, 11).unwrap();
        for cs in &joint {
            assert_eq!(cs.len(), 1);
            assert_eq!(cs[0].members, a[0].members);
            assert!((cs[0].position - a[0].position).norm() < 1e-6);
        }
        let joint_one_thread = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| find_charges_sequence(&[rays.clone(), rays.clone()], &o, 11).unwrap());
        assert_eq!(joint, joint_one_thread);
    }

    #[test]
    fn bad_options_are_refused() {
        let rays = rays_at(
            &circle(3, 2.0, Vector3::zeros(), 0.5, 0.0),
            Vector3::zeros(),
            0.1,
            0,
        );
        for o in [
            ModeOptions {
                seeds_per_ray: 0,
                ..Default::default()
            },
            ModeOptions {
                depth_min: 0.0,
                ..Default::default()
            },
            ModeOptions {
                depth_max: 0.1,
                ..Default::default()
            },
            ModeOptions {
                tol: f64::NAN,
                ..Default::default()
            },
            ModeOptions {
                region_level: 1.0,
                ..Default::default()
            },
            ModeOptions {
                min_members: 0,
                ..Default::default()
            },
        ] {
            assert!(matches!(
                find_charges(&rays, &o, 0),
                Err(Error::InvalidInput { .. })
            ));
        }
    }
}
