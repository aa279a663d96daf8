use super::*;
use crate::gazefield::init::{init_charges, init_window};
use crate::gazefield::vmf::mean_resultant;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// A sample of the vMF distribution on S² about `mu` (Wood's method, exact for S²).
pub(crate) fn sample_vmf(mu: &Vector3<f64>, kappa: f64, rng: &mut ChaCha8Rng) -> Vector3<f64> {
    let u: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let w = 1.0 + (u + (1.0 - u) * (-2.0 * kappa).exp()).ln() / kappa;
    let phi = 2.0 * PI * rng.random::<f64>();
    let a = if mu.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = mu.cross(&a).normalize();
    let e2 = mu.cross(&e1);
    let s = (1.0 - w * w).max(0.0).sqrt();
    (mu * w + (e1 * phi.cos() + e2 * phi.sin()) * s).normalize()
}

/// Members on two circles around two charges (meeting-like), gaze drawn from the vMF
/// about the direction to their charge.
pub(crate) struct Scene {
    pub rays: Vec<GazeRay>,
    pub charges: Vec<Vector3<f64>>,
    pub assign: Vec<usize>,
}

pub(crate) fn two_groups(
    rng: &mut ChaCha8Rng,
    kappa: f64,
    centres: &[Vector3<f64>],
    per: &[usize],
) -> Scene {
    let mut rays = Vec::new();
    let mut assign = Vec::new();
    let mut charges = Vec::new();
    for (g, (c, &n)) in centres.iter().zip(per).enumerate() {
        let target = c + Vector3::new(
            rng.random::<f64>() * 0.4 - 0.2,
            rng.random::<f64>() * 0.4 - 0.2,
            1.0,
        );
        charges.push(target);
        for m in 0..n {
            let ang = 2.0 * PI * (m as f64 + rng.random::<f64>() * 0.3) / n as f64;
            let rad = 1.2 + rng.random::<f64>() * 0.5;
            let p = c + Vector3::new(
                rad * ang.cos(),
                rad * ang.sin(),
                1.5 + rng.random::<f64>() * 0.3,
            );
            let mu = (target - p).normalize();
            let v = if kappa.is_finite() {
                sample_vmf(&mu, kappa, rng)
            } else {
                mu
            };
            rays.push(GazeRay::new(p, v));
            assign.push(g);
        }
    }
    Scene {
        rays,
        charges,
        assign,
    }
}

fn centres() -> Vec<Vector3<f64>> {
    vec![Vector3::new(-2.5, 0.0, 0.0), Vector3::new(2.5, 0.5, 0.0)]
}

#[test]
fn vmf_sampler_has_the_right_mean_resultant() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mu = Vector3::new(0.3, -0.5, 0.8).normalize();
    for kappa in [2.0, 30.0] {
        let n = 40_000;
        let m: f64 = (0..n)
            .map(|_| sample_vmf(&mu, kappa, &mut rng).dot(&mu))
            .sum::<f64>()
            / n as f64;
        assert!(
            (m - mean_resultant(kappa)).abs() < 0.01,
            "kappa {kappa}: {m}"
        );
    }
}

#[test]
fn exact_rays_give_exact_charges() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let s = two_groups(&mut rng, f64::INFINITY, &centres(), &[6, 5]);
    let init: Vec<_> = s
        .charges
        .iter()
        .map(|c| c + Vector3::new(0.3, -0.25, 0.2))
        .collect();
    let opts = EmOptions {
        kappa: Kappa::Fixed(50.0),
        ..Default::default()
    };
    let fit = em_frame(&s.rays, &init, &opts).unwrap();
    assert!(fit.converged);
    for (c, t) in fit.charges.iter().zip(&s.charges) {
        assert!((c.position - t).norm() < 1e-6, "{} vs {}", c.position, t);
    }
    // Memberships: each member belongs to its own charge; magnitudes count members.
    for (j, &g) in s.assign.iter().enumerate() {
        assert!(fit.responsibilities[j * 2 + g] > 0.99);
    }
    assert!((fit.charges[0].magnitude - 6.0).abs() < 0.05);
    assert!((fit.charges[1].magnitude - 5.0).abs() < 0.05);
}

