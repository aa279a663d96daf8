//! Tests of trajectory reconstruction against synthetic ground truth.

use super::testutil::*;
use super::*;
use nalgebra::Vector3;

fn fixed(k: usize) -> TrajectoryOptions {
    TrajectoryOptions {
        k: KSelection::Fixed(k),
        ..Default::default()
    }
}

fn cv(folds: usize, k_max: Option<usize>) -> TrajectoryOptions {
    TrajectoryOptions {
        k: KSelection::CrossValidation {
            folds,
            k_min: 1,
            k_max,
            rule: CvRule::Min,
        },
        ..Default::default()
    }
}

/// A trajectory exactly in the span of the first `k` DCT functions.
fn dct_trajectory(frames: &Frames, k: usize, seed: u64) -> Vec<Vector3<f64>> {
    let mut r = rng(seed);
    let coeffs: Vec<Vector3<f64>> = (0..k)
        .map(|j| {
            let s = if j == 0 { 0.0 } else { 2.0 / (j as f64) };
            Vector3::new(gauss(&mut r), gauss(&mut r), gauss(&mut r)) * s
        })
        .collect();
    let fit = TrajectoryFit {
        k,
        coeffs,
        points: vec![],
        std: vec![],
        covariance: None,
        sigma: 0.0,
        observed: 0,
        rms_linear: 0.0,
        rms: 0.0,
        converged: true,
        iterations: 0,
        rank: 0,
        cond: 0.0,
        cv_error: vec![],
        span: frames.span(),
    };
    fit.at(frames.times())
        .into_iter()
        .map(|p| p + Vector3::new(0.0, 1.0, 0.0))
        .collect()
}

#[test]
fn noise_free_random_cameras_are_exact() {
    let f = 80;
    let mut r = rng(1);
    let cams = random_cameras(&mut r, f);
    let frames = Frames::new(cams.clone(), times(f, 30.0)).unwrap();
    let truth = dct_trajectory(&frames, 7, 2);
    let px = project(&cams, &truth, 0.0, &mut r);
    let size = truth.iter().map(|p| p.norm()).fold(0.0, f64::max);
    for opts in [
        fixed(7),
        TrajectoryOptions {
            refine: false,
            ..fixed(7)
        },
        cv(5, Some(20)),
    ] {
        let fit = reconstruct_trajectory(&frames, &px, &opts).unwrap();
        let err = fit
            .points
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-6 * size, "k={} err={err:e}", fit.k);
        assert!(fit.rms < 1e-6);
        assert_eq!(fit.rank, 3 * fit.k);
        assert!(fit.cond.is_finite());
    }
}

#[test]
fn cross_validation_picks_the_true_complexity_under_noise() {
    let f = 120;
    let mut r = rng(3);
    let cams = random_cameras(&mut r, f);
    let frames = Frames::new(cams.clone(), times(f, 30.0)).unwrap();
    let truth = dct_trajectory(&frames, 6, 4);
    let px = project(&cams, &truth, 1.0, &mut r);
    let fit = reconstruct_trajectory(&frames, &px, &cv(5, Some(25))).unwrap();
    assert!((5..=9).contains(&fit.k), "k = {}", fit.k);
    // The CV curve has its minimum at the chosen K.
    let best = fit.cv_error[fit.k - 1];
    assert!(fit.cv_error.iter().all(|&e| e >= best));
    assert!(rms_error(&fit.points, &truth) < 0.02);
}

#[test]
fn refinement_lowers_reprojection_error() {
    let f = 100;
    let mut r = rng(5);
    let cams = random_cameras(&mut r, f);
    let t = times(f, 30.0);
    let frames = Frames::new(cams.clone(), t.clone()).unwrap();
    let mut lowered = 0;
    for s in 0..5 {
        let truth = smooth_trajectory(&mut r, &t, 0.8);
        let px = project(&cams, &truth, 2.0, &mut r);
        let fit = reconstruct_trajectory(&frames, &px, &fixed(10)).unwrap();
        assert!(fit.converged, "point {s}");
        assert!(fit.rms <= fit.rms_linear * (1.0 + 1e-12));
        if fit.rms < 0.999 * fit.rms_linear {
            lowered += 1;
        }
    }
    assert!(
        lowered >= 4,
        "refinement lowered the error for {lowered}/5 points"
    );
}

