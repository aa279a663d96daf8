"""Type stubs for the Rust extension ``socialcam._core`` (hand-written; checked in CI by
``mypy.stubtest``). Use the public wrappers in :mod:`socialcam`; these are their kernels.

Array conventions: float64, row-major; cameras as ``K (F,3,3)``, ``R (F,3,3)``
world→camera, ``C (F,3)`` centres in metres; NaN pixel rows mean "not observed".
"""

from typing import Any, TypeAlias

import numpy as np
import numpy.typing as npt

_F64: TypeAlias = npt.NDArray[np.float64]

__version__: str

class DegenerateError(ValueError):
    """Well-formed input that is geometrically degenerate."""

class ConvergenceError(RuntimeError):
    """An iterative solver reached its cap without converging."""

def validate_cameras(k: _F64, r: _F64, c: _F64) -> None:
    """Raises ``ValueError`` naming the first invalid frame of ``K``, ``R`` or ``C``."""

def projection_matrices(k: _F64, r: _F64, c: _F64) -> _F64:
    """``(F,3,4)`` matrices ``K R [I | -C]``."""

def project(k: _F64, r: _F64, c: _F64, x: _F64) -> tuple[_F64, _F64]:
    """Pixels ``(F,N,2)`` and depths ``(F,N)`` of points ``x (N,3)`` in every camera."""

def back_project(k: _F64, r: _F64, c: _F64, x: _F64) -> _F64:
    """Unit world ray directions ``(F,N,3)`` through pixels ``x (F,N,2)``."""

def triangulate(
    k: _F64, r: _F64, c: _F64, x: _F64, refine: bool = True, max_iterations: int = 50
) -> tuple[
    _F64,
    _F64,
    _F64,
    npt.NDArray[np.int64],
    npt.NDArray[np.bool_],
    list[str | None],
]:
    """Batched DLT + Levenberg–Marquardt of ``x (N,V,2)``: points ``(N,3)`` (NaN where it
    failed), RMS px after and before refinement ``(N,)``, views ``(N,)``, converged ``(N,)``
    and the failure reason per point."""

def dct_basis(times: _F64, k: int, t0: float | None = None, t1: float | None = None) -> _F64:
    """``(F,k)`` orthonormal DCT-II trajectory basis at ``times (F,)``."""

def align_similarity(src: _F64, dst: _F64) -> tuple[float, _F64, _F64]:
    """Umeyama ``dst ≈ s R src + t`` → ``(s, R (3,3), t (3,))``."""

def ray_sphere(origins: _F64, directions: _F64, centres: _F64, radii: _F64) -> tuple[_F64, _F64]:
    """Roots ``s (N,2)`` (NaN on a miss) and miss distances ``(N,)`` (Eq 4.8–4.9)."""

def perspective_distance(p: _F64, v: _F64, x: _F64) -> _F64:
    """Eq 6.2 vectors ``(N,3)``; ``inf`` rows behind the eye."""

# --- binary quadratic programming and articulated motion (Chapter 4) ---

def solve_bqp(
    q: _F64, c: _F64 | None = None, time_limit: float | None = None, node_limit: int | None = None
) -> tuple[npt.NDArray[np.bool_], float, float, float, int, bool]:
    """Exact ``min bᵀQb + cᵀb`` over ``{0,1}ⁿ``: ``(x (n,), objective, bound, gap, nodes,
    optimal)``."""

def reconstruct_articulated(
    k_mat: _F64,
    r_mat: _F64,
    c_mat: _F64,
    x: _F64,
    parent: _F64,
    times: _F64,
    length: float,
    k: int,
    refine: bool = True,
    time_limit: float | None = None,
    node_limit: int | None = None,
    fit_radius: bool = False,
) -> dict[str, Any]:
    """One articulated trajectory from ``x (F,2)`` (NaN = missing) and ``parent (F,3)``: a
    dict with ``X (F,3)``, ``radius``, ``coeffs_theta``/``coeffs_phi (K,)``, ``bqp_size``,
    ``bqp_objective``, ``bqp_gap``, ``bqp_nodes``, ``bqp_optimal``, ``n_observed``,
    ``reprojection_rms``, ``lm_iterations``, ``converged``."""

def reconstruct_skeleton(
    k_mat: _F64,
    r_mat: _F64,
    c_mat: _F64,
    x: _F64,
    parents: list[int],
    lengths: list[float],
    root: _F64,
    times: _F64,
    k: int,
    refine: bool = True,
    time_limit: float | None = None,
    node_limit: int | None = None,
    fit_radius: bool = False,
) -> tuple[_F64, list[dict[str, Any] | None]]:
    """Whole skeleton from ``x (F,J,2)`` and ``root (F,3)``: ``X (F,J,3)`` and one dict per
    joint as in :func:`reconstruct_articulated` (``None`` for the root)."""

def skeleton_order(parents: list[int], lengths: list[float]) -> list[int]:
    """Validates a tree (``-1`` = root) and returns a parents-first joint order."""

def articulated_reconstructability(
    k_mat: _F64, r_mat: _F64, c_mat: _F64, parent: _F64, child: _F64, times: _F64, k: int
) -> float:
    """η_a of Eq 4.13 for a known child trajectory ``(F,3)``."""

def articulated_bqp(
    k_mat: _F64,
    r_mat: _F64,
    c_mat: _F64,
    x: _F64,
    parent: _F64,
    times: _F64,
    length: float,
    k: int,
    fit_radius: bool = False,
) -> tuple[_F64, _F64, float]:
    """``(Q (n,n), c (n,), constant)`` of Eq 4.12."""
