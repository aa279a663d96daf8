"""The gaze field (thesis Chapter 7): predicting where people look.

Social charges (Chapter 6) pull the primary gaze of the members of a scene like an
electric field — selectively, the strongest charge wins (Eq 7.6) — and the gaze
direction at any place and time follows the von Mises–Fisher mixture of Eq 7.7 with
weights ``πᵢ ∝ ‖Sᵢ(x)‖ = qᵢ/‖rᵢ − x‖²``. :meth:`GazeField.fit` estimates the time-varying
charges by EM (Eq 7.10–7.14) in windows where the number of charges is constant, with a
temporal filter on the charge motion; :meth:`GazeField.predict` gives the most likely
direction (Eq 7.3) anywhere. :func:`cross_validate_gaze` measures predictive accuracy
against the radial-basis regression baseline of Sec 7.4.1, :func:`detect_anomalies` flags
members who follow no charge, and :func:`fuse_gaze` is the filter of Sec 7.4.2.

Frames
------
A *frame* is the gaze of the members at one instant: a ``socialcam.GazeRays`` (``p``,
``v``, ``h``, ``ids``), any object with ``p``, ``v`` (and optionally ``h``, ``ids``)
attributes, or a tuple ``(p, v)``, ``(p, v, h)`` or ``(p, v, h, ids)``. ``p (N, 3)`` eye
centres in metres, ``v (N, 3)`` unit primary gaze directions, ``h`` bandwidths (radians at
unit distance), ``ids (N,)`` person ids (default ``0..N-1``) that identify members across
frames.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from socialcam import _core
from socialcam._validate import (
    FloatArray,
    apply_overrides,
    as_float_array,
    as_int_array,
    check_bool,
    check_choice,
    check_float,
    check_int,
    check_rounding,
    check_seed,
    readonly,
)
from socialcam.errors import ConvergenceError, DegenerateError

IntArray = npt.NDArray[np.int64]

#: Tolerance on ``‖v‖ − 1`` (same as the core).
UNIT_TOLERANCE = 1e-6

_I64_MAX = 2**63 - 1

#: Two charges of a window closer than this (metres) in every frame are one charge: even a
#: precise gaze (h = 0.01 rad) cannot tell them apart from 1 m away.
COINCIDE = 0.01


@dataclass(frozen=True)
class GazeFieldOptions:
    """Options of :meth:`GazeField.fit` (validated on construction; the Rust binding reads
    the EM fields of the same object). Angles in radians.

    Attributes
    ----------
    kappa : fixed vMF concentration ``κ > 0``; ``None`` estimates it per window by maximum
        likelihood (starting at ``kappa_init``, default ``1/mean(h²)``: the gaze model's
        bandwidth, Sec 3.1)
    kappa_init : starting ``κ`` of the estimate (``None``: from the rays' bandwidths)
    lambda_g : weight ``λ_g ≥ 0`` of the temporal filter ``G`` (Eq 7.14), per frame
    temporal_filter : ``"velocity"`` (``Σ‖r(t) − r(t−1)‖²``) or ``"acceleration"``
        (``Σ‖2r(t) − r(t−1) − r(t+1)‖²``), thesis footnote 3
    membership : ``"frame"`` (default) — re-estimated at every frame (Eq 7.11);
        ``"window"`` — one membership per member and window (Eq 7.14). In a window that
        spans a change of groups, one membership per window gives a member's rays after
        the change to its old charge, and every EM iteration hardens that: on the meeting
        scene (seed 0) the worst charge error grows from 18 cm after one iteration to
        1.06 m at convergence, while per-frame memberships stay at 6–14 cm
    max_angle : radians in ``(0, π/2)``; rays further than this from a charge (or with it
        behind them) add a constant to the M-step cost instead of ``d = ∞``
    min_window : count runs shorter than this many frames are merged into a neighbour
    max_iter, tol : EM cap and convergence tolerance (metres, and relative for ``κ``)
    inner_iterations : M-step iterations per EM iteration
    seed : seed of the charge finder's random seeds (``n_charges=None``)
    charge_options : keyword arguments for :func:`socialcam.find_charges_sequence`; the
        EM starts from modes of the saliency field, so ``membership`` defaults to
        ``"strongest"`` here (the ``"partition"`` rule pairs stray rays with members of
        groups, which costs the field 10° of cross-validated gaze error when two members
        look at random)
    """

    kappa: float | None = None
    kappa_init: float | None = None
    lambda_g: float = 1.0
    temporal_filter: Literal["velocity", "acceleration"] = "velocity"
    membership: Literal["window", "frame"] = "frame"
    max_angle: float = float(np.pi / 6)
    min_window: int = 3
    max_iter: int = 200
    tol: float = 1e-6
    inner_iterations: int = 5
    seed: int = 0
    charge_options: Mapping[str, Any] | None = None

    def __post_init__(self) -> None:
        if self.kappa is not None:
            object.__setattr__(
                self, "kappa", check_float(self.kappa, "kappa", min=0.0, min_exclusive=True)
            )
        if self.kappa_init is not None:
            object.__setattr__(
                self,
                "kappa_init",
                check_float(self.kappa_init, "kappa_init", min=0.0, min_exclusive=True),
            )
        object.__setattr__(self, "lambda_g", check_float(self.lambda_g, "lambda_g", min=0.0))
        check_choice(self.temporal_filter, "temporal_filter", ("velocity", "acceleration"))
        check_choice(self.membership, "membership", ("window", "frame"))
        a = check_float(self.max_angle, "max_angle", min=0.0, min_exclusive=True)
        if not a < np.pi / 2:
            raise ValueError(f"max_angle: expected radians in (0, π/2), got {a}")
        object.__setattr__(self, "max_angle", a)
        object.__setattr__(self, "min_window", check_int(self.min_window, "min_window", min=1))
        object.__setattr__(self, "max_iter", check_int(self.max_iter, "max_iter", min=1))
        object.__setattr__(self, "tol", check_float(self.tol, "tol", min=0.0, min_exclusive=True))
        object.__setattr__(
            self,
            "inner_iterations",
            check_int(self.inner_iterations, "inner_iterations", min=1, max=10_000),
        )
        object.__setattr__(self, "seed", check_seed(self.seed))
        if self.charge_options is not None and not isinstance(self.charge_options, Mapping):
            raise ValueError(
                f"charge_options: expected a mapping of find_charges options, got "
                f"{type(self.charge_options).__name__}"
            )


@dataclass(frozen=True)
class _Flat:
    p: FloatArray
    v: FloatArray
    h: FloatArray
    ids: IntArray
    offsets: IntArray

    @property
    def n_frames(self) -> int:
        return len(self.offsets) - 1

    def frame_of_ray(self) -> IntArray:
        return np.repeat(np.arange(self.n_frames), np.diff(self.offsets)).astype(np.int64)

    def select(self, keep: npt.NDArray[np.bool_]) -> _Flat:
        counts = np.bincount(self.frame_of_ray()[keep], minlength=self.n_frames)
        off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return _Flat(self.p[keep], self.v[keep], self.h[keep], self.ids[keep], off)

    def to_frames(self) -> list[tuple[FloatArray, FloatArray, FloatArray, IntArray]]:
        o = self.offsets
        return [
            (self.p[a:b], self.v[a:b], self.h[a:b], self.ids[a:b]) for a, b in itertools.pairwise(o)
        ]


def _frame_parts(f: object, k: int) -> tuple[Any, Any, Any, Any]:
    if hasattr(f, "p") and hasattr(f, "v"):
        return f.p, f.v, getattr(f, "h", None), getattr(f, "ids", None)
    if isinstance(f, (tuple, list)) and 2 <= len(f) <= 4:
        parts = [*list(f), None, None][:4]
        return parts[0], parts[1], parts[2], parts[3]
    raise ValueError(
        f"frames[{k}]: expected GazeRays, an object with p and v, or a tuple (p, v[, h[, ids]])"
    )


def _flatten(frames: Sequence[object], default_h: float = 0.1) -> _Flat:
    if isinstance(frames, (str, bytes)) or not isinstance(frames, Sequence):
        raise ValueError(
            f"frames: expected a sequence of frames (GazeRays or (p, v) tuples), got "
            f"{type(frames).__name__}"
        )
    if len(frames) == 0:
        raise ValueError("frames: need at least one frame")
    ps, vs, hs, ids = [], [], [], []
    counts = []
    for k, f in enumerate(frames):
        p_, v_, h_, i_ = _frame_parts(f, k)
        p = as_float_array(p_, f"frames[{k}].p", (None, 3))
        n = p.shape[0]
        v = as_float_array(v_, f"frames[{k}].v", (n, 3))
        norms = np.linalg.norm(v, axis=1)
        if (np.abs(norms - 1.0) > UNIT_TOLERANCE).any():
            j = int(np.argmax(np.abs(norms - 1.0)))
            raise ValueError(f"frames[{k}].v: direction {j} has norm {norms[j]:.6g}, not 1")
        if h_ is None:
            h = np.full(n, default_h)
        else:
            h = as_float_array(h_, f"frames[{k}].h")
            if h.shape not in ((), (1,), (n,)):
                raise ValueError(
                    f"frames[{k}].h: expected one bandwidth or {n} (one per ray), got shape "
                    f"{h.shape}"
                )
            h = np.broadcast_to(h, (n,)).astype(np.float64)
        if (h <= 0).any():
            raise ValueError(f"frames[{k}].h: bandwidths must be > 0")
        if i_ is None:
            i = np.arange(n, dtype=np.int64)
        else:
            i = np.asarray(i_)
            if i.shape != (n,) or not np.issubdtype(i.dtype, np.integer):
                raise ValueError(f"frames[{k}].ids: expected {n} integer ids")
            if n and np.issubdtype(i.dtype, np.unsignedinteger) and int(i.max()) > _I64_MAX:
                # int64 is the id type throughout: a larger uint64 would wrap to a negative
                # id (and could collide with another person's).
                raise ValueError(
                    f"frames[{k}].ids: person ids must fit in int64, got {int(i.max())}"
                )
            i = i.astype(np.int64)
            if len(np.unique(i)) != n:
                raise ValueError(f"frames[{k}].ids: a person appears twice")
        ps.append(p)
        vs.append(v)
        hs.append(h)
        ids.append(i)
        counts.append(n)
    off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    eyes = np.concatenate(ps).reshape(-1, 3)
    check_rounding(eyes, "frames[*].p", "the eyes' spread")
    return _Flat(
        eyes,
        np.concatenate(vs).reshape(-1, 3),
        np.concatenate(hs),
        np.concatenate(ids).astype(np.int64),
        off,
    )


def _per_row(a: FloatArray, name: str, n: int) -> FloatArray:
    """A number or an ``(n,)`` array, as ``(n,)``."""
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] not in (1, n)):
        raise ValueError(f"{name}: expected a number or shape ({n},), got {a.shape}")
    return np.broadcast_to(a, (n,))


def _times(times: npt.ArrayLike | None, n: int) -> FloatArray:
    if times is None:
        return np.arange(n, dtype=np.float64)
    t = as_float_array(times, "times", (n,))
    if (np.diff(t) <= 0).any():
        raise ValueError("times: must increase strictly")
    return t


@dataclass(frozen=True)
class GazeField:
    """A time-varying gaze field fitted to observed gaze (Eq 7.9).

    Attributes
    ----------
    times : (F,) seconds of the frames
    positions : (F, I, 3) charge positions in metres; NaN rows where a frame has fewer
        charges than ``I`` (the largest count)
    magnitudes : (F, I) charge magnitudes ``qᵢ(t) = Σⱼ γᵢⱼ`` (expected number of members
        looking at the charge), NaN where no charge
    kappa : (F,) vMF concentration of each frame's window; NaN where the frame has no
        field (no charges)
    windows : (W, 3) int64 rows ``[start, end, n_charges]``: frames ``start..end`` hold
        ``n_charges`` charges (Sec 7.3.1)
    people : (J,) person ids of the members, indexing ``membership``'s second axis
    membership : (W, J, I) window memberships ``γ`` of Eq 7.14 (NaN for charges beyond a
        window's count)
    window_log_likelihood : (W,) ``Σₜ ln L`` of Eq 7.10 per window at the fitted charges
    iterations : (W,) EM iterations per window
    converged : (W,) whether each window's EM met its tolerance
    """

    times: FloatArray
    positions: FloatArray
    magnitudes: FloatArray
    kappa: FloatArray
    windows: IntArray
    people: IntArray
    membership: FloatArray
    window_log_likelihood: FloatArray
    iterations: IntArray
    converged: npt.NDArray[np.bool_]

    # ------------------------------------------------------------------ fitting
    @classmethod
    def fit(
        cls,
        frames: Sequence[object],
        n_charges: int | npt.ArrayLike | None = None,
        *,
        times: npt.ArrayLike | None = None,
        init: Literal["charges", "pairs"] | npt.ArrayLike | None = None,
        options: GazeFieldOptions | None = None,
        strict: bool = False,
        **overrides: Any,
    ) -> GazeField:
        """Estimates the time-varying social charges from observed gaze by EM.

        Parameters
        ----------
        frames : sequence of F frames (see the module docs)
        n_charges : ``None`` — take the count per frame from the social charges found by
            :func:`socialcam.find_charges_sequence` (Chapter 6), which also start the EM;
            an int — that many charges in every frame; or an (F,) integer array of counts.
            Frames with 0 charges get no field. A window cannot hold more charges than
            the people seen in it (``ValueError``).
        times : (F,) increasing seconds (default ``0..F-1``)
        init : ``"charges"`` (Chapter 6 charges; the default when ``n_charges`` is None),
            ``"pairs"`` (greedy pick among pairwise ray intersections; the default
            otherwise), or an (F, I, 3) array of starting positions (NaN-padded)
        options : :class:`GazeFieldOptions`
        strict : raise :class:`socialcam.ConvergenceError` when a window's EM hit
            ``max_iter`` (otherwise ``converged`` says so)
        **overrides : fields of :class:`GazeFieldOptions` to change, e.g. ``kappa=20.0``

        Warns
        -----
        RuntimeWarning
            when two charges of a window coincide at the end (within :data:`COINCIDE`
            metres in every frame: fewer distinct charges than requested); that window is
            reported as not converged.

        Raises
        ------
        ValueError
            malformed frames (NaN, non-unit ``v``), ``κ ≤ 0``, zero charges everywhere,
            more charges than people in a window, bad options
        socialcam.DegenerateError
            a window in which no two rays meet in front of the eyes (nothing to start from)
        """
        strict = check_bool(strict, "strict")
        opts = apply_overrides(options, GazeFieldOptions, overrides)
        flat = _flatten(frames)
        n_frames = flat.n_frames
        t = _times(times, n_frames)
        if opts.kappa_init is None:
            opts = replace(opts, kappa_init=float(np.clip(1.0 / np.mean(flat.h**2), 1.0, 1e4)))
        kappa_init = float(opts.kappa_init)  # type: ignore[arg-type]
        charge_options = dict(opts.charge_options or {})

        candidates = None
        if n_charges is None:
            counts, candidates = _charges_from_chapter6(flat, opts.seed, charge_options)
            if init is None:
                init = "charges"
        else:
            c = np.asarray(n_charges)
            if c.ndim == 0:
                if check_int(n_charges, "n_charges") < 1:
                    raise ValueError(
                        f"n_charges: zero or negative social charges ({n_charges!r}): the gaze "
                        "field needs at least one charge"
                    )
                counts = np.full(n_frames, int(c), dtype=np.int64)
            else:
                if (
                    c.shape != (n_frames,)
                    or not np.issubdtype(c.dtype, np.integer)
                    or (c < 0).any()
                ):
                    raise ValueError(f"n_charges: expected {n_frames} non-negative integer counts")
                counts = c.astype(np.int64)
            if init is None:
                init = "pairs"
        windows = _core.gaze_split_windows(counts, opts.min_window)
        if (windows[:, 2] == 0).all():
            raise ValueError("n_charges: zero social charges in every frame: no field to fit")
        fr_of_ray = flat.frame_of_ray()
        for a, b, n in windows:
            people_w = len(np.unique(flat.ids[(fr_of_ray >= a) & (fr_of_ray < b)]))
            if n > people_w:
                raise ValueError(
                    f"n_charges: {n} charges in frames {a}..{b - 1}, where only {people_w} "
                    "people are seen: each charge needs someone looking at it"
                )

        if isinstance(init, str):
            if init == "charges":
                if candidates is None:
                    _, candidates = _charges_from_chapter6(flat, opts.seed, charge_options)
                start = _core.gaze_init(flat.p, flat.v, flat.offsets, windows, 0.25, candidates)
            elif init == "pairs":
                k0 = opts.kappa if opts.kappa is not None else kappa_init
                sigma = float(np.clip(1.0 / np.sqrt(k0), 0.05, 0.6))
                start = _core.gaze_init(flat.p, flat.v, flat.offsets, windows, sigma)
            else:
                raise ValueError(f"init: expected 'charges', 'pairs' or an array, got {init!r}")
        else:
            imax = int(windows[:, 2].max())
            start = as_float_array(init, "init", (n_frames, None, 3), allow_nan=True)
            if start.shape[1] < imax:
                raise ValueError(f"init: needs room for {imax} charges per frame")
            start = _fill_window_init(start, windows)

        people, dense = np.unique(flat.ids, return_inverse=True)
        (pos, mag, kap_w, memb, _resp, ll, iters, conv) = _core.gaze_em(
            flat.p,
            flat.v,
            dense.astype(np.int64),
            flat.offsets,
            windows,
            np.ascontiguousarray(start),
            opts,
        )
        conv = np.array(conv, dtype=bool)
        for w, (a, b, n) in enumerate(windows):
            if n < 2:
                continue
            x = pos[a:b, :n]
            d = np.linalg.norm(x[:, :, None] - x[:, None, :], axis=-1).max(axis=0)
            close = np.argwhere(np.triu(d <= COINCIDE, 1))
            if len(close):
                i, j = close[0]
                conv[w] = False
                warnings.warn(
                    f"n_charges: charges {i} and {j} of frames {a}..{b - 1} coincide: the "
                    f"gaze supports fewer than {n} distinct charges there",
                    RuntimeWarning,
                    stacklevel=2,
                )
        if strict and not conv[windows[:, 2] > 0].all():
            w = int(np.flatnonzero(~conv & (windows[:, 2] > 0))[0])
            a, b, _n = windows[w]
            raise ConvergenceError(
                f"the EM of frames {a}..{b - 1} did not converge in max_iter={opts.max_iter} "
                "iterations"
            )
        kap_f = np.full(n_frames, np.nan)
        for w, (a, b, _n) in enumerate(windows):
            kap_f[a:b] = kap_w[w]
        return cls(
            times=readonly(t),
            positions=readonly(pos),
            magnitudes=readonly(mag),
            kappa=readonly(kap_f),
            windows=readonly(windows),
            people=readonly(people.astype(np.int64)),
            membership=readonly(memb),
            window_log_likelihood=readonly(ll),
            iterations=readonly(iters),
            converged=readonly(conv),
        )

    # ------------------------------------------------------------------ queries
    @property
    def n_charges(self) -> IntArray:
        """(F,) number of charges per frame."""
        return (~np.isnan(self.positions[..., 0])).sum(axis=1).astype(np.int64)

    @property
    def charges(self) -> list[FloatArray]:
        """Charge positions per frame: a list of F arrays ``(I_t, 3)`` in metres."""
        return [p[~np.isnan(p[:, 0])] for p in self.positions]

    def frame_index(self, t: float | npt.ArrayLike | None, n: int) -> IntArray:
        """Frame of each of ``n`` queries: the frame nearest in time to ``t`` (scalar or
        ``(n,)``); ``t=None`` only for a single-frame field.

        The field is only known over the fitted frames: a time more than half a frame
        spacing before the first frame or after the last raises ``ValueError`` (it used to
        be clamped silently to the nearest end)."""
        n = check_int(n, "n", min=0)
        if t is None:
            if len(self.times) != 1:
                raise ValueError("t: required for a field over several frames")
            return np.zeros(n, dtype=np.int64)
        ta_ = as_float_array(t, "t")
        if ta_.ndim > 1 or (ta_.ndim == 1 and ta_.shape[0] not in (1, n)):
            raise ValueError(f"t: expected a number or shape ({n},), got {ta_.shape}")
        ta = np.broadcast_to(ta_, (n,))
        half = 0.5 * float(np.median(np.diff(self.times))) if len(self.times) > 1 else 0.0
        lo, hi = self.times[0] - half, self.times[-1] + half
        if n and (
            ta.min() < lo - 1e-9 * max(1.0, abs(lo)) or ta.max() > hi + 1e-9 * max(1.0, abs(hi))
        ):
            bad = float(ta[np.argmax((ta < lo) | (ta > hi))])
            raise ValueError(
                f"t: {bad} s is outside the fitted frames [{self.times[0]:.6g}, "
                f"{self.times[-1]:.6g}] s; the field is not defined there"
            )
        idx = np.clip(np.searchsorted(self.times, ta), 1, max(len(self.times) - 1, 1))
        if len(self.times) == 1:
            return np.zeros(n, dtype=np.int64)
        left = self.times[idx - 1]
        right = self.times[idx]
        return np.where(ta - left <= right - ta, idx - 1, idx).astype(np.int64)

    def _state(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        return (
            np.ascontiguousarray(self.positions),
            np.ascontiguousarray(np.nan_to_num(self.magnitudes, nan=0.0)),
            np.ascontiguousarray(self.kappa),
        )

    def predict(self, points: npt.ArrayLike, t: float | npt.ArrayLike | None = None) -> FloatArray:
        """Most likely gaze directions (Eq 7.3) at ``points (M, 3)`` (or ``(3,)``) at time
        ``t`` (scalar, ``(M,)``, or ``None`` for a one-frame field): unit ``(M, 3)``.

        A row is NaN where no direction is defined: the frame has no charges, or every
        charge sits exactly at the point (a member does not look at itself).
        """
        pts = as_float_array(points, "points")
        single = pts.ndim == 1
        if single and pts.shape != (3,):
            raise ValueError(f"points: expected shape (3,) or (M, 3), got {pts.shape}")
        pts = as_float_array(pts.reshape(1, 3) if single else pts, "points", (None, 3))
        fr = self.frame_index(t, len(pts))
        out = _core.gaze_predict(*self._state(), fr, pts)
        return out[0] if single else out

    def log_likelihood(
        self, p: npt.ArrayLike, v: npt.ArrayLike, t: float | npt.ArrayLike | None = None
    ) -> FloatArray:
        """``ln p(v | p, t)`` of Eq 7.7 per row: ``p (M, 3)`` positions, ``v (M, 3)`` unit
        directions → ``(M,)`` (nats, density on the sphere; NaN where the frame has no
        field). A member exactly at a charge ignores that charge; with none left the
        density is uniform, ``−ln 4π``."""
        pp = as_float_array(p, "p", (None, 3))
        vv = as_float_array(v, "v", (len(pp), 3))
        fr = self.frame_index(t, len(pp))
        return _core.gaze_log_density(*self._state(), fr, pp, vv)

    def angle_to_charges(
        self,
        p: npt.ArrayLike,
        v: npt.ArrayLike,
        t: float | npt.ArrayLike | None = None,
        *,
        self_radius: float = 0.3,
    ) -> FloatArray:
        """Radians between each ``v`` and the direction to the closest (in angle) charge,
        ignoring charges within ``self_radius`` metres of ``p``; NaN where none
        qualifies. ``(M,)``."""
        pp = as_float_array(p, "p", (None, 3))
        vv = as_float_array(v, "v", (len(pp), 3))
        r = check_float(self_radius, "self_radius", min=0.0)
        fr = self.frame_index(t, len(pp))
        return _core.gaze_angle_to_charges(*self._state(), fr, pp, vv, r)

    def to_dict(self) -> dict[str, Any]:
        def clean(a: np.ndarray) -> Any:
            if a.dtype.kind != "f":
                return a.tolist()
            return np.where(np.isnan(a), np.array(None, dtype=object), a.astype(object)).tolist()

        return {k: clean(np.asarray(getattr(self, k))) for k in self.__dataclass_fields__}

    def plot(
        self,
        t: float | None = None,
        *,
        z: float | None = None,
        lo: npt.ArrayLike | None = None,
        hi: npt.ArrayLike | None = None,
        n: int = 17,
        rays: object | None = None,
        ax: Any = None,
    ) -> Any:
        """Plots the field as arrows of the most likely direction on the horizontal slice
        at height ``z`` (default: mean charge height), with the charges (dot area ∝
        magnitude) and, optionally, one frame's observed ``rays``. Returns the axes."""
        import matplotlib.pyplot as plt

        n = check_int(n, "n", min=2, max=1000)
        fr = int(self.frame_index(t, 1)[0])
        ch = self.positions[fr]
        ok = ~np.isnan(ch[:, 0])
        ch, mag = ch[ok], self.magnitudes[fr][ok]
        if ax is None:
            _, ax = plt.subplots(figsize=(6, 6))
        zz = float(np.mean(ch[:, 2])) if z is None and len(ch) else float(z or 0.0)
        if lo is None or hi is None:
            ref = ch[:, :2] if len(ch) else np.zeros((1, 2))
            if rays is not None:
                ref = np.vstack([ref, np.asarray(_frame_parts(rays, 0)[0])[:, :2]])
            lo2, hi2 = ref.min(axis=0) - 1.5, ref.max(axis=0) + 1.5
        else:
            lo2, hi2 = np.asarray(lo, float)[:2], np.asarray(hi, float)[:2]
        gx, gy = np.meshgrid(np.linspace(lo2[0], hi2[0], n), np.linspace(lo2[1], hi2[1], n))
        pts = np.c_[gx.ravel(), gy.ravel(), np.full(gx.size, zz)]
        d = self.predict(pts, self.times[fr])
        ax.quiver(pts[:, 0], pts[:, 1], d[:, 0], d[:, 1], color="0.35", angles="xy", scale=n * 1.6)
        if len(ch):
            ax.scatter(
                ch[:, 0], ch[:, 1], s=60 * np.maximum(mag, 0.2), c="C3", zorder=3, label="charges"
            )
        if rays is not None:
            rp, rv = (np.asarray(a, float) for a in _frame_parts(rays, 0)[:2])
            ax.quiver(
                rp[:, 0],
                rp[:, 1],
                rv[:, 0],
                rv[:, 1],
                color="C0",
                angles="xy",
                scale=8,
                label="observed gaze",
            )
            ax.scatter(rp[:, 0], rp[:, 1], c="C0", s=15)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"gaze field at t = {self.times[fr]:.2f} s, z = {zz:.2f} m")
        ax.legend(loc="upper right")
        return ax


def _charges_from_chapter6(
    flat: _Flat, seed: int, options: dict[str, Any]
) -> tuple[IntArray, FloatArray]:
    """Per-frame charge counts and positions (F, C, 3, NaN-padded, strongest first) from
    the social-charge finder of Chapter 6."""
    try:
        from socialcam.charges import GazeRays, find_charges_sequence
    except ImportError as exc:  # pragma: no cover - depends on the charges module
        raise ValueError(
            "n_charges=None needs socialcam.charges (Chapter 6); pass n_charges explicitly"
        ) from exc
    parts = flat.to_frames()
    idx = [k for k, (p, _, _, _) in enumerate(parts) if len(p)]
    rays = [GazeRays(*parts[k]) for k in idx]
    options = {"membership": "strongest", **options}
    found = find_charges_sequence(rays, seed=seed, **options) if idx else []
    counts = np.zeros(flat.n_frames, dtype=np.int64)
    cmax = max((len(c) for c in found), default=0)
    cand = np.full((flat.n_frames, max(cmax, 1), 3), np.nan)
    for k, cs in zip(idx, found, strict=True):
        counts[k] = len(cs)
        for i, c in enumerate(cs):
            cand[k, i] = c.position
    return counts, cand


# ---------------------------------------------------------------------- evaluation
@dataclass(frozen=True)
class GazeCrossValidation:
    """Angular errors of predicting left-out members' gaze (Sec 7.4.1).

    Attributes
    ----------
    method : ``"field"`` or ``"rbf"``
    leave_out : members left out per split (k)
    left_out : (S, k) person ids left out in each split
    errors : (E,) degrees between predicted and observed directions of the left-out
        members, over every split and frame where they were observed and a prediction
        was defined
    split : (E,) split index of each error
    frame : (E,) frame index of each error
    n_undefined : predictions left out because no direction was defined there
    """

    method: str
    leave_out: int
    left_out: IntArray
    errors: FloatArray
    split: IntArray
    frame: IntArray
    n_undefined: int

    @property
    def mean(self) -> float:
        """Mean error, degrees."""
        return float(np.mean(self.errors)) if len(self.errors) else float("nan")

    @property
    def std(self) -> float:
        """Standard deviation of the error, degrees."""
        return float(np.std(self.errors)) if len(self.errors) else float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "leave_out": self.leave_out,
            "left_out": self.left_out.tolist(),
            "errors": self.errors.tolist(),
            "split": self.split.tolist(),
            "frame": self.frame.tolist(),
            "n_undefined": self.n_undefined,
            "mean": self.mean,
            "std": self.std,
        }


