//! Property tests of the geometry invariants.

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use proptest::prelude::*;
use socialcore::basis::dct_basis;
use socialcore::geometry::{
    align_similarity, ray_sphere, triangulate_point, Camera, LmOptions, Similarity,
};

fn look_at(c: Vector3<f64>, target: Vector3<f64>) -> Matrix3<f64> {
    let z = (target - c).normalize();
    let x = Vector3::z().cross(&z).normalize();
    let y = z.cross(&x);
    Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()])
}

fn vec3() -> impl Strategy<Value = Vector3<f64>> {
    (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64).prop_map(|(a, b, c)| Vector3::new(a, b, c))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn noise_free_triangulation_is_exact(x in vec3(), azimuths in prop::collection::vec(0.0..std::f64::consts::TAU, 2..6)) {
        let k = Matrix3::new(900.0, 0.0, 640.0, 0.0, 900.0, 360.0, 0.0, 0.0, 1.0);
        let mut cams = Vec::new();
        for (i, a) in azimuths.iter().enumerate() {
            let c = Vector3::new(6.0 * a.cos(), 6.0 * a.sin(), 1.0 + 0.3 * i as f64);
            cams.push(Camera::new(k, look_at(c, Vector3::zeros()), c, i).unwrap());
        }
        let px: Vec<Option<Vector2<f64>>> = cams.iter().map(|c| Some(c.project(&x).0)).collect();
        match triangulate_point(&cams, &px, true, &LmOptions::default()) {
            Ok(t) => prop_assert!((t.x - x).norm() < 1e-7, "error {}", (t.x - x).norm()),
            // Nearly coincident azimuths make the rays parallel: that must be reported, not guessed.
            Err(e) => prop_assert!(e.to_string().contains("parallel"), "{e}"),
        }
    }

    #[test]
    fn ray_sphere_roots_lie_on_sphere(c in vec3(), v in vec3(), centre in vec3(), r in 0.01..3.0f64) {
        prop_assume!(v.norm() > 1e-3);
        if let Some((s1, s2)) = ray_sphere(&(c * 5.0), &v, &centre, r) {
            prop_assert!(s1 >= s2);
            for s in [s1, s2] {
                let d = (c * 5.0 + v * s - centre).norm();
                prop_assert!((d - r).abs() < 1e-9 * (1.0 + r + s.abs() * v.norm()));
            }
        }
    }

    #[test]
    fn dct_is_orthonormal(n in 1usize..60, dt in 1e-3..10.0f64, t0 in -50.0..50.0f64) {
        let times: Vec<f64> = (0..n).map(|i| t0 + dt * i as f64).collect();
        let b = dct_basis(&times, n, None, None).unwrap();
        let g = b.transpose() * &b;
        for i in 0..n {
            for j in 0..n {
                let want = if i == j { 1.0 } else { 0.0 };
                prop_assert!((g[(i, j)] - want).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn umeyama_recovers_similarity(roll in -3.0..3.0f64, pitch in -1.5..1.5f64, yaw in -3.0..3.0f64,
                                   scale in 0.01..100.0f64, t in vec3(), pts in prop::collection::vec(vec3(), 4..30)) {
        let truth = Similarity { scale, rotation: *Rotation3::from_euler_angles(roll, pitch, yaw).matrix(), translation: t * 10.0 };
        let dst: Vec<_> = pts.iter().map(|p| truth.apply(p)).collect();
        if let Ok(est) = align_similarity(&pts, &dst) {
            prop_assert!((est.scale - scale).abs() < 1e-7 * scale);
            prop_assert!((est.rotation - truth.rotation).abs().max() < 1e-6);
        }
    }
}
