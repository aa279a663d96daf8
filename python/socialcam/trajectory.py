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
from socialcam._validate import FloatArray, as_float_array, readonly
from socialcam.camera import Cameras
from socialcam.errors import DegenerateError

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
    observed : int
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
    observed: int
    cv_error: FloatArray
    covariance: FloatArray | None
    span: tuple[float, float, float]

    def at(self, times: npt.ArrayLike) -> FloatArray:
        """The trajectory at arbitrary times ``(M,)`` seconds → ``(M, 3)`` metres."""
        scalar = np.ndim(times) == 0
        t = as_float_array(times, "times").reshape(-1)
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
            "observed": self.observed,
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
    iterations, rank, observed : ndarray of int, shape (N,)
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
    observed: IntArray
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
            observed=int(self.observed[i]),
            cv_error=cv[~np.isnan(cv)],
            covariance=None,
            span=self.span,
        )

    def at(self, times: npt.ArrayLike) -> FloatArray:
        """All trajectories at times ``(M,)`` seconds → ``(N, M, 3)`` (NaN for failures)."""
        t = as_float_array(times, "times", (None,))
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
            "observed": self.observed.tolist(),
            "cv_error": self.cv_error.tolist(),
            "failures": list(self.failures),
            "span": list(self.span),
        }


def _k_arg(k: int | Literal["auto"]) -> int | None:
    if isinstance(k, str):
        if k != "auto":
            raise ValueError(f"k: expected a positive integer or 'auto', got {k!r}")
        return None
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or int(k) < 1:
        raise ValueError(f"k: expected a positive integer or 'auto', got {k!r}")
    return int(k)


def _cameras_arg(cameras: Cameras) -> FloatArray:
    if not isinstance(cameras, Cameras):
        raise ValueError(f"cameras: expected a socialcam.Cameras, got {type(cameras).__name__}")
    if cameras.times is None:
        raise ValueError(
            "cameras: trajectory reconstruction needs capture times (Cameras(..., times=...))"
        )
    return cameras.times


def _run(
    x: FloatArray,
    cameras: Cameras,
    k: int | Literal["auto"],
    folds: int,
    k_max: int | None,
    refine: bool,
    k_min: int,
    cv_rule: Literal["min", "1se"],
    max_iterations: int,
    keep_covariance: bool,
    strict: bool,
) -> dict[str, Any]:
    times = _cameras_arg(cameras)
    for name, v in (("folds", folds), ("k_min", k_min), ("max_iterations", max_iterations)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or int(v) < 0:
            raise ValueError(f"{name}: expected a non-negative integer, got {v!r}")
    if k_max is not None and (
        isinstance(k_max, bool) or not isinstance(k_max, (int, np.integer)) or int(k_max) < 1
    ):
        raise ValueError(f"k_max: expected a positive integer or None, got {k_max!r}")
    result: dict[str, Any] = _core.reconstruct_trajectories(
        cameras.K,
        cameras.R,
        cameras.C,
        times,
        x,
        k=_k_arg(k),
        folds=int(folds),
        k_min=int(k_min),
        k_max=None if k_max is None else int(k_max),
        cv_rule=cv_rule,
        refine=bool(refine),
        max_iterations=int(max_iterations),
        keep_covariance=keep_covariance,
        strict=strict,
    )
    return result


def reconstruct_trajectory(
    x: npt.ArrayLike,
    cameras: Cameras,
    k: int | Literal["auto"] = "auto",
    folds: int = 5,
    k_max: int | None = None,
    refine: bool = True,
    *,
    k_min: int = 1,
    cv_rule: Literal["min", "1se"] = "min",
    max_iterations: int = 100,
) -> Trajectory:
    """Reconstructs the 3D trajectory of one moving point (thesis Chapter 5).

    Parameters
    ----------
    x : array_like, shape (F, 2)
        Undistorted pixels of the point in frame ``f``'s camera; a NaN row means it was not
        seen in that frame.
    cameras : Cameras
        ``F`` cameras with capture ``times`` (seconds, any order, one clock).
    k : int or "auto"
        DCT basis functions per coordinate, or ``"auto"`` for per-point N-fold cross
        validation (Eq 5.8) over ``K = k_min … min(k_max, ⌊2F̂/3⌋)`` (``F̂`` observed frames).
        The cost of cross validation grows like ``k_max³``: cap ``k_max`` for long sequences.
    folds : int
        Cross-validation folds, spread uniformly in time.
    k_max : int, optional
        Largest ``K`` tried by cross validation.
    refine : bool
        Refine on the reprojection error (Eq 5.9, Levenberg–Marquardt).
    k_min : int
        Smallest ``K`` tried by cross validation.
    cv_rule : {"min", "1se"}
        ``"min"``: the ``K`` of least held-out error (Eq 5.8). ``"1se"``: the smallest ``K``
        within one standard error of it (more parsimonious; still points get ``K = 1``).
    max_iterations : int
        Levenberg–Marquardt iteration cap (``converged=False`` when reached).

    Returns
    -------
    Trajectory

    Raises
    ------
    DegenerateError
        ``rank(QΘ) < 3K``: too few observations for ``K``, a still camera, or a camera
        moving like the point (Theorem 2) — the message says which.
    ValueError
        Bad shapes, NaN in cameras, non-finite times, all observations missing, bad options.
    """
    x_ = as_float_array(x, "x", (len(cameras), 2), allow_nan=True)
    r = _run(
        x_[None],
        cameras,
        k,
        folds,
        k_max,
        refine,
        k_min,
        cv_rule,
        max_iterations,
        keep_covariance=True,
        strict=True,
    )
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
        observed=int(r["observed"][0]),
        cv_error=readonly(cv[~np.isnan(cv)].copy()),
        covariance=None if r["covariance"][0] is None else readonly(r["covariance"][0]),
        span=tuple(float(v) for v in r["span"]),  # type: ignore[arg-type]
    )


