//! Estimating the social charges of a gaze field by Expectation–Maximization (thesis Sec
//! 7.3): one frame (Eq 7.10–7.13) and a time window (Eq 7.14).
//!
//! **E-step** (Eq 7.11): `γᵢⱼ ∝ πᵢ(pⱼ) V(vⱼ | Sᵢ(pⱼ)/‖Sᵢ(pⱼ)‖, κ)`; the magnitude of each
//! charge becomes `qᵢ = Σⱼ γᵢⱼ`. In a window the membership of a member is the
//! time-integrated one of Eq 7.14 (`Membership::PerWindow`, the thesis) or recomputed per
//! frame (`Membership::PerFrame`).
//!
//! **M-step** (Eq 7.12/7.14): `rᵢ = argmin Σⱼ γᵢⱼ² d((vⱼ, pⱼ), rᵢ)² + λ_g G(rᵢ)` with the
//! perspective distance `d` of Eq 7.13 (the tangent of the angle between the ray and the
//! direction to `rᵢ`). It is solved from the current estimate by Levenberg–Marquardt
//! (Gauss–Newton with adaptive damping, a step is kept only if it lowers the cost); in a
//! window the normal equations are banded (`G` couples neighbouring frames) and solved by
//! a banded Cholesky in `O(T)`.
//!
//! *Robust cap.* Eq 7.13 sets `d = ∞` for a point behind the eye. Because `γ > 0` for every
//! ray, the literal objective would be infinite as soon as one member faces away from a
//! charge. We cap the squared distance at `tan²(max_angle)`: a ray seeing the charge behind
//! it, or more than `max_angle` off its axis, adds a constant — it neither pulls the charge
//! nor forbids a position (a truncated quadratic, default 30°). With `max_angle → 90°` it tends to the
//! thesis's objective over rays that see the charge.
//!
//! **κ**: fixed, or re-estimated after each M-step by maximum likelihood from the
//! responsibility-weighted mean resultant `r̄ = Σ γ μᵀv / Σ γ` (`A₃(κ) = r̄`).

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::banded::Banded;
use super::field::{check_unit, components, validate_kappa, Component, SocialCharge};
use super::vmf::{kappa_from_resultant, log_density_cos};
use crate::error::{ensure_finite, Error, Result};

/// An observed primary gaze ray: eye centre `p` and unit direction `v` (Sec 3.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GazeRay {
    /// Centre of the eyes (metres).
    pub p: Vector3<f64>,
    /// Unit primary gaze direction.
    pub v: Vector3<f64>,
}

impl GazeRay {
    /// A ray; not validated (see [`validate_rays`]).
    pub fn new(p: Vector3<f64>, v: Vector3<f64>) -> Self {
        Self { p, v }
    }
}

/// Checks rays: finite `p`, finite unit `v`.
pub fn validate_rays(arg: &str, rays: &[GazeRay]) -> Result<()> {
    for (k, r) in rays.iter().enumerate() {
        ensure_finite(arg, r.p.as_slice())
            .map_err(|_| Error::invalid(arg, format!("ray {k} has a non-finite origin p")))?;
        check_unit(arg, &r.v).map_err(|_| {
            Error::invalid(
                arg,
                format!("ray {k}: direction v must be a finite unit vector"),
            )
        })?;
    }
    Ok(())
}

/// How `κ` is handled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kappa {
    /// Kept at this value (`> 0`).
    Fixed(f64),
    /// Re-estimated by maximum likelihood in every iteration, starting here (`> 0`).
    Estimate {
        /// Starting concentration.
        initial: f64,
    },
}

impl Kappa {
    fn initial(&self) -> f64 {
        match *self {
            Kappa::Fixed(k) => k,
            Kappa::Estimate { initial } => initial,
        }
    }
}

