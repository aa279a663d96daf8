use super::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

struct Scene {
    cameras: Vec<Camera>,
    parent: Vec<Vector3<f64>>,
    child: Vec<Vector3<f64>>,
    pixels: Vec<Option<Vector2<f64>>>,
    times: Vec<f64>,
    length: f64,
}

/// A stationary camera 4 m away, a moving parent, a child at `length` whose angles are
/// smooth (low-frequency DCT) functions of time, pixel noise `noise` (pixels).
fn scene(f: usize, length: f64, noise: f64, seed: u64) -> Scene {
    scene_with(f, length, noise, seed, 5)
}

/// [`scene`] with the angles in `kt` DCT vectors.
fn scene_with(f: usize, length: f64, noise: f64, seed: u64, kt: usize) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
    let cam = Camera::new(k, Matrix3::identity(), Vector3::new(0.0, 0.0, -4.0), 0).expect("cam");
    let times: Vec<f64> = (0..f).map(|i| i as f64 / 30.0).collect();
    let span = DctSpan::from_times(&times).expect("span");
    let basis = span.matrix(&times, kt).expect("basis");
    let scale = (f as f64).sqrt();
    // Vectors beyond the fifth carry a quarter of the amplitude.
    let high = |j: usize| if j < 5 { 1.0 } else { 0.1 };
    let ct = DVector::from_fn(kt, |j, _| {
        if j == 0 {
            1.4 * scale
        } else {
            rng.random_range(-0.6..0.6) * high(j)
        }
    });
    let cp = DVector::from_fn(kt, |j, _| {
        if j == 0 {
            0.5 * scale
        } else {
            rng.random_range(-1.2..1.2) * high(j)
        }
    });
    let th = &basis * ct;
    let ph = &basis * cp;
    let mut parent = Vec::new();
    let mut child = Vec::new();
    let mut pixels = Vec::new();
    for i in 0..f {
        let t = times[i];
        let p = Vector3::new(0.4 * (1.3 * t).sin(), 0.2 * t - 0.2, 0.3 * (0.9 * t).cos());
        let d = Vector3::new(
            th[i].sin() * ph[i].cos(),
            th[i].sin() * ph[i].sin(),
            th[i].cos(),
        );
        let c = p + d * length;
        let (u, _) = cam.project(&c);
        let nz = Vector2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * noise;
        parent.push(p);
        child.push(c);
        pixels.push(Some(u + nz));
    }
    Scene {
        cameras: vec![cam; f],
        parent,
        child,
        pixels,
        times,
        length,
    }
}

fn rel_error(est: &[Vector3<f64>], s: &Scene) -> f64 {
    let num: f64 = est
        .iter()
        .zip(&s.child)
        .map(|(a, b)| (a - b).norm_squared())
        .sum();
    let den: f64 = s
        .child
        .iter()
        .zip(&s.parent)
        .map(|(c, p)| (c - p).norm_squared())
        .sum();
    (num / den).sqrt()
}

fn opts(k: usize) -> ArticulatedOptions {
    ArticulatedOptions {
        k,
        ..ArticulatedOptions::default()
    }
}

fn thesis(k: usize) -> ArticulatedOptions {
    ArticulatedOptions {
        method: ArticulatedMethod::Thesis,
        ..opts(k)
    }
}

#[test]
fn recovers_smooth_articulated_trajectory() {
    // Sec 4.3 (thesis method): the truth wins when η_a > 1, the impostor when η_a < 1.
    let (mut good, mut bad) = (0, 0);
    for seed in 0..10 {
        let s = scene(60, 0.4, 0.0, seed);
        let eta = reconstructability(&s.cameras, &s.parent, &s.child, &s.times, 8).expect("eta");
        let r = reconstruct_articulated(
            &s.cameras,
            &s.pixels,
            &s.parent,
            &s.times,
            s.length,
            &thesis(8),
        )
        .expect("reconstructs");
        let e = rel_error(&r.points, &s);
        assert!(r.bqp.optimal);
        if eta > 1.1 {
            good += 1;
            assert!(e < 0.02, "seed {seed}: relative error {e}, eta {eta}");
        } else if eta < 0.95 {
            bad += 1;
            assert!(e > 0.3, "seed {seed}: relative error {e}, eta {eta}");
        }
        assert!(r.reprojection_rms < 0.5, "rms {}", r.reprojection_rms);
        for (p, q) in r.points.iter().zip(&s.parent) {
            assert!(((p - q).norm() - r.radius).abs() < 1e-9);
        }
    }
    assert!(good >= 3 && bad >= 2, "good {good}, bad {bad}");
}

