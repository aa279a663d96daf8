"""Joint attention from the faces (issue 11, thesis Sec 3.2.2 with Ch. 3's charges): the
scorer ``synth.evaluate.face_joint_attention`` against rendered truth, the exo rays of
``reconstruct_faces`` and their fusion with the ego rays, on one rendered conversation
circle (6 wearers + 3 people without a camera, 5 s at 10 fps; the face truth does not
depend on the image size, so it is rendered small and the detections come from the truth
at 1280×960 scale)."""

from __future__ import annotations

import dataclasses
import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import socialcam.faces as faces_mod
from socialcam.faces import (
    _accel_ties,
    _pentadiagonal_marginals,
    _shape_covariance,
    _solve_upper_banded,
    _tridiagonal_marginals,
    _upper_banded,
    fuse_ego_exo,
    reconstruct_faces,
)
from socialcam.synth.cameras import look_at
from socialcam.synth.evaluate import (
    ego_exo_disagreement,
    face_joint_attention,
    faces_vs_truth,
    truth_detections,
)
from socialcam.synth.render import render_scene


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    truth = render_scene(tmp_path_factory.mktemp("circle6"), n_wearers=6, n_people=3,
                         duration=5.0, fps=10.0, size=(160, 120), seed=1, faces=True,
                         arrangement="circle", audio=False, calibration=False,
                         start_spread=0.0, progress=False).truth  # fmt: skip
    dets, cams = truth_detections(truth, scale=8.0, seed=1)
    f3 = reconstruct_faces(dets, cams)
    scaled = dataclasses.replace(truth, K=np.stack([c.K[0] for c in cams]))
    one = reconstruct_faces(dets, cams, single_view=True)
    return truth, f3, faces_vs_truth(scaled, dets, f3), (one, faces_vs_truth(scaled, dets, one))


def _truth_rays(truth, bias_deg: float = 0.0):
    """Exo rays made of the true face normals (turned ``bias_deg`` about the vertical) of
    every person some camera sees, in the shape of a ``Faces3D`` (one column per person)."""
    V = len(truth.names)
    seen = np.stack([truth.face_visible[v] for v in range(V)]).sum(0) >= 1
    n = Rotation.from_rotvec([0.0, 0.0, np.radians(bias_deg)]).apply(
        truth.face_normal[0].reshape(-1, 3)
    )
    return types.SimpleNamespace(
        times=truth.frame_times[0] - truth.start[0],
        p=np.where(seen[..., None], truth.face_landmarks[0][:, :, :2].mean(axis=2), np.nan),
        v=np.where(seen[..., None], n.reshape((*seen.shape, 3)), np.nan),
        h=np.full(seen.shape, 0.05),
    )


def test_joint_attention_scorer_against_truth_rays(scene):
    """The scorer itself: exo rays that are the true head directions (= the ego primary
    gaze of the wearers) of everyone seen score like the ego rays on the same groups
    (measured 0.062 vs 0.058 m; circle seed 2 0.054 vs 0.047); the same rays turned 3° / 5°
    score 2× / 3.4× worse (0.117 / 0.201 m): how little face-direction error joint
    attention tolerates."""
    truth, _f3, _r, _one = scene
    owner = {j: j for j in range(truth.face_normal[0].shape[1])}
    exact = face_joint_attention(truth, _truth_rays(truth), owner)
    # groups count once their members have looked at the head for 0.6 s: 34 groups, the
    # ego rays find all (without the settling time: 51 groups, 96 % found)
    assert 25 <= exact["exo"]["groups"] <= 45 and exact["exo"]["found_fraction"] >= 0.85, exact
    assert exact["ego"]["found_fraction"] >= 0.98, exact
    assert exact["exo"]["error_median_m"] < 1.25 * exact["ego_same_groups"]["error_median_m"]
    turned = face_joint_attention(truth, _truth_rays(truth, 3.0), owner)
    assert turned["exo"]["error_median_m"] > 1.6 * exact["exo"]["error_median_m"], turned