/// The temporal filter `G` of Eq 7.14 (thesis footnote 3), on consecutive frames of a window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TemporalFilter {
    /// `G(r) = Σₜ ‖r(t) − r(t−1)‖²`: minimal displacement.
    Velocity,
    /// `G(r) = Σₜ ‖2r(t) − r(t−1) − r(t+1)‖²`: minimal acceleration.
    Acceleration,
}

/// Membership used in a window's E-step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Membership {
    /// Eq 7.14: one `γᵢⱼ` per member for the whole window (densities integrated over time).
    PerWindow,
    /// Eq 7.11 at every frame: `γᵢⱼ(t)`, so a member may switch charges inside a window.
    PerFrame,
}

/// Options of the EM.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmOptions {
    /// `κ` fixed or estimated.
    pub kappa: Kappa,
    /// Cap on EM iterations.
    pub max_iterations: usize,
    /// Converged when no charge moves more than this (metres) in an iteration and `κ`
    /// changes by less than this relative amount.
    pub tolerance: f64,
    /// Rays further than this angle (radians, in `(0, π/2)`) from a charge, or with the
    /// charge behind them, add a constant to the M-step cost (see the module docs).
    pub max_angle: f64,
    /// Levenberg–Marquardt trials per M-step.
    pub inner_iterations: usize,
    /// Weight `λ_g ≥ 0` of the temporal filter (windows only).
    pub lambda_g: f64,
    /// The temporal filter `G`.
    pub filter: TemporalFilter,
    /// Membership in a window's E-step.
    pub membership: Membership,
}

impl Default for EmOptions {
    fn default() -> Self {
        Self {
            kappa: Kappa::Estimate { initial: 10.0 },
            max_iterations: 200,
            tolerance: 1e-7,
            max_angle: 30f64.to_radians(),
            inner_iterations: 5,
            lambda_g: 0.0,
            filter: TemporalFilter::Velocity,
            membership: Membership::PerWindow,
        }
    }
}

impl EmOptions {
    /// Checks every field.
    pub fn validate(&self) -> Result<()> {
        validate_kappa(self.kappa.initial())?;
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(Error::invalid("tol", "must be finite and > 0"));
        }
        if !(self.max_angle > 0.0 && self.max_angle < std::f64::consts::FRAC_PI_2) {
            return Err(Error::invalid("max_angle", "must lie in (0, pi/2) radians"));
        }
        if !(self.lambda_g.is_finite() && self.lambda_g >= 0.0) {
            return Err(Error::invalid("lambda_g", "must be finite and >= 0"));
        }
        if self.max_iterations == 0 || self.inner_iterations == 0 {
            return Err(Error::invalid(
                "max_iter, inner_iterations",
                "iteration counts must be at least 1",
            ));
        }
        Ok(())
    }
}

/// Gaze rays of one frame of a window with the index of the member each ray belongs to
/// (members are `0..J`; a member absent from a frame simply has no ray there).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WindowFrame {
    /// The rays.
    pub rays: Vec<GazeRay>,
    /// `members[k]` is the member of `rays[k]`; unique within a frame.
    pub members: Vec<usize>,
}

/// Result of the EM on one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameFit {
    /// The charges: positions and magnitudes `qᵢ = Σⱼ γᵢⱼ`.
    pub charges: Vec<SocialCharge>,
    /// Estimated (or fixed) concentration.
    pub kappa: f64,
    /// `γ` row-major `(J, I)`: ray `j`, charge `i`. A row is all zero for a ray at which no
    /// charge defines a direction.
    pub responsibilities: Vec<f64>,
    /// `ln L` of Eq 7.10 at the returned charges.
    pub log_likelihood: f64,
    /// EM iterations run.
    pub iterations: usize,
    /// Whether the tolerance was met before `max_iterations`.
    pub converged: bool,
}

