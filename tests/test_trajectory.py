"""Trajectory reconstruction of moving points (thesis Chapter 5) against ground truth from
``socialcam.synth`` and real CMU motion capture. Each test states the finding it reproduces
and the threshold it holds the implementation to."""

from __future__ import annotations

import json

import numpy as np
import pytest

import socialcam as sc
from socialcam import synth
from socialcam.camera import Cameras
from socialcam.mocap import load_bvh, load_c3d
from socialcam.trajectory import null_residual

# CMU files are y-up; socialcam.synth puts the ground plane at z = 0 (z up).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def rms_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-point RMS 3D distance over frames: ``(..., F, 3)`` → ``(...)``."""
    return np.sqrt(((a - b) ** 2).sum(-1).mean(-1))


def dct_trajectories(n: int, times: np.ndarray, k: int, seed: int) -> np.ndarray:
    """``n`` trajectories ``(n, F, 3)`` exactly in the span of the first ``k`` DCT functions
    (decaying random coefficients), moving ~0.5 m around (0, 0, 1)."""
    rng = np.random.default_rng(seed)
    theta = sc.dct_basis(times, k)
    scale = np.sqrt(len(times)) * 0.3 / np.arange(1, k + 1)
    beta = rng.normal(size=(n, k, 3)) * scale[None, :, None]
    beta[:, 0] = 0.0
    return np.einsum("fk,nkc->nfc", theta, beta) + np.array([0.0, 0.0, 1.0])


def shuffled(cams: Cameras, seed: int) -> Cameras:
    """The same capture positions in a random order (times unchanged)."""
    p = np.random.default_rng(seed).permutation(len(cams))
    return Cameras(cams.K[p], cams.R[p], cams.C[p], cams.times)


def walking_markers(data_dir) -> tuple[np.ndarray, np.ndarray]:
    """Real walking: the 31 joints of CMU 131_01 (300 frames, 120 Hz) as ``(J, F, 3)``
    metres, z up, centred on (0, 0, 1); and the frame times."""
    m = load_bvh(data_dir / "mocap" / "cmu_131_01_walk300.bvh")
    p = m.positions @ Y_UP_TO_Z_UP.T
    p = p - p.reshape(-1, 3).mean(0) + np.array([0.0, 0.0, 1.0])
    return np.transpose(p, (1, 0, 2)), np.arange(p.shape[0]) / m.fps


# --------------------------------------------------------------------------- accuracy


def test_noise_free_random_cameras_reconstruct_to_machine_precision():
    """Many photographers, no noise, trajectories inside the DCT span: the reconstruction
    is exact — max error below 1e-6 of the scene size, with K chosen automatically."""
    f = 120
    cams = synth.random_photographers(f, seed=1)
    X = dct_trajectories(20, cams.times, 8, seed=2)
    obs = synth.observe(X, cams, noise_px=0.0, seed=3)
    b = sc.reconstruct_trajectories(obs.x, cams, k_max=25)
    assert b.ok.all()
    size = np.ptp(X.reshape(-1, 3), axis=0).max()
    err = np.linalg.norm(b.points - X, axis=-1).max()
    assert err < 1e-6 * size, (err, size)
    assert (b.k >= 8).all()
    assert (b.rms < 1e-6).all()


def test_error_falls_as_reconstructability_rises():
    """Fig 5.6b: bin reconstructions by η; the 3D error falls from bin to bin. Camera
    trajectories range from a smooth arc (low η) to the same arc with growing random jumps
    (high η); one trajectory, K = 10, 1 px noise."""
    f = 150
    base = synth.smooth_path(f, seed=4, arc_deg=40.0)
    X = synth.smooth_trajectories(1, base.times, seed=5, extent=0.6)[0]
    rng = np.random.default_rng(6)
    etas, errs = [], []
    for jump in np.linspace(0.0, 3.0, 24):
        C = base.C + jump * rng.normal(size=base.C.shape)
        R = synth.look_at(C, np.array([0.0, 0.0, 1.0]))
        cams = Cameras(base.K, R, C, base.times)
        obs = synth.observe(X[None], cams, noise_px=1.0, seed=int(jump * 100))
        tr = sc.reconstruct_trajectory(obs.x[0], cams, k=10)
        etas.append(sc.reconstructability(X, C, 10, times=base.times))
        errs.append(rms_3d(tr.points, X))
    order = np.argsort(etas)
    bins = [np.median(np.asarray(errs)[order[i : i + 8]]) for i in (0, 8, 16)]
    assert bins[0] > bins[1] > bins[2], bins
    # The high-η bins approach the floor set by what K = 10 cannot represent (~2 cm here).
    assert bins[0] > 2 * bins[2], bins


