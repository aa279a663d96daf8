"""Chapter 4: exact BQP and articulated reconstruction on real CMU motion capture."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import socialcam as sc
from socialcam.mocap import load_bvh
from socialcam.synth.cameras import look_at

DATA = Path(__file__).parent / "data"


# ----------------------------------------------------------------------------- BQP
def _enumerate(Q: np.ndarray, c: np.ndarray) -> float:
    n = len(c)
    B = np.array(list(itertools.product([0.0, 1.0], repeat=n)))
    return float(np.min(np.einsum("ki,ij,kj->k", B, Q, B) + B @ c))


@pytest.mark.parametrize("seed", range(6))
def test_solve_bqp_matches_enumeration(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 8 + seed
    if seed % 2:
        A = rng.normal(size=(n + 2, n))
        Q = A.T @ A  # positive semidefinite
    else:
        A = rng.normal(scale=5, size=(n, n))
        Q = (A + A.T) / 2  # indefinite
    c = rng.normal(scale=3, size=n)
    r = sc.solve_bqp(Q, c)
    want = _enumerate(Q, c)
    assert r.optimal and r.gap == 0.0
    assert r.objective == pytest.approx(want, abs=1e-8)
    b = r.x.astype(float)
    assert b @ Q @ b + c @ b == pytest.approx(r.objective, abs=1e-9)
    assert r.to_dict()["nodes"] == r.nodes


def _read_qubo(path: Path) -> np.ndarray:
    lines = path.read_text().split("\n")
    n = int(lines[0])
    S = np.zeros((n, n))
    for ln in lines[1:]:
        if ln.strip():
            i, j, v = ln.split()
            S[int(i), int(j)] = S[int(j), int(i)] = float(v)
    return S


def test_or_library_instance_to_known_optimum() -> None:
    optima = {
        ln.split(",")[0]: float(ln.split(",")[3])
        for ln in (DATA / "bqp" / "optima_bqp50.csv").read_text().splitlines()[1:]
    }
    r = sc.solve_bqp(_read_qubo(DATA / "bqp" / "bqp50-9.qubo"))
    assert r.optimal
    assert r.objective == optima["bqp50-9"]


def test_limits_return_incumbent_and_gap() -> None:
    S = _read_qubo(DATA / "bqp" / "bqp50-1.qubo")
    r = sc.solve_bqp(S, node_limit=3)
    assert not r.optimal and r.nodes == 3
    assert r.bound <= -2098 <= r.objective
    assert r.gap >= 0


def test_bqp_bad_input() -> None:
    with pytest.raises(ValueError, match="symmetric"):
        sc.solve_bqp(np.array([[1.0, 2.0], [0.0, 1.0]]))
    with pytest.raises(ValueError, match="Q"):
        sc.solve_bqp(np.array([[1.0, np.nan], [np.nan, 1.0]]))
    with pytest.raises(ValueError, match="c"):
        sc.solve_bqp(np.eye(2), np.ones(3))
    with pytest.raises(ValueError, match="time_limit"):
        sc.solve_bqp(np.eye(2), time_limit=-1.0)
    # finite entries whose sum overflows: an infinite objective is no answer
    with pytest.raises(ValueError, match="overflows"):
        sc.solve_bqp(np.zeros((6, 6)), np.full(6, -1e308))
    assert sc.solve_bqp(np.zeros((6, 6)), np.full(6, -1e300)).objective == -6e300


def _orbit(P: np.ndarray, aim: np.ndarray, rate: float = 60.0) -> tuple[sc.Cameras, np.ndarray]:
    """One camera per frame (``rate`` Hz, f = 1000 px) on a 1 rad arc 1.5 m from ``aim``
    (F, 3), 0.3 m above it, looking at it; and the pixels of the points ``P`` (F, J, 3)."""
    F = P.shape[0]
    walk = aim[-1] - aim[0]
    walk[1] = 0
    walk /= np.linalg.norm(walk)
    side = np.cross(walk, [0.0, 1.0, 0.0])
    ang = np.linspace(-0.5, 0.5, F)[:, None]
    C = aim + 1.5 * (np.cos(ang) * side + np.sin(ang) * walk) + [0.0, 0.3, 0.0]
    K = np.array([[1000.0, 0, 640], [0, 1000.0, 360], [0, 0, 1]])
    R = look_at(C, aim, up=(0.0, 1.0, 0.0))
    cams = sc.Cameras(K, R, C, np.arange(F) / rate)
    Ks = np.broadcast_to(K, (F, 3, 3))
    px = np.stack(
        [
            sc._core.project(Ks[i : i + 1], cams.R[i : i + 1], C[i : i + 1], P[i])[0][0]
            for i in range(F)
        ]
    )
    return cams, px


# ----------------------------------------------------------- articulated, real mocap
class Scene:
    """CMU subject 131 walking (real motion), 60 frames at 60 Hz, seen by one camera per
    frame that orbits the subject at 1.5 m (a synthetic camera, as in the thesis)."""

    def __init__(self) -> None:
        m = load_bvh(DATA / "mocap" / "cmu_131_01_walk300.bvh")
        self.skeleton, keep = sc.Skeleton.from_bvh(m)
        P = m.positions[::2][:60][:, keep]
        self.cams, self.px = _orbit(P, P[:, 0])
        self.P = P
        self.k = 8
        self.eta = {
            j: sc.articulated_reconstructability(
                P[:, j], self.cams, P[:, self.skeleton.parents[j]], self.k
            )
            for j in range(1, len(self.skeleton.names))
        }

    def rel_error(self, est: np.ndarray, j: int) -> float:
        """‖ΔX − ΔX̂‖ / ‖ΔX‖ on the bone vector (stricter than on world positions)."""
        par = self.P[:, self.skeleton.parents[j]]
        return float(np.linalg.norm(est - self.P[:, j]) / np.linalg.norm(self.P[:, j] - par))


@pytest.fixture(scope="module")
def scene() -> Scene:
    return Scene()


def _smooth_offset(F: int, magnitude: float, rng: np.random.Generator) -> np.ndarray:
    t = np.linspace(0, 1, F)[:, None]
    a, b = rng.normal(size=(2, 3))
    off = a + np.sin(2 * np.pi * t) * b
    return off * magnitude / np.linalg.norm(off, axis=1).mean()


def _run(
    scene: Scene,
    j: int,
    *,
    noise=0.5,
    root_ratio=0.0,
    scale=1.0,
    missing=0.0,
    seed=0,
    fit=False,
    method="thesis",
    **options,
):
    rng = np.random.default_rng(seed + 17 * j)
    p = scene.skeleton.parents[j]
    r = scene.skeleton.lengths[j]
    F = scene.P.shape[0]
    x = scene.px[:, j] + rng.normal(0, noise, (F, 2))
    x[rng.random(F) < missing] = np.nan
    parent = scene.P[:, p] + _smooth_offset(F, root_ratio * r, rng)
    out = sc.reconstruct_articulated(
        x, scene.cams, parent, r * scale, k=scene.k, fit_radius=fit, method=method, **options
    )
    return out, scene.rel_error(out.points, j)


#: Noise draws every accuracy statistic below is pooled over. One draw is not enough: with
#: the thesis method a joint's result can flip between the truth and the impostor with the
#: noise realisation (on this scene, 0.5 px: the median error of the η_a > 1.25 joints is
#: 0.034–0.04 on 7 of 12 draws and 0.5–0.75 on 3). Thresholds below come from seeds 0–11
#: pooled in groups of four; "measured" gives the range over seeds 0–3, 4–7 and 8–11.
SEEDS = range(4)

_CACHE: dict[tuple, np.ndarray] = {}


def _errs(scene: Scene, joints: list[int], method: str, **kw) -> np.ndarray:
    """Relative errors ``(len(SEEDS), len(joints))`` under the conditions ``kw`` of
    :func:`_run` (cached: several tests share conditions)."""
    key = (tuple(joints), method, tuple(sorted(kw.items())))
    if key not in _CACHE:
        _CACHE[key] = np.array(
            [[_run(scene, j, seed=s, method=method, **kw)[1] for j in joints] for s in SEEDS]
        )
    return _CACHE[key]


def _good(scene: Scene) -> list[int]:
    return [j for j, e in scene.eta.items() if e > 1.25]


def _low(scene: Scene) -> list[int]:
    return [j for j, e in scene.eta.items() if e < 0.95]


def test_error_is_low_when_reconstructability_is_high(scene: Scene) -> None:
    # Fig 4.2(c): η_a ≫ 1 → the truth; η_a < 1 → the (smoother) impostor. Thesis method,
    # 0.5 px, pooled over the draws: median 0.068–0.097 for η_a > 1.25 (one draw: 0.034 to
    # 0.75), 1.13 on every draw for η_a < 0.95.
    high, low = _errs(scene, _good(scene), "thesis"), _errs(scene, _low(scene), "thesis")
    assert high.shape[1] >= 4 and low.shape[1] >= 3
    assert np.median(high) < 0.2, np.median(high, axis=1)
    assert np.median(low) > 0.8, np.median(low, axis=1)


def test_robust_method_is_stable_over_noise_draws(scene: Scene) -> None:
    # The same scene and noise with the robust method: the median error of the η_a > 1.25
    # joints is 0.031–0.038 on each of 12 draws (pooled mean 0.089–0.136: RightHip,
    # η_a = 1.26, follows the impostor on most draws).
    high = _errs(scene, _good(scene), "robust")
    assert np.median(high, axis=1).max() < 0.06, np.median(high, axis=1)
    assert high.mean() < 0.2, high.mean(axis=1)


def test_error_grows_with_root_error(scene: Scene) -> None:
    # Fig 4.3(a): the error grows with the ratio of root error to bone length. Thesis
    # method, pooled medians measured: 0.068–0.097 (exact root), 0.386–0.604 (0.1),
    # 0.698–0.807 (0.5).
    good = _good(scene)
    med = {
        ratio: float(np.median(_errs(scene, good, "thesis", root_ratio=ratio)))
        for ratio in (0.0, 0.1, 0.5)
    }
    assert med[0.0] < 0.2, med
    assert med[0.0] < med[0.1] < med[0.5], med
    assert med[0.5] > 0.5, med


def test_robust_to_small_radius_scale(scene: Scene) -> None:
    # Fig 4.3(b): radius scales 1e-2 … 1e0 reconstruct reliably (the sphere is enlarged to
    # meet every ray, so the result is that of the exact length); a scale of 3 is
    # unreliable (every ray meets the too-large sphere): median 2.88–3.11.
    good = _good(scene)
    exact = _errs(scene, good, "thesis")
    np.testing.assert_allclose(_errs(scene, good, "thesis", scale=0.01), exact, atol=0.01)
    assert np.median(exact) < 0.2
    assert np.median(_errs(scene, good, "thesis", scale=3.0)) > 1.0


def test_five_percent_missing_data(scene: Scene) -> None:
    # Fig 4.3(c): 5% missing, 0.5 px noise, length under-estimated by 5%. Pooled medians
    # measured: thesis 0.068–0.096, robust 0.034–0.037 (per draw ≤ 0.041).
    good = _good(scene)
    kw = {"scale": 0.95, "missing": 0.05}
    assert np.median(_errs(scene, good, "thesis", **kw)) < 0.2
    robust = _errs(scene, good, "robust", **kw)
    assert np.median(robust, axis=1).max() < 0.06, np.median(robust, axis=1)
    out, _ = _run(scene, good[0], missing=0.05)
    assert out.points.shape == (60, 3) and np.isfinite(out.points).all()


FIG_43C = {"noise": 1.0, "root_ratio": 0.05, "scale": 1.05, "missing": 0.05}


def test_fitted_radius_under_thesis_conditions(scene: Scene) -> None:
    # The thesis' Fig 4.3(c) conditions: 5% missing, 1 px noise, 5% root error and a 5%
    # length error. Only enlarging the sphere (the thesis) flips joints to the impostor
    # (mean 0.62–0.75); fitting the radius to the rays keeps more of them (mean
    # 0.48–0.53, 0.64–0.84 × the thesis'; median 0.28–0.49).
    good = _good(scene)
    fitted = _errs(scene, good, "thesis", fit=True, **FIG_43C)
    thesis = _errs(scene, good, "thesis", **FIG_43C)
    assert np.median(fitted) < 0.6, np.median(fitted)
    assert fitted.mean() < 0.9 * thesis.mean(), (fitted.mean(), thesis.mean())
    # Fitting ignores an over-estimated length entirely.
    j = good[-1]
    out, e = _run(scene, j, scale=3.0, fit=True)
    _, e1 = _run(scene, j, fit=True)
    assert out.radius < 1.02 * scene.skeleton.lengths[j]
    assert e == pytest.approx(e1, abs=1e-6)


def test_skeleton_recursive_and_presets(scene: Scene) -> None:
    sk = scene.skeleton
    res = sc.reconstruct_skeleton(scene.px, scene.cams, sk, scene.P[:, 0], k=8, method="thesis")
    assert res.points.shape == scene.P.shape
    assert res.joints[sk.root] is None
    np.testing.assert_allclose(res.points[:, sk.root], scene.P[:, 0])
    # A joint whose chain from the root is reconstructable is recovered.
    j = sk.index("LeftHip")
    assert scene.rel_error(res.points[:, j], j) < 0.06
    human = sc.Skeleton.cmu_human(1.8)
    assert human.names[human.root] == "Hips" and len(human.names) == 19
    assert human.lengths[human.index("LeftKnee")] == pytest.approx(0.245 * 1.8)


def test_articulated_bad_input(scene: Scene) -> None:
    x = scene.px[:, 1]
    par = scene.P[:, 0]
    for r in (0.0, -1.0):
        with pytest.raises(ValueError, match="length"):
            sc.reconstruct_articulated(x, scene.cams, par, r, k=8)
    with pytest.raises(sc.DegenerateError):
        sc.reconstruct_articulated(x, scene.cams, par, 0.1, k=100)
    with pytest.raises(ValueError, match="root"):
        sc.Skeleton(["a", "b"], [-1, -1], [0.0, 1.0])
    with pytest.raises(ValueError, match="cycle"):
        sc.Skeleton(["a", "b", "c"], [-1, 2, 1], [0.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="range"):
        sc.Skeleton(["a", "b"], [-1, 7], [0.0, 1.0])
    with pytest.raises(ValueError, match="positive"):
        sc.Skeleton(["a", "b"], [-1, 0], [0.0, 0.0])


def test_coordinates_float64_cannot_hold_are_refused(scene: Scene) -> None:
    # A scene moved far from the origin keeps its answer until float64's rounding of the
    # coordinates reaches the bone: 1e6 m away gives the same points (moved), 1e15 m away
    # gave 35 px of reprojection error silently and is refused; pixels of 1e200 overflowed
    # to an infinite error and are refused after the solve.
    x, par, r = scene.px[:, 1], scene.P[:, 0], scene.skeleton.lengths[1]
    cams = scene.cams

    def moved(off: float) -> sc.Cameras:
        return sc.Cameras(cams.K, cams.R, cams.C + off, cams.times)

    near = sc.reconstruct_articulated(x, cams, par, r, k=8)
    far = sc.reconstruct_articulated(x, moved(1e6), par + 1e6, r, k=8)
    assert np.abs(far.points - 1e6 - near.points).max() < 1e-3 * r
    for off in (1e15, 1e200):
        with pytest.raises(ValueError, match=r"parent, cameras: .*float64 rounds"):
            sc.reconstruct_articulated(x, moved(off), par + off, r, k=8)
    with pytest.raises(ValueError, match=r"parent, cameras: .*float64 rounds"):
        sc.reconstruct_articulated(x, cams, par, 1e-300, k=8)
    with pytest.raises(ValueError, match=r"root, cameras: .*float64 rounds"):
        sc.reconstruct_skeleton(scene.px, moved(1e15), scene.skeleton, scene.P[:, 0] + 1e15, k=8)
    with pytest.raises(ValueError, match="overflowed float64"):
        sc.reconstruct_articulated(x * 1e200, cams, par, r, k=8)


# ------------------------------------------------- robust method (issue 12), per joint
def test_robust_refines_the_length_per_joint(scene: Scene) -> None:
    # Length over-estimated by 5 %, 0.5 px noise, exact parent. The robust refinement of
    # Eq 4.5 (bone length free, with a prior) recovers each joint and its length; without
    # the refinement every joint is far off. Measured per joint (η_a > 1.25, in order):
    # error 0.024 0.609 0.018 0.062 0.018, length ratio 0.996–1.003 (with the basis grown
    # by BIC; at k = 8 only: 0.023 0.508 0.038 0.093 0.032); unrefined errors 1.245 0.605
    # 1.130 0.248 0.837. (The second joint, LeftHip's short bone, stays in the impostor's
    # basin, its length drifting to 1.052: neither is checked there.)
    good = _good(scene)
    assert len(good) == 5
    limits = [0.04, 0.7, 0.07, 0.15, 0.05]
    for j, limit in zip(good, limits, strict=True):
        p, r = scene.skeleton.parents[j], scene.skeleton.lengths[j]
        rng = np.random.default_rng(17 * j)
        x = scene.px[:, j] + rng.normal(0, 0.5, (scene.P.shape[0], 2))
        out = sc.reconstruct_articulated(x, scene.cams, scene.P[:, p], 1.05 * r, k=8)
        raw = sc.reconstruct_articulated(x, scene.cams, scene.P[:, p], 1.05 * r, k=8, refine=False)
        err, raw_err = scene.rel_error(out.points, j), scene.rel_error(raw.points, j)
        assert err < limit, (j, err)
        if limit < 0.2:
            assert abs(out.radius / r - 1) < 0.015, (j, out.radius / r)
            assert err < 0.85 * raw_err, (j, err, raw_err)
            # Unbiased: the mean error vector is well below the error (measured ≤ 0.01).
            bias = np.linalg.norm((out.points - scene.P[:, j]).mean(axis=0)) / r
            assert bias < 0.5 * limit, (j, bias)


def test_robust_under_thesis_conditions(scene: Scene) -> None:
    # Fig 4.3(c) conditions, pooled over the draws. Measured, robust: median 0.067–0.083,
    # mean 0.211–0.268 over seeds 0–3, 4–7, 8–11 (per draw 0.13–0.37: one or two of the
    # five joints follow the impostor; session 5's rule without the motion term: 0.202,
    # 0.273, 0.409), 0.32–0.38 × the thesis method's (mean 0.62–0.75).
    good = _good(scene)
    robust = _errs(scene, good, "robust", **FIG_43C)
    thesis = _errs(scene, good, "thesis", **FIG_43C)
    assert np.median(robust) < 0.12, np.median(robust, axis=1)
    assert robust.mean() < 0.4, robust.mean(axis=1)
    assert robust.mean() < 0.6 * thesis.mean(), (robust.mean(), thesis.mean())


def test_robust_grows_the_basis_to_the_motion(scene: Scene) -> None:
    # Real walking exceeds the k = 8 DCT basis of the binary program: the selected start is
    # refined again with up to refine_k_max vectors per angle, size by BIC. Exact length
    # and root, 0.5 px, joints with η_a > 1.25. Measured median per draw (seeds 0–7):
    # 0.012–0.036 grown, 0.034–0.038 at k = 8 (refine_k_max=0); pooled over seeds 0–3
    # about 0.021 against 0.037.
    good = _good(scene)
    grown = _errs(scene, good, "robust")
    fixed = _errs(scene, good, "robust", refine_k_max=0)
    assert np.median(grown) < 0.03, np.median(grown, axis=1)
    assert np.median(grown) < 0.75 * np.median(fixed), (np.median(grown), np.median(fixed))


def test_articulated_options_validation(scene: Scene) -> None:
    x, par = scene.px[:, 1], scene.P[:, 0]
    for bad in (
        {"k": 2.9},
        {"k": 0},
        {"method": "magic"},
        {"tangent_quantile": 1.5},
        {"length_tol": -0.1},
        {"flip_rounds": -1},
        {"motion_weight": -1.0},
        {"refine_k_max": -1},
        {"child_slack": -0.1},
        {"length_weight": -1.0},
        {"smooth_weight": float("inf")},
        {"refine": 1},
        {"average_starts": "yes"},
        {"max_iter": 0},
    ):
        name = next(iter(bad))
        with pytest.raises(ValueError, match=name):
            sc.reconstruct_articulated(x, scene.cams, par, 0.1, **bad)
    with pytest.raises(ValueError, match="colour"):
        sc.reconstruct_articulated(x, scene.cams, par, 0.1, colour=1)
    with pytest.raises(ValueError, match="length"):
        sc.reconstruct_articulated(x, scene.cams, par, float("nan"))
    for kids in ([(x[:-1], 0.1)], [(x, 0.0)], [(np.full_like(x, np.inf), 0.1)]):
        with pytest.raises(ValueError, match="children"):
            sc.reconstruct_articulated(x, scene.cams, par, 0.1, children=kids)
    opts = sc.ArticulatedOptions(k=6, method="thesis")
    assert sc.ArticulatedOptions(**opts.to_dict()) == opts


# ------------------------------- robust method, start selection (issue 12), C3D markers
def _marker_window() -> tuple[np.ndarray, list[tuple[int, int]], sc.Cameras, np.ndarray]:
    """CMU subject 85 trial 02 (optical markers, 120 Hz), frames 0, 2, …, 118: each marker
    articulated to the marker whose distance to it varies least (a nearly rigid "bone"),
    seen by one camera per frame orbiting the body centre at 1.5 m (as the bench)."""
    from socialcam.mocap import load_c3d

    P = load_c3d(DATA / "mocap" / "cmu_85_02.c3d").positions
    P = P[:, np.isfinite(P).all(axis=(0, 2))][::2][:60]
    pairs = []
    for j in range(P.shape[1]):
        d = np.linalg.norm(P[:, j, None] - P, axis=2)  # (F, M)
        mean = d.mean(0)
        ok = (mean >= 0.1) & (mean <= 0.5)
        rel = np.full(len(mean), np.inf)
        rel[ok] = d.std(0)[ok] / mean[ok]
        if rel.min() < 0.02:
            pairs.append((j, int(rel.argmin())))
    cams, px = _orbit(P, P.mean(axis=1))
    return P, pairs, cams, px


def _fig43c_draw(
    P: np.ndarray, px: np.ndarray, j: int, p: int, seed: int
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Joint ``j``'s pixels and its parent ``p`` under Fig 4.3(c) conditions (1 px noise,
    5 % missing, 5 % root error; the draw of the bench): ``(x, parent, length, den)`` with
    ``den`` the norm of the true bone vectors."""
    F = P.shape[0]
    rng = np.random.default_rng(seed * 1000 + 17 * j)
    r = float(np.linalg.norm(P[:, j] - P[:, p], axis=1).mean())
    x = px[:, j] + rng.normal(0, 1.0, (F, 2))
    x[rng.random(F) < 0.05] = np.nan
    parent = P[:, p] + _smooth_offset(F, 0.05 * r, rng)
    return x, parent, r, np.linalg.norm(P[:, j] - P[:, p])