def _angles_deg(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.rad2deg(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))


def rbf_predict(
    frames: Sequence[object],
    points: npt.ArrayLike,
    frame: npt.ArrayLike,
    *,
    kernel: str = "linear",
    smoothing: float = 0.0,
) -> FloatArray:
    """The baseline of Sec 7.4.1 (Kim et al.): radial-basis regression from the observed
    members' positions to their gaze directions, per frame, with
    :class:`scipy.interpolate.RBFInterpolator` (default kernel ``"linear"``, i.e. ``r``,
    with a constant term), evaluated at ``points (M, 3)`` in frames ``frame (M,)`` and
    normalised to unit length. NaN rows where a frame has no observation."""
    from scipy.interpolate import RBFInterpolator  # type: ignore[import-untyped]

    flat = _flatten(frames)
    pts = as_float_array(points, "points", (None, 3))
    fr = as_int_array(frame, "frame")
    if fr.shape != (len(pts),) or (fr < 0).any() or (fr >= flat.n_frames).any():
        raise ValueError("frame: expected one valid frame index per point")
    kernel = check_choice(
        kernel,
        "kernel",
        (
            "linear",
            "thin_plate_spline",
            "cubic",
            "quintic",
            "multiquadric",
            "inverse_multiquadric",
            "inverse_quadratic",
            "gaussian",
        ),
    )
    smoothing = check_float(smoothing, "smoothing", min=0.0)
    out = np.full((len(pts), 3), np.nan)
    o = flat.offsets
    for f in np.unique(fr):
        a, b = o[f], o[f + 1]
        if b == a:
            continue
        rows = np.flatnonzero(fr == f)
        if b - a == 1:
            out[rows] = flat.v[a]
            continue
        try:
            interp = RBFInterpolator(
                flat.p[a:b], flat.v[a:b], kernel=kernel, smoothing=smoothing, degree=0
            )
        except np.linalg.LinAlgError:
            _, first, count = np.unique(flat.p[a:b], axis=0, return_index=True, return_counts=True)
            if (count > 1).any():
                i = int(first[np.argmax(count > 1)])
                raise DegenerateError(
                    f"frames[{f}]: two members share the eye position of member {i}; the "
                    "radial-basis regression cannot interpolate two directions at one point "
                    "(give smoothing > 0)"
                ) from None
            raise DegenerateError(
                f"frames[{f}]: the members' eye positions make the radial-basis system "
                "singular (give smoothing > 0)"
            ) from None
        d = interp(pts[rows])
        n = np.linalg.norm(d, axis=1, keepdims=True)
        out[rows] = np.where(n > 0, d / np.where(n > 0, n, 1.0), np.nan)
    return out