#[test]
fn static_points_get_k_one() {
    let f = 40;
    let mut r = rng(7);
    let cams = random_cameras(&mut r, f);
    let frames = Frames::new(cams.clone(), times(f, 10.0)).unwrap();
    let n = 100;
    let mut px = Vec::new();
    for _ in 0..n {
        let x = Vector3::new(gauss(&mut r), 1.0 + 0.5 * gauss(&mut r), gauss(&mut r)) * 0.5;
        px.extend(project(&cams, &vec![x; f], 1.0, &mut r));
    }
    let count = |rule: CvRule| {
        let opts = TrajectoryOptions {
            k: KSelection::CrossValidation {
                folds: 5,
                k_min: 1,
                k_max: None,
                rule,
            },
            ..Default::default()
        };
        reconstruct_trajectories(&frames, &px, n, &opts)
            .unwrap()
            .iter()
            .filter(|f| f.as_ref().map(|f| f.k == 1).unwrap_or(false))
            .count()
    };
    // Plain argmin (Eq 5.8) picks K = 1 for most still points but over-fits a sizeable
    // minority (the held-out gain of 3 noise-fitting parameters is itself noisy); the
    // one-standard-error rule reaches the thesis's > 96 %.
    let plain = count(CvRule::Min);
    let one_se = count(CvRule::OneStandardError);
    assert!(
        plain * 100 > 70 * n,
        "argmin: {plain}/{n} still points got K = 1"
    );
    assert!(
        one_se * 100 > 96 * n,
        "1-SE: {one_se}/{n} still points got K = 1"
    );
}

#[test]
fn smooth_camera_is_worse_than_the_same_positions_shuffled() {
    let f = 100;
    let t = times(f, 15.0);
    let cams = arc_cameras(f, 1.0);
    let mut r = rng(11);
    // Shuffle the capture order (Fig 5.7).
    let mut perm: Vec<usize> = (0..f).collect();
    for i in (1..f).rev() {
        let j = (rand::Rng::random::<f64>(&mut r) * (i + 1) as f64) as usize;
        perm.swap(i, j.min(i));
    }
    let shuffled: Vec<Camera> = perm.iter().map(|&j| cams[j]).collect();
    let (mut e_smooth, mut e_shuf) = (0.0, 0.0);
    let (mut eta_smooth, mut eta_shuf) = (0.0, 0.0);
    for _ in 0..4 {
        let truth = smooth_trajectory(&mut r, &t, 0.6);
        for (set, err, eta) in [
            (&cams, &mut e_smooth, &mut eta_smooth),
            (&shuffled, &mut e_shuf, &mut eta_shuf),
        ] {
            let frames = Frames::new(set.clone(), t.clone()).unwrap();
            let px = project(set, &truth, 1.0, &mut r);
            let fit = reconstruct_trajectory(&frames, &px, &fixed(8)).unwrap();
            *err += rms_error(&fit.points, &truth);
            let centres: Vec<_> = set.iter().map(|c| c.c).collect();
            *eta += reconstructability(&truth, &centres, Some(&t), 8).unwrap();
        }
    }
    assert!(eta_shuf > 10.0 * eta_smooth, "η {eta_smooth} vs {eta_shuf}");
    assert!(e_smooth > 5.0 * e_shuf, "error {e_smooth} vs {e_shuf}");
}

#[test]
fn forty_percent_missing_with_k19_still_reconstructs() {
    let f = 200;
    let t = times(f, 30.0);
    let mut r = rng(13);
    let cams = random_cameras(&mut r, f);
    let frames = Frames::new(cams.clone(), t.clone()).unwrap();
    let truth = walking_trajectory(&t);
    // The best any K = 19 trajectory can do (RMS per frame).
    let floor = null_residual(&truth, Some(&t), 19).unwrap() / (f as f64).sqrt();
    let clean = project(&cams, &truth, 1.0, &mut r);
    let full = reconstruct_trajectory(&frames, &clean, &fixed(19)).unwrap();
    let mut px = project(&cams, &truth, 1.0, &mut r);
    drop_random(&mut px, 0.4, &mut r);
    let fit = reconstruct_trajectory(&frames, &px, &fixed(19)).unwrap();
    let err_full = rms_error(&full.points, &truth);
    let err = rms_error(&fit.points, &truth);
    assert!(fit.observed < 140 && fit.observed > 100);
    assert!(
        err < 1.6 * floor,
        "40 % missing: {err} m vs representation floor {floor} m"
    );
    assert!(
        err < 1.5 * err_full,
        "40 % missing: {err} m vs none missing {err_full} m"
    );
}