def test_robust_start_selection_on_markers() -> None:
    # Fig 4.3(c) conditions on another clip (optical markers), the joints with η_a > 1.25,
    # pooled over two noise draws. The pixels cannot tell the truth's basin from the
    # impostor's (after the refinement of Eq 4.5 the impostor often reprojects a few px²
    # better), so the robust method scores the reprojection cost against the smoothness of
    # Eq 4.12 (smooth_weight) and least motion (motion_weight): the wrong starts left are
    # slow swings of the bone towards the impostor side. Measured per draw (seeds 0–3, 31
    # joints): mean 0.085 0.133 0.145 0.146 (pooled by pairs 0.109, 0.146), median
    # 0.063–0.085, 81–87 % of joints below 0.15. Without the motion term (motion_weight=0,
    # session 5's rule): mean 0.192 0.310 0.260 0.215 (pooled 0.251, 0.238; robust / that
    # = 0.43, 0.61); keeping the lowest cost 0.300 0.303 0.346 0.220; the thesis method
    # 0.285–0.328.
    P, pairs, cams, px = _marker_window()
    errs: dict[str, list[float]] = {"robust": [], "smooth-only": []}
    for seed, (j, p) in itertools.product((0, 1), pairs):
        if sc.articulated_reconstructability(P[:, j], cams, P[:, p], 8) <= 1.25:
            continue
        x, parent, r, den = _fig43c_draw(P, px, j, p, seed)
        for name, kw in (("robust", {}), ("smooth-only", {"motion_weight": 0.0})):
            out = sc.reconstruct_articulated(x, cams, parent, 1.05 * r, k=8, **kw)
            errs[name].append(float(np.linalg.norm(out.points - P[:, j]) / den))
    robust = np.array(errs["robust"])
    assert len(robust) >= 50, len(robust)
    assert robust.mean() < 0.17, errs["robust"]
    assert np.median(robust) < 0.1, errs["robust"]
    assert np.mean(robust < 0.15) >= 0.75, errs["robust"]
    assert robust.mean() < 0.7 * np.mean(errs["smooth-only"]), errs