#[test]
fn noise_and_missing_frames_are_imputed() {
    let mut s = scene(60, 0.4, 0.3, 4);
    let eta = reconstructability(&s.cameras, &s.parent, &s.child, &s.times, 8).expect("eta");
    assert!(eta > 2.0, "eta {eta}");
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut missing = Vec::new();
    for i in 0..60 {
        if rng.random_range(0.0..1.0) < 0.1 {
            s.pixels[i] = None;
            missing.push(i);
        }
    }
    assert!(!missing.is_empty());
    let r = reconstruct_articulated(
        &s.cameras,
        &s.pixels,
        &s.parent,
        &s.times,
        s.length,
        &opts(8),
    )
    .expect("reconstructs");
    let e = rel_error(&r.points, &s);
    assert!(e < 0.1, "relative error {e}");
    let worst_missing = missing
        .iter()
        .map(|&i| (r.points[i] - s.child[i]).norm())
        .fold(0.0, f64::max);
    assert!(
        worst_missing < 0.15 * s.length,
        "imputed error {worst_missing}"
    );
    assert_eq!(r.n_observed, 60 - missing.len());
}

#[test]
fn small_radius_is_enlarged() {
    let s = scene(60, 0.4, 0.0, 4);
    let r = reconstruct_articulated(
        &s.cameras,
        &s.pixels,
        &s.parent,
        &s.times,
        0.01 * s.length,
        &opts(8),
    )
    .expect("reconstructs");
    assert!(
        r.radius > 0.9 * s.length && r.radius <= s.length * (1.0 + 1e-9),
        "radius {}",
        r.radius
    );
    assert!(rel_error(&r.points, &s) < 0.15);
}

#[test]
fn fitted_radius_shrinks_an_overestimated_length() {
    let s = scene(60, 0.4, 0.0, 4);
    let mut o = opts(8);
    o.fit_radius = true;
    let r = reconstruct_articulated(
        &s.cameras,
        &s.pixels,
        &s.parent,
        &s.times,
        2.0 * s.length,
        &o,
    )
    .expect("reconstructs");
    assert!(
        (r.radius / s.length - 1.0).abs() < 0.02,
        "radius {}",
        r.radius
    );
    assert!(rel_error(&r.points, &s) < 0.05);
}

#[test]
fn unwrap_keeps_angles_continuous() {
    let raw = [
        (0.3, 3.1),
        (0.3, -3.1),
        (0.1, 0.0),
        (0.05, 0.0),
        (0.05, PI),
        (0.1, PI),
    ];
    let u = unwrap_angles(&raw);
    for w in u.windows(2) {
        assert!(
            (w[1].0 - w[0].0).abs() < 1.0 && (w[1].1 - w[0].1).abs() < 0.2,
            "{u:?}"
        );
    }
    let frame = Matrix3::identity();
    for (a, b) in raw.iter().zip(&u) {
        assert!((from_angles(&frame, a.0, a.1) - from_angles(&frame, b.0, b.1)).norm() < 1e-12);
    }
}

#[test]
fn bad_input() {
    let s = scene(20, 0.4, 0.0, 0);
    for len in [0.0, -1.0, f64::NAN] {
        let e = reconstruct_articulated(&s.cameras, &s.pixels, &s.parent, &s.times, len, &opts(4));
        assert!(matches!(e, Err(Error::InvalidInput { ref arg, .. }) if arg == "length"));
    }
    let e = reconstruct_articulated(&s.cameras, &s.pixels, &s.parent, &s.times, 0.4, &opts(30));
    assert!(matches!(e, Err(Error::Degenerate(_))));
    assert!(Skeleton::new(vec![None, Some(0), Some(1)], vec![0.0, 1.0, 1.0]).is_ok());
    // Two roots, cycle, out of range, non-positive bone, self-parent.
    assert!(Skeleton::new(vec![None, None], vec![0.0, 1.0]).is_err());
    assert!(Skeleton::new(vec![None, Some(2), Some(1)], vec![0.0, 1.0, 1.0]).is_err());
    assert!(Skeleton::new(vec![None, Some(5)], vec![0.0, 1.0]).is_err());
    assert!(Skeleton::new(vec![None, Some(0)], vec![0.0, -1.0]).is_err());
    assert!(Skeleton::new(vec![Some(0)], vec![1.0]).is_err());
}