#[test]
fn std_matches_monte_carlo_spread() {
    let f = 60;
    let t = times(f, 20.0);
    let mut r = rng(17);
    let cams = random_cameras(&mut r, f);
    let frames = Frames::new(cams.clone(), t.clone()).unwrap();
    let truth = dct_trajectory(&frames, 6, 18);
    let runs = 40;
    let probe = 30;
    let mut samples = Vec::new();
    let mut predicted = Vector3::zeros();
    for _ in 0..runs {
        let px = project(&cams, &truth, 1.0, &mut r);
        let fit = reconstruct_trajectory(&frames, &px, &fixed(6)).unwrap();
        samples.push(fit.points[probe]);
        predicted += fit.std[probe] / runs as f64;
    }
    let mean = samples.iter().sum::<Vector3<f64>>() / runs as f64;
    for c in 0..3 {
        let emp = (samples
            .iter()
            .map(|s| (s[c] - mean[c]).powi(2))
            .sum::<f64>()
            / (runs - 1) as f64)
            .sqrt();
        let ratio = predicted[c] / emp;
        assert!(
            ratio > 0.6 && ratio < 1.6,
            "axis {c}: predicted {} empirical {emp}",
            predicted[c]
        );
    }
}

#[test]
fn at_matches_points_and_batch_matches_single() {
    let f = 50;
    let t = times(f, 30.0);
    let mut r = rng(19);
    let cams = random_cameras(&mut r, f);
    let frames = Frames::new(cams.clone(), t.clone()).unwrap();
    let mut px = Vec::new();
    for _ in 0..6 {
        let truth = smooth_trajectory(&mut r, &t, 0.5);
        let mut p = project(&cams, &truth, 0.5, &mut r);
        drop_random(&mut p, 0.2, &mut r);
        px.extend(p);
    }
    let opts = cv(4, Some(12));
    let batch = reconstruct_trajectories(&frames, &px, 6, &opts).unwrap();
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| reconstruct_trajectories(&frames, &px, 6, &opts).unwrap());
    for (i, (b, b1)) in batch.iter().zip(&one_thread).enumerate() {
        let b = b.as_ref().unwrap();
        let b1 = b1.as_ref().unwrap();
        let single =
            reconstruct_trajectory(&frames, &px[i * 2 * f..(i + 1) * 2 * f], &opts).unwrap();
        assert_eq!(b.k, single.k);
        assert_eq!(b.points, single.points);
        assert_eq!(b.points, b1.points);
        let again = b.at(&t);
        for (a, p) in again.iter().zip(&b.points) {
            assert!((a - p).norm() < 1e-12);
        }
    }
}

