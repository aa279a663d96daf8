//! Multi-view triangulation: linear DLT (Hartley & Zisserman, Sec 12.2) on normalised
//! coordinates, then Levenberg–Marquardt on the reprojection error with an analytic
//! Jacobian. Batched over points and parallel with rayon.

use super::camera::Camera;
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Matrix4, SymmetricEigen, Vector2, Vector3};
use rayon::prelude::*;

/// Rays closer to parallel than this (radians, largest pairwise angle) cannot be
/// triangulated.
pub const MIN_TRIANGULATION_ANGLE: f64 = 1e-7;

/// Options for the Levenberg–Marquardt refinement.
#[derive(Debug, Clone, Copy)]
pub struct LmOptions {
    pub max_iterations: usize,
    /// Stop when the relative decrease of the cost falls below this.
    pub rel_tol: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iterations: 50,
            rel_tol: 1e-12,
        }
    }
}

/// The result for one point.
#[derive(Debug, Clone, Copy)]
pub struct Triangulated {
    /// World position.
    pub x: Vector3<f64>,
    /// Number of views that observed the point.
    pub views: usize,
    /// Reprojection RMS in pixels of the linear solution.
    pub rms_linear: f64,
    /// Reprojection RMS in pixels after refinement (equal to `rms_linear` without it).
    pub rms: f64,
    /// Whether refinement met its tolerance (true when not refined).
    pub converged: bool,
}

fn reprojection_rms(x: &Vector3<f64>, views: &[(&Camera, Vector2<f64>)]) -> f64 {
    let s: f64 = views
        .iter()
        .map(|(c, u)| (c.project(x).0 - u).norm_squared())
        .sum();
    (s / views.len() as f64).sqrt()
}

/// Linear triangulation of one point from `(camera, pixel)` pairs (at least two).
pub fn triangulate_dlt(views: &[(&Camera, Vector2<f64>)]) -> Result<Vector3<f64>> {
    if views.len() < 2 {
        return Err(Error::degenerate(format!(
            "a point needs at least 2 views to be triangulated, it has {}",
            views.len()
        )));
    }
    // Parallel-ray check on unit back-projected directions.
    let dirs: Vec<Vector3<f64>> = views.iter().map(|(c, u)| c.ray_direction(u)).collect();
    let mut max_angle: f64 = 0.0;
    for i in 0..dirs.len() {
        for j in i + 1..dirs.len() {
            max_angle = max_angle.max(dirs[i].cross(&dirs[j]).norm().atan2(dirs[i].dot(&dirs[j])));
        }
    }
    // Similarity normalisation of the world: centre and scale the camera centres.
    let n = views.len() as f64;
    let mu = views.iter().map(|(c, _)| c.c).sum::<Vector3<f64>>() / n;
    let mut s = views.iter().map(|(c, _)| (c.c - mu).norm()).sum::<f64>() / n;
    if s <= f64::EPSILON {
        s = 1.0;
    }
    // One centre for every view: rays in different directions meet only there, so the
    // linear solution would be that centre (a point at depth 0), not the point.
    let baseline = views
        .iter()
        .map(|(c, _)| (c.c - mu).norm())
        .fold(0.0, f64::max);
    if baseline <= f64::EPSILON * mu.norm().max(1.0) {
        return Err(Error::degenerate(
            "all views share one camera centre: no baseline to triangulate from",
        ));
    }
    if max_angle < MIN_TRIANGULATION_ANGLE {
        return Err(Error::degenerate(format!(
            "the rays are parallel (largest angle between them {max_angle:.1e} rad): the point is at infinity"
        )));
    }
    let mut ata = Matrix4::<f64>::zeros();
    for (c, u) in views {
        let m = c.k_inv * Vector3::new(u.x, u.y, 1.0);
        let cc = (c.c - mu) / s;
        let r = &c.r;
        for (coord, row) in [(m.x, 0usize), (m.y, 1usize)] {
            let a = Vector3::new(
                coord * r[(2, 0)] - r[(row, 0)],
                coord * r[(2, 1)] - r[(row, 1)],
                coord * r[(2, 2)] - r[(row, 2)],
            );
            let row4 = nalgebra::Vector4::new(a.x, a.y, a.z, -a.dot(&cc));
            ata += row4 * row4.transpose();
        }
    }
    let eig = SymmetricEigen::new(ata);
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .fold(
            (0, f64::INFINITY),
            |acc, (i, &v)| {
                if v < acc.1 {
                    (i, v)
                } else {
                    acc
                }
            },
        );
    let h = eig.eigenvectors.column(imin);
    if h[3].abs() < 1e-12 * h.norm() {
        return Err(Error::degenerate(
            "the linear solution is a point at infinity",
        ));
    }
    let y = Vector3::new(h[0] / h[3], h[1] / h[3], h[2] / h[3]);
    Ok(y * s + mu)
}

