//! Reconstruction of the 3D trajectory of a moving point from its 2D projections in cameras
//! with known poses and capture times (thesis Chapter 5 and Appendix B). No two photos need
//! share a time instant: the trajectory is a linear combination of DCT basis functions of
//! continuous time (Eq 5.3), evaluated at each observation's own time.
//!
//! The pipeline for one point:
//! 1. **Linear solve** (Eq 5.1–5.7): each observed frame `i` gives two rows of
//!    `Q_i X_i = q_i`; with `X_i = Φ_i β` they stack into `QΘ β = q`. Missing observations
//!    (NaN rows) simply drop their rows. 2D measurements are normalised per trajectory
//!    (mean 0, mean distance √2, Sec 5.3) before stacking. The system is solved by a
//!    Householder QR in faer, and the singular values of its `R` factor give the rank and
//!    condition number. A rank below `3K` is reported as [`Error::Degenerate`] naming the
//!    case of Theorem 2 it resembles.
//! 2. **K by N-fold cross validation** (Eq 5.8): folds interleaved in time order, so each
//!    fold is spread uniformly over the sequence; the K with the least held-out reprojection
//!    error wins. All K share one factorisation per fold: unknowns are ordered `3k + c`
//!    (basis function major), so the system for `K` is the leading `3K × 3K` block of the
//!    normal equations, and the leading block of a Cholesky factor is the factor of the
//!    leading block.
//! 3. **Refinement** (Eq 5.9): Levenberg–Marquardt on the reprojection error in pixels with
//!    the analytic Jacobian.
//! 4. **Diagnostics**: reprojection RMS before and after refinement, rank and condition
//!    number, the Gauss–Newton covariance `σ² (JᵀJ)⁻¹` of the coefficients at the optimum
//!    (σ² the residual variance) and the per-frame 3D standard deviation it implies.
//!
//! [`reconstructability`] computes η of Eq 5.16 for analysis, and
//! [`reconstruct_trajectories`] runs many points that share the cameras in parallel.
//!
//! ```
//! use nalgebra::{Matrix3, Vector3};
//! use socialcore::geometry::Camera;
//! use socialcore::trajectory::{reconstruct_trajectory, Frames, KSelection, TrajectoryOptions};
//!
//! // Cameras at scattered positions around the origin, one photo per frame.
//! let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
//! let mut cams = Vec::new();
//! let mut times = Vec::new();
//! for i in 0..40 {
//!     let a = (i as f64 * 2.4).sin() * 3.0;
//!     let c = Vector3::new(5.0 * a.sin(), -1.0 + 0.1 * (i % 7) as f64, -5.0 * a.cos());
//!     let z = (-c).normalize();
//!     let x = Vector3::y().cross(&z).normalize();
//!     let y = z.cross(&x);
//!     let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
//!     cams.push(Camera::new(k, r, c, i)?);
//!     times.push(i as f64 / 10.0);
//! }
//! // A point moving on a smooth curve, seen in every frame.
//! let truth = |t: f64| Vector3::new(0.3 * t.sin(), 0.1, -0.2 * (0.7 * t).cos());
//! let mut pixels = Vec::new();
//! for (cam, &t) in cams.iter().zip(&times) {
//!     let p = cam.project(&truth(t)).0;
//!     pixels.extend([p.x, p.y]);
//! }
//! let frames = Frames::new(cams, times.clone())?;
//! let fit = reconstruct_trajectory(&frames, &pixels, &TrajectoryOptions::default())?;
//! assert!((fit.points[17] - truth(times[17])).norm() < 1e-3);
//! // Or with a fixed number of basis functions:
//! let opts = TrajectoryOptions { k: KSelection::Fixed(8), ..Default::default() };
//! let fit = reconstruct_trajectory(&frames, &pixels, &opts)?;
//! assert_eq!(fit.coeffs.len(), 8);
//! # Ok::<(), socialcore::Error>(())
//! ```

mod cv;
pub(crate) mod dense;
mod linear;
mod reconstructability;
mod refine;
#[cfg(test)]
pub(crate) mod testutil;

pub use reconstructability::{null_residual, reconstructability};

use crate::basis::DctSpan;
use crate::error::{Error, Result};
use crate::geometry::{Camera, LmOptions};
use faer::Mat;
use nalgebra::{Matrix3, Vector2, Vector3};
use rayon::prelude::*;