#[test]
fn degenerate_systems_name_their_theorem_2_case() {
    let f = 30;
    let t = times(f, 10.0);
    let mut r = rng(23);
    let cams = random_cameras(&mut r, f);
    let frames = Frames::new(cams.clone(), t.clone()).unwrap();
    let truth = smooth_trajectory(&mut r, &t, 0.5);
    let px = project(&cams, &truth, 0.0, &mut r);
    let msg = |e: Error| match e {
        Error::Degenerate(m) => m,
        other => panic!("expected Degenerate, got {other:?}"),
    };

    // Too few observations for K.
    let mut few = px.clone();
    for row in few.chunks_mut(2).skip(5) {
        row.fill(f64::NAN);
    }
    let m = msg(reconstruct_trajectory(&frames, &few, &fixed(4)).unwrap_err());
    assert!(m.contains("too few observations"), "{m}");

    // A still camera.
    let still: Vec<Camera> = (0..f).map(|_| cams[0]).collect();
    let sf = Frames::new(still.clone(), t.clone()).unwrap();
    let spx = project(&still, &truth, 0.0, &mut r);
    let m = msg(reconstruct_trajectory(&sf, &spx, &fixed(3)).unwrap_err());
    assert!(m.contains("does not move"), "{m}");

    // The camera is still relative to the point: it travels with it (X − C constant).
    let d = Vector3::new(0.0, 0.0, 5.0);
    let carried: Vec<Camera> = truth
        .iter()
        .enumerate()
        .map(|(i, x)| look_at(x - d, *x, i))
        .collect();
    let cf = Frames::new(carried.clone(), t.clone()).unwrap();
    let cpx = project(&carried, &truth, 0.0, &mut r);
    let m = msg(reconstruct_trajectory(&cf, &cpx, &fixed(3)).unwrap_err());
    assert!(m.contains("still relative to the point"), "{m}");

    // Theorem 2.i: camera and point trajectories both in col(Θ) for K = 3.
    let span = frames.span();
    let u = |tt: f64| std::f64::consts::PI * (tt - span.t0) / (span.t1 - span.t0);
    let swing: Vec<Camera> = t
        .iter()
        .enumerate()
        .map(|(i, &tt)| {
            let c = Vector3::new(-2.0 + 3.0 * u(tt).cos(), 1.5, -5.0);
            look_at(c, Vector3::new(0.0, 1.0, 0.0), i)
        })
        .collect();
    let lf = Frames::new(swing.clone(), t.clone()).unwrap();
    let moving: Vec<Vector3<f64>> = t
        .iter()
        .map(|&tt| {
            Vector3::new(
                0.3 * u(tt).cos(),
                1.0 + 0.2 * (2.0 * u(tt)).cos(),
                0.1 * u(tt).cos(),
            )
        })
        .collect();
    let lpx = project(&swing, &moving, 0.0, &mut r);
    let m = msg(reconstruct_trajectory(&lf, &lpx, &fixed(3)).unwrap_err());
    assert!(m.contains("Theorem 2.i"), "{m}");
}

#[test]
fn bad_input_is_rejected_with_the_argument_named() {
    let f = 20;
    let t = times(f, 10.0);
    let mut r = rng(29);
    let cams = random_cameras(&mut r, f);
    let frames = Frames::new(cams.clone(), t.clone()).unwrap();
    let truth = smooth_trajectory(&mut r, &t, 0.5);
    let px = project(&cams, &truth, 0.5, &mut r);
    let arg = |e: Error| match e {
        Error::InvalidInput { arg, .. } => arg,
        other => panic!("expected InvalidInput, got {other:?}"),
    };
    let opts = TrajectoryOptions::default();
    assert_eq!(
        arg(reconstruct_trajectory(&frames, &px[..10], &opts).unwrap_err()),
        "x"
    );
    let mut inf = px.clone();
    inf[3] = f64::INFINITY;
    assert_eq!(
        arg(reconstruct_trajectory(&frames, &inf, &opts).unwrap_err()),
        "x"
    );
    let nan = vec![f64::NAN; 2 * f];
    assert_eq!(
        arg(reconstruct_trajectory(&frames, &nan, &opts).unwrap_err()),
        "x"
    );
    assert_eq!(
        arg(Frames::new(cams.clone(), t[..5].to_vec()).unwrap_err()),
        "times"
    );
    let mut bad_t = t.clone();
    bad_t[2] = f64::NAN;
    assert_eq!(arg(Frames::new(cams.clone(), bad_t).unwrap_err()), "times");
    assert_eq!(
        arg(reconstruct_trajectory(&frames, &px, &fixed(0)).unwrap_err()),
        "k"
    );
    assert_eq!(
        arg(reconstruct_trajectory(&frames, &px, &cv(1, None)).unwrap_err()),
        "folds"
    );
    assert_eq!(
        arg(reconstruct_trajectories(&frames, &px, 2, &opts).unwrap_err()),
        "x"
    );
    // A half-missing row counts as missing.
    let mut half = px.clone();
    half[0] = f64::NAN;
    let fit = reconstruct_trajectory(&frames, &half, &fixed(2)).unwrap();
    assert_eq!(fit.observed, f - 1);
}
