"""Social saliency field, social charges and their tracking (thesis Chapter 6), checked
against closed forms and against simulated scenes with known joint attention."""

from __future__ import annotations

import dataclasses
import signal
import threading
import time

import numpy as np
import pytest

import socialcam as sc
from socialcam import synth
from socialcam.charges import grid_axes


def _rays_at(target, eyes, h=0.1, ids=None):
    eyes = np.asarray(eyes, float)
    v = np.asarray(target, float) - eyes
    return sc.GazeRays(eyes, v, h, ids, normalize=True)


def _circle(n, r, centre, z, phase=0.0):
    a = phase + np.arange(n) * 2 * np.pi / n
    return np.c_[centre[0] + r * np.cos(a), centre[1] + r * np.sin(a), np.full(n, z)]


def _field_numpy(p, v, h, x):
    """Eq 6.1–6.4 written directly."""
    w = x[:, None, :] - p[None]
    s = np.einsum("mnk,nk->mn", w, v)
    perp = w - s[..., None] * v[None]
    with np.errstate(divide="ignore", invalid="ignore"):
        d2 = (perp**2).sum(-1) / s**2
    d2 = np.where(s < 0, np.inf, d2)
    d2 = np.where((s == 0) & ((perp**2).sum(-1) == 0), 0.0, d2)
    return (np.exp(-0.5 * d2 / h**2) / (h * np.sqrt(2 * np.pi))).mean(axis=1)


# ---------------------------------------------------------------- gaze rays and bad input


def test_gaze_rays_validation():
    p = np.zeros((2, 3))
    v = np.array([[0, 0, 1.0], [1.0, 0, 0]])
    r = sc.GazeRays(p, v, 0.1)
    assert r.h.shape == (2,) and r.ids.tolist() == [0, 1] and len(r) == 2
    with pytest.raises(ValueError, match="v: direction 1 has norm"):
        sc.GazeRays(p, [[0, 0, 1.0], [2.0, 0, 0]], 0.1)
    assert np.allclose(sc.GazeRays(p, [[0, 0, 3.0], [2.0, 0, 0]], 0.1, normalize=True).v, v)
    with pytest.raises(ValueError, match="h:"):
        sc.GazeRays(p, v, 0.0)
    with pytest.raises(ValueError, match="h:"):
        sc.GazeRays(p, v, [0.1, -0.1])
    with pytest.raises(ValueError, match="p:"):
        sc.GazeRays([[np.nan, 0, 0], [0, 0, 0]], v, 0.1)
    with pytest.raises(ValueError, match="at least one"):
        sc.GazeRays(np.zeros((0, 3)), np.zeros((0, 3)), 0.1)
    with pytest.raises(ValueError, match="ids"):
        sc.GazeRays(p, v, 0.1, ids=[3, 3])
    with pytest.raises(ValueError, match="points"):
        sc.saliency_field(r, [[np.nan, 0, 0]])
    with pytest.raises(ValueError, match="depth_range"):
        sc.find_charges(r, depth_range=(2.0, 1.0))
    with pytest.raises(ValueError, match="seed"):
        sc.find_charges(r, seed=-1)


def test_charge_options_are_one_frozen_validated_dataclass():
    o = sc.ChargeOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.tol = 1.0  # type: ignore[misc]
    assert o.membership == "partition" and o.max_iter == 100 and o.pair_seeds
    for bad, name in [
        ({"seeds_per_ray": 2.9}, "seeds_per_ray"),
        ({"seeds_per_ray": 0}, "seeds_per_ray"),
        ({"max_iter": -1}, "max_iter"),
        ({"max_iter": True}, "max_iter"),
        ({"min_members": 1.5}, "min_members"),
        ({"tol": 0.0}, "tol"),
        ({"member_sigma": float("nan")}, "member_sigma"),
        ({"membership": "exclusive"}, "membership"),
        ({"charge_penalty": -1.0}, "charge_penalty"),
        ({"region_level": 1.0}, "region_level"),
        ({"depth_range": (0.0, 5.0)}, "depth_range"),
        ({"bounds": ((0, 0, 0), (1, -1, 1))}, "bounds"),
        ({"newton": "yes"}, "newton"),
        ({"joint_window": 1}, "joint_window"),
        ({"switch_cost": -1.0}, "switch_cost"),
        ({"switch_cost": float("inf")}, "switch_cost"),
    ]:
        with pytest.raises(ValueError, match=f"^{name}:"):
            sc.ChargeOptions(**bad)
    rays = _rays_at([0, 0, 1.0], _circle(3, 2.0, [0, 0], 1.5))
    # The same options through `options=` and through overrides give the same answer.
    a = sc.find_charges(rays, options=sc.ChargeOptions(membership="all", seeds_per_ray=5))
    b = sc.find_charges(rays, membership="all", seeds_per_ray=5)
    assert [c.position.tolist() for c in a] == [c.position.tolist() for c in b]
    with pytest.raises(ValueError, match=r"^max_iterations: not an option"):
        sc.find_charges(rays, max_iterations=5)
    with pytest.raises(ValueError, match=r"^options:"):
        sc.find_charges(rays, options={"tol": 1e-3})  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        sc.find_charges(rays, 0, sc.ChargeOptions())  # type: ignore[misc]  # keyword-only
    assert sc.ChargeOptions(bounds=([0, 0, 0], [1, 1, 1])).to_dict()["bounds"] == (
        (0.0, 0.0, 0.0),
        (1.0, 1.0, 1.0),
    )


