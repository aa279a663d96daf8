"""Type stubs for the Rust extension ``socialcam._core`` (hand-written; checked in CI by
``mypy.stubtest``). Use the public wrappers in :mod:`socialcam`; these are their kernels.

Sizes: an output larger than 2 GiB is refused with ``ValueError`` naming the argument.
Long calls run with the GIL released and stop on Ctrl-C (``KeyboardInterrupt``).

Array conventions: float64, row-major; cameras as ``K (F,3,3)``, ``R (F,3,3)``
world→camera, ``C (F,3)`` centres in metres; NaN pixel rows mean "not observed".
"""

from typing import Any, TypeAlias

import numpy as np
import numpy.typing as npt

from socialcam.charges import ChargeOptions
from socialcam.gazefield import GazeFieldOptions
from socialcam.trajectory import TrajectoryOptions

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
    k: _F64, r: _F64, c: _F64, x: _F64, refine: bool = True, max_iter: int = 50
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

# --- trajectory reconstruction (thesis Chapter 5) ---------------------------------------
def reconstruct_trajectories(
    k_intr: _F64,
    r: _F64,
    c: _F64,
    times: _F64,
    x: _F64,
    options: TrajectoryOptions,
    keep_covariance: bool = False,
    strict: bool = False,
) -> dict[str, Any]:
    """Trajectories of ``x (N,F,2)`` from cameras with capture ``times (F,)`` with the
    options of a :class:`socialcam.trajectory.TrajectoryOptions` (``k="auto"`` chooses K per
    point by cross validation, Eq 5.8). A dict of arrays: ``points (N,F,3)``,
    ``std (N,F,3)``, ``coeffs (N,Kmax,3)``, ``cv_error (N,Kcv)``, ``k``, ``rms``,
    ``rms_linear``, ``converged``, ``iterations``, ``rank``, ``cond``, ``sigma``,
    ``n_observed`` ``(N,)``, ``covariance`` (list of ``(3k,3k)`` or ``None``), ``failures``
    (list of ``str | None``) and ``span (t0, t1, n_norm)``. ``strict=True`` raises the first
    failure."""

def reconstructability(points: _F64, centres: _F64, k: int, times: _F64 | None = None) -> float:
    """η of Eq 5.16 for a true trajectory ``(F,3)`` and camera centres ``(F,3)``."""

def null_residual(trajectory: _F64, k: int, times: _F64 | None = None) -> float:
    """``‖Θ^⊥ β^⊥‖`` of a trajectory ``(F,3)`` with ``k`` DCT functions."""

# --- social saliency and social charges (issue 5, thesis Chapter 6) ---

def saliency_field(p: _F64, v: _F64, h: _F64, points: _F64) -> _F64:
    """Social saliency (Eq 6.4) of rays ``p (N,3)``, unit ``v (N,3)``, ``h (N,)`` at
    ``points (M,3)`` → ``(M,)``."""

def saliency_grid(
    p: _F64,
    v: _F64,
    h: _F64,
    lo: tuple[float, float, float],
    hi: tuple[float, float, float],
    shape: tuple[int, int, int],
) -> _F64:
    """The field on the inclusive grid ``lo..hi`` with ``shape`` samples → ``shape`` array."""

def find_charges(
    p: _F64,
    v: _F64,
    h: _F64,
    offsets: npt.NDArray[np.int64],
    seed: int,
    options: ChargeOptions,
    ids: npt.NDArray[np.int64] | None = None,
) -> tuple[
    npt.NDArray[np.int64],
    _F64,
    _F64,
    npt.NDArray[np.int64],
    npt.NDArray[np.int64],
    npt.NDArray[np.int64],
    _F64,
    _F64,
    _F64,
    _F64,
]:
    """Mode seeking (Eq 6.5–6.8) on the frames ``offsets (F+1,)`` of stacked rays →
    ``frame (C,)``, ``position (C,3)``, ``magnitude (C,)``, ``support (C,)``, flat
    ``members`` with ``member_offsets (C+1,)``, flat ``membership``, ``region_centre
    (C,3)``, ``region_axes (C,3,3)``, ``region_radii (C,3)``. ``ids (T,)`` person ids of
    the rays (default: the row within the frame) follow people across frames."""

def diagnose_window(
    p: _F64,
    v: _F64,
    h: _F64,
    offsets: npt.NDArray[np.int64],
    seed: int,
    options: ChargeOptions,
    truth: npt.NDArray[np.int64],
    ids: npt.NDArray[np.int64] | None = None,
) -> tuple[float, float, float]:
    """The joint window's objective of the assignment ``find_charges`` finds on the frames
    ``offsets``, of the true groups ``truth (T,)`` (each ray's group, -1 for none) with
    their positions fitted, and of the search started from them (a bench's debug path)."""

