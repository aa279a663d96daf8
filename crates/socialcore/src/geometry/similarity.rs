//! Least-squares similarity between two point sets (Umeyama, PAMI 1991).

use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};

/// A similarity transform `y = s R x + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Similarity {
    pub scale: f64,
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
}

impl Similarity {
    /// Applies the transform to a point.
    pub fn apply(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * x * self.scale + self.translation
    }
}

/// The similarity minimising `Σ ‖dst_i − (s R src_i + t)‖²`. Needs at least three points
/// that are not collinear.
pub fn align_similarity(src: &[Vector3<f64>], dst: &[Vector3<f64>]) -> Result<Similarity> {
    if src.len() != dst.len() {
        return Err(Error::invalid(
            "dst",
            format!("has {} points but src has {}", dst.len(), src.len()),
        ));
    }
    if src.len() < 3 {
        return Err(Error::degenerate(format!(
            "a similarity needs at least 3 point pairs, got {}",
            src.len()
        )));
    }
    for (name, pts) in [("src", src), ("dst", dst)] {
        if pts.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid(name, "contains a non-finite value"));
        }
    }
    let n = src.len() as f64;
    let mu_s = src.iter().sum::<Vector3<f64>>() / n;
    let mu_d = dst.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    let mut var_s = 0.0;
    for (a, b) in src.iter().zip(dst) {
        let (da, db) = (a - mu_s, b - mu_d);
        cov += db * da.transpose();
        var_s += da.norm_squared();
    }
    cov /= n;
    var_s /= n;
    if var_s <= 0.0 {
        return Err(Error::degenerate("src points all coincide"));
    }
    let svd = cov.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(Error::degenerate("SVD of the cross-covariance failed"));
    };
    let mut sv = svd.singular_values;
    // Sort-aware rank check: the second largest singular value must be non-zero.
    let mut sorted: Vec<f64> = sv.iter().copied().collect();
    sorted.sort_by(|a, b| b.total_cmp(a));
    if sorted[1] <= 1e-12 * sorted[0].max(f64::MIN_POSITIVE) {
        return Err(Error::degenerate(
            "the points are collinear: rotation about their line is undetermined",
        ));
    }
    let mut d = Matrix3::identity();
    if (u.determinant() * vt.determinant()) < 0.0 {
        // Flip the axis of the smallest singular value.
        let imin = (0..3).min_by(|&a, &b| sv[a].total_cmp(&sv[b])).unwrap_or(2);
        d[(imin, imin)] = -1.0;
        sv[imin] = -sv[imin];
    }
    let rotation = u * d * vt;
    let scale = sv.sum() / var_s;
    let translation = mu_d - rotation * mu_s * scale;
    Ok(Similarity {
        scale,
        rotation,
        translation,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::Rotation3;

    #[test]
    fn recovers_known_similarity() {
        let r = *Rotation3::from_euler_angles(0.4, -1.1, 2.0).matrix();
        let truth = Similarity {
            scale: 2.5,
            rotation: r,
            translation: Vector3::new(1.0, -2.0, 0.5),
        };
        let src: Vec<_> = (0..10)
            .map(|i| Vector3::new((i as f64).sin(), (i as f64 * 0.7).cos(), i as f64 * 0.1))
            .collect();
        let dst: Vec<_> = src.iter().map(|p| truth.apply(p)).collect();
        let est = align_similarity(&src, &dst).unwrap();
        assert_relative_eq!(est.scale, truth.scale, epsilon = 1e-10);
        assert_relative_eq!(est.rotation, truth.rotation, epsilon = 1e-10);
        assert_relative_eq!(est.translation, truth.translation, epsilon = 1e-10);
    }

    #[test]
    fn degenerate_inputs() {
        let line: Vec<_> = (0..5).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        assert!(matches!(
            align_similarity(&line, &line),
            Err(Error::Degenerate(_))
        ));
        assert!(align_similarity(&line[..2], &line[..2]).is_err());
        assert!(matches!(
            align_similarity(&line, &line[..4]),
            Err(Error::InvalidInput { .. })
        ));
    }
}
