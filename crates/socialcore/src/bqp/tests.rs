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

/// Beasley's OR-Library family (bqp50 … bqp250): each upper-triangle entry nonzero with
/// probability `density`, integer uniform in [−100, 100]; Beasley maximises `bᵀSb`, so the
/// minimisation is `Q = −S`.
pub(crate) fn beasley(n: usize, density: f64, seed: u64) -> BqpProblem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut q = vec![0.0; n * n];
    for i in 0..n {
        for j in i..n {
            if rng.random_bool(density) {
                let v = -f64::from(rng.random_range(-100i32..=100));
                q[i * n + j] = v;
                q[j * n + i] = v;
            }
        }
    }
    BqpProblem::from_row_major(n, q, vec![0.0; n]).expect("valid")
}

#[test]
fn matches_enumeration_beasley_like() {
    for (k, seed) in (200..212).enumerate() {
        let n = 8 + (k % 4) * 4;
        let density = [0.1, 0.3, 0.8][k % 3];
        check_exact(&beasley(n, density, seed));
    }
}

#[test]
fn parallel_and_serial_rounds_agree() {
    let p = beasley(40, 0.1, 5);
    let par = solve_bqp(&p, &BqpOptions::default()).expect("solves");
    let ser = solve_bqp(
        &p,
        &BqpOptions {
            parallel: false,
            ..BqpOptions::default()
        },
    )
    .expect("solves");
    assert!(par.optimal && ser.optimal);
    assert_eq!(par, ser);
}

/// Root bound of the uniform eigenvalue shift `s = −λ_min(W)` (the textbook convexification
/// that the QCR shift replaces), for comparison.
fn eigenvalue_root_bound(p: &BqpProblem) -> f64 {
    let n = p.n();
    let (q, c) = p.coefficients();
    let mut w = DMatrix::from_row_slice(n, n, q);
    let mut h: Vec<f64> = c.to_vec();
    for i in 0..n {
        h[i] += w[(i, i)];
        w[(i, i)] = 0.0;
    }
    let lam = w.clone().symmetric_eigenvalues().min();
    let s = 1e-9 - lam;
    let model = Model {
        n,
        w: w.transpose().as_slice().to_vec(),
        h,
        s: vec![s; n],
        adj: vec![Vec::new(); n],
        margin: 0.0,
        node_sdp: false,
        qdiag: vec![0.0; n],
        integral: true,
        k0: 0.0,
    };
    let clock = Clock::new(None);
    let mut solver = boxqp::BoxQp::new(n);
    solver
        .solve(
            &model,
            &model.s,
            &vec![FREE; n],
            &vec![0.5; n],
            f64::INFINITY,
            &clock,
        )
        .bound
}

#[test]
fn sdp_root_bound_and_node_counts_beat_the_eigenvalue_shift() {
    // Beasley instances n = 40, seeds 0–2. Measured: the root bound closes 0.73, 0.88, 0.73
    // of the gap between the eigenvalue-shift bound and the optimum, in 33, 7, 87 nodes;
    // with the eigenvalue shift instead (mutation run) seed 0 closes 0 and needs 133 nodes.
    let max_nodes = [70, 20, 180];
    for seed in 0..3 {
        let p = beasley(40, 0.1, seed);
        let sol = solve_bqp(&p, &BqpOptions::default()).expect("solves");
        assert!(sol.optimal);
        let eig = eigenvalue_root_bound(&p);
        let opt = sol.objective;
        let closed = (sol.root_bound - eig) / (opt - eig);
        eprintln!(
            "seed {seed}: opt {opt} root {} eig {eig} closed {closed:.3} nodes {}",
            sol.root_bound, sol.nodes
        );
        assert!(sol.root_bound <= opt + 1e-6);
        assert!(
            closed >= 0.6,
            "root bound closes only {closed} of the eigenvalue gap"
        );
        assert!(
            sol.nodes <= max_nodes[seed as usize],
            "seed {seed}: {} nodes",
            sol.nodes
        );
    }
}

#[test]
fn time_limit_holds_and_bound_is_finite() {
    let p = random_problem(300, false, 11);
    let t = std::time::Instant::now();
    let opts = BqpOptions {
        time_limit: Some(Duration::from_millis(300)),
        ..BqpOptions::default()
    };
    let sol = solve_bqp(&p, &opts).expect("solves");
    let dt = t.elapsed().as_secs_f64();
    assert!(dt < 1.5, "took {dt} s for a 0.3 s limit");
    assert!(!sol.optimal);
    assert!(sol.bound.is_finite() && sol.bound <= sol.objective);
    assert!(sol.gap.is_finite() && sol.gap > 0.0);
    assert!((p.objective(&sol.x) - sol.objective).abs() < 1e-6 * sol.objective.abs().max(1.0));
}