def cross_validate_gaze(
    frames: Sequence[object],
    *,
    leave_out: int = 1,
    method: Literal["field", "rbf"] = "field",
    seed: int = 0,
    times: npt.ArrayLike | None = None,
    n_splits: int | None = None,
    eligible: npt.ArrayLike | None = None,
    **fit_options: Any,
) -> GazeCrossValidation:
    """Leave-k-out cross-validation of gaze prediction (Sec 7.4.1).

    Each split leaves out ``leave_out`` members (all of their rays in every frame),
    predicts their gaze from the others — by a :class:`GazeField` fitted to the rest
    (``method="field"``, options passed to :meth:`GazeField.fit`) or by the radial-basis
    regression baseline (``method="rbf"``, :func:`rbf_predict`) — and measures the angle
    to their observed primary gaze. With ``leave_out=1`` every member is left out once;
    otherwise ``n_splits`` (default: the number of members) random subsets are drawn from
    ``seed``. ``fit_options["n_charges"]`` may be a callable taking the training person
    ids and returning the per-frame counts (e.g. true counts among the members kept).
    ``eligible`` restricts the members that may be left out (person ids; e.g.
    to keep known outliers always in the training set); the others always train.

    Returns
    -------
    GazeCrossValidation : errors in degrees, with ``mean`` and ``std``
    """
    seed = check_seed(seed)
    check_choice(method, "method", ("field", "rbf"))
    flat = _flatten(frames)
    people = np.unique(flat.ids)
    if len(people) < 3:
        raise ValueError(
            f"frames: cross-validation needs rays of at least 3 members (one left out, two "
            f"stay), got {len(people)}"
        )
    if eligible is None:
        pool = people
    else:
        el = as_int_array(eligible, "eligible")
        if el.ndim != 1 or len(el) == 0:
            raise ValueError("eligible: expected a non-empty list of person ids")
        pool = np.intersect1d(people, el)
        if len(pool) == 0:
            raise ValueError("eligible: none of these person ids appears in the frames")
    k = check_int(leave_out, "leave_out", min=1)
    if k >= len(people) - 1 or k > len(pool):
        raise ValueError(
            f"leave_out: expected 1 <= k <= {min(len(people) - 2, len(pool))} (two members must "
            f"stay), got {leave_out!r}"
        )
    if n_splits is not None:
        check_int(n_splits, "n_splits", min=1, max=1_000_000)
    t = _times(times, flat.n_frames)
    if k == 1 and n_splits is None:
        subsets = pool[:, None]
    else:
        rng = np.random.default_rng(seed)
        s = len(people) if n_splits is None else int(n_splits)
        subsets = np.array([np.sort(rng.choice(pool, size=k, replace=False)) for _ in range(s)])
    fr_all = flat.frame_of_ray()
    errs, split_ix, frame_ix = [], [], []
    undefined = 0
    for si, out_ids in enumerate(subsets):
        held = np.isin(flat.ids, out_ids)
        train = flat.select(~held)
        train_frames = train.to_frames()
        q_p, q_v, q_f = flat.p[held], flat.v[held], fr_all[held]
        if method == "field":
            opts = dict(fit_options)
            if callable(opts.get("n_charges")):
                opts["n_charges"] = opts["n_charges"](np.setdiff1d(people, out_ids))
            field = GazeField.fit(train_frames, times=t, seed=seed, **opts)
            pred = field.predict(q_p, t[q_f])
        else:
            pred = rbf_predict(train_frames, q_p, q_f)
        ok = ~np.isnan(pred[:, 0])
        undefined += int((~ok).sum())
        errs.append(_angles_deg(pred[ok], q_v[ok]))
        split_ix.append(np.full(int(ok.sum()), si, dtype=np.int64))
        frame_ix.append(q_f[ok])
    return GazeCrossValidation(
        method=method,
        leave_out=k,
        left_out=readonly(np.asarray(subsets, dtype=np.int64)),
        errors=readonly(np.concatenate(errs)),
        split=readonly(np.concatenate(split_ix)),
        frame=readonly(np.concatenate(frame_ix)),
        n_undefined=undefined,
    )