/// Default number of cross-validation folds (Sec 5.1.2).
pub const DEFAULT_FOLDS: usize = 5;

/// Which `K` cross validation returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CvRule {
    /// The `K` of least total held-out reprojection error (Eq 5.8).
    #[default]
    Min,
    /// The smallest `K` whose mean held-out error is within one standard error (over the
    /// folds) of the least (Breiman et al., *Classification and Regression Trees*, 1984).
    /// Plain minimisation picks an over-complex `K` for a fair share of still points,
    /// because the held-out gain of a few noise-fitting parameters is itself noisy; this
    /// rule prefers the simpler model when the data cannot tell them apart.
    OneStandardError,
}

/// How the number of basis functions per coordinate, `K`, is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KSelection {
    /// Use this `K` for every point.
    Fixed(usize),
    /// Per-point `N`-fold cross validation (Eq 5.8) over `K = k_min ..= k_max`, where
    /// `k_max` defaults to `⌊2F̂/3⌋` (`F̂` the point's observed frames) and is further
    /// limited, fold by fold, to what the training observations can determine.
    CrossValidation {
        folds: usize,
        k_min: usize,
        k_max: Option<usize>,
        rule: CvRule,
    },
}

impl Default for KSelection {
    fn default() -> Self {
        KSelection::CrossValidation {
            folds: DEFAULT_FOLDS,
            k_min: 1,
            k_max: None,
            rule: CvRule::Min,
        }
    }
}

/// Options of [`reconstruct_trajectory`].
#[derive(Debug, Clone, Copy)]
pub struct TrajectoryOptions {
    /// Fixed `K` or cross validation.
    pub k: KSelection,
    /// Refine the linear solution on the reprojection error (Eq 5.9).
    pub refine: bool,
    /// Levenberg–Marquardt settings of the refinement.
    pub lm: LmOptions,
    /// Keep the full `3K × 3K` coefficient covariance in the result (the per-frame
    /// standard deviation is always computed).
    pub keep_covariance: bool,
}

impl Default for TrajectoryOptions {
    fn default() -> Self {
        TrajectoryOptions {
            k: KSelection::default(),
            refine: true,
            lm: LmOptions {
                max_iterations: 100,
                rel_tol: 1e-10,
            },
            keep_covariance: true,
        }
    }
}

impl TrajectoryOptions {
    /// Checks the option values.
    pub fn validate(&self) -> Result<()> {
        match self.k {
            KSelection::Fixed(0) => return Err(Error::invalid("k", "must be at least 1")),
            KSelection::Fixed(_) => {}
            KSelection::CrossValidation {
                folds,
                k_min,
                k_max,
                ..
            } => {
                if folds < 2 {
                    return Err(Error::invalid(
                        "folds",
                        format!("cross validation needs at least 2 folds, got {folds}"),
                    ));
                }
                if k_min == 0 {
                    return Err(Error::invalid("k_min", "must be at least 1"));
                }
                if let Some(m) = k_max {
                    if m < k_min {
                        return Err(Error::invalid(
                            "k_max",
                            format!("k_max = {m} is below k_min = {k_min}"),
                        ));
                    }
                }
            }
        }
        if self.lm.max_iterations == 0 && self.refine {
            return Err(Error::invalid("max_iter", "must be at least 1"));
        }
        if !(self.lm.rel_tol.is_finite() && self.lm.rel_tol >= 0.0) {
            return Err(Error::invalid(
                "rel_tol",
                "must be a finite non-negative number",
            ));
        }
        Ok(())
    }

    /// The largest `K` any point of an `F`-frame sequence can use under these options.
    fn k_cap(&self, frames: usize) -> usize {
        match self.k {
            // A point has at most `F` observations, so `K > F` fails every point (2F̂ < 3K)
            // before the table is read: no need to build columns it will never use.
            KSelection::Fixed(k) => k.min(frames.max(1)),
            KSelection::CrossValidation { k_min, k_max, .. } => {
                let thesis = (2 * frames) / 3;
                k_max
                    .unwrap_or(thesis)
                    .min(thesis)
                    .max(k_min)
                    .min(frames.max(1))
            }
        }
    }
}