#[test]
fn rejects_bad_options() {
    let p = beasley(5, 0.5, 1);
    for opts in [
        BqpOptions {
            batch: 0,
            ..BqpOptions::default()
        },
        BqpOptions {
            dive_depth: 0,
            ..BqpOptions::default()
        },
        BqpOptions {
            rel_tol: f64::NAN,
            ..BqpOptions::default()
        },
        BqpOptions {
            time_limit: Some(Duration::ZERO),
            ..BqpOptions::default()
        },
    ] {
        assert!(matches!(
            solve_bqp(&p, &opts),
            Err(Error::InvalidInput { .. })
        ));
    }
}

/// Diagnostic (not run by default): root bound, optimum and node counts on Beasley n = 100.
/// `BQP_PROBE="n seeds nodelimit"`.
#[test]
#[ignore]
fn probe_beasley() {
    let spec = std::env::var("BQP_PROBE").unwrap_or_else(|_| "100 3 20000".into());
    let v: Vec<u64> = spec
        .split_whitespace()
        .map(|s| s.parse().unwrap())
        .collect();
    for seed in 0..v[1] {
        let p = beasley(v[0] as usize, 0.1, seed);
        let t = std::time::Instant::now();
        let opts = BqpOptions {
            node_limit: Some(v[2]),
            parallel: false,
            ..BqpOptions::default()
        };
        let sol = solve_bqp(&p, &opts).expect("solves");
        eprintln!(
            "n {} seed {seed}: obj {} root {:.1} bound {:.1} opt {} nodes {} {:.2}s",
            v[0],
            sol.objective,
            sol.root_bound,
            sol.bound,
            sol.optimal,
            sol.nodes,
            t.elapsed().as_secs_f64()
        );
    }
}

#[test]
fn node_sdp_keeps_beasley_100_trees_small() {
    // Beasley n = 100 (10 % density), seeds 3, 6, 9, 10, 11. Measured with the per-node SDP
    // shift and the triangle cuts fitted at the root (n ≥ 64) and re-weighted at every
    // node: see MEASURED (deterministic, any thread count). Mutation runs: the cuts fitted
    // only after 2n plain nodes (the previous rule) needed 185, 199, 247, 171, 269 nodes;
    // the root shift kept at every node (no node SDP) 3,479 nodes on seed 3 before the
    // cuts. The counts are deterministic (ceilings: see below).
    // Four multiplier steps of 8 sweeps per node (3 × 12 before: 27, 41, 75, 33, 49
    // nodes), root separation from a pool between full scans every 8 steps (full scans
    // every other step before: 27, 31, 77, 31, 47 nodes, root gaps 55, 116, 154, 56, 83;
    // a pool 4× the cuts kept per scan instead of 16×: 29, 33, 19, 33, 39 nodes).
    // Session 7 (mixing on compressed rows, strengthening warm-started from the root SDP,
    // warm box relaxations at the root evaluations; same arithmetic up to summation order)
    // moved them to 11, 27, 19, 47, 23 nodes, root gaps 60, 25, 38, 49, 21, from 9, 33,
    // 33, 11, 21 and 26, 37, 32, 7, 149: the multiplier ascent is chaotic, so rounding-level
    // changes move single instances 2–7× either way (seeds 0–11: 500 nodes against 509).
    // Hence per-instance ceilings of 2.5× and ceilings of 1.25× on the sums.
    // Session 9 (nodes' mixing at rank 8, rows re-weighted in place; root arithmetic
    // unchanged: same root gaps): 19, 23, 27, 43, 31 nodes (sum 143 against 127).
    // Session 11 (root ascent of 0.6 n steps instead of 80, its bound and shift taken from
    // its best evaluation instead of a fresh SDP solve, dot products in four lanes): 27, 51,
    // 27, 63, 41 nodes, root gaps 138, 292, 293, 65, 286. The roots are weaker and these
    // five trees larger, but over seeds 0–49 the trees are smaller (2,696 → 2,916 nodes
    // with 60 steps, 2,413 with 80) and the solves 17 % cheaper (3.64 → 3.04 s CPU).
    const MEASURED: [u64; 5] = [27, 51, 27, 63, 41];
    // Optimum minus root bound (deterministic).
    const ROOT_GAP: [f64; 5] = [138.2, 291.8, 293.1, 65.4, 286.0];
    let (mut got, mut gaps) = (Vec::new(), Vec::new());
    for seed in [3u64, 6, 9, 10, 11] {
        let p = beasley(100, 0.1, seed);
        let sol = solve_bqp(&p, &BqpOptions::default()).expect("solves");
        eprintln!(
            "seed {seed}: {} nodes, root {} opt {}",
            sol.nodes, sol.root_bound, sol.objective
        );
        assert!(sol.optimal, "seed {seed} not proven");
        gaps.push(sol.objective - sol.root_bound);
        got.push(sol.nodes);
    }
    for k in 0..5 {
        assert!(
            gaps[k] <= 2.5 * ROOT_GAP[k] && got[k] as f64 <= 2.5 * MEASURED[k] as f64,
            "instance {k}: root gap {} ({}), {} nodes ({})",
            gaps[k],
            ROOT_GAP[k],
            got[k],
            MEASURED[k]
        );
    }
    let (g, m) = (got.iter().sum::<u64>(), MEASURED.iter().sum::<u64>());
    assert!(g as f64 <= 1.25 * m as f64, "{g} nodes > 1.25 x {m}");
    let (g, m) = (gaps.iter().sum::<f64>(), ROOT_GAP.iter().sum::<f64>());
    assert!(g <= 1.25 * m, "root gaps {g} > 1.25 x {m}");
}

