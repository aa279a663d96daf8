//! Articulated trajectories from one camera per frame (thesis Chapter 4).
//!
//! A child joint stays at distance `r` from its known parent trajectory `X_p(t)`. Each
//! frame's ray meets the sphere of radius `r` about the parent twice (Eq 4.8–4.9); choosing
//! one intersection per frame so that the relative directions are best explained by a
//! DCT trajectory basis `Θ` is the binary quadratic program of Eq 4.10–4.12, solved
//! exactly by [`crate::bqp`]. The chosen directions are projected onto the basis in
//! spherical coordinates (Eq 4.4, with angle unwrapping) and refined by Levenberg–Marquardt
//! on the reprojection error (Eq 4.5). Frames without an observation are imputed by the
//! basis. Whole skeletons are reconstructed from the root outwards (Eq 4.6).

// Index loops mirror the equations in these dense numeric kernels.
#![allow(clippy::needless_range_loop)]

use crate::basis::DctSpan;
use crate::bqp::{solve_bqp, BqpOptions, BqpProblem, BqpSolution};
use crate::error::{ensure_finite, Error, Result};
use crate::geometry::{line_point_distance, ray_sphere, Camera, LmOptions};
use nalgebra::{DMatrix, DVector, Matrix3, Vector2, Vector3};
use std::f64::consts::{PI, TAU};

/// How the ray–sphere ambiguity is resolved and the bone length treated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArticulatedMethod {
    /// The thesis (Sec 4.2): one BQP at the given length (enlarged so that every ray meets
    /// the sphere), refinement of Eq 4.5 at that fixed length.
    Thesis,
    /// Robust to length and root error: the BQP is also solved on a sphere shrunk to a
    /// quantile of the parent-to-ray distances (near-grazing rays then touch the sphere at
    /// one point, so the true trajectory can pass from one root to the other), each start
    /// is refined with the bone length free within `length_tol`, and the start with the
    /// one that best trades the reprojection error against smoothness wins
    /// (`smooth_weight`).
    Robust,
}

/// Weight of the bone-length prior of the robust refinement: a length off by `length_tol`
/// (relative) costs as much as `LENGTH_PRIOR` pixels of reprojection error at every
/// observation (chosen on CMU 131/85 windows: 0 lets the length drift to its bounds, 1
/// pins it to the given, possibly wrong, value).
pub const LENGTH_PRIOR: f64 = 0.3;

/// Default of [`ArticulatedOptions::smooth_weight`]: a start ten times smoother (in the
/// sense of Eq 4.12) than another is preferred unless its reprojection cost is higher by
/// more than this many standard deviations of the cost. Among 0.5–4 on the CMU windows of
/// `benches/articulated_accuracy.py` (6 noise draws) weights 1–3 perform alike (Fig 4.3(c)
/// mean 0.147–0.153 dev, 0.160–0.162 held-out, 0.223–0.231 new), while on the 131_01
/// scene of the tests weights above 1 lose to the lowest cost (mean 0.24 at 1, 0.34 at 2):
/// the lowest weight that helps was kept (session 5, before the motion term; with it, 0.5
/// and 1 perform alike on the same windows).
pub const SMOOTH_WEIGHT: f64 = 1.0;

/// Default of [`ArticulatedOptions::motion_weight`]: a start whose bone direction sweeps
/// ten times less angular variance over the window than another is preferred unless its
/// score is otherwise worse by twice this many units. On the CMU windows of
/// `benches/articulated_accuracy.py` (Fig 4.3(c), 6 noise draws) the wrong starts that
/// fit the pixels and Eq 4.12 as well as the truth are mostly slow swings of the bone away
/// from the truth towards the impostor side: they move more. Among 0, 1, 2, 4 (with
/// `smooth_weight` 1): mean 0.151 / 0.120 / 0.122 / 0.125 on the development windows,
/// 0.161 / 0.130 / 0.121 / 0.120 held out, 0.231 / 0.231 / 0.234 / 0.233 on the starting
/// and stopping clips; at exact length and root mean/median 2.20 / 1.89 / 1.62 / 1.54 held
/// out. 2 was kept (weights 1–4 alike; the last two figures favour the larger).
pub const MOTION_WEIGHT: f64 = 2.0;

/// Suggested [`ArticulatedOptions::length_weight`] (the option is off by default): a start
/// whose refined bone is 5 % longer than another's must fit the pixels better by about one
/// standard deviation of the cost (`20 · ln 1.05 ≈ 1`). Measured on the CMU windows of
/// `benches/articulated_accuracy.py` (dev, held-out, new and fresh; 3 noise draws; every
/// refined start recorded): where the selection kept a start more than twice as far from
/// the truth as the best one (and over 0.2 of the bone), the kept start had the longer bone
/// in 257 of 320 cases. In the bench ("robust-lw20", Fig 4.3(c) mean, 3 draws) it lowers
/// the error on dev 0.125 → 0.116, held-out 0.130 → 0.126, new 0.200 → 0.184, fresh
/// 0.269 → 0.256 and on the never-seen final9 0.152 → 0.138 and final11 0.237 → 0.213, but
/// not on unseen (0.138 → 0.142, the standing clips) nor unseen8 (0.171 → 0.173), and at
/// exact length and root it raises the unseen mean/median ratio 2.10 → 2.87 (131_02a): so
/// it is not on by default.
pub const LENGTH_WEIGHT: f64 = 20.0;

/// Default of [`ArticulatedOptions::angle_weight`]: a start outside an [`AnglePrior`]'s
/// range by one [`ArticulatedOptions::angle_tolerance`] at every frame scores as if it
/// fitted the pixels worse by this many standard deviations of the cost.
pub const ANGLE_WEIGHT: f64 = 1.0;

/// Default of [`ArticulatedOptions::angle_tolerance`], radians (5°): the angle between a
/// joint's bone and a reference bone computed from a parent and reference joints a few
/// percent of their bones off is itself off by several degrees, so a start only counts as
/// leaving the range by whole multiples of this.
pub const ANGLE_TOLERANCE: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// Default of [`ArticulatedOptions::angle_refine`]: a frame's bone one tolerance outside a
/// range costs as much as a quarter px² of reprojection error. Chosen on the CMU windows of
/// `benches/articulated_accuracy.py` (dev / held-out / new / fresh / lowrate, seed 0): under
/// Fig 4.3(c) 0.5 takes most of the gain of 1 (mean 0.104 → 0.088 against 0.087 on dev + new)
/// while at exact length and root, where ranges learned from another trial pull a true bone
/// that leaves them, it costs less (0.043 → 0.043 against 0.049).
pub const ANGLE_REFINE: f64 = 0.5;

/// Roughness (Eq 4.12 on the refined unit directions) below which two starts count as
/// equally smooth: keeps the logarithm finite for trajectories inside the basis.
pub const ROUGHNESS_FLOOR: f64 = 1e-6;

/// Default of [`ArticulatedOptions::child_slack`]: a child may lie up to 10 % farther from
/// the joint than its given bone length (the tolerance of the joint's own length,
/// [`ArticulatedOptions::length_tol`]).
pub const CHILD_SLACK: f64 = 0.1;

/// Default of [`ArticulatedOptions::refine_k_max`]: four times the default `k`. Sixty
/// frames at 20–40 Hz (2–3 s of walking) need more than `2k` vectors: capped at 16, BIC
/// stopped at the cap on most such joints with the fit still pixels off at 0.5 px noise
/// (session 18); at 60 Hz BIC mostly stops below 16 and the cap rarely binds.
pub const REFINE_K_MAX: usize = 32;