/// Result of the EM on a time window.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowFit {
    /// `charges[t][i]`: charge `i` at frame `t` of the window (magnitude `qᵢ(t)` = summed
    /// membership of the members present at `t`).
    pub charges: Vec<Vec<SocialCharge>>,
    /// Concentration.
    pub kappa: f64,
    /// Window memberships `(J, I)` row-major (Eq 7.14 E-step; for `PerFrame`, the
    /// time-average of the per-frame memberships). Rows of members never seen are zero.
    pub membership: Vec<f64>,
    /// Per-frame responsibilities `responsibilities[t]`, `(rays of t, I)` row-major.
    pub responsibilities: Vec<Vec<f64>>,
    /// `Σₜ ln L(t)` (Eq 7.10 summed over the frames) at the returned charges.
    pub log_likelihood: f64,
    /// EM iterations.
    pub iterations: usize,
    /// Converged within `max_iterations`.
    pub converged: bool,
}

/// Smallest depth `vᵀ(x − p)` (metres) at which a ray still counts as seeing a point.
const MIN_DEPTH: f64 = 1e-9;

/// Perspective residual (Eq 7.13 as a vector) and its Jacobian, or `None` when capped.
#[inline]
fn residual(ray: &GazeRay, x: &Vector3<f64>, cap2: f64) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    let w = x - ray.p;
    let a = ray.v.dot(&w);
    if a <= MIN_DEPTH {
        return None;
    }
    let u = w - ray.v * a;
    let d = u / a;
    if d.norm_squared() >= cap2 {
        return None;
    }
    let proj = Matrix3::identity() - ray.v * ray.v.transpose();
    let jac = proj / a - (u * ray.v.transpose()) / (a * a);
    Some((d, jac))
}

#[inline]
fn capped_sq(ray: &GazeRay, x: &Vector3<f64>, cap2: f64) -> f64 {
    let w = x - ray.p;
    let a = ray.v.dot(&w);
    if a <= MIN_DEPTH {
        return cap2;
    }
    let u = w - ray.v * a;
    (u.norm_squared() / (a * a)).min(cap2)
}

/// Rows of the difference operator of `G` over `t` frames: `(first frame, coefficients)`.
fn filter_rows(filter: TemporalFilter, t: usize) -> Vec<(usize, &'static [f64])> {
    const VEL: [f64; 2] = [-1.0, 1.0];
    const ACC: [f64; 3] = [-1.0, 2.0, -1.0];
    match filter {
        TemporalFilter::Velocity if t >= 2 => (0..t - 1).map(|s| (s, &VEL[..])).collect(),
        TemporalFilter::Acceleration if t >= 3 => (0..t - 2).map(|s| (s, &ACC[..])).collect(),
        _ => Vec::new(),
    }
}

