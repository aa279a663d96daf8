"""Social saliency and social charges: 3D joint attention (thesis Chapter 6).

A frame's primary gaze rays (:class:`GazeRays`, Sec 3.1) induce the social saliency field
of Eq 6.1–6.4 (:func:`saliency_field`, :func:`saliency_grid`): a cone-shaped Gaussian about
every ray, averaged over the rays. Its modes, found by the ray mean-shift of Eq 6.5–6.7,
are the social charges (:func:`find_charges`, :func:`find_charges_sequence`); each carries
its membership feature (Eq 6.8) and an 80 % confidence region. Classic mean-shift on the
membership features links charges over time (:func:`track_charges`, Sec 6.1.3).

All kernels run in the Rust core with the GIL released, in parallel; results do not
depend on the thread count.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import InitVar, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from socialcam import _core
from socialcam._validate import (
    FloatArray,
    apply_overrides,
    as_float_array,
    as_int_array,
    check_choice,
    check_float,
    check_int,
    check_rounding,
    check_seed,
    check_sequence,
    readonly,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

IntArray = npt.NDArray[np.int64]

#: How far ``‖v‖`` may be from 1 (same tolerance as the core).
UNIT_TOLERANCE = 1e-6


def _norms(v: FloatArray) -> FloatArray:
    """Row norms; a row too long for float64 (1e200) is ``inf``, without a warning."""
    with np.errstate(over="ignore"):
        return np.asarray(np.linalg.norm(v, axis=1))


#: smallest bandwidth ``h`` (metres) a ray may have: the field's ``1/h²`` overflows below
#: about 1e-154 (an atom is 1e-10 m)
MIN_H = 1e-100


@dataclass(frozen=True)
class GazeRays:
    """The primary gaze rays of one frame (Sec 3.1).

    Parameters
    ----------
    p : (N, 3) eye centres, metres
    v : (N, 3) unit gaze directions (an error if not unit, unless ``normalize=True``)
    h : float or (N,) bandwidths > 0: std of eye-in-head deviation on the plane at unit
        distance from the eye (dimensionless, metres per metre of depth; equal to the
        angle in radians for small angles, never degrees)
    ids : (N,) integer person ids (default ``0..N-1``); used to follow people across frames
    normalize : scale ``v`` to unit length instead of refusing it
    """

    p: FloatArray
    v: FloatArray
    h: FloatArray
    ids: IntArray = field(default=None)  # type: ignore[assignment, arg-type]
    normalize: InitVar[bool] = False

    def __post_init__(self, normalize: bool) -> None:
        p = as_float_array(self.p, "p", (None, 3))
        n = p.shape[0]
        if n == 0:
            raise ValueError("p: need at least one gaze ray, got 0")
        v = as_float_array(self.v, "v", (n, 3))
        if normalize:
            # scaled by the largest component first: |v| of 1e200 overflows to inf (and
            # v / inf is a zero "unit" vector), of 1e-170 underflows to 0
            big = np.abs(v).max(axis=1)
            if (big == 0).any():
                raise ValueError(f"v: direction {int(np.argmin(big))} is zero")
            v = v / big[:, None]
            v = v / np.linalg.norm(v, axis=1)[:, None]
        elif (np.abs((norms := _norms(v)) - 1.0) > UNIT_TOLERANCE).any():
            i = int(np.argmax(np.abs(norms - 1.0)))
            raise ValueError(
                f"v: direction {i} has norm {norms[i]:.6g}; directions must be unit "
                "(pass normalize=True to scale them)"
            )
        # A scalar is every ray's bandwidth.
        h = as_float_array([self.h] * n if np.ndim(self.h) == 0 else self.h, "h", (n,))
        if (h < MIN_H).any():
            raise ValueError(
                f"h: bandwidths must be >= {MIN_H:g} m (1/h² must not overflow), got "
                f"{h[h < MIN_H][0]!r}"
            )
        if self.ids is None:
            ids = np.arange(n, dtype=np.int64)
        else:
            ids_in = np.asarray(self.ids)
            if ids_in.shape != (n,):
                raise ValueError(f"ids: expected {n} integer ids, got shape {ids_in.shape}")
            ids = as_int_array(ids_in, "ids")  # floats, bools and uint64 ≥ 2⁶³ refused
            if len(np.unique(ids)) != n:
                raise ValueError("ids: person ids must be distinct within a frame")
        for name, arr in (("p", p), ("v", v), ("h", h), ("ids", ids)):
            object.__setattr__(self, name, readonly(np.ascontiguousarray(arr)))

    def __len__(self) -> int:
        return int(self.p.shape[0])

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k).tolist() for k in ("p", "v", "h", "ids")}


def _rays(rays: GazeRays | tuple[Any, ...], name: str = "rays") -> GazeRays:
    if not isinstance(rays, GazeRays):
        if not isinstance(rays, (tuple, list)) or len(rays) not in (3, 4):
            raise ValueError(
                f"{name}: expected a GazeRays or a tuple (p, v, h[, ids]), "
                f"got {type(rays).__name__}"
            )
        rays = GazeRays(*rays)
    # eyes 1e15 m from the origin are rounded by 0.1 m: charges moved by that, or lost
    check_rounding(rays.p, f"{name}.p", "the eyes' spread")
    return rays


def saliency_field(rays: GazeRays, points: npt.ArrayLike) -> FloatArray:
    """The social saliency field (Eq 6.4) at ``points``.

    ``f(x) = (1/N) Σᵢ exp(−½‖dᵢ(x)‖²/hᵢ²) / (hᵢ√(2π))`` with the perspective distance
    vector ``dᵢ`` of Eq 6.2 (a point behind an eye gets nothing from that ray; at an eye
    ``d = 0``, so the eye itself gets the ray's peak ``1/(h√2π)``).

    Parameters
    ----------
    rays : the frame's gaze rays
    points : (M, 3) or (3,) points, metres

    Returns
    -------
    (M,) field values (a float for a single point)
    """
    r = _rays(rays)
    x = as_float_array(points, "points")
    single = x.shape == (3,)
    x2 = as_float_array(x.reshape(1, 3) if single else x, "points", (None, 3))
    out = _core.saliency_field(r.p, r.v, r.h, x2)
    return out[0] if single else out  # type: ignore[no-any-return]


#: The most samples :func:`saliency_grid` computes (2 GiB of float64; the core's limit).
MAX_GRID_CELLS = 1 << 28


def _grid_shape(shape: int | Sequence[int]) -> tuple[int, int, int]:
    """``shape`` as 3 positive sizes whose product fits in :data:`MAX_GRID_CELLS`."""
    if isinstance(shape, (int, np.integer)) and not isinstance(shape, bool):
        sizes: list[object] = [shape] * 3
    elif isinstance(shape, (tuple, list, np.ndarray)) and len(shape) == 3:
        sizes = list(shape)
    else:
        raise ValueError(f"shape: expected an integer or 3 integers, got {shape!r}")
    sh = tuple(check_int(n, "shape", min=1) for n in sizes)
    if sh[0] * sh[1] * sh[2] > MAX_GRID_CELLS:
        raise ValueError(
            f"shape: {sh} is {sh[0] * sh[1] * sh[2]:.3g} samples, more than {MAX_GRID_CELLS} "
            f"({MAX_GRID_CELLS * 8 >> 30} GiB of float64)"
        )
    return sh  # type: ignore[return-value]


def saliency_grid(
    rays: GazeRays,
    lo: npt.ArrayLike,
    hi: npt.ArrayLike,
    *,
    shape: int | Sequence[int] = 64,
) -> FloatArray:
    """The field sampled on a regular grid, in parallel.

    Axis ``a`` has ``shape[a]`` samples ``numpy.linspace(lo[a], hi[a], shape[a])``; the
    result ``g[i, j, k]`` is the field at ``(x_i, y_j, z_k)``.

    Parameters
    ----------
    rays : the frame's gaze rays
    lo, hi : (3,) corners of the box, metres
    shape : int or (3,) samples per axis

    Returns
    -------
    (nx, ny, nz) array
    """
    r = _rays(rays)
    lo_a = as_float_array(lo, "lo", (3,))
    hi_a = as_float_array(hi, "hi", (3,))
    with np.errstate(over="ignore"):
        span = hi_a - lo_a
    if not np.isfinite(span).all():
        raise ValueError(f"lo, hi: the box's size overflows float64 ({lo_a} to {hi_a})")
    sh = _grid_shape(shape)
    return _core.saliency_grid(  # type: ignore[no-any-return]
        r.p, r.v, r.h, tuple(lo_a.tolist()), tuple(hi_a.tolist()), sh
    )


def grid_axes(
    lo: npt.ArrayLike, hi: npt.ArrayLike, shape: int | Sequence[int]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The sample coordinates of :func:`saliency_grid` along x, y and z."""
    lo_a = as_float_array(lo, "lo", (3,))
    hi_a = as_float_array(hi, "hi", (3,))
    sh = _grid_shape(shape)
    xs, ys, zs = (np.linspace(lo_a[a], hi_a[a], sh[a]) for a in range(3))
    return xs, ys, zs


@dataclass(frozen=True)
class Charge:
    """One social charge of one frame.

    Attributes
    ----------
    position : (3,) the mode of the saliency field, metres
    magnitude : the field value there (Eq 6.4), the charge's strength
    members : (K,) person ids of the member rays (rays within ``member_sigma`` bandwidths)
    member_index : (K,) the same members as row indices into the frame's rays
    ids : (N,) person ids of all the frame's rays
    membership : (N,) membership feature (Eq 6.8): ``fᵢ(x)/‖f(x)‖`` over the frame's rays
    support : how many mean-shift seeds converged here (0: no mode, e.g. a pair's
        candidate, ``pair_candidates``)
    region_centre, region_axes, region_radii : the confidence region (where the field
        exceeds ``region_level`` (0.8) of ``magnitude``) as an ellipsoid: centre (3,),
        unit axes as the columns of (3, 3), semi-axes (3,) in metres
    frame : index of the frame in the sequence
    """

    position: FloatArray
    magnitude: float
    members: IntArray
    member_index: IntArray
    ids: IntArray
    membership: FloatArray
    support: int
    region_centre: FloatArray
    region_axes: FloatArray
    region_radii: FloatArray
    frame: int = 0

    def in_region(self, x: npt.ArrayLike) -> bool | npt.NDArray[np.bool_]:
        """Whether points ``x`` ((3,) or (M, 3)) lie inside the confidence ellipsoid."""
        pts = np.asarray(x, dtype=np.float64)
        d = (pts - self.region_centre) @ self.region_axes / self.region_radii
        inside = (d**2).sum(axis=-1) <= 1.0
        return bool(inside) if inside.ndim == 0 else inside

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k in self.__dataclass_fields__:
            val = getattr(self, k)
            out[k] = val.tolist() if isinstance(val, np.ndarray) else val
        return out


MEMBERSHIP_RULES = ("partition", "cover", "strongest", "all")


@dataclass(frozen=True)
class ChargeOptions:
    """Options of :func:`find_charges` and :func:`find_charges_sequence` (validated on
    construction; the Rust binding reads the fields of the same object). Metres.

    Attributes
    ----------
    seeds_per_ray : mean-shift seeds per ray, stratified in depth (Sec 6.2)
    depth_range : ``(min, max)`` depth of those seeds, metres from the eye
    pair_seeds : also seed at the near-intersection of every pair of rays passing within
        ``member_sigma`` bandwidths of each other (narrow bandwidths make basins shorter
        than the spacing of the stratified seeds)
    pair_candidates : also a candidate charge (not a seed; ``support`` 0) at the
        least-squares intersection (weights ``1/(s²h²)``) of every pair of rays within
        ``member_sigma`` bandwidths of it that no mode (nor a closer pair's candidate)
        holds as members: an extension of Sec 6.2 for two rays of one group each 1–3
        bandwidths off their target on opposite sides, whose field has no joint mode. It
        then passes the same membership rule as the modes. Most such pairs are rays aimed
        at different things: see ``RunOptions.pair_bridge`` for how ``socialcam run``
        keeps only those that bridge a group's modes over time
    min_member_depth : a ray is no member of a candidate (mode or pair) closer than this
        (metres) to its eye; a candidate left with fewer than ``min_members`` is rejected
    tol : a climb has converged when a step moves less than ``tol`` metres
    newton : Newton / over-relaxed steps where they raise the field (fast on elongated
        modes); ``False`` runs the plain update of Eq 6.7
    max_iter : iteration cap per climb; climbs that reach it are dropped
    merge_radius : converged climbs closer than this (metres) are one mode
    member_sigma : a ray can be a member of a charge within ``member_sigma`` bandwidths
        (``‖d/h‖ ≤ member_sigma``, Eq 6.2)
    min_members : fewest member rays of a charge (Sec 6.2: more than one ray)
    membership : ``"partition"`` (default) — every ray belongs to at most one charge, by
        likelihood under each charge's perspective-distance kernel (Eq 6.2, gaze model of
        Sec 3.1); each charge sits at the least-squares intersection of its members'
        rays (weights ``1/(s²h²)``, ``s`` the depth), not at a mode of the field; the set
        of charges is the partition of the rays with the highest likelihood minus an
        Occam cost per charge that scales with the bandwidths and distances (prior volume:
        the ``bounds`` box, else a cube of side ``depth_range[1]``; in a sequence, see
        ``pool_frames``) and the mixture weight ``(1 − unattended)/K`` of each attending
        ray among ``K`` charges, found by hard EM from the mean-shift modes (and, in a
        sequence, the neighbouring frames' charges); ``"strongest"`` — winner-take-all: a ray counts only for the
        strongest mode it is within ``member_sigma`` of, and ``min_members`` applies to
        the rays still free; ``"all"`` — the thesis' rule (every mode with
        ``min_members`` rays within ``member_sigma``; a ray may count for several);
        ``"cover"`` (experimental) — each ray belongs to the candidate it fits best and
        the set of charges is the one that explains the rays best (score ``−½Σ‖d/h‖² −
        ½ member_sigma² · #rays left out − charge_penalty · #charges``), each charge at
        the mode of its members' own field
    charge_penalty : ``"cover"`` only: the price of one more charge, in units of ``½‖d/h‖²``
    unattended : ``"partition"`` only: prior probability that a ray attends no charge (it
        then points anywhere); in (0, 1)
    min_magnitude : charges with a weaker field value are rejected
    bounds : ``(lo, hi)`` (3,) corners of a box (a room) outside of which modes are rejected
    pool_frames : ``"partition"`` in :func:`find_charges_sequence` only: pool evidence over
        the ``pool_frames`` frames before and after each frame. A first pass finds every
        frame's charges alone; a second pass gives each charge a position prior made of the
        first pass's charges in those neighbouring frames (half of the prior mass; the other
        half stays uniform over the prior volume, for a charge that is new) and adds their
        positions as candidates. A charge seen near by in time then costs far less than a
        new one, so static or slow targets are found in frames where the frame alone cannot
        tell two close groups from one. ``0``: every frame alone (as :func:`find_charges`)
    drift : how far a charge may move per frame (metres, standard deviation of a random
        walk): a neighbour ``k`` frames away is widened by ``(drift·k)²`` per axis
    joint_window : ``"partition"`` in :func:`find_charges_sequence` with ``pool_frames > 0``
        only: a third pass decides all frames jointly, with one likelihood over the
        sequence. Targets persist (*sources*, moving at most by the ``drift`` random walk)
        and so does attention: each person attends one source or none in every frame, and
        changing target costs ``switch_cost`` nats (free between sources closer than
        ``merge_radius``, the same target); each attending ray gains what it gains in the
        frame rule; a source pays its Occam cost once, not once per frame. Sources start
        as the pooled pass's charges linked over frames; a source's position in a frame
        is the local-linear fit of the rays attending it within ``pool_frames`` frames
        (lag weights of standard deviation ``pool_frames / 2``; a source that the
        narrower fits — ``pool_frames / 4`` down to half a frame — reject in most of its
        frames, a target that turns or bounces within the window like the party's
        table-tennis ball, takes in each frame the widest fit that no narrower one
        rejects); every person's attention is decoded over the whole sequence (Viterbi),
        then every pair of people jointly given the others (two people who must change
        target together, each of whom alone would make no charge), and sources are
        dropped while the likelihood grows. A frame's charges are the
        sources with ``min_members`` rays attending. People are followed by their
        ``ids``. The window resolves frames that the frame alone cannot (two close
        targets seen from far, pairs of near-parallel rays); it cannot split a target
        that no frame found apart. It needs people that can be followed over frames: give
        every frame's rays their person ``ids`` (rows are taken as people otherwise);
        when neither ids nor rows identify a person over frames, use ``False`` (the pooled
        frame rule alone)
    switch_cost : ``joint_window`` only: the cost (nats) of a person changing target,
        ``ln(1/q)`` for a prior change probability ``q`` per frame (default ``ln 30``:
        people keep a target for about 3 s at 10 fps)
    region_level : the confidence region is where the field exceeds this fraction of the
        charge's magnitude (Sec 6.2.1: 0.8)
    region_max_radius : cap on the region's semi-axes, metres
    """

    seeds_per_ray: int = 20
    depth_range: tuple[float, float] = (0.3, 10.0)
    pair_seeds: bool = True
    pair_candidates: bool = False
    min_member_depth: float = 0.0
    tol: float = 1e-5
    newton: bool = True
    max_iter: int = 100
    merge_radius: float = 0.2
    member_sigma: float = 2.5
    min_members: int = 2
    membership: str = "partition"
    charge_penalty: float = 2.0
    unattended: float = 0.05
    min_magnitude: float = 0.0
    bounds: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    pool_frames: int = 10
    drift: float = 0.05
    joint_window: bool = True
    switch_cost: float = float(np.log(30.0))
    region_level: float = 0.8
    region_max_radius: float = 10.0

    def __post_init__(self) -> None:
        # Seeds alone for 10**12 per ray would be terabytes: the core refuses what does not
        # fit in memory; the Python layer caps the integer so it converts to usize.
        check_int(self.seeds_per_ray, "seeds_per_ray", min=1)
        dr = self.depth_range
        if not isinstance(dr, (tuple, list)) or len(dr) != 2:
            raise ValueError(f"depth_range: expected (min, max) in metres, got {dr!r}")
        lo = check_float(dr[0], "depth_range", min=0.0, min_exclusive=True)
        hi = check_float(dr[1], "depth_range", min=lo)
        object.__setattr__(self, "depth_range", (lo, hi))
        for name in ("pair_seeds", "pair_candidates", "newton", "joint_window"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name}: expected True or False, got {getattr(self, name)!r}")
            object.__setattr__(self, name, bool(getattr(self, name)))
        check_float(self.tol, "tol", min=0.0, min_exclusive=True)
        check_int(self.max_iter, "max_iter", min=1)
        check_float(self.merge_radius, "merge_radius", min=0.0)
        check_float(self.min_member_depth, "min_member_depth", min=0.0)
        check_float(self.member_sigma, "member_sigma", min=0.0, min_exclusive=True)
        check_int(self.min_members, "min_members", min=1)
        check_choice(self.membership, "membership", MEMBERSHIP_RULES)
        check_float(self.charge_penalty, "charge_penalty", min=0.0)
        check_float(self.unattended, "unattended", min=0.0, min_exclusive=True, max=1.0)
        if self.unattended >= 1.0:
            raise ValueError(f"unattended: expected a number < 1, got {self.unattended}")
        check_float(self.min_magnitude, "min_magnitude")
        if self.bounds is not None:
            if not isinstance(self.bounds, (tuple, list)) or len(self.bounds) != 2:
                raise ValueError(f"bounds: expected (lo, hi), got {self.bounds!r}")
            blo = as_float_array(self.bounds[0], "bounds", (3,))
            bhi = as_float_array(self.bounds[1], "bounds", (3,))
            if (bhi < blo).any():
                raise ValueError(f"bounds: hi {bhi.tolist()} is below lo {blo.tolist()}")
            object.__setattr__(self, "bounds", (tuple(blo.tolist()), tuple(bhi.tolist())))
        check_int(self.pool_frames, "pool_frames", min=0, max=1 << 31)
        check_float(self.drift, "drift", min=0.0)
        check_float(self.switch_cost, "switch_cost", min=0.0)
        check_float(self.region_level, "region_level", min=0.0, min_exclusive=True, max=1.0)
        if self.region_level >= 1.0:
            raise ValueError(f"region_level: expected a number < 1, got {self.region_level}")
        check_float(self.region_max_radius, "region_max_radius", min=0.0, min_exclusive=True)
        for name in ("tol", "merge_radius", "min_member_depth", "member_sigma", "charge_penalty", "unattended", "min_magnitude",
                     "drift", "switch_cost", "region_level", "region_max_radius"):  # fmt: skip
            object.__setattr__(self, name, float(getattr(self, name)))
        for name in ("seeds_per_ray", "max_iter", "min_members", "pool_frames"):
            object.__setattr__(self, name, int(getattr(self, name)))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _options(options: ChargeOptions | None, overrides: dict[str, Any]) -> ChargeOptions:
    """``options`` (default: ``ChargeOptions()``) with ``overrides`` (field names) applied;
    an unknown name raises ``ValueError`` naming it."""
    return apply_overrides(options, ChargeOptions, overrides)


def _run(frames: Sequence[GazeRays], seed: int, options: ChargeOptions) -> list[list[Charge]]:
    if len(frames) == 0:
        return []
    p = np.concatenate([f.p for f in frames])
    v = np.concatenate([f.v for f in frames])
    h = np.concatenate([f.h for f in frames])
    ids = np.concatenate([f.ids for f in frames])
    counts = np.array([len(f) for f in frames], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    (frame, pos, mag, sup, mem, mem_off, membership, centre, axes, radii) = _core.find_charges(
        p, v, h, offsets, check_seed(seed), options, ids=ids
    )
    # Ragged pieces, split with one numpy call each.
    mem_split = np.split(mem, mem_off[1:-1]) if len(frame) else []
    n_per = counts[frame]
    ms_split = np.split(membership, np.cumsum(n_per)[:-1]) if len(frame) else []
    out: list[list[Charge]] = [[] for _ in frames]
    for k in range(len(frame)):
        f = int(frame[k])
        ids = frames[f].ids
        out[f].append(
            Charge(
                position=readonly(pos[k]),
                magnitude=float(mag[k]),
                members=readonly(ids[mem_split[k]]),
                member_index=readonly(mem_split[k]),
                ids=ids,
                membership=readonly(ms_split[k]),
                support=int(sup[k]),
                region_centre=readonly(centre[k]),
                region_axes=readonly(axes[k]),
                region_radii=readonly(radii[k]),
                frame=f,
            )
        )
    return out


def find_charges(
    rays: GazeRays,
    *,
    seed: int = 0,
    options: ChargeOptions | None = None,
    **overrides: Any,
) -> list[Charge]:
    """The social charges of one frame (Sec 6.1.2).

    Seeds are drawn along every ray (``seeds_per_ray`` stratified depths in
    ``depth_range`` metres, from ``seed``) and at the near-intersections of ray pairs
    (``pair_seeds``); each climbs the field with the update of Eq 6.7 (accelerated by
    Newton steps with ``newton``) until it moves less than ``tol`` metres; climbs still
    moving after ``max_iter`` iterations are dropped; modes closer than ``merge_radius``
    are merged in seed order. Which modes are charges, and which rays are their members,
    is decided by ``membership`` (see :class:`ChargeOptions`; the default ``"partition"``
    gives each ray to at most one charge and places each charge at the intersection of
    its members' rays, ``"all"`` is the thesis' rule). Give the room as ``bounds``: it
    rejects modes outside it and sets the prior volume of the ``"partition"`` rule.
    ``bounds=(lo, hi)`` rejects modes outside a box (a room); ``min_magnitude`` weak modes.

    Parameters
    ----------
    rays : the frame's gaze rays
    seed : seed of the random seed depths
    options : a :class:`ChargeOptions` (default ``ChargeOptions()``)
    **overrides : fields of :class:`ChargeOptions` to change, e.g. ``membership="all"``

    Returns
    -------
    list of :class:`Charge`, strongest first. A single ray, or rays that never meet, give
    an empty list. Same ``seed``, same answer, whatever the number of threads.

    Raises
    ------
    ValueError
        Bad rays or options; eyes so far from the origin that float64 rounds them by more
        than a thousandth of their spread (1e15 m for a room: the charges would move by
        the rounding, or vanish).
    """
    r = _rays(rays)
    return _run([r], seed, _options(options, overrides))[0]


def find_charges_sequence(
    frames: Sequence[GazeRays],
    *,
    seed: int = 0,
    options: ChargeOptions | None = None,
    **overrides: Any,
) -> list[list[Charge]]:
    """:func:`find_charges` on every frame in one parallel core call, pooling evidence
    over neighbouring frames.

    With ``membership="partition"`` (the default) and ``pool_frames > 0`` (default 10) a
    second pass gives each frame's charges a position prior made of the charges found in
    the ``pool_frames`` frames before and after it (see :class:`ChargeOptions`): static
    or slow targets are then resolved in frames where the frame alone cannot tell two
    close groups from one. With ``joint_window=True`` (the default) a third pass decides the
    charges of all frames jointly: sources persist, people change target rarely (``switch_cost``), and a
    frame is read with its neighbours; people are followed over frames by their ``ids``.
    With ``pool_frames=0`` (or another rule) frame ``t`` of the
    result equals ``find_charges(frames[t], seed=seed, ...)``. Each :class:`Charge` has
    ``frame = t``. ``options`` and ``overrides`` as for :func:`find_charges`.
    """
    opts = _options(options, overrides)
    fr = [_rays(f, f"frames[{i}]") for i, f in enumerate(check_sequence(frames, "frames"))]
    return _run(fr, seed, opts)


@dataclass(frozen=True)
class ChargeTrack:
    """One social charge followed through time.

    Attributes
    ----------
    id : track id (0, 1, ... in order of first appearance)
    frames : (K,) frame indices, increasing (gaps where the group had dissolved)
    positions : (K, 3) charge positions, metres
    magnitudes : (K,) field values
    members : per frame, the person ids of the members
    people : (J,) the person ids indexing ``feature``
    feature : (J,) centre of the track's membership-feature cluster
    core_members : person ids that are members in at least half of the track's frames
    """

    id: int
    frames: IntArray
    positions: FloatArray
    magnitudes: FloatArray
    members: tuple[IntArray, ...]
    people: IntArray
    feature: FloatArray
    core_members: IntArray

    def __len__(self) -> int:
        return int(self.frames.shape[0])

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "frames": self.frames.tolist(),
            "positions": self.positions.tolist(),
            "magnitudes": self.magnitudes.tolist(),
            "members": [m.tolist() for m in self.members],
            "people": self.people.tolist(),
            "feature": self.feature.tolist(),
            "core_members": self.core_members.tolist(),
        }


def track_charges(
    charges_per_frame: Sequence[Sequence[Charge]],
    *,
    bandwidth: float = 0.3,
    max_iter: int = 300,
    bin_seeding: bool = True,
    max_gap: int = 5,
    min_length: int = 10,
) -> list[ChargeTrack]:
    """Links charges over frames by their membership features (Sec 6.1.3).

    Every charge's membership (Eq 6.8) is laid out over all person ids of the sequence
    (zero for people absent from its frame) and the features are clustered by classic
    mean-shift (flat kernel of radius ``bandwidth``) in the core. A cluster is a track:
    the same group keeps its id while its charge moves, and gets it back when it dissolves
    and re-forms. A track holds at most one charge per frame (the one closest to the
    cluster centre); other charges of that cluster in that frame are left out.

    Parameters
    ----------
    charges_per_frame : ``find_charges_sequence`` output; entry ``t`` is frame ``t``
    bandwidth : flat-kernel radius in feature space (unit vectors: two disjoint groups are
        √2 apart)
    max_iter : iteration cap of each mean-shift climb
    bin_seeding : one climb per occupied cell of a grid of spacing ``bandwidth``
    max_gap : a track's charges at most ``max_gap`` missing frames apart form one run; a
        longer gap (the group dissolved) starts a new run of the same track
    min_length : runs with fewer charges are dropped: the short clusters that transitions
        make while people switch targets one by one (default 10 frames, 1 s at 10 fps).
        ``min_length=1`` keeps everything (the thesis' plain clustering)

    Returns
    -------
    list of :class:`ChargeTrack` sorted by id
    """
    bw = check_float(bandwidth, "bandwidth", min=0.0, min_exclusive=True)
    it = check_int(max_iter, "max_iter", min=1)
    gap = check_int(max_gap, "max_gap", min=0)
    length = check_int(min_length, "min_length", min=1)
    if not isinstance(bin_seeding, (bool, np.bool_)):
        raise ValueError(f"bin_seeding: expected True or False, got {bin_seeding!r}")
    per_frame = check_sequence(charges_per_frame, "charges_per_frame")
    flat = [
        (t, c)
        for t, cs in enumerate(per_frame)
        for c in check_sequence(cs, f"charges_per_frame[{t}]")
    ]
    seen: dict[int, int] = {}
    for t, c in flat:
        if not isinstance(c, Charge):
            raise ValueError(f"charges_per_frame[{t}]: expected Charge objects, got {c!r}")
        i = seen[t] = seen.get(t, -1) + 1
        name = f"charges_per_frame[{t}][{i}]"
        ids, m = np.asarray(c.ids), np.asarray(c.membership)
        if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer):
            raise ValueError(f"{name}.ids: expected (N,) integer person ids, got {ids.shape}")
        if m.shape != ids.shape:
            raise ValueError(
                f"{name}.membership: expected one value per id {ids.shape}, got {m.shape}"
            )
        if not np.isfinite(m).all():
            raise ValueError(f"{name}.membership: contains NaN or infinite values")
        if len(np.unique(ids)) != len(ids):
            raise ValueError(f"{name}.ids: a person appears twice")
    if not flat:
        return []
    people = np.unique(np.concatenate([c.ids for _, c in flat]))
    feats = np.zeros((len(flat), len(people)))
    for k, (_, c) in enumerate(flat):
        feats[k, np.searchsorted(people, c.ids)] = c.membership
    frames = np.array([t for t, _ in flat], dtype=np.int64)
    track, centres = _core.track_charges(
        feats,
        frames,
        bandwidth=bw,
        max_iter=it,
        bin_seeding=bool(bin_seeding),
        max_gap=gap,
        min_length=length,
    )
    out: list[ChargeTrack] = []
    for tid in range(centres.shape[0]):
        ks = np.flatnonzero(track == tid)
        ks = ks[np.argsort(frames[ks], kind="stable")]
        members = tuple(readonly(flat[k][1].members.copy()) for k in ks)
        allm = np.concatenate(members) if members else np.zeros(0, np.int64)
        uniq, cnt = np.unique(allm, return_counts=True)
        out.append(
            ChargeTrack(
                id=tid,
                frames=readonly(frames[ks].copy()),
                positions=readonly(np.array([flat[k][1].position for k in ks]).reshape(-1, 3)),
                magnitudes=readonly(np.array([flat[k][1].magnitude for k in ks])),
                members=members,
                people=readonly(people.astype(np.int64)),
                feature=readonly(centres[tid].copy()),
                core_members=readonly(uniq[cnt * 2 >= len(ks)].astype(np.int64)),
            )
        )
    return out