/// Settings of [`reconstruct_articulated`].
#[derive(Debug, Clone, Copy)]
pub struct ArticulatedOptions {
    /// Number of DCT basis vectors `K` per angle.
    pub k: usize,
    /// Run the Levenberg–Marquardt refinement of Eq 4.5.
    pub refine: bool,
    pub lm: LmOptions,
    /// Limits of the branch-and-bound (on a limit the best incumbent is used).
    pub bqp: BqpOptions,
    /// Set the sphere radius to the largest parent-to-ray distance over the observed
    /// frames, shrinking an over-estimated length as well as enlarging a short one. The
    /// thesis only enlarges (Sec 4.4.1, the default); fitting assumes that the bone passes
    /// at least once near perpendicular to the viewing ray, and makes the reconstruction
    /// robust to over-estimated lengths and root error.
    pub fit_radius: bool,
    pub method: ArticulatedMethod,
    /// Robust method: the shrunk BQP sphere has the radius of this quantile (in `[0, 1]`)
    /// of the parent-to-ray distances over the observed frames (never above the thesis
    /// radius).
    pub tangent_quantile: f64,
    /// Robust method: the bone length is refined within `[r/(1+tol), r(1+tol)]` of the
    /// thesis radius `r`, with a Gaussian prior of relative deviation `tol` about `r`
    /// (weight [`LENGTH_PRIOR`]); 0 keeps it fixed.
    pub length_tol: f64,
    /// Robust method: rays whose two roots' unit directions are closer than this (a local
    /// minimum in time) are grazing points where passing to the other root is also tried.
    pub grazing_separation: f64,
    /// Robust method: rounds of the greedy search over those passes (0 = none).
    pub flip_rounds: usize,
    /// Robust method: weight of smoothness against the pixels when choosing among the
    /// refined starts. Each start scores `Δc / s + w · log₁₀(roughness)`, with `Δc` its
    /// reprojection cost above the lowest, `s` the standard deviation of that cost (a χ² at
    /// the noise level estimated from the lowest) and the roughness the objective of Eq 4.12
    /// on its refined unit directions; the lowest score wins. 0 keeps the lowest cost.
    pub smooth_weight: f64,
    /// Robust method: weight of the least-motion evidence in the same score:
    /// `+ motion_weight · log₁₀(motion)`, the motion being the angular variance of the
    /// refined bone direction over the window, `Σ_t ‖u_t − ū‖²` (every frame, `u` the unit
    /// parent-to-child direction). 0 leaves the score of `smooth_weight` alone.
    pub motion_weight: f64,
    /// Robust method: largest DCT basis size of the final refinement. The `k` of the binary
    /// program and of the start selection is a prior on smoothness; the motion of a window
    /// (a subject starting to walk, an arm swinging up) can need more. So the selected start
    /// is refined again with `k + 1, …, refine_k_max` basis vectors per angle (new
    /// coefficients start at zero) and the size with the lowest Bayesian information
    /// criterion `2n ln(c / 2n) + (2k' + 1) ln 2n` on its reprojection cost `c` (`n`
    /// observations) is kept. Sizes above half the observed frames are not tried;
    /// `refine_k_max ≤ k` keeps `k` (session 6's method).
    pub refine_k_max: usize,
    /// Robust method, with the joint's children observed ([`reconstruct_articulated_with`]):
    /// each child must lie on its own viewing ray within `(1 + child_slack)` times its given
    /// bone length of the joint. A start whose joint lies farther than that from a child's
    /// ray at some frame pays the child's reprojection error of that frame (the excess
    /// distance in pixels at the joint's depth, squared) in the selection score. The
    /// impostor side of the joint's ray is often too far from its children's rays, which
    /// the joint's own pixels cannot show.
    pub child_slack: f64,
    /// Robust method: weight of the bone length in the selection score,
    /// `+ length_weight · ln(r / r_min)` for a start refined to length `r` (`r_min` the
    /// shortest refined length among the starts; [`LENGTH_WEIGHT`]). Where a ray grazes the
    /// sphere, the wrong branch can follow the far root and still fit the pixels by
    /// lengthening the bone within `length_tol`, while the true branch touches the sphere
    /// there: of two starts that explain the pixels alike, the one with the shorter bone is
    /// preferred. 0 (the default) leaves the selection to the other weights; see
    /// [`LENGTH_WEIGHT`] for the weight measured and why it is off.
    pub length_weight: f64,
    /// Robust method: return the average of the refined starts' trajectories weighted by
    /// `exp(−λ Δscore)` (Δscore above the best start's score of `smooth_weight`;
    /// [`AVERAGE_SHARPNESS`]; normalised to sum to 1), instead of the best start alone.
    /// Where the pixels, Eq 4.12 and the least motion cannot tell two starts apart
    /// (near-grazing rays under root and length error, where the starts are a family of
    /// trajectories along the rays), the best start is as often the farther one as the
    /// nearer: the average lowers the expected error under the scores read as a posterior
    /// over the starts. Each distinct solution counts once ([`DISTINCT_STARTS`]), and
    /// nothing is averaged where the final refinement grew the basis (the starts' costs are
    /// then misfit, not noise). Off by default (the best start alone): on the CMU windows
    /// of `benches/articulated_accuracy.py` ("robust-avg") it lowers the Fig 4.3(c) mean
    /// error by 2–5 % and leaves the exact-length error unchanged, but raises the median
    /// on one test scene.
    pub average_starts: bool,
    /// Robust method, with [`AnglePrior`]s: weight of each prior in the selection score,
    /// `+ angle_weight · mean_t (e_t / angle_tolerance)²`, `e_t` the angle by which the
    /// start's bone at frame `t` leaves the prior's range ([`ANGLE_WEIGHT`]); ≥ 0, 0 ignores
    /// the priors.
    pub angle_weight: f64,
    /// Robust method, with [`AnglePrior`]s: the angle (radians, > 0) by which a bone
    /// outside a range counts as one unit ([`ANGLE_TOLERANCE`]).
    pub angle_tolerance: f64,
    /// Robust method, with [`AnglePrior`]s: also refine the start whose root in every
    /// observed frame leaves the priors' ranges least (a start the binary program and the
    /// flips at grazing frames may miss when the whole window follows the impostor).
    pub prior_start: bool,
    /// Robust method, with [`AnglePrior`]s: the refinement (Eq 4.5) also minimises each
    /// frame's excess `e` beyond each prior's range as a residual of
    /// `angle_refine · e / angle_tolerance` pixels (≥ 0; 0 leaves Eq 4.5 alone).
    pub angle_refine: f64,
    /// Robust method, with [`AnglePrior`]s: each frame's `(e_t / angle_tolerance)²` in the
    /// selection score is capped at this value (> 0; `+∞` = no cap), and beyond
    /// `angle_tolerance · √angle_cap` a frame no longer pulls the refinement (a truncated
    /// quadratic). A range learned from another capture may miss the true angles of a whole
    /// window by tens of degrees; uncapped, that prior then outweighs any pixel evidence.
    pub angle_cap: f64,
}

impl Default for ArticulatedOptions {
    fn default() -> Self {
        ArticulatedOptions {
            k: 8,
            refine: true,
            lm: LmOptions {
                max_iterations: 100,
                rel_tol: 1e-10,
            },
            bqp: BqpOptions::default(),
            fit_radius: false,
            method: ArticulatedMethod::Robust,
            tangent_quantile: 0.8,
            length_tol: 0.1,
            grazing_separation: 1.0,
            flip_rounds: 3,
            smooth_weight: SMOOTH_WEIGHT,
            motion_weight: MOTION_WEIGHT,
            refine_k_max: REFINE_K_MAX,
            child_slack: CHILD_SLACK,
            length_weight: 0.0,
            average_starts: false,
            angle_weight: ANGLE_WEIGHT,
            angle_tolerance: ANGLE_TOLERANCE,
            prior_start: true,
            angle_refine: ANGLE_REFINE,
            angle_cap: f64::INFINITY,
        }
    }
}

/// The observations of one child of the reconstructed joint: its pixel in every frame
/// (`None` = missing) and its given bone length (metres) from the joint.
#[derive(Debug, Clone)]
pub struct ChildObservations {
    pub pixels: Vec<Option<Vector2<f64>>>,
    pub length: f64,
}

/// Squared pixel distance by which the children's rays miss their reach from the joint
/// trajectory `points`: at each frame where child `c` is observed, the distance of the
/// joint from the child's ray beyond `(1 + slack) · length_c`, times the focal length over
/// the joint's depth. Zero when every child can lie on its ray within reach.
fn children_miss(
    cameras: &[Camera],
    children: &[ChildObservations],
    points: &[Vector3<f64>],
    slack: f64,
) -> f64 {
    let mut total = 0.0;
    for child in children {
        let reach = child.length * (1.0 + slack);
        for (i, u) in child.pixels.iter().enumerate() {
            let (Some(u), Some(x)) = (u, points.get(i)) else {
                continue;
            };
            let cam = &cameras[i];
            let excess = line_point_distance(&cam.c, &cam.ray_direction(u), x) - reach;
            let depth = (cam.r * (x - cam.c)).z;
            if excess > 0.0 && depth > 0.0 {
                total += (excess * cam.k[(0, 0)] / depth).powi(2);
            }
        }
    }
    total
}

/// A prior on the joint's bone: at every frame `t` the angle between the bone
/// `X_t − parent_t` and the reference bone `reference[t]` lies in `range` (radians,
/// `0 ≤ lo ≤ hi ≤ π`).
///
/// The two roots of a viewing ray on the parent's sphere (Fig 4.2(a)) fit the pixels alike,
/// and where neither the pixels nor smoothness (Eq 4.12) tell them apart the impostor side
/// often puts the bone where the body does not: a spine folded backwards, a hip or a
/// shoulder turned off the rigid pelvis or thorax. The thesis has no such prior (its Sec
/// 4.4 decides by smoothness alone). Two references serve a kinematic tree: the parent's
/// bone (`parent − grandparent`: how the joint bends) and a sibling's bone (`sibling −
/// parent`: two bones on one rigid segment keep their angle). The ranges are learned from
/// motion capture; the robust method adds each prior's mean squared excess beyond its
/// range, in units of [`ArticulatedOptions::angle_tolerance`], to the start's selection
/// score. An angle between two bones rather than a direction in a local frame: reference
/// joints a few percent of their bones off turn a local frame by 5–10° but the angle only
/// by the angle error of the two bones.
#[derive(Debug, Clone, PartialEq)]
pub struct AnglePrior {
    /// The reference bone vector at every camera frame, metres.
    pub reference: Vec<Vector3<f64>>,
    /// `(lo, hi)`, radians.
    pub range: (f64, f64),
}

/// The angle (radians) by which each frame's bone leaves `range`: the angle between
/// `points[t] − parent[t]` and `reference[t]` below `lo` or above `hi`, 0 inside (and where
/// a bone has no length).
pub fn angle_excess(
    points: &[Vector3<f64>],
    parent: &[Vector3<f64>],
    reference: &[Vector3<f64>],
    range: (f64, f64),
) -> Vec<f64> {
    points
        .iter()
        .zip(parent.iter().zip(reference))
        .map(|(x, (p, b))| {
            let a = x - p;
            let (na, nb) = (a.norm(), b.norm());
            if !(na > 0.0 && nb > 0.0) {
                return 0.0;
            }
            let angle = (a.dot(b) / (na * nb)).clamp(-1.0, 1.0).acos();
            range_excess(angle, range).map_or(0.0, |(e, _)| e)
        })
        .collect()
}

/// How far `angle` lies outside `(lo, hi)` and the derivative of that excess by the angle
/// (−1 below, +1 above); `None` inside.
fn range_excess(angle: f64, (lo, hi): (f64, f64)) -> Option<(f64, f64)> {
    if angle < lo {
        Some((lo - angle, -1.0))
    } else if angle > hi {
        Some((angle - hi, 1.0))
    } else {
        None
    }
}

/// Per observed candidate, the root (`true` = `¹χ`) whose unit direction from the parent
/// leaves the priors' ranges least (summed squared excess); `fallback`'s root on a tie.
fn prior_choice(
    cand: &Candidates,
    parent: &[Vector3<f64>],
    priors: &[AnglePrior],
    fallback: &[bool],
) -> Vec<bool> {
    let excess = |a: usize, chi: &Vector3<f64>| -> f64 {
        let i = cand.frames[a];
        let x = [parent[i] + chi];
        priors
            .iter()
            .map(|p| angle_excess(&x, &parent[i..=i], &p.reference[i..=i], p.range)[0].powi(2))
            .sum()
    };
    (0..cand.frames.len())
        .map(|a| {
            let (e1, e2) = (excess(a, &cand.chi1[a]), excess(a, &cand.chi2[a]));
            if e1 < e2 {
                true
            } else if e2 < e1 {
                false
            } else {
                fallback[a]
            }
        })
        .collect()
}

fn valid_range((lo, hi): (f64, f64)) -> bool {
    lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi && hi <= std::f64::consts::PI
}

