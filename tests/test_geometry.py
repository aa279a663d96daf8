from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import socialcam as sc
from socialcam import synth

seeds = st.integers(0, 2**31 - 1)


@settings(max_examples=40, deadline=None)
@given(seed=seeds, n_views=st.integers(2, 8))
def test_noise_free_triangulation_is_exact(seed, n_views):
    cams = synth.ring_rig(n_views, seed=seed)
    X = synth.random_points(50, seed=seed + 1)
    obs = synth.observe(X, cams, seed=seed)
    for refine in (False, True):
        Y = sc.triangulate(obs.x, cams, refine=refine)
        np.testing.assert_allclose(Y, X, atol=1e-7)


def test_single_point_and_missing_views():
    cams = synth.ring_rig(3, seed=4)
    X = np.array([0.2, -0.3, 1.1])
    x = cams.project(X)
    np.testing.assert_allclose(sc.triangulate(x, cams), X, atol=1e-8)
    x[1] = np.nan
    np.testing.assert_allclose(sc.triangulate(x, cams), X, atol=1e-8)
    x[2] = np.nan
    with pytest.raises(sc.DegenerateError, match="at least 2 views"):
        sc.triangulate(x, cams)


def test_batch_marks_untriangulable_points():
    cams = synth.ring_rig(3, seed=4)
    X = synth.random_points(5, seed=2)
    obs = synth.observe(X, cams)
    x = obs.x.copy()
    x[1, 1:] = np.nan
    Y, info = sc.triangulate(x, cams, return_info=True)
    assert np.isnan(Y[1]).all() and np.isfinite(np.delete(Y, 1, 0)).all()
    assert "at least 2 views" in info.failures[1]
    assert info.views.tolist() == [3, 1, 3, 3, 3]


def test_parallel_rays_are_degenerate():
    K = synth.intrinsics()
    C = np.array([[0.0, 0, 0], [0.0, 0, 0]])
    R = np.stack([np.eye(3), np.eye(3)])
    cams = sc.Cameras(K, R, C)
    x = cams.project(np.array([0.1, 0.2, 3.0]))
    with pytest.raises(sc.DegenerateError, match=r"camera centre|parallel"):
        sc.triangulate(x, cams)


def test_refinement_lowers_reprojection_error_and_error_scales_with_noise():
    scene = synth.multiview_scene(500, 4, noise_px=1.0, seed=7)
    X, info = sc.triangulate(scene.obs.x, scene.cameras, return_info=True)
    assert (info.rms <= info.rms_linear + 1e-9).all()
    assert info.rms.mean() < info.rms_linear.mean()
    assert info.converged.all()
    err = np.linalg.norm(X - scene.obs.points, axis=1)
    # 1 px at ~6 m with f ≈ 1100 px is ~5 mm per view; 4 views, triangulation angle ~90°.
    assert 1e-3 < np.median(err) < 1.5e-2
    hi = synth.multiview_scene(500, 4, noise_px=4.0, seed=7)
    err_hi = np.linalg.norm(sc.triangulate(hi.obs.x, hi.cameras) - hi.obs.points, axis=1)
    assert 3.0 < np.median(err_hi) / np.median(err) < 5.0


def _transform_cameras(cams: sc.Cameras, s: float, Rw: np.ndarray, t: np.ndarray) -> sc.Cameras:
    """The same cameras after the world change X' = s Rw X + t."""
    return sc.Cameras(cams.K, cams.R @ Rw.T, s * cams.C @ Rw.T + t, cams.times)


@settings(max_examples=25, deadline=None)
@given(seed=seeds, scale=st.floats(0.01, 100.0))
def test_triangulation_is_similarity_equivariant(seed, scale):
    rng = np.random.default_rng(seed)
    Rw = Rotation.random(random_state=seed).as_matrix()
    t = rng.normal(0, 10, 3)
    scene = synth.multiview_scene(30, 4, noise_px=0.5, seed=seed % 1000)
    X = sc.triangulate(scene.obs.x, scene.cameras)
    X2 = sc.triangulate(scene.obs.x, _transform_cameras(scene.cameras, scale, Rw, t))
    np.testing.assert_allclose(X2, scale * X @ Rw.T + t, rtol=1e-6, atol=1e-6 * scale)


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(1, 80), k=st.integers(1, 80), dt=st.floats(1e-3, 10.0), t0=st.floats(-100, 100)
)
def test_dct_basis_orthonormal_on_uniform_samples(n, k, dt, t0):
    k = min(k, n)
    B = sc.dct_basis(t0 + dt * np.arange(n), k)
    assert B.shape == (n, k)
    np.testing.assert_allclose(B.T @ B, np.eye(k), atol=1e-9)
    # Spans constants: the first column is constant.
    np.testing.assert_allclose(B[:, 0], B[0, 0])


def test_dct_basis_matches_scipy_dct():
    from scipy.fft import dct

    n = 16
    B = sc.dct_basis(np.arange(n) * 0.5, n)
    # Orthonormal DCT-II: coefficients = B.T @ x.
    x = np.random.default_rng(0).normal(size=n)
    np.testing.assert_allclose(B.T @ x, dct(x, type=2, norm="ortho"), atol=1e-12)


