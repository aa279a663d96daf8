//! One point's full trajectory solve (200 frames from random cameras, 1 px noise): 5-fold
//! cross validation over K ≤ 30, linear solve and Levenberg–Marquardt refinement; plus a
//! batch of 1,000 such points (rayon).
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use socialcore::geometry::Camera;
use socialcore::trajectory::{
    reconstruct_trajectories, reconstruct_trajectory, CvRule, Frames, KSelection, TrajectoryOptions,
};

const F: usize = 200;

fn gauss(r: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = r.random::<f64>().max(1e-300);
    let u2: f64 = r.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn scene(n: usize) -> (Frames, Vec<f64>) {
    let mut r = ChaCha8Rng::seed_from_u64(42);
    let k = Matrix3::new(1000.0, 0.0, 640.0, 0.0, 1000.0, 360.0, 0.0, 0.0, 1.0);
    let cams: Vec<Camera> = (0..F)
        .map(|i| {
            let a: f64 = r.random::<f64>() * std::f64::consts::TAU;
            let rad = 4.0 + 2.0 * r.random::<f64>();
            let c = Vector3::new(rad * a.cos(), 1.5, rad * a.sin());
            let z = (Vector3::new(0.0, 1.0, 0.0) - c).normalize();
            let x = z.cross(&Vector3::y()).normalize();
            let y = z.cross(&x);
            let rot = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
            Camera::new(k, rot, c, i).expect("camera")
        })
        .collect();
    let times: Vec<f64> = (0..F).map(|i| i as f64 / 30.0).collect();
    let mut px = Vec::with_capacity(n * F * 2);
    for _ in 0..n {
        let (a, b, c) = (r.random::<f64>(), r.random::<f64>(), r.random::<f64>());
        for (cam, &t) in cams.iter().zip(&times) {
            let x = Vector3::new(
                0.4 * (1.3 * t + 6.0 * a).sin(),
                1.0 + 0.3 * (2.1 * t + 6.0 * b).sin(),
                0.4 * (0.9 * t + 6.0 * c).cos(),
            );
            let p = cam.project(&x).0;
            px.push(p.x + gauss(&mut r));
            px.push(p.y + gauss(&mut r));
        }
    }
    (Frames::new(cams, times).expect("frames"), px)
}

fn bench(c: &mut Criterion) {
    let opts = TrajectoryOptions {
        k: KSelection::CrossValidation {
            folds: 5,
            k_min: 1,
            k_max: Some(30),
            rule: CvRule::Min,
        },
        ..Default::default()
    };
    let (frames, px) = scene(1000);
    let mut g = c.benchmark_group("trajectory_200_frames");
    g.sample_size(20);
    g.bench_function("one_point_cv30_refine", |b| {
        b.iter(|| reconstruct_trajectory(&frames, &px[..2 * F], &opts).expect("fit"))
    });
    g.sample_size(10);
    g.bench_function("batch_1000_points_cv30_refine", |b| {
        b.iter(|| reconstruct_trajectories(&frames, &px, 1000, &opts).expect("batch"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