def _ego_as_exo(truth, drop=(), people_turn_deg=0.0):
    """The wearers' own ego rays (true eyes, primary gaze and ``h``) in the shape of a
    ``Faces3D``, the wearers in ``drop`` without a ray, followed by the true head rays of
    the people without a camera turned ``people_turn_deg`` about the vertical."""
    V = len(truth.names)
    rays = _truth_rays(truth, people_turn_deg)
    p, v, h = rays.p.copy(), rays.v.copy(), rays.h.copy()
    p[:, :V] = np.stack([truth.eyes[w] for w in range(V)], axis=1)
    v[:, :V] = np.stack([truth.gaze[w] for w in range(V)], axis=1)
    h[:, :V] = truth.h
    p[:, list(drop)] = v[:, list(drop)] = np.nan
    return types.SimpleNamespace(times=rays.times, p=p, v=v, h=h)


def test_matched_scoring_compares_the_same_wearers(scene):
    """``matched`` scores the exo and ego rays of the same wearers on the same groups: exo
    rays that ARE the ego rays give identical errors, whichever wearers lack an exo ray
    and however wrong the rays of the people without a camera are (which do move the
    unmatched ``exo`` score); ``coverage`` counts the ego groups left out."""
    truth = scene[0]
    owner = {j: j for j in range(truth.face_normal[0].shape[1])}
    base = face_joint_attention(truth, _ego_as_exo(truth, drop=(0, 3)), owner)
    m = base["matched"]
    assert m["groups"] >= 10, m
    np.testing.assert_allclose(m["exo_errors"], m["ego_errors"], rtol=1e-9)
    assert m["ratio"] == pytest.approx(1.0, rel=1e-9)
    # one (truth frame, looked-at head) key per group, none twice
    keys = m["keys"]
    assert keys.shape == (m["groups"], 2), keys.shape
    assert len({tuple(k) for k in keys.tolist()}) == len(keys)
    # coverage: the ego groups scored; every one when every wearer has an exo ray
    full = face_joint_attention(truth, _ego_as_exo(truth), owner)["matched"]
    assert full["coverage"] == 1.0 and 0.2 < m["coverage"] < 0.9, (full, m)
    turned = face_joint_attention(truth, _ego_as_exo(truth, drop=(0, 3), people_turn_deg=20), owner)
    np.testing.assert_allclose(turned["matched"]["exo_errors"], m["exo_errors"], rtol=1e-9)
    assert turned["exo"] != base["exo"], (turned["exo"], base["exo"])


def test_matched_ratio_of_true_head_rays_is_one(scene):
    """Exo rays made of the true head directions from the faces' eye midpoints (``h``
    0.05) score like the ego rays under ``matched`` (measured 0.94 on 27 groups; circles 1–6
    of 10 s: 0.89–1.16); turned 3° about the vertical they score 1.64."""
    truth = scene[0]
    owner = {j: j for j in range(truth.face_normal[0].shape[1])}
    exact = face_joint_attention(truth, _truth_rays(truth), owner)["matched"]
    turned = face_joint_attention(truth, _truth_rays(truth, 3.0), owner)["matched"]
    assert 0.8 < exact["ratio"] < 1.25, exact
    assert turned["ratio"] > 1.5 * exact["ratio"], turned