#[test]
fn noisy_frames_recover_charges_kappa_and_membership() {
    let kappa_true = 40.0; // about 9 degrees of eye-in-head deviation
    let cap2 = 30f64.to_radians().tan().powi(2);
    let mut errs = Vec::new();
    let mut oracle = Vec::new();
    let mut kappas = Vec::new();
    let mut wrong = 0;
    let mut total = 0;
    for seed in 0..40 {
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let s = two_groups(&mut rng, kappa_true, &centres(), &[6, 5]);
        let init = init_charges(&s.rays, 2, 0.2).unwrap();
        let perm = crate::gazefield::init::associate(&s.charges, &init);
        let init: Vec<_> = perm.iter().map(|&j| init[j]).collect();
        let fit = em_frame(&s.rays, &init, &EmOptions::default()).unwrap();
        assert!(fit.converged, "seed {seed}");
        for (c, t) in fit.charges.iter().zip(&s.charges) {
            errs.push((c.position - t).norm());
        }
        // Oracle: Eq 7.12 with the true memberships, started at the truth.
        let frame = WindowFrame {
            rays: s.rays.clone(),
            members: (0..s.rays.len()).collect(),
        };
        for (g, t) in s.charges.iter().enumerate() {
            let w: Vec<f64> = s
                .assign
                .iter()
                .map(|&a| f64::from(u8::from(a == g)))
                .collect();
            let mut x = vec![*t];
            m_step(
                std::slice::from_ref(&frame),
                &[w],
                &mut x,
                cap2,
                0.0,
                &[],
                200,
                1e-12,
            );
            oracle.push((x[0] - t).norm());
        }
        kappas.push(fit.kappa);
        for (j, &g) in s.assign.iter().enumerate() {
            total += 1;
            if fit.responsibilities[j * 2 + g] < 0.5 {
                wrong += 1;
            }
        }
    }
    let median = |mut e: Vec<f64>| {
        e.sort_by(f64::total_cmp);
        e[e.len() / 2]
    };
    let (m_em, m_or) = (median(errs), median(oracle));
    let mean_k = kappas.iter().sum::<f64>() / kappas.len() as f64;
    // The EM, not knowing who looks where, is about as accurate as the intersection with
    // known memberships (members stand 1.2-1.7 m away: 9 degrees is ~0.25 m per ray).
    assert!(
        m_em < 1.15 * m_or && m_em < 0.3,
        "median charge error {m_em}, oracle {m_or}"
    );
    // Few rays per charge bias the ML κ upwards (the fit absorbs part of the noise).
    assert!(
        mean_k > 0.7 * kappa_true && mean_k < 1.8 * kappa_true,
        "kappa {mean_k}"
    );
    assert!(wrong * 50 <= total, "{wrong}/{total} memberships wrong");
}

#[test]
fn m_step_reaches_a_stationary_point_below_its_start() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let s = two_groups(&mut rng, 30.0, &centres(), &[6, 5]);
    let frame = WindowFrame {
        rays: s.rays.clone(),
        members: (0..s.rays.len()).collect(),
    };
    let w: Vec<f64> = s
        .assign
        .iter()
        .map(|&g| if g == 0 { 0.9 } else { 0.05 })
        .collect();
    let cap2 = 75f64.to_radians().tan().powi(2);
    let mut x = vec![s.charges[0] + Vector3::new(0.5, 0.4, -0.3)];
    let start = x[0];
    let frames = std::slice::from_ref(&frame);
    let weights = vec![w.clone()];
    let cost0 = m_step(frames, &weights, &mut x.clone(), cap2, 0.0, &[], 1, 1e-12);
    let c = m_step(frames, &weights, &mut x, cap2, 0.0, &[], 100, 1e-12);
    assert!(c < cost0);
    let f = |p: Vector3<f64>| -> f64 {
        s.rays
            .iter()
            .zip(&w)
            .map(|(r, w)| w * capped_sq(r, &p, cap2))
            .sum()
    };
    assert!(f(x[0]) < f(start));
    // No direction of a small step improves the cost: a local minimum.
    for dir in [
        Vector3::x(),
        Vector3::y(),
        Vector3::z(),
        Vector3::new(1.0, 1.0, 1.0).normalize(),
    ] {
        for h in [1e-4, -1e-4] {
            assert!(f(x[0] + dir * h) >= f(x[0]) - 1e-12);
        }
    }
}