# ------------------------- robust method, children's evidence (issue 12, session 8)
def _starting_window() -> tuple[np.ndarray, sc.Skeleton, sc.Cameras, np.ndarray]:
    """CMU 131_01 frames 240, 242, …, 358 (the subject starts to walk), seen as in the
    bench (one camera per frame orbiting the body centre at 1.5 m)."""
    m = load_bvh(DATA / "mocap" / "cmu_131_01_start300.bvh")
    skeleton, keep = sc.Skeleton.from_bvh(m)
    P = m.positions[90::2][:60][:, keep]
    cams, px = _orbit(P, P.mean(axis=1))
    return P, skeleton, cams, px


def test_children_reject_the_impostor_shoulder() -> None:
    # RightShoulder (η_a 1.36) under Fig 4.3(c) conditions: on the impostor side of its rays
    # the shoulder fits its own pixels, Eq 4.12 and least motion at least as well as the
    # truth (the whole window follows the impostor, error 1.33–1.37 on seeds 0–2), but the
    # elbow's rays then pass out of the upper arm's reach of it. Measured with the elbow's
    # pixels given: 0.078, 0.082, 0.235 (seeds 0–2; 0.07–0.24 on seeds 0–7); without:
    # 1.398, 1.387, 1.315 (1.32–1.40 on seeds 0–7).
    P, skeleton, cams, px = _starting_window()
    F = P.shape[0]
    j, p, c = (skeleton.index(n) for n in ("RightShoulder", "Chest2", "RightElbow"))
    r = float(np.linalg.norm(P[:, j] - P[:, p], axis=1).mean())
    rc = float(np.linalg.norm(P[:, c] - P[:, j], axis=1).mean())
    den = np.linalg.norm(P[:, j] - P[:, p])
    errs: dict[bool, list[float]] = {True: [], False: []}
    for seed in range(3):
        rng = np.random.default_rng(seed)
        x = px[:, j] + rng.normal(0, 1.0, (F, 2))
        x[rng.random(F) < 0.05] = np.nan
        parent = P[:, p] + _smooth_offset(F, 0.05 * r, rng)
        xc = px[:, c] + rng.normal(0, 1.0, (F, 2))
        xc[rng.random(F) < 0.05] = np.nan
        for given in (True, False):
            kids = [(xc, 1.05 * rc)] if given else None
            out = sc.reconstruct_articulated(x, cams, parent, 1.05 * r, k=8, children=kids)
            errs[given].append(float(np.linalg.norm(out.points - P[:, j]) / den))
    assert max(errs[True]) < 0.4, errs
    assert min(errs[False]) > 0.8, errs  # the impostor this evidence is here for
    # The thesis method ignores the children.
    kids = [(xc, 1.05 * rc)]
    a = sc.reconstruct_articulated(x, cams, parent, 1.05 * r, method="thesis", children=kids)
    b = sc.reconstruct_articulated(x, cams, parent, 1.05 * r, method="thesis")
    np.testing.assert_array_equal(a.points, b.points)