fn validate_prior(prior: &AnglePrior, index: usize, frames: usize) -> Result<()> {
    let name = "angle_priors";
    if prior.reference.len() != frames {
        return Err(Error::invalid(
            name,
            format!(
                "prior {index}: need one reference bone per camera frame ({frames}), got {}",
                prior.reference.len()
            ),
        ));
    }
    if prior
        .reference
        .iter()
        .any(|g| !g.iter().all(|v| v.is_finite()))
    {
        return Err(Error::invalid(
            name,
            format!("prior {index}: reference bones must be finite"),
        ));
    }
    if !valid_range(prior.range) {
        return Err(Error::invalid(
            name,
            format!(
                "prior {index}: range must satisfy 0 ≤ lo ≤ hi ≤ π radians, got {:?}",
                prior.range
            ),
        ));
    }
    Ok(())
}

/// One reconstructed articulated trajectory.
#[derive(Debug, Clone)]
pub struct ArticulatedResult {
    /// Child position at every frame (missing frames imputed), world metres. With
    /// [`ArticulatedOptions::average_starts`], the starts' weighted average (the other
    /// fields then describe the best start).
    pub points: Vec<Vector3<f64>>,
    /// Bone length of the result: the given length enlarged so that every ray meets the
    /// sphere (Sec 4.4.1), then refined within `length_tol` by the robust method.
    pub radius: f64,
    /// Radius of the sphere whose binary program gave the returned trajectory.
    pub bqp_radius: f64,
    /// Rows: the spherical frame (`e1`, `e2`, pole) in world coordinates.
    pub frame: Matrix3<f64>,
    /// DCT coefficients of the inclination `θ(t)` and azimuth `φ(t)` (radians).
    pub coeffs_theta: Vec<f64>,
    pub coeffs_phi: Vec<f64>,
    /// The binary program (variables = ambiguous observed frames) and its solution.
    pub bqp: BqpSolution,
    /// Number of BQP variables.
    pub bqp_size: usize,
    /// Observed frames.
    pub n_observed: usize,
    /// RMS reprojection error of `points` over the observed frames, pixels.
    pub reprojection_rms: f64,
    /// LM iterations and whether its tolerance was met (true when not refined).
    pub lm_iterations: usize,
    pub converged: bool,
    /// How clearly the selection preferred the result (robust method): the selection
    /// score of the best start lying in another basin ([`OTHER_BASIN`]) minus the
    /// selected start's (≥ 0; in the score's units, where a reprojection cost one standard
    /// deviation higher counts 1). `+∞` when no start lies in another basin (and for the
    /// thesis method, which has one start).
    pub selection_margin: f64,
    /// That start's trajectory (at the selection's basis size `k`, before any growth),
    /// world metres, every frame; `None` when there is none.
    pub alternative: Option<Vec<Vector3<f64>>>,
}

/// The candidate geometry of one joint: both intersections per observed frame.
#[derive(Debug, Clone)]
pub struct Candidates {
    /// Observed frame indices (time order of the input).
    pub frames: Vec<usize>,
    /// Unit relative directions `¹χ_i`, `²χ_i` (Eq 4.10) per observed frame.
    pub chi1: Vec<Vector3<f64>>,
    pub chi2: Vec<Vector3<f64>>,
    /// Radius after enlargement.
    pub radius: f64,
}

fn validate_common(
    cameras: &[Camera],
    pixels: &[Option<Vector2<f64>>],
    parent: &[Vector3<f64>],
    times: &[f64],
    length: f64,
) -> Result<()> {
    let f = cameras.len();
    if !(length.is_finite() && length > 0.0) {
        return Err(Error::invalid(
            "length",
            format!("must be positive and finite, got {length}"),
        ));
    }
    if pixels.len() != f || parent.len() != f || times.len() != f {
        return Err(Error::invalid(
            "x/parent/times",
            format!(
                "need one entry per camera frame ({f}), got x {}, parent {}, times {}",
                pixels.len(),
                parent.len(),
                times.len()
            ),
        ));
    }
    ensure_finite("times", times)?;
    for (i, p) in parent.iter().enumerate() {
        if !p.iter().all(|v| v.is_finite()) {
            return Err(Error::invalid(
                "parent",
                format!("frame {i} is not finite (the parent trajectory must be complete)"),
            ));
        }
    }
    for (i, u) in pixels.iter().enumerate() {
        if let Some(u) = u {
            if !u.iter().all(|v| v.is_finite()) {
                return Err(Error::invalid(
                    "x",
                    format!("frame {i}: a pixel must be finite or the whole row NaN"),
                ));
            }
        }
    }
    Ok(())
}

/// The observed frames, their viewing rays and the parent-to-ray distances.
struct Rays {
    frames: Vec<usize>,
    dirs: Vec<Vector3<f64>>,
    dist: Vec<f64>,
}

fn observed_rays(
    cameras: &[Camera],
    pixels: &[Option<Vector2<f64>>],
    parent: &[Vector3<f64>],
) -> Rays {
    let mut rays = Rays {
        frames: Vec::new(),
        dirs: Vec::new(),
        dist: Vec::new(),
    };
    for (i, u) in pixels.iter().enumerate() {
        if let Some(u) = u {
            let v = cameras[i].ray_direction(u);
            rays.dist
                .push(line_point_distance(&cameras[i].c, &v, &parent[i]));
            rays.frames.push(i);
            rays.dirs.push(v);
        }
    }
    rays
}

/// The radius of the thesis: `length` enlarged to the largest parent-to-ray distance so
/// that every ray meets the sphere (Sec 4.4.1), or that distance when `fit_radius`.
fn thesis_radius(dist: &[f64], length: f64, fit_radius: bool) -> f64 {
    let farthest = dist.iter().copied().fold(0.0, f64::max);
    if fit_radius && farthest > 0.0 {
        farthest
    } else {
        length.max(farthest)
    }
}

/// The `q`-quantile of `values` (linear interpolation; `values` non-empty).
fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    v[lo] + (v[hi] - v[lo]) * (pos - lo as f64)
}

/// Both intersections of every observed ray with the sphere of `radius` about the parent
/// (Eq 4.8–4.9). A ray that misses the sphere (complex roots) gets its point nearest to
/// the parent twice; a candidate behind the camera is replaced by the other one.
fn candidates_at(
    cameras: &[Camera],
    parent: &[Vector3<f64>],
    rays: &Rays,
    radius: f64,
) -> Candidates {
    let mut chi1 = Vec::with_capacity(rays.frames.len());
    let mut chi2 = Vec::with_capacity(rays.frames.len());
    for (&i, v) in rays.frames.iter().zip(&rays.dirs) {
        let c = cameras[i].c;
        let xp = parent[i];
        let (s1, s2) = match ray_sphere(&c, v, &xp, radius) {
            Some(s) => s,
            None => {
                let s = v.dot(&(xp - c)) / v.norm_squared();
                (s, s)
            }
        };
        let (s1, s2) = match (s1 > 0.0, s2 > 0.0) {
            (true, false) => (s1, s1),
            (false, true) => (s2, s2),
            _ => (s1, s2),
        };
        let unit = |s: f64| -> Vector3<f64> {
            let d = c + v * s - xp;
            let n = d.norm();
            if n > 0.0 {
                d / n
            } else {
                Vector3::z()
            }
        };
        chi1.push(unit(s1));
        chi2.push(unit(s2));
    }
    Candidates {
        frames: rays.frames.clone(),
        chi1,
        chi2,
        radius,
    }
}

/// Both ray–sphere intersections per observed frame (Eq 4.8–4.9) on the sphere of the
/// thesis: the radius is enlarged to the largest parent-to-ray distance when some ray
/// misses (Sec 4.4.1), or set to that distance when `fit_radius`.
pub fn candidates(
    cameras: &[Camera],
    pixels: &[Option<Vector2<f64>>],
    parent: &[Vector3<f64>],
    length: f64,
    fit_radius: bool,
) -> Result<Candidates> {
    let rays = observed_rays(cameras, pixels, parent);
    let radius = thesis_radius(&rays.dist, length, fit_radius);
    Ok(candidates_at(cameras, parent, &rays, radius))
}
/// Orthonormal basis of the span of the observed rows of `Θ` (thin QR), `n_obs × K`.
fn observed_basis(theta_obs: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    let (m, k) = theta_obs.shape();
    if m < k {
        return Err(Error::degenerate(format!(
            "{m} observed frames cannot determine k = {k} basis coefficients"
        )));
    }
    let qr = theta_obs.clone().qr();
    let r = qr.r();
    let rmax = r.diagonal().amax();
    if r.diagonal().iter().any(|d| d.abs() <= 1e-10 * rmax) {
        return Err(Error::degenerate(
            "the observed frames make the trajectory basis rank deficient",
        ));
    }
    Ok(qr.q())
}

/// The BQP of Eq 4.12, `min ‖P⊥(E b + F)‖²` with `P⊥` the projector off the basis of the
/// observed frames: returns `(Q, c, constant, ambiguous)` such that the cost equals
/// `bᵀQb + cᵀb + constant` over the `ambiguous` observed positions (`¹χ ≠ ²χ`).
pub fn articulated_qp(
    cand: &Candidates,
    theta: &DMatrix<f64>,
) -> Result<(BqpProblem, f64, Vec<usize>)> {
    let m = cand.frames.len();
    let k = theta.ncols();
    let theta_obs = DMatrix::from_fn(m, k, |a, j| theta[(cand.frames[a], j)]);
    let q1 = observed_basis(&theta_obs)?;
    // P⊥ = I − Q1 Q1ᵀ.
    let mut pperp = -(&q1 * q1.transpose());
    for a in 0..m {
        pperp[(a, a)] += 1.0;
    }
    let fmat = DMatrix::from_fn(m, 3, |a, c| cand.chi2[a][c]);
    let pf = &pperp * &fmat;
    let constant = fmat.dot(&pf);
    let amb: Vec<usize> = (0..m)
        .filter(|&a| (cand.chi1[a] - cand.chi2[a]).norm() > 1e-12)
        .collect();
    let n = amb.len();
    let d: Vec<Vector3<f64>> = amb.iter().map(|&a| cand.chi1[a] - cand.chi2[a]).collect();
    let mut q = vec![0.0; n * n];
    let mut c = vec![0.0; n];
    for (i, &a) in amb.iter().enumerate() {
        for (j, &b) in amb.iter().enumerate() {
            q[i * n + j] = d[i].dot(&d[j]) * pperp[(a, b)];
        }
        let pfa = Vector3::new(pf[(a, 0)], pf[(a, 1)], pf[(a, 2)]);
        c[i] = 2.0 * d[i].dot(&pfa);
    }
    Ok((BqpProblem::from_row_major(n, q, c)?, constant, amb))
}