def track_charges(
    features: _F64,
    frames: npt.NDArray[np.int64],
    bandwidth: float = 0.3,
    max_iter: int = 300,
    bin_seeding: bool = True,
    max_gap: int = 5,
    min_length: int = 10,
) -> tuple[npt.NDArray[np.int64], _F64]:
    """Mean-shift tracking of membership features ``(n,J)`` → track ids ``(n,)`` (−1 =
    dropped: a duplicate in its frame, or in a run shorter than ``min_length`` frames, runs
    being split by gaps of more than ``max_gap`` frames) and centres ``(K,J)`` (Sec 6.1.3)."""

# ---- issue 6: gaze field (thesis Chapter 7). Rays flat: p (N,3), v (N,3), members (N,)
# dense int64 in 0..J, offsets (F+1,) int64; windows (W,3) int64 [start, end, n_charges];
# a field as positions (F,I,3) NaN-padded, magnitudes (F,I), kappa (F,) (NaN = no field).

def gaze_split_windows(counts: npt.NDArray[np.int64], min_len: int) -> npt.NDArray[np.int64]:
    """Windows ``(W,3)`` of constant charge count (Sec 7.3.1); runs shorter than
    ``min_len`` frames are absorbed into a neighbour."""

def gaze_init(
    p: _F64,
    v: _F64,
    offsets: npt.NDArray[np.int64],
    windows: npt.NDArray[np.int64],
    sigma: float,
    candidates: _F64 | None = None,
) -> _F64:
    """Initial charge tracks ``(F,I,3)`` (NaN-padded) from ``candidates (F,C,3)`` or from
    pairwise ray intersections scored with bandwidth ``sigma``."""

def gaze_em(
    p: _F64,
    v: _F64,
    members: npt.NDArray[np.int64],
    offsets: npt.NDArray[np.int64],
    windows: npt.NDArray[np.int64],
    init: _F64,
    options: GazeFieldOptions,
) -> tuple[
    _F64,
    _F64,
    _F64,
    _F64,
    _F64,
    _F64,
    npt.NDArray[np.int64],
    npt.NDArray[np.bool_],
]:
    """Time-windowed EM (Eq 7.10–7.14) with the EM fields of a
    :class:`socialcam.gazefield.GazeFieldOptions`: positions ``(F,I,3)``, magnitudes
    ``(F,I)``, κ ``(W,)``, memberships ``(W,J,I)``, responsibilities ``(N,I)``,
    log-likelihood ``(W,)``, iterations ``(W,)``, converged ``(W,)``."""

def gaze_predict(
    positions: _F64,
    magnitudes: _F64,
    kappa: _F64,
    frame: npt.NDArray[np.int64],
    points: _F64,
) -> _F64:
    """Most likely directions ``(M,3)`` (Eq 7.3); NaN rows where undefined."""

def gaze_log_density(
    positions: _F64,
    magnitudes: _F64,
    kappa: _F64,
    frame: npt.NDArray[np.int64],
    p: _F64,
    v: _F64,
) -> _F64:
    """``ln p(v | p)`` ``(M,)`` (Eq 7.7); NaN where the frame has no field."""

def gaze_angle_to_charges(
    positions: _F64,
    magnitudes: _F64,
    kappa: _F64,
    frame: npt.NDArray[np.int64],
    p: _F64,
    v: _F64,
    self_radius: float,
) -> _F64:
    """Radians from ``v`` to the closest charge direction ``(M,)``; NaN where none."""

# --- binary quadratic programming and articulated motion (Chapter 4) ---

def solve_bqp(
    q: _F64, c: _F64 | None, options: Any
) -> tuple[npt.NDArray[np.bool_], float, float, float, int, bool, float]:
    """Exact ``min bᵀQb + cᵀb`` over ``{0,1}ⁿ`` with a ``socialcam.BqpOptions``:
    ``(x (n,), objective, bound, gap, nodes, optimal, root_bound)``."""

def reconstruct_articulated(
    k_mat: _F64,
    r_mat: _F64,
    c_mat: _F64,
    x: _F64,
    parent: _F64,
    times: _F64,
    length: float,
    options: Any,
    children: list[tuple[_F64, float]] = ...,
    angle_priors: list[tuple[_F64, float, float]] = ...,
) -> dict[str, Any]:
    """One articulated trajectory from ``x (F,2)`` (NaN = missing) and ``parent (F,3)``;
    ``options`` is an ``ArticulatedOptions`` (its fields are read); ``children``: the
    joint's children as ``(x_c (F,2), bone length)``; ``angle_priors``: priors on the
    joint's bone as ``(reference bones (F,3), lo, hi)``, radians. A dict with ``X (F,3)``,
    ``radius``, ``bqp_radius``, ``coeffs_theta``/``coeffs_phi (K,)``, ``bqp_size``,
    ``bqp_objective``, ``bqp_gap``, ``bqp_nodes``, ``bqp_optimal``, ``n_observed``,
    ``reprojection_rms``, ``lm_iterations``, ``converged``, ``selection_margin``,
    ``alternative`` ``(F,3)`` or ``None``."""