def test_smooth_camera_is_much_worse_than_the_same_positions_shuffled():
    """Fig 5.7: same capture positions; a smooth order gives low η and a poor
    reconstruction, a shuffled order high η and an accurate one (≥ 5× less error)."""
    f = 120
    smooth = synth.smooth_path(f, seed=7, arc_deg=30.0)
    rand = shuffled(smooth, seed=8)
    X = synth.smooth_trajectories(8, smooth.times, seed=9, extent=0.6)
    e, eta = {}, {}
    for name, cams in (("smooth", smooth), ("shuffled", rand)):
        obs = synth.observe(X, cams, noise_px=1.0, seed=10)
        b = sc.reconstruct_trajectories(obs.x, cams, k=10)
        assert b.ok.all()
        e[name] = np.median(rms_3d(b.points, X))
        eta[name] = np.median([sc.reconstructability(x, cams.C, 10, times=cams.times) for x in X])
        # The reported uncertainty tells the two apart as well (Fig 5.7, right column).
        e[name + "_std"] = np.median(np.linalg.norm(b.std, axis=-1))
    assert eta["shuffled"] > 10 * eta["smooth"], eta
    assert e["smooth"] > 5 * e["shuffled"], e
    assert e["smooth_std"] > 5 * e["shuffled_std"], e


def test_missing_data_and_low_frame_rates_degrade_gracefully(data_dir):
    """Fig 5.10 on real walking (CMU 131_01, 31 joints): with K = 19, 40 % random missing
    data costs less than 30 % extra error over none; halving and quartering the frame rate
    raise the error gradually (each step < 1.5×)."""
    X, times = walking_markers(data_dir)
    cams = synth.random_photographers(len(times), seed=11, times=times)
    err = {}
    for miss in (0.0, 0.2, 0.4, 0.6):
        obs = synth.observe(X, cams, noise_px=1.0, missing=miss, seed=12)
        b = sc.reconstruct_trajectories(obs.x, cams, k=19)
        assert b.ok.all()
        err[miss] = rms_3d(b.points, X).mean()
    assert err[0.4] < 1.3 * err[0.0], err
    assert err[0.0] <= err[0.2] <= err[0.4] <= err[0.6], err
    assert err[0.4] < 0.02, err  # 2 cm on a 3 m walk
    rate = {}
    for step in (1, 2, 4):
        sub = cams[::step]
        obs = synth.observe(X[:, ::step], sub, noise_px=1.0, seed=13)
        b = sc.reconstruct_trajectories(obs.x, sub, k=19)
        rate[step] = rms_3d(b.points, X[:, ::step]).mean()
    assert rate[1] < rate[2] < rate[4] < 1.5 * rate[2] < 2.25 * rate[1], rate


def test_static_points_get_k_one():
    """Sec 5.3.2: still points should get K = 1 (> 96 % in the thesis). The one-standard-
    error rule reaches that; plain argmin of Eq 5.8 over-fits a minority, which we bound."""
    f = 40
    cams = synth.random_photographers(f, seed=14, fps=10.0)
    pts = synth.random_points(200, seed=15)
    X = np.repeat(pts[:, None], f, axis=1)
    obs = synth.observe(X, cams, noise_px=1.0, seed=16)
    one_se = sc.reconstruct_trajectories(obs.x, cams, cv_rule="1se")
    plain = sc.reconstruct_trajectories(obs.x, cams)
    assert (one_se.k == 1).mean() > 0.96, np.bincount(one_se.k)
    assert (plain.k == 1).mean() > 0.70, np.bincount(plain.k)


