from __future__ import annotations

import numpy as np
import pytest

import socialcam as sc
from socialcam import synth


def test_same_seed_same_scene_different_seed_different_scene():
    a = synth.multiview_scene(50, 3, noise_px=1.0, missing=0.2, seed=5)
    b = synth.multiview_scene(50, 3, noise_px=1.0, missing=0.2, seed=5)
    c = synth.multiview_scene(50, 3, noise_px=1.0, missing=0.2, seed=6)
    np.testing.assert_array_equal(a.obs.x, b.obs.x)
    assert not np.array_equal(np.nan_to_num(a.obs.x), np.nan_to_num(c.obs.x))


def test_noise_and_missing_statistics():
    scene = synth.multiview_scene(4000, 4, noise_px=2.0, missing=0.25, seed=1)
    miss = scene.obs.missing
    assert abs(miss.mean() - 0.25) < 0.02
    resid = (scene.obs.x - scene.obs.x_clean)[~miss]
    assert abs(resid.std() - 2.0) < 0.05
    assert abs(resid.mean()) < 0.05


def test_camera_paths_look_at_their_target():
    tgt = np.array([0.5, -0.5, 1.0])
    for cams in (
        synth.smooth_path(50, seed=2, target=tgt),
        synth.ring_rig(6, seed=2, target=tgt),
    ):
        px, depth = cams.project(tgt, return_depth=True)
        assert (depth > 0).all()
        K = cams.K[0]
        np.testing.assert_allclose(px, np.broadcast_to(K[:2, 2], px.shape), atol=1e-6)
    photo = synth.random_photographers(200, seed=3, target=tgt, aim_jitter=0.3)
    px, depth = photo.project(tgt, return_depth=True)
    assert (depth > 0).all() and (np.abs(px - photo.K[0, :2, 2]).max() < 640)


def test_smooth_path_is_smooth_and_photographers_are_not():
    smooth = synth.smooth_path(100, seed=0)
    rand = synth.random_photographers(100, seed=0)

    def step(C):
        return np.linalg.norm(np.diff(C, axis=0), axis=1).mean()

    assert step(smooth.C) < 0.05
    assert step(rand.C) > 2.0


def test_head_mounted_camera_follows_the_head():
    pos, d = synth.walking_head(90, seed=1)
    cams = synth.head_mounted(pos, d)
    np.testing.assert_allclose(cams.optical_axes, d, atol=1e-12)
    assert np.linalg.norm(cams.C - pos, axis=1).max() < 0.11
    speed = np.linalg.norm(np.diff(pos[:, :2], axis=0), axis=1) * 30
    assert 1.0 < speed.mean() < 1.6
    assert np.ptp(pos[:, 2]) > 0.03  # head bob


def test_smooth_trajectories_static_fraction():
    t = np.arange(100) / 30
    X = synth.smooth_trajectories(200, t, seed=0, static_fraction=0.5)
    moving = np.ptp(X, axis=1).max(axis=1) > 0
    assert 0.35 < 1 - moving.mean() < 0.65
    assert X.shape == (200, 100, 3)


def test_moving_points_observed_frame_by_frame():
    cams = synth.random_photographers(60, seed=1)
    X = synth.smooth_trajectories(3, cams.times, seed=2)
    obs = synth.observe(X, cams, noise_px=0.0)
    np.testing.assert_allclose(obs.x[1], cams.project_trajectory(X[1]))
    for f in (0, 17, 59):
        np.testing.assert_allclose(obs.x[1, f], cams[f].project(X[1, f])[0], atol=1e-9)


def test_gaze_model_offset_distribution():
    rng = np.random.default_rng(0)
    u = np.tile([0.0, 0.0, 1.0], (20000, 1))
    v = synth.primary_from_true(u, 0.1, rng)
    # Offset of the true direction on the plane at unit distance along v.
    m = u / np.sum(u * v, axis=1, keepdims=True) - v
    assert np.abs(np.sum(m * v, axis=1)).max() < 1e-12
    r = np.linalg.norm(m, axis=1)
    # |m| is Rayleigh with sigma = h: E|m|^2 = 2 h^2.
    assert np.mean(r**2) == pytest.approx(2 * 0.1**2, rel=0.03)