def test_a_close_call_is_flagged_and_its_alternative_kept() -> None:
    # CMU 131_03 (start, hop, stop; never used to shape the method): the right elbow swings
    # through a right angle with its ray at frame 23 of this window and goes on to the far
    # root; the reconstruction touches the ray there and comes back on the near side (the
    # least-motion term prefers the bounce, by 0.01-0.24 score units on seeds 0-5). Measured
    # at exact length and root with the wrist's pixels given: error 0.58-0.59, margin
    # 0.01-0.24, alternative 0.053-0.058 of the bone (seeds 0-5). Whichever is returned, the
    # truth is the result or the alternative, and when it is the alternative the margin
    # says it was a close call.
    m = load_bvh(DATA / "mocap" / "cmu_131_03_hop300b.bvh")
    skeleton, keep = sc.Skeleton.from_bvh(m)
    P = m.positions[::2][:60][:, keep]
    cams, px = _orbit(P, P.mean(axis=1))
    j, p, c = (skeleton.index(n) for n in ("RightElbow", "RightShoulder", "RightWrist"))
    r = float(np.linalg.norm(P[:, j] - P[:, p], axis=1).mean())
    rc = float(np.linalg.norm(P[:, c] - P[:, j], axis=1).mean())
    den = np.linalg.norm(P[:, j] - P[:, p])
    for seed in range(3):
        rng = np.random.default_rng(seed)
        x = px[:, j] + rng.normal(0, 0.5, (60, 2))
        xc = px[:, c] + rng.normal(0, 0.5, (60, 2))
        out = sc.reconstruct_articulated(x, cams, P[:, p], r, children=[(xc, rc)])
        err = float(np.linalg.norm(out.points - P[:, j]) / den)
        assert out.alternative is not None and out.alternative.shape == (60, 3)
        assert not out.alternative.flags.writeable
        alt = float(np.linalg.norm(out.alternative - P[:, j]) / den)
        assert 0.0 <= out.selection_margin < np.inf
        assert min(err, alt) < 0.1, (seed, err, alt)
        if err > 0.1:
            assert out.selection_margin < 0.5, (seed, out.selection_margin)
            # the alternative is another basin: a tenth of the bone or more from the result
            assert np.sqrt(np.mean(np.sum((out.alternative - out.points) ** 2, 1))) > 0.1 * r
    # The thesis method has one start: nothing to compare.
    thesis = sc.reconstruct_articulated(x, cams, P[:, p], r, method="thesis")
    assert thesis.selection_margin == np.inf and thesis.alternative is None
    assert thesis.to_dict()["alternative"] is None


def test_skeleton_gives_each_joint_its_children() -> None:
    # The same window, whole skeleton from the true root at exact lengths, 1 px: the
    # skeleton passes every joint its children's pixels. RightShoulder's error (its parent
    # Chest2 reconstructed too), measured on seeds 0–1: with the children's reach 0.533,
    # 0.519 (0.20–0.53 on seeds 0–7); with the reach unlimited (child_slack=1e6, the
    # evidence off) 1.769, 1.818 (1.51–1.82).
    P, skeleton, cams, px = _starting_window()
    F, J = P.shape[:2]
    j, p = skeleton.index("RightShoulder"), skeleton.index("Chest2")
    den = np.linalg.norm(P[:, j] - P[:, p])
    errs: dict[bool, list[float]] = {True: [], False: []}
    for seed in range(2):
        x = px + np.random.default_rng(seed).normal(0, 1.0, (F, J, 2))
        for on in (True, False):
            rec = sc.reconstruct_skeleton(
                x, cams, skeleton, P[:, skeleton.root], k=8, child_slack=0.1 if on else 1e6
            )
            errs[on].append(float(np.linalg.norm(rec.points[:, j] - P[:, j]) / den))
    assert max(errs[True]) < 0.8, errs
    assert min(errs[False]) > 1.2, errs


# ------------------------- robust method, the starts' average (issue 12, session 9)
def test_the_starts_average_beats_the_best_start() -> None:
    # CMU 131_02 frames 910, 912, …, 1028 (walking to a stop) under Fig 4.3(c) conditions,
    # the 7 joints with η_a > 1.25. Near grazing rays the refined starts form a family
    # along the rays that the pixels, Eq 4.12 and the least motion score alike, and the
    # best score is as often the farther member as the nearer; averaging the distinct starts
    # by exp(−2 score) lowers the expected error. Measured per seed (0–3), average / best
    # start: mean 0.123 / 0.141, 0.165 / 0.189, 0.090 / 0.099, 0.091 / 0.097 (ratio
    # 0.87–0.94); pooled seeds 0–1: 0.144 / 0.165.
    m = load_bvh(DATA / "mocap" / "cmu_131_02_stop300.bvh")
    skeleton, keep = sc.Skeleton.from_bvh(m)
    P = m.positions[60::2][:60][:, keep]
    cams, px = _orbit(P, P.mean(axis=1))
    errs: dict[bool, list[float]] = {True: [], False: []}
    for seed, j in itertools.product((0, 1), range(len(skeleton.names))):
        p = skeleton.parents[j]
        if p == -1 or sc.articulated_reconstructability(P[:, j], cams, P[:, p], 8) <= 1.25:
            continue
        x, parent, r, den = _fig43c_draw(P, px, j, p, seed)
        for on in (True, False):
            out = sc.reconstruct_articulated(x, cams, parent, 1.05 * r, k=8, average_starts=on)
            errs[on].append(float(np.linalg.norm(out.points - P[:, j]) / den))
    avg, best = np.array(errs[True]), np.array(errs[False])
    assert len(avg) == 14, len(avg)
    assert avg.mean() < 0.16, errs
    assert avg.mean() < 0.95 * best.mean(), errs


def test_the_shorter_bone_rejects_the_impostor_hip(scene: Scene) -> None:
    # RightHip of the walking scene (η_a > 1.25) under Fig 4.3(c) conditions (length
    # × 1.05), its knee given: on some draws the start kept by the pixels, Eq 4.12 and least
    # motion follows the impostor with the bone lengthened beyond the given one, while a
    # start that fits about as well keeps a shorter bone near the truth. length_weight=20
    # (issue 12, session 11; off by default) prefers it. Measured on seeds 0–7, error
    # (refined length / true) with 20 against 0: seed 1 0.418 (0.958) / 0.639 (1.067),
    # seed 7 0.062 (0.956) / 0.639 (1.031); the six others unchanged (within 0.001).
    j = scene.skeleton.index("RightHip")
    p, c = scene.skeleton.parents[j], scene.skeleton.index("RightKnee")
    rc = float(np.linalg.norm(scene.P[:, c] - scene.P[:, j], axis=1).mean())
    for seed in range(8):
        x, parent, r, den = _fig43c_draw(scene.P, scene.px, j, p, seed)
        kids = [(_fig43c_draw(scene.P, scene.px, c, j, seed)[0], 1.05 * rc)]
        on, off = (
            sc.reconstruct_articulated(
                x, scene.cams, parent, 1.05 * r, k=8, children=kids, length_weight=w
            )
            for w in (20.0, 0.0)
        )
        e_on, e_off = (float(np.linalg.norm(o.points - scene.P[:, j]) / den) for o in (on, off))
        msg = f"seed {seed}: {e_on:.3f} ({on.radius / r:.3f}) / {e_off:.3f} ({off.radius / r:.3f})"
        if seed in (1, 7):
            assert e_on < e_off - 0.15 and on.radius < off.radius, msg
        else:
            assert e_on < e_off + 0.01, msg
    # Off by default: the default is the session 10 selection.
    assert sc.ArticulatedOptions().length_weight == 0.0


