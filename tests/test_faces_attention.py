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

from socialcam.faces import _tridiagonal_marginals, fuse_ego_exo, reconstruct_faces
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
    return truth, f3, faces_vs_truth(scaled, dets, f3)


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
    truth, _f3, _r = scene
    owner = {j: j for j in range(truth.face_normal[0].shape[1])}
    exact = face_joint_attention(truth, _truth_rays(truth), owner)
    # groups count once their members have looked at the head for 0.6 s: 34 groups, the
    # ego rays find all (without the settling time: 51 groups, 96 % found)
    assert 25 <= exact["exo"]["groups"] <= 45 and exact["exo"]["found_fraction"] >= 0.85, exact
    assert exact["ego"]["found_fraction"] >= 0.98, exact
    assert exact["exo"]["error_median_m"] < 1.25 * exact["ego_same_groups"]["error_median_m"]
    turned = face_joint_attention(truth, _truth_rays(truth, 3.0), owner)
    assert turned["exo"]["error_median_m"] > 1.6 * exact["exo"]["error_median_m"], turned


def test_exo_joint_attention_and_ego_exo_fusion(scene):
    """Exo rays from the reconstructed faces on the rendered circle. Measured on this scene
    (default / rotations not tied / not rigid / Cauchy ties without the quadratic start):
    face gaze 2.10 / 4.91 / 5.39 / 3.01° median; joint-attention groups found 1.00 / 0.29 /
    0.23 / 0.65 with exo error 0.20 / 0.36 / 0.36 / 0.26 m (ego rays on the same groups
    0.056 m: the issue's 1.5× is not met, see ``benches/faces_accuracy.out.txt``); ego/exo
    disagreement of the wearers 1.9 / 5.4 / 5.8 / 3.1° median."""
    truth, f3, r = scene
    assert r["association"] >= 0.98 and r["face_instants"] >= 150, r
    assert r["gaze_deg"] < 2.6, r["gaze_deg"]
    ja = face_joint_attention(truth, f3, r["owner"])
    assert ja["exo"]["groups"] >= 25 and ja["exo"]["found_fraction"] >= 0.85, ja
    assert ja["exo"]["error_median_m"] < 0.3, ja
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
    _truth, f3, r = scene
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
