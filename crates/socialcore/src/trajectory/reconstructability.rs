//! Reconstructability η (Eq 5.16): how poorly the `K` basis functions describe the camera
//! trajectory relative to how poorly they describe the point trajectory,
//! `η = ‖Θ^⊥ β_C^⊥‖ / ‖Θ^⊥ β_X^⊥‖`. The null components are the residuals of projecting each
//! coordinate onto `col(Θ)` (Θ = blkdiag(θ, θ, θ), App B.1). By Theorem 3 the least-squares
//! solution tends to the truth as η → ∞. An analysis tool: it needs the true trajectory.

use crate::basis::DctSpan;
use crate::error::{Error, Result};
use nalgebra::{DMatrix, Vector3};

fn check_trajectory(arg: &str, x: &[Vector3<f64>]) -> Result<()> {
    if x.is_empty() {
        return Err(Error::invalid(arg, "is empty"));
    }
    if let Some(i) = x.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(Error::invalid(arg, format!("row {i} is not finite")));
    }
    Ok(())
}

/// The orthonormal basis of `col(θ)` at the given times (uniform `0, 1, …, F−1` when
/// `None`), `θ` the first `k` DCT functions on the span of the times.
fn span_basis(f: usize, times: Option<&[f64]>, k: usize) -> Result<DMatrix<f64>> {
    if k == 0 || k > f {
        return Err(Error::invalid(
            "k",
            format!("must be between 1 and the number of frames {f}, got {k}"),
        ));
    }
    let uniform: Vec<f64>;
    let t = match times {
        Some(t) => {
            if t.len() != f {
                return Err(Error::invalid(
                    "times",
                    format!("has {} entries for {f} frames", t.len()),
                ));
            }
            t
        }
        None => {
            uniform = (0..f).map(|i| i as f64).collect();
            &uniform
        }
    };
    let span = DctSpan::from_times(t)?;
    let theta = span.matrix(t, k)?;
    let svd = theta.clone().svd(true, false);
    let smax = svd.singular_values.max();
    let rank = svd
        .singular_values
        .iter()
        .filter(|&&s| s > smax * f as f64 * f64::EPSILON)
        .count();
    if rank < k {
        return Err(Error::invalid(
            "times",
            format!("the {k} basis functions are linearly dependent at these times (rank {rank})"),
        ));
    }
    svd.u
        .map(|u| u.columns(0, k).into_owned())
        .ok_or_else(|| Error::degenerate("SVD of the basis failed"))
}

fn residual_norm(q: &DMatrix<f64>, x: &[Vector3<f64>]) -> f64 {
    let f = x.len();
    let m = DMatrix::from_fn(f, 3, |i, c| x[i][c]);
    let r = &m - q * (q.transpose() * &m);
    r.norm()
}

/// `‖Θ^⊥ β^⊥‖`: the part of a trajectory `(F, 3)` that the first `k` DCT functions cannot
/// describe (`e_X` or `e_C` of Sec 5.2.2), in the trajectory's units.
pub fn null_residual(x: &[Vector3<f64>], times: Option<&[f64]>, k: usize) -> Result<f64> {
    check_trajectory("trajectory", x)?;
    let q = span_basis(x.len(), times, k)?;
    Ok(residual_norm(&q, x))
}