def test_bad_children_are_refused_by_name() -> None:
    f = 20
    cams = sc.synth.random_photographers(f, seed=1)
    parent = np.c_[np.zeros(f), np.zeros(f), np.ones(f)]
    x = cams.project_trajectory(parent + np.array([0.4, 0.0, 0.0]))
    cases = [
        ([(x, -1.0)], r"^children\[0\] length"),
        ([(x[:5], 0.3)], r"^children\[0\] pixels: expected shape"),
        ([x], r"^children\[0\]: expected a \(pixels"),
        ([(x, 0.3, 1)], r"^children\[0\]: expected a \(pixels"),
        ("ab", r"^children: expected a sequence"),
    ]
    for children, message in cases:
        with pytest.raises(ValueError, match=message):
            sc.reconstruct_articulated(x, cams, parent, 0.4, k=4, children=children)


# --------------------------------------- robust method, angle priors (issue 12, session 25)
def _trial_ranges(
    trial: str, skeleton: sc.Skeleton, keep: list[int], **kinds: Any
) -> dict[tuple[int, int, int], tuple[float, float]]:
    """Angle priors (radians) learned from every clip of CMU 131 trial ``trial``."""
    clips = [
        load_bvh(f).positions[:, keep]
        for f in sorted((DATA / "mocap").glob(f"cmu_131_{trial}_*.bvh"))
    ]
    assert len(clips) == 4
    return sc.learn_angle_ranges(clips, skeleton.parents, **kinds)


def _clip_window(
    name: str, offset: int = 0, step: int = 2
) -> tuple[np.ndarray, sc.Skeleton, list[int], sc.Cameras, np.ndarray]:
    """CMU ``name`` (120 Hz) frames ``offset``, ``offset`` + ``step``, … (60 frames, at
    120 / ``step`` Hz), seen as in the bench: ``(P, skeleton, keep, cameras, pixels)``."""
    m = load_bvh(DATA / "mocap" / name)
    skeleton, keep = sc.Skeleton.from_bvh(m)
    P = m.positions[offset::step][:60][:, keep]
    cams, px = _orbit(P, P.mean(axis=1), rate=120.0 / step)
    return P, skeleton, keep, cams, px


def _fig43c_children(
    P: np.ndarray, px: np.ndarray, skeleton: sc.Skeleton, j: int, seed: int
) -> list[tuple[np.ndarray, float]]:
    """Joint ``j``'s children as the bench gives them: pixels drawn as in
    :func:`_fig43c_draw`, bones × 1.05."""
    return [
        (
            _fig43c_draw(P, px, c, j, seed)[0],
            1.05 * float(np.linalg.norm(P[:, c] - P[:, j], axis=1).mean()),
        )
        for c in range(len(skeleton.names))
        if skeleton.parents[c] == j
    ]


def test_the_bend_prior_rejects_the_impostor_head() -> None:
    # CMU 131_02 walking to a stop (frames 850, 852, …, 968), Fig 4.3(c) conditions; the
    # bend prior (the angle between the joint's bone and its parent's bone) learned from the
    # OTHER trial (131_01's four clips), the grandparent given 5 % of its bone off like the
    # parent. Head (η_a 1.32) and Chest2 (1.27): where the pixels, Eq 4.12 and least motion
    # keep a start that bends the head or the upper spine beyond anything the other trial
    # does, the prior hands the selection to one inside the range. Measured on seeds 0–5,
    # without → with the prior: Head 0.23 0.25 0.22 0.24 0.29 0.31 → 0.23 0.13 0.22 0.24
    # 0.12 0.11, Chest2 0.23 0.24 0.21 0.32 0.09 0.36 → 0.23 0.17 0.21 0.23 0.09 0.36 (pooled
    # mean 0.249 → 0.195).
    P, skeleton, keep, cams, px = _clip_window("cmu_131_02_stop300.bvh")
    ranges = _trial_ranges("01", skeleton, keep, siblings=False)
    F = P.shape[0]
    errs: dict[bool, list[float]] = {True: [], False: []}
    for name, seed in itertools.product(("Head", "Chest2"), range(6)):
        j = skeleton.index(name)
        p = skeleton.parents[j]
        g = skeleton.parents[p]
        x, parent, r, den = _fig43c_draw(P, px, j, p, seed)
        rg = float(np.linalg.norm(P[:, p] - P[:, g], axis=1).mean())
        rng = np.random.default_rng(seed * 1000 + 17 * j + 5)
        grand = P[:, g] + _smooth_offset(F, 0.05 * rg, rng)
        kids = _fig43c_children(P, px, skeleton, j, seed)
        prior = [(parent - grand, ranges[j, g, p])]
        for on in (True, False):
            out = sc.reconstruct_articulated(
                x, cams, parent, 1.05 * r, k=8, children=kids, angle_priors=prior if on else None
            )
            errs[on].append(float(np.linalg.norm(out.points - P[:, j]) / den))
    on_, off_ = np.array(errs[True]), np.array(errs[False])
    assert on_.mean() < 0.85 * off_.mean(), errs
    assert (on_ < off_ + 0.02).all(), errs  # where the prior changes nothing it costs nothing
    assert (on_ < off_ - 0.05).sum() >= 3, errs
    # Weight 0 reads no prior.
    out0, out1 = (
        sc.reconstruct_articulated(
            x, cams, parent, 1.05 * r, k=8, children=kids, angle_priors=prior, angle_weight=w
        )
        for w in (0.0, 1.0)
    )
    plain = sc.reconstruct_articulated(x, cams, parent, 1.05 * r, k=8, children=kids)
    np.testing.assert_array_equal(out0.points, plain.points)
    assert out1.points.shape == plain.points.shape


def test_rigid_marker_priors_keep_the_foot_and_wrist_markers() -> None:
    # CMU 85_02 (optical markers) frames 300, 302, …, 418, Fig 4.3(c) conditions. Markers
    # have no anatomy for a bend or sibling prior, but they sit in groups on one segment:
    # learn_angle_ranges(rigid=0.08) finds, for a marker and its parent, the other markers
    # rigid with both (distances within 8 % std / mean) and the angle at the parent, here
    # learned from the clip's frames outside the window (a calibration capture of the same
    # marker set), the other markers given 5 % of their distance to the parent off. RTOE and
    # RMT5 on the right heel (RHEE), RWRB on RWRA: without the priors the whole window follows
    # the impostor (measured seeds 0–1: 0.85–1.09); with them 0.03–0.09.
    from socialcam.mocap import load_c3d

    full = load_c3d(DATA / "mocap" / "cmu_85_02.c3d")
    keep = np.isfinite(full.positions).all(axis=(0, 2))
    Q = full.positions[:, keep]
    labels = [name for name, k in zip(full.labels, keep, strict=True) if k]
    idx = {name.split(":")[-1]: i for i, name in enumerate(labels)}
    P = Q[300:420:2]
    F = P.shape[0]
    outside = np.ones(Q.shape[0], bool)
    outside[300:420] = False
    cams, px = _orbit(P, P.mean(axis=1))
    pairs = [("RTOE", "RHEE"), ("RMT5", "RHEE"), ("RWRB", "RWRA")]
    parents = [-1] * Q.shape[1]
    for a, b in pairs:
        parents[idx[a]] = idx[b]
    ranges = sc.learn_angle_ranges(Q[outside], parents, bend=False, siblings=False, rigid=0.08)
    assert not set(ranges) & set(
        sc.learn_angle_ranges(Q[outside], parents, bend=False, siblings=False)
    )
    for a, b in pairs:
        j, p = idx[a], idx[b]
        refs = [(q, lohi) for (jj, pp, q), lohi in ranges.items() if (jj, pp) == (j, p)]
        assert refs, a  # every one of them has rigid partners on its segment
        for seed in (0, 1):
            x, parent, r, den = _fig43c_draw(P, px, j, p, seed)
            priors = []
            for q, lohi in refs:
                rq = float(np.linalg.norm(P[:, q] - P[:, p], axis=1).mean())
                rng = np.random.default_rng(seed * 1000 + 17 * j + 6 + q)
                priors.append((P[:, q] + _smooth_offset(F, 0.05 * rq, rng) - parent, lohi))
            on, off = (
                sc.reconstruct_articulated(x, cams, parent, 1.05 * r, k=8, angle_priors=pr)
                for pr in (priors, None)
            )
            e_on, e_off = (float(np.linalg.norm(o.points - P[:, j]) / den) for o in (on, off))
            assert e_off > 0.5 and e_on < 0.15, (a, seed, e_off, e_on)