/// Spherical frame whose pole is the direction the unit vectors vary least along (they
/// stay near its equator, away from the coordinate singularity).
fn spherical_frame(dirs: &[Vector3<f64>]) -> Matrix3<f64> {
    let mut s = Matrix3::zeros();
    for d in dirs {
        s += d * d.transpose();
    }
    let eig = s.symmetric_eigen();
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let e1: Vector3<f64> = eig.eigenvectors.column(idx[0]).into();
    let e2: Vector3<f64> = eig.eigenvectors.column(idx[1]).into();
    let pole = e1.cross(&e2);
    Matrix3::from_rows(&[e1.transpose(), e2.transpose(), pole.transpose()])
}

fn to_angles(frame: &Matrix3<f64>, d: &Vector3<f64>) -> (f64, f64) {
    let l = frame * d;
    (l.z.clamp(-1.0, 1.0).acos(), l.y.atan2(l.x))
}

fn from_angles(frame: &Matrix3<f64>, th: f64, ph: f64) -> Vector3<f64> {
    let (st, ct) = th.sin_cos();
    let (sp, cp) = ph.sin_cos();
    frame.transpose() * Vector3::new(st * cp, st * sp, ct)
}

/// Among all spherical representations of a direction, `(θ + 2πk, φ + 2πm)` and
/// `(−θ + 2πk, φ + π + 2πm)`, the one nearest to the previous frame's (end of Sec 4.2.2).
fn unwrap_angles(raw: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(raw.len());
    for &(th, ph) in raw {
        let Some(&(pt, pp)) = out.last() else {
            out.push((th, ph));
            continue;
        };
        let near = |base: f64, target: f64| base + TAU * ((target - base) / TAU).round();
        let a = (near(th, pt), near(ph, pp));
        let b = (near(-th, pt), near(ph + PI, pp));
        let da = (a.0 - pt).powi(2) + (a.1 - pp).powi(2);
        let db = (b.0 - pt).powi(2) + (b.1 - pp).powi(2);
        out.push(if db < da { b } else { a });
    }
    out
}

fn least_squares(theta_obs: &DMatrix<f64>, y: &DVector<f64>) -> Result<DVector<f64>> {
    let svd = theta_obs.clone().svd(true, true);
    svd.solve(y, 1e-12)
        .map_err(|e| Error::degenerate(format!("basis least squares failed: {e}")))
}

/// The binary program of Eq 4.12 solved on the sphere of one radius: the candidates, the
/// solution, and the chosen root per observed frame (`true` = `¹χ`, the farther one).
struct Program {
    cand: Candidates,
    bqp: BqpSolution,
    bqp_size: usize,
    choice: Vec<bool>,
    /// Observed positions (indices into `cand.frames`) in time order.
    order: Vec<usize>,
}

fn solve_program(
    cameras: &[Camera],
    parent: &[Vector3<f64>],
    rays: &Rays,
    radius: f64,
    theta: &DMatrix<f64>,
    times: &[f64],
    bqp: &BqpOptions,
) -> Result<Program> {
    let cand = candidates_at(cameras, parent, rays, radius);
    let m = cand.frames.len();
    let (problem, _constant, amb) = articulated_qp(&cand, theta)?;
    let sol = solve_bqp(&problem, bqp)?;
    // χ = E b + F (Eq 4.11): b = 1 picks ¹χ.
    let mut choice = vec![false; m];
    for (i, &a) in amb.iter().enumerate() {
        choice[a] = sol.x[i];
    }
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| times[cand.frames[a]].total_cmp(&times[cand.frames[b]]));
    Ok(Program {
        cand,
        bqp_size: problem.n(),
        bqp: sol,
        choice,
        order,
    })
}

/// Positions in `order` where the ray grazes the sphere: local minima in time of the
/// separation `‖¹χ − ²χ‖` of the two roots (a plateau of tangent rays counts once, at its
/// middle) below `max_sep`. There the true trajectory can pass from one root to the other
/// (it crosses the plane perpendicular to the ray) or touch it and come back; the smooth
/// program cannot always tell which, so both are tried.
fn grazing_points(cand: &Candidates, order: &[usize], max_sep: f64) -> Vec<usize> {
    let sep: Vec<f64> = order
        .iter()
        .map(|&a| (cand.chi1[a] - cand.chi2[a]).norm())
        .collect();
    let n = sep.len();
    let mut out = Vec::new();
    let mut r = 0;
    while r < n {
        let mut e = r;
        while e + 1 < n && (sep[e + 1] - sep[r]).abs() <= 1e-9 {
            e += 1;
        }
        let lower_left = r == 0 || sep[r - 1] > sep[r];
        let lower_right = e + 1 == n || sep[e + 1] > sep[r];
        if lower_left && lower_right && sep[r] < max_sep && r > 0 && e + 1 < n {
            out.push((r + e) / 2);
        }
        r = e + 1;
    }
    out
}

/// Chosen unit directions projected on the spherical basis (Eq 4.4, with unwrapping):
/// the spherical frame and the DCT coefficients of both angles.
fn project_choice(
    cand: &Candidates,
    choice: &[bool],
    order: &[usize],
    theta: &DMatrix<f64>,
    k: usize,
) -> Result<(Matrix3<f64>, DVector<f64>, DVector<f64>)> {
    let m = cand.frames.len();
    let chi: Vec<Vector3<f64>> = (0..m)
        .map(|a| {
            if choice[a] {
                cand.chi1[a]
            } else {
                cand.chi2[a]
            }
        })
        .collect();
    let frame = spherical_frame(&chi);
    let raw: Vec<(f64, f64)> = order.iter().map(|&a| to_angles(&frame, &chi[a])).collect();
    let unwrapped = unwrap_angles(&raw);
    let theta_obs = DMatrix::from_fn(m, k, |r, j| theta[(cand.frames[order[r]], j)]);
    let yt = DVector::from_fn(m, |r, _| unwrapped[r].0);
    let yp = DVector::from_fn(m, |r, _| unwrapped[r].1);
    Ok((
        frame,
        least_squares(&theta_obs, &yt)?,
        least_squares(&theta_obs, &yp)?,
    ))
}

/// The reprojection objective of Eq 4.5 for one joint in the spherical parameterisation
/// of Eq 4.4: angles `Θ a_θ`, `Θ a_φ` in `frame`, radius `r` about the parent.
struct Fit<'a> {
    cameras: &'a [Camera],
    obs: &'a [(usize, Vector2<f64>)],
    parent: &'a [Vector3<f64>],
    theta: &'a DMatrix<f64>,
    frame: Matrix3<f64>,
    /// Prior on the bone length `(r0, w)`: adds `(w (r − r0) / r0)²` to the cost.
    prior: Option<(f64, f64)>,
    /// Angle priors read by the refinement, `(priors, s, e_max)`: each frame's excess `e`
    /// beyond a range adds `(s min(e, e_max))²` to the objective [`refine`] minimises (not to
    /// [`Fit::cost`]); beyond `e_max` the frame no longer pulls.
    angles: Option<(&'a [AnglePrior], f64, f64)>,
}

impl Fit<'_> {
    fn point(&self, i: usize, at: &DVector<f64>, ap: &DVector<f64>, r: f64) -> Vector3<f64> {
        let row = self.theta.row(i);
        let th = row.dot(&at.transpose());
        let ph = row.dot(&ap.transpose());
        self.parent[i] + from_angles(&self.frame, th, ph) * r
    }

    /// Sum of squared reprojection errors, pixels².
    fn cost(&self, at: &DVector<f64>, ap: &DVector<f64>, r: f64) -> f64 {
        self.obs
            .iter()
            .map(|&(i, u)| {
                let (p, _) = self.cameras[i].project(&self.point(i, at, ap, r));
                (p - u).norm_squared()
            })
            .sum::<f64>()
            + self
                .prior
                .map_or(0.0, |(r0, w)| (w * (r - r0) / r0).powi(2))
    }

    /// The angle priors' term of the refinement objective, `Σ_t Σ_priors (s min(e_t,
    /// e_max))²`.
    fn angle_cost(&self, at: &DVector<f64>, ap: &DVector<f64>) -> f64 {
        let Some((priors, s, e_max)) = self.angles else {
            return 0.0;
        };
        let points: Vec<Vector3<f64>> = (0..self.parent.len())
            .map(|i| self.point(i, at, ap, 1.0))
            .collect();
        priors
            .iter()
            .map(|p| {
                angle_excess(&points, self.parent, &p.reference, p.range)
                    .iter()
                    .map(|e| (s * e.min(e_max)).powi(2))
                    .sum::<f64>()
            })
            .sum()
    }

    /// Refinement objective: [`Fit::cost`] plus [`Fit::angle_cost`].
    fn objective(&self, at: &DVector<f64>, ap: &DVector<f64>, r: f64) -> f64 {
        self.cost(at, ap, r) + self.angle_cost(at, ap)
    }
}

/// Outcome of [`refine`]: coefficients, radius, iterations, converged.
type Refined = (DVector<f64>, DVector<f64>, f64, usize, bool);

/// A refined choice of roots: cost, spherical frame, fit.
type Evaluated = (f64, Matrix3<f64>, Refined);

/// The evidence of one refined start for [`select_start`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct StartEvidence {
    /// Reprojection cost of Eq 4.5 (with the length prior), pixels².
    pub cost: f64,
    /// The objective of Eq 4.12 on the refined unit directions at the observed frames.
    pub roughness: f64,
    /// Angular variance of the refined unit directions over every frame, `Σ ‖u_t − ū‖²`.
    pub motion: f64,
    /// Squared pixel distance by which the children's rays miss their reach from the
    /// refined joint ([`children_miss`]; 0 without children).
    pub children: f64,
    /// Refined bone length, metres.
    pub radius: f64,
    /// Score of the angle priors ([`AnglePrior`]): `angle_weight · Σ_priors mean_t (e_t /
    /// tolerance)²` (0 without a prior).
    pub angle: f64,
}