/// The M-step of one charge over a window: minimises
/// `Σₜ Σₖ wₜₖ min(‖d(rayₜₖ, xₜ)‖², cap²) + λ Σ_rows ‖Σ c xₜ‖²` by Levenberg–Marquardt from `x`.
/// `weights[t][k]` pairs with `frames[t].rays[k]`. Returns the final cost.
#[allow(clippy::too_many_arguments)]
fn m_step(
    frames: &[WindowFrame],
    weights: &[Vec<f64>],
    x: &mut [Vector3<f64>],
    cap2: f64,
    lambda: f64,
    rows: &[(usize, &'static [f64])],
    trials: usize,
    tol: f64,
) -> f64 {
    let t_len = x.len();
    let span = rows.first().map_or(1, |(_, c)| c.len());
    let band = 3 * span - 1;
    let cost = |x: &[Vector3<f64>]| -> f64 {
        let mut c = 0.0;
        for (t, f) in frames.iter().enumerate() {
            for (k, ray) in f.rays.iter().enumerate() {
                let w = weights[t][k];
                if w > 0.0 {
                    c += w * capped_sq(ray, &x[t], cap2);
                }
            }
        }
        if lambda > 0.0 {
            for (s, coef) in rows {
                let mut d = Vector3::zeros();
                for (o, cf) in coef.iter().enumerate() {
                    d += x[s + o] * *cf;
                }
                c += lambda * d.norm_squared();
            }
        }
        c
    };
    let mut current = cost(x);
    let mut mu = 1e-3;
    let mut h = Banded::zeros(3 * t_len, band);
    let mut g = vec![0.0; 3 * t_len];
    let mut cand = x.to_vec();
    let mut build = true;
    let mut diag = vec![0.0; 3 * t_len];
    for _ in 0..trials {
        if build {
            h.clear();
            g.iter_mut().for_each(|v| *v = 0.0);
            for (t, f) in frames.iter().enumerate() {
                let mut jtj = Matrix3::zeros();
                let mut jtd = Vector3::zeros();
                for (k, ray) in f.rays.iter().enumerate() {
                    let w = weights[t][k];
                    if w <= 0.0 {
                        continue;
                    }
                    if let Some((d, j)) = residual(ray, &x[t], cap2) {
                        let jt = j.transpose();
                        jtj += (jt * j) * w;
                        jtd += (jt * d) * w;
                    }
                }
                for a in 0..3 {
                    g[3 * t + a] += jtd[a];
                    for b in 0..=a {
                        h.add(3 * t + a, 3 * t + b, jtj[(a, b)]);
                    }
                }
            }
            if lambda > 0.0 {
                for (s, coef) in rows {
                    let mut d = Vector3::zeros();
                    for (o, cf) in coef.iter().enumerate() {
                        d += x[s + o] * *cf;
                    }
                    for (oa, ca) in coef.iter().enumerate() {
                        for a in 0..3 {
                            g[3 * (s + oa) + a] += lambda * ca * d[a];
                        }
                        for (ob, cb) in coef.iter().enumerate().take(oa + 1) {
                            for a in 0..3 {
                                h.add(3 * (s + oa) + a, 3 * (s + ob) + a, lambda * ca * cb);
                            }
                        }
                    }
                }
            }
            for (i, dv) in diag.iter_mut().enumerate() {
                *dv = h.diag(i);
            }
            build = false;
        }
        if g.iter().all(|v| *v == 0.0) {
            break;
        }
        let max_diag = diag.iter().copied().fold(0.0, f64::max);
        let floor = 1e-12 * max_diag + 1e-300;
        let mut sys = h.clone();
        for (i, dv) in diag.iter().enumerate() {
            sys.add_diag(i, mu * (dv + floor) + floor);
        }
        let mut step: Vec<f64> = g.iter().map(|v| -v).collect();
        if !sys.cholesky_solve(&mut step) || step.iter().any(|v| !v.is_finite()) {
            mu *= 10.0;
            continue;
        }
        let mut max_move: f64 = 0.0;
        for t in 0..t_len {
            let dt = Vector3::new(step[3 * t], step[3 * t + 1], step[3 * t + 2]);
            max_move = max_move.max(dt.norm());
            cand[t] = x[t] + dt;
        }
        let c = cost(&cand);
        if c < current {
            x.copy_from_slice(&cand);
            current = c;
            mu = (mu / 3.0).max(1e-12);
            build = true;
            if max_move < 0.01 * tol {
                break;
            }
        } else {
            mu *= 4.0;
            if mu > 1e12 {
                break;
            }
        }
    }
    current
}

/// Validates a window's frames and initial positions; returns `(J, I)`.
fn validate_window(frames: &[WindowFrame], init: &[Vec<Vector3<f64>>]) -> Result<(usize, usize)> {
    if frames.is_empty() {
        return Err(Error::invalid(
            "frames",
            "a window needs at least one frame",
        ));
    }
    if init.len() != frames.len() {
        return Err(Error::invalid(
            "init",
            format!(
                "needs one row of charge positions per frame ({}), got {}",
                frames.len(),
                init.len()
            ),
        ));
    }
    let n_charges = init[0].len();
    if n_charges == 0 {
        return Err(Error::invalid(
            "n_charges",
            "zero social charges: the gaze field needs at least one charge",
        ));
    }
    let mut n_members = 0;
    for (t, (f, row)) in frames.iter().zip(init).enumerate() {
        if row.len() != n_charges {
            return Err(Error::invalid(
                "init",
                format!(
                    "frame {t} has {} charges, frame 0 has {n_charges}",
                    row.len()
                ),
            ));
        }
        for x in row {
            ensure_finite("init", x.as_slice())?;
        }
        if f.members.len() != f.rays.len() {
            return Err(Error::invalid(
                "members",
                format!(
                    "frame {t}: {} rays but {} member ids",
                    f.rays.len(),
                    f.members.len()
                ),
            ));
        }
        validate_rays("rays", &f.rays)?;
        let mut seen = f.members.clone();
        seen.sort_unstable();
        if seen.windows(2).any(|w| w[0] == w[1]) {
            return Err(Error::invalid(
                "members",
                format!("frame {t} lists a member twice"),
            ));
        }
        if let Some(m) = seen.last() {
            n_members = n_members.max(m.saturating_add(1));
        }
    }
    // Member indices are dense (0..J): a huge index would allocate a huge membership table.
    crate::error::ensure_alloc("members", &[n_members, n_charges], 8)?;
    Ok((n_members, n_charges))
}

/// Log of `πᵢ V(vⱼ | μᵢ, κ)` for every charge at one ray (`−∞` where undefined).
fn ray_log_terms(
    charges: &[SocialCharge],
    ray: &GazeRay,
    kappa: f64,
    comps: &mut Vec<Component>,
    out: &mut [f64],
) {
    out.iter_mut().for_each(|v| *v = f64::NEG_INFINITY);
    components(charges, &ray.p, comps);
    for c in comps.iter() {
        out[c.index] = c.log_weight + log_density_cos(c.direction.dot(&ray.v), kappa);
    }
}

fn softmax_into(logs: &[f64], out: &mut [f64]) {
    let m = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        out.iter_mut().for_each(|v| *v = 0.0);
        return;
    }
    let mut s = 0.0;
    for (o, l) in out.iter_mut().zip(logs) {
        *o = (l - m).exp();
        s += *o;
    }
    out.iter_mut().for_each(|v| *v /= s);
}

fn lse(logs: &[f64]) -> f64 {
    let m = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return m;
    }
    m + logs.iter().map(|l| (l - m).exp()).sum::<f64>().ln()
}

