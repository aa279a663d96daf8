//! Rays against spheres and points.

use nalgebra::Vector3;

/// Both intersections of the line `C + s v` with the sphere of radius `r` about `centre`
/// (thesis Eq 4.8–4.9): returns `(s₁, s₂)` with `s₁ ≥ s₂` (the `+` root first), or `None`
/// when the line misses the sphere. `v` need not be unit length.
///
/// `s₁,₂ = (−vᵀΔC ± √((vᵀΔC)² − ‖v‖²(‖ΔC‖² − r²))) / ‖v‖²`, `ΔC = C − X_p`.
pub fn ray_sphere(
    c: &Vector3<f64>,
    v: &Vector3<f64>,
    centre: &Vector3<f64>,
    r: f64,
) -> Option<(f64, f64)> {
    let dc = c - centre;
    let vv = v.norm_squared();
    if vv == 0.0 {
        return None;
    }
    let b = v.dot(&dc);
    let disc = b * b - vv * (dc.norm_squared() - r * r);
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    // Numerically stable pair: avoid cancelling −b against ±sq.
    let q = if b > 0.0 { -(b + sq) } else { -b + sq };
    if q == 0.0 {
        return Some((0.0, 0.0));
    }
    let (a1, a2) = (q / vv, (dc.norm_squared() - r * r) / q);
    Some(if a1 >= a2 { (a1, a2) } else { (a2, a1) })
}

/// The smallest radius at which the line `C + s v` touches a sphere about `centre`: the
/// distance from `centre` to the line. Used to enlarge a sphere that a noisy ray misses
/// (Sec 4.4.1).
pub fn line_point_distance(c: &Vector3<f64>, v: &Vector3<f64>, centre: &Vector3<f64>) -> f64 {
    let vn = v.normalize();
    let d = centre - c;
    (d - vn * vn.dot(&d)).norm()
}

/// The perspective distance vector of Eq 6.2: for a ray from eye `p` along unit `v`,
/// `d = (x − x̂)/((x − p)ᵀv)` with `x̂` the projection of `x` on the ray. `None` stands for
/// the infinite distance of a point behind the eye, `(x − p)ᵀv < 0`.
///
/// At the eye itself (`x = p`) the ratio is 0/0; we define it as the zero vector (the eye
/// sees its own position on its axis), which keeps fields and kernels finite there.
#[inline]
pub fn perspective_distance(
    p: &Vector3<f64>,
    v: &Vector3<f64>,
    x: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let w = x - p;
    let depth = w.dot(v);
    if depth < 0.0 {
        return None;
    }
    let perp = w - v * depth;
    if depth == 0.0 {
        return if perp.norm_squared() == 0.0 {
            Some(Vector3::zeros())
        } else {
            None
        };
    }
    Some(perp / depth)
}

/// Scalar version of [`perspective_distance`] (Eq 7.13): `‖x − x̂‖ / vᵀ(x − p)`, or
/// `f64::INFINITY` behind the eye.
#[inline]
pub fn perspective_distance_norm(p: &Vector3<f64>, v: &Vector3<f64>, x: &Vector3<f64>) -> f64 {
    perspective_distance(p, v, x).map_or(f64::INFINITY, |d| d.norm())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn sphere_roots_lie_on_sphere_and_line() {
        let c = Vector3::new(3.0, 1.0, -2.0);
        let v = Vector3::new(-1.0, -0.2, 0.6);
        let centre = Vector3::new(0.1, 0.0, 0.0);
        let r = 1.5;
        let (s1, s2) = ray_sphere(&c, &v, &centre, r).unwrap();
        assert!(s1 >= s2);
        for s in [s1, s2] {
            assert_relative_eq!((c + v * s - centre).norm(), r, epsilon = 1e-12);
        }
        // Two distinct crossings (the line passes 0.23 m from the centre of a 1.5 m sphere).
        assert!(s1 - s2 > 1.0, "{s1} {s2}");
    }

    #[test]
    fn miss_and_enlarge() {
        let c = Vector3::new(0.0, 2.0, -5.0);
        let v = Vector3::new(0.0, 0.0, 1.0);
        let centre = Vector3::zeros();
        assert!(ray_sphere(&c, &v, &centre, 1.0).is_none());
        let r = line_point_distance(&c, &v, &centre);
        assert_relative_eq!(r, 2.0, epsilon = 1e-12);
        let (s1, s2) = ray_sphere(&c, &v, &centre, r).unwrap();
        assert_relative_eq!(s1, s2, epsilon = 1e-6);
    }

    #[test]
    fn perspective_distance_cases() {
        let p = Vector3::zeros();
        let v = Vector3::z();
        let d = perspective_distance(&p, &v, &Vector3::new(1.0, 0.0, 2.0)).unwrap();
        assert_relative_eq!(d, Vector3::new(0.5, 0.0, 0.0));
        assert!(perspective_distance(&p, &v, &Vector3::new(0.0, 0.0, -1.0)).is_none());
        assert_eq!(
            perspective_distance_norm(&p, &v, &Vector3::new(0.0, 0.0, -1.0)),
            f64::INFINITY
        );
        assert_eq!(perspective_distance(&p, &v, &p), Some(Vector3::zeros()));
        // Scale invariance along the ray: the distance is an angle-like quantity.
        let a = perspective_distance_norm(&p, &v, &Vector3::new(1.0, 1.0, 3.0));
        let b = perspective_distance_norm(&p, &v, &Vector3::new(2.0, 2.0, 6.0));
        assert_relative_eq!(a, b, epsilon = 1e-12);
    }
}