def test_exo_joint_attention_and_ego_exo_fusion(scene):
    """Exo rays from the reconstructed faces on the rendered circle. Measured on this scene
    (default / rotations not tied / not rigid / Cauchy ties without the quadratic start):
    face gaze 2.10 / 4.91 / 5.39 / 3.01° median; joint-attention groups found 1.00 / 0.29 /
    0.23 / 0.65 with exo error 0.20 / 0.36 / 0.36 / 0.26 m (ego rays on the same groups
    0.056 m: the issue's 1.5× is not met, see ``benches/faces_accuracy.out.txt``); ego/exo
    disagreement of the wearers 1.9 / 5.4 / 5.8 / 3.1° median. Scored on the same wearers
    (``matched``, 24 groups; ego 0.229 m, found 0.79): exo/ego 1.14 / 1.84 / 1.55 / — with
    0.96 / 0.25 / 0.25 / — of the groups found."""
    truth, f3, r, _one = scene
    assert r["association"] >= 0.98 and r["face_instants"] >= 150, r
    assert r["gaze_deg"] < 2.6, r["gaze_deg"]
    ja = face_joint_attention(truth, f3, r["owner"])
    assert ja["exo"]["groups"] >= 25 and ja["exo"]["found_fraction"] >= 0.85, ja
    assert ja["exo"]["error_median_m"] < 0.3, ja
    m = ja["matched"]
    assert m["groups"] >= 20 and m["exo_found_fraction"] >= 0.85, m
    assert m["ratio"] < 1.4, m
    dis = ego_exo_disagreement(truth, f3, r["owner"])
    assert len(dis) >= 100 and np.median(dis) < 2.6, np.median(dis)
    # the fused direction lies between the two, nearer the sharper one (here ego)
    j = next(j for j, own in r["owner"].items() if own == 0)
    ts = np.nonzero(np.isfinite(f3.v[:, j, 0]))[0]
    ft = truth.frame_times[0] - truth.start[0]
    k = [int(np.argmin(np.abs(ft - f3.times[t]))) for t in ts]
    ego = truth.gaze[0][k]
    fused, _kappa, d = fuse_ego_exo(ego, truth.h[0], f3.v[ts, j], f3.h[ts, j])
    to_ego = np.arccos(np.clip(np.einsum("ij,ij->i", fused, ego), -1, 1))
    to_exo = np.arccos(np.clip(np.einsum("ij,ij->i", fused, f3.v[ts, j]), -1, 1))
    np.testing.assert_allclose(to_ego + to_exo, d, atol=1e-6)
    assert (to_ego <= to_exo + 1e-9).all()


def test_h_reflects_the_face_direction_error(scene):
    """``h`` of the rigid faces comes from each instant's marginal covariance under the
    rotation ties: the gaze error over σ = √(h² − eye_in_head²) has the median of a 2-D
    Gaussian's angle (1.18); measured 1.26 (seeds 2, 3: 1.40, 1.54). With each instant's
    own covariance (ties ignored) σ was 2.6× too large (0.50; 0.66, 0.69)."""
    _truth, f3, r, _one = scene
    sig = np.concatenate(
        [np.sqrt(f3.h[np.isfinite(f3.v[:, j, 0]), j] ** 2 - 0.05**2) for j in r["owner"]]
    )
    z = np.median(np.radians(r["gaze_errors_deg"]) / sig)
    assert 0.9 < z < 2.0, z