def test_sizes_that_do_not_fit_in_memory_are_refused():
    rays = _rays_at([0, 0, 1.0], _circle(3, 2.0, [0, 0], 1.5))
    with pytest.raises(ValueError, match=r"^shape:"):
        sc.saliency_grid(rays, (0, 0, 0), (1, 1, 1), shape=100000)
    with pytest.raises(ValueError, match=r"^shape:"):
        sc.saliency_grid(rays, (0, 0, 0), (1, 1, 1), shape=(10, -1, 10))
    with pytest.raises(ValueError, match=r"^shape:"):
        sc.saliency_grid(rays, (0, 0, 0), (1, 1, 1), shape=2.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^seeds_per_ray:"):
        sc.find_charges(rays, seeds_per_ray=10**12)
    with pytest.raises(ValueError, match=r"^seeds_per_ray:"):
        sc.find_charges(rays, seeds_per_ray=10**30)
    with pytest.raises(ValueError, match=r"^max_gap:"):
        sc.track_charges([], max_gap=-1)
    with pytest.raises(ValueError, match=r"^min_length:"):
        sc.track_charges([], min_length=0)


def test_results_are_read_only():
    rays = _rays_at([0, 0, 1.0], _circle(4, 2.0, [0, 0], 1.5))
    (c,) = sc.find_charges(rays)
    for name in ("position", "members", "member_index", "membership", "region_radii"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(c, name)[0] = 0
    (tr,) = sc.track_charges([[c]] * 12)
    with pytest.raises(ValueError, match="read-only"):
        tr.positions[0, 0] = 0.0


def _interrupt_soon(delay: float) -> threading.Timer:
    timer = threading.Timer(
        delay, lambda: signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
    )
    timer.start()
    return timer


@pytest.mark.parametrize("what", ["charges", "grid"])
def test_ctrl_c_stops_long_calls(what):
    """A call that takes many seconds stops within a fraction of a second of Ctrl-C."""
    scene = synth.meeting(200, seed=1)
    frames = scene.ray_frames()
    timer = _interrupt_soon(0.2)
    t0 = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            if what == "charges":
                # About 60 s of climbs on this machine.
                sc.find_charges_sequence(frames, seeds_per_ray=2000)
            else:
                # 8.4e6 samples (67 MB) of 300 rays: seconds even in a release build.
                rng = np.random.default_rng(0)
                many = sc.GazeRays(
                    rng.uniform(0, 8, (300, 3)), rng.normal(size=(300, 3)), 0.1, normalize=True
                )
                sc.saliency_grid(many, (0, 0, 0), (8, 8, 3), shape=(256, 256, 128))
    finally:
        timer.cancel()
    assert time.perf_counter() - t0 < 5.0
    # The interrupt is cleared: the next call works.
    assert len(sc.find_charges(frames[0], seeds_per_ray=2)) >= 1  # 2 groups there


# ---------------------------------------------------------------- field


def test_field_matches_equations_and_grid(rng):
    n = 7
    p = rng.uniform(-3, 3, (n, 3))
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    h = rng.uniform(0.05, 0.2, n)
    r = sc.GazeRays(p, v, h)
    x = rng.uniform(-4, 4, (500, 3))
    # Points near the rays too, where the field is large.
    x = np.vstack([x, p + v * rng.uniform(0.5, 4, (n, 1)) + rng.normal(0, 0.05, (n, 3))])
    want = _field_numpy(p, v, h, x)
    got = sc.saliency_field(r, x)
    # The core drops contributions below e^-50 of a ray's peak.
    assert np.allclose(got, want, rtol=1e-10, atol=1e-20 / h.min())
    assert got.max() > 0.1
    lo, hi, shape = (-3, -2, -1), (3, 2, 1.5), (9, 7, 5)
    g = sc.saliency_grid(r, lo, hi, shape=shape)
    xs, ys, zs = grid_axes(lo, hi, shape)
    pts = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), -1).reshape(-1, 3)
    assert g.shape == shape
    assert np.allclose(g.ravel(), sc.saliency_field(r, pts), rtol=1e-12, atol=0)


def test_field_behind_the_eye_and_at_the_eye():
    r = sc.GazeRays([[0, 0, 0.0]], [[0, 0, 1.0]], 0.1)
    peak = 1 / (0.1 * np.sqrt(2 * np.pi))
    # The cone: same value at the same angle, whatever the depth.
    vals = sc.saliency_field(r, [[0.05, 0, 0.5], [0.2, 0, 2.0], [1.0, 0, 10.0]])
    assert np.allclose(vals, peak * np.exp(-0.5), rtol=1e-12)
    assert sc.saliency_field(r, [0, 0, -1.0]) == 0.0  # behind the eye
    assert sc.saliency_field(r, [0, 0, 0.0]) == pytest.approx(peak)  # at the eye: d = 0
    assert sc.saliency_field(r, [0.3, 0, 0.0]) == 0.0  # beside the eye: 90° off the axis


# ---------------------------------------------------------------- charges


def test_exact_rays_meet_at_their_target():
    t = np.array([1.0, 2.0, 1.0])
    r = _rays_at(t, _circle(5, 2.5, t, 1.6, 0.3), ids=[10, 11, 12, 13, 14])
    (c,) = sc.find_charges(r, seed=3)
    assert np.linalg.norm(c.position - t) < 1e-4
    assert c.members.tolist() == [10, 11, 12, 13, 14]
    assert c.magnitude == pytest.approx(1 / (0.1 * np.sqrt(2 * np.pi)), rel=1e-6)
    assert np.isclose(np.linalg.norm(c.membership), 1.0)
    assert c.in_region(t) and not c.in_region(t + np.array([0, 0, 1.0]))
    # The ellipsoid's ends lie where the field is 80 % of the peak.
    ends = c.region_centre + (c.region_axes * c.region_radii).T
    assert np.allclose(sc.saliency_field(r, ends) / c.magnitude, 0.8, atol=0.05)
    d = c.to_dict()
    assert d["members"] == [10, 11, 12, 13, 14] and len(d["position"]) == 3