/// Reconstructability η (Eq 5.16) of a point trajectory `points (F, 3)` seen from camera
/// centres `centres (F, 3)` with `k` basis functions per coordinate; frame `i` at
/// `times[i]` (uniform when `None`).
///
/// Returns `0` when the basis describes the camera trajectory exactly (a still camera:
/// nothing to reconstruct from), and `+∞` when it describes the point trajectory exactly but
/// not the camera's.
pub fn reconstructability(
    points: &[Vector3<f64>],
    centres: &[Vector3<f64>],
    times: Option<&[f64]>,
    k: usize,
) -> Result<f64> {
    check_trajectory("points_true", points)?;
    check_trajectory("camera_centres", centres)?;
    if points.len() != centres.len() {
        return Err(Error::invalid(
            "camera_centres",
            format!(
                "has {} rows but points_true has {}",
                centres.len(),
                points.len()
            ),
        ));
    }
    let q = span_basis(points.len(), times, k)?;
    let e_x = residual_norm(&q, points);
    let e_c = residual_norm(&q, centres);
    // Round-off floor of a projection residual, relative to the trajectories' size.
    let size = points
        .iter()
        .chain(centres)
        .map(|p| p.norm_squared())
        .sum::<f64>()
        .sqrt();
    let floor = 1e-12 * size.max(f64::MIN_POSITIVE);
    if e_c <= floor {
        return Ok(0.0);
    }
    if e_x <= floor {
        return Ok(f64::INFINITY);
    }
    Ok(e_c / e_x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eta_grows_with_camera_null_component() {
        let f = 60;
        let pts: Vec<Vector3<f64>> = (0..f)
            .map(|i| {
                let t = i as f64 / f as f64;
                Vector3::new(t, (3.0 * t).sin(), 0.2 * (7.0 * t).cos())
            })
            .collect();
        // Smooth camera: low η. Jittered camera: a larger null component, larger η.
        let smooth: Vec<Vector3<f64>> = (0..f)
            .map(|i| {
                let a = i as f64 / f as f64;
                Vector3::new(5.0 * a.cos(), 1.0, 5.0 * a.sin())
            })
            .collect();
        let jitter: Vec<Vector3<f64>> = smooth
            .iter()
            .enumerate()
            .map(|(i, c)| c + Vector3::new(((i * 7919) % 13) as f64 * 0.1, 0.0, 0.0))
            .collect();
        let k = 5;
        let e1 = reconstructability(&pts, &smooth, None, k).unwrap();
        let e2 = reconstructability(&pts, &jitter, None, k).unwrap();
        assert!(e2 > 3.0 * e1, "{e1} {e2}");
        // η scales with the camera path and ignores a constant shift (in the span of Θ);
        // swapping camera and point inverts it.
        let scaled: Vec<_> = jitter
            .iter()
            .map(|c| 3.0 * c + Vector3::new(1.0, -2.0, 0.5))
            .collect();
        let e3 = reconstructability(&pts, &scaled, None, k).unwrap();
        assert!((e3 - 3.0 * e2).abs() < 1e-9 * e3, "{e3} vs 3 × {e2}");
        let swapped = reconstructability(&jitter, &pts, None, k).unwrap();
        assert!((swapped * e2 - 1.0).abs() < 1e-9);
        // A still camera: η = 0; a point inside the span: η = ∞.
        let still = vec![Vector3::new(1.0, 2.0, 3.0); f];
        assert_eq!(reconstructability(&pts, &still, None, k).unwrap(), 0.0);
        let line: Vec<Vector3<f64>> = (0..f).map(|_| Vector3::new(0.1, 0.2, 0.3)).collect();
        assert!(reconstructability(&line, &jitter, None, k)
            .unwrap()
            .is_infinite());
    }

    #[test]
    fn eta_is_similarity_invariant_and_checks_input() {
        let f = 30;
        let pts: Vec<Vector3<f64>> = (0..f)
            .map(|i| Vector3::new((i as f64 * 0.3).sin(), 0.1 * i as f64, 1.0))
            .collect();
        let cams: Vec<Vector3<f64>> = (0..f)
            .map(|i| Vector3::new(((i * 37) % 11) as f64, 2.0, -3.0))
            .collect();
        let e = reconstructability(&pts, &cams, None, 4).unwrap();
        let shift = Vector3::new(10.0, -4.0, 2.0);
        let tp: Vec<_> = pts.iter().map(|p| 2.5 * p + shift).collect();
        let tc: Vec<_> = cams.iter().map(|p| 2.5 * p + shift).collect();
        let e2 = reconstructability(&tp, &tc, None, 4).unwrap();
        assert!((e - e2).abs() < 1e-9 * e);
        assert!(reconstructability(&pts, &cams[..5], None, 4).is_err());
        assert!(reconstructability(&pts, &cams, None, 0).is_err());
        assert!(reconstructability(&pts, &cams, None, f + 1).is_err());
        let mut bad = pts.clone();
        bad[3].x = f64::NAN;
        assert!(reconstructability(&bad, &cams, None, 4).is_err());
        let times = vec![0.0; f];
        assert!(reconstructability(&pts, &cams, Some(&times), 4).is_err());
    }
}
