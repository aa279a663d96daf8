//! Batched triangulation of 100,000 points seen by 4 cameras, with and without refinement.
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Vector3};
use socialcore::geometry::{triangulate_batch, Camera, LmOptions};

fn cameras() -> Vec<Camera> {
    let k = Matrix3::new(700.0, 0.0, 320.0, 0.0, 700.0, 240.0, 0.0, 0.0, 1.0);
    (0..4)
        .map(|i| {
            let a = i as f64 * 0.6;
            let c = Vector3::new(6.0 * a.sin(), 0.5, -6.0 * a.cos());
            let z = (-c).normalize();
            let x = Vector3::y().cross(&z).normalize();
            let y = z.cross(&x);
            Camera::new(
                k,
                Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]),
                c,
                i,
            )
            .expect("camera")
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let cams = cameras();
    let n = 100_000;
    let mut px = Vec::with_capacity(n * 8);
    for i in 0..n {
        let f = i as f64;
        let x = Vector3::new((f * 0.37).sin(), (f * 0.11).cos(), (f * 0.07).sin() * 0.5);
        for (v, cam) in cams.iter().enumerate() {
            let p = cam.project(&x).0;
            // Deterministic sub-pixel "noise".
            px.extend([
                p.x + 0.5 * ((f + v as f64) * 1.3).sin(),
                p.y + 0.5 * ((f - v as f64) * 0.7).cos(),
            ]);
        }
    }
    let opts = LmOptions::default();
    let mut g = c.benchmark_group("triangulate_100k_x4");
    g.sample_size(10);
    g.bench_function("dlt", |b| {
        b.iter(|| triangulate_batch(&cams, &px, n, false, &opts))
    });
    g.bench_function("dlt+lm", |b| {
        b.iter(|| triangulate_batch(&cams, &px, n, true, &opts))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