/// Weights of the selection score: `(smooth_weight, motion_weight, length_weight)`.
pub(crate) type SelectionWeights = (f64, f64, f64);

/// Index of the start to keep. Reprojection error alone cannot tell the truth from the
/// impostor: after the refinement both basins fit the pixels to within the noise (measured
/// on CMU windows under the Fig 4.3(c) conditions the impostor fits better about as often as
/// the truth), while the truth is the smoother in the sense of Eq 4.12 in 64–91 % of such
/// pairs, and the wrong starts left are mostly slow swings away from the truth that move
/// the bone more. So each start scores its cost above the lowest, in standard deviations of
/// a χ² with `2 n_obs − 2k − 1` degrees of freedom (the noise variance estimated from the
/// lowest cost), plus `smooth · log₁₀` of its roughness plus `motion · log₁₀` of its
/// angular variance: a tenfold smoother start may fit the pixels worse by `smooth`
/// standard deviations, a tenfold stiller one by `motion`, plus `length · ln(r / r_min)` on
/// its refined bone length `r` ([`ArticulatedOptions::length_weight`]). The cost includes the children's
/// misses (their pixels are part of the data). `None` (or zero weights) keeps the lowest
/// cost.
pub(crate) fn select_start(
    starts: &[StartEvidence],
    n_obs: usize,
    k: usize,
    weights: Option<SelectionWeights>,
) -> Option<usize> {
    let total = |e: &StartEvidence| e.cost + e.children;
    let lowest =
        (0..starts.len()).min_by(|&a, &b| total(&starts[a]).total_cmp(&total(&starts[b])))?;
    match start_scores(starts, n_obs, k, weights) {
        Some(score) => (0..starts.len()).min_by(|&a, &b| score[a].total_cmp(&score[b])),
        None => Some(lowest),
    }
}

/// The selection score of every start (lower is better; see [`select_start`]), or `None`
/// when the weights are absent or zero (the lowest cost is kept) or there is no start.
/// A start whose evidence is not a number scores `+∞`.
pub(crate) fn start_scores(
    starts: &[StartEvidence],
    n_obs: usize,
    k: usize,
    weights: Option<SelectionWeights>,
) -> Option<Vec<f64>> {
    let cmin = starts
        .iter()
        .map(|e| e.cost + e.children)
        .min_by(f64::total_cmp)?;
    start_scores_at(starts, cost_sd(cmin, n_obs, k), weights)
}

/// Standard deviation of a reprojection cost `c` with `2 n_obs − 2k − 1` degrees of
/// freedom, the noise variance estimated from `c` itself (a χ²).
fn cost_sd(c: f64, n_obs: usize, k: usize) -> f64 {
    let dof = (2 * n_obs).saturating_sub(2 * k + 1).max(1) as f64;
    ((2.0 * dof).sqrt() * c / dof).max(f64::MIN_POSITIVE)
}

/// [`start_scores`] with the cost differences counted in units of `sd`.
pub(crate) fn start_scores_at(
    starts: &[StartEvidence],
    sd: f64,
    weights: Option<SelectionWeights>,
) -> Option<Vec<f64>> {
    let (smooth, motion, length) = weights.filter(|&(s, m, l)| s > 0.0 || m > 0.0 || l > 0.0)?;
    let total = |e: &StartEvidence| e.cost + e.children;
    let cmin = starts.iter().map(total).min_by(f64::total_cmp)?;
    let rmin = starts
        .iter()
        .map(|e| e.radius)
        .filter(|r| r.is_finite() && *r > 0.0)
        .min_by(f64::total_cmp)
        .unwrap_or(1.0);
    let longer = |r: f64| -> f64 {
        if length > 0.0 {
            length * (r / rmin).ln()
        } else {
            0.0
        }
    };
    let log = |v: f64, w: f64| -> f64 {
        if w > 0.0 {
            w * (v.max(0.0) + ROUGHNESS_FLOOR).log10()
        } else {
            0.0
        }
    };
    let score = |e: &StartEvidence| -> f64 {
        let s = (total(e) - cmin) / sd
            + log(e.roughness, smooth)
            + log(e.motion, motion)
            + longer(e.radius)
            + e.angle;
        if e.roughness.is_nan() || e.motion.is_nan() || s.is_nan() {
            f64::INFINITY
        } else {
            s
        }
    };
    Some(starts.iter().map(score).collect())
}

/// Sharpness `λ` of the weights `exp(−λ (score − min score))` of
/// [`ArticulatedOptions::average_starts`].
pub const AVERAGE_SHARPNESS: f64 = 2.0;

/// A start whose trajectory lies farther than this fraction of the bone length (RMS over
/// the frames) from the selected start's is another solution: mostly the other root of the
/// rays over part of the window. The best-scoring of them is the result's
/// [`ArticulatedResult::alternative`], its score gap the
/// [`ArticulatedResult::selection_margin`].
pub const OTHER_BASIN: f64 = 0.1;

/// The best start in another basin than `pick` ([`OTHER_BASIN`] × `bone`, RMS over the
/// frames) and its score above `pick`'s: `(margin, index)`, or `(+∞, None)`.
pub(crate) fn other_basin(
    points: &[Vec<Vector3<f64>>],
    scores: &[f64],
    pick: usize,
    bone: f64,
) -> (f64, Option<usize>) {
    let mut best: (f64, Option<usize>) = (f64::INFINITY, None);
    for (i, p) in points.iter().enumerate() {
        if i == pick || !scores[i].is_finite() {
            continue;
        }
        let ms = p
            .iter()
            .zip(&points[pick])
            .map(|(a, b)| (a - b).norm_squared())
            .sum::<f64>()
            / p.len().max(1) as f64;
        let gap = scores[i] - scores[pick];
        if ms.sqrt() > OTHER_BASIN * bone && gap < best.0 {
            best = (gap, Some(i));
        }
    }
    best
}

/// Starts whose trajectories lie within this fraction of the bone length (RMS over the
/// frames) of a better-scoring start are the same solution found again (the searches over
/// grazing passes converge to the same basin many times) and count once in the average of
/// [`ArticulatedOptions::average_starts`]; distinct basins differ by tenths of the bone.
pub const DISTINCT_STARTS: f64 = 0.01;

/// Indices of the distinct starts, best score first: a start is dropped when its
/// trajectory lies within `tol` (RMS distance over the frames, metres) of a kept one.
pub(crate) fn distinct_starts(
    points: &[Vec<Vector3<f64>>],
    scores: &[f64],
    tol: f64,
) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| scores[i].is_finite())
        .collect();
    order.sort_by(|&a, &b| scores[a].total_cmp(&scores[b]));
    let mut kept: Vec<usize> = Vec::new();
    for i in order {
        let near = kept.iter().any(|&j| {
            let ms = points[i]
                .iter()
                .zip(&points[j])
                .map(|(a, b)| (a - b).norm_squared())
                .sum::<f64>()
                / points[i].len().max(1) as f64;
            ms.sqrt() <= tol
        });
        if !near {
            kept.push(i);
        }
    }
    kept
}

/// Weights of the starts in the average of [`ArticulatedOptions::average_starts`]:
/// `exp(−λ (score − min score))` (λ = [`AVERAGE_SHARPNESS`]), normalised to sum to 1 (a start scoring `+∞` weighs 0).
/// `None` when no start has a finite score.
pub(crate) fn start_weights(scores: &[f64]) -> Option<Vec<f64>> {
    let best = scores
        .iter()
        .copied()
        .filter(|s| s.is_finite())
        .min_by(f64::total_cmp)?;
    let w: Vec<f64> = scores
        .iter()
        .map(|&s| {
            if s.is_finite() {
                (AVERAGE_SHARPNESS * (best - s)).exp()
            } else {
                0.0
            }
        })
        .collect();
    let sum: f64 = w.iter().sum();
    Some(w.iter().map(|v| v / sum).collect())
}

/// Reconstructs one articulated trajectory (Eq 4.5–4.12): `pixels[i]` is the child's pixel
/// in `cameras[i]` at `times[i]` (`None` = missing), `parent[i]` the parent's world position.
pub fn reconstruct_articulated(
    cameras: &[Camera],
    pixels: &[Option<Vector2<f64>>],
    parent: &[Vector3<f64>],
    times: &[f64],
    length: f64,
    opts: &ArticulatedOptions,
) -> Result<ArticulatedResult> {
    reconstruct_articulated_with(cameras, pixels, parent, times, length, &[], opts)
}

/// [`reconstruct_articulated`] with the joint's own children observed: the robust method
/// weighs each start by whether the children can lie on their rays within reach of it
/// ([`ArticulatedOptions::child_slack`]); the thesis method ignores them.
pub fn reconstruct_articulated_with(
    cameras: &[Camera],
    pixels: &[Option<Vector2<f64>>],
    parent: &[Vector3<f64>],
    times: &[f64],
    length: f64,
    children: &[ChildObservations],
    opts: &ArticulatedOptions,
) -> Result<ArticulatedResult> {
    reconstruct_articulated_prior(cameras, pixels, parent, times, length, children, &[], opts)
}

