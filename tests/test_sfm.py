"""Structure from motion on real photos, and the COLMAP → socialcam conventions checked
against COLMAP's own reprojections."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest

import socialcam as sc
from socialcam.sfm import reconstruct_static

TRUE_FOCAL = 2905.88 / 4  # K.txt of the dataset, images downscaled 4x


@pytest.fixture(scope="module")
def castle(data_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("sfm") / "castle"
    stages: list[str] = []
    model = reconstruct_static(
        data_dir / "sceaux_castle_small", out, max_image_size=800, progress=stages.append
    )
    assert stages == ["features", "matching", "mapping"]
    return pycolmap.Reconstruction(str(model))


def _observations(rec, cams: sc.Cameras, names: list[str]):
    """Per 3D point: its COLMAP position and its raw pixels (OpenCV convention) per view."""
    index = {n: i for i, n in enumerate(names)}
    by_id = {img.image_id: img for img in rec.images.values()}
    ids = sorted(rec.points3D)
    X = np.array([rec.points3D[i].xyz for i in ids])
    x = np.full((len(ids), len(names), 2), np.nan)
    for row, pid in enumerate(ids):
        for el in rec.points3D[pid].track.elements:
            img = by_id[el.image_id]
            x[row, index[img.name]] = np.asarray(img.points2D[el.point2D_idx].xy) - 0.5
    return X, x


def test_all_photos_registered_with_the_true_focal_length(castle):
    assert castle.num_reg_images() == 6
    (cam,) = castle.cameras.values()
    assert cam.focal_length == pytest.approx(TRUE_FOCAL, rel=0.06)
    assert castle.compute_mean_reprojection_error() < 1.0


def test_from_colmap_reprojects_like_colmap(castle):
    names = sorted(img.name for img in castle.images.values())
    cams = sc.Cameras.from_colmap(castle)
    assert len(cams) == 6
    X, x_raw = _observations(castle, cams, names)
    x = np.transpose(cams.undistort_points(np.transpose(x_raw, (1, 0, 2))), (1, 0, 2))
    proj = np.transpose(cams.project(X), (1, 0, 2))
    seen = np.isfinite(x).all(axis=2)
    resid = (proj - x)[seen]
    rms = np.sqrt((resid**2).sum(axis=1).mean())
    assert rms < 1.0  # COLMAP's own mean reprojection error is ~0.3 px here
    # No half-pixel bias: the COLMAP→OpenCV shift is applied exactly once.
    assert np.abs(resid.mean(axis=0)).max() < 0.05
    # Our triangulation of COLMAP's tracks lands on COLMAP's points.
    multi = seen.sum(axis=1) >= 3
    Y = sc.triangulate(x[multi], cams)
    scale = np.linalg.norm(cams.C - cams.C.mean(axis=0), axis=1).mean()
    err = np.linalg.norm(Y - X[multi], axis=1) / scale
    assert np.median(err) < 1e-3


def test_reconstruct_static_bad_input(tmp_path, data_dir):
    with pytest.raises(ValueError, match="image_dir"):
        reconstruct_static(tmp_path / "nope", tmp_path / "out")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="image_dir"):
        reconstruct_static(tmp_path / "empty", tmp_path / "out")
    (tmp_path / "out").mkdir()
    with pytest.raises(ValueError, match="out_dir"):
        reconstruct_static(data_dir / "sceaux_castle_small", tmp_path / "out")
    with pytest.raises(ValueError, match="camera_mode"):
        reconstruct_static(data_dir / "sceaux_castle_small", tmp_path / "o2", camera_mode="x")  # type: ignore[arg-type]


def test_world_up_from_head_cameras_that_look_down():
    """Gravity from head cameras: with zero roll but a mean pitch (people look down at
    things), the mean camera −y leans by that pitch; the x axes stay horizontal and give
    up exactly. Few headings (x axes nearly parallel): the mean −y is the fallback."""
    from socialcam.sfm import _camera_up
    from socialcam.synth import look_at

    rng = np.random.default_rng(4)
    n = 200
    yaw = rng.uniform(-1.0, 1.0, n)  # a short clip: headings within ±57°
    pitch = np.radians(-20 + 10 * rng.normal(size=n))  # looking 20° down on average
    d = np.c_[np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)]
    C = rng.normal(size=(n, 3))
    R = look_at(C, C + d)
    # the same cameras in a world whose up is tilted: R' = R Gᵀ for a world rotation G
    ax = np.array([1.0, 2.0, 0.0]) / np.sqrt(5.0)
    th = np.radians(30)
    K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    G = np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K
    true_up = G @ np.array([0.0, 0.0, 1.0])
    Rt = R @ G.T
    up = _camera_up(Rt)
    assert np.degrees(np.arccos(np.clip(up @ true_up, -1, 1))) < 0.1
    mean_minus_y = -Rt[:, 1, :].mean(axis=0)
    mean_minus_y /= np.linalg.norm(mean_minus_y)
    assert np.degrees(np.arccos(mean_minus_y @ true_up)) > 5.0  # what the old rule gave
    # one heading only: the x axes do not define up; fall back to the mean −y
    narrow = look_at(C[:20], C[:20] + np.array([1.0, 0.0, -0.3]))
    fallback = _camera_up(narrow)
    expected = -narrow[:, 1, :].mean(axis=0)
    np.testing.assert_allclose(fallback, expected / np.linalg.norm(expected), atol=1e-12)


def test_floor_is_found_despite_points_far_below_it():
    """The floor is the densest layer of map points well below the cameras; a few badly
    triangulated points metres below it (seen on a 4-s clip) must not hide it."""
    from socialcam.sfm import _floor_height

    rng = np.random.default_rng(2)
    floor = np.c_[rng.uniform(-4, 4, (300, 2)), rng.normal(0.0, 0.03, 300)]
    walls = np.c_[rng.uniform(-4, 4, (600, 2)), rng.uniform(0.0, 3.0, 600)]
    outliers = np.c_[rng.uniform(-4, 4, (8, 2)), rng.uniform(-8.0, -5.0, 8)]
    cams = rng.normal(1.7, 0.05, 100)
    pts = np.concatenate([floor, walls, outliers])
    assert abs(_floor_height(pts, cams, 0)) < 0.02
    # too few points below the cameras: no floor rather than a guess
    assert _floor_height(walls[walls[:, 2] > 1.0], cams, 0) is None
