//! The social saliency field of Eq 6.1–6.4: a cone-shaped Gaussian kernel about every gaze
//! ray, averaged over the rays of a frame.

use super::GazeRays;
use crate::error::{ensure_finite, Error, Result};
use crate::geometry::perspective_distance;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// `1/√(2π)`, the normalisation of the kernel of Eq 6.1 (divided by `h`).
pub(crate) const INV_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// Squared normalised distances `‖d/h‖²` above this contribute `e^{-50}` or less of a
/// ray's peak value; they are treated as zero, which lets the kernels skip the `exp`.
pub(crate) const Q_CUTOFF: f64 = 100.0;

/// `f_i(x)` of Eq 6.1 for ray `i`: `exp(−½‖d/h‖²)/(h√(2π))` with the perspective distance
/// vector `d` of Eq 6.2; zero behind the eye (`d = ∞`). At the eye itself `d = 0`
/// (see [`perspective_distance`]), so `f_i(p_i) = 1/(h_i√(2π))`.
#[inline]
pub fn ray_density(rays: &GazeRays, i: usize, x: &Vector3<f64>) -> f64 {
    let h = rays.h[i];
    match perspective_distance(&rays.p[i], &rays.v[i], x) {
        None => 0.0,
        Some(d) => {
            let q = d.norm_squared() / (h * h);
            if q > Q_CUTOFF {
                0.0
            } else {
                (-0.5 * q).exp() * INV_SQRT_2PI / h
            }
        }
    }
}

/// The social saliency `f(x) = (1/N) Σᵢ fᵢ(x)` (Eq 6.3–6.4).
#[inline]
pub fn saliency(rays: &GazeRays, x: &Vector3<f64>) -> f64 {
    let n = rays.len();
    let mut sum = 0.0;
    for i in 0..n {
        // Same value as `ray_density`, without divisions in the common case.
        let w = x - rays.p[i];
        let s = w.dot(&rays.v[i]);
        if s <= 0.0 {
            if s == 0.0 && w.norm_squared() == 0.0 {
                sum += rays.peak[i];
            }
            continue;
        }
        let (mut s2, mut w2) = (s * s, w.norm_squared());
        if !(s2.is_finite() && w2.is_finite()) {
            // A point beyond 1e154 m: the ratio below depends only on the direction of
            // `w`, so scale it down instead of comparing infinities (which read as 0).
            let k = 1.0 / w.amax();
            s2 = (s * k) * (s * k);
            w2 = (w * k).norm_squared();
        }
        let pp_h = (w2 - s2).max(0.0) * rays.inv_h2[i];
        if pp_h > Q_CUTOFF * s2 {
            continue;
        }
        sum += (-0.5 * pp_h / s2).exp() * rays.peak[i];
    }
    sum / n as f64
}

/// The field at many points, in parallel. Errors if a point is not finite.
pub fn saliency_at(rays: &GazeRays, points: &[Vector3<f64>]) -> Result<Vec<f64>> {
    for x in points {
        ensure_finite("points", x.as_slice())?;
    }
    Ok(points.par_iter().map(|x| saliency(rays, x)).collect())
}

/// The Hessian of the field, `∇²f(x)`, in closed form. With `w = x − p`, `s = wᵀv` and
/// `q = (‖w‖²/s² − 1)/h²` (so that `fᵢ = e^{−q/2}/(h√2π)`), `∇q = 2(w − (‖w‖²/s) v)/(h²s²)`
/// and `∇²q = (2/h²)(I/s² − 2(w vᵀ + v wᵀ)/s³ + 3‖w‖² v vᵀ/s⁴)`, and
/// `∇²fᵢ = fᵢ(¼ ∇q ∇qᵀ − ½ ∇²q)`. Used to orient the confidence ellipsoid of a charge.
pub fn ray_hessian(rays: &GazeRays, x: &Vector3<f64>) -> Matrix3<f64> {
    let n = rays.len();
    let mut total = Matrix3::zeros();
    for i in 0..n {
        let (p, v, h) = (&rays.p[i], &rays.v[i], rays.h[i]);
        let w = x - p;
        let s = w.dot(v);
        if s <= 0.0 {
            continue;
        }
        let ww = w.norm_squared();
        let q = (ww / (s * s) - 1.0).max(0.0) / (h * h);
        if q > Q_CUTOFF {
            continue;
        }
        let fi = (-0.5 * q).exp() * INV_SQRT_2PI / h;
        let h2 = h * h;
        let grad = (w - v * (ww / s)) * (2.0 / (h2 * s * s));
        let hq = (Matrix3::identity() / (s * s)
            - (w * v.transpose() + v * w.transpose()) * (2.0 / (s * s * s))
            + v * v.transpose() * (3.0 * ww / (s * s * s * s)))
            * (2.0 / h2);
        total += (grad * grad.transpose() * 0.25 - hq * 0.5) * fi;
    }
    total / n as f64
}

