from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import socialcam as sc
from socialcam import synth


def _rig(seed: int = 0, n: int = 4) -> sc.Cameras:
    return synth.ring_rig(n, seed=seed)


def test_projection_matrix_agrees_with_project():
    cams = _rig()
    X = synth.random_points(20, seed=1)
    px = cams.project(X)
    h = np.einsum("fij,nj->fni", cams.P, np.c_[X, np.ones(len(X))])
    np.testing.assert_allclose(px, h[..., :2] / h[..., 2:], rtol=1e-10)
    assert cams.P.shape == (4, 3, 4)
    # P = K R [I | -C]
    f = 2
    P = cams.K[f] @ cams.R[f] @ np.c_[np.eye(3), -cams.C[f]]
    np.testing.assert_allclose(cams.P[f], P, rtol=1e-12, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_project_back_project_round_trip(seed):
    cams = synth.random_photographers(6, seed=seed)
    X = synth.random_points(5, seed=seed + 1, extent=0.5)
    px, depth = cams.project(X, return_depth=True)
    assert (depth > 0).all()
    d = cams.back_project(px)  # (F, N, 3)
    truth = X[None] - cams.C[:, None]
    truth /= np.linalg.norm(truth, axis=-1, keepdims=True)
    np.testing.assert_allclose(d, truth, atol=1e-10)


def test_len_slicing_and_times():
    cams = synth.random_photographers(10, seed=3)
    assert len(cams) == 10
    sub = cams[2:5]
    assert len(sub) == 3
    np.testing.assert_array_equal(sub.C, cams.C[2:5])
    np.testing.assert_array_equal(sub.times, cams.times[2:5])
    one = cams[-1]
    assert len(one) == 1 and np.array_equal(one.R[0], cams.R[-1])
    assert len(cams[[0, 3, 7]]) == 3
    with pytest.raises(IndexError):
        cams[10]
    assert cams.with_times(np.arange(10.0) * 2).times[-1] == 18.0
    with pytest.raises(ValueError, match="read-only"):
        cams.C[0, 0] = 1.0


def test_shared_K_broadcasts():
    cams = _rig()
    one = sc.Cameras(cams.K[0], cams.R, cams.C)
    assert one.K.shape == (4, 3, 3)
    np.testing.assert_array_equal(one.K, np.broadcast_to(cams.K[0], (4, 3, 3)))
    X = synth.random_points(5, seed=2)
    np.testing.assert_allclose(one.project(X), cams.project(X), rtol=1e-12)


@pytest.mark.parametrize(
    "change, arg",
    [
        (lambda K, R, C: (K, R[:, :2], C), "R"),
        (lambda K, R, C: (K, R, C[:, :2]), "C"),
        (lambda K, R, C: (K[:, :2], R, C), "K"),
        (lambda K, R, C: (K, R * 1.1, C), "R"),
        (lambda K, R, C: (K, R, np.where(np.arange(3) == 0, np.nan, C)), "C"),
        (lambda K, R, C: (np.zeros_like(K), R, C), "K"),
        (
            lambda K, R, C: (
                K * np.array([1, 1, 0])[None, :, None] * 0 + np.diag([0.0, 1, 1]),
                R,
                C,
            ),
            "K",
        ),
        (lambda K, R, C: (K, R @ np.diag([1.0, 1, -1]), C), "R"),
    ],
)
def test_bad_cameras_name_the_argument(change, arg):
    cams = _rig()
    K, R, C = change(cams.K.copy(), cams.R.copy(), cams.C.copy())
    with pytest.raises(ValueError, match=rf"^{arg}"):
        sc.Cameras(K, R, C)


def test_bad_times():
    cams = _rig()
    with pytest.raises(ValueError, match="times"):
        sc.Cameras(cams.K, cams.R, cams.C, times=[0.0, 1.0])
    with pytest.raises(ValueError, match="times"):
        sc.Cameras(cams.K, cams.R, cams.C, times=[0.0, 1.0, np.inf, 2.0])


def _write_colmap_text(folder):
    (folder / "cameras.txt").write_text(
        "1 PINHOLE 640 480 500 510 320.5 240.5\n2 SIMPLE_RADIAL 640 480 520 320 240 0.05\n"
    )
    # qw qx qy qz tx ty tz: identity, and 45° about y.
    (folder / "images.txt").write_text(
        "1 1 0 0 0 0.5 -0.2 3 1 a.png\n\n2 0.9238795325 0 0.3826834324 0 -1 0.1 2.5 2 b.png\n\n"
    )
    (folder / "points3D.txt").write_text("")


def test_from_colmap_pixel_convention_and_centres(tmp_path):
    _write_colmap_text(tmp_path)
    cams = sc.Cameras.from_colmap(tmp_path)
    assert len(cams) == 2
    # Image a: R = I, t = (0.5, -0.2, 3) → C = -t; principal point shifted by -0.5 px.
    np.testing.assert_allclose(cams.C[0], [-0.5, 0.2, -3.0], atol=1e-12)
    np.testing.assert_allclose(cams.K[0], [[500, 0, 320.0], [0, 510, 240.0], [0, 0, 1]])
    import pycolmap

    rec = pycolmap.Reconstruction(str(tmp_path))
    img = next(i for i in rec.images.values() if i.name == "b.png")
    np.testing.assert_allclose(cams.C[1], img.projection_center(), atol=1e-9)
    # A world point projects where COLMAP projects it, minus half a pixel.
    X = np.array([0.3, -0.1, 2.0])
    cam = rec.cameras[img.camera_id]
    pose = img.cam_from_world() if callable(img.cam_from_world) else img.cam_from_world
    xc = pose * X if hasattr(pose, "__mul__") else None
    ours = cams[1].project(X)[0]
    theirs = np.asarray(cam.img_from_cam(np.asarray(xc)[None]))[0] - 0.5
    # Camera b has radial distortion: undistorting COLMAP's pixel gives our pinhole pixel.
    np.testing.assert_allclose(cams[1].undistort_points(theirs[None])[0], ours, atol=1e-6)
    assert np.linalg.norm(theirs - ours) > 1e-3  # distortion is really there
    # scaled (a map put in metres): centres times s, projections of scaled points and the
    # lens unchanged
    big = cams.scaled(2.5)
    np.testing.assert_allclose(big.C, cams.C * 2.5)
    np.testing.assert_array_equal(big.R, cams.R)
    np.testing.assert_allclose(big[1].project(2.5 * X)[0], ours, atol=1e-9)
    np.testing.assert_allclose(big[1].undistort_points(theirs[None])[0], ours, atol=1e-6)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="s"):
            cams.scaled(bad)
    # moved (a group of cameras put back into another frame): the moved points project
    # where the points did, the lens kept; a reflection or NaN is refused
    a = np.radians(30.0)
    Rm = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    tm = np.array([0.5, -1.0, 0.2])
    mv = cams.moved(Rm, tm)
    np.testing.assert_allclose(mv.C, cams.C @ Rm.T + tm, atol=1e-12)
    np.testing.assert_allclose(mv[1].project(Rm @ X + tm)[0], ours, atol=1e-9)
    np.testing.assert_allclose(mv[1].undistort_points(theirs[None])[0], ours, atol=1e-6)
    with pytest.raises(ValueError, match="R: expected a rotation"):
        cams.moved(np.diag([1.0, 1.0, -1.0]), tm)
    with pytest.raises(ValueError, match="t"):
        cams.moved(Rm, [0.0, float("nan"), 0.0])
    with pytest.raises(ValueError, match="R"):
        cams.moved(np.eye(2), tm)