def test_per_point_k_beats_any_single_k_on_mixed_scene():
    """Fig 5.13: a scene of still and fast points. Per-point cross-validated K gives a
    lower mean 3D error than any one K for all points."""
    f = 150
    cams = synth.random_photographers(f, seed=17)
    slow = synth.smooth_trajectories(15, cams.times, seed=18, static_fraction=1.0)
    fast = synth.smooth_trajectories(15, cams.times, seed=19, frequency=1.0, extent=0.8)
    X = np.concatenate([slow, fast])
    obs = synth.observe(X, cams, noise_px=2.0, seed=20)
    auto = rms_3d(sc.reconstruct_trajectories(obs.x, cams, k_max=40).points, X).mean()
    fixed = {
        k: rms_3d(sc.reconstruct_trajectories(obs.x, cams, k=k).points, X).mean()
        for k in (3, 8, 14, 20, 30)
    }
    assert auto < min(fixed.values()), (auto, fixed)


def test_refinement_lowers_reprojection_error():
    """Eq 5.9: the refined solution reprojects better than the linear one (never worse;
    strictly better for nearly every point)."""
    f = 100
    cams = synth.random_photographers(f, seed=21)
    X = synth.smooth_trajectories(30, cams.times, seed=22)
    obs = synth.observe(X, cams, noise_px=2.0, missing=0.1, seed=23)
    b = sc.reconstruct_trajectories(obs.x, cams, k=12)
    assert b.converged.all()
    assert (b.rms <= b.rms_linear * (1 + 1e-12)).all()
    assert (b.rms < 0.999 * b.rms_linear).mean() > 0.9
    lin = sc.reconstruct_trajectories(obs.x, cams, k=12, refine=False)
    np.testing.assert_allclose(lin.rms, b.rms_linear)
    assert (lin.iterations == 0).all()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refinement_lowers_the_3d_error_of_the_linear_solution(seed):
    """Eq 5.9 is a stage of its own: the linear solution minimises an algebraic error that
    weighs each photo by its depth, so with photographers between 1.5 and 15 m away the
    refined trajectories are much closer to the truth. Trajectories in the span of K = 8,
    2 px noise. Measured over seeds 0–2: linear/refined mean 3D error 1.40, 1.63, 1.43;
    97–100 % of the points improve."""
    f = 80
    cams = synth.random_photographers(f, seed=100 + seed, radius=(1.5, 15.0))
    X = dct_trajectories(30, cams.times, 8, seed=200 + seed)
    obs = synth.observe(X, cams, noise_px=2.0, seed=300 + seed)
    refined = rms_3d(sc.reconstruct_trajectories(obs.x, cams, k=8).points, X)
    linear = rms_3d(sc.reconstruct_trajectories(obs.x, cams, k=8, refine=False).points, X)
    assert linear.mean() > 1.25 * refined.mean(), (linear.mean(), refined.mean())
    assert (linear > refined).mean() >= 0.9, (linear > refined).mean()
    # Per point, against the truth: 2 px at 1.5–15 m is at most ~2 cm (measured 6.9–9.3 mm
    # mean, worst point below 2 cm).
    assert refined.max() < 0.025, refined.max()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_in_span_reconstruction_is_unbiased_and_fits_to_the_noise(seed):
    """When the model holds (trajectories in the DCT span, K fixed to its size) the
    estimate is unbiased and the residual is the noise: the reprojection RMS per
    observation is ``σ √((2F − 3K)/F)`` (F observations of 2 coordinates, 3K unknowns).
    Measured over seeds 0–2: mean RMS / expected 0.985–1.001; mean signed 3D error over
    the 60 points within 1.8 standard errors of zero on every axis (a 0.5 px principal-point
    shift: 13–19 standard errors, vertical); worst point's RMS error 11.5–14.4 mm."""
    f, k, noise = 80, 8, 2.0
    cams = synth.random_photographers(f, seed=400 + seed)
    X = dct_trajectories(60, cams.times, k, seed=500 + seed)
    obs = synth.observe(X, cams, noise_px=noise, seed=600 + seed)
    b = sc.reconstruct_trajectories(obs.x, cams, k=k)
    ratio = b.rms / (noise * np.sqrt((2 * f - 3 * k) / f))
    assert 0.96 < ratio.mean() < 1.04, ratio.mean()
    signed = (b.points - X).mean(axis=1)  # (60, 3) per-point mean signed error
    se = signed.std(axis=0, ddof=1) / np.sqrt(len(signed))
    assert (np.abs(signed.mean(axis=0)) < 4 * se).all(), (signed.mean(axis=0), se)
    assert rms_3d(b.points, X).max() < 0.02, rms_3d(b.points, X).max()


