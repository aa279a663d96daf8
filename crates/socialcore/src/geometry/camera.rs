//! Pinhole cameras `P = K R [I | −C]` (thesis Sec 4.1), x right, y down, z forward.

use crate::error::{Error, Result};
use nalgebra::{Matrix3, Matrix3x4, Vector2, Vector3};

/// Tolerance on `RᵀR = I` and `det R = 1` when validating a rotation.
pub const ROTATION_TOL: f64 = 1e-6;

/// One calibrated pinhole camera: intrinsics `K` (upper triangular), world→camera rotation
/// `R` and centre `C` in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub k: Matrix3<f64>,
    pub r: Matrix3<f64>,
    pub c: Vector3<f64>,
    /// `K⁻¹`, cached because back-projection needs it for every pixel.
    pub k_inv: Matrix3<f64>,
}

impl Camera {
    /// Builds a camera and validates it: finite entries; `K` upper triangular, with
    /// positive focal lengths and `K[2,2] = 1` (a `K` with another positive `K[2,2]` is
    /// rescaled); `R` a proper rotation within [`ROTATION_TOL`].
    /// `index` names the frame in error messages.
    pub fn new(k: Matrix3<f64>, r: Matrix3<f64>, c: Vector3<f64>, index: usize) -> Result<Self> {
        if !k.iter().all(|v| v.is_finite()) {
            return Err(Error::invalid(
                "K",
                format!("frame {index}: contains a non-finite value"),
            ));
        }
        if !r.iter().all(|v| v.is_finite()) {
            return Err(Error::invalid(
                "R",
                format!("frame {index}: contains a non-finite value"),
            ));
        }
        if !c.iter().all(|v| v.is_finite()) {
            return Err(Error::invalid(
                "C",
                format!("frame {index}: contains a non-finite value"),
            ));
        }
        if k[(1, 0)] != 0.0 || k[(2, 0)] != 0.0 || k[(2, 1)] != 0.0 {
            return Err(Error::invalid(
                "K",
                format!("frame {index}: must be upper triangular"),
            ));
        }
        if k[(2, 2)] <= 0.0 {
            return Err(Error::invalid(
                "K",
                format!("frame {index}: K[2,2] must be positive"),
            ));
        }
        let k = k / k[(2, 2)];
        if k[(0, 0)] <= 0.0 || k[(1, 1)] <= 0.0 {
            return Err(Error::invalid(
                "K",
                format!("frame {index}: focal lengths K[0,0], K[1,1] must be positive (K is singular or mirrored)"),
            ));
        }
        let orth = (r.transpose() * r - Matrix3::identity()).abs().max();
        let det = r.determinant();
        if orth > ROTATION_TOL || (det - 1.0).abs() > ROTATION_TOL {
            return Err(Error::invalid(
                "R",
                format!(
                    "frame {index}: not a rotation (|RᵀR − I|max = {orth:.2e}, det = {det:.6})"
                ),
            ));
        }
        // K upper triangular with positive diagonal: the inverse exists.
        let k_inv = k
            .try_inverse()
            .ok_or_else(|| Error::invalid("K", format!("frame {index}: singular")))?;
        Ok(Camera { k, r, c, k_inv })
    }

    /// The 3×4 projection matrix `K R [I | −C]`.
    pub fn projection_matrix(&self) -> Matrix3x4<f64> {
        let kr = self.k * self.r;
        let t = -(kr * self.c);
        Matrix3x4::from_columns(&[
            kr.column(0).into(),
            kr.column(1).into(),
            kr.column(2).into(),
            t,
        ])
    }

    /// A point in this camera's frame: `R (X − C)`.
    #[inline]
    pub fn to_camera(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.r * (x - self.c)
    }

    /// Pixel of a world point, and its depth along the optical axis. Points at zero depth
    /// project to infinity (non-finite pixel); the depth lets callers reject points behind.
    #[inline]
    pub fn project(&self, x: &Vector3<f64>) -> (Vector2<f64>, f64) {
        let xc = self.to_camera(x);
        let h = self.k * xc;
        (Vector2::new(h.x / h.z, h.y / h.z), xc.z)
    }

    /// Unit world direction of the ray through pixel `u`: `Rᵀ K⁻¹ [u, 1]` normalised
    /// (thesis Sec 4.2.2).
    #[inline]
    pub fn ray_direction(&self, u: &Vector2<f64>) -> Vector3<f64> {
        let d = self.r.transpose() * (self.k_inv * Vector3::new(u.x, u.y, 1.0));
        // The squares of a pixel beyond ~1e154 overflow the plain norm: such a direction is
        // scaled first. Ordinary pixels take the plain path, bit for bit as before.
        let m = d.amax();
        if m > 1e150 && m.is_finite() {
            (d / m).normalize()
        } else {
            d.normalize()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::Rotation3;

    fn cam() -> Camera {
        let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 790.0, 240.0, 0.0, 0.0, 1.0);
        let r = *Rotation3::from_euler_angles(0.1, -0.2, 0.3).matrix();
        Camera::new(k, r, Vector3::new(1.0, 2.0, -3.0), 0).unwrap()
    }

    #[test]
    fn projection_matrix_matches_project() {
        let c = cam();
        let x = Vector3::new(0.3, -0.2, 4.0);
        let p = c.projection_matrix() * x.push(1.0);
        let (u, _) = c.project(&x);
        assert_relative_eq!(u, Vector2::new(p.x / p.z, p.y / p.z), epsilon = 1e-9);
    }

    #[test]
    fn ray_direction_of_huge_pixels_is_unit() {
        // The squares of 1e200 px overflow a plain norm: NaN or a zero ray before.
        let c = cam();
        for u in [Vector2::new(3e200, -1e200), Vector2::new(1e300, 1e300)] {
            let d = c.ray_direction(&u);
            assert_relative_eq!(d.norm(), 1.0, epsilon = 1e-12);
            assert_relative_eq!(d, c.ray_direction(&(u / 1e180)), epsilon = 1e-12);
        }
    }

    #[test]
    fn back_projection_round_trip() {
        let c = cam();
        let x = Vector3::new(0.3, -0.2, 4.0);
        let (u, depth) = c.project(&x);
        assert!(depth > 0.0);
        let d = c.ray_direction(&u);
        assert_relative_eq!(d, (x - c.c).normalize(), epsilon = 1e-12);
    }

    #[test]
    fn rejects_bad_cameras() {
        let c = cam();
        assert!(Camera::new(c.k, c.r * 1.01, c.c, 0).is_err());
        let mut k = c.k;
        k[(0, 0)] = 0.0;
        assert!(Camera::new(k, c.r, c.c, 0).is_err());
        let mut k = c.k;
        k[(1, 0)] = 1.0;
        assert!(Camera::new(k, c.r, c.c, 0).is_err());
        assert!(Camera::new(c.k, c.r, Vector3::new(f64::NAN, 0.0, 0.0), 3).is_err());
        let reflection = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        assert!(Camera::new(c.k, reflection, c.c, 0).is_err());
    }
}