/// Two charges moving smoothly; members follow them at a distance.
fn moving_window(
    seed: u64,
    t_len: usize,
    kappa: f64,
) -> (Vec<WindowFrame>, Vec<Vec<Vector3<f64>>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut frames = Vec::new();
    let mut truth = Vec::new();
    let offsets: Vec<(usize, f64, f64)> = (0..11)
        .map(|j| {
            let g = usize::from(j >= 6);
            let n = if g == 0 { 6.0 } else { 5.0 };
            let k = if g == 0 { j as f64 } else { (j - 6) as f64 };
            (g, 2.0 * PI * k / n, 1.3 + 0.05 * j as f64)
        })
        .collect();
    for t in 0..t_len {
        let s = t as f64 / t_len as f64;
        let c = [
            Vector3::new(-2.5 + 0.8 * s, 0.3 * (3.0 * s).sin(), 1.0),
            Vector3::new(2.5, 0.5 - 0.8 * s, 1.1 + 0.2 * (2.0 * s).cos()),
        ];
        let mut f = WindowFrame::default();
        for (j, &(g, a, r)) in offsets.iter().enumerate() {
            if (t + j) % 13 == 0 {
                continue; // a member now and then unobserved
            }
            let p = c[g] + Vector3::new(r * a.cos(), r * a.sin(), 0.6);
            let v = sample_vmf(&(c[g] - p).normalize(), kappa, &mut rng);
            f.rays.push(GazeRay::new(p, v));
            f.members.push(j);
        }
        frames.push(f);
        truth.push(c.to_vec());
    }
    (frames, truth)
}

fn window_error(fit: &WindowFit, truth: &[Vec<Vector3<f64>>]) -> f64 {
    let mut s = 0.0;
    let mut n = 0;
    for (row, tr) in fit.charges.iter().zip(truth) {
        for (c, x) in row.iter().zip(tr) {
            s += (c.position - x).norm();
            n += 1;
        }
    }
    s / n as f64
}

#[test]
fn temporal_filter_reduces_error_in_a_window() {
    let (frames, truth) = moving_window(11, 80, 25.0);
    let init = init_window(&frames, 2, 0.25).unwrap();
    let perm = crate::gazefield::init::associate(&truth[0], &init[0]);
    let init: Vec<Vec<_>> = init
        .iter()
        .map(|r| perm.iter().map(|&j| r[j]).collect())
        .collect();
    let base = EmOptions {
        kappa: Kappa::Fixed(25.0),
        ..Default::default()
    };
    let free = em_window(&frames, &init, &base).unwrap();
    let vel = em_window(
        &frames,
        &init,
        &EmOptions {
            lambda_g: 50.0,
            ..base
        },
    )
    .unwrap();
    let acc = em_window(
        &frames,
        &init,
        &EmOptions {
            lambda_g: 500.0,
            filter: TemporalFilter::Acceleration,
            ..base
        },
    )
    .unwrap();
    let (e0, e1, e2) = (
        window_error(&free, &truth),
        window_error(&vel, &truth),
        window_error(&acc, &truth),
    );
    eprintln!("window errors: none {e0}, velocity {e1}, acceleration {e2}");
    assert!(e1 < 0.7 * e0, "velocity filter {e1} vs none {e0}");
    assert!(e2 < 0.7 * e0, "acceleration filter {e2} vs none {e0}");
    // The window membership (Eq 7.14) puts each member with its group.
    for j in 0..11 {
        let g = usize::from(j >= 6);
        assert!(
            vel.membership[j * 2 + g] > 0.9,
            "member {j}: {:?}",
            &vel.membership
        );
    }
    // Per-frame membership gives the same groups here.
    let pf = em_window(
        &frames,
        &init,
        &EmOptions {
            lambda_g: 50.0,
            membership: Membership::PerFrame,
            ..base
        },
    )
    .unwrap();
    assert!(window_error(&pf, &truth) < 0.7 * e0);
    // Estimating κ over the window recovers it (many rays: little bias).
    let est = em_window(
        &frames,
        &init,
        &EmOptions {
            lambda_g: 50.0,
            kappa: Kappa::Estimate { initial: 5.0 },
            ..base
        },
    )
    .unwrap();
    assert!((est.kappa / 25.0 - 1.0).abs() < 0.2, "kappa {}", est.kappa);
}