/// The largest grid [`Grid::new`] accepts: 2²⁸ samples, 2 GiB of float64.
pub const MAX_GRID_CELLS: usize = 1 << 28;

/// A regular grid of sample points: axis `a` has `shape[a]` points from `lo[a]` to `hi[a]`
/// inclusive (like `numpy.linspace`); an axis with one point sits at `lo[a]`.

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    pub lo: [f64; 3],
    pub hi: [f64; 3],
    pub shape: [usize; 3],
}

impl Grid {
    /// Validates the bounds (finite, `lo ≤ hi`) and shape (every axis ≥ 1).
    pub fn new(lo: [f64; 3], hi: [f64; 3], shape: [usize; 3]) -> Result<Self> {
        ensure_finite("lo", &lo)?;
        ensure_finite("hi", &hi)?;
        if (0..3).any(|a| hi[a] < lo[a]) {
            return Err(Error::invalid(
                "hi",
                format!("{hi:?} is below lo {lo:?} on some axis"),
            ));
        }
        if shape.contains(&0) {
            return Err(Error::invalid(
                "shape",
                format!("{shape:?} has an empty axis"),
            ));
        }
        let cells = shape
            .iter()
            .try_fold(1usize, |acc, &n| acc.checked_mul(n))
            .filter(|&c| c <= MAX_GRID_CELLS);
        if cells.is_none() {
            return Err(Error::invalid(
                "shape",
                format!(
                    "{shape:?} asks for more than {MAX_GRID_CELLS} samples ({} GiB of float64)",
                    (MAX_GRID_CELLS * 8) >> 30
                ),
            ));
        }
        Ok(Grid { lo, hi, shape })
    }

    /// Coordinate of sample `k` on axis `a`.
    #[inline]
    pub fn coord(&self, a: usize, k: usize) -> f64 {
        if self.shape[a] == 1 {
            self.lo[a]
        } else {
            self.lo[a] + (self.hi[a] - self.lo[a]) * k as f64 / (self.shape[a] - 1) as f64
        }
    }
}