/// [`reconstruct_articulated_with`] with priors on the angle between the joint's bone and
/// reference bones ([`AnglePrior`]): the robust method adds `angle_weight · mean_t (e_t /
/// angle_tolerance)²` per prior to each start's selection score; the thesis method ignores
/// them.
#[allow(clippy::too_many_arguments)]
pub fn reconstruct_articulated_prior(
    cameras: &[Camera],
    pixels: &[Option<Vector2<f64>>],
    parent: &[Vector3<f64>],
    times: &[f64],
    length: f64,
    children: &[ChildObservations],
    priors: &[AnglePrior],
    opts: &ArticulatedOptions,
) -> Result<ArticulatedResult> {
    validate_common(cameras, pixels, parent, times, length)?;
    for (i, prior) in priors.iter().enumerate() {
        validate_prior(prior, i, cameras.len())?;
    }
    if !(opts.angle_tolerance.is_finite() && opts.angle_tolerance > 0.0) {
        return Err(Error::invalid(
            "angle_tolerance",
            format!("must be positive and finite, got {}", opts.angle_tolerance),
        ));
    }
    if opts.angle_cap.is_nan() || opts.angle_cap <= 0.0 {
        return Err(Error::invalid(
            "angle_cap",
            format!("must be positive (+inf: no cap), got {}", opts.angle_cap),
        ));
    }
    for (c, child) in children.iter().enumerate() {
        if child.pixels.len() != cameras.len() {
            return Err(Error::invalid(
                "children",
                format!(
                    "child {c}: need one pixel entry per camera frame ({}), got {}",
                    cameras.len(),
                    child.pixels.len()
                ),
            ));
        }
        if !(child.length.is_finite() && child.length > 0.0) {
            return Err(Error::invalid(
                "children",
                format!(
                    "child {c}: length must be positive and finite, got {}",
                    child.length
                ),
            ));
        }
        if child
            .pixels
            .iter()
            .flatten()
            .any(|u| !u.iter().all(|v| v.is_finite()))
        {
            return Err(Error::invalid(
                "children",
                format!("child {c}: a pixel must be finite or the whole row NaN"),
            ));
        }
    }
    if opts.k == 0 {
        return Err(Error::invalid("k", "must be at least 1"));
    }
    if !(0.0..=1.0).contains(&opts.tangent_quantile) {
        return Err(Error::invalid(
            "tangent_quantile",
            format!("must be in [0, 1], got {}", opts.tangent_quantile),
        ));
    }
    if !(opts.length_tol.is_finite() && opts.length_tol >= 0.0) {
        return Err(Error::invalid(
            "length_tol",
            format!("must be finite and non-negative, got {}", opts.length_tol),
        ));
    }
    for (name, w) in [
        ("smooth_weight", opts.smooth_weight),
        ("motion_weight", opts.motion_weight),
        ("child_slack", opts.child_slack),
        ("length_weight", opts.length_weight),
        ("angle_weight", opts.angle_weight),
        ("angle_refine", opts.angle_refine),
    ] {
        if !(w.is_finite() && w >= 0.0) {
            return Err(Error::invalid(
                name,
                format!("must be finite and non-negative, got {w}"),
            ));
        }
    }
    let f = cameras.len();
    let span = DctSpan::from_times(times)?;
    let theta = span.matrix(times, opts.k)?;
    let rays = observed_rays(cameras, pixels, parent);
    let m = rays.frames.len();
    if m < opts.k {
        return Err(Error::degenerate(format!(
            "{m} observed frames cannot determine k = {} basis coefficients",
            opts.k
        )));
    }
    let r_thesis = thesis_radius(&rays.dist, length, opts.fit_radius);
    let robust = opts.method == ArticulatedMethod::Robust;
    let mut radii = Vec::with_capacity(2);
    if robust {
        let shrunk = quantile(&rays.dist, opts.tangent_quantile).min(r_thesis);
        if shrunk > 0.0 && shrunk < r_thesis * (1.0 - 1e-9) {
            radii.push(shrunk);
        }
    }
    radii.push(r_thesis);
    let bounds = (robust && opts.length_tol > 0.0).then(|| {
        (
            r_thesis / (1.0 + opts.length_tol),
            r_thesis * (1.0 + opts.length_tol),
        )
    });
    let obs: Vec<(usize, Vector2<f64>)> = rays
        .frames
        .iter()
        .filter_map(|&i| pixels[i].map(|u| (i, u)))
        .collect();

    // Every refined start: (evidence, frame, refined, BQP solution, size, radius).
    type Start = (
        StartEvidence,
        Matrix3<f64>,
        Refined,
        BqpSolution,
        usize,
        f64,
    );
    let mut starts: Vec<Start> = Vec::new();
    // A length off by `length_tol` costs LENGTH_PRIOR² px² per observation.
    let prior = bounds.map(|_| {
        (
            r_thesis,
            LENGTH_PRIOR * (obs.len() as f64).sqrt() / opts.length_tol,
        )
    });
    // Angle priors inside the refinement (robust method): residual angle_refine · e /
    // angle_tolerance, pixels. A frame's excess counts at most e_max (angle_cap), here and
    // in the selection score.
    let e_max = opts.angle_tolerance * opts.angle_cap.sqrt();
    let angles =
        (robust && opts.angle_refine > 0.0 && opts.angle_weight > 0.0 && !priors.is_empty())
            .then_some((priors, opts.angle_refine / opts.angle_tolerance, e_max));
    // Orthonormal basis of the observed rows of Θ, for the roughness of Eq 4.12.
    let theta_obs = DMatrix::from_fn(m, opts.k, |a, j| theta[(rays.frames[a], j)]);
    let q1 = observed_basis(&theta_obs)?;
    // Projection of a choice of roots on the basis, refined (Eq 4.5): (cost, frame, fit).
    let evaluate = |prog: &Program, choice: &[bool]| -> Result<(f64, Matrix3<f64>, Refined)> {
        let (frame, at, ap) = project_choice(&prog.cand, choice, &prog.order, &theta, opts.k)?;
        let fit = Fit {
            cameras,
            obs: &obs,
            parent,
            theta: &theta,
            frame,
            prior,
            angles,
        };
        let refined = if opts.refine {
            refine(&fit, at, ap, r_thesis, bounds, &opts.lm)?
        } else {
            (at, ap, r_thesis, 0, true)
        };
        let c = fit.cost(&refined.0, &refined.1, refined.2);
        Ok((
            if c.is_finite() { c } else { f64::INFINITY },
            frame,
            refined,
        ))
    };
    // The evidence of a refined start: the smoothness objective of Eq 4.12, ‖P⊥ χ‖², on
    // its unit directions at the observed frames, and their angular variance over every
    // frame (least motion).
    let evidence = |e: &(f64, Matrix3<f64>, Refined)| -> StartEvidence {
        let (cost, frame, (at, ap, r, _, _)) = e;
        let fit = Fit {
            cameras,
            obs: &obs,
            parent,
            theta: &theta,
            frame: *frame,
            prior,
            angles,
        };
        let points: Vec<Vector3<f64>> = (0..f).map(|i| fit.point(i, at, ap, *r)).collect();
        let dirs: Vec<Vector3<f64>> = (0..f)
            .map(|i| {
                let d = points[i] - parent[i];
                d / d.norm().max(f64::MIN_POSITIVE)
            })
            .collect();
        let u = DMatrix::from_fn(m, 3, |a, c| dirs[rays.frames[a]][c]);
        let rough = u.norm_squared() - (q1.transpose() * &u).norm_squared();
        let mean = dirs.iter().sum::<Vector3<f64>>() / f as f64;
        let motion: f64 = dirs.iter().map(|d| (d - mean).norm_squared()).sum();
        let finite = |v: f64| {
            if v.is_finite() {
                v.max(0.0)
            } else {
                f64::INFINITY
            }
        };
        let children = if robust {
            children_miss(cameras, children, &points, opts.child_slack)
        } else {
            0.0
        };
        let angle: f64 = if robust && opts.angle_weight > 0.0 {
            priors
                .iter()
                .map(|prior| {
                    let excess = angle_excess(&points, parent, &prior.reference, prior.range);
                    opts.angle_weight
                        * excess
                            .iter()
                            .map(|e| (e.min(e_max) / opts.angle_tolerance).powi(2))
                            .sum::<f64>()
                        / f.max(1) as f64
                })
                .sum()
        } else {
            0.0
        };
        StartEvidence {
            cost: *cost,
            roughness: finite(rough),
            motion: finite(motion),
            children: finite(children),
            radius: *r,
            angle: finite(angle),
        }
    };
    for radius in radii {
        crate::interrupt::check()?;
        let prog = solve_program(cameras, parent, &rays, radius, &theta, times, &opts.bqp)?;
        let mut choice = prog.choice.clone();
        let mut current = evaluate(&prog, &choice)?;
        let mut push = |e: &(f64, Matrix3<f64>, Refined)| {
            starts.push((
                evidence(e),
                e.1,
                e.2.clone(),
                prog.bqp.clone(),
                prog.bqp_size,
                radius,
            ));
        };
        push(&current);
        if robust && opts.prior_start && opts.angle_weight > 0.0 && !priors.is_empty() {
            // A start the priors choose: in every observed frame the root whose bone leaves
            // the priors' ranges least (squared excess summed over the priors; a tie keeps
            // the program's root). Where the program's smooth choice follows the impostor
            // all through the window, no flip at a grazing frame reaches the truth, but the
            // priors often still tell the two roots apart frame by frame.
            let guided = prior_choice(&prog.cand, parent, priors, &prog.choice);
            if guided != prog.choice {
                let e = evaluate(&prog, &guided)?;
                push(&e);
            }
        }
        if robust {
            // Greedy search over passing to the other root after or before each grazing
            // frame, judged by the refined reprojection error; every variant is kept as a
            // start for the final selection.
            let graze = grazing_points(&prog.cand, &prog.order, opts.grazing_separation);
            for _ in 0..opts.flip_rounds {
                let mut improved: Option<(Vec<bool>, Evaluated)> = None;
                for &g in &graze {
                    for part in [&prog.order[g + 1..], &prog.order[..g]] {
                        crate::interrupt::check()?;
                        let mut variant = choice.clone();
                        for &a in part {
                            variant[a] = !variant[a];
                        }
                        let e = evaluate(&prog, &variant)?;
                        push(&e);
                        let bar = improved.as_ref().map_or(current.0, |(_, b)| b.0);
                        if e.0 < bar {
                            improved = Some((variant, e));
                        }
                    }
                }
                match improved {
                    Some((v, e)) => {
                        choice = v;
                        current = e;
                    }
                    None => break,
                }
            }
        }
    }
    let scores: Vec<StartEvidence> = starts.iter().map(|s| s.0).collect();
    let weights = robust.then_some((opts.smooth_weight, opts.motion_weight, opts.length_weight));
    let pick = select_start(&scores, obs.len(), opts.k, weights)
        .ok_or_else(|| Error::degenerate("no start of the reconstruction"))?;
    let start_points = |s: &Start| -> Vec<Vector3<f64>> {
        let fit = Fit {
            cameras,
            obs: &obs,
            parent,
            theta: &theta,
            frame: s.1,
            prior,
            angles,
        };
        (0..f)
            .map(|i| fit.point(i, &s.2 .0, &s.2 .1, s.2 .2))
            .collect()
    };
    // Every start's trajectory at `k`: the other basin's best start, and the average.
    let all: Vec<Vec<Vector3<f64>>> = starts.iter().map(start_points).collect();
    // The selection's scores (the lowest cost kept when the weights are zero: then in
    // standard deviations of the cost).
    let margin_scores: Vec<f64> = start_scores(&scores, obs.len(), opts.k, weights)
        .or_else(|| {
            let cmin = scores
                .iter()
                .map(|e| e.cost + e.children)
                .min_by(f64::total_cmp)?;
            let sd = cost_sd(cmin, obs.len(), opts.k);
            Some(
                scores
                    .iter()
                    .map(|e| (e.cost + e.children - cmin) / sd)
                    .collect(),
            )
        })
        .unwrap_or_default();
    let (selection_margin, alt) = if margin_scores.len() == all.len() {
        other_basin(&all, &margin_scores, pick, r_thesis)
    } else {
        (f64::INFINITY, None)
    };
    let alternative = alt.map(|i| all[i].clone());
    let all = (robust && opts.average_starts).then_some(all);
    let (_, frame, (at, ap, radius, lm_iterations, converged), bqp, bqp_size, bqp_radius) =
        starts.swap_remove(pick);
    let c = scores[pick].cost;
    let fit = Fit {
        cameras,
        obs: &obs,
        parent,
        theta: &theta,
        frame,
        prior,
        angles,
    };
    // The selected start with the basis grown to the motion (robust method).
    let (wide, (at, ap, radius, lm_iterations, converged), _) = if robust && opts.refine {
        grow_basis(
            &fit,
            (at, ap, radius, lm_iterations, converged),
            c,
            &span,
            times,
            opts.refine_k_max,
            bounds,
            &opts.lm,
        )?
    } else {
        (theta.clone(), (at, ap, radius, lm_iterations, converged), c)
    };
    let fit = Fit {
        theta: &wide,
        ..fit
    };
    let mut points: Vec<Vector3<f64>> = (0..f).map(|i| fit.point(i, &at, &ap, radius)).collect();
    // The weighted average of the distinct starts minus the best start, both at `k`, added
    // to the best start's final trajectory; only where the basis did not grow: where `k`
    // cannot follow the motion, the starts' costs are misfit, not noise, and their scores
    // no posterior.
    if let (Some(all), true) = (all, at.len() == opts.k) {
        if let Some(sc) = start_scores(&scores, obs.len(), opts.k, weights) {
            let kept = distinct_starts(&all, &sc, DISTINCT_STARTS * r_thesis);
            let ksc: Vec<f64> = kept.iter().map(|&i| sc[i]).collect();
            for (&i, wi) in kept.iter().zip(start_weights(&ksc).unwrap_or_default()) {
                for (p, (a, b)) in points.iter_mut().zip(all[i].iter().zip(&all[pick])) {
                    *p += (a - b) * wi;
                }
            }
        }
    }
    let pixel_cost: f64 = obs
        .iter()
        .map(|&(i, u)| (cameras[i].project(&points[i]).0 - u).norm_squared())
        .sum();
    let reprojection_rms = (pixel_cost / obs.len().max(1) as f64).sqrt();
    Ok(ArticulatedResult {
        points,
        radius,
        bqp_radius,
        frame,
        coeffs_theta: at.iter().copied().collect(),
        coeffs_phi: ap.iter().copied().collect(),
        bqp_size,
        bqp,
        n_observed: m,
        reprojection_rms,
        lm_iterations,
        converged,
        selection_margin: selection_margin.max(0.0),
        alternative,
    })
}