def test_other_basis_sizes_follow_fast_marker_motion() -> None:
    # CMU 85_02 (optical markers) at 20 Hz: frames 7, 13, …, 361 (60 frames, 3 s of fast
    # motion), exact length and parent, 0.5 px noise; each marker articulated to the marker
    # whose distance to it varies least, the rigid priors learned from the clip's frames
    # outside the window. k = 8 is too small a smoothness prior for 3 s: the start chosen
    # at k = 8 misses the motion and the basis grown after it (refine_k_max) cannot undo it.
    # k_alternatives = (12, 16) (default; 3 s at 20 Hz is long enough for both) runs the
    # reconstruction again at those sizes and keeps the lowest BIC plus the priors' excess. Measured (11 markers with η_a > 1.25 and rigid
    # partners, seeds 0-1): pooled 0.161 -> 0.100; LHEE 0.61 -> 0.05, RWRB 0.10-0.12 -> 0.02-0.03.
    from socialcam.mocap import load_c3d

    full = load_c3d(DATA / "mocap" / "cmu_85_02.c3d")
    keep = np.isfinite(full.positions).all(axis=(0, 2))
    Q = full.positions[:, keep]
    D = np.linalg.norm(Q[:, :, None] - Q[:, None], axis=3)
    spread = D.std(axis=0) / np.maximum(D.mean(axis=0), 1e-9)
    np.fill_diagonal(spread, np.inf)
    parents = [int(v) for v in spread.argmin(axis=1)]
    P = Q[7::6][:60]
    outside = np.ones(Q.shape[0], bool)
    outside[7 : 7 + 6 * 59 + 1] = False
    ranges = sc.learn_angle_ranges(Q[outside], parents, bend=False, siblings=False, rigid=0.08)
    cams, px = _orbit(P, P.mean(axis=1), rate=20.0)
    errs: dict[str, list[float]] = {"k8": [], "alt": []}
    for j, p in enumerate(parents):
        refs = [(q, lohi) for (jj, pp, q), lohi in ranges.items() if (jj, pp) == (j, p)]
        if not refs or sc.articulated_reconstructability(P[:, j], cams, P[:, p], 8) <= 1.25:
            continue
        r = float(np.linalg.norm(P[:, j] - P[:, p], axis=1).mean())
        den = float(np.linalg.norm(P[:, j] - P[:, p]))
        priors = [(P[:, q] - P[:, p], lohi) for q, lohi in refs]
        for seed in (0, 1):
            x = px[:, j] + np.random.default_rng(seed * 100 + j).normal(0, 0.5, (60, 2))
            for name, kw in (("k8", {"k_alternatives": ()}), ("alt", {})):
                o = sc.reconstruct_articulated(x, cams, P[:, p], r, k=8, angle_priors=priors, **kw)
                errs[name].append(float(np.linalg.norm(o.points - P[:, j]) / den))
    k8, alt = (float(np.mean(errs[n])) for n in ("k8", "alt"))
    assert len(errs["k8"]) >= 16, len(errs["k8"])
    assert alt < 0.75 * k8 and alt < 0.13, (k8, alt)


def test_basis_sizes_are_tried_up_to_k_per_second_of_the_window() -> None:
    # k_per_second = 8 (default) caps the k_alternatives tried (default (12, 16)) at 8
    # per second of the window. RightKnee of 131_01 walking, 1 px noise: tried at every size (k_per_second =
    # None) the choice is k = 16 whatever the frame rate (the DCT basis does not depend on
    # the time unit). A 1 s window (60 frames at 60 Hz) keeps k = 8; 1.5 s (40 Hz) tries
    # 12 only; 3 s (20 Hz) tries 12 and 16. Without times the duration is unknown: k only.
    P, skeleton, _, _, _ = _clip_window("cmu_131_01_walk300.bvh", 0)
    j = skeleton.index("RightKnee")
    p = skeleton.parents[j]
    r = float(np.linalg.norm(P[:, j] - P[:, p], axis=1).mean())
    alt = dict(k_alternatives=(12, 16))
    for rate in (60.0, 40.0, 20.0, None):
        cams, px = _orbit(P, P.mean(axis=1), rate=rate or 60.0)
        if rate is None:
            cams = sc.Cameras(cams.K, cams.R, cams.C)
        x = px[:, j] + np.random.default_rng(3).normal(0, 1.0, (60, 2))
        size = {
            kk: sc.reconstruct_articulated(x, cams, P[:, p], r, k=kk, k_alternatives=()).points
            for kk in (8, 12, 16)
        }
        gated = sc.reconstruct_articulated(x, cams, P[:, p], r, k=8, k_growth=None, **alt).points
        every = sc.reconstruct_articulated(x, cams, P[:, p], r, k=8, k_per_second=None, **alt)
        np.testing.assert_array_equal(every.points, size[16])
        if rate == 40.0:
            twelve = sc.reconstruct_articulated(
                x, cams, P[:, p], r, k=8, k_alternatives=(12,), k_growth=None
            )
            np.testing.assert_array_equal(gated, twelve.points)
            assert not np.array_equal(gated, size[16])
        else:
            np.testing.assert_array_equal(gated, size[16] if rate == 20.0 else size[8])


def test_a_grown_basis_tries_the_sizes_the_duration_skipped() -> None:
    # CMU 131_03 hopping (hop300b, frames 0, 2, …, 118: one second at 60 Hz), exact length
    # and parent, 0.5 px noise, bend and sibling priors learned from both walking trials. The
    # right elbow swings faster than k = 8 follows in that second: the start chosen at k = 8
    # follows the impostor and the basis grown after it (to 29-30 vectors) cannot undo it.
    # k_per_second (8 per second) skips k = 12 and 16 for a one-second window; k_growth
    # = 1.5 tries them because the k = 8 result grew to at least 12 vectors. Measured
    # (seeds 0-2): 0.569 0.595 0.587 -> 0.010 0.022 0.010.
    P, skeleton, keep, cams, px = _clip_window("cmu_131_03_hop300b.bvh", 0)
    clips = [
        load_bvh(f).positions[:, keep] for f in sorted((DATA / "mocap").glob("cmu_131_0[12]_*.bvh"))
    ]
    assert len(clips) == 8
    ranges = sc.learn_angle_ranges(clips, skeleton.parents)
    j = skeleton.index("RightElbow")
    p = skeleton.parents[j]
    priors = _joint_priors(P, ranges, j, p)
    duration_only = _exact_errors(P, cams, px, j, p, priors, k_growth=None)
    grown = _exact_errors(P, cams, px, j, p, priors, k_growth=1.5)
    assert min(duration_only) > 0.3, duration_only
    assert max(grown) < 0.05, grown


def _joint_priors(
    P: np.ndarray, ranges: dict[tuple[int, int, int], tuple[float, float]], j: int, p: int
) -> list[tuple[np.ndarray, tuple[float, float]]]:
    """The true-reference angle priors of joint ``j`` (parent ``p``) among ``ranges``."""
    return [
        (P[:, b] - P[:, a], lohi) for (jj, a, b), lohi in ranges.items() if jj == j and p in (a, b)
    ]


def _exact_errors(
    P: np.ndarray, cams: sc.Cameras, px: np.ndarray, j: int, p: int, priors: list, **opts: Any
) -> list[float]:
    """Relative error of joint ``j`` with its exact parent and mean length, 0.5 px noise,
    seeds 0-2."""
    r = float(np.linalg.norm(P[:, j] - P[:, p], axis=1).mean())
    den = float(np.linalg.norm(P[:, j] - P[:, p]))
    errs = []
    for seed in range(3):
        x = px[:, j] + np.random.default_rng(seed * 100 + j).normal(0, 0.5, (P.shape[0], 2))
        out = sc.reconstruct_articulated(x, cams, P[:, p], r, angle_priors=priors, **opts)
        errs.append(float(np.linalg.norm(out.points - P[:, j]) / den))
    return errs


