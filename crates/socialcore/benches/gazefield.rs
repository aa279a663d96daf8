//! Gaze-field EM (thesis Eq 7.10–7.14): 1,000 independent frames × 11 members × 2 charges,
//! and one 1,000-frame window with the velocity filter; plus field prediction at 100,000
//! points.
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use socialcore::gazefield::{
    em_frames, em_window, init_window, EmOptions, GazeField, GazeRay, SocialCharge, WindowFrame,
};

/// Deterministic meeting-like frames: two groups of 6 and 5 around moving charges, gaze
/// perturbed by a fixed pseudo-random pattern of a few degrees.
fn frames(n: usize) -> Vec<WindowFrame> {
    (0..n)
        .map(|t| {
            let s = t as f64 / n as f64;
            let c = [
                Vector3::new(-2.5 + 0.5 * s, 0.2 * (5.0 * s).sin(), 1.0),
                Vector3::new(2.5, 0.5 - 0.5 * s, 1.1),
            ];
            let mut f = WindowFrame::default();
            for j in 0..11usize {
                let (g, k, n) = if j < 6 { (0, j, 6.0) } else { (1, j - 6, 5.0) };
                let a = 2.0 * std::f64::consts::PI * k as f64 / n;
                let p = c[g] + Vector3::new(1.4 * a.cos(), 1.4 * a.sin(), 0.6);
                let jitter = Vector3::new(
                    ((t * 31 + j * 7) as f64 * 0.7).sin(),
                    ((t * 17 + j * 3) as f64 * 1.3).cos(),
                    ((t * 13 + j * 11) as f64 * 0.9).sin(),
                ) * 0.12;
                let v = ((c[g] - p).normalize() + jitter).normalize();
                f.rays.push(GazeRay::new(p, v));
                f.members.push(j);
            }
            f
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let fr = frames(1000);
    let init = init_window(&fr, 2, 0.25).expect("init");
    let rays: Vec<Vec<GazeRay>> = fr.iter().map(|f| f.rays.clone()).collect();
    let opts = EmOptions::default();
    let mut g = c.benchmark_group("gazefield");
    g.sample_size(10);
    g.bench_function("em_frames_1000x11x2", |b| {
        b.iter(|| em_frames(&rays, &init, &opts).expect("em"))
    });
    let wopts = EmOptions {
        lambda_g: 20.0,
        ..opts
    };
    g.bench_function("em_window_1000x11x2_velocity", |b| {
        b.iter(|| em_window(&fr, &init, &wopts).expect("em"))
    });
    let field = GazeField::new(
        vec![
            SocialCharge::new(Vector3::new(-2.5, 0.0, 1.0), 6.0),
            SocialCharge::new(Vector3::new(2.5, 0.5, 1.1), 5.0),
        ],
        20.0,
    )
    .expect("field");
    let pts: Vec<Vector3<f64>> = (0..100_000)
        .map(|i| {
            let f = i as f64;
            Vector3::new(4.0 * (f * 0.37).sin(), 3.0 * (f * 0.11).cos(), 1.6)
        })
        .collect();
    g.bench_function("most_likely_direction_100k", |b| {
        b.iter(|| {
            pts.iter()
                .map(|x| field.most_likely_direction(x).ok().flatten())
                .filter(Option::is_some)
                .count()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