def reconstruct_skeleton(
    k_mat: _F64,
    r_mat: _F64,
    c_mat: _F64,
    x: _F64,
    parents: list[int],
    lengths: list[float],
    root: _F64,
    times: _F64,
    options: Any,
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

# --- ego-motion gaze calibration (thesis Sec 3.2.1, Eq 3.1) ---------------------------

def calibrate_gaze(
    r: npt.NDArray[np.float64],
    c: npt.NDArray[np.float64],
    lambda_c: float,
    lambda_axis: float,
    max_iter: int,
    tol: float,
) -> dict[str, Any]:
    """Eq 3.1 on one fixation segment: ``R (F,3,3)`` world→camera, ``C (F,3)`` centres →
    dict of ``p, v, y (3,)``, ``h``, ``p_std, y_std (3,)``, ``v_std``, ``h_rel_std``,
    ``residuals (F,)``, ``iterations``, ``converged``."""

def gaze_rays(
    r: npt.NDArray[np.float64],
    c: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    v: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """World rays ``p_i = R_iᵀ p + C_i``, ``v_i = R_iᵀ v`` → ``(p (F,3), v (F,3))``."""

# --- 3D faces (thesis Sec 3.2.2, Eq 3.2–3.4) ------------------------------------------

def face_associate(
    k: npt.NDArray[np.float64],
    r: npt.NDArray[np.float64],
    c: npt.NDArray[np.float64],
    instant: npt.NDArray[np.int64],
    slot: npt.NDArray[np.int64],
    landmarks: npt.NDArray[np.float64],
    size: npt.NDArray[np.float64],
    anchor_centre: npt.NDArray[np.float64],
    anchor_slot: npt.NDArray[np.int64],
    anchor_instant: npt.NDArray[np.int64],
    anchor_gate: npt.NDArray[np.float64],
    rel_threshold: float,
    min_threshold: float,
    interocular_min: float,
    interocular_max: float,
    shape_min: float = 0.5,
    shape_max: float = 1.6,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Eq 3.2 over instants: camera slots ``K, R (M,3,3)``, ``C (M,3)`` with their
    ``instant (M,)``; detections ``slot (N,)``, ``landmarks (N,5,2)``, ``size (N,)``; anchors
    ``(A,3)`` (wearers' head cameras with their own ``anchor_slot``, or tracked faces with
    slot −1) at ``anchor_instant (A,)`` with ``anchor_gate (A,)`` metres → ``group (N,)``,
    ``group_anchor (G,)``, ``group_instant (G,)`` (−1 = none). ``shape_min``/``shape_max``:
    plausible eyes-to-mouth distances over the interocular one, for RANSAC hypotheses and
    for the detections a tracked face keeps."""

def face_triangulate(
    k: npt.NDArray[np.float64],
    r: npt.NDArray[np.float64],
    c: npt.NDArray[np.float64],
    slot: npt.NDArray[np.int64],
    landmarks: npt.NDArray[np.float64],
    sigma: npt.NDArray[np.float64],
    group: npt.NDArray[np.int64],
) -> tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.int64],
]:
    """Eq 3.3 per group → ``x (G,5,3)``, ``std (G,5)`` m, ``rms (G,)`` px, ``views (G,)``."""

def face_refine_track(
    k: npt.NDArray[np.float64],
    r: npt.NDArray[np.float64],
    c: npt.NDArray[np.float64],
    step: npt.NDArray[np.int64],
    slot: npt.NDArray[np.int64],
    landmarks: npt.NDArray[np.float64],
    sigma: npt.NDArray[np.float64],
    x0: npt.NDArray[np.float64],
    lam: float,
    iterations: int,
    lam_shape: float | None = None,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Eq 3.4 over one track of ``T`` instants → ``x (T,5,3)``, ``std (T,5)``; ``lam``
    weighs the motion of the face's centre, ``lam_shape`` (default ``lam``) its turning."""

def face_gaze(
    x: npt.NDArray[np.float64], std: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Primary gaze rays of faces ``(G,5,3)`` → ``p (G,3)``, ``v (G,3)``, ``sigma (G,)``."""