def test_single_ray_and_rays_that_never_meet_give_nothing():
    assert sc.find_charges(sc.GazeRays([[0, 0, 0.0]], [[1.0, 0, 0]], 0.1)) == []
    p = [[0, 0, 0.0], [0, 5, 0.0], [9, -3, 0.0]]
    assert sc.find_charges(sc.GazeRays(p, [[1.0, 0, 0]] * 3, 0.05)) == []
    diverging = sc.GazeRays([[0, 0, 0.0], [1, 0, 0.0]], [[-1.0, 0, 0], [1.0, 0, 0]], 0.1)
    assert sc.find_charges(diverging) == []


def test_same_seed_same_answer_and_sequence_matches_frames():
    scene = synth.meeting(12, seed=4)
    frames = scene.ray_frames()
    # Every frame alone (pool_frames=0): frame t is exactly find_charges(frames[t]).
    seq = sc.find_charges_sequence(frames, seed=9, pool_frames=0)
    for t in (0, 5, 11):
        one = sc.find_charges(frames[t], seed=9)
        assert len(one) == len(seq[t])
        for a, b in zip(one, seq[t], strict=True):
            assert np.array_equal(a.position, b.position) and a.magnitude == b.magnitude
            assert b.frame == t
    # Pooled over neighbouring frames (the default): deterministic too.
    seq = sc.find_charges_sequence(frames, seed=9)
    again = sc.find_charges_sequence(frames, seed=9)
    assert all(
        np.array_equal(a.position, b.position)
        for fa, fb in zip(seq, again, strict=True)
        for a, b in zip(fa, fb, strict=True)
    )


# ---------------------------------------------------------------- scenes: accuracy


def _replica_matches(scene, charges):
    """Per (frame, marker): the charge sharing most members with the true group (None if
    no charge shares 2), its marker, and the oracle intersection of the group's rays."""
    orc = scene.oracle_intersections()
    out = []
    for f, cs in enumerate(charges):
        for m in range(2):
            members = set(scene.members(f, m).tolist())
            match = [c for c in cs if len(members & set(c.members.tolist())) >= 2]
            c = max(match, key=lambda c: len(members & set(c.members.tolist())), default=None)
            out.append((f, c, scene.targets[f, m], orc[f, m]))
    return out


def _sum_q(p, v, h, x):
    """Σᵢ ‖dᵢ/hᵢ‖² (Eq 6.2) of rays (p, v, h) at each point of x (M, 3)."""
    w = x[:, None, :] - p[None]
    s = np.einsum("mnk,nk->mn", w, v)
    perp = w - s[..., None] * v[None]
    return ((perp**2).sum(-1) / (s * h) ** 2).sum(axis=1)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_mocap_replica_accuracy(seed):
    """Sec 6.2.1 replica: 6 people, 2 static markers, eye-in-head noise 0.015 (0.86°),
    bandwidth 0.05. Thresholds are what we measure (seeds 1–3, 200 frames each, default
    membership "partition" and the joint window), with margins: mean error 2.3 / 1.9 /
    3.5 cm (7.4 / 7.3 / 8.3 cm frame by frame; the thesis
    reports 10.1 cm on real data), the oracle least-squares intersection of the true
    groups 8.8 / 7.7 / 8.5 cm; per point at most 7 / 4 / 12 cm worse than the oracle; mean
    error vector within 2.3 standard errors of zero on every axis; every charge the
    intersection of its members (Σ‖d/h‖² at 5 mm neighbours at most 0.28 % lower)."""
    scene = synth.mocap_replica(200, h=0.05, noise=0.015, seed=seed)
    charges = sc.find_charges_sequence(
        scene.ray_frames(), seed=0, bounds=tuple(scene.room), joint_window=True
    )
    # Right number of charges in every frame (measured: all 200 frames, all seeds).
    assert all(len(cs) == 2 for cs in charges)
    matches = _replica_matches(scene, charges)
    assert all(c is not None for _, c, _, _ in matches)
    pos = np.array([c.position for _, c, _, _ in matches])
    marker = np.array([t for _, _, t, _ in matches])
    oracle = np.array([o for _, _, _, o in matches])
    err = np.linalg.norm(pos - marker, axis=1)
    oerr = np.linalg.norm(oracle - marker, axis=1)
    print(f"replica seed {seed}: error {100 * err.mean():.2f} ± {100 * err.std():.2f} cm, "
          f"oracle {100 * oerr.mean():.2f} cm, max {100 * err.max():.1f} cm")  # fmt: skip
    # Mean: the joint window pools ±10 frames, so well below the oracle intersection of
    # single frames (measured ratio 0.26 / 0.25 / 0.41; 0.84–0.97 frame by frame).
    assert err.mean() <= 0.6 * oerr.mean()
    # Per point: every charge at most 20 cm farther from its marker than the oracle
    # (measured at most 12 cm), and 95 % within 3× the oracle's 95th-percentile error.
    assert (err - oerr).max() < 0.2
    assert np.mean(err <= 3 * np.quantile(oerr, 0.95)) >= 0.95
    # Unbiased: the mean error vector is within 4 standard errors of 0 on each axis (a
    # +4 cm bias is more than 10 standard errors). The joint window pools ±10 frames, so
    # the errors of neighbouring frames are correlated: standard errors of 20-frame blocks.
    d = pos - marker
    blocks = np.array([d[k : k + 40].mean(axis=0) for k in range(0, len(d), 40)])
    se = blocks.std(axis=0) / np.sqrt(len(blocks))
    assert (np.abs(d.mean(axis=0)) <= 4 * se).all(), (d.mean(axis=0), se)
    # Converged: each charge of the frame rule (the pooled pass alone) minimises its
    # members' Σ‖d/h‖² (Eq 6.2) to 1 % at 5 mm.
    frames = scene.ray_frames()[:40]
    for f, c, _, _ in _replica_matches(
        scene, sc.find_charges_sequence(frames, bounds=tuple(scene.room), joint_window=False)
    ):
        assert c is not None
        r = scene.rays(f)
        nb = c.position + np.vstack([np.zeros(3), np.eye(3), -np.eye(3)]) * 0.005
        q = _sum_q(r.p[c.member_index], r.v[c.member_index], r.h[c.member_index], nb)
        assert q[1:].min() >= 0.99 * q[0], (f, q)
    # The marker lies in the 80 % confidence region in ≥ 95 % of cases (measured 1.0).
    inside = [c.in_region(t) for _, c, t, _ in matches]
    assert np.mean(inside) >= 0.95