def test_tridiagonal_marginals_match_the_dense_inverse():
    rng = np.random.default_rng(0)
    n = 6
    M = rng.normal(size=(n, 6, 6))
    A = M @ np.transpose(M, (0, 2, 1)) + 6 * np.eye(6)
    w = rng.uniform(0.5, 2.0, n - 1)
    F = np.zeros((6 * n, 6 * n))
    for i in range(n):
        F[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = A[i]
    for i in range(n - 1):
        for a in range(3):
            F[6 * i + a, 6 * i + 6 + a] = F[6 * i + 6 + a, 6 * i + a] = -w[i]
    inv = np.linalg.inv(F)
    got = _tridiagonal_marginals(A, w)
    for i in range(n):
        np.testing.assert_allclose(got[i], inv[6 * i : 6 * i + 6, 6 * i : 6 * i + 6], atol=1e-12)


def _dense(A, o1, o2):
    """The symmetric matrix of diagonal blocks ``A (n, 6, 6)`` and diagonal blocks
    ``diag(o1_i)``, ``diag(o2_i)`` one and two blocks off the diagonal."""
    n = len(A)
    F = np.zeros((6 * n, 6 * n))
    for i in range(n):
        F[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = A[i]
    for k, o in ((1, o1), (2, o2)):
        for i in range(n - k):
            F[6 * i : 6 * i + 6, 6 * (i + k) : 6 * (i + k) + 6] = np.diag(o[i])
            F[6 * (i + k) : 6 * (i + k) + 6, 6 * i : 6 * i + 6] = np.diag(o[i])
    return F


@pytest.mark.parametrize("n", [6, 7])
def test_pentadiagonal_marginals_match_the_dense_inverse(n):
    """The marginals under the turning-rate ties (blocks two instants apart), by pairs of
    instants, and the banded solve the rigid fit uses, against dense linear algebra."""
    rng = np.random.default_rng(n)
    M = rng.normal(size=(n, 6, 6))
    A = M @ np.transpose(M, (0, 2, 1)) + 12 * np.eye(6)
    o1, o2 = rng.uniform(-2, 2, (n - 1, 6)), rng.uniform(-2, 2, (n - 2, 6))
    inv = np.linalg.inv(_dense(A, o1, o2))
    got = _pentadiagonal_marginals(A, o1, o2)
    for i in range(n):
        np.testing.assert_allclose(got[i], inv[6 * i : 6 * i + 6, 6 * i : 6 * i + 6], atol=1e-12)
    b = rng.normal(size=(6 * n, 2))
    np.testing.assert_allclose(_solve_upper_banded(_upper_banded(A, o1, o2), b), inv @ b,
                               atol=1e-10)  # fmt: skip


def test_turning_rate_ties_are_least_squares_of_their_residual():
    """``_accel_ties`` adds ``Jᵀ W J`` and ``Jᵀ W r`` of the residual ``(e_i + x_{i+1} −
    x_i) / Δt_i − (e_{i−1} + x_i − x_{i−1}) / Δt_{i−1}`` (the change of the turning rate,
    with ``x`` the rotation updates), its Jacobian taken here by finite differences."""
    rng = np.random.default_rng(3)
    n = 6
    e = rng.normal(scale=0.05, size=(n - 1, 3))
    dt = rng.uniform(0.05, 0.15, n - 1)
    accel = 0.7

    def res(x):
        ex = e + x[1:] - x[:-1]
        return (ex[1:] / dt[1:, None] - ex[:-1] / dt[:-1, None]).reshape(-1)

    r0 = res(np.zeros((n, 3)))
    J = np.empty((len(r0), 3 * n))
    for a in range(3 * n):
        d = np.zeros(3 * n)
        d[a] = 1e-6
        J[:, a] = (res(d.reshape(n, 3)) - r0) / 1e-6
    W = np.repeat(1.0 / (accel * 0.5 * (dt[1:] + dt[:-1])) ** 2, 3)
    want_H, want_g = J.T @ (W[:, None] * J), J.T @ (W * r0)
    g = np.zeros((n, 6))
    Hb, o1, o2 = _accel_ties(np.zeros((n, 6, 6)), g, np.zeros((n - 1, 6)),
                             np.zeros((n - 2, 6)), e, dt, accel, robust=False)  # fmt: skip
    full = _dense(Hb, o1, o2)
    rot = np.r_[[6 * i + a for i in range(n) for a in range(3)]]
    np.testing.assert_allclose(full[np.ix_(rot, rot)], want_H, rtol=1e-4)
    np.testing.assert_allclose(g[:, :3].reshape(-1), want_g, rtol=1e-4)
    assert not full[3::6].any() and not g[:, 3:].any()  # positions untouched
    # robust: a turn far beyond the scale gets a small weight
    e[2] += 1.0
    g2 = np.zeros((n, 6))
    Hr, _, _ = _accel_ties(np.zeros((n, 6, 6)), g2, np.zeros((n - 1, 6)),
                           np.zeros((n - 2, 6)), e, dt, accel, robust=True)  # fmt: skip
    assert Hr[3, 0, 0] < 0.01 * Hb[3, 0, 0]


def test_turning_rate_ties_reach_the_fit(scene):
    """``rigid_turn_accel`` (on by default) reaches the rigid fit: the rays' σ shrinks (the
    marginal under more ties; measured 1.72 → 1.56° median on this scene) and the gaze is
    no worse (2.10 → 2.09°; circles 1–6, 10 s: 2.42 → 2.23° median)."""
    truth, f3, r, _one = scene
    dets, cams = truth_detections(truth, scale=8.0, seed=1)
    f0 = reconstruct_faces(dets, cams, rigid_turn_accel=None)
    scaled = dataclasses.replace(truth, K=np.stack([c.K[0] for c in cams]))
    r0 = faces_vs_truth(scaled, dets, f0)
    ok = np.isfinite(f3.v[..., 0])
    assert (ok == np.isfinite(f0.v[..., 0])).all()
    sig, sig0 = (np.sqrt(np.maximum(f.h[ok] ** 2 - 0.05**2, 0.0)) for f in (f3, f0))
    assert np.median(sig) < 0.95 * np.median(sig0), (np.median(sig), np.median(sig0))
    assert r["gaze_deg"] <= 1.02 * r0["gaze_deg"], (r["gaze_deg"], r0["gaze_deg"])
    with pytest.raises(ValueError, match="rigid_turn_accel"):
        reconstruct_faces(dets, cams, rigid_turn_accel=0.0)


def test_head_pivot_lowers_the_direction_error(scene):
    """``rigid_pivot_accel`` (on by default): the face turns about a pivot behind it (here
    the renderer's eye centre) whose path is smooth, so a turn shows as a shift of the well
    triangulated face. Measured on this scene, with the rotations of the instants untied
    (what each instant alone knows): gaze 4.88 → 3.22° median (circle seeds 2, 3 of 5 s:
    5.20 → 3.31, 4.13 → 2.59); with the default ties: landmarks 3.00 → 1.89 mm, gaze 2.02
    either way here (dev circles of 10 s: 2.21 → 2.09° median, faces_attention.out.txt)."""
    truth, _f3, r, _one = scene
    dets, cams = truth_detections(truth, scale=8.0, seed=1)
    scaled = dataclasses.replace(truth, K=np.stack([c.K[0] for c in cams]))

    def score(**kw):
        return faces_vs_truth(scaled, dets, reconstruct_faces(dets, cams, **kw))

    untied = {"rigid_turn_rate": None, "rigid_turn_accel": None}
    alone, alone0 = score(**untied), score(**untied, rigid_pivot_accel=None)
    assert alone["gaze_deg"] < 0.8 * alone0["gaze_deg"], (alone["gaze_deg"], alone0["gaze_deg"])
    r0 = score(rigid_pivot_accel=None)
    assert r["face_instants"] == r0["face_instants"] and r["association"] >= 0.98
    assert r["landmark_mm"] < 0.8 * r0["landmark_mm"], (r["landmark_mm"], r0["landmark_mm"])
    assert r["gaze_deg"] <= 1.02 * r0["gaze_deg"], (r["gaze_deg"], r0["gaze_deg"])
    with pytest.raises(ValueError, match="rigid_pivot_accel"):
        reconstruct_faces(dets, cams, rigid_pivot_accel=-0.1)


def _pivot_track(seed: int, noise: float = 1.0):
    """A face turning (yaw ±25°, pitch ±8°) about a pivot 6 cm behind and 3 cm above its
    landmarks' plane, the pivot drifting slowly; three cameras 1.8 m away over 70°; the
    arguments of ``_rigid_track`` and the true landmarks."""
    rng = np.random.default_rng(seed)
    n = 40
    times = 0.1 * np.arange(n)
    S = np.array([[0, 0.032, 0], [0, -0.032, 0], [0.02, 0, -0.03], [0, 0.025, -0.05],
                  [0, -0.025, -0.05]])  # fmt: skip
    rot = Rotation.from_euler(
        "zy",
        np.c_[25 * np.sin(2 * np.pi * 0.3 * times), 8 * np.sin(1.3 * times + 1)],
        degrees=True,
    )
    pivot = np.c_[0.03 * np.sin(0.5 * times), 0.02 * times, np.full(n, 1.6)]
    off = S + np.array([0.06, 0.0, -0.03])
    X = np.stack([rot[t].apply(off) for t in range(n)]) + pivot[:, None]
    ang = np.radians([-35.0, 0.0, 35.0])
    Cc = np.c_[1.8 * np.cos(ang), 1.8 * np.sin(ang), np.full(3, 1.7)]
    Rc = look_at(Cc, np.tile([0.0, 0.0, 1.55], (3, 1)))
    K = np.array([[1000.0, 0, 640], [0, 1000.0, 480], [0, 0, 1]])
    step = np.repeat(np.arange(n), 3)
    slot = np.arange(3 * n)
    Xc = np.einsum("rij,rpj->rpi", Rc[slot % 3], X[step] - Cc[slot % 3][:, None])
    uv = Xc[..., :2] / Xc[..., 2:] * 1000.0 + [640, 480]
    uv += noise * rng.normal(size=uv.shape)
    args = (np.tile(K, (3 * n, 1, 1)), Rc[slot % 3], Cc[slot % 3], step, slot, uv,
            np.full(3 * n, noise), X + 0.004 * rng.normal(size=X.shape), np.full(n, 3.0),
            times, 0.1)  # fmt: skip
    return args, X


def test_rigid_track_with_a_pivot(monkeypatch):
    """The rigid fit with a head pivot places the landmarks better than the fit about the
    landmarks' mean (measured 1.19–1.30 → 0.94–0.99 mm mean error on three draws); an
    offset beyond ``PIVOT_MAX`` falls back to the fit without the pivot."""
    kw = {"turn_accel": 1.0, "centre_rate": 0.3}
    for seed in range(3):
        args, X = _pivot_track(seed)
        L1, cov1 = faces_mod._rigid_track(*args, **kw, pivot_accel=0.1)
        L0, cov0 = faces_mod._rigid_track(*args, **kw)
        e1, e0 = (np.linalg.norm(L - X, axis=-1).mean() for L in (L1, L0))
        assert e1 < 0.85 * e0, (seed, e1, e0)
        assert np.isfinite(cov1).all()
    monkeypatch.setattr(faces_mod, "PIVOT_MAX", 0.0)
    L2, cov2 = faces_mod._rigid_track(*args, **kw, pivot_accel=0.1)
    np.testing.assert_array_equal(L2, L0)
    np.testing.assert_array_equal(cov2, cov0)


def test_shape_covariance_is_the_joint_inverses_extra_term():
    """The rotation covariance of a rigid face with its shape unknown too: the diagonal
    blocks of the joint (poses + shape) inverse equal the poses' own marginals plus the
    shape's share from ``_shape_covariance`` (the shape's gauge fixed the same way)."""
    rng = np.random.default_rng(1)
    n, rows = 5, 9
    step = np.r_[np.arange(n), rng.integers(0, n, rows - n)]
    Jp = rng.normal(size=(rows, 10, 6))
    Js = rng.normal(size=(rows, 10, 15))
    S = rng.normal(size=(5, 3))
    S -= S.mean(0)
    ties = rng.uniform(0.5, 2.0, (n - 1, 6))
    A = np.zeros((n, 6, 6))
    np.add.at(A, step, np.einsum("rka,rkb->rab", Jp, Jp))
    F = np.zeros((6 * n + 15, 6 * n + 15))
    for i in range(n):
        F[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = A[i] + np.diag(
            (ties[i] if i < n - 1 else 0) + (ties[i - 1] if i else 0)
        )
    for i in range(n - 1):
        for a in range(6):
            F[6 * i + a, 6 * i + 6 + a] = F[6 * i + 6 + a, 6 * i + a] = -ties[i, a]
    Hp = F[: 6 * n, : 6 * n].copy()
    ab = np.zeros((12, 6 * n))  # upper banded form (bandwidth 11)
    for d in range(12):
        ab[11 - d, d:] = np.diagonal(Hp, d)
    for r in range(rows):
        F[6 * step[r] : 6 * step[r] + 6, 6 * n :] += Jp[r].T @ Js[r]
    F[6 * n :, : 6 * n] = F[: 6 * n, 6 * n :].T
    G = np.zeros((15, 6))
    for a in range(3):
        G[a::3, a] = 1.0
        G[:, 3 + a] = np.cross(np.eye(3)[a], S).reshape(-1)
    G /= np.linalg.norm(G, axis=0)
    Hss = np.einsum("rka,rkb->ab", Js, Js)
    F[6 * n :, 6 * n :] = Hss + 1e6 * np.trace(Hss) * G @ G.T
    joint = np.linalg.inv(F)
    own = _tridiagonal_marginals(Hp.reshape(n, 6, n, 6)[np.arange(n), :, np.arange(n)], ties)
    extra = _shape_covariance(ab, Jp, Js, step, S)
    for i in range(n):
        want = joint[6 * i : 6 * i + 3, 6 * i : 6 * i + 3] - own[i, :3, :3]
        np.testing.assert_allclose(extra[i], want, rtol=1e-5, atol=1e-9)
    assert np.trace(extra, axis1=1, axis2=2).min() > 0


def test_faces_seen_by_one_camera_join_their_tracks(scene):
    """``single_view``: a tracked face seen by one camera at an instant gets a ray there,
    placed by the track (measured on this scene: face-instants 185 → 272, median gaze error
    2.10 → 2.54°, association 0.998 either way, no false detection), and its σ says it is
    less sure than the instants seen by several cameras (2.3 vs 1.7° median). Their depth
    comes from the position ties: landmarks 23 mm off median (68 mm without the ties; 3 mm
    where several cameras see the face)."""
    _truth, f3, r, (one, r1) = scene
    assert r1["association"] >= 0.98 and r1["false_surviving"] == 0, r1
    assert r1["face_instants"] > 1.3 * r["face_instants"], (r1["face_instants"], r["face_instants"])
    assert not (np.isfinite(f3.v[..., 0]) & (f3.views < 2)).any()  # off by default
    single = np.isfinite(one.v[..., 0]) & (one.views == 1)
    multi = np.isfinite(one.v[..., 0]) & (one.views >= 2)
    sig = np.sqrt(np.maximum(one.h**2 - 0.05**2, 0.0))
    assert np.median(sig[single]) > 1.2 * np.median(sig[multi])
    assert r1["gaze_deg"] < 1.5 * r["gaze_deg"], (r1["gaze_deg"], r["gaze_deg"])
    views = np.concatenate(
        [one.views[np.isfinite(one.landmarks[:, j, 0, 0]), j] for j in r1["owner"]]
    )
    assert np.median(r1["landmark_errors_m"][views == 1]) < 0.04


def test_ransac_only_association_tells_the_people_apart(scene):
    """Without the wearers' anchors every face goes through RANSAC and tracks. On this
    circle a track used to gather detections whose Eq 3.4 normal equations are singular (a
    DegenerateError from the core once): the track keeps its Eq 3.3 landmarks instead. And
    a track claiming detections by distance took other people's faces (association 0.79
    here, 0.87 / 0.84 on seeds 2 / 3) until a tracked face had to be one face: the largest
    set of its detections that a pair of them with a face's proportions reprojects
    (measured: 1.000 on seeds 1-3, face-instants 188 -> 177)."""
    truth = scene[0]
    dets, cams = truth_detections(truth, scale=8.0, seed=1)
    f3 = reconstruct_faces(dets, cams, anchors=False)
    assert f3.landmarks.shape[1] > 0 and np.isfinite(f3.v[..., 0]).sum() > 150
    scaled = dataclasses.replace(truth, K=np.stack([c.K[0] for c in cams]))
    assert faces_vs_truth(scaled, dets, f3)["association"] >= 0.97


def test_bench_oracle_hold_means(scene):
    """``benches/faces_attention.py oracle=m``: while a wearer holds a target (0.5 s after
    a change of code), its exo direction becomes the true head direction averaged over that
    hold, turned ``hold_error`` degrees; elsewhere (and for the people without a camera)
    the reconstructed direction is kept."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benches" / "faces_attention.py"
    spec = importlib.util.spec_from_file_location("faces_attention_bench", path)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    truth, f3, r, _one = scene
    V = len(truth.names)
    ft = truth.frame_times[0] - truth.start[0]
    k = np.abs(ft[None] - np.asarray(f3.times)[:, None]).argmin(1)
    codes = truth.face_target[0]
    exact = bench.with_true_rays(truth, f3, r["owner"], "m", 0.0, 1)
    off = bench.with_true_rays(truth, f3, r["owner"], "m", 2.0, 1)
    replaced = 0
    for j, w in r["owner"].items():
        seen = np.nonzero(np.isfinite(f3.v[:, j, 0]))[0]
        moved = seen[~np.all(np.isclose(exact.v[seen, j], f3.v[seen, j]), axis=1)]
        if w >= V:
            assert len(moved) == 0
            continue
        # runs of consecutive replaced instants with one code: one hold each
        cut = np.nonzero((np.diff(moved) > 1) | (np.diff(codes[k[moved], w]) != 0))[0] + 1
        for run in np.split(moved, cut):
            if len(run) == 0:
                continue
            m = truth.face_normal[0][k[run], w].mean(0)
            m /= np.linalg.norm(m)
            assert np.allclose(exact.v[run, j], m, atol=1e-9)
            ang = np.degrees(np.arccos(np.clip(off.v[run, j] @ m, -1, 1)))
            assert np.allclose(ang, 2.0, atol=1e-6)
            replaced += len(run)
    assert replaced > 50, replaced