const LOG_UNIFORM: f64 = -2.531_024_246_969_291; // −ln 4π

/// Time-windowed EM (Eq 7.14) for a fixed number of charges `I = init[0].len()` over the
/// frames of one window, from initial positions `init[t][i]` (e.g. tracked social charges
/// of Chapter 6). With one frame it is the single-frame EM of Eq 7.10–7.12.
///
/// Errors: zero charges, NaN/non-unit rays, NaN initial positions, `κ ≤ 0` or bad options
/// → `InvalidInput`. Reaching `max_iterations` is not an error (`converged = false`).
pub fn em_window(
    frames: &[WindowFrame],
    init: &[Vec<Vector3<f64>>],
    opts: &EmOptions,
) -> Result<WindowFit> {
    opts.validate()?;
    let (n_members, n_charges) = validate_window(frames, init)?;
    let fit = em_window_unchecked(frames, init, opts, n_members, n_charges);
    crate::interrupt::check()?;
    Ok(fit)
}

fn em_window_unchecked(
    frames: &[WindowFrame],
    init: &[Vec<Vector3<f64>>],
    opts: &EmOptions,
    n_members: usize,
    n_charges: usize,
) -> WindowFit {
    let t_len = frames.len();
    let ni = n_charges;
    let cap2 = opts.max_angle.tan().powi(2);
    let rows = filter_rows(opts.filter, t_len);
    let lambda = if t_len > 1 { opts.lambda_g } else { 0.0 };
    let estimate = matches!(opts.kappa, Kappa::Estimate { .. });
    let mut kappa = opts.kappa.initial();
    // charges[t][i]; magnitudes start equal.
    let mut charges: Vec<Vec<SocialCharge>> = init
        .iter()
        .map(|row| row.iter().map(|x| SocialCharge::new(*x, 1.0)).collect())
        .collect();
    // log terms and responsibilities per frame: (rays, I) row-major.
    let mut logs: Vec<Vec<f64>> = frames
        .iter()
        .map(|f| vec![0.0; f.rays.len() * ni])
        .collect();
    let mut gamma: Vec<Vec<f64>> = logs.clone();
    let mut membership = vec![0.0; n_members * ni];
    let mut comps = Vec::with_capacity(ni);
    let mut acc = vec![f64::NEG_INFINITY; n_members * ni];
    let mut buf = vec![0.0; ni];
    let mut iterations = 0;
    let mut converged = false;
    let mut log_likelihood;
    let mut positions_prev: Vec<Vec<Vector3<f64>>> = init.to_vec();
    let mut kappa_prev = kappa;
    loop {
        // ---- E-step (Eq 7.11 / 7.14) ----
        log_likelihood = 0.0;
        for (t, f) in frames.iter().enumerate() {
            for (k, ray) in f.rays.iter().enumerate() {
                let row = &mut logs[t][k * ni..(k + 1) * ni];
                ray_log_terms(&charges[t], ray, kappa, &mut comps, row);
                let l = lse(row);
                log_likelihood += if l == f64::NEG_INFINITY {
                    LOG_UNIFORM
                } else {
                    l
                };
            }
        }
        match opts.membership {
            Membership::PerFrame => {
                for (t, f) in frames.iter().enumerate() {
                    for k in 0..f.rays.len() {
                        let (l, g) = (
                            &logs[t][k * ni..(k + 1) * ni],
                            &mut gamma[t][k * ni..(k + 1) * ni],
                        );
                        softmax_into(l, g);
                    }
                }
                membership.iter_mut().for_each(|v| *v = 0.0);
                let mut counts = vec![0usize; n_members];
                for (t, f) in frames.iter().enumerate() {
                    for (k, m) in f.members.iter().enumerate() {
                        counts[*m] += 1;
                        for i in 0..ni {
                            membership[m * ni + i] += gamma[t][k * ni + i];
                        }
                    }
                }
                for (m, c) in counts.iter().enumerate() {
                    if *c > 0 {
                        for i in 0..ni {
                            membership[m * ni + i] /= *c as f64;
                        }
                    }
                }
            }
            Membership::PerWindow => {
                // ∫ πᵢ V dt per member and charge, in the log domain (unit frame weights).
                acc.iter_mut().for_each(|v| *v = f64::NEG_INFINITY);
                for (t, f) in frames.iter().enumerate() {
                    for (k, m) in f.members.iter().enumerate() {
                        for i in 0..ni {
                            let a = &mut acc[m * ni + i];
                            let l = logs[t][k * ni + i];
                            if l > f64::NEG_INFINITY {
                                *a = if *a == f64::NEG_INFINITY {
                                    l
                                } else {
                                    let hi = a.max(l);
                                    hi + ((*a - hi).exp() + (l - hi).exp()).ln()
                                };
                            }
                        }
                    }
                }
                for m in 0..n_members {
                    softmax_into(
                        &acc[m * ni..(m + 1) * ni],
                        &mut membership[m * ni..(m + 1) * ni],
                    );
                }
                for (t, f) in frames.iter().enumerate() {
                    for (k, m) in f.members.iter().enumerate() {
                        // Where a charge is undefined at this ray (it sits on the member),
                        // the member does not look at it here: renormalise over the rest.
                        let l = &logs[t][k * ni..(k + 1) * ni];
                        let mut s = 0.0;
                        for i in 0..ni {
                            buf[i] = if l[i] > f64::NEG_INFINITY {
                                membership[m * ni + i]
                            } else {
                                0.0
                            };
                            s += buf[i];
                        }
                        for i in 0..ni {
                            gamma[t][k * ni + i] = if s > 0.0 { buf[i] / s } else { 0.0 };
                        }
                    }
                }
            }
        }
        // Magnitudes qᵢ(t) = Σⱼ γᵢⱼ(t).
        for (t, f) in frames.iter().enumerate() {
            if f.rays.is_empty() {
                continue;
            }
            for i in 0..ni {
                charges[t][i].magnitude = (0..f.rays.len()).map(|k| gamma[t][k * ni + i]).sum();
            }
        }
        if iterations > 0 {
            let mut moved: f64 = 0.0;
            for t in 0..t_len {
                for i in 0..ni {
                    moved = moved.max((charges[t][i].position - positions_prev[t][i]).norm());
                }
            }
            let dk = (kappa - kappa_prev).abs() / kappa_prev;
            if moved < opts.tolerance && dk < opts.tolerance {
                converged = true;
                break;
            }
        }
        // Ctrl-C: stop after this E-step; `em_window` turns it into `Interrupted`.
        if iterations >= opts.max_iterations || crate::interrupt::requested() {
            break;
        }
        iterations += 1;
        for t in 0..t_len {
            for i in 0..ni {
                positions_prev[t][i] = charges[t][i].position;
            }
        }
        kappa_prev = kappa;
        // ---- M-step (Eq 7.12 / 7.14): each charge independently ----
        let mut x = vec![Vector3::zeros(); t_len];
        let mut weights: Vec<Vec<f64>> = frames.iter().map(|f| vec![0.0; f.rays.len()]).collect();
        for i in 0..ni {
            for t in 0..t_len {
                x[t] = charges[t][i].position;
                for (k, w) in weights[t].iter_mut().enumerate() {
                    let g = gamma[t][k * ni + i];
                    *w = g * g;
                }
            }
            m_step(
                frames,
                &weights,
                &mut x,
                cap2,
                lambda,
                &rows,
                opts.inner_iterations,
                opts.tolerance,
            );
            for t in 0..t_len {
                charges[t][i].position = x[t];
            }
        }
        // ---- κ (ML from the weighted mean resultant) ----
        if estimate {
            let (mut num, mut den) = (0.0, 0.0);
            for (t, f) in frames.iter().enumerate() {
                for (k, ray) in f.rays.iter().enumerate() {
                    for i in 0..ni {
                        let g = gamma[t][k * ni + i];
                        if g <= 0.0 {
                            continue;
                        }
                        let d = charges[t][i].position - ray.p;
                        let n = d.norm();
                        if n > 0.0 {
                            num += g * d.dot(&ray.v) / n;
                            den += g;
                        }
                    }
                }
            }
            if den > 0.0 {
                kappa = kappa_from_resultant(num / den);
            }
        }
    }
    WindowFit {
        charges,
        kappa,
        membership,
        responsibilities: gamma,
        log_likelihood,
        iterations,
        converged,
    }
}