@pytest.mark.parametrize("membership", ["strongest", "all"])
def test_modes_are_local_maxima_of_the_field(membership):
    """The mode rules place charges at modes of the field (Eq 6.7 run to convergence): at
    5 mm no neighbour is higher by more than 1e-6 of the magnitude (measured −2.6e-5;
    mean-shift stopped at 5 cm tolerance gives +1.4e-3)."""
    scene = synth.mocap_replica(40, h=0.05, noise=0.015, seed=1)
    charges = sc.find_charges_sequence(
        scene.ray_frames(), seed=0, bounds=tuple(scene.room), membership=membership
    )
    assert sum(len(cs) for cs in charges) >= 80
    for f, cs in enumerate(charges):
        for c in cs:
            nb = c.position + np.vstack([np.eye(3), -np.eye(3)]) * 0.005
            gain = sc.saliency_field(scene.rays(f), nb).max() - c.magnitude
            assert gain <= 1e-6 * c.magnitude, (f, gain / c.magnitude)


def test_partition_does_not_depend_on_mean_shift_convergence():
    """Mutation "mean-shift stopped early" cannot change the partition rule: its charges
    are the weighted least-squares intersections of their members (a function of the
    member sets only), and the member sets are the fixed point of a search whose
    candidates are the mean-shift modes *and* the near-intersections of every ray pair,
    which alone already start every group. Mean-shift stopped at 10 cm tolerance after 3
    iterations gives the same charges to 1e-9 m; the mode rules, whose charges are the
    modes, are guarded by ``test_modes_are_local_maxima_of_the_field``."""
    scene = synth.mocap_replica(40, h=0.05, noise=0.015, seed=1)
    frames, room = scene.ray_frames(), tuple(scene.room)
    a = sc.find_charges_sequence(frames, seed=0, bounds=room)
    b = sc.find_charges_sequence(frames, seed=0, bounds=room, tol=0.1, max_iter=3)
    assert sum(map(len, a)) == 80
    for x, y in zip(a, b, strict=True):
        assert [c.members.tolist() for c in x] == [c.members.tolist() for c in y]
        assert all(
            np.allclose(c.position, d.position, atol=1e-9) for c, d in zip(x, y, strict=False)
        )


def _marker_window_scores(seed):
    """``charge_scores`` (right-count fraction, mean error, mean oracle error) of
    ``find_charges_sequence`` with defaults on marker scene ``seed`` at 100 frames."""
    scene = synth.marker_check_family(seed, n_frames=100)
    right, err, oerr = scene.charge_scores(
        sc.find_charges_sequence(scene.ray_frames(), bounds=tuple(scene.room))
    )
    print(f"seed {seed}: right {right:.2f}, error/oracle {err / oerr:.2f}")
    return right, err, oerr


def _heldout_scores(scene, charges):
    """Right-count fraction, mean charge error and mean oracle error (``charge_scores``)."""
    return scene.charge_scores(charges)


def test_heldout_marker_scenes_beat_the_thesis_rule():
    """Held-out marker-check scenes (synth.marker_check_family; seeds 100–119 were never
    used for tuning, development used 0–29), the room given as ``bounds``. Measured at 60
    frames with the default rule ("partition", pooled over ±10 frames): right count 0.98 /
    0.98 / 1.00, mean error / oracle 0.71 / 0.91 / 0.77; the former default ("strongest") 0.87 / 0.92 /
    0.98 and 0.84 / 1.08 / 0.83 without bounds; the thesis' rule (membership="all")
    over-counts: right count 0.25 or less."""
    for seed in (104, 105, 108):
        scene = synth.marker_check_family(seed, n_frames=60)
        frames = scene.ray_frames()
        room = tuple(scene.room)
        right, err, oerr = _heldout_scores(scene, sc.find_charges_sequence(frames, bounds=room))
        right_all, _, _ = _heldout_scores(
            scene, sc.find_charges_sequence(frames, membership="all", bounds=room)
        )
        print(f"held-out {seed}: right {right:.2f} (thesis rule {right_all:.2f}), "
              f"error/oracle {err / oerr:.2f}")  # fmt: skip
        assert right >= 0.93 and right >= right_all + 0.5
        assert err <= 1.1 * oerr


