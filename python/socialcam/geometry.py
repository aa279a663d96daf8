"""Multi-view geometry: triangulation, trajectory basis, alignment, rays."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
import numpy.typing as npt

from socialcam import _core
from socialcam._validate import (
    FloatArray,
    as_float_array,
    check_bool,
    check_float,
    check_int,
    check_rounding,
    check_size,
    readonly,
)
from socialcam.camera import Cameras
from socialcam.errors import ConvergenceError, DegenerateError

#: Tolerance on ``‖v‖ − 1`` for unit directions (the gaze field uses the same).
UNIT_TOLERANCE = 1e-6


@dataclass(frozen=True)
class TriangulationInfo:
    """Diagnostics of a batched triangulation (arrays of length ``N``).

    Attributes
    ----------
    rms : reprojection RMS in pixels after refinement (NaN where it failed)
    rms_linear : reprojection RMS in pixels of the linear (DLT) solution
    views : number of views that saw each point
    converged : whether Levenberg–Marquardt met its tolerance
    failures : per point ``None`` or the reason it could not be triangulated
    """

    rms: FloatArray
    rms_linear: FloatArray
    views: npt.NDArray[np.int64]
    converged: npt.NDArray[np.bool_]
    failures: list[str | None]

    def to_dict(self) -> dict[str, Any]:
        return {
            "rms": self.rms.tolist(),
            "rms_linear": self.rms_linear.tolist(),
            "views": self.views.tolist(),
            "converged": self.converged.tolist(),
            "failures": list(self.failures),
        }


@overload
def triangulate(
    x: npt.ArrayLike,
    cameras: Cameras,
    *,
    refine: bool = ...,
    max_iter: int = ...,
    strict: bool = ...,
    return_info: Literal[False] = ...,
) -> FloatArray: ...
@overload
def triangulate(
    x: npt.ArrayLike,
    cameras: Cameras,
    *,
    refine: bool = ...,
    max_iter: int = ...,
    strict: bool = ...,
    return_info: Literal[True],
) -> tuple[FloatArray, TriangulationInfo]: ...
def triangulate(
    x: npt.ArrayLike,
    cameras: Cameras,
    *,
    refine: bool = True,
    max_iter: int = 50,
    strict: bool = False,
    return_info: bool = False,
) -> FloatArray | tuple[FloatArray, TriangulationInfo]:
    """Triangulates static points seen by several cameras.

    Linear DLT on normalised coordinates, then (``refine=True``) Levenberg–Marquardt on the
    reprojection error with an analytic Jacobian. Runs in parallel with the GIL released.

    Parameters
    ----------
    x : array_like, shape (V, 2) or (N, V, 2)
        Undistorted pixels of each point in each of the ``V`` cameras; a NaN row means the
        point was not seen in that view.
    cameras : Cameras
        ``V`` cameras.
    refine : bool
        Refine the linear solution by minimising reprojection error.
    max_iter : int
        Levenberg–Marquardt iteration cap per point (``info.converged`` says if it was met).
    strict : bool
        Raise :class:`ConvergenceError` when a triangulated point hit ``max_iter``.
    return_info : bool
        Also return a :class:`TriangulationInfo`.

    Returns
    -------
    X : ndarray, shape (3,) or (N, 3)
        World points. In the batched form a point seen in fewer than two views, or whose rays
        are parallel, is a NaN row (``info.failures`` says why).

    Raises
    ------
    DegenerateError
        Single-point form only: fewer than two views, or parallel rays.
    ValueError
        Wrong shapes, infinite values, mismatched number of views; camera centres so far
        from the origin that float64 rounds them by more than a thousandth of their spread.
    ConvergenceError
        ``strict=True`` and some point did not converge.
    """
    if not isinstance(cameras, Cameras):
        raise ValueError(f"cameras: expected socialcam.Cameras, got {type(cameras).__name__}")
    refine = check_bool(refine, "refine")
    strict = check_bool(strict, "strict")
    return_info = check_bool(return_info, "return_info")
    n_iter = check_int(max_iter, "max_iter", min=1)
    x_ = as_float_array(x, "x", allow_nan=True)
    single = x_.ndim == 2
    if single:
        x_ = x_[None]
    v = len(cameras)
    if x_.ndim != 3 or x_.shape[1:] != (v, 2):
        raise ValueError(
            f"x: expected shape ({v}, 2) or (N, {v}, 2) for {v} cameras, got {np.shape(x)}"
        )
    check_rounding(cameras.C, "cameras.C", "the cameras' spread")
    X, rms, rms0, views, conv, why = _core.triangulate(
        cameras.K, cameras.R, cameras.C, x_, bool(refine), n_iter
    )
    if single and why[0] is not None:
        raise DegenerateError(why[0])
    if strict:
        stuck = np.flatnonzero(~conv & np.array([w is None for w in why], dtype=bool))
        if len(stuck):
            raise ConvergenceError(
                f"{len(stuck)} point(s) did not converge in max_iter={n_iter} iterations "
                f"(first: point {int(stuck[0])})"
            )
    info = TriangulationInfo(readonly(rms), readonly(rms0), readonly(views), readonly(conv), why)
    out = X[0] if single else X
    return (out, info) if return_info else out


def dct_basis(
    times: npt.ArrayLike, k: int, *, t0: float | None = None, t1: float | None = None
) -> FloatArray:
    """The first ``k`` DCT-II trajectory basis vectors at (possibly non-uniform) times.

    ``phi_j(t) = c_j cos(pi j (t - t0) / (t1 - t0))`` with ``c_0 = sqrt(1/F)``,
    ``c_j = sqrt(2/F)`` (``F = len(times)``), so the ``(F, k)`` result has orthonormal
    columns on uniform samples, and its first column is constant. By default ``[t0, t1]``
    extends the sampled range by half a mean sample spacing on each side, which puts uniform
    samples at the DCT's cell centres.

    Parameters
    ----------
    times : array_like, shape (F,)
        Seconds.
    k : int
        Number of basis vectors, ``k >= 1`` (the ``(F, k)`` result must fit in 2 GiB).
    t0, t1 : float, optional
        The time span mapped to ``[0, 1]``.

    Returns
    -------
    ndarray, shape (F, k)
    """
    t = as_float_array(times, "times", (None,))
    kk = check_int(k, "k", min=1)
    check_size("k", (len(t), kk))
    a = None if t0 is None else check_float(t0, "t0")
    b = None if t1 is None else check_float(t1, "t1")
    if a is not None and b is not None and not a < b:
        raise ValueError(f"t0, t1: need t0 < t1, got {a} and {b}")
    ends = np.concatenate([t, [x for x in (a, b) if x is not None]])
    with np.errstate(over="ignore"):  # the default span adds half a spacing on each side
        span = 2.0 * (ends.max() - ends.min()) if len(ends) else 0.0
    if not np.isfinite(span):
        name = "times" if a is None and b is None else "times, t0, t1"
        raise ValueError(f"{name}: the span {ends.min():g} .. {ends.max():g} s overflows float64")
    return _core.dct_basis(t, kk, a, b)


def align_similarity(
    src: npt.ArrayLike, dst: npt.ArrayLike
) -> tuple[float, FloatArray, FloatArray]:
    """Least-squares similarity (Umeyama) with ``dst ≈ scale * R @ src + t``.

    Parameters
    ----------
    src, dst : array_like, shape (N, 3)
        Corresponding points, ``N >= 3`` and not collinear.

    Returns
    -------
    scale : float
    R : ndarray, shape (3, 3)
        Proper rotation.
    t : ndarray, shape (3,)

    Raises
    ------
    DegenerateError
        Fewer than 3 points, or collinear/coincident points.
    ValueError
        Points so far from the origin that float64 rounds them by more than a thousandth of
        their spread.
    """
    a = as_float_array(src, "src", (None, 3))
    b = as_float_array(dst, "dst", (None, 3))
    # Solved on centred points of unit RMS spread, then mapped back: points of 1e200 m
    # overflowed (scale, R, t all NaN), of 1e-200 m underflowed to "coincident", and a
    # scene far from the origin lost its spread in the rounding.
    ma, sa = _centre_spread(a, "src")
    mb, sb = _centre_spread(b, "dst")
    s_n, R, t_n = _core.align_similarity((a - ma) / sa, (b - mb) / sb)
    scale = float(s_n) * sb / sa
    t = mb + sb * np.asarray(t_n) - scale * (np.asarray(R) @ ma)
    return scale, R, t


def _centre_spread(x: FloatArray, name: str) -> tuple[FloatArray, float]:
    """Centroid and RMS distance from it of ``(N, 3)`` points (1.0 when they coincide, for
    the core to name), computed without overflow; refuses points float64 rounds by more
    than a thousandth of their spread."""
    m = x.mean(axis=0) if len(x) else np.zeros(3)
    d = x - m
    big = float(np.abs(d).max(initial=0.0))
    if big == 0.0:
        return m, 1.0
    spread = big * float(np.sqrt(np.mean(np.sum((d / big) ** 2, axis=1))))
    check_rounding(x, name, "the points' spread", spread)
    return m, spread


def ray_sphere(
    origins: npt.ArrayLike, directions: npt.ArrayLike, centres: npt.ArrayLike, radii: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Both intersections of rays with spheres (thesis Eq 4.8–4.9), batched.

    Parameters
    ----------
    origins, directions, centres : array_like, shape (N, 3)
        Ray origins ``C``, directions ``v`` (any non-zero length), sphere centres.
    radii : float or array_like, shape (N,)

    Returns
    -------
    s : ndarray, shape (N, 2)
        Ray parameters of the two roots, larger first, with points ``C + s v``. NaN where the
        line misses the sphere.
    miss : ndarray, shape (N,)
        Where the line misses, the radius at which it would touch (Sec 4.4.1 enlarges the
        sphere to this); 0 where it hits.
    """
    o = as_float_array(origins, "origins", (None, 3))
    n = o.shape[0]
    d = as_float_array(directions, "directions", (n, 3))
    c = as_float_array(centres, "centres", (n, 3))
    r_ = as_float_array(radii, "radii")
    if r_.ndim > 1 or (r_.ndim == 1 and r_.shape[0] not in (1, n)):
        raise ValueError(f"radii: expected a number or shape ({n},), got {r_.shape}")
    r = np.broadcast_to(r_, (n,)).copy()
    # The roots scale with 1/|v|: solved with each direction divided by its largest
    # component, then divided back (|v| of 1e200 or 1e-170 overflowed in the squares)
    big = np.abs(d).max(axis=1) if n else np.ones(0)
    big = np.where(big > 0, big, 1.0)
    s, miss = _core.ray_sphere(o, d / big[:, None], c, r)
    if not (np.isfinite(s) | np.isnan(s)).all() or not np.isfinite(miss).all():
        raise ValueError(
            "origins, centres, radii: the intersections overflow float64 (positions or radii "
            "beyond 1e150)"
        )
    return s / big[:, None], miss


def perspective_distance(p: npt.ArrayLike, v: npt.ArrayLike, x: npt.ArrayLike) -> FloatArray:
    """Perspective distance vectors of thesis Eq 6.2 between rays and points.

    ``d = (x - x_hat) / ((x - p)·v)`` with ``x_hat`` the projection of ``x`` on the ray; it
    is the offset on the plane at unit distance in front of the eye. Points behind the eye
    get ``inf`` rows; the eye itself (``x = p``) gets the zero vector.

    Parameters
    ----------
    p, v, x : array_like, shape (N, 3)
        Eye centres, unit directions (``|‖v‖ − 1| ≤ 1e-6``; anything else is refused, as
        the distance scales with ``1/‖v‖``), query points, row by row.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    p_ = as_float_array(p, "p", (None, 3))
    n = p_.shape[0]
    v_ = as_float_array(v, "v", (n, 3))
    x_ = as_float_array(x, "x", (n, 3))
    norms = np.linalg.norm(v_, axis=1)
    bad = np.abs(norms - 1.0) > UNIT_TOLERANCE
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"v: direction {i} has norm {norms[i]:.6g}, not 1 (normalise it)")
    return _core.perspective_distance(p_, v_, x_)