@dataclass(frozen=True)
class Anomalies:
    """Members who follow no social charge (Sec 7.4.2, Fig 7.3b).

    Attributes
    ----------
    frame : (K,) frame index of each flagged observation
    member : (K,) person id of each flagged observation
    score : (K,) the score that crossed the threshold (radians for ``kind="angle"``, log
        density for ``kind="loglik"``)
    scores : (N,) the score of every observation (rays in frame order; NaN where the field
        cannot judge, e.g. the only charge sits on the member)
    flags : (N,) bool, whether each observation is flagged
    kind : ``"angle"`` or ``"loglik"``
    threshold : the threshold used
    """

    frame: IntArray
    member: IntArray
    score: FloatArray
    scores: FloatArray
    flags: npt.NDArray[np.bool_]
    kind: str
    threshold: float

    def pairs(self) -> set[tuple[int, int]]:
        """The flagged ``(frame, member)`` pairs."""
        return {(int(f), int(m)) for f, m in zip(self.frame, self.member, strict=True)}

    def to_dict(self) -> dict[str, Any]:
        return {
            "frame": self.frame.tolist(),
            "member": self.member.tolist(),
            "score": self.score.tolist(),
            "kind": self.kind,
            "threshold": self.threshold,
        }


def detect_anomalies(
    frames: Sequence[object],
    field: GazeField,
    *,
    threshold: float = float(np.pi / 6),
    times: npt.ArrayLike | None = None,
    kind: Literal["angle", "loglik"] = "angle",
    self_radius: float = 0.3,
) -> Anomalies:
    """Flags observations whose gaze does not follow the group's attention.

    ``kind="angle"`` (default): flagged when the primary gaze is more than ``threshold``
    radians from the direction to every charge of the field at that time (charges within
    ``self_radius`` metres of the member are ignored: the person being looked at is not
    expected to look at themself; with no charge left the observation is not judged).
    ``kind="loglik"``: flagged when ``ln p(v | p, t)`` (Eq 7.7) is below ``threshold``.

    ``frames`` must be on the field's time axis (``times``, default the field's own).
    """
    flat = _flatten(frames)
    if not isinstance(field, GazeField):
        raise ValueError(f"field: expected a GazeField, got {type(field).__name__}")
    check_choice(kind, "kind", ("angle", "loglik"))
    threshold = check_float(threshold, "threshold")
    self_radius = check_float(self_radius, "self_radius", min=0.0)
    t = (
        field.times
        if times is None and flat.n_frames == len(field.times)
        else _times(times, flat.n_frames)
    )
    fr = flat.frame_of_ray()
    if kind == "angle":
        scores = field.angle_to_charges(flat.p, flat.v, t[fr], self_radius=self_radius)
        flags = np.nan_to_num(scores, nan=-np.inf) > threshold
    else:
        scores = field.log_likelihood(flat.p, flat.v, t[fr])
        flags = np.nan_to_num(scores, nan=np.inf) < threshold
    return Anomalies(
        frame=readonly(fr[flags]),
        member=readonly(flat.ids[flags]),
        score=readonly(scores[flags]),
        scores=readonly(scores),
        flags=readonly(flags),
        kind=kind,
        threshold=float(threshold),
    )