def _group_evidence(r, idx, ln_volume, n_charges, unattended=0.05):
    """Log evidence (nats, against the rays pointing anywhere) of one charge explaining
    rays ``idx`` under the gaze model of the ``"partition"`` rule (module docs of
    ``saliency/partition.rs``): each member gains ``ln(2/h²) + ln((1 − u)/u) − ln K −
    ½‖d/h‖²``, the charge costs ``ln V − 3/2 ln 2π + ½ ln det A``, at the intersection of
    the members' rays (weights ``1/(s²h²)``); ``(-inf, x)`` if it is behind an eye."""
    p, v, h = r.p[idx], r.v[idx], r.h[idx]
    proj = np.eye(3)[None] - v[:, :, None] * v[:, None, :]
    w = 1 / h**2
    for _ in range(20):
        a = (proj * w[:, None, None]).sum(0)
        x = np.linalg.solve(a, np.einsum("nij,nj->i", proj * w[:, None, None], p))
        s = np.einsum("nk,nk->n", x - p, v)
        if (s <= 0).any():
            return -np.inf, x
        w = 1 / (h * s) ** 2
    q = _sum_q(p, v, h, x[None])[0]
    bonus = np.log(2 / h**2) + np.log((1 - unattended) / unattended) - np.log(n_charges)
    ln_det = np.linalg.slogdet((proj * w[:, None, None]).sum(0))[1]
    return bonus.sum() - 0.5 * q - ln_volume + 1.5 * np.log(2 * np.pi) - 0.5 * ln_det, x


def _frames_identifiable(scene):
    """Fraction of frames where the frame alone makes the true grouping likelier than the
    simplest confusions: any two of its groups merged into one charge, or any group left
    out (its rays attending nothing); a true charge outside the room counts as not
    identifiable. Needs no charge finder: it is a property of the scene and the gaze model,
    the oracle bound of any rule deciding frame by frame on this model."""
    lo, hi = scene.room
    ln_v = float(np.log(np.prod(hi - lo)))

    def score(r, groups):
        k = len(groups)
        out = 0.0
        for g in groups:
            e, x = _group_evidence(r, np.array(g), ln_v, k)
            out += e if ((x >= lo) & (x <= hi)).all() else -np.inf
        return out

    ok = []
    for f in range(scene.n_frames):
        r = scene.rays(f)
        groups = [
            np.flatnonzero(scene.group[f] == t).tolist() for t in range(scene.targets.shape[1])
        ]
        groups = [g for g in groups if len(g) >= 2]
        alts = [[a + b] + [g for g in groups if g is not a and g is not b]
                for i, a in enumerate(groups) for b in groups[i + 1 :]]  # fmt: skip
        alts += [[g for g in groups if g is not a] for a in groups]
        ok.append(score(r, groups) > max((score(r, alt) for alt in alts), default=-np.inf))
    return float(np.mean(ok))


#: Held-out seeds (never used for development) by the identifiability criterion of the
#: issue target (``_frames_identifiable ≥ 0.95``), measured at 100 frames: 11 of 20.
IDENTIFIABLE = (100, 104, 105, 107, 108, 109, 110, 111, 112, 113, 117)


@pytest.mark.parametrize("seed", [14, 26])
def test_pooling_over_frames_is_the_stage_that_reaches_the_target(seed):
    """Development scenes (seeds 14: moving markers, 26: static) where the frame-by-frame
    rule misses the issue target and pooling over ±10 frames reaches it. Measured at 100
    frames: pooled right count 0.97 / 0.99, error/oracle 1.06 / 0.91; frame by frame
    (``pool_frames=0``) 0.81 / 0.87 and 1.86 / 1.37."""
    scene = synth.marker_check_family(seed, n_frames=100)
    frames, room = scene.ray_frames(), tuple(scene.room)
    right, err, oerr = scene.charge_scores(
        sc.find_charges_sequence(frames, bounds=room, joint_window=False)
    )
    assert right >= 0.95 and err <= 1.25 * oerr
    right, err, oerr = scene.charge_scores(
        sc.find_charges_sequence(frames, bounds=room, pool_frames=0)
    )
    assert right < 0.9 and err > 1.3 * oerr


def test_heldout_scenes_that_frames_cannot_resolve():
    """The scenes the issue target fails on are the ones where the frame alone does not
    make the true grouping the likeliest under the gaze model in more than 5 % of frames:
    two markers 1–2 m apart seen at h ≥ 0.05 from far, or pairs of near-parallel rays.
    Measured: seed 101 (the former xfail) 70 %, 115 48 %, 104 and 111 100 %."""
    for seed, low, high in ((101, 0.6, 0.8), (115, 0.4, 0.6), (104, 0.99, 1.0), (111, 0.99, 1.0)):
        frac = _frames_identifiable(synth.marker_check_family(seed, n_frames=100))
        print(f"held-out {seed}: frames identifiable {frac:.2f}")
        assert low <= frac <= high, (seed, frac)


@pytest.mark.parametrize("seed", [100, 104, 110, 111, 113])
def test_heldout_marker_scenes_reach_the_issue_target(seed):
    """Issue 13 target on held-out scenes that frames can resolve (``IDENTIFIABLE``, every
    third one, 2 or 3 markers, static and moving, h 0.019–0.069, plus seed 100): right
    count in ≥ 95 % of frames and mean error ≤ 1.25× the oracle intersection, with the
    defaults (pooled over ±10 frames, then the joint window) and the room as bounds.
    Measured at 100 frames (seeds 100, 104, 110, 111, 113): right count 1.00 / 1.00 /
    1.00 / 1.00 / 1.00, error/oracle 0.24 / 0.25 / 0.36 / 0.32 / 0.54; all 11
    identifiable seeds reach the target (benches/charges_heldout.py). Seed 100 (right
    count 0.93 before) needs the window's position fit to lower the members' ``Σ‖d/h‖²``
    at every reweighting: the plain reweighting settled on a member's eye, where a pair
    of near-parallel rays along the 20 m room cross behind it, and the pair was lost."""
    assert seed in IDENTIFIABLE
    scene = synth.marker_check_family(seed, n_frames=100)
    charges = sc.find_charges_sequence(
        scene.ray_frames(), bounds=tuple(scene.room), joint_window=True
    )
    right, err, oerr = _heldout_scores(scene, charges)
    print(f"held-out {seed}: right {right:.2f}, error/oracle {err / oerr:.2f}")
    assert right >= 0.95 and err <= 1.25 * oerr