@pytest.mark.parametrize("seed", [24, 1, 2])
def test_real_mocap_markers_from_random_cameras(data_dir, seed):
    """Real data: the 41 optical markers of CMU 85_02 (first 400 frames at 120 Hz, every 4th:
    100 frames, 3.3 s) seen by random photographers with 1 px noise, K by cross validation.
    Measured over camera seeds 0–11 (‖X‖ ≈ 1.7 m in lab coordinates): mean relative error
    0.50–0.58 %, RMS 3D error 10.3–11.9 mm, worst marker's RMS 12.7–21.3 mm (one marker's
    noise: the widest-spread figure), mean signed error per axis at most 0.72 mm in
    magnitude. Thresholds: those plus a noise margin; a +5 mm bias gives ~13.5 mm RMS and a
    5 mm mean error, a 0.5 px principal-point shift a −2.6 mm vertical mean error, a
    half-frame time offset on every other photo a relative error of 0.71–0.75 % and an RMS
    of 14.9–16.5 mm."""
    m = load_c3d(data_dir / "mocap" / "cmu_85_02.c3d", frames=slice(0, 400, 4))
    p = m.positions @ Y_UP_TO_Z_UP.T
    X = np.transpose(p, (1, 0, 2))  # (M, F, 3), NaN where the marker was lost
    centre = np.nanmean(p.reshape(-1, 3), axis=0)
    times = np.arange(X.shape[1]) / (m.fps / 4)
    cams = synth.random_photographers(
        X.shape[1], seed=seed, times=times, target=(centre[0], centre[1], 1.0)
    )
    obs = synth.observe(np.nan_to_num(X), cams, noise_px=1.0, seed=seed + 1)
    x = obs.x.copy()
    x[np.isnan(X).any(-1)] = np.nan  # gaps in the capture are missing observations
    b = sc.reconstruct_trajectories(x, cams)
    assert b.ok.all(), [f for f in b.failures if f]
    seen = ~np.isnan(X).any(-1)
    d = b.points - X
    err = np.linalg.norm(d, axis=-1)
    rel = (err / np.linalg.norm(X, axis=-1))[seen]
    assert rel.mean() < 0.007, rel.mean()
    assert np.sqrt((err[seen] ** 2).mean()) < 0.0125, np.sqrt((err[seen] ** 2).mean())
    # Per marker: each one's RMS error over the frames where it was captured.
    per_marker = np.array([np.sqrt((e[s] ** 2).mean()) for e, s in zip(err, seen, strict=True)])
    assert per_marker.max() < 0.025, per_marker.max()
    # Unbiased: the mean signed error per axis (over markers' means) is near zero.
    signed = np.array([dj[s].mean(axis=0) for dj, s in zip(d, seen, strict=True)])
    assert (np.abs(signed.mean(axis=0)) < 0.0012).all(), signed.mean(axis=0)