#: largest concentration :func:`fuse_gaze` takes: κ is about 1/σ² for an angular spread σ,
#: so 1e150 is σ of 1e-75 rad; the norm of the weighted sum of two directions (its squares)
#: overflows beyond it
MAX_KAPPA = 1e150


def fuse_gaze(
    measured: npt.ArrayLike,
    kappa_measured: float | npt.ArrayLike,
    predicted: npt.ArrayLike,
    kappa_field: float | npt.ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Fuses noisy measured head directions with the gaze field's prediction (Sec 7.4.2).

    Both are von Mises–Fisher: the product ``V(u | a, κₐ) V(u | b, κ_b)`` is again vMF with
    mean ``(κₐa + κ_b b)/‖κₐa + κ_b b‖`` and concentration ``‖κₐa + κ_b b‖`` — the average
    of the two directions weighted by their concentrations. Rows where the prediction is
    NaN keep the measurement.

    Parameters
    ----------
    measured, predicted : (M, 3) unit directions
    kappa_measured, kappa_field : float or (M,) concentrations > 0

    Returns
    -------
    directions (M, 3) unit, kappa (M,)
    """
    a = as_float_array(measured, "measured", (None, 3))
    b = as_float_array(predicted, "predicted", (len(a), 3), allow_nan=True)
    ka = _per_row(as_float_array(kappa_measured, "kappa_measured"), "kappa_measured", len(a))
    kb = _per_row(as_float_array(kappa_field, "kappa_field", allow_nan=True), "kappa_field", len(a))
    if (ka <= 0).any() or (np.nan_to_num(kb, nan=1.0) <= 0).any():
        raise ValueError("kappa_measured, kappa_field: concentrations must be > 0")
    if (ka > MAX_KAPPA).any() or (np.nan_to_num(kb, nan=1.0) > MAX_KAPPA).any():
        raise ValueError(
            f"kappa_measured, kappa_field: concentrations above {MAX_KAPPA:g} (a spread far "
            "below float64's angular resolution) overflow the fusion"
        )
    partial = np.isnan(b).any(axis=1) & ~np.isnan(b).all(axis=1)
    if partial.any():
        raise ValueError(
            f"predicted: row {int(np.flatnonzero(partial)[0])} is partly NaN (a row is a "
            "direction or all NaN)"
        )
    for name, arr in (("measured", a), ("predicted", b)):
        n = np.linalg.norm(arr, axis=1)
        bad = np.abs(n - 1.0) > UNIT_TOLERANCE
        if (bad & ~np.isnan(n)).any():
            raise ValueError(f"{name}: directions must be unit vectors")
    missing = np.isnan(b[:, 0]) | np.isnan(kb)
    s = ka[:, None] * a + np.where(
        missing[:, None], 0.0, np.nan_to_num(kb)[:, None] * np.nan_to_num(b)
    )
    kappa = np.linalg.norm(s, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = s / kappa[:, None]
    # Exactly opposite, equally certain directions cancel: keep the measurement.
    zero = kappa == 0
    d[zero] = a[zero]
    kappa[zero] = np.finfo(float).tiny
    return d, kappa


def plot_gaze_field(field: GazeField, t: float | None = None, **kwargs: Any) -> Any:
    """Plots ``field`` on a horizontal slice; see :meth:`GazeField.plot`."""
    return field.plot(t, **kwargs)


def _fill_window_init(start: FloatArray, windows: npt.NDArray[np.int64]) -> FloatArray:
    """A window of ``n`` charges may hold frames that had another count (short runs are
    merged into their neighbours, ``gaze_split_windows``): a frame with fewer starts from the
    nearest frame of its window that has all ``n`` positions, one with more keeps its first
    ``n``."""
    start = np.array(start, dtype=np.float64)
    for a, b, n in windows:
        start[a:b, n:] = np.nan  # a frame with more charges than its window keeps n
        if n == 0:
            continue
        ok = np.isfinite(start[a:b, :n]).all(axis=(1, 2))
        if ok.all():
            continue
        good = np.flatnonzero(ok)
        if len(good) == 0:
            raise ValueError(
                f"init: no frame of frames {a}..{b - 1} has the window's {n} charge positions"
            )
        for k in np.flatnonzero(~ok):
            start[a + k, :n] = start[a + good[np.argmin(np.abs(good - k))], :n]
    return start