@pytest.mark.parametrize("seed", [101, 118, 119])
def test_joint_window_resolves_frames_the_frame_alone_cannot(seed):
    """Held-out scenes that are not identifiable frame by frame (``_frames_identifiable``
    0.70 / 0.76 / 0.74: two markers 1.1–2.1 m apart seen from far, pairs of wide rays):
    the joint likelihood over the sequence (``joint_window``) reaches the issue target,
    the pooled frame-by-frame rule does not. Measured at 100 frames: joint right count
    0.95 / 1.00 / 1.00, error/oracle 0.44 / 0.30 / 0.44; without it 0.65 / 0.91 / 0.81
    and 1.29 / 0.86 / 1.13. Seed 101 needs the window's decoding to close one source
    with too few rays per frame and round (closing all of them left 0.77: a pair split
    over two copies of its target never met)."""
    scene = synth.marker_check_family(seed, n_frames=100)
    frames, room = scene.ray_frames(), tuple(scene.room)
    # The window is the default.
    right, err, oerr = scene.charge_scores(sc.find_charges_sequence(frames, bounds=room))
    print(f"held-out {seed}: joint right {right:.2f}, error/oracle {err / oerr:.2f}")
    assert right >= 0.95 and err <= 1.25 * oerr
    # Unbiased and better than the oracle intersection of single frames: the window's
    # positions pool the rays of neighbouring frames.
    assert err <= 0.6 * oerr
    right, err, oerr = scene.charge_scores(
        sc.find_charges_sequence(frames, bounds=room, joint_window=False)
    )
    print(f"held-out {seed}: frame by frame right {right:.2f}, error/oracle {err / oerr:.2f}")
    assert right < 0.93


@pytest.mark.parametrize("seed", [21, 27, 400, 408])
def test_joint_window_moves_pairs_together(seed):
    """Marker scenes where two people must change target together: the window decodes
    every pair of people jointly given the others (pair moves), a move closes no charge
    except a copy of the target the pair goes to. Measured at 100 frames (right count,
    error/oracle): dev 21 1.00 / 0.45, dev 27 1.00 / 0.64, seeds 400 1.00 / 0.38 and 408
    1.00 / 0.52. Without pair moves 21 and 400 miss (0.93, 0.88: at frame 87 of 400 a
    new pair looks down the 17 m room through another pair's marker; either person alone
    on the new target makes no charge, so both stay on the old one); with moves that may
    close a charge 27 loses its pair to a neighbouring group (0.52: with the positions
    held, the ln K_t every ray saves outweighs the misfit); without the copy exception
    408 keeps a group split over two copies of its target (0.92)."""
    right, err, oerr = _marker_window_scores(seed)
    assert right >= 0.95 and err <= 1.25 * oerr


@pytest.mark.parametrize("seed", [211, 216, 605])
def test_joint_window_extends_groups_to_where_they_formed(seed):
    """Marker scenes where the window's search, holding the positions, missed a group for
    a stretch of frames (the objective of the true assignment is higher: 4347 against
    4224, 4326 against 4312, 3070 against 2980): a source seen only after its group
    formed (211: frames 0–8, 216: frames 28–41, no position or one extrapolated from
    one side) or a pair that leaves its source at the end (605: frames 92–99). The
    extension moves (a group switching together moved to where it formed, or on to the
    end, its sources refitted and scored by the objective) reach it. Measured at 100
    frames (right count, error/oracle): 1.00 / 0.23, 1.00 / 0.51, 1.00 / 0.28; without
    them 0.91, 0.86 and 0.92 right."""
    right, err, oerr = _marker_window_scores(seed)
    assert right >= 0.97 and err <= 1.25 * oerr


def test_joint_window_splits_a_charge_that_holds_two_groups():
    """Marker scene 1008 (never seen before this change; h 0.053, markers 1.9 m apart):
    in frames 0-30 groups of 3 and 5 look at two markers 1.9 m apart and the per-frame
    charges already hold both groups in one charge of 8; the decoding, pair moves, drops
    and extensions never open a source, so the window kept them merged (0.69 right). The
    split move (a source's members in a segment of constant membership split in two by
    2-means in the gaze model's distance, one side moved to a new source, refitted,
    decoded and scored by the objective) separates them. Measured at 100 frames: right
    count 1.00, error/oracle 0.62; without the split move 0.69 / 0.65."""
    right, err, oerr = _marker_window_scores(1008)
    assert right >= 0.97 and err <= 1.25 * oerr


def test_joint_window_moves_start_from_the_best_round():
    """Development marker scene 12 (h 0.067, markers 1.39 m apart in a 19 m room): the
    window held two groups in one source over the whole sequence (0.08 right) although
    the true groups, refitted, score higher (9013 against 9003). The rounds (refit,
    decode, drop) are no ascent: they fell from 9003 to 8965 before the first move, and
    the extension and split moves started from there. Stopping the rounds when one falls
    below the best so far, and starting every move from the best round, reaches 9029 and
    the true count. Measured at 100 frames: right count 1.00, error/oracle 0.43; before
    0.08 / 0.83."""
    right, err, oerr = _marker_window_scores(12)
    assert right >= 0.97 and err <= 1.25 * oerr