#[test]
fn skeleton_chain_recursive() {
    // root → a → b, both bones following smooth motions.
    let s1 = scene(60, 0.4, 0.0, 4);
    let s2 = scene(60, 0.3, 0.0, 5);
    let root = s1.parent.clone();
    let a = s1.child.clone();
    let b: Vec<Vector3<f64>> = a
        .iter()
        .zip(s2.child.iter().zip(&s2.parent))
        .map(|(x, (c, p))| x + (c - p))
        .collect();
    let cam = s1.cameras[0];
    let pixels: Vec<Vec<Option<Vector2<f64>>>> = (0..60)
        .map(|i| {
            vec![
                Some(cam.project(&root[i]).0),
                Some(cam.project(&a[i]).0),
                Some(cam.project(&b[i]).0),
            ]
        })
        .collect();
    let sk = Skeleton::new(vec![None, Some(0), Some(1)], vec![0.0, 0.4, 0.3]).expect("tree");
    let (pos, res) =
        reconstruct_skeleton(&s1.cameras, &pixels, &sk, &root, &s1.times, &opts(8)).expect("ok");
    assert!(res[0].is_none() && res[1].is_some() && res[2].is_some());
    let eta_b = reconstructability(&s1.cameras, &a, &b, &s1.times, 8).expect("eta");
    assert!(eta_b > 1.1, "eta_b {eta_b}");
    let err_b = pos
        .iter()
        .zip(&b)
        .map(|(p, t)| (p[2] - t).norm())
        .fold(0.0, f64::max);
    assert!(err_b < 0.05, "joint b error {err_b}");
}

#[test]
fn start_selection_trades_cost_against_smoothness() {
    // 50 observations, k = 8: 83 degrees of freedom; lowest cost 83 → σ² = 1 and one
    // standard deviation of the cost √166 ≈ 12.9 px². Weight 2: a tenfold smoother start
    // may cost up to 25.8 px² more.
    let base = (83.0, 1e-3);
    // (starts as (cost, roughness), weight, expected pick, what).
    type Case<'a> = (&'a [(f64, f64)], Option<f64>, Option<usize>, &'a str);
    let cases: [Case; 10] = [
        (
            &[base, (95.0, 1e-4)],
            Some(2.0),
            Some(1),
            "12 px² worse, 10× smoother",
        ),
        (
            &[base, (113.0, 1e-4)],
            Some(2.0),
            Some(0),
            "30 px² worse: rejected",
        ),
        (
            &[base, (123.0, 1e-5)],
            Some(2.0),
            Some(1),
            "40 px² worse, 100× smoother",
        ),
        (
            &[base, (93.0, 0.5e-3)],
            Some(2.0),
            Some(0),
            "10 px² worse, twice as smooth",
        ),
        (
            &[base, (80.0, 1e-4)],
            Some(0.5),
            Some(1),
            "smoother and lower cost",
        ),
        (
            &[(83.0, 1e-9), (84.0, 1e-12)],
            Some(2.0),
            Some(0),
            "below the floor",
        ),
        (&[base, (84.0, 1e-5)], None, Some(0), "selection off"),
        (&[(90.0, 1e-5), base], Some(0.0), Some(1), "weight 0"),
        (
            &[(83.0, f64::NAN), (90.0, 1e-3)],
            Some(2.0),
            Some(1),
            "NaN roughness",
        ),
        (&[], Some(2.0), None, "no start"),
    ];
    for (starts, weight, want, what) in cases {
        // Equal motion: only the cost and the roughness decide.
        let ev: Vec<StartEvidence> = starts
            .iter()
            .map(|&(cost, roughness)| StartEvidence {
                angle: 0.0,
                cost,
                roughness,
                motion: 1.0,
                children: 0.0,
                radius: 1.0,
            })
            .collect();
        for motion in [0.0, 2.0] {
            let w = weight.map(|w| (w, motion, 0.0));
            assert_eq!(select_start(&ev, 50, 8, w), want, "{what}");
        }
    }
}

