//! Ego-motion gaze calibration (thesis Sec 3.2.1, Eq 3.1).
//!
//! A wearer moves the head while fixating a still point `y` (the "range of motion"
//! segment). The primary gaze ray is fixed in the camera frame: eye centre `p` and unit
//! direction `v`. At frame `i` with world→camera rotation `R_i` and centre `C_i` it is
//! `p_i = R_iᵀ p + C_i`, `v_i = R_iᵀ v`. Eq 3.1 finds `p`, `v` and `y` by minimising
//!
//! ```text
//! Σ_i ‖ (I − v_i v_iᵀ)(y − p_i) / ((y − p_i)ᵀ v_i) ‖² + λ_c ‖p‖²
//! ```
//!
//! — the residual is the eye-in-head deviation `m` on the plane at unit distance of the
//! Sec 3.1 gaze model, so the eye-in-head spread is `h = std(m)` over the segment.
//!
//! **What the data determine.** Sliding the eye centre along its own gaze direction,
//! `p → p + s v`, leaves every ray `p_i + α v_i` unchanged, so only the part of `p` normal
//! to `v` is observable; with noise, the depth normalisation even rewards `s → −∞` (the
//! trivial solution Sec 3.2.1 mentions). Eq 3.1's `λ_c ‖p‖²` alone must be strong to stop
//! that drift, and then it also shrinks the observable part towards the camera centre. We
//! keep `λ_c ‖p‖²` (weak by default) and add a strong prior on the unobservable component
//! only, `λ_axis (pᵀv)²`: the reported `p` is the point of the primary ray closest to the
//! camera centre, and its normal part is unbiased. Compare eye offsets with
//! `p − (pᵀv) v` when the true eye sits elsewhere on the ray.
//! Initialisation as in the thesis: `p = 0`, `v = z`, `y` the least-squares intersection of
//! the initial rays; then Levenberg–Marquardt over `(p, y, v)` with `v` kept on the unit
//! sphere by a two-parameter tangent update.

use crate::error::{Error, Result};
use crate::interrupt;
use nalgebra::{Matrix3, SMatrix, SVector, Vector2, Vector3};

/// Number of free parameters: `p` (3), `y` (3), `v` on the sphere (2).
const NP: usize = 8;
type Mat8 = SMatrix<f64, NP, NP>;
type Vec8 = SVector<f64, NP>;

/// Options of [`calibrate_gaze`].
#[derive(Debug, Clone, Copy)]
pub struct CalibrationOptions {
    /// λ_c of Eq 3.1, the weight of `‖p‖²` (per frame: the total weight is `λ_c · F_c`, so
    /// the prior's strength does not fade as the segment grows). Units 1/m².
    pub lambda_c: f64,
    /// Weight (per frame, 1/m²) of `(pᵀv)²`, the prior on the component of `p` along the
    /// gaze direction, which the data cannot determine (see the module docs).
    pub lambda_axis: f64,
    /// Levenberg–Marquardt iteration cap.
    pub max_iter: usize,
    /// Stop when the relative decrease of the cost falls below this.
    pub tol: f64,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        CalibrationOptions {
            lambda_c: 1e-4,
            lambda_axis: 100.0,
            max_iter: 200,
            tol: 1e-12,
        }
    }
}

/// The calibrated primary gaze ray of one wearer (camera frame) and its uncertainty.
#[derive(Debug, Clone)]
pub struct GazeCalibration {
    /// Eye centre in the camera frame, metres.
    pub p: Vector3<f64>,
    /// Unit primary gaze direction in the camera frame.
    pub v: Vector3<f64>,
    /// The fixated point in the world frame, metres.
    pub y: Vector3<f64>,
    /// Eye-in-head spread: standard deviation of each coordinate of the deviation `m`
    /// on the unit-distance plane (unbiased for the 8 fitted parameters).
    pub h: f64,
    /// Standard errors of `p` (metres, per axis).
    pub p_std: Vector3<f64>,
    /// Standard error of the direction `v` (radians, the RMS of its two tangent axes).
    pub v_std: f64,
    /// Standard errors of `y` (metres, per axis).
    pub y_std: Vector3<f64>,
    /// Relative standard error of `h` (≈ 1/√(2·dof)).
    pub h_rel_std: f64,
    /// Per-frame deviation `‖m_i‖` at the solution (radians, small-angle).
    pub residuals: Vec<f64>,
    /// LM iterations taken.
    pub iterations: usize,
    /// Whether LM met its tolerance before the cap.
    pub converged: bool,
}