def test_joint_window_merges_copies_then_extends_a_group():
    """Marker scene 1218 (never seen before this change; h 0.015, 9 people, markers 1.05
    m apart): in frames 0-7 marker 0's group is split over two copies of its source
    (0.15 m apart) and a pair whose marker lies behind marker 0 along their rays sits in
    them; the window counted 2 charges there (0.92 right) although the true groups,
    refitted, score 31 nats more. Neither the pair's extension to its own source (a copy
    is left with too few rays) nor the merge of the copies alone raises the objective;
    the merge move (the copies merged, refitted, decoded, then given their best
    extension) does. Measured at 100 frames: right count 1.00, error/oracle 0.59; without
    the merge move 0.92 / 0.73."""
    right, err, oerr = _marker_window_scores(1218)
    assert right >= 0.97 and err <= 1.25 * oerr


@pytest.mark.parametrize(("seed", "want"), [(415, 0.98), (902, 0.99), (913, 0.99)])
def test_joint_window_charges_a_frame_per_charge_and_merges_copies(seed, want):
    """Marker scenes decided by the cost of a charge. 415: a group of 4 seen in the last 7
    frames, at a marker 1.5 m from another's; with the frame model's mixture weight
    (- ln K_t paid by every ray in every frame) the third charge cost 11 ln 3/2 = 4.5 nats
    per frame and the group stayed merged (0.93 right); at a cost per charge and frame it
    holds (1.00). 902, 913 (h 0.019, 0.012): the cheaper charge lets a group split over two
    copies of its marker, 4-6 cm apart, in a few frames (0.97, 0.95 right); copies within
    merge_radius are one charge (1.00 both). Measured at 100 frames."""
    right, err, oerr = _marker_window_scores(seed)
    assert right >= want and err <= 1.25 * oerr


def test_joint_window_follows_people_by_id():
    """The window follows a person over frames by person id, not by row. Held-out seed
    118 with the rows of every frame shuffled: with the ids along, the issue target holds
    (measured right count 1.00, error/oracle 0.30); with the rows taken as the people
    (default ids), the people are scrambled from frame to frame and the window pools the
    wrong rays: error/oracle 0.50 (the right count, 0.83 before copies within merge_radius
    were one charge, is now 1.00)."""
    scene = synth.marker_check_family(118, n_frames=100)
    rng = np.random.default_rng(0)
    shuffled = []
    for r in scene.ray_frames():
        o = rng.permutation(len(r))
        shuffled.append(sc.GazeRays(r.p[o], r.v[o], r.h[o], r.ids[o]))
    room = tuple(scene.room)
    right, err, oerr = scene.charge_scores(
        sc.find_charges_sequence(shuffled, bounds=room, joint_window=True)
    )
    assert right >= 0.95 and err <= 1.25 * oerr
    plain = [sc.GazeRays(r.p, r.v, r.h) for r in shuffled]
    _, err_plain, _ = scene.charge_scores(
        sc.find_charges_sequence(plain, bounds=room, joint_window=True)
    )
    assert err_plain > 1.4 * err


@pytest.mark.parametrize("name", ["meeting", "party"])
def test_scene_charge_counts_and_tracks(name):
    """The thesis' meeting and party scenes with the defaults (the joint window on).
    Measured right count 1.00 on both; the party's table-tennis ball (3 m/s, turning
    every 1.25 s) needs the window's narrower position fits: with the wide local-linear
    fit alone the count was right in 0.72 of frames."""
    scene = getattr(synth, name)(300, seed=2)
    charges = sc.find_charges_sequence(scene.ray_frames(), seed=0, bounds=tuple(scene.room))
    counts = np.array([len(cs) for cs in charges])
    truth = scene.n_charges()
    correct = np.mean(counts == truth)
    print(f"{name}: correct number of charges in {correct:.3f} of frames")
    assert correct >= 0.95
    tracks = sc.track_charges(charges)
    # At most one charge per track per frame.
    for tr in tracks:
        assert len(np.unique(tr.frames)) == len(tr.frames)
    # Every true group (a target and the exact set of people attending it) that lasts at
    # least 3 s keeps one track id through the whole sequence: one track has the group as
    # its core members and holds the group's charge in ≥ 90 % of the group's frames (in
    # the meeting, group A and B each exist before and after the presenter: same id).
    groups: dict[tuple[int, tuple[int, ...]], list[int]] = {}
    for f in range(scene.n_frames):
        for t in range(scene.targets.shape[1]):
            m = tuple(scene.members(f, t).tolist())
            if len(m) >= 2:
                groups.setdefault((t, m), []).append(f)
    checked = 0
    for (t, m), fr in groups.items():
        if len(fr) < 30:
            continue
        checked += 1
        tr = [tr for tr in tracks if tuple(tr.core_members.tolist()) == m]
        assert len(tr) == 1, f"{name}: target {t} group {m} has {len(tr)} tracks"
        covered = np.isin(fr, tr[0].frames).mean()
        print(f"{name}: target {t} group {m} track {tr[0].id} covers {covered:.3f}")
        assert covered >= 0.9
    assert checked == (3 if name == "meeting" else 5)