def reconstruct_trajectories(
    x: npt.ArrayLike,
    cameras: Cameras,
    k: int | Literal["auto"] = "auto",
    folds: int = 5,
    k_max: int | None = None,
    refine: bool = True,
    *,
    k_min: int = 1,
    cv_rule: Literal["min", "1se"] = "min",
    max_iterations: int = 100,
) -> TrajectoryBatch:
    """Reconstructs ``N`` moving points that share the cameras, each with its own missing
    pattern and its own ``K``; in parallel over points.

    Parameters are those of :func:`reconstruct_trajectory`, with ``x`` of shape
    ``(N, F, 2)``. A point that cannot be reconstructed (degenerate, all missing) does not
    stop the batch: its rows are NaN and ``failures[i]`` says why.

    Returns
    -------
    TrajectoryBatch
    """
    f = len(cameras) if isinstance(cameras, Cameras) else None
    x_ = as_float_array(x, "x", (None, f, 2), allow_nan=True)
    r = _run(
        x_,
        cameras,
        k,
        folds,
        k_max,
        refine,
        k_min,
        cv_rule,
        max_iterations,
        keep_covariance=False,
        strict=False,
    )
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
        observed=readonly(r["observed"]),
        cv_error=readonly(r["cv_error"]),
        failures=list(r["failures"]),
        span=tuple(float(v) for v in r["span"]),  # type: ignore[arg-type]
    )


def reconstructability(
    points_true: npt.ArrayLike,
    camera_centres: npt.ArrayLike,
    k: int,
    times: npt.ArrayLike | None = None,
) -> float:
    """Reconstructability η (Eq 5.16): ``‖Θ^⊥β_C^⊥‖ / ‖Θ^⊥β_X^⊥‖``, how poorly ``k`` DCT
    functions describe the camera trajectory relative to the point trajectory. Large η
    means an accurate reconstruction (Theorem 3); an analysis tool, as it needs the truth.

    Parameters
    ----------
    points_true : array_like, shape (F, 3)
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
    p = as_float_array(points_true, "points_true", (None, 3))
    c = as_float_array(camera_centres, "camera_centres", (None, 3))
    t = None if times is None else as_float_array(times, "times", (None,))
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise ValueError(f"k: expected a positive integer, got {k!r}")
    return float(_core.reconstructability(p, c, int(k), t))


def null_residual(trajectory: npt.ArrayLike, k: int, times: npt.ArrayLike | None = None) -> float:
    """``‖Θ^⊥ β^⊥‖``: the part of a trajectory ``(F, 3)`` that ``k`` DCT functions cannot
    describe (``e_X`` or ``e_C`` of Sec 5.2.2), in metres."""
    p = as_float_array(trajectory, "trajectory", (None, 3))
    t = None if times is None else as_float_array(times, "times", (None,))
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise ValueError(f"k: expected a positive integer, got {k!r}")
    return float(_core.null_residual(p, int(k), t))