def test_angle_cap_frees_a_joint_from_ranges_that_miss_its_window() -> None:
    # CMU 131_01 starting to walk, frames 201-260 at 120 Hz (0.5 s), exact parent and
    # length, 0.5 px noise, every prior learned from the other trial (bend, siblings, rigid
    # points). Those ranges miss these frames' true angles by 10-40 deg (RightKnee's bend
    # range 15.9-53.4 deg, true 55-73), which outweighs the pixels: the reconstruction
    # takes the impostor and the refinement pulls it into the wrong ranges (without priors:
    # 0.01-0.03). angle_cap = 9 counts each frame at most 3 tolerances (15 deg) out and stops
    # pulling beyond. Measured seeds 0-2: RightKnee 1.02 -> 0.02, LeftAnkle 0.56 -> 0.02.
    P, skeleton, keep, cams, px = _clip_window("cmu_131_01_start300.bvh", 201, step=1)
    ranges = _trial_ranges("02", skeleton, keep, rigid=0.08)
    for name in ("RightKnee", "LeftAnkle"):
        j = skeleton.index(name)
        p = skeleton.parents[j]
        priors = _joint_priors(P, ranges, j, p)
        assert len(priors) >= 8
        e = {cap: _exact_errors(P, cams, px, j, p, priors, angle_cap=cap) for cap in (None, 9.0)}
        for seed in range(3):
            assert e[None][seed] > 0.4 and e[9.0][seed] < 0.05, (name, seed, e)


def test_steady_keeps_only_rigid_points_whose_angle_holds() -> None:
    # learn_angle_ranges(rigid=) tests distances: a point far from a short bone keeps them
    # within a few per cent while the angle at the parent swings. steady= also tests the
    # angle. A toy first: a 0.1 m bone swinging +-30 deg about its parent, a point 2 m away
    # (distances vary by < 3 %) and a partner rigid with the bone.
    t = np.linspace(0.0, 2.0 * np.pi, 200)
    F = t.size
    swing = np.radians(30.0) * np.sin(t)
    P = np.zeros((F, 4, 3))
    P[:, 1] = np.stack([0.1 * np.sin(swing), -0.1 * np.cos(swing), np.zeros(F)], axis=1)
    P[:, 2] = [0.0, 2.0, 0.0]
    P[:, 3] = 0.5 * P[:, 1] + np.stack([0.02 * np.cos(swing), 0.02 * np.sin(swing), 0 * t], 1)
    d = np.linalg.norm(P[:, 2] - P[:, 1], axis=1)
    assert d.std() / d.mean() < 0.03
    parents = [-1, 0, 0, 0]
    kw = {"bend": False, "siblings": False, "rigid": 0.08}
    assert {(1, 0, 2), (1, 0, 3)} <= set(sc.learn_angle_ranges(P, parents, **kw))
    r = sc.learn_angle_ranges(P, parents, steady=0.08, **kw)
    assert (1, 0, 3) in r and (1, 0, 2) not in r
    assert r[1, 0, 3][1] - r[1, 0, 3][0] < np.radians(1.0)
    # On real motion: CMU 131_01 starting to walk, frames 201-260 at 120 Hz, RightKnee with
    # every prior learned from the other trial (exact parent and length, 0.5 px noise). The
    # distance test admits 9 points of the trunk and arms whose ranges (30-75 deg wide, from
    # the other trial's walking postures) these frames' true angles miss by up to 45 deg:
    # measured 1.02 (seeds 0-2). With steady=0.08 only the root stays besides the bend
    # range: 0.014 0.015 0.032.
    P, skeleton, keep, cams, px = _clip_window("cmu_131_01_start300.bvh", 201, step=1)
    j = skeleton.index("RightKnee")
    p = skeleton.parents[j]
    for steady, ok in ((None, False), (0.08, True)):
        ranges = _trial_ranges("02", skeleton, keep, rigid=0.08, steady=steady)
        errs = _exact_errors(P, cams, px, j, p, _joint_priors(P, ranges, j, p))
        for seed, e in enumerate(errs):
            assert (e < 0.06) == ok, (steady, seed, e)


def test_the_priors_own_start_reaches_a_hip_the_flips_miss() -> None:
    # Fig 4.3(c) conditions, every prior of the bench's robust-rigid (bend, siblings and
    # points rigid with the joint and its parent, learned from the other trial with
    # rigid=0.08; references 5 % of their bones off). LeftHip of 131_01 walking (frames 60,
    # 62, …) and of 131_02 stopping (frames 90, 92, …): in some draws the binary program
    # and the flips at grazing frames offer only impostor-side starts, which the priors
    # score badly but cannot replace. prior_start adds the start that takes, frame by
    # frame, the root the priors prefer. Measured seeds 0–3, without → with: walking
    # 0.366 0.463 0.083 0.134 → 0.060 0.017 0.083 0.134; stopping 0.365 0.014 0.066 0.088
    # → 0.068 0.014 0.067 0.088.
    errs: dict[bool, list[float]] = {True: [], False: []}
    for name, offset, trial in (
        ("cmu_131_01_walk300.bvh", 60, "02"),
        ("cmu_131_02_stop300.bvh", 90, "01"),
    ):
        P, skeleton, keep, cams, px = _clip_window(name, offset)
        ranges = _trial_ranges(trial, skeleton, keep, rigid=0.08)
        F = P.shape[0]
        j = skeleton.index("LeftHip")
        p = skeleton.parents[j]
        for seed in range(4):
            x, parent, r, den = _fig43c_draw(P, px, j, p, seed)
            kids = _fig43c_children(P, px, skeleton, j, seed)
            priors = []
            for (jj, a, b), lohi in ranges.items():
                if (jj, a) != (j, p):
                    continue  # (LeftHip hangs off the root: no bend prior)
                rb = float(np.linalg.norm(P[:, b] - P[:, p], axis=1).mean())
                rng = np.random.default_rng(seed * 1000 + 17 * j + 6 + b)
                priors.append((P[:, b] + _smooth_offset(F, 0.05 * rb, rng) - parent, lohi))
            assert len(priors) >= 5
            for on in (True, False):
                out = sc.reconstruct_articulated(
                    x,
                    cams,
                    parent,
                    1.05 * r,
                    k=8,
                    children=kids,
                    angle_priors=priors,
                    prior_start=on,
                    angle_refine=0.0,  # the start alone (the refinement pulls these in too)
                )
                errs[on].append(float(np.linalg.norm(out.points - P[:, j]) / den))
    on_, off_ = np.array(errs[True]), np.array(errs[False])
    assert (on_ < off_ + 0.02).all(), errs  # the extra start costs nothing where it loses
    assert (on_ < off_ - 0.2).sum() >= 3, errs
    assert on_.max() < 0.2, errs


def test_the_priors_in_the_refinement_pull_the_trunk_into_range() -> None:
    # CMU 131_01 walking (frames 0, 2, …, 118), Fig 4.3(c) conditions, the trunk joints and
    # the hips and shoulders, each with every prior whose reference hangs off its parent
    # (siblings and rigid points, learned from the other trial with rigid=0.08, given 5 %
    # of their bones off). With the parent 5 % off the refinement of Eq 4.5 alone leaves
    # the bone turned out of ranges the other trial never leaves; angle_refine (0.5, the
    # default) adds each frame's excess as a residual. Measured seeds 0–3, pooled mean over
    # the 28 draws: 0.107 without → 0.094 with (Chest 0.177 → 0.122, RightHip 0.060 →
    # 0.046, Head 0.171 → 0.155; the shoulders 0.049 / 0.059 → 0.054 / 0.057); at 1: 0.083.
    P, skeleton, keep, cams, px = _clip_window("cmu_131_01_walk300.bvh")
    ranges = _trial_ranges("02", skeleton, keep, rigid=0.08)
    F = P.shape[0]
    errs: dict[float, list[float]] = {0.0: [], 0.5: []}
    names = ("LeftHip", "RightHip", "Chest", "LeftShoulder", "RightShoulder", "Neck", "Head")
    for name, seed in itertools.product(names, range(4)):
        j = skeleton.index(name)
        p = skeleton.parents[j]
        x, parent, r, den = _fig43c_draw(P, px, j, p, seed)
        kids = _fig43c_children(P, px, skeleton, j, seed)
        priors = []
        for (jj, a, b), lohi in ranges.items():
            if (jj, a) == (j, p):
                rb = float(np.linalg.norm(P[:, b] - P[:, p], axis=1).mean())
                rng = np.random.default_rng(seed * 1000 + 17 * j + 6 + b)
                priors.append((P[:, b] + _smooth_offset(F, 0.05 * rb, rng) - parent, lohi))
        for w in errs:
            out = sc.reconstruct_articulated(
                x, cams, parent, 1.05 * r, k=8, children=kids, angle_priors=priors, angle_refine=w
            )
            errs[w].append(float(np.linalg.norm(out.points - P[:, j]) / den))
    on_, off_ = np.mean(errs[0.5]), np.mean(errs[0.0])
    assert on_ < 0.92 * off_, (on_, off_)