def test_meeting_demo_gives_its_real_groups_as_tracks():
    """The meeting demo (seed 0, 300 frames): 3 real groups (A, B, everyone). Measured:
    3 tracks of 192, 199 and 91 frames with the defaults; 23 tracks, 20 of them 1–5
    frames long (transitions), without the run rules (min_length=1, max_gap=0)."""
    scene = synth.meeting(seed=0)
    charges = sc.find_charges_sequence(scene.ray_frames(), seed=0)
    tracks = sc.track_charges(charges)
    assert [t.core_members.tolist() for t in tracks] == [
        list(range(6)),
        list(range(6, 11)),
        list(range(11)),
    ]
    assert [t.id for t in tracks] == [0, 1, 2]
    assert all(len(t) >= 80 for t in tracks)
    raw = sc.track_charges(charges, min_length=1, max_gap=0)
    assert len(raw) > 10 and sum(len(t) < 10 for t in raw) >= 10
    # A gap longer than max_gap splits a run: A (192 frames in all) is two runs of about
    # 100 frames (before and after the presenter), so min_length=120 drops every track,
    # while bridging the gap (max_gap=150) keeps A and B whole.
    assert sc.track_charges(charges, min_length=120) == []
    bridged = sc.track_charges(charges, min_length=120, max_gap=150)
    assert [t.core_members.tolist() for t in bridged] == [list(range(6)), list(range(6, 11))]


def test_tracks_survive_dissolution_and_reemergence():
    """Fig 6.3b: group A dissolves (its members look around) and re-forms; its charge
    gets its old track id back, while group B's track continues."""
    scene = synth.meeting(90, seed=5)
    group = scene.group.copy()
    group[30:60, :6] = -1  # group A dissolves for 3 s
    people = synth.looking_at(scene.eyes, scene.targets, group, h=scene.noise, seed=3)
    frames = [sc.GazeRays(people.eyes[f], people.gaze[f], scene.h) for f in range(90)]
    charges = sc.find_charges_sequence(frames, seed=0, bounds=tuple(scene.room))
    tracks = sc.track_charges(charges)
    a = [t for t in tracks if t.core_members.tolist() == [0, 1, 2, 3, 4, 5]]
    assert len(a) == 1
    fa = a[0].frames
    assert np.isin(np.r_[0:30, 60 + 10 : 90], fa).mean() >= 0.9  # before and after
    assert not np.isin(np.r_[32:60], fa).any()  # not while dissolved


def test_plots_return_figures():
    import matplotlib

    matplotlib.use("Agg")
    scene = synth.meeting(20, seed=1)
    rays = scene.rays(0)
    charges = sc.find_charges(rays, bounds=tuple(scene.room))
    fig = sc.plot_saliency(rays, scene.room[0], scene.room[1], shape=24, charges=charges,
                           truth=scene.targets[0])  # fmt: skip
    assert fig.axes and len(fig.axes[0].images) == 1
    tracks = sc.track_charges(sc.find_charges_sequence(scene.ray_frames()))
    fig2 = sc.plot_charge_tracks(tracks, times=scene.times, truth=scene.targets)
    assert len(fig2.axes) == 4
    # The legend names the real tracks only (≥ legend_min_length charges) and the truth;
    # the title is the figure's, above the panels.
    raw = sc.track_charges(sc.find_charges_sequence(scene.ray_frames()), min_length=1)
    fig3 = sc.plot_charge_tracks(raw, truth=scene.targets, legend_min_length=5)
    (legend,) = fig3.legends
    labels = [t.get_text() for t in legend.get_texts()]
    real = [tr for tr in raw if len(tr) >= 5]
    assert len(labels) == len(real) + 1 and labels[-1] == "true targets"
    assert all(f"track {tr.id}:" in lab for tr, lab in zip(real, labels, strict=False))
    assert fig3.get_suptitle().startswith(f"social charge tracks: {len(real)} of ≥ 5 frames")
    import matplotlib.pyplot as plt

    plt.close("all")


def test_overflowing_rays_and_bad_charges_are_refused_by_name():
    # |v| of 1e200 normalised to a zero "unit" vector; h of 1e-160 gave a NaN field; a
    # box of ±1e308 a grid of NaN; track_charges took memberships of another length than
    # their ids (broadcast or a numpy error), NaN memberships and a person twice
    r = sc.GazeRays([[0.0, 0, 0]], [[0.0, 0, 1e200]], 0.1, normalize=True)
    np.testing.assert_array_equal(r.v, [[0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="v: direction 0 has norm inf"):
        sc.GazeRays([[0.0, 0, 0]], [[0.0, 0, 1e200]], 0.1)
    with pytest.raises(ValueError, match="h: bandwidths must be >= 1e-100"):
        sc.GazeRays([[0.0, 0, 0]], [[0.0, 0, 1.0]], 1e-160)
    two = sc.GazeRays([[0.0, 0, 0], [1.0, 0, 0]], [[0.0, 0, 1], [0.0, 0, 1]], 0.1)
    d45 = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    near, far = sc.saliency_field(two, np.array([d45 * 1e3, d45 * 1e200]))
    assert far == pytest.approx(near, rel=1e-3) and far < 1e-20  # was the peak, 3.99
    with pytest.raises(ValueError, match="lo, hi: the box's size overflows"):
        sc.saliency_grid(two, [-1e308] * 3, [1e308] * 3, shape=4)
    frames = synth.meeting(n_frames=3, seed=0).ray_frames()
    c = next(ch for cs in sc.find_charges_sequence(frames) for ch in cs)
    for bad, why in (
        (dataclasses.replace(c, membership=c.membership[:1]), "membership: expected one value"),
        (
            dataclasses.replace(c, membership=np.full_like(c.membership, np.nan)),
            "membership: contains NaN",
        ),
        (dataclasses.replace(c, ids=np.zeros_like(c.ids)), "ids: a person appears twice"),
    ):
        with pytest.raises(ValueError, match=rf"charges_per_frame\[1\]\[0\]\.{why}"):
            sc.track_charges([[c], [bad]], min_length=1)