def test_dct_basis_non_uniform_times_and_errors():
    t = np.sort(np.random.default_rng(1).uniform(0, 5, 40))
    B = sc.dct_basis(t, 6, t0=0.0, t1=5.0)
    assert B.shape == (40, 6)
    assert np.allclose(B[:, 0], B[0, 0])
    with pytest.raises(ValueError, match="k"):
        sc.dct_basis(t, 0)
    with pytest.raises(ValueError, match="times"):
        sc.dct_basis([0.0, np.nan], 2)
    with pytest.raises(ValueError, match="t0"):
        sc.dct_basis(t, 3, t0=5.0, t1=1.0)


@settings(max_examples=40, deadline=None)
@given(seed=seeds, scale=st.floats(1e-3, 1e3), n=st.integers(3, 50))
def test_align_similarity_recovers_known_transform(seed, scale, n):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    t = rng.normal(0, 5, 3)
    src = rng.normal(size=(n, 3))
    dst = scale * src @ R.T + t
    s, R_, t_ = sc.align_similarity(src, dst)
    assert s == pytest.approx(scale, rel=1e-8)
    np.testing.assert_allclose(R_, R, atol=1e-8)
    np.testing.assert_allclose(t_, t, atol=1e-7 * max(1, scale))


def test_align_similarity_errors():
    line = np.c_[np.arange(5.0), np.zeros(5), np.zeros(5)]
    with pytest.raises(sc.DegenerateError, match="collinear"):
        sc.align_similarity(line, line)
    with pytest.raises(ValueError, match="dst"):
        sc.align_similarity(np.eye(3), np.eye(4, 3))
    with pytest.raises(ValueError, match="src"):
        sc.align_similarity(np.full((3, 3), np.nan), np.eye(3))


def test_align_similarity_at_any_size_and_far_from_the_origin():
    # points of 1e200 m gave NaN scale, R and t; of 1e-200 m "coincident"; 1e6 m off the
    # origin (UTM) keeps the answer, 1e15 m (0.2 m of rounding) is refused by name
    rng = np.random.default_rng(0)
    src = rng.normal(size=(6, 3))
    dst = 2 * src + [1.0, 2.0, 3.0]
    for k in (1e200, 1e-200, 1.0):
        s, R, t = sc.align_similarity(src * k, dst * k)
        assert s == pytest.approx(2.0, rel=1e-9)
        np.testing.assert_allclose(R, np.eye(3), atol=1e-9)
        np.testing.assert_allclose(t / k, [1.0, 2.0, 3.0], atol=1e-9)
    s, R, t = sc.align_similarity(src + 6.4e6, dst + 6.4e6)
    assert s == pytest.approx(2.0, rel=1e-8)
    np.testing.assert_allclose(t, [1.0, 2.0, 3.0] - np.full(3, 6.4e6), rtol=1e-9)
    with pytest.raises(ValueError, match=r"src: .*float64 rounds"):
        sc.align_similarity(src + 1e15, dst + 1e15)


def test_ray_sphere_both_roots():
    o = np.array([[3.0, 1.0, -2.0], [0.0, 2.0, -5.0]])
    d = np.array([[-1.0, -0.2, 0.6], [0.0, 0.0, 1.0]])
    c = np.zeros((2, 3))
    s, miss = sc.ray_sphere(o, d, c, [1.5, 1.0])
    assert s[0, 0] >= s[0, 1]
    for root in s[0]:
        assert np.linalg.norm(o[0] + root * d[0]) == pytest.approx(1.5, abs=1e-12)
    assert np.isnan(s[1]).all() and miss[1] == pytest.approx(2.0)
    with pytest.raises(ValueError, match="radii"):
        sc.ray_sphere(o, d, c, [1.0, -1.0])
    with pytest.raises(ValueError, match="directions"):
        sc.ray_sphere(o, np.zeros((2, 3)), c, 1.0)


def test_perspective_distance():
    p = np.zeros((4, 3))
    v = np.tile([0.0, 0.0, 1.0], (4, 1))
    x = np.array([[1.0, 0, 2], [0, 0, -1], [0, 0, 0], [2.0, 2, 6]])
    d = sc.perspective_distance(p, v, x)
    np.testing.assert_allclose(d[0], [0.5, 0, 0])
    assert np.isinf(d[1]).all()  # behind the eye
    np.testing.assert_array_equal(d[2], 0.0)  # at the eye
    np.testing.assert_allclose(np.linalg.norm(d[3]), np.sqrt(8) / 6)


@pytest.mark.parametrize(
    "x, msg",
    [
        (np.zeros((5, 3, 3)), "x: expected shape"),
        (np.full((5, 4, 2), np.inf), "x: contains an infinite"),
        ("abc", "x: cannot be converted"),
    ],
)
def test_triangulate_bad_input(x, msg):
    with pytest.raises(ValueError, match=msg):
        sc.triangulate(x, synth.ring_rig(4))


def test_triangulate_needs_cameras():
    with pytest.raises(ValueError, match="cameras"):
        sc.triangulate(np.zeros((4, 2)), np.zeros((4, 3, 4)))  # type: ignore[arg-type]


def test_ray_sphere_directions_of_any_length():
    # the roots scale with 1/|v|; |v| of 1e200 gave NaN roots reported as a hit (miss 0)
    for k in (1e200, 2.0, 1e-170):
        s, miss = sc.ray_sphere([[0.0, 0, 0]], [[0.0, 0, k]], [[0.0, 0, 5]], 1.0)
        np.testing.assert_allclose(s * k, [[6.0, 4.0]], rtol=1e-12)
        assert miss[0] == 0.0
    with pytest.raises(ValueError, match="overflow"):
        sc.ray_sphere([[0.0, 0, 0]], [[0.0, 0, 1]], [[0.0, 0, 0]], 1e200)
