//! Solves Beasley-style random instances (OR-Library bqp family): `n` variables, each
//! upper-triangle entry nonzero with probability `density`, integer uniform in
//! [−100, 100]; Beasley maximises `xᵀSx`, we minimise `−xᵀSx`.
//! Run: cargo run --release --example bqp_beasley -- N SEEDS [TIME_LIMIT] [serial]
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use socialcore::bqp::{solve_bqp, BqpOptions, BqpProblem};
use std::time::{Duration, Instant};

fn beasley(n: usize, density: f64, seed: u64) -> BqpProblem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut q = vec![0.0; n * n];
    for i in 0..n {
        for j in i..n {
            if rng.random_bool(density) {
                let v = -(rng.random_range(-100i32..=100) as f64);
                q[i * n + j] = v;
                q[j * n + i] = v;
            }
        }
    }
    BqpProblem::from_row_major(n, q, vec![0.0; n]).expect("valid")
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let n: usize = a.get(1).and_then(|v| v.parse().ok()).unwrap_or(100);
    let seeds: u64 = a.get(2).and_then(|v| v.parse().ok()).unwrap_or(3);
    let tl: f64 = a.get(3).and_then(|v| v.parse().ok()).unwrap_or(60.0);
    let serial = a.get(4).is_some_and(|v| v == "serial");
    let mut total = 0.0;
    for seed in 0..seeds {
        let p = beasley(n, 0.1, seed);
        let opts = BqpOptions {
            time_limit: Some(Duration::from_secs_f64(tl)),
            parallel: !serial,
            ..BqpOptions::default()
        };
        let t = Instant::now();
        let s = solve_bqp(&p, &opts).expect("solve");
        let dt = t.elapsed().as_secs_f64();
        total += dt;
        println!(
            "n={n} seed={seed} obj={} bound={:.1} gap={:.4} nodes={} optimal={} {:.3}s",
            s.objective, s.bound, s.gap, s.nodes, s.optimal, dt
        );
    }
    println!("total {total:.3}s");
}
