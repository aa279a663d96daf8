//! Property tests of the geometry invariants.

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use proptest::prelude::*;
use socialcore::basis::dct_basis;
use socialcore::geometry::{
    align_similarity, line_point_distance, ray_sphere, triangulate_point, Camera, LmOptions,
    Similarity,
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
        // The widest angle between two rays: nearly coincident azimuths make them parallel.
        let dirs: Vec<Vector3<f64>> = cams.iter().map(|c| (x - c.c).normalize()).collect();
        let widest = dirs
            .iter()
            .flat_map(|a| dirs.iter().map(move |b| a.cross(b).norm().asin()))
            .fold(0.0, f64::max);
        match triangulate_point(&cams, &px, true, &LmOptions::default()) {
            Ok(t) => prop_assert!((t.x - x).norm() < 1e-7, "error {}", (t.x - x).norm()),
            // Parallel rays must be reported, not guessed; any other failure is a bug.
            Err(e) => prop_assert!(
                e.to_string().contains("parallel") && widest < 1e-3,
                "{e} (widest angle between rays {widest} rad)"
            ),
        }
    }

    #[test]
    fn ray_sphere_roots_lie_on_sphere(c in vec3(), v in vec3(), centre in vec3(), r in 0.01..3.0f64) {
        prop_assume!(v.norm() > 1e-3);
        // The line misses the sphere exactly when it passes further than r from the centre.
        let gap = line_point_distance(&(c * 5.0), &v, &centre);
        match ray_sphere(&(c * 5.0), &v, &centre, r) {
            Some((s1, s2)) => {
                prop_assert!(gap <= r * (1.0 + 1e-9), "roots for a line {gap} from the centre, r = {r}");
                prop_assert!(s1 >= s2);
                for s in [s1, s2] {
                    let d = (c * 5.0 + v * s - centre).norm();
                    prop_assert!((d - r).abs() < 1e-9 * (1.0 + r + s.abs() * v.norm()));
                }
            }
            None => prop_assert!(gap >= r * (1.0 - 1e-9), "no root for a line {gap} from the centre, r = {r}"),
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
        // Only (nearly) collinear points leave the rotation undetermined: the second
        // singular value of the centred points measures their spread off a line.
        let mean = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
        let spread = pts.iter().fold(Matrix3::zeros(), |m, p| m + (p - mean) * (p - mean).transpose());
        let mut sv: Vec<f64> = spread.symmetric_eigenvalues().iter().copied().collect();
        sv.sort_by(|a, b| b.total_cmp(a));
        prop_assume!(sv[1] > 1e-2);
        let est = align_similarity(&pts, &dst);
        prop_assert!(est.is_ok(), "{est:?}");
        if let Ok(est) = est {
            prop_assert!((est.scale - scale).abs() < 1e-7 * scale);
            prop_assert!((est.rotation - truth.rotation).abs().max() < 1e-6);
            prop_assert!((est.translation - truth.translation).norm() < 1e-6 * (1.0 + scale));
        }
    }
}
