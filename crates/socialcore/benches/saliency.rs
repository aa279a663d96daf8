//! One frame of the meeting scene's size: 11 gaze rays in two groups, 20 seeds per ray,
//! mode seeking with confidence regions; and the field on a 64³ grid.
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use socialcore::saliency::{find_charges, saliency_grid, GazeRays, Grid, ModeOptions};
use std::hint::black_box;

fn frame() -> GazeRays {
    let targets = [Vector3::new(1.0, 1.0, 1.5), Vector3::new(5.0, 2.0, 1.4)];
    let mut p = Vec::new();
    let mut v = Vec::new();
    for k in 0..11 {
        let (t, n, i) = if k < 6 {
            (targets[0], 6, k)
        } else {
            (targets[1], 5, k - 6)
        };
        let a = i as f64 * std::f64::consts::TAU / n as f64 + 0.3;
        let eye = t + Vector3::new(1.4 * a.cos(), 1.4 * a.sin(), 0.1);
        // Deterministic eye-in-head deviation of a few degrees.
        let d = (t - eye).normalize();
        let e = d.cross(&Vector3::z()).normalize();
        let dev = 0.05 * ((k as f64) * 1.7).sin();
        p.push(eye);
        v.push((d + e * dev + Vector3::z() * (0.03 * (k as f64).cos())).normalize());
    }
    GazeRays::new(p, v, vec![0.1; 11], None).expect("rays")
}

fn bench(c: &mut Criterion) {
    let rays = frame();
    let opts = ModeOptions::default();
    c.bench_function("find_charges 11 rays x 20 seeds", |b| {
        b.iter(|| find_charges(black_box(&rays), &opts, 0).expect("charges"))
    });
    let grid = Grid::new([-1.0, -1.0, 0.0], [7.0, 4.0, 3.0], [64, 64, 64]).expect("grid");
    c.bench_function("saliency_grid 11 rays on 64^3", |b| {
        b.iter(|| saliency_grid(black_box(&rays), &grid).expect("grid"))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