/// Frame data: world→camera rotations and camera centres of the segment.
struct Segment<'a> {
    r: &'a [Matrix3<f64>],
    c: &'a [Vector3<f64>],
}

/// An orthonormal basis `(a, b)` of the plane normal to unit `v`.
fn tangent_basis(v: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if v.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let a = v.cross(&helper).normalize();
    let b = v.cross(&a);
    (a, b)
}

/// `v` moved by the tangent step `(d0, d1)` along the great circle, kept unit.
fn rotate_dir(v: &Vector3<f64>, d: &Vector2<f64>) -> Vector3<f64> {
    let (a, b) = tangent_basis(v);
    let w = a * d.x + b * d.y;
    let th = w.norm();
    if th < 1e-300 {
        return *v;
    }
    (v * th.cos() + w / th * th.sin()).normalize()
}

/// Deviation `m_i` of Eq 3.1 for one frame, or `None` when `y` is not in front of the eye.
fn deviation(
    r: &Matrix3<f64>,
    c: &Vector3<f64>,
    p: &Vector3<f64>,
    v: &Vector3<f64>,
    y: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let pi = r.transpose() * p + c;
    let vi = r.transpose() * v;
    let d = y - pi;
    let depth = d.dot(&vi);
    if depth.is_nan() || depth <= 1e-9 {
        return None;
    }
    Some((d - vi * depth) / depth)
}

/// `(p, y, v)` moved by the parameter step `d` (p: 0..3, y: 3..6, v tangent: 6..8).
fn apply_step(
    p: &Vector3<f64>,
    y: &Vector3<f64>,
    v: &Vector3<f64>,
    d: &Vec8,
) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    (
        p + Vector3::new(d[0], d[1], d[2]),
        y + Vector3::new(d[3], d[4], d[5]),
        rotate_dir(v, &Vector2::new(d[6], d[7])),
    )
}

impl Segment<'_> {
    /// Central-difference Jacobian of [`Self::residuals`] (8 columns; the residual is
    /// cheap) into `jac`; false when a perturbed point leaves the front of a camera.
    #[allow(clippy::too_many_arguments)]
    fn jacobian(
        &self,
        p: &Vector3<f64>,
        y: &Vector3<f64>,
        v: &Vector3<f64>,
        sqrt_lambda: (f64, f64),
        scale: f64,
        jac: &mut [Vec8],
        rp: &mut Vec<f64>,
        rm: &mut Vec<f64>,
    ) -> bool {
        for k in 0..NP {
            let hstep = if k < 6 { 1e-6 * scale } else { 1e-6 };
            let mut d = Vec8::zeros();
            d[k] = hstep;
            let (pp, yp, vp) = apply_step(p, y, v, &d);
            d[k] = -hstep;
            let (pm, ym, vm) = apply_step(p, y, v, &d);
            if !self.residuals(&pp, &yp, &vp, sqrt_lambda, rp)
                || !self.residuals(&pm, &ym, &vm, sqrt_lambda, rm)
            {
                return false;
            }
            for (row, (a, b)) in jac.iter_mut().zip(rp.iter().zip(rm.iter())) {
                row[k] = (a - b) / (2.0 * hstep);
            }
        }
        true
    }

    /// Residual vector (3 per frame, then 3 for the prior) at `(p, y, v)`.
    fn residuals(
        &self,
        p: &Vector3<f64>,
        y: &Vector3<f64>,
        v: &Vector3<f64>,
        sqrt_lambda: (f64, f64),
        out: &mut Vec<f64>,
    ) -> bool {
        out.clear();
        for (r, c) in self.r.iter().zip(self.c) {
            let Some(m) = deviation(r, c, p, v, y) else {
                return false;
            };
            out.extend_from_slice(m.as_slice());
        }
        out.extend_from_slice((p * sqrt_lambda.0).as_slice());
        out.push(sqrt_lambda.1 * p.dot(v));
        true
    }
}

/// Least-squares intersection of rays `(o_i, d_i)` (unit `d_i`); `None` when they are
/// (nearly) parallel.
fn intersect_rays(origins: &[Vector3<f64>], dirs: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    let mut a = Matrix3::<f64>::zeros();
    let mut b = Vector3::<f64>::zeros();
    for (o, d) in origins.iter().zip(dirs) {
        let pr = Matrix3::identity() - d * d.transpose();
        a += pr;
        b += pr * o;
    }
    let eig = a.symmetric_eigen();
    let (lo, hi) = (eig.eigenvalues.min(), eig.eigenvalues.max());
    if lo.is_nan() || lo <= 1e-10 * hi.max(f64::MIN_POSITIVE) {
        return None;
    }
    a.cholesky().map(|ch| ch.solve(&b))
}