/// The cameras of every frame with their capture times: what all points of a scene share.
/// Frame `i` was taken by `cameras[i]` at `times[i]` (seconds, any order).
#[derive(Debug, Clone)]
pub struct Frames {
    cameras: Vec<Camera>,
    times: Vec<f64>,
    span: DctSpan,
    /// `K R` of each frame: rows 1–3 of `P_{1:3}`.
    kr: Vec<Matrix3<f64>>,
    /// `−K R C` of each frame: `P_4`.
    kt: Vec<Vector3<f64>>,
}

impl Frames {
    /// Frames with the DCT span implied by the times ([`DctSpan::from_times`]).
    pub fn new(cameras: Vec<Camera>, times: Vec<f64>) -> Result<Self> {
        crate::error::ensure_finite("times", &times)?;
        let span = DctSpan::from_times(&times)?;
        Self::with_span(cameras, times, span)
    }

    /// Frames with an explicit DCT span (so that, for example, a sub-sampled sequence keeps
    /// the basis of the full one).
    pub fn with_span(cameras: Vec<Camera>, times: Vec<f64>, span: DctSpan) -> Result<Self> {
        if cameras.is_empty() {
            return Err(Error::invalid("cameras", "no frames"));
        }
        if cameras.len() != times.len() {
            return Err(Error::invalid(
                "times",
                format!(
                    "has {} entries but there are {} cameras",
                    times.len(),
                    cameras.len()
                ),
            ));
        }
        crate::error::ensure_finite("times", &times)?;
        span.validate()?;
        let kr = cameras.iter().map(|c| c.k * c.r).collect::<Vec<_>>();
        let kt = cameras
            .iter()
            .zip(&kr)
            .map(|(c, m)| -(m * c.c))
            .collect::<Vec<_>>();
        Ok(Frames {
            cameras,
            times,
            span,
            kr,
            kt,
        })
    }

    /// Number of frames `F`.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Never true: construction rejects an empty sequence.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The capture times.
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// The cameras.
    pub fn cameras(&self) -> &[Camera] {
        &self.cameras
    }

    /// The DCT span of the basis.
    pub fn span(&self) -> DctSpan {
        self.span
    }

    /// Homogeneous image point `P_i [X; 1]` of frame `i` (its third entry is the depth
    /// scaled by `K[2,2] = 1`).
    #[inline]
    pub(crate) fn project_h(&self, i: usize, x: &Vector3<f64>) -> Vector3<f64> {
        self.kr[i] * x + self.kt[i]
    }

    /// The `F × kc` basis values, row-major (row `i` is `θ(t_i)`).
    pub(crate) fn basis_rows(&self, kc: usize) -> Vec<f64> {
        let mut out = vec![0.0; self.len() * kc];
        if kc > 0 {
            for (row, &t) in out.chunks_mut(kc).zip(&self.times) {
                self.span.eval_row(t, row);
            }
        }
        out
    }
}

/// The reconstruction of one point trajectory and its diagnostics.
#[derive(Debug, Clone)]
pub struct TrajectoryFit {
    /// Basis functions per coordinate.
    pub k: usize,
    /// Coefficients `β_k ∈ ℝ³`, `k = 0..K`: `X(t) = Σ_k θ_k(t) β_k`.
    pub coeffs: Vec<Vector3<f64>>,
    /// The trajectory at every frame time (including frames where the point was missing).
    pub points: Vec<Vector3<f64>>,
    /// Per-frame standard deviation of each coordinate (metres) implied by the coefficient
    /// covariance; NaN when it is undefined (no more observations than unknowns).
    pub std: Vec<Vector3<f64>>,
    /// The `3K × 3K` covariance of the coefficients, row-major in the unknown order
    /// `3k + c` (the order of `coeffs` flattened), when requested.
    pub covariance: Option<Vec<f64>>,
    /// Residual standard deviation per image coordinate (px) used to scale the covariance.
    pub sigma: f64,
    /// Number of observed frames `F̂`.
    pub observed: usize,
    /// Reprojection RMS (px per observation) of the linear solution.
    pub rms_linear: f64,
    /// Reprojection RMS (px per observation) of the returned solution.
    pub rms: f64,
    /// Whether the refinement met its tolerance (true when not refined).
    pub converged: bool,
    /// Levenberg–Marquardt iterations taken.
    pub iterations: usize,
    /// Numerical rank of `QΘ` (always `3K` for a returned fit).
    pub rank: usize,
    /// Condition number of `QΘ` (2-norm) with the normalised measurements.
    pub cond: f64,
    /// Cross-validated held-out reprojection RMS (px per observation) for `K = 1, 2, …`;
    /// infinite where `K` was not admissible; empty when `K` was fixed.
    pub cv_error: Vec<f64>,
    /// The DCT span, to evaluate the trajectory at other times.
    pub span: DctSpan,
}