def test_std_reflects_the_spread_of_repeated_noise():
    """The Gauss–Newton std matches the spread of solutions over noise draws (within
    ±40 %) when the model holds (trajectory in the DCT span, K fixed to its size)."""
    f = 80
    cams = synth.random_photographers(f, seed=26)
    X = dct_trajectories(1, cams.times, 6, seed=27)
    Xr = np.repeat(X, 40, axis=0)
    obs = synth.observe(Xr, cams, noise_px=1.0, seed=28)
    b = sc.reconstruct_trajectories(obs.x, cams, k=6)
    emp = b.points.std(axis=0, ddof=1)  # (F, 3)
    pred = b.std.mean(axis=0)
    ratio = np.median(pred / emp)
    assert 0.6 < ratio < 1.4, ratio


# --------------------------------------------------------------------------- API


def test_single_point_result_and_batch_access_agree():
    f = 60
    cams = synth.random_photographers(f, seed=29)
    X = synth.smooth_trajectories(3, cams.times, seed=30)
    obs = synth.observe(X, cams, noise_px=0.5, missing=0.2, seed=31)
    b = sc.reconstruct_trajectories(obs.x, cams, k_max=15)
    for i in range(3):
        t = sc.reconstruct_trajectory(obs.x[i], cams, k_max=15)
        assert t.k == b.k[i] == b[i].k
        np.testing.assert_array_equal(t.points, b.points[i])
        np.testing.assert_allclose(t.at(cams.times), t.points, atol=1e-12)
        assert t.coeffs.shape == (t.k, 3)
        assert t.covariance is not None and t.covariance.shape == (3 * t.k, 3 * t.k)
        # One held-out error per K = 1..15 (k_max), and the chosen K is its minimum (Eq 5.8).
        assert t.cv_error.shape == (15,)
        assert np.argmin(t.cv_error) == t.k - 1, t.cv_error
        assert t.rank == 3 * t.k and t.cond > 1
    np.testing.assert_allclose(b.at(cams.times), b.points, atol=1e-12)
    mid = (cams.times[:-1] + cams.times[1:]) / 2
    assert b.at(mid).shape == (3, f - 1, 3)
    # to_dict() is plain JSON and keeps the values.
    d = json.loads(json.dumps(b.to_dict()))
    assert d["k"] == b.k.tolist()
    np.testing.assert_allclose(d["points"], b.points)
    one = json.loads(json.dumps(sc.reconstruct_trajectory(obs.x[0], cams, k=4).to_dict()))
    assert one["k"] == 4 and np.shape(one["points"]) == (f, 3)
    assert sc.reconstruct_trajectory(obs.x[0], cams, k=4).at(0.5).shape == (3,)


def test_batch_keeps_going_past_a_failed_point():
    f = 30
    cams = synth.random_photographers(f, seed=32)
    X = synth.smooth_trajectories(3, cams.times, seed=33)
    x = synth.observe(X, cams, noise_px=0.5, seed=34).x
    x[1] = np.nan
    x[2, 3:] = np.nan  # 3 observations: too few for K = 4
    b = sc.reconstruct_trajectories(x, cams, k=4)
    assert b.ok.tolist() == [True, False, False]
    assert "all observations are missing" in b.failures[1]
    assert "too few observations" in b.failures[2]
    assert np.isnan(b.points[1:]).all() and np.isfinite(b.points[0]).all()
    with pytest.raises(sc.DegenerateError):
        b[2]


def test_degenerate_cases_raise_with_the_theorem_2_case():
    f = 30
    cams = synth.random_photographers(f, seed=35)
    X = synth.smooth_trajectories(1, cams.times, seed=36)[0]
    x = synth.observe(X[None], cams, seed=37).x[0]
    still = Cameras(cams.K[[0] * f], cams.R[[0] * f], cams.C[[0] * f], cams.times)
    xs = synth.observe(X[None], still, seed=37).x[0]
    with pytest.raises(sc.DegenerateError, match="does not move"):
        sc.reconstruct_trajectory(xs, still, k=3)
    few = x.copy()
    few[4:] = np.nan
    with pytest.raises(sc.DegenerateError, match="too few observations"):
        sc.reconstruct_trajectory(few, cams, k=5)
    # A camera carried along with the point (X − C constant): rank(QΘ) = 2K.
    d = np.array([5.0, 0.0, 0.3])
    Cc = X - d
    carried = Cameras(cams.K, synth.look_at(Cc, X), Cc, cams.times)
    xc = synth.observe(X[None], carried, seed=38).x[0]
    with pytest.raises(sc.DegenerateError, match="still relative to the point"):
        sc.reconstruct_trajectory(xc, carried, k=3)