def test_from_colmap_errors(tmp_path):
    with pytest.raises(ValueError, match="reconstruction"):
        sc.Cameras.from_colmap(tmp_path / "nope")
    _write_colmap_text(tmp_path)
    with pytest.raises(ValueError, match="image_names"):
        sc.Cameras.from_colmap(tmp_path, image_names=["zzz.png"])


def test_from_colmap_damaged_models_are_errors_naming_the_file(tmp_path):
    # pycolmap loops without end on an images.bin cut after its count, reads other binary
    # files cut short as far as they go, and fails on broken ones with its own exceptions.
    import pycolmap

    _write_colmap_text(tmp_path)
    good = tmp_path / "bin"
    good.mkdir()
    pycolmap.Reconstruction(str(tmp_path)).write_binary(str(good))
    assert len(sc.Cameras.from_colmap(good)) == 2
    for name in ("images.bin", "cameras.bin", "points3D.bin", "rigs.bin", "frames.bin"):
        if not (good / name).exists():  # pycolmap before rigs and frames
            continue
        data = (good / name).read_bytes()
        for cut in sorted({4, 8, len(data) // 2, len(data) - 1} - {len(data)}):
            bad = tmp_path / f"{name}_{cut}"
            bad.mkdir()
            for f in good.iterdir():
                (bad / f.name).write_bytes(f.read_bytes() if f.name != name else data[:cut])
            with pytest.raises(ValueError, match="reconstruction: ") as err:
                sc.Cameras.from_colmap(bad)
            assert name in str(err.value) or str(bad) in str(err.value), err.value
    garbage = tmp_path / "garbage"
    garbage.mkdir()
    (garbage / "cameras.txt").write_text("1 PINHOLE 640 480 500 510 320.5 240.5\n")
    (garbage / "images.txt").write_text("1 1 0 0 0 0.5 -0.2 3 7 a.png\n\n")  # camera 7
    (garbage / "points3D.txt").write_text("")
    with pytest.raises(ValueError, match="cannot read the COLMAP model"):
        sc.Cameras.from_colmap(garbage)
    twice = tmp_path / "twice"
    twice.mkdir()
    _write_colmap_text(twice)
    (twice / "images.txt").write_text(
        "1 1 0 0 0 0.5 -0.2 3 1 a.png\n\n2 1 0 0 0 0.1 -0.2 3 2 a.png\n\n"
    )
    with pytest.raises(ValueError, match=r"registered twice: \['a.png'\]"):
        sc.Cameras.from_colmap(twice)
    with pytest.raises(ValueError, match="reconstruction: expected a folder"):
        sc.Cameras.from_colmap(3)  # type: ignore[arg-type]


def test_indexing_takes_integers_slices_and_masks_only():
    cams = _rig()
    n = len(cams)
    assert len(cams[[0, 2]]) == 2 and len(cams[np.arange(n) % 2 == 0]) == (n + 1) // 2
    np.testing.assert_array_equal(cams[-1].C, cams.C[-1:])
    assert len(cams[[]]) == 0 and repr(cams.with_times(np.arange(n))[1:1]) == "Cameras(F=0)"
    # None, a bool, a 2-D array, floats, a mask of another length, out of range: IndexError
    # (None and np.True_ used to add an axis and fail later deep in the core; True meant 1)
    for bad in (None, True, np.True_, np.array([[0, 1]]), [0.5], [n], "a", np.ones(n + 1, bool)):
        with pytest.raises(IndexError, match="camera index"):
            cams[bad]


def test_moved_and_scaled_refuse_overflow_and_keep_rotations():
    cams = _rig()
    with pytest.raises(ValueError, match="s: centres times 1e"):
        cams.scaled(1e200).scaled(1e200)
    with pytest.raises(ValueError, match="t: the moved camera centres overflow"):
        cams.moved(np.eye(3), [1e308, 0.0, 0.0]).moved(np.eye(3), [1e308, 0.0, 0.0])
    # a rotation 1e-7 off orthonormal, applied 2000 times: snapped each time, so the
    # result is still a rotation the constructor takes (det R drifted to 1.005 before)
    a = 1e-3
    turn = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    turn = turn * (1 + 1e-7)
    out = cams
    for _ in range(2000):
        out = out.moved(turn, np.zeros(3))
    assert np.abs(np.linalg.det(out.R) - 1).max() < 1e-9
    sc.Cameras(out.K, out.R, out.C)