#[test]
fn start_selection_prefers_the_stiller_of_equal_starts() {
    // σ(cost) ≈ 12.9 px² as above. Default weights (1, 2): a start sweeping ten times less
    // angular variance may cost up to two standard deviations (25.8 px²) more.
    let ev = |cost: f64, roughness: f64, motion: f64| StartEvidence {
        angle: 0.0,
        cost,
        roughness,
        motion,
        children: 0.0,
        radius: 1.0,
    };
    let w = Some((SMOOTH_WEIGHT, MOTION_WEIGHT, 0.0));
    let base = ev(83.0, 1e-3, 4.0);
    // Same cost and roughness, the second moves 10× less: the stiller wins.
    assert_eq!(
        select_start(&[base, ev(83.0, 1e-3, 0.4)], 50, 8, w),
        Some(1)
    );
    // 20 px² worse and 10× stiller: still kept; 30 px² worse: rejected.
    assert_eq!(
        select_start(&[base, ev(103.0, 1e-3, 0.4)], 50, 8, w),
        Some(1)
    );
    assert_eq!(
        select_start(&[base, ev(113.0, 1e-3, 0.4)], 50, 8, w),
        Some(0)
    );
    // 10× stiller but 1000× rougher: the smoothness of Eq 4.12 outweighs (1·3 > 2·1).
    assert_eq!(select_start(&[base, ev(83.0, 1.0, 0.4)], 50, 8, w), Some(0));
    // The motion term off: equal scores, the first (lowest) kept; NaN motion never wins.
    assert_eq!(
        select_start(&[base, ev(83.0, 1e-3, 0.4)], 50, 8, Some((1.0, 0.0, 0.0))),
        Some(0)
    );
    assert_eq!(
        select_start(&[base, ev(80.0, 1e-3, f64::NAN)], 50, 8, w),
        Some(0)
    );
}

#[test]
fn final_refinement_grows_the_basis_to_the_motion() {
    // The angles use 5 DCT vectors; the binary program and the start selection run at
    // k = 3. The selected start refined again with up to `refine_k_max` vectors (size by
    // BIC) must fit the pixels to the noise and track the truth far better than at k = 3.
    // Measured (seeds 0–5, uniform noise ±0.5 px, RMS 0.41): grown k' 5–8, error
    // 0.004–0.072, RMS 0.33–0.42 px; at k = 3 error 0.28–0.36, RMS 8–15 px.
    for seed in 0..6 {
        let s = scene(60, 0.4, 0.5, seed);
        let run = |refine_k_max: usize| {
            let o = ArticulatedOptions {
                refine_k_max,
                average_starts: false,
                ..opts(3)
            };
            reconstruct_articulated(&s.cameras, &s.pixels, &s.parent, &s.times, s.length, &o)
                .expect("reconstructs")
        };
        let (grown, fixed) = (run(16), run(0));
        let (eg, ef) = (rel_error(&grown.points, &s), rel_error(&fixed.points, &s));
        let msg = format!(
            "seed {seed}: k' {} error {eg:.4} rms {:.3}; k = 3 error {ef:.4} rms {:.3}",
            grown.coeffs_theta.len(),
            grown.reprojection_rms,
            fixed.reprojection_rms
        );
        assert_eq!(fixed.coeffs_theta.len(), 3, "{msg}");
        // BIC, not the lowest cost: the angles use 5 vectors, so no size near 16.
        assert!((4..=10).contains(&grown.coeffs_theta.len()), "{msg}");
        assert!(grown.reprojection_rms < 0.5, "{msg}");
        assert!(eg < 0.1 && ef > 0.25 && eg < ef / 3.0, "{msg}");
    }
}

#[test]
fn default_refinement_grows_beyond_twice_k() {
    // A window spanning more motion than 2k vectors (as 60 frames at 20-30 Hz of walking):
    // the angles use 24 DCT vectors over 120 frames, the program and the selection run at
    // k = 8. The default refine_k_max lets BIC pick a size above 16 (the cap of sessions
    // 8-17), where the fit reaches the noise; capped at 16 it misses the pixels by several
    // noise levels. Measured (seeds 0-5, uniform noise ±0.5 px, RMS 0.41): k' 24, RMS
    // 0.34-0.38 px, error 0.007-0.034 against capped RMS 1.24-1.67 px, error 0.022-0.044
    // (seed 1 keeps the other branch either way: 0.60 / 0.53).
    let mut better = 0;
    for seed in 0..6 {
        let s = scene_with(120, 0.4, 0.5, seed, 24);
        let run = |refine_k_max: usize| {
            let o = ArticulatedOptions {
                refine_k_max,
                ..opts(8)
            };
            reconstruct_articulated(&s.cameras, &s.pixels, &s.parent, &s.times, s.length, &o)
                .expect("reconstructs")
        };
        let (grown, capped) = (run(REFINE_K_MAX), run(16));
        let (eg, ec) = (rel_error(&grown.points, &s), rel_error(&capped.points, &s));
        let msg = format!(
            "seed {seed}: k' {} error {eg:.4} rms {:.3}; capped k' {} error {ec:.4} rms {:.3}",
            grown.coeffs_theta.len(),
            grown.reprojection_rms,
            capped.coeffs_theta.len(),
            capped.reprojection_rms
        );
        assert!(grown.coeffs_theta.len() > 16, "{msg}");
        assert!(grown.reprojection_rms < 0.5, "{msg}");
        assert!(capped.reprojection_rms > 1.0, "{msg}");
        better += usize::from(eg < ec);
    }
    assert!(better >= 5, "error lower on {better} of 6 seeds");
}