/// Bayesian information criterion of a refined fit: `2n ln(c / 2n) + (2k + 1) ln 2n` for a
/// reprojection cost `c` (pixels²) over `n` observations and `k` coefficients per angle plus
/// the bone length (a Gaussian pixel noise of unknown variance).
fn refinement_bic(cost: f64, n_obs: usize, k: usize) -> f64 {
    let n = (2 * n_obs).max(1) as f64;
    n * (cost.max(f64::MIN_POSITIVE) / n).ln() + (2 * k + 1) as f64 * n.ln()
}

/// The selected start refined again with `k + 1, …, k_max` DCT vectors per angle (the
/// first `k` coefficients carried over, the others from zero); the basis size with the
/// lowest [`refinement_bic`] is kept. Returns the basis matrix, the fit and its cost.
#[allow(clippy::too_many_arguments)]
fn grow_basis(
    fit: &Fit<'_>,
    start: Refined,
    cost: f64,
    span: &DctSpan,
    times: &[f64],
    k_max: usize,
    bounds: Option<(f64, f64)>,
    lm: &LmOptions,
) -> Result<(DMatrix<f64>, Refined, f64)> {
    let k = start.0.len();
    let n_obs = fit.obs.len();
    let mut best_bic = refinement_bic(cost, n_obs, k);
    let (a0, p0, r0) = (start.0.clone(), start.1.clone(), start.2);
    let mut best = (fit.theta.clone(), start, cost);
    for kk in k + 1..=k_max.min(n_obs / 2) {
        crate::interrupt::check()?;
        let theta = span.matrix(times, kk)?;
        let grow = |a: &DVector<f64>| {
            let mut g = DVector::zeros(kk);
            g.rows_mut(0, k).copy_from(a);
            g
        };
        let wide = Fit {
            theta: &theta,
            ..*fit
        };
        let refined = refine(&wide, grow(&a0), grow(&p0), r0, bounds, lm)?;
        let c = wide.cost(&refined.0, &refined.1, refined.2);
        let bic = refinement_bic(c, n_obs, kk);
        if c.is_finite() && bic < best_bic {
            best_bic = bic;
            best = (theta, refined, c);
        }
    }
    Ok(best)
}

/// The unit direction of Eq 4.4 at frame `i` (basis row `i` of `theta`) and its partial derivatives
/// by that frame's two angles, in world coordinates (`ft` = the spherical frame's transpose).
fn unit_and_partials(
    ft: &Matrix3<f64>,
    theta: &DMatrix<f64>,
    i: usize,
    at: &DVector<f64>,
    ap: &DVector<f64>,
) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let row = theta.row(i);
    let (st, ct) = row.dot(&at.transpose()).sin_cos();
    let (sp, cp) = row.dot(&ap.transpose()).sin_cos();
    (
        ft * Vector3::new(st * cp, st * sp, ct),
        ft * Vector3::new(ct * cp, ct * sp, -st),
        ft * Vector3::new(-st * sp, st * cp, 0.0),
    )
}