def test_look_at_keeps_the_world_upright_in_the_image():
    """World up is image up (smaller row) and world left is image left: no 180° roll."""
    C = np.array([[0.0, 0.0, 1.6]])
    R = synth.look_at(C, np.array([3.0, 0.0, 1.6]))
    cams = sc.Cameras(synth.intrinsics(640, 480), R, C)
    centre = cams.project(np.array([3.0, 0.0, 1.6]))[0]
    above = cams.project(np.array([3.0, 0.0, 2.0]))[0]
    left = cams.project(np.array([3.0, 0.5, 1.6]))[0]  # +y is on the left when facing +x
    assert above[1] < centre[1] - 10 and abs(above[0] - centre[0]) < 1e-6
    assert left[0] < centre[0] - 10 and abs(left[1] - centre[1]) < 1e-6
    np.testing.assert_allclose(np.linalg.det(R), 1.0)


def test_people_look_at_their_targets():
    eyes = synth.wander(40, 5, seed=3, fps=10)
    targets = np.array([[0.0, 0.0, 1.0], [2.0, 1.0, 1.5]])
    att = np.zeros((40, 5), dtype=int)
    att[:, 3:] = 1
    att[20:, 4] = -1
    people = synth.looking_at(eyes, targets, att, h=0.05, seed=1)
    np.testing.assert_allclose(people.regard[:, 0], np.broadcast_to(targets[0], (40, 3)))
    cos = np.sum(people.gaze * people.gaze_true, axis=-1)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).mean() < 8  # h = 0.05 ≈ 2.9°
    p, v, h, ids = people.rays(0)
    assert (
        p.shape == (5, 3)
        and v.shape == (5, 3)
        and h.shape == (5,)
        and ids.tolist() == [0, 1, 2, 3, 4]
    )
    assert np.allclose(np.linalg.norm(people.gaze, axis=-1), 1)
    lo, hi = np.array([-4.0, -4.0]), np.array([4.0, 4.0])
    assert ((eyes[..., :2] >= lo) & (eyes[..., :2] <= hi)).all()


@pytest.mark.parametrize(
    "call, arg",
    [
        (lambda: synth.observe(np.zeros((3, 2)), synth.ring_rig(2)), "points"),
        (lambda: synth.observe(np.zeros((3, 3)), synth.ring_rig(2), missing=1.0), "missing"),
        (lambda: synth.observe(np.zeros((3, 3)), synth.ring_rig(2), noise_px=-1), "noise_px"),
        (lambda: synth.ring_rig(2, seed=-1), "seed"),
        (
            lambda: synth.looking_at(
                np.zeros((2, 1, 3)), np.ones((1, 3)), np.zeros((2, 1), dtype=int), h=0.0
            ),
            "h",
        ),
        (
            lambda: synth.looking_at(
                np.zeros((2, 1, 3)), np.ones((1, 3)), np.ones((2, 1), dtype=int)
            ),
            "attention",
        ),
        (lambda: synth.look_at(np.zeros((1, 3)), np.zeros(3)), "targets"),
    ],
)
def test_bad_input(call, arg):
    with pytest.raises(ValueError, match=arg):
        call()


def test_intrinsics_match_field_of_view():
    K = synth.intrinsics(1000, 500, 90.0)
    assert K[0, 0] == pytest.approx(500.0)
    cams = sc.Cameras(K, np.eye(3)[None], np.zeros((1, 3)))
    # A point at 45° to the right lands on the right border.
    assert cams.project(np.array([1.0, 0.0, 1.0]))[0, 0] == pytest.approx(999.5)