#[test]
fn parallel_batches_match_sequential_runs() {
    let mut rays = Vec::new();
    let mut inits = Vec::new();
    for seed in 0..24 {
        let mut rng = ChaCha8Rng::seed_from_u64(500 + seed);
        let s = two_groups(&mut rng, 20.0, &centres(), &[6, 5]);
        inits.push(init_charges(&s.rays, 2, 0.25).unwrap());
        rays.push(s.rays);
    }
    let opts = EmOptions::default();
    let batch = em_frames(&rays, &inits, &opts).unwrap();
    for ((r, i), b) in rays.iter().zip(&inits).zip(&batch) {
        assert_eq!(&em_frame(r, i, &opts).unwrap(), b);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let single = pool.install(|| em_frames(&rays, &inits, &opts).unwrap());
    assert_eq!(single, batch);
    // Windows in parallel = windows one by one.
    let (frames, _) = moving_window(4, 60, 20.0);
    let jobs: Vec<WindowJob> = [(0, 25), (25, 60)]
        .iter()
        .map(|&(a, b)| WindowJob {
            start: a,
            end: b,
            init: init_window(&frames[a..b], 2, 0.25).unwrap(),
        })
        .collect();
    let o = EmOptions {
        lambda_g: 2.0,
        ..opts
    };
    let par = em_windows(&frames, &jobs, &o).unwrap();
    for (j, p) in jobs.iter().zip(&par) {
        assert_eq!(&em_window(&frames[j.start..j.end], &j.init, &o).unwrap(), p);
    }
}

#[test]
fn windows_split_where_the_count_changes() {
    let w = split_windows(&[2, 2, 2, 1, 1, 1, 1, 2, 2], 1);
    assert_eq!(
        w,
        vec![
            Window {
                start: 0,
                end: 3,
                n_charges: 2
            },
            Window {
                start: 3,
                end: 7,
                n_charges: 1
            },
            Window {
                start: 7,
                end: 9,
                n_charges: 2
            },
        ]
    );
    // A one-frame flicker is absorbed.
    let w = split_windows(&[2, 2, 2, 3, 2, 2, 1, 1, 1, 1], 2);
    assert_eq!(
        w,
        vec![
            Window {
                start: 0,
                end: 6,
                n_charges: 2
            },
            Window {
                start: 6,
                end: 10,
                n_charges: 1
            }
        ]
    );
    let w = split_windows(&[1, 2, 2, 2], 2);
    assert_eq!(
        w,
        vec![Window {
            start: 0,
            end: 4,
            n_charges: 2
        }]
    );
    assert!(split_windows(&[], 3).is_empty());
}

#[test]
fn a_member_exactly_at_a_charge() {
    // Mafia-like: seven players look at player 0's eyes; player 0 looks at player 1.
    let eyes: Vec<Vector3<f64>> = (0..8)
        .map(|j| {
            let a = 2.0 * PI * j as f64 / 8.0;
            Vector3::new(1.5 * a.cos(), 1.5 * a.sin(), 1.2 + 0.05 * j as f64)
        })
        .collect();
    let mut rays = Vec::new();
    for (j, p) in eyes.iter().enumerate() {
        let target = if j == 0 { eyes[1] } else { eyes[0] };
        rays.push(GazeRay::new(*p, (target - p).normalize()));
    }
    // Start with one charge exactly at player 0 and one near player 1.
    let init = vec![eyes[0], eyes[1] + Vector3::new(0.1, 0.1, 0.0)];
    let opts = EmOptions {
        kappa: Kappa::Fixed(30.0),
        ..Default::default()
    };
    let fit = em_frame(&rays, &init, &opts).unwrap();
    assert!(fit.log_likelihood.is_finite());
    assert!(fit.responsibilities.iter().all(|g| g.is_finite()));
    assert!((fit.charges[0].position - eyes[0]).norm() < 1e-6);
    // Player 0 does not look at the charge on its own eyes: all its weight goes to charge 1.
    assert!(fit.responsibilities[1] > 0.999);
    // A single charge sitting on the member's eyes: that ray has no defined direction.
    let fit1 = em_frame(&rays[..1], &[eyes[0]], &opts).unwrap();
    assert_eq!(fit1.responsibilities, vec![0.0]);
    assert!((fit1.log_likelihood + (4.0 * PI).ln()).abs() < 1e-12);
}

#[test]
fn bad_input_is_refused_with_the_argument_named() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let s = two_groups(&mut rng, 30.0, &centres(), &[6, 5]);
    let init = s.charges.clone();
    let arg_of = |r: Result<FrameFit>| match r {
        Err(Error::InvalidInput { arg, .. }) => arg,
        other => panic!("expected InvalidInput, got {other:?}"),
    };
    for k in [0.0, -2.0, f64::NAN] {
        let o = EmOptions {
            kappa: Kappa::Fixed(k),
            ..Default::default()
        };
        assert_eq!(arg_of(em_frame(&s.rays, &init, &o)), "kappa");
        let o = EmOptions {
            kappa: Kappa::Estimate { initial: k },
            ..Default::default()
        };
        assert_eq!(arg_of(em_frame(&s.rays, &init, &o)), "kappa");
    }
    assert_eq!(
        arg_of(em_frame(&s.rays, &[], &EmOptions::default())),
        "n_charges"
    );
    let mut bad = s.rays.clone();
    bad[3].p.y = f64::NAN;
    assert_eq!(arg_of(em_frame(&bad, &init, &EmOptions::default())), "rays");
    let mut bad = s.rays.clone();
    bad[2].v.x = f64::NAN;
    assert_eq!(arg_of(em_frame(&bad, &init, &EmOptions::default())), "rays");
    let mut bad = s.rays.clone();
    bad[2].v *= 2.0;
    assert_eq!(arg_of(em_frame(&bad, &init, &EmOptions::default())), "rays");
    let nan_init = vec![Vector3::new(f64::NAN, 0.0, 0.0)];
    assert_eq!(
        arg_of(em_frame(&s.rays, &nan_init, &EmOptions::default())),
        "init"
    );
    let o = EmOptions {
        lambda_g: -1.0,
        ..Default::default()
    };
    assert_eq!(arg_of(em_frame(&s.rays, &init, &o)), "lambda_g");
    let o = EmOptions {
        max_angle: 2.0,
        ..Default::default()
    };
    assert_eq!(arg_of(em_frame(&s.rays, &init, &o)), "max_angle");
    assert!(matches!(
        init_charges(&s.rays, 0, 0.2),
        Err(Error::InvalidInput { .. })
    ));
    // Diverging rays: nothing to intersect.
    let div = vec![
        GazeRay::new(Vector3::zeros(), Vector3::x()),
        GazeRay::new(Vector3::new(-1.0, 0.0, 0.0), -Vector3::x()),
    ];
    assert!(matches!(
        init_charges(&div, 1, 0.2),
        Err(Error::Degenerate(_))
    ));
    // No rays at all: the EM keeps the start and reports the empty likelihood.
    let fit = em_frame(&[], &init, &EmOptions::default()).unwrap();
    assert_eq!(fit.log_likelihood, 0.0);
    assert_eq!(fit.charges[0].position, init[0]);
}