#[test]
fn children_out_of_reach_outweigh_a_better_fit() {
    // A joint 2 m in front of a camera (f = 1000 px); its child's ray passes 0.35 m from it
    // for a 0.3 m bone: beyond the 10 % slack (0.33 m) by 0.02 m = 10 px at that depth.
    let cam = Camera::new(
        Matrix3::new(1000.0, 0.0, 0.0, 0.0, 1000.0, 0.0, 0.0, 0.0, 1.0),
        Matrix3::identity(),
        Vector3::zeros(),
        0,
    )
    .unwrap();
    let joint = Vector3::new(0.0, 0.0, 2.0);
    // The pixel whose ray passes 0.35 m from the joint: tan = 0.35 / √(2² − 0.35²).
    let child_px = Some(Vector2::new(
        1000.0 * 0.35 / (4.0f64 - 0.35 * 0.35).sqrt(),
        0.0,
    ));
    let kids = [ChildObservations {
        pixels: vec![child_px, None],
        length: 0.3,
    }];
    let miss = children_miss(&[cam, cam], &kids, &[joint, joint], 0.1);
    assert!((miss - 100.0).abs() < 1e-6, "{miss}");
    // Within reach: no cost.
    let near = [ChildObservations {
        pixels: vec![child_px, None],
        length: 0.33,
    }];
    assert_eq!(children_miss(&[cam, cam], &near, &[joint, joint], 0.1), 0.0);
    // Two starts alike but for 1 px² of fit: the one whose children are out of reach by
    // 100 px² loses; without children the better fit wins.
    let ev = |cost: f64, children: f64| StartEvidence {
        angle: 0.0,
        cost,
        roughness: 1e-3,
        motion: 1.0,
        children,
        radius: 1.0,
    };
    let w = Some((SMOOTH_WEIGHT, MOTION_WEIGHT, 0.0));
    assert_eq!(
        select_start(&[ev(100.0, 100.0), ev(101.0, 0.0)], 50, 8, w),
        Some(1)
    );
    assert_eq!(
        select_start(&[ev(100.0, 0.0), ev(101.0, 0.0)], 50, 8, w),
        Some(0)
    );
}

