"""Trajectory reconstruction of moving points (thesis Chapter 5).

A moving point seen once per frame, by cameras with known poses and capture times, is
reconstructed as ``X(t) = Σ_k θ_k(t) β_k`` with the first ``K`` DCT basis functions of
continuous time (Eq 5.3): no two photos need share a time instant. The coefficients come
from the linear system ``QΘ β = q`` (Eq 5.7), ``K`` is chosen per point by N-fold cross
validation (Eq 5.8) and the solution is refined on the reprojection error (Eq 5.9). The work
runs in the Rust core, in parallel over points, with the GIL released.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from socialcam import _core
from socialcam._validate import (
    FloatArray,
    apply_overrides,
    as_float_array,
    check_bool,
    check_choice,
    check_int,
    check_rounding,
    check_size,
    readonly,
)
from socialcam.camera import Cameras
from socialcam.errors import ConvergenceError, DegenerateError

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


def _basis(times: FloatArray, k: int, span: tuple[float, float, float]) -> FloatArray:
    """The ``(M, k)`` DCT basis of :func:`socialcam.dct_basis` on a fixed span and
    normalisation: ``θ_j(t) = c_j cos(π j u)``, ``u = (t − t0)/(t1 − t0)``."""
    t0, t1, n_norm = span
    u = (times - t0) / (t1 - t0)
    j = np.arange(k)
    c = np.where(j == 0, np.sqrt(1.0 / n_norm), np.sqrt(2.0 / n_norm))
    return np.asarray(c * np.cos(np.pi * np.outer(u, j)), dtype=np.float64)


@dataclass(frozen=True)
class Trajectory:
    """One reconstructed point trajectory and its diagnostics.

    Attributes
    ----------
    points : ndarray, shape (F, 3)
        The trajectory at every frame time (metres), including frames where the point was
        not seen.
    k : int
        Basis functions per coordinate.
    coeffs : ndarray, shape (k, 3)
        DCT coefficients ``β``: ``X(t) = Σ_j θ_j(t) coeffs[j]``.
    rms : float
        Reprojection RMS (pixels per observation) of the returned solution.
    rms_linear : float
        Reprojection RMS of the linear solution (Eq 5.7), before refinement.
    std : ndarray, shape (F, 3)
        Per-frame standard deviation of each coordinate (metres) from the Gauss–Newton
        covariance at the optimum; NaN when there are no more equations than unknowns.
    converged : bool
        Whether the refinement met its tolerance (true when not refined).
    iterations : int
        Levenberg–Marquardt iterations.
    rank : int
        Numerical rank of ``QΘ`` (``3k``).
    cond : float
        Condition number of ``QΘ`` (normalised measurements).
    sigma : float
        Residual standard deviation per image coordinate (pixels) scaling the covariance.
    n_observed : int
        Number of frames where the point was seen.
    cv_error : ndarray, shape (Kcv,)
        Cross-validated reprojection RMS (pixels) for ``K = 1, 2, …`` (inf: not admissible;
        empty when ``k`` was fixed).
    covariance : ndarray, shape (3k, 3k) or None
        Covariance of ``coeffs.ravel()`` (order ``3 j + c``).
    span : (t0, t1, n_norm)
        The DCT span, to evaluate the trajectory at other times.
    """

    points: FloatArray
    k: int
    coeffs: FloatArray
    rms: float
    rms_linear: float
    std: FloatArray
    converged: bool
    iterations: int
    rank: int
    cond: float
    sigma: float
    n_observed: int
    cv_error: FloatArray
    covariance: FloatArray | None
    span: tuple[float, float, float]

    def at(self, times: npt.ArrayLike, *, extrapolate: bool = False) -> FloatArray:
        """The trajectory at arbitrary times ``(M,)`` seconds → ``(M, 3)`` metres.

        The DCT basis is even about both ends of its span (``cos`` mirrors), so outside
        ``[span[0], span[1]]`` it would return the trajectory reflected in time, not a
        prediction. Times outside the span therefore raise ``ValueError`` unless
        ``extrapolate=True`` (then the mirrored values are returned as they are).
        """
        scalar = np.ndim(times) == 0
        t = as_float_array(times, "times").reshape(-1)
        _check_in_span(t, self.span, extrapolate)
        out = _basis(t, self.k, self.span) @ self.coeffs
        return out[0] if scalar else out

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able data."""
        return {
            "points": self.points.tolist(),
            "k": self.k,
            "coeffs": self.coeffs.tolist(),
            "rms": self.rms,
            "rms_linear": self.rms_linear,
            "std": self.std.tolist(),
            "converged": self.converged,
            "iterations": self.iterations,
            "rank": self.rank,
            "cond": self.cond,
            "sigma": self.sigma,
            "n_observed": self.n_observed,
            "cv_error": self.cv_error.tolist(),
            "covariance": None if self.covariance is None else self.covariance.tolist(),
            "span": list(self.span),
        }