/// Single-frame EM (Eq 7.10–7.13) from initial charge positions `init` (`I ≥ 1`).
pub fn em_frame(rays: &[GazeRay], init: &[Vector3<f64>], opts: &EmOptions) -> Result<FrameFit> {
    let frame = WindowFrame {
        rays: rays.to_vec(),
        members: (0..rays.len()).collect(),
    };
    let mut fit = em_window(std::slice::from_ref(&frame), &[init.to_vec()], opts)?;
    Ok(FrameFit {
        charges: fit.charges.pop().unwrap_or_default(),
        kappa: fit.kappa,
        responsibilities: fit.responsibilities.pop().unwrap_or_default(),
        log_likelihood: fit.log_likelihood,
        iterations: fit.iterations,
        converged: fit.converged,
    })
}

/// Single-frame EM on many independent frames in parallel (same result whatever the
/// thread count). `inits[f]` are frame `f`'s initial positions.
pub fn em_frames(
    frames: &[Vec<GazeRay>],
    inits: &[Vec<Vector3<f64>>],
    opts: &EmOptions,
) -> Result<Vec<FrameFit>> {
    if frames.len() != inits.len() {
        return Err(Error::invalid(
            "inits",
            format!(
                "{} frames but {} rows of initial charges",
                frames.len(),
                inits.len()
            ),
        ));
    }
    opts.validate()?;
    frames
        .par_iter()
        .zip(inits.par_iter())
        .enumerate()
        .map(|(f, (rays, init))| {
            em_frame(rays, init, opts).map_err(|e| match e {
                Error::InvalidInput { arg, msg } => {
                    Error::invalid(arg, format!("frame {f}: {msg}"))
                }
                other => other,
            })
        })
        .collect()
}