/// Levenberg–Marquardt on the summed squared reprojection error of one point.
/// Returns the refined point and whether the tolerance was met.
pub fn refine_point(
    x0: Vector3<f64>,
    views: &[(&Camera, Vector2<f64>)],
    opts: &LmOptions,
) -> (Vector3<f64>, bool) {
    let cost_of = |x: &Vector3<f64>| -> f64 {
        views
            .iter()
            .map(|(c, u)| {
                let (p, _) = c.project(x);
                (p - u).norm_squared()
            })
            .sum()
    };
    let mut x = x0;
    let mut cost = cost_of(&x);
    if !cost.is_finite() {
        return (x0, false);
    }
    let mut lambda = 1e-3;
    for _ in 0..opts.max_iterations {
        let mut jtj = Matrix3::<f64>::zeros();
        let mut jtr = Vector3::<f64>::zeros();
        for (c, u) in views {
            let kr = c.k * c.r;
            let h = kr * (x - c.c);
            let (pu, pv) = (h.x / h.z, h.y / h.z);
            let iz = 1.0 / h.z;
            let ju = (kr.row(0) - pu * kr.row(2)) * iz;
            let jv = (kr.row(1) - pv * kr.row(2)) * iz;
            let (ru, rv) = (pu - u.x, pv - u.y);
            jtj += ju.transpose() * ju + jv.transpose() * jv;
            jtr += ju.transpose() * ru + jv.transpose() * rv;
        }
        if jtr.amax() <= 1e-15 * (1.0 + cost.sqrt()) {
            return (x, true);
        }
        let mut improved = false;
        for _ in 0..20 {
            let mut a = jtj;
            for i in 0..3 {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&(-jtr))) else {
                lambda *= 10.0;
                continue;
            };
            let xn = x + step;
            let cn = cost_of(&xn);
            if cn.is_finite() && cn <= cost {
                let rel = (cost - cn) / cost.max(f64::MIN_POSITIVE);
                x = xn;
                cost = cn;
                lambda = (lambda * 0.3).max(1e-12);
                improved = true;
                if rel < opts.rel_tol || step.norm() <= 1e-14 * (1.0 + x.norm()) {
                    return (x, true);
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            // No step decreases the cost: we are at a (numerical) minimum.
            return (x, true);
        }
    }
    (x, false)
}

/// Triangulates one point from its pixels in `cameras` (`pixels[v]`, `None` = not seen).
pub fn triangulate_point(
    cameras: &[Camera],
    pixels: &[Option<Vector2<f64>>],
    refine: bool,
    opts: &LmOptions,
) -> Result<Triangulated> {
    if cameras.len() != pixels.len() {
        return Err(Error::invalid(
            "x",
            format!("{} views given for {} cameras", pixels.len(), cameras.len()),
        ));
    }
    let views: Vec<(&Camera, Vector2<f64>)> = cameras
        .iter()
        .zip(pixels)
        .filter_map(|(c, p)| p.map(|p| (c, p)))
        .collect();
    let x_lin = triangulate_dlt(&views)?;
    let rms_linear = reprojection_rms(&x_lin, &views);
    let (x, converged) = if refine {
        refine_point(x_lin, &views, opts)
    } else {
        (x_lin, true)
    };
    let rms = reprojection_rms(&x, &views);
    Ok(Triangulated {
        x,
        views: views.len(),
        rms_linear,
        rms,
        converged,
    })
}

/// Triangulates `n` points at once. `pixels` is row-major `(n, V, 2)` with NaN rows for
/// views that did not see a point. Each point gets its own `Result`, so one degenerate
/// point does not spoil a batch. Parallel over points.
pub fn triangulate_batch(
    cameras: &[Camera],
    pixels: &[f64],
    n: usize,
    refine: bool,
    opts: &LmOptions,
) -> Result<Vec<Result<Triangulated>>> {
    let v = cameras.len();
    if pixels.len() != n * v * 2 {
        return Err(Error::invalid(
            "x",
            format!("expected {n}×{v}×2 values, got {}", pixels.len()),
        ));
    }
    if v == 0 {
        return Err(Error::invalid("cameras", "no cameras"));
    }
    // Ctrl-C: points not yet started are skipped once a stop is requested.
    let out: Vec<Result<Triangulated>> = pixels
        .par_chunks(v * 2)
        .map(|row| {
            crate::interrupt::check()?;
            let obs: Vec<Option<Vector2<f64>>> = row
                .chunks(2)
                .map(|p| {
                    if p[0].is_finite() && p[1].is_finite() {
                        Some(Vector2::new(p[0], p[1]))
                    } else {
                        None
                    }
                })
                .collect();
            triangulate_point(cameras, &obs, refine, opts)
        })
        .collect();
    crate::interrupt::check()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    pub(crate) fn ring_cameras(v: usize) -> Vec<Camera> {
        let k = Matrix3::new(700.0, 0.0, 320.0, 0.0, 700.0, 240.0, 0.0, 0.0, 1.0);
        (0..v)
            .map(|i| {
                let a = i as f64 * 0.5;
                let c = Vector3::new(5.0 * a.sin(), 0.3 * i as f64, -5.0 * a.cos());
                // Look at the origin.
                let z = (-c).normalize();
                let x = Vector3::y().cross(&z).normalize();
                let y = z.cross(&x);
                let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
                Camera::new(k, r, c, i).unwrap()
            })
            .collect()
    }

    #[test]
    fn noise_free_is_exact() {
        let cams = ring_cameras(4);
        let x = Vector3::new(0.2, -0.4, 0.7);
        let px: Vec<_> = cams.iter().map(|c| Some(c.project(&x).0)).collect();
        let t = triangulate_point(&cams, &px, false, &LmOptions::default()).unwrap();
        assert_relative_eq!(t.x, x, epsilon = 1e-9);
        let t = triangulate_point(&cams, &px, true, &LmOptions::default()).unwrap();
        assert_relative_eq!(t.x, x, epsilon = 1e-10);
        assert!(t.rms < 1e-8);
    }

    #[test]
    fn refinement_lowers_reprojection_error() {
        let cams = ring_cameras(5);
        let x = Vector3::new(0.2, -0.4, 0.7);
        let noise = [0.7, -1.1, 0.4, 0.9, -0.8, 1.3, -0.2, 0.5, 1.0, -0.6];
        let px: Vec<_> = cams
            .iter()
            .enumerate()
            .map(|(i, c)| Some(c.project(&x).0 + Vector2::new(noise[2 * i], noise[2 * i + 1])))
            .collect();
        let t = triangulate_point(&cams, &px, true, &LmOptions::default()).unwrap();
        assert!(t.converged);
        // Strictly lower: the DLT minimises an algebraic error, not the reprojection error.
        assert!(
            t.rms < 0.999 * t.rms_linear,
            "{} vs {}",
            t.rms,
            t.rms_linear
        );
        let lin = triangulate_point(&cams, &px, false, &LmOptions::default()).unwrap();
        assert_eq!(lin.rms, t.rms_linear);
        assert!((t.x - x).norm() < 0.02);
    }

    #[test]
    fn degenerate_cases() {
        let cams = ring_cameras(3);
        let x = Vector3::new(0.2, -0.4, 0.7);
        let one = vec![Some(cams[0].project(&x).0), None, None];
        assert!(matches!(
            triangulate_point(&cams, &one, true, &LmOptions::default()),
            Err(Error::Degenerate(_))
        ));
        let same = vec![cams[0]; 3];
        let px: Vec<_> = same.iter().map(|c| Some(c.project(&x).0)).collect();
        assert!(matches!(
            triangulate_point(&same, &px, true, &LmOptions::default()),
            Err(Error::Degenerate(_))
        ));
        // One centre, turned heads (a camera that only rotates), noisy pixels: the rays
        // differ in direction by more than the parallel test allows but meet only at the
        // centre, which the linear solution used to return as the point.
        let turned: Vec<Camera> = cams
            .iter()
            .map(|c| Camera::new(c.k, c.r, cams[0].c, 0).unwrap())
            .collect();
        let noise = [
            Vector2::new(0.5, -0.3),
            Vector2::new(-0.4, 0.6),
            Vector2::new(0.2, 0.7),
        ];
        let px: Vec<_> = turned
            .iter()
            .zip(noise)
            .map(|(c, e)| Some(c.project(&x).0 + e))
            .collect();
        match triangulate_point(&turned, &px, true, &LmOptions::default()) {
            Err(Error::Degenerate(m)) => assert!(m.contains("one camera centre"), "{m}"),
            other => panic!("expected Degenerate, got {other:?}"),
        }
    }

    #[test]
    fn batch_reports_per_point() {
        let cams = ring_cameras(3);
        let x = Vector3::new(0.1, 0.1, 0.1);
        let mut px = Vec::new();
        for c in &cams {
            let p = c.project(&x).0;
            px.extend([p.x, p.y]);
        }
        px.extend([f64::NAN, f64::NAN, 1.0, 1.0, f64::NAN, f64::NAN]);
        let out = triangulate_batch(&cams, &px, 2, true, &LmOptions::default()).unwrap();
        assert!(out[0].is_ok());
        assert!(out[1].is_err());
    }
}