@dataclass(frozen=True)
class TrajectoryBatch:
    """``N`` reconstructed trajectories sharing the cameras. Points that could not be
    reconstructed have NaN rows, ``k = 0`` and their reason in ``failures``.

    Attributes
    ----------
    points : ndarray, shape (N, F, 3)
    k : ndarray, shape (N,)
    rms, rms_linear : ndarray, shape (N,)
        Reprojection RMS (pixels) after and before refinement.
    std : ndarray, shape (N, F, 3)
    coeffs : ndarray, shape (N, Kmax, 3)
        Zero beyond each point's ``k``.
    converged : ndarray of bool, shape (N,)
    iterations, rank, n_observed : ndarray of int, shape (N,)
    cond, sigma : ndarray, shape (N,)
    cv_error : ndarray, shape (N, Kcv)
        NaN beyond each point's range.
    failures : list of (str or None)
    span : (t0, t1, n_norm)
    """

    points: FloatArray
    k: IntArray
    rms: FloatArray
    rms_linear: FloatArray
    std: FloatArray
    coeffs: FloatArray
    converged: BoolArray
    iterations: IntArray
    rank: IntArray
    cond: FloatArray
    sigma: FloatArray
    n_observed: IntArray
    cv_error: FloatArray
    failures: list[str | None]
    span: tuple[float, float, float]

    @property
    def ok(self) -> BoolArray:
        """``(N,)`` true where the point was reconstructed."""
        return np.array([f is None for f in self.failures], dtype=bool)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def __getitem__(self, i: int) -> Trajectory:
        """Point ``i`` as a :class:`Trajectory`; raises :class:`DegenerateError` if it failed."""
        n = len(self)
        if not -n <= int(i) < n:
            raise IndexError(f"point index {i} out of range for {n} points")
        i = int(i) % n
        if self.failures[i] is not None:
            raise DegenerateError(f"point {i}: {self.failures[i]}")
        k = int(self.k[i])
        cv = self.cv_error[i]
        return Trajectory(
            points=self.points[i],
            k=k,
            coeffs=self.coeffs[i, :k],
            rms=float(self.rms[i]),
            rms_linear=float(self.rms_linear[i]),
            std=self.std[i],
            converged=bool(self.converged[i]),
            iterations=int(self.iterations[i]),
            rank=int(self.rank[i]),
            cond=float(self.cond[i]),
            sigma=float(self.sigma[i]),
            n_observed=int(self.n_observed[i]),
            cv_error=cv[~np.isnan(cv)],
            covariance=None,
            span=self.span,
        )

    def at(self, times: npt.ArrayLike, *, extrapolate: bool = False) -> FloatArray:
        """All trajectories at times ``(M,)`` seconds → ``(N, M, 3)`` (NaN for failures).
        Times outside the span raise ``ValueError`` unless ``extrapolate`` (see
        :meth:`Trajectory.at`)."""
        t = as_float_array(times, "times", (None,))
        _check_in_span(t, self.span, extrapolate)
        check_size("times", (len(self), len(t), 3))
        kmax = self.coeffs.shape[1]
        out = np.einsum("mk,nkc->nmc", _basis(t, kmax, self.span), self.coeffs)
        out[~self.ok] = np.nan
        return out

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able data."""
        return {
            "points": self.points.tolist(),
            "k": self.k.tolist(),
            "rms": self.rms.tolist(),
            "rms_linear": self.rms_linear.tolist(),
            "std": self.std.tolist(),
            "coeffs": self.coeffs.tolist(),
            "converged": self.converged.tolist(),
            "iterations": self.iterations.tolist(),
            "rank": self.rank.tolist(),
            "cond": self.cond.tolist(),
            "sigma": self.sigma.tolist(),
            "n_observed": self.n_observed.tolist(),
            "cv_error": self.cv_error.tolist(),
            "failures": list(self.failures),
            "span": list(self.span),
        }


def _check_in_span(t: FloatArray, span: tuple[float, float, float], extrapolate: bool) -> None:
    extrapolate = check_bool(extrapolate, "extrapolate")
    t0, t1, _ = span
    slack = 1e-9 * (t1 - t0)
    if not extrapolate and len(t) and (t.min() < t0 - slack or t.max() > t1 + slack):
        raise ValueError(
            f"times: outside the fitted span [{t0:.6g}, {t1:.6g}] s, where the DCT basis "
            "mirrors the trajectory instead of predicting it (pass extrapolate=True to get "
            "the mirrored values anyway)"
        )


@dataclass(frozen=True)
class TrajectoryOptions:
    """Options of :func:`reconstruct_trajectory` and :func:`reconstruct_trajectories`
    (validated on construction; the Rust binding reads the same object).

    Attributes
    ----------
    k : int or "auto"
        DCT basis functions per coordinate, or ``"auto"`` for per-point N-fold cross
        validation (Eq 5.8) over ``K = k_min … min(k_max, ⌊2F̂/3⌋)`` (``F̂`` observed frames).
        The cost of cross validation grows like ``k_max³``: cap ``k_max`` for long sequences.
    folds : int
        Cross-validation folds (≥ 2), spread uniformly in time.
    k_min : int
        Smallest ``K`` tried by cross validation (≥ 1).
    k_max : int, optional
        Largest ``K`` tried by cross validation.
    cv_rule : {"min", "1se"}
        ``"min"``: the ``K`` of least held-out error (Eq 5.8). ``"1se"``: the smallest ``K``
        within one standard error of it (more parsimonious; still points get ``K = 1``).
    refine : bool
        Refine on the reprojection error (Eq 5.9, Levenberg–Marquardt).
    max_iter : int
        Levenberg–Marquardt iteration cap (``converged=False`` when reached).
    """

    k: int | Literal["auto"] = "auto"
    folds: int = 5
    k_min: int = 1
    k_max: int | None = None
    cv_rule: Literal["min", "1se"] = "min"
    refine: bool = True
    max_iter: int = 100

    def __post_init__(self) -> None:
        if isinstance(self.k, str):
            check_choice(self.k, "k", ("auto",))
        else:
            object.__setattr__(self, "k", check_int(self.k, "k", min=1))
        object.__setattr__(self, "folds", check_int(self.folds, "folds", min=2))
        object.__setattr__(self, "k_min", check_int(self.k_min, "k_min", min=1))
        if self.k_max is not None:
            object.__setattr__(self, "k_max", check_int(self.k_max, "k_max", min=self.k_min))
        check_choice(self.cv_rule, "cv_rule", ("min", "1se"))
        if not isinstance(self.refine, (bool, np.bool_)):
            raise ValueError(f"refine: expected a bool, got {self.refine!r}")
        object.__setattr__(self, "refine", bool(self.refine))
        object.__setattr__(self, "max_iter", check_int(self.max_iter, "max_iter", min=1))


def _cameras_arg(cameras: object) -> tuple[Cameras, FloatArray]:
    if not isinstance(cameras, Cameras):
        raise ValueError(f"cameras: expected a socialcam.Cameras, got {type(cameras).__name__}")
    if cameras.times is None:
        raise ValueError(
            "cameras: trajectory reconstruction needs capture times (Cameras(..., times=...))"
        )
    return cameras, cameras.times


def _check_converged(r: dict[str, Any], opts: TrajectoryOptions, strict: bool) -> None:
    if not strict:
        return
    ok = np.array([f is None for f in r["failures"]], dtype=bool)
    stuck = np.flatnonzero(ok & ~np.asarray(r["converged"], dtype=bool))
    if len(stuck):
        raise ConvergenceError(
            f"{len(stuck)} trajectory(ies) did not converge in max_iter={opts.max_iter} "
            f"iterations (first: point {int(stuck[0])})"
        )


def _run(
    x: FloatArray,
    cameras: Cameras,
    times: FloatArray,
    options: TrajectoryOptions,
    *,
    keep_covariance: bool,
    strict: bool,
) -> dict[str, Any]:
    # Solved about the camera centres' mean, then moved back: the linear system of Eq 5.7
    # carries the centres, and far from the origin (a scene at 1e9 m) their size swamps
    # the point's motion in float64 (1e10 m read as a still camera).
    origin = cameras.C.mean(axis=0)
    check_rounding(cameras.C, "cameras.C", "the camera's motion")
    result: dict[str, Any] = _core.reconstruct_trajectories(
        cameras.K,
        cameras.R,
        np.ascontiguousarray(cameras.C - origin),
        times,
        x,
        options,
        keep_covariance=keep_covariance,
        strict=strict,
    )
    if origin.any():
        result["points"] = result["points"] + origin
        # X(t) = Σ θ_j(t) β_j with θ_0 = sqrt(1/n_norm): the shift enters β_0 alone
        coeffs = np.array(result["coeffs"], dtype=np.float64)
        solved = np.array([f is None for f in result["failures"]], dtype=bool)
        coeffs[solved, 0] += origin * np.sqrt(float(result["span"][2]))
        result["coeffs"] = coeffs
    return result


def reconstruct_trajectory(
    x: npt.ArrayLike,
    cameras: Cameras,
    *,
    options: TrajectoryOptions | None = None,
    strict: bool = False,
    **overrides: Any,
) -> Trajectory:
    """Reconstructs the 3D trajectory of one moving point (thesis Chapter 5).

    Parameters
    ----------
    x : array_like, shape (F, 2)
        Undistorted pixels of the point in frame ``f``'s camera; a NaN row means it was not
        seen in that frame.
    cameras : Cameras
        ``F`` cameras with capture ``times`` (seconds, any order, one clock).
    options : TrajectoryOptions, optional
        ``k``, ``folds``, ``k_min``, ``k_max``, ``cv_rule``, ``refine``, ``max_iter``.
    strict : bool
        Raise :class:`ConvergenceError` when the refinement hit ``max_iter``.
    **overrides
        Fields of :class:`TrajectoryOptions` to change, e.g. ``k=10`` or ``k_max=25``.

    Returns
    -------
    Trajectory

    Raises
    ------
    DegenerateError
        ``rank(QΘ) < 3K``: too few observations for ``K``, a still camera, or a camera
        moving like the point (Theorem 2) — the message says which.
    ValueError
        Bad shapes, NaN in cameras, non-finite times, all observations missing, bad options;
        camera centres so far from the origin that float64 rounds them by more than a
        thousandth of their motion (the solve itself is about their mean, so a scene at
        1e10 m gives the answer it gives at the origin).
    ConvergenceError
        ``strict=True`` and the refinement did not converge.
    """
    strict = check_bool(strict, "strict")
    opts = apply_overrides(options, TrajectoryOptions, overrides)
    cams, times = _cameras_arg(cameras)
    x_ = as_float_array(x, "x", (len(cams), 2), allow_nan=True)
    r = _run(x_[None], cams, times, opts, keep_covariance=True, strict=True)
    _check_converged(r, opts, strict)
    kk = int(r["k"][0])
    cv = r["cv_error"][0]
    return Trajectory(
        points=readonly(r["points"][0]),
        k=kk,
        coeffs=readonly(r["coeffs"][0, :kk].copy()),
        rms=float(r["rms"][0]),
        rms_linear=float(r["rms_linear"][0]),
        std=readonly(r["std"][0]),
        converged=bool(r["converged"][0]),
        iterations=int(r["iterations"][0]),
        rank=int(r["rank"][0]),
        cond=float(r["cond"][0]),
        sigma=float(r["sigma"][0]),
        n_observed=int(r["n_observed"][0]),
        cv_error=readonly(cv[~np.isnan(cv)].copy()),
        covariance=None if r["covariance"][0] is None else readonly(r["covariance"][0]),
        span=tuple(float(v) for v in r["span"]),  # type: ignore[arg-type]
    )


def reconstruct_trajectories(
    x: npt.ArrayLike,
    cameras: Cameras,
    *,
    options: TrajectoryOptions | None = None,
    strict: bool = False,
    **overrides: Any,
) -> TrajectoryBatch:
    """Reconstructs ``N`` moving points that share the cameras, each with its own missing
    pattern and its own ``K``; in parallel over points.

    Parameters are those of :func:`reconstruct_trajectory`, with ``x`` of shape
    ``(N, F, 2)``. A point that cannot be reconstructed (degenerate, all missing) does not
    stop the batch: its rows are NaN and ``failures[i]`` says why. Ctrl-C stops the batch
    (``KeyboardInterrupt``). ``strict=True`` raises :class:`ConvergenceError` when a
    reconstructed point's refinement hit ``max_iter``.

    Returns
    -------
    TrajectoryBatch
    """
    strict = check_bool(strict, "strict")
    opts = apply_overrides(options, TrajectoryOptions, overrides)
    cams, times = _cameras_arg(cameras)
    x_ = as_float_array(x, "x", (None, len(cams), 2), allow_nan=True)
    r = _run(x_, cams, times, opts, keep_covariance=False, strict=False)
    _check_converged(r, opts, strict)
    return TrajectoryBatch(
        points=readonly(r["points"]),
        k=readonly(r["k"]),
        rms=readonly(r["rms"]),
        rms_linear=readonly(r["rms_linear"]),
        std=readonly(r["std"]),
        coeffs=readonly(r["coeffs"]),
        converged=readonly(r["converged"]),
        iterations=readonly(r["iterations"]),
        rank=readonly(r["rank"]),
        cond=readonly(r["cond"]),
        sigma=readonly(r["sigma"]),
        n_observed=readonly(r["n_observed"]),
        cv_error=readonly(r["cv_error"]),
        failures=list(r["failures"]),
        span=tuple(float(v) for v in r["span"]),  # type: ignore[arg-type]
    )


def reconstructability(
    points: npt.ArrayLike,
    camera_centres: npt.ArrayLike,
    k: int,
    *,
    times: npt.ArrayLike | None = None,
) -> float:
    """Reconstructability η (Eq 5.16): ``‖Θ^⊥β_C^⊥‖ / ‖Θ^⊥β_X^⊥‖``, how poorly ``k`` DCT
    functions describe the camera trajectory relative to the point trajectory. Large η
    means an accurate reconstruction (Theorem 3); an analysis tool, as it needs the truth.

    Arguments in the order of every reconstruction call: the trajectory, then the cameras,
    then ``k`` (as :func:`socialcam.articulated_reconstructability`).

    Parameters
    ----------
    points : array_like, shape (F, 3)
        The true point trajectory (metres).
    camera_centres : array_like, shape (F, 3)
        The camera centre of each frame.
    k : int
        Basis functions per coordinate, ``1 ≤ k ≤ F``.
    times : array_like, shape (F,), optional
        Frame times; uniform when omitted.

    Returns
    -------
    float
        η; ``0`` when the basis describes the camera trajectory exactly (e.g. a still
        camera), ``inf`` when it describes the point's exactly but not the camera's.
    """
    p = as_float_array(points, "points", (None, 3))
    c = as_float_array(camera_centres, "camera_centres", (None, 3))
    t = None if times is None else as_float_array(times, "times", (None,))
    kk = check_int(k, "k", min=1, max=max(len(p), 1))
    return float(_core.reconstructability(p, c, kk, t))


def null_residual(
    trajectory: npt.ArrayLike, k: int, *, times: npt.ArrayLike | None = None
) -> float:
    """``‖Θ^⊥ β^⊥‖``: the part of a trajectory ``(F, 3)`` that ``k`` DCT functions cannot
    describe (``e_X`` or ``e_C`` of Sec 5.2.2), in metres."""
    p = as_float_array(trajectory, "trajectory", (None, 3))
    t = None if times is None else as_float_array(times, "times", (None,))
    kk = check_int(k, "k", min=1, max=max(len(p), 1))
    return float(_core.null_residual(p, kk, t))