impl TrajectoryFit {
    /// The trajectory at arbitrary times (seconds).
    pub fn at(&self, times: &[f64]) -> Vec<Vector3<f64>> {
        let mut row = vec![0.0; self.k];
        times
            .iter()
            .map(|&t| {
                self.span.eval_row(t, &mut row);
                row.iter()
                    .zip(&self.coeffs)
                    .fold(Vector3::zeros(), |acc, (w, b)| acc + b * *w)
            })
            .collect()
    }
}

/// Basis values for all frames up to `kc` functions, shared by the points of a batch.
struct BasisTable {
    kc: usize,
    rows: Vec<f64>,
}

impl BasisTable {
    fn new(frames: &Frames, kc: usize) -> Self {
        BasisTable {
            kc,
            rows: frames.basis_rows(kc),
        }
    }

    #[inline]
    fn row(&self, i: usize) -> &[f64] {
        &self.rows[i * self.kc..(i + 1) * self.kc]
    }

    /// The `n × k` matrix of basis values at the given frames.
    fn gather(&self, idx: &[usize], k: usize) -> Mat<f64> {
        Mat::from_fn(idx.len(), k, |r, c| self.rows[idx[r] * self.kc + c])
    }
}

/// Parses one point's `(F, 2)` row-major pixels: NaN in a row marks it missing.
fn parse_observations(
    frames: &Frames,
    pixels: &[f64],
    arg: &str,
) -> Result<(Vec<usize>, Vec<Vector2<f64>>)> {
    let f = frames.len();
    if pixels.len() != 2 * f {
        return Err(Error::invalid(
            arg,
            format!(
                "expected {f}×2 values (one pixel per frame), got {}",
                pixels.len()
            ),
        ));
    }
    let mut idx = Vec::new();
    let mut px = Vec::new();
    for (i, p) in pixels.chunks_exact(2).enumerate() {
        if p[0].is_nan() || p[1].is_nan() {
            continue;
        }
        if !(p[0].is_finite() && p[1].is_finite()) {
            return Err(Error::invalid(
                arg,
                format!("row {i} is infinite (mark a missing observation with NaN)"),
            ));
        }
        idx.push(i);
        px.push(Vector2::new(p[0], p[1]));
    }
    if idx.is_empty() {
        return Err(Error::invalid(
            arg,
            "all observations are missing (every row is NaN)",
        ));
    }
    Ok((idx, px))
}

/// Reconstructs one trajectory from its pixels `(F, 2)` row-major (NaN rows = not seen).
pub fn reconstruct_trajectory(
    frames: &Frames,
    pixels: &[f64],
    opts: &TrajectoryOptions,
) -> Result<TrajectoryFit> {
    opts.validate()?;
    let table = BasisTable::new(frames, opts.k_cap(frames.len()));
    solve_point(frames, &table, pixels, opts)
}

/// Reconstructs `n` trajectories that share the frames: `pixels` is row-major `(n, F, 2)`,
/// each point with its own missing pattern. Each point gets its own `Result`, so one
/// degenerate point does not spoil the batch. Parallel over points (rayon); the result does
/// not depend on the number of threads.
pub fn reconstruct_trajectories(
    frames: &Frames,
    pixels: &[f64],
    n: usize,
    opts: &TrajectoryOptions,
) -> Result<Vec<Result<TrajectoryFit>>> {
    opts.validate()?;
    let f = frames.len();
    if pixels.len() != n * f * 2 {
        return Err(Error::invalid(
            "x",
            format!("expected {n}×{f}×2 values, got {}", pixels.len()),
        ));
    }
    let table = BasisTable::new(frames, opts.k_cap(f));
    // Ctrl-C: points not yet started are skipped once a stop is requested, and the
    // refinement and cross-validation loops of running points stop early.
    let out: Vec<Result<TrajectoryFit>> = pixels
        .par_chunks(2 * f.max(1))
        .map(|row| {
            crate::interrupt::check()?;
            solve_point(frames, &table, row, opts)
        })
        .collect();
    crate::interrupt::check()?;
    Ok(out)
}