/// A window of consecutive frames `start..end` holding `n_charges` charges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// First frame.
    pub start: usize,
    /// One past the last frame.
    pub end: usize,
    /// Number of charges throughout.
    pub n_charges: usize,
}

/// Splits a sequence into windows where the number of charges stays constant (Sec 7.3.1,
/// "in practice"). Runs shorter than `min_len` frames are first absorbed into the preceding
/// run (the following one at the start), so a one-frame flicker of the charge count does
/// not create a window. Frames with zero charges form windows with `n_charges = 0`, which
/// the caller skips (no field is defined there).
pub fn split_windows(counts: &[usize], min_len: usize) -> Vec<Window> {
    let mut runs: Vec<Window> = Vec::new();
    for (t, &c) in counts.iter().enumerate() {
        match runs.last_mut() {
            Some(w) if w.n_charges == c => w.end = t + 1,
            _ => runs.push(Window {
                start: t,
                end: t + 1,
                n_charges: c,
            }),
        }
    }
    if min_len <= 1 || runs.len() <= 1 {
        return runs;
    }
    // Absorb short runs, shortest first, into the neighbour (previous if any).
    loop {
        let short = runs
            .iter()
            .enumerate()
            .filter(|(_, w)| w.end - w.start < min_len)
            .min_by_key(|(i, w)| (w.end - w.start, *i))
            .map(|(i, _)| i);
        let Some(i) = short else { break };
        if runs.len() == 1 {
            break;
        }
        if i > 0 {
            runs[i - 1].end = runs[i].end;
        } else {
            runs[1].start = runs[0].start;
        }
        runs.remove(i);
        // Merge equal neighbours created by the absorption.
        let mut merged: Vec<Window> = Vec::with_capacity(runs.len());
        for w in runs.drain(..) {
            match merged.last_mut() {
                Some(m) if m.n_charges == w.n_charges => m.end = w.end,
                _ => merged.push(w),
            }
        }
        runs = merged;
    }
    runs
}

/// A window and its initial positions `init[t − start][i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowJob {
    /// First frame (into the sequence).
    pub start: usize,
    /// One past the last frame.
    pub end: usize,
    /// Initial positions per frame of the window.
    pub init: Vec<Vec<Vector3<f64>>>,
}

/// Runs [`em_window`] on many windows of one sequence in parallel (deterministic order).
pub fn em_windows(
    frames: &[WindowFrame],
    jobs: &[WindowJob],
    opts: &EmOptions,
) -> Result<Vec<WindowFit>> {
    opts.validate()?;
    for (w, j) in jobs.iter().enumerate() {
        if j.start >= j.end || j.end > frames.len() {
            return Err(Error::invalid(
                "windows",
                format!(
                    "window {w} = {}..{} is empty or outside the {} frames",
                    j.start,
                    j.end,
                    frames.len()
                ),
            ));
        }
    }
    jobs.par_iter()
        .map(|j| em_window(&frames[j.start..j.end], &j.init, opts))
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests;
