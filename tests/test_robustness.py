"""Sizes refused before allocating, Ctrl-C in every long call, silent wrong answers turned
into errors, and output files that respect the umask (issue 13)."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from _scenes import ring

import socialcam as sc
from socialcam import _core, io, synth

# ----------------------------------------------------------------------------- helpers


def gaze_frames(n_frames: int, n_people: int = 6, seed: int = 0) -> list[tuple[Any, Any]]:
    """People on a circle looking at a slowly moving point, with a little noise."""
    rng = np.random.default_rng(seed)
    ang = np.linspace(0, 2 * np.pi, n_people, endpoint=False)
    p = np.c_[2 * np.cos(ang), 2 * np.sin(ang), np.full(n_people, 1.6)]
    frames = []
    for t in range(n_frames):
        target = np.array([0.3 * np.sin(0.05 * t), 0.2, 1.0])
        v = target - p + rng.normal(scale=0.05, size=p.shape)
        frames.append((p, v / np.linalg.norm(v, axis=1, keepdims=True)))
    return frames


def interrupted(fn: Callable[[], object], delay: float = 0.5) -> float:
    """Runs ``fn`` and sends SIGINT to the main thread after ``delay`` seconds; asserts
    ``KeyboardInterrupt`` and returns the latency from the signal to the exception."""
    sent: list[float] = []

    def fire() -> None:
        sent.append(time.perf_counter())
        signal.pthread_kill(threading.main_thread().ident or 0, signal.SIGINT)

    timer = threading.Timer(delay, fire)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            fn()
    finally:
        timer.cancel()
    assert sent, "the call returned before the interrupt was sent: make it longer"
    latency = time.perf_counter() - sent[0]
    print(f"Ctrl-C latency: {latency * 1e3:.0f} ms")
    return latency


#: Ctrl-C must stop a call within this many seconds (measured: < 0.1 s on a loaded
#: machine with a dev build; the binding polls signals every 20 ms).
LATENCY = 2.0


# ----------------------------------------------------------------------------- sizes


def test_dct_basis_size_is_checked_before_allocating():
    t = np.linspace(0, 1, 100)
    with pytest.raises(ValueError, match=r"^k: too large"):
        sc.dct_basis(t, 10**9)
    with pytest.raises(ValueError, match=r"^k: too large"):
        _core.dct_basis(t, 10**9)  # the kernel checks too
    assert sc.dct_basis(t, 300).shape == (100, 300)  # k > F is a valid request


def test_project_size_is_checked_before_allocating():
    cams = ring(10_000)
    with pytest.raises(ValueError, match=r"^points: too large"):
        cams.project(np.zeros((100_000, 3)))
    with pytest.raises(ValueError, match=r"^points: too large"):
        _core.project(cams.K, cams.R, cams.C, np.zeros((100_000, 3)))


def test_trajectory_k_beyond_frames_does_not_allocate():
    cams = ring(20)
    x = np.zeros((1, 20, 2))
    # The kernel used to allocate an F × k basis table before noticing K is impossible.
    b = _core.reconstruct_trajectories(
        cams.K,
        cams.R,
        cams.C,
        cams.times,
        x,
        sc.TrajectoryOptions(k=2**62),
    )
    assert b["failures"][0] is not None
    with pytest.raises(sc.DegenerateError, match="too few observations"):
        sc.reconstruct_trajectory(np.ones((20, 2)), cams, k=2**62)


def test_gaze_sizes_are_checked():
    frames = gaze_frames(3)
    with pytest.raises(ValueError, match=r"^n_charges: 1000000000000 charges"):
        sc.GazeField.fit(frames, n_charges=10**12)
    flat_p = np.concatenate([f[0] for f in frames])
    flat_v = np.concatenate([f[1] for f in frames])
    off = np.array([0, 6, 12, 18], dtype=np.int64)
    win = np.array([[0, 3, 10**12]], dtype=np.int64)
    with pytest.raises(ValueError, match=r"^windows: too large"):
        _core.gaze_init(flat_p, flat_v, off, win, 0.25)


# ----------------------------------------------------------------------------- Ctrl-C


def test_ctrl_c_stops_batched_triangulation():
    cams = ring(6)
    rng = np.random.default_rng(1)
    X = rng.normal(scale=0.5, size=(2_000, 3))
    x = np.ascontiguousarray(cams.project(X).transpose(1, 0, 2))
    x = np.tile(x, (600, 1, 1)) + rng.normal(scale=0.5, size=(1_200_000, 6, 2))
    lat = interrupted(lambda: sc.triangulate(x, cams, max_iter=200))
    assert lat < LATENCY
    # The flag is cleared: the next call runs normally.
    assert np.isfinite(sc.triangulate(x[:10], cams)).all()


def test_ctrl_c_stops_trajectory_cross_validation():
    f = 400
    cams = ring(f, seed=2)
    rng = np.random.default_rng(2)
    t = cams.times
    X = np.stack(
        [np.c_[np.sin(t * w), np.cos(t * 0.7 * w), 0.2 * t] for w in rng.uniform(0.5, 3, 4_000)]
    )
    x = cams.project_trajectory(X) + rng.normal(scale=0.5, size=(4_000, f, 2))
    lat = interrupted(lambda: sc.reconstruct_trajectories(x, cams, k_max=80))
    assert lat < LATENCY
    assert sc.reconstruct_trajectories(x[:2], cams, k=5).ok.all()


def test_ctrl_c_stops_trajectory_refinement():
    f = 400
    cams = ring(f, seed=3)
    rng = np.random.default_rng(3)
    t = cams.times
    X = np.stack([np.c_[np.sin(t * w), np.cos(t * w), 0.1 * t] for w in rng.uniform(1, 3, 4_000)])
    x = cams.project_trajectory(X) + rng.normal(scale=2.0, size=(4_000, f, 2))
    lat = interrupted(lambda: sc.reconstruct_trajectories(x, cams, k=60, max_iter=10**6))
    assert lat < LATENCY


def test_ctrl_c_stops_gaze_field_em():
    frames = gaze_frames(3_000, n_people=8)
    p = np.concatenate([f[0] for f in frames])
    v = np.concatenate([f[1] for f in frames])
    off = np.arange(0, 8 * 3_000 + 1, 8, dtype=np.int64)
    members = np.tile(np.arange(8, dtype=np.int64), 3_000)
    windows = np.array([[0, 3_000, 2]], dtype=np.int64)
    init = _core.gaze_init(p, v, off, windows, 0.25)
    # A tiny tol and a huge cap: the EM would run for hours without the interrupt. The
    # kernel is called directly so that the signal lands inside the EM, not in the setup.
    opts = sc.GazeFieldOptions(kappa=30.0, tol=1e-300, max_iter=10**9)
    lat = interrupted(lambda: _core.gaze_em(p, v, members, off, windows, init, opts))
    assert lat < LATENCY
    assert sc.GazeField.fit(frames[:5], n_charges=1, kappa=30.0).converged.all()


def test_ctrl_c_stops_gaze_field_fit():
    frames = gaze_frames(3_000, n_people=8)
    lat = interrupted(
        lambda: sc.GazeField.fit(frames, n_charges=2, kappa=30.0, tol=1e-300, max_iter=10**9),
        delay=3.0,
    )
    assert lat < LATENCY


def test_ctrl_c_stops_articulated_reconstruction():
    """The articulated method (thesis Ch. 4) polls between its BQP solves, starts and
    refinements: 300 frames with the robust method run for minutes (measured > 300 s,
    loaded); Ctrl-C stops them."""
    f = 300
    cams = synth.random_photographers(f, seed=1)
    t = cams.times
    parent = np.c_[np.zeros(f), np.zeros(f), np.ones(f)]
    a, b = np.sin(3 * t), np.cos(2 * t)
    child = parent + 0.4 * np.c_[np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), np.sin(b)]
    x = cams.project_trajectory(child) + np.random.default_rng(0).normal(size=(f, 2))
    lat = interrupted(
        lambda: sc.reconstruct_articulated(x, cams, parent, 0.4, k=8, node_limit=100), delay=1.0
    )
    assert lat < LATENCY


#: A pipeline run interrupted in pycolmap's matching took 2.7 s to stop (loaded machine):
#: pycolmap polls for signals itself, less often than the core.
RUN_LATENCY = 6.0

_RUN_CHILD = (
    "import signal, sys\n"
    "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
    "import socialcam as sc\n"
    "print('ready', flush=True)\n"
    "sc.run(sys.argv[1:-1], sys.argv[-1], progress=False)\n"
    "print('finished', flush=True)\n"
)


def _run_child(videos, out):
    proc = subprocess.Popen(
        [sys.executable, "-c", _RUN_CHILD, *[str(v) for v in videos], str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    return proc


@pytest.fixture(scope="module")
def run_duration(small_scene, tmp_path_factory):
    """Seconds an uninterrupted ``socialcam.run`` of the small scene takes here after its
    imports, so the interrupts below land inside it on a fast machine as on a loaded one."""
    proc = _run_child(small_scene.videos, tmp_path_factory.mktemp("whole") / "out")
    start = time.perf_counter()
    out, err = proc.communicate(timeout=900)
    assert "finished" in out, err[-2000:]
    return time.perf_counter() - start


@pytest.mark.parametrize("fraction", [0.25, 0.75])
def test_ctrl_c_stops_a_pipeline_run(small_scene, run_duration, tmp_path, fraction):
    """``socialcam.run`` (decoding, features, matching, mapping, gaze, charges, plots) stops
    on Ctrl-C at any stage: interrupted a quarter and three quarters of the way through an
    uninterrupted run's time. In a child process, so that an import the signal lands in
    cannot leave half-imported modules behind for the other tests.

    A run's time varies between runs (the first, timed one measured 8.5 s, a later one ended
    before 6.4 s on CI): when a run ends before the interrupt, nothing was tested, so it is
    tried again with the interrupt a third earlier, at most three times."""
    delay = fraction * run_duration
    for attempt in range(3):
        proc = _run_child(small_scene.videos, tmp_path / f"out{attempt}")
        try:
            time.sleep(delay)
            proc.send_signal(signal.SIGINT)
            sent = time.perf_counter()
            out, err = proc.communicate(timeout=60)
            latency = time.perf_counter() - sent
        finally:
            if proc.poll() is None:
                proc.kill()
        if "finished" not in out:
            break
        delay *= 2 / 3
    assert "finished" not in out, f"every run ended before the interrupt ({run_duration:.1f} s)"
    assert "KeyboardInterrupt" in err, err[-2000:]
    assert latency < RUN_LATENCY, latency


# ----------------------------------------------------------------------------- silent wrong answers


def test_perspective_distance_refuses_non_unit_directions():
    p = np.zeros((2, 3))
    v = np.array([[0.0, 0, 1], [0, 0, 2]])
    with pytest.raises(ValueError, match=r"^v: direction 1 has norm 2"):
        sc.perspective_distance(p, v, np.ones((2, 3)))
    d = sc.perspective_distance(p, v / [[1], [2]], np.array([[1.0, 0, 1], [0, 1, 2]]))
    np.testing.assert_allclose(d, [[1.0, 0, 0], [0, 0.5, 0]], atol=1e-12)


def test_trajectory_at_outside_the_span_raises():
    cams = ring(30, seed=4)
    t = cams.times
    X = np.c_[np.sin(t), np.cos(t), 0.1 * t]
    tr = sc.reconstruct_trajectory(cams.project_trajectory(X), cams, k=4)
    t0, t1, _ = tr.span
    inside = tr.at(np.linspace(t0, t1, 5))
    assert np.isfinite(inside).all()
    with pytest.raises(ValueError, match=r"^times: outside the fitted span"):
        tr.at(t1 + 1.0)
    # Explicit opt-in returns the mirror image: X(t1 + d) == X(t1 - d).
    d = 0.3
    np.testing.assert_allclose(tr.at(t1 + d, extrapolate=True), tr.at(t1 - d), atol=1e-9)


def test_gaze_predict_outside_the_fit_raises():
    frames = gaze_frames(10)
    field = sc.GazeField.fit(frames, n_charges=1, kappa=30.0)
    assert np.isfinite(field.predict([[1.0, 1.0, 1.6]], t=9.4)).all()  # within half a frame
    with pytest.raises(ValueError, match=r"^t: 25.0 s is outside the fitted frames"):
        field.predict([[1.0, 1.0, 1.6]], t=25.0)
    with pytest.raises(ValueError, match=r"^t: -3.0 s is outside"):
        field.predict([[1.0, 1.0, 1.6]], t=-3.0)


def test_too_many_charges_for_the_gaze_raises():
    frames = [gaze_frames(1, n_people=6)[0]]
    with pytest.raises(ValueError, match=r"^n_charges: 50 charges .* only 6 people"):
        sc.GazeField.fit(frames, n_charges=50)


def test_coinciding_charges_warn_and_are_not_converged():
    # 6 charges for 6 people who all look at one point: the EM converges (64 iterations
    # measured) with the charges collapsed onto that point; it used to say "converged".
    frames = [gaze_frames(1, n_people=6)[0]]
    with pytest.warns(RuntimeWarning, match=r"n_charges: charges \d and \d .* coincide"):
        field = sc.GazeField.fit(frames, n_charges=6, kappa=400.0, init="pairs")
    assert field.iterations[0] < 200
    assert not field.converged.any()


def test_floats_are_not_truncated_to_ints():
    cams = ring(12)
    with pytest.raises(ValueError, match=r"^k: expected an integer, got 2.9"):
        sc.dct_basis(cams.times, 2.9)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^k: expected an integer"):
        sc.reconstruct_trajectory(np.zeros((12, 2)), cams, k=2.9)
    frames = gaze_frames(3)
    with pytest.raises(ValueError, match=r"^leave_out: expected an integer"):
        sc.cross_validate_gaze(frames, leave_out=1.7, n_charges=1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^n_charges: expected an integer"):
        sc.GazeField.fit(frames, n_charges=1.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^eligible: expected integers"):
        sc.cross_validate_gaze(frames, eligible=[0, 1.5], n_charges=1)


def test_uint64_ids_do_not_wrap():
    p, v = gaze_frames(1)[0]
    ids = np.arange(6, dtype=np.uint64)
    ids[0] = 2**63 + 5
    with pytest.raises(ValueError, match=r"^frames\[0\].ids: person ids must fit in int64"):
        sc.GazeField.fit([(p, v, None, ids)], n_charges=1)
    ok = np.arange(6, dtype=np.uint64) + 10
    field = sc.GazeField.fit([(p, v, None, ok)], n_charges=1, kappa=20.0)
    assert field.people.tolist() == list(range(10, 16))


# ----------------------------------------------------------------------------- files


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077])
def test_written_files_respect_the_umask(tmp_path, mask):
    old = os.umask(mask)
    try:
        path = io.write_json(tmp_path / "sub" / "report.json", {"a": np.arange(3)})
        mode = stat.S_IMODE(path.stat().st_mode)
    finally:
        os.umask(old)
    assert mode == 0o666 & ~mask
    assert not list(path.parent.glob(".*.tmp"))  # no temp file left behind


# ----------------------------------------------------------------------------- ConvergenceError


def test_strict_raises_convergence_error_where_documented():
    """``strict=True`` turns an iteration cap that was hit into the documented
    :class:`socialcam.ConvergenceError` (a ``RuntimeError``), in every place that offers it:
    the gaze field, triangulation and trajectories (one point and a batch)."""
    frames = gaze_frames(3)
    with pytest.raises(sc.ConvergenceError, match="did not converge in max_iter=1"):
        sc.GazeField.fit(frames, n_charges=2, max_iter=1, strict=True)
    assert not sc.GazeField.fit(frames, n_charges=2, max_iter=1).converged.all()
    cams = ring(6)
    rng = np.random.default_rng(2)
    X = rng.normal(scale=0.5, size=(20, 3))
    x = np.ascontiguousarray(cams.project(X).transpose(1, 0, 2))
    x = x + rng.normal(scale=2.0, size=x.shape)
    with pytest.raises(sc.ConvergenceError):
        sc.triangulate(x, cams, refine=True, max_iter=1, strict=True)
    cams = ring(30, seed=4)
    t = cams.times
    xt = cams.project_trajectory(np.c_[np.sin(t), np.cos(t), 0.1 * t])
    xt = xt + rng.normal(scale=2.0, size=xt.shape)
    with pytest.raises(sc.ConvergenceError, match="max_iter=1"):
        sc.reconstruct_trajectory(xt, cams, k=4, max_iter=1, strict=True)
    with pytest.raises(sc.ConvergenceError, match="max_iter=1"):
        sc.reconstruct_trajectories(xt[None], cams, k=4, max_iter=1, strict=True)
    assert not sc.reconstruct_trajectory(xt, cams, k=4, max_iter=1).converged
    assert sc.reconstruct_trajectory(xt, cams, k=4, strict=True).converged
    assert issubclass(sc.ConvergenceError, RuntimeError)


def test_a_scene_far_from_the_origin_keeps_its_answer_or_is_refused():
    # Geo-referenced scenes (UTM, ECEF: 1e6-1e7 m) keep their answers; trajectories are
    # solved about the cameras' mean centre, so even 1e10 m does (before, 1e10 m read as a
    # still camera); where float64 rounds the coordinates by more than a thousandth of the
    # scene (1e15 m for metres of motion) the call names the argument instead of returning
    # a result moved by the rounding (0.1 m) or no charge at all.
    cams = ring(40)
    t = np.asarray(cams.times)
    X = np.c_[0.3 * np.sin(t), 0.2 * np.cos(2 * t), 1.0 + 0.1 * t]
    x = cams.project_trajectory(X)
    rng = np.random.default_rng(3)
    x = x + rng.normal(0, 0.3, x.shape)
    statics = rng.normal(0, 0.5, (5, 3))
    xs = np.asarray(cams.project(statics)).transpose(1, 0, 2)  # (5, 40, 2)
    eyes = rng.normal(0, 1, (5, 3))
    v = np.array([0.0, 1.0, 2.0]) - eyes
    v /= np.linalg.norm(v, axis=1, keepdims=True)

    def moved(off: float) -> sc.Cameras:
        return sc.Cameras(cams.K, cams.R, cams.C + off, cams.times)

    near = sc.reconstruct_trajectory(x, cams, k=6)
    batch = sc.reconstruct_trajectories(np.stack([x, np.full_like(x, np.nan)]), moved(1e6), k=6)
    assert batch.failures[1] is not None and (batch.coeffs[1] == 0).all()
    for off in (6.4e6, 1e10):
        far = sc.reconstruct_trajectory(x, moved(off), k=6)
        assert np.abs(far.points - off - near.points).max() < 1e-4, off
        # the coefficients moved with the points: .at() agrees with .points
        assert np.abs(far.at(t) - far.points).max() < 1e-4 * max(1.0, off * 1e-9)
    with pytest.raises(ValueError, match=r"cameras\.C: .*float64 rounds"):
        sc.reconstruct_trajectory(x, moved(1e15), k=6)

    tri = sc.triangulate(xs, cams)
    assert np.abs(sc.triangulate(xs, moved(6.4e6)) - 6.4e6 - tri).max() < 1e-6
    with pytest.raises(ValueError, match=r"cameras\.C: .*float64 rounds"):
        sc.triangulate(xs, moved(1e15))

    def charges(off: float) -> list[sc.Charge]:
        return sc.find_charges(sc.GazeRays(eyes + off, v, np.full(5, 0.03)), seed=0)

    (c0,) = charges(0.0)
    (c1,) = charges(6.4e6)
    assert np.abs(c1.position - 6.4e6 - c0.position).max() < 1e-6
    with pytest.raises(ValueError, match=r"rays\.p: .*float64 rounds"):
        charges(1e15)
    with pytest.raises(ValueError, match=r"frames\[0\]\.p: .*float64 rounds"):
        sc.find_charges_sequence([sc.GazeRays(eyes + 1e15, v, np.full(5, 0.03))], seed=0)
    from socialcam.synth.calibration import fixation_segment

    head = fixation_segment(30, seed=0).cameras
    g0 = sc.calibrate_gaze(head)
    g1 = sc.calibrate_gaze(head.moved(np.eye(3), [6.4e6, 0.0, 0.0]))  # returned its start
    assert g1.converged and np.abs(g1.v - g0.v).max() < 1e-8
    np.testing.assert_allclose(g1.y - [6.4e6, 0.0, 0.0], g0.y, atol=1e-6)
    with pytest.raises(ValueError, match=r"cameras\.C: .*float64 rounds"):
        sc.calibrate_gaze(head.moved(np.eye(3), [1e15, 0.0, 0.0]))
    f0 = sc.GazeField.fit([(eyes, v)], n_charges=1, kappa=20.0)
    f1 = sc.GazeField.fit([(eyes + 6.4e6, v)], n_charges=1, kappa=20.0)
    assert np.abs(f1.charges[0] - 6.4e6 - f0.charges[0]).max() < 1e-6
    with pytest.raises(ValueError, match=r"frames\[\*\]\.p: .*float64 rounds"):
        sc.GazeField.fit([(eyes + 1e15, v)], n_charges=1, kappa=20.0)


# ------------------------------------------------------- values that used to pass silently


@pytest.mark.parametrize(
    ("bad", "words"),
    [([True, False], "booleans"), (np.array([1 + 2j, 0j]), "complex"), (["1.5", "2"], "text")],
)
def test_arrays_of_bools_complex_or_text_are_refused(bad, words):
    # converted before: True → 1.0, the imaginary part dropped, "1.5" → 1.5
    with pytest.raises(ValueError, match=rf"^times: cannot be converted .*{words}"):
        sc.dct_basis(bad, 1)
    assert sc.dct_basis(np.array([0, 1], np.uint8), 1).shape == (2, 1)  # integers still read


def test_gaze_rays_ids_beyond_int64_are_refused_not_wrapped():
    p, v = gaze_frames(1)[0]
    ids = np.arange(6, dtype=np.uint64)
    ids[0] = 2**63  # wrapped to -2**63 before
    with pytest.raises(ValueError, match=r"^ids: values must fit in int64"):
        sc.GazeRays(p, v, 0.1, ids)
    ok = sc.GazeRays(p, v, 0.1, np.arange(6, dtype=np.uint64) + 10)
    assert ok.ids.dtype == np.int64 and ok.ids.tolist() == list(range(10, 16))


def test_dct_basis_refuses_a_span_that_overflows():
    with pytest.raises(ValueError, match=r"^times: the span .* overflows"):
        sc.dct_basis([-1e308, 1e308], 2)
    with pytest.raises(ValueError, match=r"^times, t0, t1: the span .* overflows"):
        sc.dct_basis([0.0, 1.0], 2, t0=-1e308, t1=1e308)


def test_back_projection_of_huge_pixels_stays_unit():
    cams = ring(2)
    x = np.array([[3e200, -1e200], [1e300, 1e300]])
    d = cams.back_project(x)  # the norm's squares overflowed: NaN or zero before
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    # the direction is that of the pixel seen from far away: same as a scaled-down pixel
    far = cams.back_project(x / 1e180)  # 1e20 px: the principal point is lost in rounding
    np.testing.assert_allclose(d, far, atol=1e-12)


@pytest.mark.parametrize("flag", ["no", 1, None])
def test_flags_must_be_bools(flag):
    cams = ring(12)
    x = cams.project(np.zeros(3))
    calls: list[tuple[str, Callable[[], object]]] = [
        ("strict", lambda: sc.triangulate(x, cams, strict=flag)),
        ("return_info", lambda: sc.triangulate(x, cams, return_info=flag)),
        ("strict", lambda: sc.reconstruct_trajectory(x, cams, strict=flag)),
        ("strict", lambda: sc.reconstruct_trajectories(x[None], cams, strict=flag)),
        ("return_depth", lambda: cams.project(np.zeros(3), return_depth=flag)),
        ("strict", lambda: sc.GazeField.fit(gaze_frames(2), n_charges=1, strict=flag)),
    ]
    for name, call in calls:
        with pytest.raises(ValueError, match=rf"^{name}: expected a bool"):
            call()
    traj = sc.reconstruct_trajectory(x, cams)
    with pytest.raises(ValueError, match=r"^extrapolate: expected a bool"):
        traj.at([0.5], extrapolate=flag)


def test_calibration_refuses_a_stalling_prior_and_a_head_that_did_not_move():
    from socialcam.gaze import MAX_LAMBDA_AXIS, MIN_HEAD_MOTION
    from socialcam.synth.calibration import fixation_segment

    head = fixation_segment(60, seed=0).cameras
    # 1e300 returned the start (p = 0, v = z) marked converged
    with pytest.raises(ValueError, match=r"^lambda_axis: "):
        sc.calibrate_gaze(head, lambda_axis=1e300)
    assert sc.calibrate_gaze(head, lambda_axis=MAX_LAMBDA_AXIS).converged
    # a head that moved micrometres returned the start
    tiny = head.scaled(0.5 * MIN_HEAD_MOTION / np.ptp(head.C, axis=0).max())
    with pytest.raises(sc.DegenerateError, match=r"^cameras\.C: the head moved"):
        sc.calibrate_gaze(tiny)


def test_cross_validation_needs_three_members():
    frames = gaze_frames(3, n_people=2)
    # said "leave_out: expected 1 <= k <= 0" before
    with pytest.raises(ValueError, match=r"^frames: cross-validation needs rays of at least 3"):
        sc.cross_validate_gaze(frames, n_charges=1)