#[test]
fn stopped_solves_bound_the_optimum_from_below() {
    // A node bound above the optimum (an invalid node relaxation) shows in the bound of a
    // solve stopped after a few nodes: it must never exceed the proven optimum.
    for seed in [0u64, 6] {
        let p = beasley(60, 0.1, seed);
        let full = solve_bqp(&p, &BqpOptions::default()).expect("solves");
        assert!(full.optimal);
        for limit in [3u64, 10, 30, 100] {
            let opts = BqpOptions {
                node_limit: Some(limit),
                ..BqpOptions::default()
            };
            let part = solve_bqp(&p, &opts).expect("solves");
            if part.optimal {
                assert_eq!(part.objective, full.objective);
                continue;
            }
            assert!(
                part.bound <= full.objective,
                "seed {seed}, {limit} nodes: bound {} above the optimum {}",
                part.bound,
                full.objective
            );
        }
    }
}

/// The internal model of `p` (as `solve_bqp` builds it, shift zero).
pub(crate) fn model_of(p: &BqpProblem) -> Model {
    let n = p.n();
    let (q, c) = p.coefficients();
    let mut w = q.to_vec();
    let mut h = c.to_vec();
    for i in 0..n {
        h[i] += w[i * n + i];
        w[i * n + i] = 0.0;
    }
    let adj = (0..n)
        .map(|i| {
            (0..n)
                .filter(|&j| w[i * n + j] != 0.0)
                .map(|j| (j, w[i * n + j]))
                .collect()
        })
        .collect();
    Model {
        n,
        w,
        h,
        s: vec![0.0; n],
        adj,
        margin: 1e-7,
        node_sdp: true,
        qdiag: vec![0.0; n],
        integral: false,
        k0: 0.0,
    }
}

#[test]
fn lagrangian_objective_never_exceeds_f_on_binary_points() {
    // f_γ = f + Σ γ_t g_t with every triangle and pair inequality and random γ ≥ 0: below f
    // on every binary point (a sign or coefficient error in a cut makes it exceed f).
    let n = 7;
    let p = random_problem(n, false, 31);
    let base = model_of(&p);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let cuts: Vec<_> = triangles::all_cuts(n)
        .into_iter()
        .map(|c| (c, rng.random_range(0.0..2.0)))
        .collect();
    let lm = triangles::lagrangian_model(&base, &cuts);
    let mut b = vec![false; n];
    for mask in 0u32..(1 << n) {
        for (i, bi) in b.iter_mut().enumerate() {
            *bi = (mask >> i) & 1 == 1;
        }
        let (f, fg) = (base.f(&b), lm.f(&b) + lm.k0);
        assert!(fg <= f + 1e-9, "f_γ {fg} > f {f} at {b:?}");
    }
}

#[test]
fn triangle_bound_is_valid_and_tighter_than_the_sdp_bound() {
    // Beasley-like n = 18: the multipliers' root bound never exceeds the enumerated optimum
    // and closes part of the gap left by the plain SDP/QCR bound (measured: see eprintln).
    for seed in [300u64, 301, 302] {
        let p = beasley(18, 0.3, seed);
        let opt = enumerate(&p);
        let mut model = model_of(&p);
        let clock = Clock::new(None);
        let mut mix = sdp::Mixing::new(18);
        let (plain, _) = shift::choose_shift(&mut model, &clock, f64::INFINITY, &mut mix, false);
        eprintln!("seed {seed}: opt {opt} sdp {plain:.2}");
        assert!(plain <= opt + 1e-6);
        let Some((_, bound, _)) =
            triangles::strengthen(&model, &clock, opt, plain, &mut mix, false)
        else {
            panic!("seed {seed}: no multipliers beat the plain bound {plain} (opt {opt})");
        };
        eprintln!("seed {seed}: opt {opt} sdp {plain:.2} triangles {bound:.2}");
        assert!(
            bound <= opt + 1e-6,
            "seed {seed}: bound {bound} > optimum {opt}"
        );
        assert!(bound > plain);
    }
}