/// Levenberg–Marquardt on Eq 4.5 over the `2K` angle coefficients, and the bone length
/// when `bounds` is given (kept within them by projection).
fn refine(
    fit: &Fit<'_>,
    mut at: DVector<f64>,
    mut ap: DVector<f64>,
    mut radius: f64,
    bounds: Option<(f64, f64)>,
    opts: &LmOptions,
) -> Result<Refined> {
    let k = at.len();
    let free_r = bounds.is_some();
    let np = 2 * k + usize::from(free_r);
    let clamp_r = |r: f64| bounds.map_or(r, |(lo, hi)| r.clamp(lo, hi));
    radius = clamp_r(radius);
    let mut cost = fit.objective(&at, &ap, radius);
    if !cost.is_finite() {
        return Ok((at, ap, radius, 0, false));
    }
    let ft = fit.frame.transpose();
    let mut lambda = 1e-3;
    for it in 0..opts.max_iterations {
        crate::interrupt::check()?;
        let mut jtj = DMatrix::<f64>::zeros(np, np);
        let mut jtr = DVector::<f64>::zeros(np);
        let mut jrow_u = DVector::<f64>::zeros(np);
        let mut jrow_v = DVector::<f64>::zeros(np);
        for &(i, u) in fit.obs {
            let row = fit.theta.row(i);
            let (dir, dth, dph) = unit_and_partials(&ft, fit.theta, i, &at, &ap);
            let x = fit.parent[i] + dir * radius;
            let (dth, dph) = (dth * radius, dph * radius);
            let cam = &fit.cameras[i];
            let kr = cam.k * cam.r;
            let h = kr * (x - cam.c);
            let (pu, pv) = (h.x / h.z, h.y / h.z);
            let iz = 1.0 / h.z;
            let ju = (kr.row(0) - pu * kr.row(2)) * iz;
            let jv = (kr.row(1) - pv * kr.row(2)) * iz;
            let (ut, up) = ((ju * dth)[0], (ju * dph)[0]);
            let (vt, vp) = ((jv * dth)[0], (jv * dph)[0]);
            for j in 0..k {
                jrow_u[j] = ut * row[j];
                jrow_u[k + j] = up * row[j];
                jrow_v[j] = vt * row[j];
                jrow_v[k + j] = vp * row[j];
            }
            if free_r {
                jrow_u[2 * k] = (ju * dir)[0];
                jrow_v[2 * k] = (jv * dir)[0];
            }
            let (ru, rv) = (pu - u.x, pv - u.y);
            jtj.ger(1.0, &jrow_u, &jrow_u, 1.0);
            jtj.ger(1.0, &jrow_v, &jrow_v, 1.0);
            jtr.axpy(ru, &jrow_u, 1.0);
            jtr.axpy(rv, &jrow_v, 1.0);
        }
        if let Some((priors, s, e_max)) = fit.angles {
            // Each frame's excess beyond a range: e = lo − α or α − hi, α the angle between
            // the unit direction and the reference; ∂α/∂q = −(b̂ · ∂u/∂q) / sin α.
            let mut jrow = DVector::<f64>::zeros(np);
            for i in 0..fit.parent.len() {
                let row = fit.theta.row(i);
                let (dir, dth, dph) = unit_and_partials(&ft, fit.theta, i, &at, &ap);
                for p in priors {
                    let b = p.reference[i];
                    let nb = b.norm();
                    if nb <= 0.0 {
                        continue;
                    }
                    let b = b / nb;
                    let c = dir.dot(&b).clamp(-1.0, 1.0);
                    let alpha = c.acos();
                    let sin = (1.0 - c * c).sqrt();
                    let Some((e, sign)) = range_excess(alpha, p.range) else {
                        continue;
                    };
                    if sin < 1e-9 || e > e_max {
                        continue;
                    }
                    let (gt, gp) = (-b.dot(&dth) / sin, -b.dot(&dph) / sin);
                    jrow.fill(0.0);
                    for j in 0..k {
                        jrow[j] = s * sign * gt * row[j];
                        jrow[k + j] = s * sign * gp * row[j];
                    }
                    jtj.ger(1.0, &jrow, &jrow, 1.0);
                    jtr.axpy(s * e, &jrow, 1.0);
                }
            }
        }
        if let (true, Some((r0, w))) = (free_r, fit.prior) {
            let d = w / r0;
            jtj[(2 * k, 2 * k)] += d * d;
            jtr[2 * k] += d * (w * (radius - r0) / r0);
        }
        if jtr.amax() <= 1e-14 * (1.0 + cost.sqrt()) {
            return Ok((at, ap, radius, it, true));
        }
        let mut improved = false;
        for _ in 0..20 {
            let mut a = jtj.clone();
            for d in 0..np {
                a[(d, d)] += lambda * jtj[(d, d)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&(-&jtr))) else {
                lambda *= 10.0;
                continue;
            };
            let nt = &at + step.rows(0, k);
            let npv = &ap + step.rows(k, k);
            let nr = if free_r {
                clamp_r(radius + step[2 * k])
            } else {
                radius
            };
            let cn = fit.objective(&nt, &npv, nr);
            if cn.is_finite() && cn <= cost {
                let rel = (cost - cn) / cost.max(f64::MIN_POSITIVE);
                at = nt;
                ap = npv;
                radius = nr;
                cost = cn;
                lambda = (lambda * 0.3).max(1e-12);
                improved = true;
                if rel < opts.rel_tol {
                    return Ok((at, ap, radius, it + 1, true));
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            return Ok((at, ap, radius, it + 1, true));
        }
    }
    Ok((at, ap, radius, opts.max_iterations, false))
}

/// Reconstructability η_a (Eq 4.13) of a known articulated trajectory: the ratio of the
/// parts of the impostor and of the true relative trajectories that the basis cannot
/// span, `‖P⊥ χ_C‖ / ‖P⊥ χ_X‖`, measured on the unit relative directions (the quantities
/// of Eq 4.12) rather than on a planar angle. `η_a ≫ 1` means the BQP picks the truth.
pub fn reconstructability(
    cameras: &[Camera],
    parent: &[Vector3<f64>],
    child: &[Vector3<f64>],
    times: &[f64],
    k: usize,
) -> Result<f64> {
    let f = cameras.len();
    if parent.len() != f || child.len() != f || times.len() != f {
        return Err(Error::invalid(
            "parent/child/times",
            "need one entry per camera frame",
        ));
    }
    if k == 0 || k > f {
        return Err(Error::invalid("k", format!("must be in 1..={f}")));
    }
    let span = DctSpan::from_times(times)?;
    let theta = span.matrix(times, k)?;
    let mut truth = DMatrix::zeros(f, 3);
    let mut impostor = DMatrix::zeros(f, 3);
    for i in 0..f {
        let d = child[i] - parent[i];
        let r = d.norm();
        if !(r.is_finite() && r > 0.0) {
            return Err(Error::invalid(
                "child",
                format!("frame {i}: must differ from the parent and be finite"),
            ));
        }
        let v = child[i] - cameras[i].c;
        let other = match ray_sphere(&cameras[i].c, &v, &parent[i], r) {
            Some((s1, s2)) => {
                // The truth is at s = 1; the impostor is the other root.
                let s = if (s1 - 1.0).abs() < (s2 - 1.0).abs() {
                    s2
                } else {
                    s1
                };
                cameras[i].c + v * s - parent[i]
            }
            None => d,
        };
        for c in 0..3 {
            truth[(i, c)] = d[c] / r;
            impostor[(i, c)] = other[c] / r;
        }
    }
    let q1 = observed_basis(&theta)?;
    let perp = |m: &DMatrix<f64>| -> f64 { (m - &q1 * (q1.transpose() * m)).norm() };
    let (nc, nx) = (perp(&impostor), perp(&truth));
    Ok(if nx > 0.0 { nc / nx } else { f64::INFINITY })
}

#[cfg(test)]
mod tests;

/// A kinematic tree: `parents[j]` is the parent joint of `j` (`None` for the one root) and
/// `lengths[j]` the length of the bone from the parent to `j` (ignored for the root).
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    parents: Vec<Option<usize>>,
    lengths: Vec<f64>,
    /// Joints in an order where every parent precedes its children, root first.
    order: Vec<usize>,
}

impl Skeleton {
    /// Validates a tree: exactly one root, parents in range, no cycle, positive finite
    /// lengths on every bone.
    pub fn new(parents: Vec<Option<usize>>, lengths: Vec<f64>) -> Result<Self> {
        let j = parents.len();
        if lengths.len() != j {
            return Err(Error::invalid(
                "lengths",
                format!("expected one length per joint ({j}), got {}", lengths.len()),
            ));
        }
        if j == 0 {
            return Err(Error::invalid("parents", "the skeleton has no joint"));
        }
        let roots: Vec<usize> = (0..j).filter(|&i| parents[i].is_none()).collect();
        if roots.len() != 1 {
            return Err(Error::invalid(
                "parents",
                format!(
                    "a tree needs exactly one root, found {} ({roots:?})",
                    roots.len()
                ),
            ));
        }
        let mut children = vec![Vec::new(); j];
        for (i, p) in parents.iter().enumerate() {
            if let Some(p) = *p {
                if p >= j {
                    return Err(Error::invalid(
                        "parents",
                        format!("joint {i} has parent {p}, out of range 0..{j}"),
                    ));
                }
                if p == i {
                    return Err(Error::invalid(
                        "parents",
                        format!("joint {i} is its own parent"),
                    ));
                }
                if !(lengths[i].is_finite() && lengths[i] > 0.0) {
                    return Err(Error::invalid(
                        "lengths",
                        format!("bone of joint {i} must be positive, got {}", lengths[i]),
                    ));
                }
                children[p].push(i);
            }
        }
        let mut order = Vec::with_capacity(j);
        let mut queue = std::collections::VecDeque::from([roots[0]]);
        while let Some(i) = queue.pop_front() {
            order.push(i);
            queue.extend(children[i].iter().copied());
        }
        if order.len() != j {
            let unreached: Vec<usize> = (0..j).filter(|i| !order.contains(i)).collect();
            return Err(Error::invalid(
                "parents",
                format!(
                    "not a tree: joints {unreached:?} lie on a cycle, unreachable from the root"
                ),
            ));
        }
        Ok(Skeleton {
            parents,
            lengths,
            order,
        })
    }

    pub fn n_joints(&self) -> usize {
        self.parents.len()
    }
    pub fn parents(&self) -> &[Option<usize>] {
        &self.parents
    }
    pub fn lengths(&self) -> &[f64] {
        &self.lengths
    }
    /// Parents-before-children order, root first.
    pub fn order(&self) -> &[usize] {
        &self.order
    }
    pub fn root(&self) -> usize {
        self.order[0]
    }
}

/// Positions `[frame][joint]` and one result per joint (`None` for the root).
pub type SkeletonReconstruction = (Vec<Vec<Vector3<f64>>>, Vec<Option<ArticulatedResult>>);

/// Reconstructs every joint from the root trajectory outwards (forward kinematics, Eq 4.6):
/// `pixels[i][j]` is joint `j` in frame `i`. Returns positions `[frame][joint]` and one
/// result per non-root joint (`None` for the root).
///
/// No [`AnglePrior`]s here: from reconstructed references a flipped ancestor makes a prior
/// wrong and pushes its descendants after it (measured on the CMU windows of
/// `benches/articulated_accuracy.py --skeleton`, Fig 4.3(c), seed 0: bend and sibling priors
/// took the mean error 0.147 → 0.128 on one window set but 0.151 → 0.178 and 0.177 → 0.322
/// on two others).
pub fn reconstruct_skeleton(
    cameras: &[Camera],
    pixels: &[Vec<Option<Vector2<f64>>>],
    skeleton: &Skeleton,
    root: &[Vector3<f64>],
    times: &[f64],
    opts: &ArticulatedOptions,
) -> Result<SkeletonReconstruction> {
    let f = cameras.len();
    let nj = skeleton.n_joints();
    if pixels.len() != f || root.len() != f {
        return Err(Error::invalid(
            "x/root",
            format!("need one entry per camera frame ({f})"),
        ));
    }
    if let Some(i) = pixels.iter().position(|row| row.len() != nj) {
        return Err(Error::invalid(
            "x",
            format!("frame {i}: expected {nj} joints, got {}", pixels[i].len()),
        ));
    }
    let mut traj: Vec<Option<Vec<Vector3<f64>>>> = vec![None; nj];
    let mut results: Vec<Option<ArticulatedResult>> = vec![None; nj];
    traj[skeleton.root()] = Some(root.to_vec());
    for &j in &skeleton.order()[1..] {
        crate::interrupt::check()?;
        let p = skeleton.parents()[j].ok_or_else(|| Error::invalid("parents", "bad order"))?;
        let parent = traj[p]
            .clone()
            .ok_or_else(|| Error::invalid("parents", "parent not reconstructed"))?;
        let px: Vec<Option<Vector2<f64>>> = pixels.iter().map(|row| row[j]).collect();
        let kids: Vec<ChildObservations> = (0..nj)
            .filter(|&c| skeleton.parents()[c] == Some(j))
            .map(|c| ChildObservations {
                pixels: pixels.iter().map(|row| row[c]).collect(),
                length: skeleton.lengths()[c],
            })
            .collect();
        let res = reconstruct_articulated_with(
            cameras,
            &px,
            &parent,
            times,
            skeleton.lengths()[j],
            &kids,
            opts,
        )
        .map_err(|e| match e {
            Error::Degenerate(m) => Error::Degenerate(format!("joint {j}: {m}")),
            other => other,
        })?;
        traj[j] = Some(res.points.clone());
        results[j] = Some(res);
    }
    let mut out = vec![vec![Vector3::zeros(); nj]; f];
    for (j, t) in traj.iter().enumerate() {
        if let Some(t) = t {
            for i in 0..f {
                out[i][j] = t[i];
            }
        }
    }
    Ok((out, results))
}