/// Calibrates the primary gaze ray of one wearer from a fixation segment (Eq 3.1).
///
/// `r[i]` is the world→camera rotation and `c[i]` the camera centre of frame `i`.
/// Errors: fewer than 5 frames, non-finite poses, or head motion too small to intersect
/// the rays ([`Error::Degenerate`]).
pub fn calibrate_gaze(
    r: &[Matrix3<f64>],
    c: &[Vector3<f64>],
    opts: &CalibrationOptions,
) -> Result<GazeCalibration> {
    let f = r.len();
    if c.len() != f {
        return Err(Error::invalid(
            "C",
            format!("{} centres for {} rotations", c.len(), f),
        ));
    }
    if f < 5 {
        return Err(Error::invalid(
            "cameras",
            format!("a calibration segment needs at least 5 frames, got {f}"),
        ));
    }
    if !(opts.lambda_c >= 0.0 && opts.lambda_c.is_finite()) {
        return Err(Error::invalid(
            "lambda_c",
            format!("expected a finite number ≥ 0, got {}", opts.lambda_c),
        ));
    }
    if !(opts.lambda_axis >= 0.0 && opts.lambda_axis.is_finite()) {
        return Err(Error::invalid(
            "lambda_axis",
            format!("expected a finite number ≥ 0, got {}", opts.lambda_axis),
        ));
    }
    if !(opts.tol >= 0.0 && opts.tol.is_finite()) {
        return Err(Error::invalid(
            "tol",
            format!("expected a finite number ≥ 0, got {}", opts.tol),
        ));
    }
    for (i, (ri, ci)) in r.iter().zip(c).enumerate() {
        if !ri.iter().chain(ci.iter()).all(|x| x.is_finite()) {
            return Err(Error::invalid(
                "cameras",
                format!("frame {i} has a non-finite pose"),
            ));
        }
    }
    let seg = Segment { r, c };
    // Initialisation (Sec 3.2.1): p = 0, v = z, y from the initial rays.
    let mut p = Vector3::zeros();
    let mut v = Vector3::z();
    let dirs: Vec<Vector3<f64>> = r.iter().map(|ri| ri.transpose() * v).collect();
    let mut y = intersect_rays(c, &dirs).ok_or_else(|| {
        Error::degenerate(
            "the optical axes of the calibration segment are parallel: the head must move \
             (translate and turn) while fixating the point",
        )
    })?;
    let sqrt_lambda = (
        (opts.lambda_c * f as f64).sqrt(),
        (opts.lambda_axis * f as f64).sqrt(),
    );
    let mut res = Vec::with_capacity(3 * f + 4);
    if !seg.residuals(&p, &y, &v, sqrt_lambda, &mut res) {
        return Err(Error::degenerate(
            "the initial fixation point lies behind some cameras: the segment does not look \
             at one point",
        ));
    }
    let cost_of = |r: &[f64]| r.iter().map(|x| x * x).sum::<f64>();
    let mut cost = cost_of(&res);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut converged = false;
    let mut jac = vec![Vec8::zeros(); 3 * f + 4];
    let mut rp = Vec::with_capacity(3 * f + 4);
    let mut rm = Vec::with_capacity(3 * f + 4);
    let scale = 1.0 + y.norm();
    'outer: while iterations < opts.max_iter {
        interrupt::check()?;
        iterations += 1;
        if !seg.jacobian(&p, &y, &v, sqrt_lambda, scale, &mut jac, &mut rp, &mut rm) {
            break 'outer;
        }
        let mut jtj = Mat8::zeros();
        let mut jtr = Vec8::zeros();
        for (row, e) in jac.iter().zip(&res) {
            jtj += row * row.transpose();
            jtr += row * *e;
        }
        let mut improved = false;
        for _ in 0..30 {
            let mut a = jtj;
            for i in 0..NP {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&(-jtr))) else {
                lambda *= 10.0;
                continue;
            };
            let (pn, yn, vn) = apply_step(&p, &y, &v, &step);
            if seg.residuals(&pn, &yn, &vn, sqrt_lambda, &mut rp) {
                let cn = cost_of(&rp);
                if cn.is_finite() && cn <= cost {
                    let rel = (cost - cn) / cost.max(f64::MIN_POSITIVE);
                    p = pn;
                    y = yn;
                    v = vn;
                    cost = cn;
                    std::mem::swap(&mut res, &mut rp);
                    lambda = (lambda * 0.3).max(1e-12);
                    improved = true;
                    if rel < opts.tol {
                        converged = true;
                        break 'outer;
                    }
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !improved {
            converged = true; // no step lowers the cost: a numerical minimum
            break;
        }
    }
    // Spread, uncertainty (Gauss–Newton covariance at the solution).
    let dev: Vec<f64> = (0..f)
        .map(|i| Vector3::new(res[3 * i], res[3 * i + 1], res[3 * i + 2]).norm())
        .collect();
    let data_ss: f64 = dev.iter().map(|x| x * x).sum();
    let dof = (2 * f).saturating_sub(NP).max(1) as f64;
    let sigma2 = data_ss / dof;
    let h = sigma2.sqrt();
    let mut jtj = Mat8::from_element(f64::NAN);
    if seg.jacobian(&p, &y, &v, sqrt_lambda, scale, &mut jac, &mut rp, &mut rm) {
        jtj = Mat8::zeros();
        for row in &jac {
            jtj += row * row.transpose();
        }
    }
    let cov = jtj
        .try_inverse()
        .map(|m| m * sigma2)
        .filter(|m| m.iter().all(|x| x.is_finite()))
        .unwrap_or_else(|| Mat8::from_element(f64::INFINITY));
    let sd = |i: usize| cov[(i, i)].max(0.0).sqrt();
    Ok(GazeCalibration {
        p,
        v,
        y,
        h,
        p_std: Vector3::new(sd(0), sd(1), sd(2)),
        y_std: Vector3::new(sd(3), sd(4), sd(5)),
        v_std: ((cov[(6, 6)].max(0.0) + cov[(7, 7)].max(0.0)) / 2.0).sqrt(),
        h_rel_std: 1.0 / (2.0 * dof).sqrt(),
        residuals: dev,
        iterations,
        converged,
    })
}

/// World gaze rays of a calibrated wearer: `p_i = R_iᵀ p + C_i`, `v_i = R_iᵀ v`.
pub fn gaze_rays(
    r: &[Matrix3<f64>],
    c: &[Vector3<f64>],
    p: &Vector3<f64>,
    v: &Vector3<f64>,
) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    r.iter()
        .zip(c)
        .map(|(ri, ci)| (ri.transpose() * p + ci, ri.transpose() * v))
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A fixation segment with exact truth: eye offset `p`, direction `v` (camera frame),
    /// point `y`; the eye moves ±0.3 m side to side and ±0.4 m back and forth (the thesis'
    /// range of motion: the depth change is what separates the eye offset from the
    /// direction) and the head rolls ±15°; the primary ray
    /// misses `y` by the Sec 3.1 deviation m ~ N(0, h²) per axis.
    fn segment(
        seed: u64,
        f: usize,
        h: f64,
        p: Vector3<f64>,
        v: Vector3<f64>,
        y: Vector3<f64>,
    ) -> (Vec<Matrix3<f64>>, Vec<Vector3<f64>>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut rs = Vec::new();
        let mut cs = Vec::new();
        for i in 0..f {
            let t = i as f64 / f as f64 * std::f64::consts::TAU;
            let eye = Vector3::new(
                0.3 * t.sin(),
                0.15 * (2.0 * t).sin(),
                -0.4 * (2.0 * t).cos(),
            );
            let u = (y - eye).normalize();
            let (a, b) = tangent_basis(&u);
            let n = |rng: &mut ChaCha8Rng| {
                // Box–Muller
                let u1: f64 = rng.random::<f64>().max(1e-300);
                let u2: f64 = rng.random();
                (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
            };
            let m = a * (h * n(&mut rng)) + b * (h * n(&mut rng));
            // Primary direction w with (I − wwᵀ)u/(uᵀw) ≈ m: w = normalize(u − m).
            let w = (u - m).normalize();
            let roll = rng.random_range(-0.26..0.26);
            let align = Rotation3::rotation_between(&v, &w).unwrap_or_else(Rotation3::identity);
            let spin = Rotation3::from_axis_angle(&Unit::new_normalize(w), roll);
            let world_from_cam = (spin * align).into_inner();
            rs.push(world_from_cam.transpose());
            cs.push(eye - world_from_cam * p);
        }
        (rs, cs)
    }

    fn truth() -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let p = Vector3::new(0.01, 0.08, -0.06);
        let v = Vector3::new(0.05, 0.08, 1.0).normalize();
        let y = Vector3::new(0.2, -0.1, 1.2);
        (p, v, y)
    }

    #[test]
    fn recovers_offset_direction_and_spread() {
        let (p, v, y) = truth();
        let pn = normal_part(&p, &v);
        for seed in 0..5 {
            let h = 0.01;
            let (rs, cs) = segment(seed, 300, h, p, v, y);
            let cal = calibrate_gaze(&rs, &cs, &CalibrationOptions::default()).unwrap();
            let ang = cal.v.dot(&v).clamp(-1.0, 1.0).acos();
            let perr = (cal.p - pn).norm();
            // Measured over seeds 0–4 (h = 0.01, 300 frames): p error 3–10 mm (reported
            // std ≈ 7 mm), v error 0.04–0.17° (std ≈ 0.15°), h within 11 %.
            assert!(perr < 0.02, "seed {seed}: p {:?} ({perr} m off)", cal.p);
            assert!(
                ang.to_degrees() < 0.5,
                "seed {seed}: v off by {}°",
                ang.to_degrees()
            );
            assert!((cal.h / h - 1.0).abs() < 0.15, "seed {seed}: h {}", cal.h);
            assert!((cal.y - y).norm() < 0.03, "seed {seed}: y {:?}", cal.y);
            assert!(cal.p.dot(&cal.v).abs() < 1e-3, "p not on the normal plane");
            assert!(cal.converged);
            // The reported uncertainty is honest: errors within 3.5σ, σ not inflated.
            for k in 0..3 {
                assert!(
                    (cal.p[k] - pn[k]).abs() < 3.5 * cal.p_std[k] + 1e-4,
                    "seed {seed}: p[{k}] error {} vs std {}",
                    cal.p[k] - pn[k],
                    cal.p_std[k]
                );
            }
            assert!(cal.p_std.norm() < 0.02 && cal.v_std < 0.5f64.to_radians());
            assert!(
                ang < 3.5 * cal.v_std,
                "seed {seed}: v error {ang} vs std {}",
                cal.v_std
            );
        }
    }

    #[test]
    fn the_optimisation_moves_away_from_the_initialisation() {
        // The initialisation p = 0, v = z is 10 cm and 5.4° away; removing the
        // Levenberg–Marquardt stage would fail both checks.
        let (p, v, y) = truth();
        let (rs, cs) = segment(3, 200, 0.01, p, v, y);
        let cal = calibrate_gaze(&rs, &cs, &CalibrationOptions::default()).unwrap();
        assert!(cal.iterations > 1);
        let pn = normal_part(&p, &v);
        assert!((cal.p - pn).norm() < 0.25 * pn.norm());
        let ang = |a: &Vector3<f64>, b: &Vector3<f64>| a.dot(b).clamp(-1.0, 1.0).acos();
        assert!(ang(&cal.v, &v) < 0.2 * ang(&Vector3::z(), &v));
    }

    fn normal_part(p: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
        p - v * p.dot(v)
    }

    #[test]
    fn noise_free_is_exact() {
        let (p, v, y) = truth();
        let (rs, cs) = segment(7, 60, 0.0, p, v, y);
        let opts = CalibrationOptions {
            lambda_c: 0.0,
            ..Default::default()
        };
        let cal = calibrate_gaze(&rs, &cs, &opts).unwrap();
        assert!((cal.p - normal_part(&p, &v)).norm() < 1e-6, "{:?}", cal.p);
        assert!((cal.v - v).norm() < 1e-7);
        assert!(cal.h < 1e-6);
        let (pw, vw) = gaze_rays(&rs, &cs, &cal.p, &cal.v);
        for (pi, vi) in pw.iter().zip(&vw) {
            let d = y - pi;
            assert!((d - vi * d.dot(vi)).norm() < 1e-6);
        }
    }

    #[test]
    fn still_head_is_degenerate_and_bad_input_is_refused() {
        let r = vec![Matrix3::identity(); 10];
        let c = vec![Vector3::zeros(); 10];
        assert!(matches!(
            calibrate_gaze(&r, &c, &CalibrationOptions::default()),
            Err(Error::Degenerate(_))
        ));
        assert!(matches!(
            calibrate_gaze(&r[..3], &c[..3], &CalibrationOptions::default()),
            Err(Error::InvalidInput { .. })
        ));
        let mut cn = c.clone();
        cn[2].x = f64::NAN;
        assert!(matches!(
            calibrate_gaze(&r, &cn, &CalibrationOptions::default()),
            Err(Error::InvalidInput { .. })
        ));
        let bad = CalibrationOptions {
            lambda_c: -1.0,
            ..Default::default()
        };
        assert!(matches!(
            calibrate_gaze(&r, &c, &bad),
            Err(Error::InvalidInput { .. })
        ));
    }
}