def test_bad_input_names_the_argument():
    f = 20
    cams = synth.random_photographers(f, seed=39)
    x = synth.observe(synth.smooth_trajectories(1, cams.times, seed=40), cams, seed=41).x[0]
    with pytest.raises(ValueError, match=r"^x"):
        sc.reconstruct_trajectory(x[:10], cams)
    with pytest.raises(ValueError, match=r"^x"):
        sc.reconstruct_trajectory(np.full((f, 2), np.nan), cams)
    inf = x.copy()
    inf[2, 0] = np.inf
    with pytest.raises(ValueError, match=r"^x"):
        sc.reconstruct_trajectory(inf, cams)
    with pytest.raises(ValueError, match="cameras"):
        sc.reconstruct_trajectory(x, Cameras(cams.K, cams.R, cams.C))
    with pytest.raises(ValueError, match="times"):
        Cameras(cams.K, cams.R, cams.C, np.r_[cams.times[:-1], np.nan])
    with pytest.raises(ValueError, match="times"):
        Cameras(cams.K, cams.R, cams.C, cams.times[:-1])
    bad_c = cams.C.copy()
    bad_c[3, 1] = np.nan
    with pytest.raises(ValueError, match="C"):
        Cameras(cams.K, cams.R, bad_c, cams.times)
    with pytest.raises(ValueError, match=r"^k"):
        sc.reconstruct_trajectory(x, cams, k=0)
    with pytest.raises(ValueError, match=r"^k"):
        sc.reconstruct_trajectory(x, cams, k="many")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="folds"):
        sc.reconstruct_trajectory(x, cams, folds=1)
    with pytest.raises(ValueError, match="k_max"):
        sc.reconstruct_trajectory(x, cams, k_min=5, k_max=3)
    with pytest.raises(ValueError, match="cv_rule"):
        sc.reconstruct_trajectory(x, cams, cv_rule="best")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^x"):
        sc.reconstruct_trajectories(x, cams)


def test_reconstructability_conventions():
    f = 50
    t = np.arange(f) / 10.0
    X = synth.smooth_trajectories(1, t, seed=42)[0]
    still = np.tile([3.0, 0.0, 1.5], (f, 1))
    assert sc.reconstructability(X, still, 5) == 0.0
    jumpy = np.random.default_rng(43).normal(size=(f, 3)) * 3
    eta = sc.reconstructability(X, jumpy, 5, times=t)
    assert eta > 1.0  # a jumpy camera has a large component outside the span
    # η (Eq 5.16) measures the camera's motion outside the span of Θ relative to the
    # point's: it scales with the camera path, ignores a constant shift (in the span),
    # and swapping the roles inverts it.
    assert sc.reconstructability(X, 2.0 * jumpy + 5.0, 5, times=t) == pytest.approx(2 * eta)
    assert sc.reconstructability(jumpy, X, 5, times=t) == pytest.approx(1 / eta)
    # A camera path inside the span of the first 5 DCT functions: η = 0 up to rounding.
    in_span = 3 * sc.dct_basis(t, 5) @ np.random.default_rng(44).normal(size=(5, 3))
    assert sc.reconstructability(X, in_span, 5, times=t) < 1e-9 * eta
    assert null_residual(in_span, 5, times=t) < 1e-12
    with pytest.raises(ValueError, match="camera_centres"):
        sc.reconstructability(X, jumpy[:-1], 5)
    with pytest.raises(ValueError, match=r"^k"):
        sc.reconstructability(X, jumpy, 0)