def plot_saliency(
    rays: GazeRays,
    lo: npt.ArrayLike,
    hi: npt.ArrayLike,
    *,
    shape: int | Sequence[int] = 96,
    axis: int = 2,
    charges: Sequence[Charge] = (),
    truth: npt.ArrayLike | None = None,
    ax: Axes | None = None,
) -> Figure:
    """Maximum-intensity projection of the saliency field along ``axis`` (Fig 6.2c), with
    the rays, the charges (with their confidence ellipses projected) and optional true
    targets ``truth (T, 3)``. Returns the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    if axis not in (0, 1, 2):
        raise ValueError(f"axis: expected 0, 1 or 2, got {axis!r}")
    r = _rays(rays)
    g = saliency_grid(r, lo, hi, shape=shape)
    mip = g.max(axis=axis)
    keep = [a for a in range(3) if a != axis]
    axes_xyz = grid_axes(lo, hi, shape)
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 5))
    else:
        fig = ax.figure  # type: ignore[assignment]
    u, w = axes_xyz[keep[0]], axes_xyz[keep[1]]
    im = ax.imshow(
        mip.T, origin="lower", extent=(u[0], u[-1], w[0], w[-1]), cmap="magma", aspect="equal"
    )
    fig.colorbar(im, ax=ax, label="social saliency (MIP)")
    span = float(np.linalg.norm(np.asarray(hi, float) - np.asarray(lo, float)))
    for i in range(len(r)):
        a = r.p[i][keep]
        b = (r.p[i] + r.v[i] * span)[keep]
        ax.plot([a[0], b[0]], [a[1], b[1]], color="cyan", lw=0.6, alpha=0.6)
        ax.plot(*a, "o", color="cyan", ms=3)
    theta = np.linspace(0, 2 * np.pi, 60)
    for c in charges:
        ax.plot(*c.position[keep], "x", color="lime", ms=8, mew=2)
        # Outline of the ellipsoid's projection: project a dense set of surface points.
        s = np.stack(
            [np.outer(np.cos(theta), np.sin(theta)), np.outer(np.sin(theta), np.sin(theta)),
             np.outer(np.ones_like(theta), np.cos(theta))], axis=-1,
        ).reshape(-1, 3)  # fmt: skip
        pts = c.region_centre + (s * c.region_radii) @ c.region_axes.T
        hull = _convex_hull(pts[:, keep])
        ax.add_patch(Polygon(hull, fill=False, ec="lime", lw=1))
    if truth is not None:
        t = as_float_array(truth, "truth", (None, 3))
        ax.plot(t[:, keep[0]], t[:, keep[1]], "+", color="white", ms=10, mew=1.5)
    names = "xyz"
    ax.set_xlabel(f"{names[keep[0]]} (m)")
    ax.set_ylabel(f"{names[keep[1]]} (m)")
    ax.set_xlim(u[0], u[-1])
    ax.set_ylim(w[0], w[-1])
    ax.set_title(f"social saliency field, {len(r)} rays, {len(charges)} charges")
    return fig  # type: ignore[return-value]


def _cross2(a: FloatArray, b: FloatArray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _convex_hull(pts: FloatArray) -> FloatArray:
    """Monotone-chain convex hull of 2D points (for drawing projected ellipsoids)."""
    p = pts[np.lexsort((pts[:, 1], pts[:, 0]))]

    def half(seq: FloatArray) -> list[FloatArray]:
        h: list[FloatArray] = []
        for q in seq:
            while len(h) >= 2 and _cross2(h[-1] - h[-2], q - h[-2]) <= 0:
                h.pop()
            h.append(q)
        return h

    lower, upper = half(p), half(p[::-1])
    return np.array(lower[:-1] + upper[:-1])


def plot_charge_tracks(
    tracks: Sequence[ChargeTrack],
    *,
    times: npt.ArrayLike | None = None,
    truth: npt.ArrayLike | None = None,
    legend_min_length: int = 10,
) -> Figure:
    """Charge tracks over time (Fig 6.3b, 6.4a): x, y, z of every track against frame (or
    ``times``, seconds), one colour per track id, gaps where a group had dissolved; plus a
    top view. ``truth (F, T, 3)`` or ``(T, 3)`` draws true target positions dotted.

    The legend (outside the axes) names each track with at least ``legend_min_length``
    charges and its core members; shorter tracks are drawn thin and grey, unnamed."""
    import matplotlib.pyplot as plt

    n_min = check_int(legend_min_length, "legend_min_length", min=1)
    tracks = check_sequence(tracks, "tracks")
    if not all(isinstance(tr, ChargeTrack) for tr in tracks):
        raise ValueError("tracks: expected ChargeTrack objects (from track_charges)")
    fig, axs = plt.subplots(1, 4, figsize=(17, 4.2), layout="constrained")
    cmap = plt.get_cmap("tab10")
    tt = None if times is None else as_float_array(times, "times", (None,))
    handles = []
    for tr in tracks:
        real = len(tr) >= n_min
        col = cmap(tr.id % 10) if real else (0.6, 0.6, 0.6)
        lw = 1.6 if real else 0.8
        x = tr.frames.astype(np.float64) if tt is None else tt[tr.frames]
        # Break the line at gaps so dissolution shows.
        gaps = np.flatnonzero(np.diff(tr.frames) > 1) + 1
        for a in range(3):
            for seg_x, seg_y in zip(
                np.split(x, gaps), np.split(tr.positions[:, a], gaps), strict=True
            ):
                (line,) = axs[a].plot(seg_x, seg_y, color=col, lw=lw)
        if real:
            who = ", ".join(str(i) for i in tr.core_members.tolist())
            line.set_label(f"track {tr.id}: people {who} ({len(tr)} frames)")
            handles.append(line)
        axs[3].plot(tr.positions[:, 0], tr.positions[:, 1], ".", color=col, ms=2)
    if truth is not None:
        T = np.asarray(truth, dtype=np.float64)
        if T.ndim == 2:
            for a in range(3):
                for t in T:
                    axs[a].axhline(t[a], color="k", ls=":", lw=1)
            axs[3].plot(T[:, 0], T[:, 1], "k+", ms=10)
        else:
            x = np.arange(T.shape[0], dtype=np.float64) if tt is None else tt
            for a in range(3):
                axs[a].plot(x, T[:, :, a], "k:", lw=1)
            axs[3].plot(T[..., 0].ravel(), T[..., 1].ravel(), "k,", alpha=0.3)
        (truth_line,) = axs[0].plot([], [], "k:", lw=1, label="true targets")
        handles.append(truth_line)
    for a, name in enumerate("xyz"):
        axs[a].set_xlabel("frame" if tt is None else "time (s)")
        axs[a].set_ylabel(f"{name} (m)")
        axs[a].set_title(f"{name} of each charge")
    axs[3].set_xlabel("x (m)")
    axs[3].set_ylabel("y (m)")
    axs[3].set_aspect("equal", adjustable="datalim")
    axs[3].set_title("top view")
    if handles:
        fig.legend(handles=handles, loc="outside right upper", fontsize=8, frameon=False)
    n_real = sum(len(tr) >= n_min for tr in tracks)
    fig.suptitle(
        f"social charge tracks: {n_real} of ≥ {n_min} frames"
        + (f" (+{len(tracks) - n_real} shorter, grey)" if n_real < len(tracks) else "")
    )
    return fig
