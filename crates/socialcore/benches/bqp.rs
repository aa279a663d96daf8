//! One exact BQP solve with n = 40 built from an articulated reconstruction (Eq 4.12):
//! a stationary camera, a moving parent, a child on a smooth path, 1 px pixel noise.
//! Plus the OR-Library instance bqp50-1 from `tests/data/bqp`, and a Beasley-style random
//! instance with n = 70 (10 % density, integers in [−100, 100], minimising `−xᵀSx`) solved
//! with the parallel rounds and on one thread.
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{DMatrix, DVector, Matrix3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use socialcore::articulated::{articulated_qp, candidates};
use socialcore::basis::DctSpan;
use socialcore::bqp::{solve_bqp, BqpOptions, BqpProblem};
use socialcore::geometry::Camera;

fn articulated_instance(f: usize, seed: u64) -> BqpProblem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
    let cam = Camera::new(k, Matrix3::identity(), Vector3::new(0.0, 0.0, -4.0), 0).expect("cam");
    let times: Vec<f64> = (0..f).map(|i| i as f64 / 30.0).collect();
    let span = DctSpan::from_times(&times).expect("span");
    let basis = span.matrix(&times, 5).expect("basis");
    let s = (f as f64).sqrt();
    let ct = DVector::from_fn(5, |j, _| {
        if j == 0 {
            1.4 * s
        } else {
            rng.random_range(-0.6..0.6)
        }
    });
    let cp = DVector::from_fn(5, |j, _| {
        if j == 0 {
            0.5 * s
        } else {
            rng.random_range(-1.2..1.2)
        }
    });
    let (th, ph) = (&basis * ct, &basis * cp);
    let mut parent = Vec::new();
    let mut pixels = Vec::new();
    for i in 0..f {
        let t = times[i];
        let p = Vector3::new(0.4 * (1.3 * t).sin(), 0.2 * t - 0.2, 0.3 * (0.9 * t).cos());
        let d = Vector3::new(
            th[i].sin() * ph[i].cos(),
            th[i].sin() * ph[i].sin(),
            th[i].cos(),
        );
        let noise = Vector2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        pixels.push(Some(cam.project(&(p + d * 0.4)).0 + noise));
        parent.push(p);
    }
    let cams = vec![cam; f];
    let cand = candidates(&cams, &pixels, &parent, 0.4, false).expect("candidates");
    let theta = span.matrix(&times, 8).expect("basis");
    articulated_qp(&cand, &theta).expect("qp").0
}

fn bqp50() -> BqpProblem {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/data/bqp/bqp50-1.qubo"
    );
    let text = std::fs::read_to_string(path).expect("instance");
    let mut lines = text.lines();
    let n: usize = lines.next().and_then(|l| l.trim().parse().ok()).expect("n");
    let mut q = DMatrix::zeros(n, n);
    for l in lines {
        let v: Vec<f64> = l
            .split_whitespace()
            .filter_map(|x| x.parse().ok())
            .collect();
        if v.len() == 3 {
            q[(v[0] as usize, v[1] as usize)] = v[2];
            q[(v[1] as usize, v[0] as usize)] = v[2];
        }
    }
    BqpProblem::new(&q, None).expect("valid")
}

fn bench(c: &mut Criterion) {
    let p = articulated_instance(40, 1);
    let s = solve_bqp(&p, &BqpOptions::default()).expect("solve");
    assert!(s.optimal);
    eprintln!("articulated n=40: {} nodes", s.nodes);
    c.bench_function("bqp_articulated_n40", |b| {
        b.iter(|| solve_bqp(&p, &BqpOptions::default()).expect("solve"))
    });
    let q = bqp50();
    let s = solve_bqp(&q, &BqpOptions::default()).expect("solve");
    eprintln!("bqp50-1: {} nodes, objective {}", s.nodes, s.objective);
    c.bench_function("bqp50-1", |b| {
        b.iter(|| solve_bqp(&q, &BqpOptions::default()).expect("solve"))
    });
}

fn beasley(n: usize, seed: u64) -> BqpProblem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut q = vec![0.0; n * n];
    for i in 0..n {
        for j in i..n {
            if rng.random_bool(0.1) {
                let v = -f64::from(rng.random_range(-100i32..=100));
                q[i * n + j] = v;
                q[j * n + i] = v;
            }
        }
    }
    BqpProblem::from_row_major(n, q, vec![0.0; n]).expect("valid")
}

fn bench_beasley(c: &mut Criterion) {
    let p = beasley(70, 0);
    let mut g = c.benchmark_group("bqp_beasley_n70");
    g.sample_size(10);
    for parallel in [true, false] {
        let opts = BqpOptions {
            parallel,
            ..BqpOptions::default()
        };
        let s = solve_bqp(&p, &opts).expect("solve");
        eprintln!(
            "beasley n=70 parallel={parallel}: {} nodes, optimal {}",
            s.nodes, s.optimal
        );
        g.bench_function(if parallel { "parallel" } else { "serial" }, |b| {
            b.iter(|| solve_bqp(&p, &opts).expect("solve"))
        });
    }
    g.finish();
}

criterion_group!(benches, bench, bench_beasley);
criterion_main!(benches);