#[test]
fn starts_are_averaged_by_the_exponential_of_their_score() {
    // σ(cost) ≈ 12.9 px² (50 observations, k = 8). Equal roughness; the second start moves
    // 10× less (−2 in score, default weights) and costs one σ more (+1): it scores 1 lower
    // and weighs e^λ (λ = AVERAGE_SHARPNESS) times as much as the first. The third never
    // counts (NaN motion).
    let ev = |cost: f64, motion: f64| StartEvidence {
        angle: 0.0,
        cost,
        roughness: 1e-3,
        motion,
        children: 0.0,
        radius: 1.0,
    };
    let sd = (2.0f64 * 83.0).sqrt() * 80.0 / 83.0;
    let starts = [ev(80.0, 4.0), ev(80.0 + sd, 0.4), ev(70.0, f64::NAN)];
    let w = Some((SMOOTH_WEIGHT, MOTION_WEIGHT, 0.0));
    // The cost floor is the NaN start's 70 px², so recompute σ from it.
    let sc = start_scores(&starts, 50, 8, w).unwrap();
    assert!(sc[2].is_infinite());
    let weights = start_weights(&sc).unwrap();
    let want = (AVERAGE_SHARPNESS * (sc[0] - sc[1])).exp();
    assert!(
        (weights[1] / weights[0] - want).abs() < 1e-12,
        "{weights:?}"
    );
    assert!(sc[0] > sc[1], "{sc:?}");
    assert!((weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    assert_eq!(weights[2], 0.0);
    // Without the NaN start the score gap is 1: weights e^λ/(1+e^λ) and 1/(1+e^λ).
    let sc = start_scores(&starts[..2], 50, 8, w).unwrap();
    assert!((sc[0] - sc[1] - 1.0).abs() < 1e-5, "{sc:?}");
    let weights = start_weights(&sc).unwrap();
    let e = AVERAGE_SHARPNESS.exp();
    assert!((weights[1] - e / (1.0 + e)).abs() < 1e-5, "{weights:?}");
    // The best start of the average is the one `select_start` keeps.
    assert_eq!(select_start(&starts[..2], 50, 8, w), Some(1));
    // No weights (lowest cost kept): no scores, nothing to average.
    assert!(start_scores(&starts, 50, 8, None).is_none());
    assert!(start_weights(&[f64::INFINITY]).is_none());
    // The same solution found twice counts once: starts within 1 cm (RMS) of a better one
    // are dropped, farther ones kept, best score first.
    let traj = |x: f64| vec![Vector3::new(x, 0.0, 0.0); 4];
    let pts = [traj(0.0), traj(0.005), traj(0.3), traj(0.302)];
    assert_eq!(
        distinct_starts(&pts, &[1.0, 0.0, 2.0, 3.0], 0.01),
        vec![1, 2]
    );
    assert_eq!(
        distinct_starts(&pts, &[1.0, 0.0, 2.0, f64::INFINITY], 0.001),
        vec![1, 0, 2]
    );
}

#[test]
fn the_best_start_of_another_basin_gives_the_margin() {
    // Bone 0.5 m: another basin lies farther than 0.05 m (RMS) from the selected start.
    let traj = |x: f64| vec![Vector3::new(x, 0.0, 0.0); 4];
    let pts = [traj(0.0), traj(0.02), traj(0.3), traj(0.2), traj(0.4)];
    // Start 1 is the same basin (2 cm), however close its score; start 3 beats start 2 and
    // start 4 does not count (not a number).
    let scores = [-1.0, -0.99, 0.5, -0.7, f64::NAN];
    let (margin, alt) = other_basin(&pts, &scores, 0, 0.5);
    assert_eq!(alt, Some(3));
    assert!((margin - 0.3).abs() < 1e-12, "{margin}");
    // Nothing farther than a tenth of the bone: no alternative.
    let (margin, alt) = other_basin(&pts[..2], &scores[..2], 0, 0.5);
    assert!(margin.is_infinite() && alt.is_none());
    // A longer bone makes the same starts one basin.
    let (_, alt) = other_basin(&pts[..4], &scores[..4], 0, 4.0);
    assert!(alt.is_none());
}

#[test]
fn the_result_reports_its_margin() {
    let s = scene(40, 0.4, 0.5, 3);
    let run = |o: &ArticulatedOptions| {
        reconstruct_articulated(&s.cameras, &s.pixels, &s.parent, &s.times, s.length, o)
    };
    let robust = run(&ArticulatedOptions::default()).expect("robust");
    assert!(
        robust.selection_margin >= 0.0,
        "{}",
        robust.selection_margin
    );
    if let Some(alt) = &robust.alternative {
        assert_eq!(alt.len(), 40);
        assert!(robust.selection_margin.is_finite());
    } else {
        assert!(robust.selection_margin.is_infinite());
    }
    let thesis = run(&ArticulatedOptions {
        method: ArticulatedMethod::Thesis,
        ..Default::default()
    })
    .expect("thesis");
    assert!(thesis.selection_margin.is_infinite() && thesis.alternative.is_none());
}

#[test]
fn of_starts_alike_the_shorter_bone_wins() {
    // σ(cost) ≈ 12.9 px² (50 observations, k = 8). Two starts alike in roughness and motion;
    // the second fits 6 px² (about half a σ) worse with a 5 % shorter bone: with the
    // default length weight (20 · ln 1.05 ≈ 0.98 σ) it wins, without it the better fit.
    let ev = |cost: f64, radius: f64| StartEvidence {
        angle: 0.0,
        cost,
        roughness: 1e-3,
        motion: 1.0,
        children: 0.0,
        radius,
    };
    let starts = [ev(83.0, 0.42), ev(89.0, 0.40)];
    let on = Some((SMOOTH_WEIGHT, MOTION_WEIGHT, LENGTH_WEIGHT));
    let off = Some((SMOOTH_WEIGHT, MOTION_WEIGHT, 0.0));
    assert_eq!(select_start(&starts, 50, 8, on), Some(1));
    assert_eq!(select_start(&starts, 50, 8, off), Some(0));
    // 20 px² (1.5 σ) worse: the better fit wins even with the shorter bone.
    assert_eq!(
        select_start(&[ev(83.0, 0.42), ev(103.0, 0.40)], 50, 8, on),
        Some(0)
    );
    // The length alone turns the selection on, and the score is relative to the shortest
    // bone: 20 · ln(0.42 / 0.40) above it.
    let sc = start_scores(&starts, 50, 8, Some((0.0, 0.0, LENGTH_WEIGHT))).unwrap();
    let sd = (2.0f64 * 83.0).sqrt() * 83.0 / 83.0;
    assert!(
        (sc[0] - LENGTH_WEIGHT * (0.42f64 / 0.40).ln()).abs() < 1e-9,
        "{sc:?}"
    );
    assert!((sc[1] - 6.0 / sd).abs() < 1e-9, "{sc:?}");
}

#[test]
fn angle_excess_is_the_angle_outside_the_range() {
    let deg = std::f64::consts::PI / 180.0;
    let reference = vec![Vector3::new(0.0, 1.0, 0.0); 3];
    let p = vec![Vector3::zeros(); 3];
    // Along the reference (0°), at right angles (90°), against it (180°).
    let x = vec![
        Vector3::new(0.0, 0.5, 0.0),
        Vector3::new(0.3, 0.0, 0.0),
        Vector3::new(0.0, -0.2, 0.0),
    ];
    let e = angle_excess(&x, &p, &reference, (10.0 * deg, 100.0 * deg));
    let want = [10.0 * deg, 0.0, 80.0 * deg];
    for (a, b) in e.iter().zip(want) {
        assert!((a - b).abs() < 1e-12, "{e:?}");
    }
    // A bone without length leaves no range.
    let e = angle_excess(&p, &p, &reference, (10.0 * deg, 20.0 * deg));
    assert_eq!(e, vec![0.0; 3]);
}

#[test]
fn the_priors_choose_the_root_per_frame() {
    // Three frames; the reference bone points up (+y), the range is 0°..30°. Frame 0: ¹χ up,
    // ²χ down → ¹χ. Frame 1: ¹χ down, ²χ tilted 45° → ²χ (out by less). Frame 2: both at
    // right angles (same excess) → the fallback's root.
    let up = Vector3::new(0.0, 1.0, 0.0);
    let tilt = Vector3::new(1.0, 1.0, 0.0).normalize();
    let side = Vector3::new(1.0, 0.0, 0.0);
    let cand = Candidates {
        frames: vec![0, 1, 2],
        chi1: vec![up, -up, side],
        chi2: vec![-up, tilt, -side],
        radius: 1.0,
    };
    let parent = vec![Vector3::new(0.5, 0.0, 2.0); 3];
    let prior = AnglePrior {
        reference: vec![up * 0.3; 3],
        range: (0.0, 30f64.to_radians()),
    };
    let p = std::slice::from_ref(&prior);
    assert_eq!(
        prior_choice(&cand, &parent, p, &[false, true, true]),
        vec![true, false, true]
    );
    assert_eq!(
        prior_choice(&cand, &parent, p, &[false, true, false]),
        vec![true, false, false]
    );
    // A second prior that prefers ²χ at frame 0 more strongly than the first prefers ¹χ.
    let down = AnglePrior {
        reference: vec![-up; 3],
        range: (0.0, 0.0),
    };
    let both = [prior.clone(), down.clone(), down];
    assert!(!prior_choice(&cand, &parent, &both, &[true; 3])[0]);
}

#[test]
fn the_refinement_pulls_the_bone_into_the_priors_range() {
    // The parent given 3 cm off; a prior that the bone keeps within 1° of its true
    // direction. With angle_refine the refined bone leaves that range by less, and the
    // pixels still hold it (the reprojection error stays near the noise).
    let s = scene(40, 0.4, 0.5, 5);
    let off: Vec<Vector3<f64>> = s
        .parent
        .iter()
        .map(|p| p + Vector3::new(0.03, -0.01, 0.01))
        .collect();
    let truth: Vec<Vector3<f64>> = s.child.iter().zip(&s.parent).map(|(c, p)| c - p).collect();
    let prior = AnglePrior {
        reference: truth,
        range: (0.0, 1f64.to_radians()),
    };
    let run = |w: f64| {
        let o = ArticulatedOptions {
            angle_refine: w,
            // the pull itself, on every frame however far out
            angle_cap: f64::INFINITY,
            ..opts(6)
        };
        reconstruct_articulated_prior(
            &s.cameras,
            &s.pixels,
            &off,
            &s.times,
            s.length,
            &[],
            std::slice::from_ref(&prior),
            &o,
        )
        .expect("reconstruction")
    };
    let excess = |r: &ArticulatedResult| -> f64 {
        angle_excess(&r.points, &off, &prior.reference, prior.range)
            .iter()
            .sum::<f64>()
            / r.points.len() as f64
    };
    let (plain, pulled) = (run(0.0), run(10.0));
    assert!(
        excess(&pulled) < 0.7 * excess(&plain),
        "{} {}",
        excess(&pulled),
        excess(&plain)
    );
    assert!(pulled.reprojection_rms < 3.0, "{}", pulled.reprojection_rms);
}

#[test]
fn the_angle_prior_outweighs_a_slightly_better_fit() {
    // σ(cost) ≈ 12.9 px² (50 observations, k = 8). The impostor fits 6 px² better (half a
    // σ) but leaves a prior's range: an angle score of 2 (out by 1.4 tolerances on average)
    // hands the selection to the start inside it; a score of 0.2 does not.
    let ev = |cost: f64, angle: f64| StartEvidence {
        cost,
        roughness: 1e-3,
        motion: 1.0,
        radius: 0.4,
        angle,
        ..Default::default()
    };
    let w = Some((SMOOTH_WEIGHT, MOTION_WEIGHT, 0.0));
    assert_eq!(
        select_start(&[ev(89.0, 0.0), ev(83.0, 2.0)], 50, 8, w),
        Some(0)
    );
    assert_eq!(
        select_start(&[ev(89.0, 0.0), ev(83.0, 0.2)], 50, 8, w),
        Some(1)
    );
    assert_eq!(
        select_start(&[ev(89.0, 0.0), ev(83.0, 0.0)], 50, 8, w),
        Some(1)
    );
}

#[test]
fn angle_priors_are_checked_and_ignored_at_weight_zero() {
    let s = scene(40, 0.4, 0.5, 3);
    let o = opts(6);
    let prior = AnglePrior {
        reference: vec![Vector3::new(0.0, 0.3, 0.0); s.cameras.len()],
        range: (0.0, 0.2),
    };
    let run = |priors: &[AnglePrior], o: &ArticulatedOptions| {
        reconstruct_articulated_prior(
            &s.cameras,
            &s.pixels,
            &s.parent,
            &s.times,
            s.length,
            &[],
            priors,
            o,
        )
    };
    let plain = run(&[], &o).expect("plain");
    let off = run(
        std::slice::from_ref(&prior),
        &ArticulatedOptions {
            angle_weight: 0.0,
            ..o
        },
    )
    .expect("weight 0");
    assert_eq!(plain.points, off.points);
    // With a weight the priors are read (whatever they select, the call succeeds).
    run(&[prior.clone(), prior.clone()], &o).expect("with the priors");
    let bad = |b: AnglePrior, o: &ArticulatedOptions, what: &str| match run(&[b], o) {
        Err(Error::InvalidInput { arg, .. }) => assert!(arg == what, "{arg}"),
        other => panic!(
            "{what}: expected an error, got {:?}",
            other.map(|r| r.radius)
        ),
    };
    let with = |f: &dyn Fn(&mut AnglePrior)| {
        let mut b = prior.clone();
        f(&mut b);
        b
    };
    bad(with(&|b| b.range = (0.3, 0.2)), &o, "angle_priors");
    bad(with(&|b| b.range = (0.0, 4.0)), &o, "angle_priors");
    bad(with(&|b| b.reference.truncate(5)), &o, "angle_priors");
    bad(with(&|b| b.reference[3].x = f64::NAN), &o, "angle_priors");
    let zero_tol = ArticulatedOptions {
        angle_tolerance: 0.0,
        ..o
    };
    bad(prior.clone(), &zero_tol, "angle_tolerance");
    let negative = ArticulatedOptions {
        angle_weight: -1.0,
        ..o
    };
    bad(prior.clone(), &negative, "angle_weight");
    let pull = ArticulatedOptions {
        angle_refine: f64::NAN,
        ..o
    };
    bad(prior.clone(), &pull, "angle_refine");
    for cap in [0.0, -1.0, f64::NAN] {
        let capped = ArticulatedOptions {
            angle_cap: cap,
            ..o
        };
        bad(prior.clone(), &capped, "angle_cap");
    }
}
