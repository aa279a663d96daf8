"""Articulated body motion via binary quadratic programming (thesis Chapter 4).

A child joint stays at a fixed distance from its parent. From one camera per frame, each
observation leaves two candidate 3D points (ray–sphere intersections, Eq 4.8–4.9); choosing
one per frame so that the trajectory is smooth in a DCT basis is a binary quadratic program
(Eq 4.10–4.12), solved exactly by branch-and-bound in the Rust core, then refined by
Levenberg–Marquardt on the reprojection error (Eq 4.5). Skeletons are reconstructed from
the root outwards (Eq 4.6).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from socialcam import _core
from socialcam._validate import (
    FloatArray,
    as_float_array,
    check_bool,
    check_choice,
    check_float,
    check_int,
    check_rounding,
    readonly,
)
from socialcam.camera import Cameras

__all__ = [
    "ArticulatedOptions",
    "ArticulatedTrajectory",
    "BqpOptions",
    "BqpResult",
    "Skeleton",
    "SkeletonReconstruction",
    "articulated_bqp",
    "articulated_reconstructability",
    "bone_angles",
    "learn_angle_ranges",
    "reconstruct_articulated",
    "reconstruct_skeleton",
    "solve_bqp",
]


#: Default branch-and-bound node cap of the reconstruction functions: a safety net (a few
#: seconds at n = 100 frames; programs from real mocap needed at most ~1,300 nodes).
DEFAULT_NODE_LIMIT = 100_000


#: Longest accepted ``time_limit`` in seconds (about 31 years).
MAX_TIME_LIMIT = 1e9


@dataclass(frozen=True)
class BqpOptions:
    """Limits and search settings of :func:`solve_bqp`.

    Attributes
    ----------
    time_limit : seconds of wall clock for the whole solve (root work included), in
        ``(0, 1e9]``, or None for no limit. On expiry the best incumbent is returned with a
        finite ``bound`` and ``optimal=False``.
    node_limit : maximum number of branch-and-bound nodes (≥ 0), or None.
    parallel : run the dives of each round of the tree search on all cores (rayon). The
        rounds are merged in a fixed order, so the answer and the node count are the same
        with one thread or many.
    batch : open nodes expanded per round (best bounds first), each starting a dive, ≥ 1.
    dive_depth : nodes per dive (a node, then its nearer child, …), ≥ 1.
    """

    time_limit: float | None = None
    node_limit: int | None = None
    parallel: bool = True
    batch: int = 4
    dive_depth: int = 16

    def __post_init__(self) -> None:
        if self.time_limit is not None:
            t = check_float(
                self.time_limit, "time_limit", min=0.0, min_exclusive=True, max=MAX_TIME_LIMIT
            )
            object.__setattr__(self, "time_limit", t)
        if self.node_limit is not None:
            object.__setattr__(self, "node_limit", check_int(self.node_limit, "node_limit", min=0))
        if not isinstance(self.parallel, (bool, np.bool_)):
            raise ValueError(f"parallel: expected a bool, got {self.parallel!r}")
        object.__setattr__(self, "parallel", bool(self.parallel))
        object.__setattr__(self, "batch", check_int(self.batch, "batch", min=1, max=1 << 20))
        object.__setattr__(
            self, "dive_depth", check_int(self.dive_depth, "dive_depth", min=1, max=1 << 20)
        )


@dataclass(frozen=True, eq=False)
class BqpResult:
    """Outcome of :func:`solve_bqp`.

    Attributes
    ----------
    x : (n,) bool, read-only, the best binary point found.
    objective : ``xᵀQx + cᵀx``.
    bound : proven lower bound on the minimum (equals ``objective`` when optimal; always
        finite, also when a limit stopped the solve).
    gap : relative gap ``(objective − bound) / max(|objective|, |bound|)``.
    nodes : branch-and-bound nodes processed.
    optimal : whether optimality was proven (no limit was hit).
    root_bound : bound proven at the root before branching (the semidefinite/QCR bound).
    """

    x: npt.NDArray[np.bool_]
    objective: float
    bound: float
    gap: float
    nodes: int
    optimal: bool
    root_bound: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "x": self.x.astype(int).tolist(),
            "objective": self.objective,
            "bound": self.bound,
            "gap": self.gap,
            "nodes": self.nodes,
            "optimal": self.optimal,
            "root_bound": self.root_bound,
        }


def solve_bqp(
    Q: npt.ArrayLike,
    c: npt.ArrayLike | None = None,
    *,
    options: BqpOptions | None = None,
    **overrides: Any,
) -> BqpResult:
    """Minimise ``bᵀQb + cᵀb`` over ``b ∈ {0,1}ⁿ`` exactly (branch-and-bound, Eq 4.12).

    The bound is the quadratic convex reformulation of the semidefinite relaxation (a
    diagonal shift ``b_i² = b_i`` that makes the problem convex, chosen by a low-rank SDP
    solve at the root); every node solves its box-constrained convex relaxation. A
    maximisation ``max bᵀSb`` (Beasley's OR-Library convention) is ``Q = −S``.

    Parameters
    ----------
    Q : (n, n) symmetric float array, any sign pattern.
    c : (n,) linear term, zero when omitted.
    options : :class:`BqpOptions`; ``overrides`` are its field names (e.g.
        ``time_limit=1.0``) applied on top.

    Raises
    ------
    ValueError
        ``Q`` not square, not symmetric, or not finite; ``c`` of the wrong length; a bad
        option (the message names it), or an unknown option name.
    KeyboardInterrupt
        Ctrl-C during the solve (it stops within a fraction of a second).
    """
    opts = options if options is not None else BqpOptions()
    if not isinstance(opts, BqpOptions):
        raise ValueError(f"options: expected a BqpOptions, got {type(opts).__name__}")
    if overrides:
        known = {f.name for f in fields(BqpOptions)}
        for name in overrides:
            if name not in known:
                raise ValueError(f"{name}: not an option of solve_bqp ({', '.join(sorted(known))})")
        opts = replace(opts, **overrides)
    Q_ = as_float_array(Q, "Q", (None, None))
    n = Q_.shape[0]
    if Q_.shape[1] != n:
        raise ValueError(f"Q: must be square, got shape {Q_.shape}")
    c_ = None if c is None else as_float_array(c, "c", (n,))
    with np.errstate(over="ignore"):  # |objective| ≤ Σ|Q| + Σ|c| over every x
        largest = np.abs(Q_).sum() + (0.0 if c_ is None else np.abs(c_).sum())
    if not np.isfinite(largest):
        raise ValueError(
            "Q, c: entries so large that the objective overflows float64 (Σ|Q| + Σ|c| is "
            "infinite): scale the problem down"
        )
    x, obj, bound, gap, nodes, optimal, root = _core.solve_bqp(Q_, c_, opts)
    return BqpResult(readonly(np.asarray(x, dtype=bool)), obj, bound, gap, nodes, optimal, root)


@dataclass(frozen=True, eq=False)
class ArticulatedTrajectory:
    """One reconstructed articulated trajectory.

    Attributes
    ----------
    points : (F, 3) child positions in metres, every frame (missing frames imputed).
    times : (F,) seconds.
    radius : bone length of the result: the given one enlarged so that every ray meets the
        sphere (Sec 4.4.1), then refined within ``length_tol`` by the robust method.
    bqp_radius : radius of the sphere whose binary program (Eq 4.12) gave the result.
    coeffs_theta, coeffs_phi : (K',) DCT coefficients of the spherical angles (radians);
        ``K' = k`` except where the robust method grew the basis (``refine_k_max``).
    bqp_size, bqp_nodes, bqp_optimal, bqp_gap : the binary program of Eq 4.12.
    n_observed : frames with an observation.
    rms : reprojection RMS in pixels, over the observed frames.
    converged : the refinement met its tolerance.
    selection_margin : how clearly the robust method's start selection preferred the result
        over the best start lying in another basin (farther than a tenth of the bone from it,
        RMS over the frames: mostly the other root of the rays over part of the window), in
        the selection score's units (a reprojection cost one standard deviation higher counts
        1; see ``smooth_weight``); ``inf`` when no start lies in another basin, and for the
        thesis method. A small margin says the pixels and priors hardly told the two apart;
        a large one is no guarantee (a model the motion breaks can be confidently wrong). On
        the CMU windows of ``benches/articulated_accuracy.py`` at exact length and root
        (3 seeds), a margin below 0.25 marked 5 % of the joints of three window sets and 22
        of their 101 whose error was above a tenth of the bone (6 of the 499 below 0.05),
        the alternative then holding the truth (within 0.1) for 13 of the 22; on two other
        sets it marked 1 %, 2 of 62 and 3 of 519. Under Fig 4.3(c) (1 px noise, root 5 % and
        length 5 % off) it marked 5 % and 2.5 % of the joints, of which 33 of 36 and 13 of 18
        erred above 0.1.
    alternative : (F, 3) that start's trajectory in metres (at the selection's basis size
        ``k``, before the basis grows), or ``None``. Where other evidence is at hand (a
        second camera, contact with the ground), it may pick this one instead.
    """

    points: FloatArray
    times: FloatArray
    radius: float
    bqp_radius: float
    coeffs_theta: FloatArray
    coeffs_phi: FloatArray
    bqp_size: int
    bqp_nodes: int
    bqp_optimal: bool
    bqp_gap: float
    n_observed: int
    rms: float
    converged: bool
    selection_margin: float = float("inf")
    alternative: FloatArray | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()
        }


def _traj(d: dict[str, Any], times: FloatArray) -> ArticulatedTrajectory:
    X = np.asarray(d["X"])
    if not (np.isfinite(X).all() and np.isfinite(d["reprojection_rms"])):
        raise ValueError(
            "x, parent, length: the reconstruction overflowed float64 (points or reprojection "
            "error not finite); pixels, positions and the bone length must be of a size a "
            "camera can see (pixels near the image, metres near the scene)"
        )
    return ArticulatedTrajectory(
        points=readonly(d["X"]),
        times=readonly(times),
        radius=float(d["radius"]),
        bqp_radius=float(d["bqp_radius"]),
        coeffs_theta=readonly(d["coeffs_theta"]),
        coeffs_phi=readonly(d["coeffs_phi"]),
        bqp_size=int(d["bqp_size"]),
        bqp_nodes=int(d["bqp_nodes"]),
        bqp_optimal=bool(d["bqp_optimal"]),
        bqp_gap=float(d["bqp_gap"]),
        n_observed=int(d["n_observed"]),
        rms=float(d["reprojection_rms"]),
        converged=bool(d["converged"]),
        selection_margin=float(d["selection_margin"]),
        alternative=None if d["alternative"] is None else readonly(d["alternative"]),
    )


def _check_cameras(cameras: object) -> Cameras:
    if not isinstance(cameras, Cameras):
        raise ValueError(f"cameras: expected a socialcam.Cameras, got {type(cameras).__name__}")
    return cameras


def _check_scale(parent: FloatArray, cameras: Cameras, length: float, name: str) -> None:
    """Refuses coordinates so far from the origin that float64's rounding of them is a
    noticeable part of the bone ``length``: the rays' intersections with the sphere about
    the parent are then lost in the rounding (a scene shifted by 1e15 m for a 0.3 m bone
    gave 35 px of reprojection error and no error message)."""
    both = np.concatenate([parent.reshape(-1, 3), cameras.C.reshape(-1, 3)])
    check_rounding(both, f"{name}, cameras", "the bone (is its length in metres?)", length)


def _times(cameras: Cameras) -> FloatArray:
    t = cameras.times
    return np.arange(len(cameras), dtype=np.float64) if t is None else np.asarray(t)


_METHODS = ("robust", "thesis")


@dataclass(frozen=True)
class ArticulatedOptions:
    """Options of :func:`reconstruct_articulated` and :func:`reconstruct_skeleton`.

    Attributes
    ----------
    k : number of DCT basis vectors per spherical angle (``Θ`` of Eq 4.4), ≥ 1.
    refine : run the Levenberg–Marquardt refinement of the reprojection error (Eq 4.5).
    method : ``"robust"`` (default) or ``"thesis"``. The thesis solves the binary program
        of Eq 4.12 on the sphere of the given length (enlarged until every ray meets it,
        Sec 4.4.1) and refines with that length fixed. A length or a parent only a few
        percent off then separates the two ray–sphere roots where the true bone crosses
        the viewing ray at right angles, so the smooth solution cannot pass from one root
        to the other and follows the impostor. ``"robust"`` also solves the program on a
        sphere shrunk to the ``tangent_quantile`` of the parent-to-ray distances (the
        near-grazing rays then touch it once, both roots' evidence merged), refines each
        start with the bone length free within ``length_tol``, and keeps the start that
        best trades reprojection error against smoothness (``smooth_weight``) and least
        motion (``motion_weight``), or averages the starts by that score
        (``average_starts``).
    fit_radius : set the thesis sphere to the largest parent-to-ray distance instead of
        only enlarging the given length when a ray misses.
    tangent_quantile : robust method: quantile in [0, 1] of the parent-to-ray distances
        giving the shrunk sphere's radius (never above the thesis radius).
    length_tol : robust method: the bone length is refined within ``[r/(1+tol), r(1+tol)]``
        around the thesis radius ``r``, with a Gaussian prior of relative deviation ``tol``
        (a deviation of ``tol`` costs 0.3 px of reprojection error per observation);
        ≥ 0, 0 keeps it fixed.
    grazing_separation : robust method: where, at a local minimum in time, the two roots'
        unit directions are closer than this (in [0, 2]; 1.0 ≈ the bone within 30° of
        perpendicular to the ray), the true trajectory may cross to the other root or
        touch and come back: both are refined and the lower reprojection error kept.
    flip_rounds : robust method: rounds of the greedy search over those passes (≥ 0; each
        round keeps the single pass that lowers the reprojection error most).
    smooth_weight : robust method: how much smoothness counts against the pixels when
        choosing among the refined starts (both spheres, every pass tried); ≥ 0. Each start
        scores its reprojection cost above the lowest, in standard deviations of that cost
        (a χ² at the noise level estimated from the lowest), plus ``smooth_weight × log₁₀``
        of its roughness (the objective of Eq 4.12 on its refined unit directions); the
        lowest score wins. So a start ten times smoother may fit the pixels worse by up to
        ``smooth_weight`` standard deviations — on real motion the impostor often fits them
        slightly better. 0 (with ``motion_weight`` 0) keeps the lowest cost.
    motion_weight : robust method: least-motion evidence in the same score, ``motion_weight
        × log₁₀`` of the angular variance ``Σ_t ‖u_t − ū‖²`` of the start's unit bone
        direction over the window (every frame); ≥ 0. The wrong starts that fit the pixels
        and Eq 4.12 as well as the truth are mostly slow swings of the bone away from it,
        towards the impostor side: a start that moves ten times less may fit the pixels
        worse by up to ``motion_weight`` standard deviations. 0 leaves the selection to
        ``smooth_weight``.
    refine_k_max : robust method: largest DCT basis size of the final refinement. The ``k``
        of the binary program and of the start selection is a prior on smoothness that
        some motion (a subject starting to walk, an arm swinging up) exceeds; the selected
        start is refined again with ``k + 1, …, refine_k_max`` vectors per angle and the
        size with the lowest Bayesian information criterion on the reprojection error is
        kept (sizes above half the observed frames are not tried). ``≤ k`` keeps ``k``
        (session 6's method). The result's coefficients have the kept size. The default
        32 (16 until session 17) lets windows spanning 2-3 s of walking grow past 16.
    child_slack : robust method, when the joint's children are given (``children`` of
        :func:`reconstruct_articulated`; :func:`reconstruct_skeleton` always gives them):
        each child must lie on its own viewing ray within ``(1 + child_slack)`` times its
        bone length of the joint; ≥ 0. A start whose joint lies farther from a child's ray
        pays the child's reprojection error of that frame (the excess distance in pixels at
        the joint's depth, squared) in the selection score. On the impostor side of its ray
        the joint is often out of its children's reach, which its own pixels cannot show.
    length_weight : robust method: weight of the refined bone length in the same score,
        ``length_weight × ln(r / r_min)`` (``r_min`` the shortest refined length among the
        starts); ≥ 0. Where a ray grazes the sphere, the wrong branch can follow the far root
        and still fit the pixels by lengthening the bone within ``length_tol``: of two starts
        that explain the pixels alike, the shorter bone is preferred (at 20, a 5 % longer
        bone must fit better by about one standard deviation). Off (0) by default: on the
        bench's CMU windows (Fig 4.3(c)) 20 lowers the mean error on six of eight window
        sets (e.g. 0.200 → 0.184 on the starting/stopping clips) but raises it on the
        standing clips and, at exact length and root, doubles their heavy tail.
    average_starts : robust method: return the average of the refined starts, weighted by
        ``exp(−2 Δscore)`` (Δscore: a start's selection score above the best one's; the
        score of ``smooth_weight``), instead of the best start alone. Under root and length
        error the starts near grazing rays form a family along the rays that neither the
        pixels, Eq 4.12 nor the least motion separate, and the best score is as often the
        farther member as the nearer; the average lowers the expected error. Each distinct
        solution counts once, and nothing is averaged where the final refinement grew the
        basis (``refine_k_max``). The result's coefficients, ``radius`` and ``bqp_radius``
        are the best start's; ``rms`` is that of the returned points. Off by default: on
        the bench's CMU windows it lowers the Fig 4.3(c) mean error by 2–5 % and leaves
        the error at exact length and root unchanged, but on one test scene (131_01) it
        raises the median.
    angle_weight : robust method, with angle priors (``angle_priors`` of
        :func:`reconstruct_articulated`): weight of each prior in
        the same score, ``angle_weight × mean_t (e_t / angle_tolerance)²``, ``e_t`` the angle
        by which the start's bone at frame ``t`` leaves the prior's range of angles to its
        reference bone; ≥ 0, 0 ignores the priors. At 1, a start outside a range by one
        tolerance at every frame scores as if it fitted the pixels one standard deviation
        worse.
    angle_tolerance : robust method, with angle priors: the angle, radians (> 0; default
        5°), by which a bone outside a range counts as one unit. The angle computed from a
        parent and reference joints a few percent of their bones off is itself off by
        several degrees.
    prior_start : robust method, with angle priors: also refine the start that takes, in
        every observed frame, the root (of the ray and the sphere) whose bone leaves the
        priors' ranges least. The binary program of Eq 4.12 and the flips at grazing frames
        choose roots by smoothness; where the whole window follows the impostor no flip
        reaches the truth, but the priors can still tell the two roots apart frame by frame.
    angle_refine : robust method, with angle priors: the refinement of Eq 4.5 also
        minimises each frame's angle beyond each prior's range, as a residual of
        ``angle_refine × excess / angle_tolerance`` pixels (≥ 0; 0 leaves Eq 4.5 alone).
        Under root and length error (Fig 4.3(c)) the refined bone otherwise turns out of
        ranges the capture never leaves; at 0.5 (default) the bench's mean error drops by
        about 15 %. Ranges learned from another capture that miss the true angles pull the
        bone off them, and with the length free (``length_tol``) the joint follows in depth:
        at exact length and root the error then rises where the ranges miss the motion. On
        the bench's never-seen CMU subject doing jumping jacks with ranges from subject
        131's walking (its true angles leave them by > 5° in 27 % of the frames, a pelvis
        relation by 9° in all): mean 0.061 → 0.095, while under Fig 4.3(c) it still helps,
        0.114 → 0.108; where the ranges fit (a second FAIR actor judged by the first's
        ranges, 4 % of the frames) it helps both, 0.033 → 0.023 and 0.110 → 0.098.
    angle_cap : robust method, with angle priors: each frame's ``(e_t / angle_tolerance)²``
        counts at most this much (> 0), in the selection score and in the ``k_alternatives``
        choice, and beyond ``angle_tolerance × √angle_cap`` a frame no longer pulls the
        refinement (``angle_refine``): a truncated quadratic. ``None``: no cap. A range
        learned from another capture may miss a whole window's true angles by tens of
        degrees; uncapped, such a prior outweighs any evidence of the pixels. Off by default:
        at 9 (three tolerances, 15°) such windows are reconstructed (a knee 1.02 → 0.02 at
        exact length and root) and the bench's Fig 4.3(c) means move by −0.003 to +0.005,
        but where the ranges are right and the impostor leaves them far (markers whose
        ranges come from the same capture) the cap frees the impostor too (CMU 85_02 at
        20 Hz, k = 8: mean 0.16 → 0.31); at 4 the bench's marker windows lose 0.12 → 0.20.
    k_alternatives : robust method: other basis sizes to run the whole reconstruction with
        (each ≥ 1; a size above the number of frames is skipped); the result whose final
        fit has the lowest Bayesian information criterion ``2n ln(c / 2n) + (2k' + 1) ln 2n``
        (as in ``refine_k_max``), plus the angle priors' excess ``Σ_t (e_t /
        angle_tolerance)²`` over every prior and frame when ``angle_priors`` are given, is
        returned. ``k`` is a prior on smoothness that a window spanning seconds of fast
        motion exceeds; the basis grown after the selection (``refine_k_max``) cannot undo a
        start chosen at a ``k`` too small. The priors' term keeps a larger basis from being
        chosen for following the impostor root in some frames (the pixels cannot tell).
        Default ``(12, 16)``, tried only where the window is long enough
        (``k_per_second``): on the bench's 60 Hz windows (1 s) larger sizes help no more
        than they hurt, while on windows of 1.5–3.5 s (40 Hz and slower) they lower the
        Fig 4.3(c) mean error on 9 of 10 window sets (e.g. 0.143 → 0.113 at 20–30 Hz; see
        the bench's record). Each size tried costs one more reconstruction; ``()`` runs
        ``k`` only. :func:`reconstruct_articulated` only (:func:`reconstruct_skeleton` keeps
        ``k``).
    k_per_second : with ``k_alternatives``: the largest basis size tried per second of the
        window (> 0, default 8: frequencies up to about 4 Hz); a size above
        ``k_per_second × duration`` is skipped, the duration ``F · (t_max − t_min) / (F − 1)``
        from ``cameras.times`` in seconds. A one-second window keeps ``k = 8``; a window of
        three seconds tries 12 and 16. Without ``cameras.times`` (frame indices, the
        duration unknown) every alternative is skipped (unless the basis grew,
        ``k_growth``). ``None`` tries every alternative whatever the duration.
    k_growth : robust method, with ``k_alternatives``: where the result of the sizes tried
        for the window's duration grew its basis in the final refinement
        (``refine_k_max``) to at least ``k_growth × k`` vectors, the motion outruns ``k``
        however short the window: the ``k_alternatives`` that ``k_per_second`` skipped are
        then tried too (each up to the number of frames) and the choice is made among all
        of them as above. A dancer's thigh or a hopping subject's foot leaves ``k = 8``
        behind within one second; the start chosen at ``k`` then misses the motion and the
        grown basis cannot undo it. ``None`` (default): the duration alone decides
        (``k_per_second``). At 1.5 on the bench's CMU windows at exact length and root, a
        hopping elbow's error drops 0.59 → 0.01 and the mean/median ratio of two window sets
        falls below 2 (2.26 → 1.73, 2.18 → 1.99), but on a standing clip a wrist the pixels
        cannot place takes the other side (0.01 → 0.5), and each size tried costs one more
        reconstruction where the basis grew (most windows of fast motion); see the bench's
        record.
    max_iter : Levenberg–Marquardt iterations of the refinement (≥ 1).
    time_limit : seconds per binary program (the best incumbent is used after it), or
        ``None``.
    node_limit : branch-and-bound nodes per binary program (deterministic, unlike
        ``time_limit``); ``None`` = prove optimality whatever it takes.
    """

    k: int = 8
    refine: bool = True
    method: str = "robust"
    fit_radius: bool = False
    tangent_quantile: float = 0.8
    length_tol: float = 0.1
    grazing_separation: float = 1.0
    flip_rounds: int = 3
    smooth_weight: float = 1.0
    motion_weight: float = 2.0
    refine_k_max: int = 32
    child_slack: float = 0.1
    length_weight: float = 0.0
    average_starts: bool = False
    angle_weight: float = 1.0
    angle_tolerance: float = float(np.radians(5.0))
    prior_start: bool = True
    angle_refine: float = 0.5
    angle_cap: float | None = None
    k_alternatives: tuple[int, ...] = (12, 16)
    k_per_second: float | None = 8.0
    k_growth: float | None = None
    max_iter: int = 100
    time_limit: float | None = None
    node_limit: int | None = DEFAULT_NODE_LIMIT

    def __post_init__(self) -> None:
        check_int(self.k, "k", min=1)
        for name in ("refine", "fit_radius", "average_starts", "prior_start"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name}: expected a bool, got {getattr(self, name)!r}")
        check_choice(self.method, "method", _METHODS)
        check_float(self.tangent_quantile, "tangent_quantile", min=0.0, max=1.0)
        check_float(self.length_tol, "length_tol", min=0.0, max=10.0)
        check_float(self.grazing_separation, "grazing_separation", min=0.0, max=2.0)
        check_int(self.flip_rounds, "flip_rounds", min=0, max=100)
        check_float(self.smooth_weight, "smooth_weight", min=0.0, max=1e6)
        check_float(self.motion_weight, "motion_weight", min=0.0, max=1e6)
        check_int(self.refine_k_max, "refine_k_max", min=0, max=10_000)
        check_float(self.child_slack, "child_slack", min=0.0, max=1e6)
        check_float(self.length_weight, "length_weight", min=0.0, max=1e6)
        check_float(self.angle_weight, "angle_weight", min=0.0, max=1e6)
        check_float(self.angle_refine, "angle_refine", min=0.0, max=1e6)
        if self.angle_cap is not None:
            check_float(self.angle_cap, "angle_cap", min=0.0, max=1e12, min_exclusive=True)
        check_float(
            self.angle_tolerance, "angle_tolerance", min=0.0, max=float(np.pi), min_exclusive=True
        )
        if isinstance(self.k_alternatives, (str, bytes)) or not isinstance(
            self.k_alternatives, (tuple, list)
        ):
            raise ValueError(
                f"k_alternatives: expected a tuple of basis sizes, got {self.k_alternatives!r}"
            )
        for i, kk in enumerate(self.k_alternatives):
            check_int(kk, f"k_alternatives[{i}]", min=1)
        if self.k_per_second is not None:
            check_float(self.k_per_second, "k_per_second", min=0.0, max=1e6, min_exclusive=True)
        if self.k_growth is not None:
            check_float(self.k_growth, "k_growth", min=1.0, max=1e6)
        check_int(self.max_iter, "max_iter", min=1, max=100_000)
        if self.time_limit is not None:
            check_float(self.time_limit, "time_limit", min=0.0, max=1e9)
        if self.node_limit is not None:
            check_int(self.node_limit, "node_limit", min=0, max=2**63 - 1)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _options(options: ArticulatedOptions | None, overrides: dict[str, Any]) -> ArticulatedOptions:
    if options is None:
        options = ArticulatedOptions()
    elif not isinstance(options, ArticulatedOptions):
        raise ValueError(f"options: expected ArticulatedOptions, got {type(options).__name__}")
    names = {f.name for f in dataclasses.fields(ArticulatedOptions)}
    for key in overrides:
        if key not in names:
            raise ValueError(f"{key}: not an option of ArticulatedOptions")
    return dataclasses.replace(options, **overrides) if overrides else options


def reconstruct_articulated(
    x: npt.ArrayLike,
    cameras: Cameras,
    parent: npt.ArrayLike,
    length: float,
    *,
    children: Sequence[tuple[npt.ArrayLike, float]] | None = None,
    angle_priors: Sequence[tuple[npt.ArrayLike, tuple[float, float]]] | None = None,
    options: ArticulatedOptions | None = None,
    **overrides: Any,
) -> ArticulatedTrajectory:
    """Reconstructs a joint at fixed distance ``length`` from a known parent trajectory.

    Parameters
    ----------
    x : (F, 2) pixels of the child in ``cameras[i]`` (one camera per frame); NaN rows are
        missing and get imputed by the basis.
    cameras : ``F`` cameras with their ``times`` in seconds (frame indices when ``times`` is
        None). The window's duration sets which ``k_alternatives`` are tried
        (``k_per_second``): give true times, or a slow-rate window is fitted at ``k`` only.
    parent : (F, 3) parent positions, metres, every frame.
    length : bone length in metres (> 0); see :class:`ArticulatedOptions` for how it is
        enlarged (thesis) or refined (robust method).
    children : the joint's own children, if observed: ``(x_c (F, 2) pixels, NaN rows
        missing; bone length from this joint in metres)`` each. The robust method rejects
        starts that leave a child's ray out of its reach (``child_slack``); the thesis
        method ignores them.
    angle_priors : priors on the joint's bone (not in the thesis): ``(reference (F, 3) bone
        vectors in metres, (lo, hi) radians within [0, π])`` each: at every frame the angle
        between the bone (parent → joint) and the reference bone lies in the range. With a
        kinematic tree, the parent's bone (``parent − grandparent``) bounds how the joint
        bends and a sibling's bone (``sibling − parent``) keeps two bones of one rigid
        segment (pelvis, thorax) at their angle; any point rigid with the joint and its
        parent (``point − parent``; a marker on the same segment) keeps its angle too
        (``learn_angle_ranges(rigid=...)``). Learn the ranges from motion capture with
        :func:`learn_angle_ranges`. The robust method scores each start's excess beyond the
        ranges (``angle_weight``, ``angle_tolerance``), adds the start the priors choose
        frame by frame (``prior_start``) and pulls the refined bone into the ranges
        (``angle_refine``): where the pixels and smoothness cannot tell the two roots of a
        ray apart, the impostor side often puts the bone where the body does not.
    options : :class:`ArticulatedOptions`; ``overrides`` replace some of its fields
        (e.g. ``k=10, method="thesis"``).

    Raises
    ------
    ValueError
        Bad shapes, non-finite parent, ``length <= 0``, a bad or unknown option or angle prior;
        coordinates so far from the origin that float64 rounds them by more than a
        thousandth of the bone; inputs so large that the result overflows.
    DegenerateError
        Fewer observed frames than ``k``.

    Notes
    -----
    What one camera per frame cannot tell. Each ray meets the sphere about the parent twice;
    where the two roots come close (the ray nearly grazes the sphere), the arc between them
    leaves the ray by only ``sep² / 8r`` (``sep`` the roots' distance, ``r`` the bone), a
    pixel or two at the joint's depth. A trajectory can pass to the other root there and come
    back at the next such frame for about the noise's worth of reprojection error, so the
    piece between may lie on either side. The smoothness score, the angle priors and the
    children then decide, and they are sometimes wrong: on the CMU windows of
    ``benches/articulated_accuracy.py`` at exact length and root, such pieces make a third to
    two thirds of the joints whose error is above a tenth of the bone (a slow arm in a
    standing clip goes to the other side by 6–10 cm). Where the joint is seen from a second
    camera at the same time, that view decides. Likewise, a window without grazing frames
    does not fix the bone length (any length above the rays' distances from the parent puts
    a point on every ray): the refinement within ``length_tol`` then follows the noise. A
    length known exactly can be held (``length_tol=0``): on the same windows the median
    error falls 1.2–3.7-fold, the other-side pieces stay.

    Examples
    --------
    A right hip from the hips (``parent``) with the left hip given too (the pelvis keeps the
    two bones at one angle), the range learned from another capture ``mocap (F', J, 3)`` of
    the same skeleton (``hips``, ``lhip``, ``rhip`` its joint indices):

    >>> ranges = learn_angle_ranges(mocap, parents, bend=False)        # doctest: +SKIP
    >>> prior = (lhip_xyz - hips_xyz, ranges[rhip, hips, lhip])        # doctest: +SKIP
    >>> out = reconstruct_articulated(x, cams, hips_xyz, 0.12,
    ...                               angle_priors=[prior])            # doctest: +SKIP
    """
    opts = _options(options, overrides)
    f = len(_check_cameras(cameras))
    x_ = as_float_array(x, "x", (f, 2), allow_nan=True)
    p_ = as_float_array(parent, "parent", (f, 3))
    length_ = check_float(length, "length", min=0.0, min_exclusive=True)
    _check_scale(p_, cameras, length_, "parent")
    kids = []
    if isinstance(children, (str, bytes, np.ndarray)):
        raise ValueError("children: expected a sequence of (pixels, length) pairs")
    for c, child in enumerate(children or ()):
        if not isinstance(child, (tuple, list)) or len(child) != 2:
            raise ValueError(f"children[{c}]: expected a (pixels (F, 2), length) pair")
        xc, lc = child
        kids.append(
            (
                as_float_array(xc, f"children[{c}] pixels", (f, 2), allow_nan=True),
                check_float(lc, f"children[{c}] length", min=0.0, min_exclusive=True),
            )
        )
    if isinstance(angle_priors, (str, bytes, np.ndarray)):
        raise ValueError("angle_priors: expected a sequence of (reference (F, 3), (lo, hi)) pairs")
    priors = []
    for i, prior in enumerate(angle_priors or ()):
        if not isinstance(prior, (tuple, list)) or len(prior) != 2:
            raise ValueError(
                f"angle_priors[{i}]: expected a (reference (F, 3), (lo, hi) radians) pair"
            )
        ref = as_float_array(prior[0], f"angle_priors[{i}] reference", (f, 3))
        lo, hi = _angle_range(prior[1], f"angle_priors[{i}] range")
        priors.append((ref, lo, hi))
    t = _times(cameras)
    sizes = [opts.k]
    skipped: list[int] = []  # sizes k_per_second skipped, tried where the basis grew
    if opts.method == "robust":
        cap = _largest_size(cameras, opts.k_per_second)
        for i, kk in enumerate(opts.k_alternatives):
            kk = check_int(kk, f"k_alternatives[{i}]", min=1)
            if kk <= min(cap, f):
                sizes.append(kk)
            elif kk <= f and opts.k_growth is not None:
                skipped.append(kk)

    def run(kk: int) -> tuple[float, dict[str, Any]]:
        d = _core.reconstruct_articulated(
            cameras.K, cameras.R, cameras.C, x_, p_, t, length_, replace(opts, k=kk), kids, priors
        )
        return _choice_score(d, p_, priors, opts.angle_tolerance, opts.angle_cap), d

    # the lowest score wins; min keeps the first of equals (the size tried first)
    best = min((run(kk) for kk in dict.fromkeys(sizes)), key=lambda r: r[0])
    grown = len(best[1]["coeffs_theta"])
    if opts.k_growth is not None and grown >= opts.k_growth * opts.k:
        more = [run(kk) for kk in dict.fromkeys(skipped) if kk not in sizes]
        best = min([best, *more], key=lambda r: r[0])
    return _traj(best[1], t)


def _largest_size(cameras: Cameras, per_second: float | None) -> float:
    """The largest ``k_alternatives`` size worth trying (``k_per_second``): the window's
    duration in seconds (its frames' cells, as the DCT basis spans them) times
    ``per_second``; 0 without times, ``inf`` for ``None``."""
    if per_second is None:
        return float("inf")
    if cameras.times is None or len(cameras) < 2:
        return 0.0
    t = np.asarray(cameras.times, dtype=float)
    f = len(t)
    duration = (float(t.max()) - float(t.min())) * f / (f - 1)
    return per_second * duration * (1.0 + 1e-9)


def _choice_score(
    d: dict[str, Any],
    parent: FloatArray,
    priors: list[tuple[FloatArray, float, float]],
    tolerance: float,
    cap: float | None = None,
) -> float:
    """The score of ``k_alternatives``: BIC of the final fit (as the Rust core's
    ``refinement_bic``) plus the angle priors' excess, ``Σ min((e / tolerance)², cap)``
    (``angle_cap``)."""
    n_obs = int(d["n_observed"])
    n = max(2 * n_obs, 1)
    cost = max(float(d["reprojection_rms"]) ** 2 * n_obs, np.finfo(float).tiny)
    k_final = len(d["coeffs_theta"])
    score = n * np.log(cost / n) + (2 * k_final + 1) * np.log(n)
    bone = np.asarray(d["X"], dtype=float) - parent
    for ref, lo, hi in priors:
        a = _vector_angles(bone, ref)
        a = a[np.isfinite(a)]
        e = np.maximum(lo - a, 0.0) + np.maximum(a - hi, 0.0)
        u = (e / tolerance) ** 2
        score += float((u if cap is None else np.minimum(u, cap)).sum())
    return float(score)


def _angle_range(r: object, name: str) -> tuple[float, float]:
    """``(lo, hi)`` radians, checked."""
    v = np.asarray(r, dtype=float) if not isinstance(r, (str, bytes)) else None
    if v is None or v.shape != (2,):
        raise ValueError(f"{name}: expected (lo, hi) in radians, got {r!r}")
    lo, hi = float(v[0]), float(v[1])
    if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo <= hi <= np.pi):
        raise ValueError(f"{name}: need 0 <= lo <= hi <= pi radians, got ({lo}, {hi})")
    return lo, hi


def articulated_bqp(
    x: npt.ArrayLike, cameras: Cameras, parent: npt.ArrayLike, length: float, k: int
) -> tuple[FloatArray, FloatArray, float]:
    """The binary program of Eq 4.12 for one joint: ``(Q (n,n), c (n,), constant)`` with
    ``n`` the number of observed frames whose ray has two distinct intersections; the
    smoothness cost of a choice ``b`` is ``bᵀQb + cᵀb + constant``."""
    f = len(_check_cameras(cameras))
    x_ = as_float_array(x, "x", (f, 2), allow_nan=True)
    p_ = as_float_array(parent, "parent", (f, 3))
    length_ = check_float(length, "length", min=0.0, min_exclusive=True)
    k_ = check_int(k, "k", min=1, max=f)
    return _core.articulated_bqp(
        cameras.K, cameras.R, cameras.C, x_, p_, _times(cameras), length_, k_
    )


def articulated_reconstructability(
    child: npt.ArrayLike, cameras: Cameras, parent: npt.ArrayLike, k: int
) -> float:
    """Reconstructability η_a (Eq 4.13) of a known child trajectory ``(F, 3)``.

    Arguments in the order of :func:`reconstruct_articulated` and
    :func:`socialcam.reconstructability`: the trajectory, the cameras, the parent
    trajectory ``(F, 3)``, then ``k``.

    The ratio of the parts of the impostor and of the true relative trajectories that the
    ``k``-vector DCT basis cannot span, measured on unit relative directions (the vectors
    of Eq 4.12). ``η_a ≫ 1``: the smooth truth is separable from its impostor and the
    reconstruction is accurate; ``η_a < 1``: the impostor is smoother and wins.
    """
    f = len(_check_cameras(cameras))
    p_ = as_float_array(parent, "parent", (f, 3))
    c_ = as_float_array(child, "child", (f, 3))
    k = check_int(k, "k", min=1, max=f)
    return float(
        _core.articulated_reconstructability(
            cameras.K, cameras.R, cameras.C, p_, c_, _times(cameras), int(k)
        )
    )


def _bone_lengths(parents: Sequence[int], lengths: FloatArray) -> list[float]:
    return [0.0 if p == -1 else float(v) for p, v in zip(parents, lengths, strict=True)]


# Anthropometric segment lengths as fractions of body height (after Drillis & Contini's
# segment table, with the spine split CMU-style into lower back, chest and neck).
_CMU_HUMAN: tuple[tuple[str, str | None, float], ...] = (
    ("Hips", None, 0.0),
    ("LeftHip", "Hips", 0.070),
    ("LeftKnee", "LeftHip", 0.245),
    ("LeftAnkle", "LeftKnee", 0.246),
    ("LeftToe", "LeftAnkle", 0.080),
    ("RightHip", "Hips", 0.070),
    ("RightKnee", "RightHip", 0.245),
    ("RightAnkle", "RightKnee", 0.246),
    ("RightToe", "RightAnkle", 0.080),
    ("Chest", "Hips", 0.100),
    ("Chest2", "Chest", 0.100),
    ("Neck", "Chest2", 0.080),
    ("Head", "Neck", 0.070),
    ("LeftShoulder", "Chest2", 0.129),
    ("LeftElbow", "LeftShoulder", 0.186),
    ("LeftWrist", "LeftElbow", 0.146),
    ("RightShoulder", "Chest2", 0.129),
    ("RightElbow", "RightShoulder", 0.186),
    ("RightWrist", "RightElbow", 0.146),
)


@dataclass(frozen=True, init=False, eq=False)
class Skeleton:
    """A kinematic tree of joints.

    Parameters
    ----------
    names : joint names, length ``J``.
    parents : (J,) parent index per joint, ``-1`` for the single root.
    lengths : (J,) bone length from the parent, metres (ignored for the root).
    Raises
    ------
    ValueError
        Not a tree (no or several roots, a cycle, a parent out of range), a non-positive
        bone length.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    lengths: FloatArray
    order: tuple[int, ...] = field(init=False)

    def __init__(
        self,
        names: Sequence[str],
        parents: Sequence[int],
        lengths: npt.ArrayLike,
    ) -> None:
        names_ = tuple(str(n) for n in names)
        parents_ = tuple(int(p) for p in parents)
        j = len(parents_)
        if len(names_) != j:
            raise ValueError(f"names: expected {j} names (one per joint), got {len(names_)}")
        lengths_ = np.array(as_float_array(lengths, "lengths", (j,)))
        # The root has no bone; the core ignores its entry.
        order = _core.skeleton_order(list(parents_), _bone_lengths(parents_, lengths_))
        lengths_.setflags(write=False)
        object.__setattr__(self, "names", names_)
        object.__setattr__(self, "parents", parents_)
        object.__setattr__(self, "lengths", lengths_)
        object.__setattr__(self, "order", tuple(order))

    @property
    def root(self) -> int:
        """Index of the root joint."""
        return self.order[0]

    def index(self, name: str) -> int:
        """Index of the joint called ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(f"name: no joint called {name!r}") from None

    @classmethod
    def cmu_human(cls, scale: float = 1.75) -> Skeleton:
        """A CMU-style 19-joint human (root ``Hips``) with anthropometric length ratios.

        ``scale`` is the body height in metres; every bone is ``ratio × scale``.
        """
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"scale: must be positive, got {scale}")
        names = [n for n, _, _ in _CMU_HUMAN]
        parents = [-1 if p is None else names.index(p) for _, p, _ in _CMU_HUMAN]
        lengths = [r * scale for _, _, r in _CMU_HUMAN]
        return cls(names, parents, lengths)

    @classmethod
    def from_bvh(cls, motion: Any, min_length: float = 0.05) -> tuple[Skeleton, list[int]]:
        """The skeleton of a :class:`socialcam.mocap.BvhMotion`, keeping the root and the
        joints whose bone is at least ``min_length`` metres (zero-length helper joints are
        collapsed onto their ancestors, short finger bones dropped). Returns the skeleton and
        the kept BVH joint indices."""
        parents = [int(p) for p in motion.parents]
        lengths = np.asarray(motion.bone_lengths)
        keep = [i for i in range(len(parents)) if parents[i] == -1 or lengths[i] >= min_length]
        kept = set(keep)
        new_parent: list[int] = []
        for i in keep:
            p = parents[i]
            while p != -1 and p not in kept:
                p = parents[p]
            new_parent.append(-1 if p == -1 else keep.index(p))
        pos = np.asarray(motion.positions)
        bone = [
            0.0 if q == -1 else float(np.linalg.norm(pos[:, i] - pos[:, keep[q]], axis=1).mean())
            for i, q in zip(keep, new_parent, strict=True)
        ]
        names = [motion.names[i] for i in keep]
        return cls(names, new_parent, bone), keep


@dataclass(frozen=True, eq=False)
class SkeletonReconstruction:
    """Result of :func:`reconstruct_skeleton`.

    Attributes
    ----------
    points : (F, J, 3) joint positions, metres.
    joints : per joint, its :class:`ArticulatedTrajectory` diagnostics (``None`` for the root).
    """

    points: FloatArray
    joints: tuple[ArticulatedTrajectory | None, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "points": self.points.tolist(),
            "joints": [None if j is None else j.to_dict() for j in self.joints],
        }


def reconstruct_skeleton(
    x: npt.ArrayLike,
    cameras: Cameras,
    skeleton: Skeleton,
    root: npt.ArrayLike,
    *,
    options: ArticulatedOptions | None = None,
    **overrides: Any,
) -> SkeletonReconstruction:
    """Reconstructs every joint recursively from the root trajectory (Eq 4.6).

    Parameters
    ----------
    x : (F, J, 2) pixels of every joint (NaN rows missing).
    cameras : ``F`` cameras, one per frame.
    skeleton : the tree and bone lengths.
    root : (F, 3) root trajectory, metres.
    options, overrides : as in :func:`reconstruct_articulated`, for every joint.

    No angle priors (``angle_priors`` of :func:`reconstruct_articulated`) are passed between
    joints: from reconstructed references a flipped ancestor makes a prior wrong and pushes
    its descendants after it (``benches/articulated_accuracy.py --skeleton``, Fig 4.3(c),
    seed 0: bend and sibling priors took the mean error 0.147 → 0.128 on one window set but
    0.151 → 0.178 and 0.177 → 0.322 on two others).
    """
    opts = _options(options, overrides)
    f = len(_check_cameras(cameras))
    if not isinstance(skeleton, Skeleton):
        raise ValueError(f"skeleton: expected a socialcam.Skeleton, got {type(skeleton).__name__}")
    j = len(skeleton.parents)
    x_ = as_float_array(x, "x", (f, j, 2), allow_nan=True)
    r_ = as_float_array(root, "root", (f, 3))
    t = _times(cameras)
    lengths = _bone_lengths(skeleton.parents, skeleton.lengths)
    _check_scale(r_, cameras, min((v for v in lengths if v > 0), default=np.inf), "root")
    X, dicts = _core.reconstruct_skeleton(
        cameras.K, cameras.R, cameras.C, x_, list(skeleton.parents), lengths, r_, t, opts
    )
    joints = tuple(None if d is None else _traj(d, t) for d in dicts)
    return SkeletonReconstruction(readonly(X), joints)


def bone_angles(
    positions: npt.ArrayLike, bone: tuple[int, int], reference: tuple[int, int]
) -> FloatArray:
    """The angle, radians, between the bone ``bone = (a, b)`` (a → b) and the bone
    ``reference = (c, d)`` (c → d) in every frame.

    Parameters
    ----------
    positions : (F, J, 3) joint positions, metres (e.g. motion capture); NaN where a point
        is missing (marker gaps).
    bone, reference : pairs of joint indices.

    Returns
    -------
    (F,) radians in [0, π]; NaN where a bone has no length or a point is missing.
    """
    P = as_float_array(positions, "positions", (None, None, 3), allow_nan=True)
    J = P.shape[1]
    for name, pair in (("bone", bone), ("reference", reference)):
        if len(pair) != 2 or not all(0 <= int(v) < J for v in pair):
            raise ValueError(f"{name}: expected two joint indices in 0..{J}, got {pair!r}")
    u = P[:, int(bone[1])] - P[:, int(bone[0])]
    v = P[:, int(reference[1])] - P[:, int(reference[0])]
    return _vector_angles(u, v)


def _vector_angles(u: FloatArray, v: FloatArray) -> FloatArray:
    """Row by row, the angle in radians between ``u`` and ``v`` (both (F, 3)); NaN where
    either has no length or is missing."""
    nu, nv = np.linalg.norm(u, axis=1), np.linalg.norm(v, axis=1)
    out = np.full(u.shape[0], np.nan)
    ok = (nu > 0) & (nv > 0)
    cos = np.einsum("ij,ij->i", u[ok], v[ok]) / (nu[ok] * nv[ok])
    out[ok] = np.arccos(np.clip(cos, -1.0, 1.0))
    return out


def _angle_spread(X: FloatArray, p: int, j: int, qs: list[int]) -> FloatArray:
    """(len(qs),) standard deviation, radians, over the frames of ``X`` (F, J, 3), of the
    angle at ``p`` between the bone ``p → j`` and ``p → q`` for each ``q`` (frames with a gap
    left out; NaN where fewer than two frames are left)."""
    u = np.repeat(X[:, j] - X[:, p], len(qs), axis=0)
    v = (X[:, qs] - X[:, p : p + 1]).reshape(-1, 3)
    ang = _vector_angles(u, v).reshape(-1, len(qs))  # (F, n)
    seen = np.isfinite(ang)
    k = seen.sum(axis=0)
    mean = np.where(seen, ang, 0.0).sum(axis=0) / np.maximum(k, 1)
    var = (np.where(seen, ang - mean, 0.0) ** 2).sum(axis=0) / np.maximum(k, 1)
    return np.where(k > 1, np.sqrt(var), np.nan)


def learn_angle_ranges(
    positions: npt.ArrayLike | Sequence[npt.ArrayLike],
    parents: Sequence[int],
    *,
    bend: bool = True,
    siblings: bool = True,
    rigid: float = 0.0,
    quantiles: tuple[float, float] = (0.0, 1.0),
    margin: float = 0.0,
    steady: float | None = None,
) -> dict[tuple[int, int, int], tuple[float, float]]:
    """Angle priors for :func:`reconstruct_articulated` learned from motion capture.

    Parameters
    ----------
    positions : (F, J, 3) joint positions, metres, or a list of such clips (same joints);
        NaN where a point is missing (marker gaps): those frames are left out.
    parents : (J,) parent per joint, ``-1`` for the root.
    bend : learn ``(joint, grandparent, parent)``: the angle between each bone and its
        parent's bone (how the joint bends).
    siblings : learn ``(joint, parent, sibling)`` for every other child of the joint's
        parent: on a rigid segment (pelvis, thorax) the angle is nearly constant.
    rigid : if > 0, also learn ``(joint, parent, q)`` for every other joint or marker ``q``
        whose distances to the joint and to its parent both vary by less than ``rigid``
        (standard deviation over mean, over every frame given): the three move as one rigid
        body, so the angle at the parent is nearly constant. Made for optical marker sets,
        whose markers have no anatomy but sit in groups on one segment (e.g. 0.08).
    quantiles : the range's ends as quantiles of the angle over every frame (the default,
        min and max).
    margin : radians added on both sides (≥ 0), the range then clipped to [0, π].
    steady : if given (radians), a ``rigid`` point is kept only if the angle itself at the
        parent, between the bone and the point, varies by less than ``steady`` (standard
        deviation over every frame given). Distances alone let through a point far from a
        short bone whose angle swings by tens of degrees (the head seen from the hip as the
        thigh swings): a range that holds for the poses of the capture it was learned from
        and misses other activities. Give it (e.g. 0.08) when the ranges come from another
        capture than the one reconstructed; leave it out for a calibration capture of the
        same session. A steady relation still belongs to one body: learned on one person's
        walking, the angle between the two hips missed another person's (the bench's CMU
        subject 14) by 9° in every frame; see ``ArticulatedOptions.angle_refine`` for what
        such a miss costs.

    Returns
    -------
    ``{(joint, a, b): (lo, hi)}`` radians: the angle between the bone of ``joint`` (its
    parent → it) and the bone ``a → b``; give ``(X[:, b] − X[:, a], (lo, hi))`` as an
    ``angle_priors`` entry of :func:`reconstruct_articulated`.
    """
    if isinstance(positions, (list, tuple)) and not positions:
        raise ValueError("positions: no clip given")
    clips: list[Any] = (
        list(positions)
        if isinstance(positions, (list, tuple)) and np.ndim(positions[0]) == 3
        else [positions]
    )
    parents_ = [int(p) for p in parents]
    J = len(parents_)
    bend, siblings = check_bool(bend, "bend"), check_bool(siblings, "siblings")
    clips = [as_float_array(c, "positions", (None, J, 3), allow_nan=True) for c in clips]
    for c, p in enumerate(parents_):
        if p < -1 or p >= J or p == c:
            raise ValueError(f"parents: joint {c} has parent {p}, out of range")
    q0, q1 = (check_float(q, "quantiles", min=0.0, max=1.0) for q in quantiles)
    if q0 > q1:
        raise ValueError(f"quantiles: need lo <= hi, got {quantiles}")
    m = check_float(margin, "margin", min=0.0, max=float(np.pi))
    tol = check_float(rigid, "rigid", min=0.0)
    sd_max = None if steady is None else check_float(steady, "steady", min=0.0, min_exclusive=True)
    spread = np.full((J, J), np.inf)
    if tol > 0:
        # Relative spread (std / mean) of every pairwise distance over all frames, frames
        # where either point is missing (NaN) left out; one row of pairs at a time.
        n, s1, s2 = np.zeros((J, J)), np.zeros((J, J)), np.zeros((J, J))
        for c in clips:
            for q in range(J):
                d = np.linalg.norm(c - c[:, q : q + 1], axis=2)  # (F, J)
                ok = np.isfinite(d)
                d = np.where(ok, d, 0.0)
                n[q] += ok.sum(axis=0)
                s1[q] += d.sum(axis=0)
                s2[q] += (d * d).sum(axis=0)
        seen = (n > 1) & (s1 > 0)
        mean = np.divide(s1, n, out=np.zeros_like(s1), where=seen)
        var = np.divide(s2, n, out=np.zeros_like(s2), where=seen) - mean**2
        spread[seen] = np.sqrt(np.maximum(var[seen], 0.0)) / mean[seen]
    # Every clip's frames, stacked for the steady test only.
    frames = np.concatenate(clips) if sd_max is not None else np.empty((0, J, 3))
    keys: list[tuple[int, int, int]] = []
    for j, p in enumerate(parents_):
        if p == -1:
            continue
        # (In a 2-cycle, j ↔ p, as marker pairs may be, the "grandparent" is j itself.)
        if bend and parents_[p] not in (-1, j):
            keys.append((j, parents_[p], p))
        if siblings:
            keys += [(j, p, s) for s, ps in enumerate(parents_) if ps == p and s != j]
        if tol > 0:
            qs = [
                q for q in range(J) if q not in (j, p) and spread[q, p] < tol and spread[q, j] < tol
            ]
            if sd_max is not None and qs:
                qs = [
                    q
                    for q, sd in zip(qs, _angle_spread(frames, p, j, qs), strict=True)
                    if sd < sd_max
                ]
            keys += [(j, p, q) for q in qs]
    keys = list(dict.fromkeys(keys))
    out: dict[tuple[int, int, int], tuple[float, float]] = {}
    for j, a, b in keys:
        v = np.concatenate([bone_angles(c, (parents_[j], j), (a, b)) for c in clips])
        v = v[np.isfinite(v)]
        if v.size:
            lo = float(np.clip(np.quantile(v, q0) - m, 0.0, np.pi))
            hi = float(np.clip(np.quantile(v, q1) + m, 0.0, np.pi))
            out[j, a, b] = (lo, hi)
    return out