#[test]
fn init_finds_exact_intersections() {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let s = two_groups(&mut rng, f64::INFINITY, &centres(), &[6, 5]);
    let init = init_charges(&s.rays, 2, 0.1).unwrap();
    let perm = crate::gazefield::init::associate(&s.charges, &init);
    for (i, &j) in perm.iter().enumerate() {
        assert!((init[j] - s.charges[i]).norm() < 1e-9);
    }
    // Three charges from two groups: the two intersections are among them, and the third
    // is a finite point (a repeated candidate).
    let init3 = init_charges(&s.rays, 3, 0.1).unwrap();
    assert_eq!(init3.len(), 3);
    assert!(init3.iter().all(|x| x.iter().all(|v| v.is_finite())));
    for c in &s.charges {
        let nearest = init3
            .iter()
            .map(|x| (x - c).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(nearest < 1e-9, "{nearest}");
    }
}

#[test]
fn init_refuses_more_charges_than_rays() {
    let mut rng = ChaCha8Rng::seed_from_u64(22);
    let s = two_groups(&mut rng, f64::INFINITY, &centres(), &[3, 3]);
    // 50 charges from 6 gaze rays could only repeat the same few points.
    assert!(matches!(
        init_charges(&s.rays, 50, 0.1),
        Err(Error::Degenerate(_))
    ));
    assert_eq!(init_charges(&s.rays, 6, 0.1).map(|v| v.len()), Ok(6));
}