def test_bone_angles_and_learned_ranges() -> None:
    # A tree root → a → b → c and root → s: b's bone turns 10°..40° from a's, c's stays at
    # 90° from b's, s's bone is fixed (a sibling of a, at 90° from it).
    t = np.radians(np.linspace(10.0, 40.0, 31))
    F = len(t)
    P = np.zeros((F, 5, 3))
    P[:, 1] = [0.0, 0.1, 0.0]
    P[:, 2] = P[:, 1] + 0.3 * np.c_[np.sin(t), np.cos(t), np.zeros(F)]
    d = (P[:, 2] - P[:, 1]) / 0.3
    P[:, 3] = P[:, 2] + 0.2 * np.c_[d[:, 1], -d[:, 0], np.zeros(F)]
    P[:, 4] = [0.2, 0.0, 0.0]
    parents = [-1, 0, 1, 2, 0]
    np.testing.assert_allclose(sc.bone_angles(P, (1, 2), (0, 1)), t, atol=1e-9)
    np.testing.assert_allclose(sc.bone_angles(P, (2, 3), (1, 2)), np.pi / 2, atol=1e-9)
    assert np.isnan(sc.bone_angles(P, (0, 0), (0, 1))).all()  # a bone without length
    r = sc.learn_angle_ranges(P, parents)
    assert set(r) == {(2, 0, 1), (3, 1, 2), (1, 0, 4), (4, 0, 1)}
    np.testing.assert_allclose(r[2, 0, 1], np.radians([10.0, 40.0]), atol=1e-9)
    np.testing.assert_allclose(r[3, 1, 2], [np.pi / 2, np.pi / 2], atol=1e-9)
    np.testing.assert_allclose(r[1, 0, 4], [np.pi / 2, np.pi / 2], atol=1e-9)
    assert set(sc.learn_angle_ranges(P, parents, siblings=False)) == {(2, 0, 1), (3, 1, 2)}
    assert set(sc.learn_angle_ranges(P, parents, bend=False)) == {(1, 0, 4), (4, 0, 1)}
    r = sc.learn_angle_ranges([P, P[:10]], parents, quantiles=(0.5, 0.5), margin=2.0)
    assert r[2, 0, 1][0] == 0.0 and r[3, 1, 2][1] == np.pi  # clipped to [0, π]
    # rigid: 3 keeps its distances to 1 and 2 (a right angle at 2), 4 and 1 are fixed; the
    # angle at the parent between the bone and the rigid partner is learned.
    r = sc.learn_angle_ranges(P, parents, bend=False, siblings=False, rigid=0.01)
    assert set(r) == {(1, 0, 4), (4, 0, 1), (2, 1, 3), (3, 2, 1)}
    np.testing.assert_allclose(r[2, 1, 3], [np.arctan(2 / 3)] * 2, atol=1e-9)
    np.testing.assert_allclose(r[3, 2, 1], [np.pi / 2] * 2, atol=1e-9)
    # Frames where a point is missing (NaN, marker gaps) are left out of both steps.
    Pn = P.copy()
    Pn[::3, 3] = np.nan
    rn = sc.learn_angle_ranges(Pn, parents, bend=False, siblings=False, rigid=0.01)
    assert set(rn) == set(r)
    np.testing.assert_allclose(rn[3, 2, 1], r[3, 2, 1], atol=1e-9)
    assert (2, 1, 3) in sc.learn_angle_ranges(P, parents, rigid=0.01)
    assert (2, 1, 3) not in sc.learn_angle_ranges(P, parents)


def test_bad_angle_priors_are_refused_by_name(scene: Scene) -> None:
    j = scene.skeleton.index("LeftElbow")
    p = scene.skeleton.parents[j]
    g = scene.skeleton.parents[p]
    x, parent, r, _ = _fig43c_draw(scene.P, scene.px, j, p, 0)
    ref = scene.P[:, p] - scene.P[:, g]
    cases = [
        ([(ref, (0.9, 0.2))], r"^angle_priors\[0\] range: need 0 <= lo"),
        ([(ref, (0.2, 3.5))], r"^angle_priors\[0\] range: need 0 <= lo"),
        ([(ref, (0.2,))], r"^angle_priors\[0\] range: expected \(lo, hi\)"),
        ([(ref, "ab")], r"^angle_priors\[0\] range: expected \(lo, hi\)"),
        ([(ref[:5], (0.2, 0.9))], r"^angle_priors\[0\] reference: expected shape"),
        ([(np.full_like(ref, np.nan), (0.2, 0.9))], r"^angle_priors\[0\] reference"),
        ([ref], r"^angle_priors\[0\]: expected a \(reference"),
        (ref, r"^angle_priors: expected a sequence"),
    ]
    for priors, message in cases:
        with pytest.raises(ValueError, match=message):
            sc.reconstruct_articulated(x, scene.cams, parent, r, k=8, angle_priors=priors)
    for kw, message in (
        (dict(angle_tolerance=0.0), r"^angle_tolerance"),
        (dict(angle_weight=-1.0), r"^angle_weight"),
        (dict(prior_start=1), r"^prior_start: expected a bool"),
        (dict(angle_refine=-1.0), r"^angle_refine"),
        (dict(k_alternatives=12), r"^k_alternatives: expected a tuple"),
        (dict(k_alternatives=(12, 0)), r"^k_alternatives\[1\]"),
        (dict(k_per_second=0.0), r"^k_per_second"),
        (dict(angle_cap=0.0), r"^angle_cap"),
        (dict(angle_cap=float("inf")), r"^angle_cap"),
        (dict(k_per_second=float("nan")), r"^k_per_second"),
        (dict(k_growth=0.5), r"^k_growth"),
        (dict(k_growth=float("nan")), r"^k_growth"),
        (dict(k_growth="1.5"), r"^k_growth"),
    ):
        with pytest.raises(ValueError, match=message):
            sc.reconstruct_articulated(x, scene.cams, parent, r, k=8, **kw)
    sk = scene.skeleton
    J = len(sk.names)
    with pytest.raises(ValueError, match=r"^quantiles"):
        sc.learn_angle_ranges(scene.P, sk.parents, quantiles=(0.9, 0.1))
    with pytest.raises(ValueError, match=r"^rigid"):
        sc.learn_angle_ranges(scene.P, sk.parents, rigid=-0.1)
    for bad in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match=r"^steady"):
            sc.learn_angle_ranges(scene.P, sk.parents, rigid=0.08, steady=bad)
    with pytest.raises(ValueError, match=r"^positions: expected shape"):
        sc.learn_angle_ranges(scene.P[:, :3], sk.parents)
    with pytest.raises(ValueError, match=r"^bone: expected two joint indices"):
        sc.bone_angles(scene.P, (0, J), (0, 1))


def test_the_sibling_prior_keeps_the_hip_on_the_pelvis() -> None:
    # CMU 131_01 walking (frames 0, 2, …, 118), Fig 4.3(c) conditions. RightHip (η_a 1.30)
    # hangs off the root like LeftHip: both bones are fixed in the pelvis, so their angle is
    # constant (68.3° over the other trial). Without a prior the whole window follows the
    # impostor side (errors 0.72 0.74 0.73 0.67 on seeds 0–3); with LeftHip given 5 % of its
    # bone off and the angle range learned from the other trial (131_02's four clips):
    # 0.09 0.05 0.07 0.03.
    P, skeleton, keep, cams, px = _clip_window("cmu_131_01_walk300.bvh")
    ranges = _trial_ranges("02", skeleton, keep, bend=False)
    F = P.shape[0]
    j, s = skeleton.index("RightHip"), skeleton.index("LeftHip")
    p = skeleton.parents[j]
    assert skeleton.parents[s] == p == skeleton.root
    lo, hi = ranges[j, p, s]
    assert hi - lo < np.radians(1.0)  # rigid in the capture
    errs: dict[bool, list[float]] = {True: [], False: []}
    for seed in range(4):
        x, parent, r, den = _fig43c_draw(P, px, j, p, seed)
        rs = float(np.linalg.norm(P[:, s] - P[:, p], axis=1).mean())
        rng = np.random.default_rng(seed * 1000 + 17 * j + 6 + s)
        sibling = P[:, s] + _smooth_offset(F, 0.05 * rs, rng)
        kids = _fig43c_children(P, px, skeleton, j, seed)
        for on in (True, False):
            prior = [(sibling - parent, (lo, hi))] if on else None
            out = sc.reconstruct_articulated(
                x, cams, parent, 1.05 * r, k=8, children=kids, angle_priors=prior
            )
            errs[on].append(float(np.linalg.norm(out.points - P[:, j]) / den))
    assert max(errs[True]) < 0.2, errs
    assert min(errs[False]) > 0.5, errs  # the impostor this prior is here for
