use super::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn enumerate(p: &BqpProblem) -> f64 {
    let n = p.n();
    let mut best = f64::INFINITY;
    let mut b = vec![false; n];
    for mask in 0u64..(1u64 << n) {
        for (i, bi) in b.iter_mut().enumerate() {
            *bi = (mask >> i) & 1 == 1;
        }
        best = best.min(p.objective(&b));
    }
    best
}

fn random_problem(n: usize, psd: bool, seed: u64) -> BqpProblem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let q = if psd {
        let a = DMatrix::from_fn(n + 3, n, |_, _| rng.random_range(-1.0..1.0));
        a.transpose() * a
    } else {
        let a = DMatrix::from_fn(n, n, |_, _| rng.random_range(-10.0..10.0));
        (&a + a.transpose()) * 0.5
    };
    let c = DVector::from_fn(n, |_, _| rng.random_range(-5.0..5.0));
    BqpProblem::new(&q, Some(&c)).expect("valid problem")
}

fn check_exact(p: &BqpProblem) {
    let want = enumerate(p);
    let sol = solve_bqp(p, &BqpOptions::default()).expect("solves");
    assert!(sol.optimal);
    let tol = 1e-7 * (1.0 + want.abs());
    assert!(
        (sol.objective - want).abs() <= tol,
        "objective {} vs enumeration {want}",
        sol.objective
    );
    assert!((p.objective(&sol.x) - sol.objective).abs() <= tol);
    assert!(sol.bound <= sol.objective + tol && sol.gap <= 1e-9);
}

#[test]
fn matches_enumeration_psd() {
    for seed in 0..12 {
        check_exact(&random_problem(4 + (seed as usize % 4) * 5, true, seed));
    }
}

#[test]
fn matches_enumeration_indefinite() {
    for seed in 100..112 {
        check_exact(&random_problem(4 + (seed as usize % 4) * 5, false, seed));
    }
}

#[test]
fn matches_enumeration_near_singular_articulated_like() {
    // Q = D P⊥ D with P⊥ the projector off a smooth (low-frequency) basis: the structure of
    // Eq 4.12 with a stationary camera, positive semidefinite with a K-dimensional null space.
    let n = 18;
    let k = 4;
    let times: Vec<f64> = (0..n).map(|i| i as f64).collect();
    let theta = crate::basis::dct_basis(&times, k, None, None).expect("basis");
    let proj = DMatrix::identity(n, n) - &theta * theta.transpose();
    for seed in 0..4u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let d = DVector::from_fn(n, |_, _| rng.random_range(0.2..1.0));
        let f0 = DVector::from_fn(n, |i, _| {
            (i as f64 * 0.3).sin() * 0.5 - d[i] * rng.random_range(0.0..1.0)
        });
        let dm = DMatrix::from_diagonal(&d);
        let q = &dm * &proj * &dm;
        let c = (&dm * &proj * &f0) * 2.0;
        check_exact(&BqpProblem::new(&q, Some(&c)).expect("valid"));
    }
}

#[test]
fn deterministic() {
    let p = random_problem(30, false, 7);
    let a = solve_bqp(&p, &BqpOptions::default()).expect("solves");
    let b = solve_bqp(&p, &BqpOptions::default()).expect("solves");
    assert_eq!(a, b);
}

#[test]
fn node_limit_returns_incumbent_bound_and_gap() {
    let p = random_problem(40, false, 3);
    let full = solve_bqp(&p, &BqpOptions::default()).expect("solves");
    assert!(
        full.nodes > 2,
        "instance too easy for this test: {} nodes",
        full.nodes
    );
    let opts = BqpOptions {
        node_limit: Some(2),
        ..BqpOptions::default()
    };
    let part = solve_bqp(&p, &opts).expect("solves");
    assert!(!part.optimal);
    assert_eq!(part.nodes, 2);
    assert!(part.bound <= full.objective + 1e-9);
    assert!(part.objective >= full.objective - 1e-9);
    assert!(part.gap >= 0.0);
    assert!((p.objective(&part.x) - part.objective).abs() < 1e-9);
}

#[test]
fn rejects_bad_input() {
    let q = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 0.0, 1.0]);
    assert!(matches!(
        BqpProblem::new(&q, None),
        Err(Error::InvalidInput { ref arg, .. }) if arg == "Q"
    ));
    let q = DMatrix::from_row_slice(2, 2, &[1.0, f64::NAN, f64::NAN, 1.0]);
    assert!(BqpProblem::new(&q, None).is_err());
    let q = DMatrix::from_row_slice(2, 3, &[1.0; 6]);
    assert!(BqpProblem::new(&q, None).is_err());
    let q = DMatrix::identity(2, 2);
    let c = DVector::from_vec(vec![1.0, 2.0, 3.0]);
    assert!(matches!(
        BqpProblem::new(&q, Some(&c)),
        Err(Error::InvalidInput { ref arg, .. }) if arg == "c"
    ));
    let c = DVector::from_vec(vec![1.0, f64::INFINITY]);
    assert!(BqpProblem::new(&q, Some(&c)).is_err());
}

#[test]
fn empty_problem() {
    let p = BqpProblem::new(&DMatrix::zeros(0, 0), None).expect("valid");
    let s = solve_bqp(&p, &BqpOptions::default()).expect("solves");
    assert!(s.optimal && s.x.is_empty() && s.objective == 0.0);
}

/// Reads an OR-Library `.qubo` file (see `tests/data/bqp/README.md`).
pub(crate) fn read_qubo(text: &str) -> BqpProblem {
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let n: usize = lines
        .next()
        .and_then(|l| l.trim().parse().ok())
        .expect("header");
    let mut q = DMatrix::zeros(n, n);
    for l in lines {
        let v: Vec<&str> = l.split_whitespace().collect();
        let i: usize = v[0].parse().expect("i");
        let j: usize = v[1].parse().expect("j");
        let x: f64 = v[2].parse().expect("v");
        q[(i, j)] = x;
        q[(j, i)] = x;
    }
    BqpProblem::new(&q, None).expect("valid")
}

#[test]
fn or_library_bqp50_to_known_optimum() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/bqp");
    let csv = std::fs::read_to_string(dir.join("optima_bqp50.csv")).expect("optima csv");
    let mut solved = 0;
    for name in ["bqp50-1", "bqp50-5", "bqp50-9"] {
        let want: f64 = csv
            .lines()
            .find(|l| l.starts_with(&format!("{name},")))
            .and_then(|l| l.split(',').nth(3))
            .and_then(|v| v.trim().parse().ok())
            .expect("optimum listed");
        let text = std::fs::read_to_string(dir.join(format!("{name}.qubo"))).expect("instance");
        let p = read_qubo(&text);
        let sol = solve_bqp(&p, &BqpOptions::default()).expect("solves");
        assert!(sol.optimal, "{name} not proven optimal");
        assert_eq!(sol.objective, want, "{name}");
        solved += 1;
    }
    assert_eq!(solved, 3);
}