/// Tolerance on camera-centre spread (relative to the scene's coordinate magnitude) below
/// which the camera counts as still.
const STILL_CAMERA_TOL: f64 = 1e-9;

fn solve_point(
    frames: &Frames,
    table: &BasisTable,
    pixels: &[f64],
    opts: &TrajectoryOptions,
) -> Result<TrajectoryFit> {
    let (idx, px) = parse_observations(frames, pixels, "x")?;
    let n = idx.len();
    // Enough equations for the smallest K we may use (2F̂ ≥ 3K, Sec 5.1.1)?
    let k_floor = match opts.k {
        KSelection::Fixed(k) => k,
        KSelection::CrossValidation { k_min, .. } => k_min,
    };
    if 2 * n < k_floor.saturating_mul(3) {
        return Err(Error::degenerate(format!(
            "too few observations for K = {k_floor} (k): {n} observed frames give {} equations \
             for {} unknowns; need at least {} observations",
            2 * n,
            k_floor.saturating_mul(3),
            k_floor.saturating_mul(3).div_ceil(2)
        )));
    }
    // A still camera sees every point on fixed rays: depth is unobservable for any K
    // (Theorem 2.i, a constant C always lies in col(Θ)).
    let c0 = frames.cameras[idx[0]].c;
    let scale = idx
        .iter()
        .map(|&i| frames.cameras[i].c.norm())
        .fold(1.0, f64::max);
    let spread = idx
        .iter()
        .map(|&i| (frames.cameras[i].c - c0).norm())
        .fold(0.0, f64::max);
    if spread <= STILL_CAMERA_TOL * scale {
        return Err(Error::degenerate(format!(
            "the camera centre does not move over the {n} observed frames: a still camera cannot \
             recover the depth of a moving point (Theorem 2.i: the camera trajectory lies in \
             col(Θ) for every K)"
        )));
    }

    let sys = linear::PointSystem::new(frames, idx, px);
    let (k, cv_error) = match opts.k {
        KSelection::Fixed(k) => (k, Vec::new()),
        KSelection::CrossValidation {
            folds,
            k_min,
            k_max,
            rule,
        } => {
            let k_hi = k_max.unwrap_or(usize::MAX).min((2 * n) / 3).min(table.kc);
            let cv = cv::select_k(frames, table, &sys, folds, k_min, k_hi, rule);
            // Cross validation stops early on Ctrl-C: do not use its partial answer.
            crate::interrupt::check()?;
            (cv.k.unwrap_or(k_min), cv.errors)
        }
    };
    if k > table.kc {
        return Err(Error::invalid(
            "k",
            format!("K = {k} exceeds the basis table size {}", table.kc),
        ));
    }
    let theta = table.gather(&sys.idx, k);
    let lin = linear::solve(&theta, &sys)?;
    if lin.rank < 3 * k {
        return Err(linear::diagnose(frames, &sys, &theta, k, lin.rank));
    }
    let mut beta = lin.beta;
    let rms_linear = refine::rms(frames, &theta, &sys, &beta);
    let (converged, iterations) = if opts.refine {
        let r = refine::refine(frames, &theta, &sys, &beta, &opts.lm);
        crate::interrupt::check()?;
        beta = r.beta;
        (r.converged, r.iterations)
    } else {
        (true, 0)
    };
    let rms = refine::rms(frames, &theta, &sys, &beta);
    let unc = refine::uncertainty(frames, table, &theta, &sys, &beta, k);
    let coeffs: Vec<Vector3<f64>> = beta
        .chunks_exact(3)
        .map(|b| Vector3::new(b[0], b[1], b[2]))
        .collect();
    let points = (0..frames.len())
        .map(|i| {
            table.row(i)[..k]
                .iter()
                .zip(&coeffs)
                .fold(Vector3::zeros(), |acc, (w, b)| acc + b * *w)
        })
        .collect();
    Ok(TrajectoryFit {
        k,
        coeffs,
        points,
        std: unc.std,
        covariance: if opts.keep_covariance {
            unc.covariance
        } else {
            None
        },
        sigma: unc.sigma,
        observed: n,
        rms_linear,
        rms,
        converged,
        iterations,
        rank: lin.rank,
        cond: lin.cond,
        cv_error,
        span: frames.span,
    })
}

#[cfg(test)]
mod tests;