/// The field sampled on a grid, in C order (last axis fastest), parallel over the first
/// two axes.
pub fn saliency_grid(rays: &GazeRays, grid: &Grid) -> Result<Vec<f64>> {
    let [nx, ny, nz] = grid.shape;
    let zs: Vec<f64> = (0..nz).map(|k| grid.coord(2, k)).collect();
    let mut out = vec![0.0; nx * ny * nz];
    out.par_chunks_mut(nz)
        .enumerate()
        .try_for_each(|(row, dst)| {
            // One check per grid row (nz samples): Ctrl-C stops a large grid promptly.
            crate::interrupt::check()?;
            let x = grid.coord(0, row / ny);
            let y = grid.coord(1, row % ny);
            for (k, z) in zs.iter().enumerate() {
                dst[k] = saliency(rays, &Vector3::new(x, y, *z));
            }
            Ok(())
        })?;
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn two_rays() -> GazeRays {
        let p = vec![Vector3::new(-2.0, 0.0, 0.0), Vector3::new(0.0, -3.0, 0.5)];
        let t = Vector3::new(0.5, 0.5, 0.2);
        let v = p.iter().map(|p| (t - p).normalize()).collect();
        GazeRays::new(p, v, vec![0.1, 0.2], None).unwrap()
    }

    #[test]
    fn kernel_matches_equation_and_is_a_cone() {
        let r = two_rays();
        let (p, v) = (r.p[0], r.v[0]);
        // On the ray: the peak 1/(h√2π), whatever the depth.
        for s in [0.1, 1.0, 10.0] {
            assert_relative_eq!(
                ray_density(&r, 0, &(p + v * s)),
                INV_SQRT_2PI / 0.1,
                epsilon = 1e-12
            );
        }
        // Off the ray by a perpendicular offset e at depth s: exp(-½(e/s/h)²)/(h√2π).
        let e = v.cross(&Vector3::z()).normalize();
        for s in [0.5, 2.0, 4.0] {
            let x = p + v * s + e * (0.1 * s);
            assert_relative_eq!(
                ray_density(&r, 0, &x),
                (-0.5f64).exp() * INV_SQRT_2PI / 0.1,
                epsilon = 1e-12
            );
        }
        // Behind the eye: zero. At the eye: the peak.
        assert_eq!(ray_density(&r, 0, &(p - v)), 0.0);
        assert_relative_eq!(ray_density(&r, 0, &p), INV_SQRT_2PI / 0.1);
        // At the eye, off the axis in the eye plane: infinitely far in angle.
        assert_eq!(ray_density(&r, 0, &(p + e)), 0.0);
        // Average over rays (Eq 6.3).
        let x = Vector3::new(0.3, 0.1, 0.0);
        assert_relative_eq!(
            saliency(&r, &x),
            0.5 * (ray_density(&r, 0, &x) + ray_density(&r, 1, &x)),
            max_relative = 1e-12
        );
        // A cone: a point 1e200 m out along a direction scores as one 10 m out along it
        // (the squares used to overflow and the far point scored the peak).
        let d = (v + e * 0.1).normalize();
        let (near, far) = (
            saliency(&r, &(p + d * 10.0)),
            saliency(&r, &(p + d * 1e200)),
        );
        assert!(near > 0.0);
        assert_relative_eq!(far, near, max_relative = 1e-3);
    }

    #[test]
    fn hessian_matches_finite_differences() {
        let r = two_rays();
        let x = Vector3::new(0.45, 0.55, 0.25);
        let hs = ray_hessian(&r, &x);
        let eps = 1e-4;
        for a in 0..3 {
            for b in 0..3 {
                let (ea, eb) = (Vector3::ith(a, eps), Vector3::ith(b, eps));
                let fd = (saliency(&r, &(x + ea + eb))
                    - saliency(&r, &(x + ea - eb))
                    - saliency(&r, &(x - ea + eb))
                    + saliency(&r, &(x - ea - eb)))
                    / (4.0 * eps * eps);
                assert_relative_eq!(hs[(a, b)], fd, epsilon = 1e-4 * hs.norm());
            }
        }
    }

    #[test]
    fn grid_is_c_ordered_linspace() {
        let r = two_rays();
        let g = Grid::new([-1.0, -1.0, 0.0], [1.0, 2.0, 0.0], [3, 4, 1]).unwrap();
        let vals = saliency_grid(&r, &g).unwrap();
        assert_eq!(vals.len(), 12);
        for i in 0..3 {
            for j in 0..4 {
                let x = Vector3::new(-1.0 + i as f64, -1.0 + j as f64, 0.0);
                assert_eq!(vals[i * 4 + j], saliency(&r, &x));
            }
        }
        assert!(Grid::new([0.0; 3], [1.0, -1.0, 1.0], [2, 2, 2]).is_err());
        assert!(Grid::new([0.0; 3], [1.0; 3], [2, 0, 2]).is_err());
        assert!(Grid::new([0.0; 3], [1.0; 3], [100_000; 3]).is_err());
        assert!(Grid::new([0.0; 3], [1.0; 3], [usize::MAX, 2, 2]).is_err());
        assert!(saliency_at(&r, &[Vector3::new(f64::NAN, 0.0, 0.0)]).is_err());
    }

    #[test]
    fn bad_rays_are_refused() {
        let p = vec![Vector3::zeros()];
        let v = vec![Vector3::z()];
        assert!(GazeRays::new(vec![], vec![], vec![], None).is_err());
        assert!(GazeRays::new(
            p.clone(),
            vec![Vector3::new(0.0, 0.0, 2.0)],
            vec![0.1],
            None
        )
        .is_err());
        assert!(GazeRays::new(p.clone(), v.clone(), vec![0.0], None).is_err());
        assert!(GazeRays::new(p.clone(), v.clone(), vec![-0.1], None).is_err());
        assert!(GazeRays::new(
            vec![Vector3::new(f64::NAN, 0.0, 0.0)],
            v.clone(),
            vec![0.1],
            None
        )
        .is_err());
        assert!(GazeRays::new(p.clone(), v.clone(), vec![0.1, 0.2], None).is_err());
        assert!(GazeRays::new(p.clone(), v.clone(), vec![0.1], Some(vec![1, 2])).is_err());
        let ok = GazeRays::new(p, v, vec![0.1], Some(vec![42])).unwrap();
        assert_eq!(ok.ids(), &[42]);
    }
}
