"""Simulated social scenes with known joint attention (thesis Sec 6.2).

Every scene is people (eye centres over time) looking at targets chosen per frame; the
primary gaze directions a social camera would measure are drawn from the gaze model of
Sec 3.1 (:func:`socialcam.synth.looking_at`), so each ray misses its target by an
eye-in-head deviation ``m ~ N(0, h² I₂)`` on the plane at unit distance.

- :func:`mocap_replica`: 6 people walk freely in the 8.3 × 17.7 × 4.3 m capture volume
  of Sec 6.2.1 and look at 2 static markers (3 each).
- :func:`meeting`: 11 people in two groups (6 and 5) around two tables, each group
  attending its own focus; then everyone faces a presenter; then back to the groups
  (Fig 6.6).
- :func:`party`: 11 people in four groups (3 on couches, 3 at a table, 3 at table
  tennis, 2 at pool); then everyone walks over to watch the table-tennis ball (Fig 6.7).

All return a :class:`SocialScene`: per-frame rays ``(p, v, h, ids)``, the true point each
person attends, and the true group (= attended target) of each person. ``h`` is the rays'
bandwidth (the calibrated range of eye-in-head motion the field uses, Sec 3.2.1) and
``noise`` the std of the deviation actually drawn while people fixate a target (default
0.02 ≈ 1.1°; ``noise=None`` draws with ``h`` itself, a harder setting).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from socialcam._validate import FloatArray, check_seed
from socialcam.synth.people import looking_at, wander

if TYPE_CHECKING:
    from socialcam.charges import GazeRays

IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class SocialScene:
    """A simulated scene of ``F`` frames, ``P`` people and ``T`` attention targets.

    Attributes
    ----------
    name : scene name
    times : (F,) seconds
    eyes : (F, P, 3) eye centres ``p``, metres
    gaze : (F, P, 3) primary gaze directions ``v`` (unit): what social cameras measure
    gaze_true : (F, P, 3) true gaze directions (unit, eye → ``regard``)
    h : (P,) gaze-model bandwidths of the rays (what the saliency field uses)
    noise : (P,) std of the eye-in-head deviation actually drawn between ``gaze_true``
        and ``gaze`` (equal to ``h`` unless a scene was asked for another noise)
    ids : (P,) person ids
    targets : (F, T, 3) positions of the attention targets, metres
    group : (F, P) true group of each person: the index of the target attended, -1 for
        a person attending nothing shared (walking, looking around)
    regard : (F, P, 3) the point each person really looks at (the target, or a random
        point 3 m away when ``group`` is -1)
    room : (2, 3) corners ``lo, hi`` of the scene's box, metres
    """

    name: str
    times: FloatArray
    eyes: FloatArray
    gaze: FloatArray
    gaze_true: FloatArray
    h: FloatArray
    noise: FloatArray
    ids: IntArray
    targets: FloatArray
    group: IntArray
    regard: FloatArray
    room: FloatArray

    @property
    def n_frames(self) -> int:
        return int(self.eyes.shape[0])

    @property
    def n_people(self) -> int:
        return int(self.eyes.shape[1])

    def rays(self, frame: int) -> GazeRays:
        """The gaze rays of one frame."""
        from socialcam.charges import GazeRays

        return GazeRays(self.eyes[frame], self.gaze[frame], self.h, self.ids)

    def ray_frames(self) -> list[GazeRays]:
        """The gaze rays of every frame (input of ``find_charges_sequence``)."""
        return [self.rays(f) for f in range(self.n_frames)]

    def n_charges(self, min_members: int = 2) -> IntArray:
        """(F,) true number of social charges: targets attended by ≥ ``min_members``."""
        T = self.targets.shape[1]
        counts = np.stack([(self.group == t).sum(axis=1) for t in range(T)], axis=1)
        return (counts >= min_members).sum(axis=1).astype(np.int64)  # type: ignore[no-any-return]

    def members(self, frame: int, target: int) -> IntArray:
        """Person ids attending ``target`` in ``frame``."""
        return self.ids[self.group[frame] == target]  # type: ignore[no-any-return]

    def oracle_intersections(self) -> FloatArray:
        """(F, T, 3) the least-squares intersection of each true group's measured rays
        (the point minimising the sum of squared distances to the lines of the rays of
        the people attending target ``t``; NaN where fewer than 2 people attend it): the
        error of an estimator that knew who looks at what."""
        F, T = self.n_frames, self.targets.shape[1]
        out = np.full((F, T, 3), np.nan)
        eye = np.eye(3)
        for f in range(F):
            for t in range(T):
                sel = self.group[f] == t
                if sel.sum() < 2:
                    continue
                v = self.gaze[f, sel]
                proj = eye[None] - v[:, :, None] * v[:, None, :]
                a = proj.sum(axis=0)
                b = np.einsum("nij,nj->i", proj, self.eyes[f, sel])
                out[f, t] = np.linalg.solve(a, b)
        return out

    def charge_scores(self, charges: Sequence[Sequence[Any]]) -> tuple[float, float, float]:
        """How well per-frame charges (``find_charges_sequence`` output: objects with a
        ``position``) recover the attended targets: the fraction of frames with the right
        number of charges (:meth:`n_charges`), the mean distance from each attended
        target to its nearest charge (the room diagonal when the frame has none) and the
        same mean for :meth:`oracle_intersections`, metres."""
        truth = self.n_charges()
        right = np.mean([len(cs) == t for cs, t in zip(charges, truth, strict=True)])
        orc = self.oracle_intersections()
        diag = float(np.linalg.norm(self.room[1] - self.room[0]))
        err, oerr = [], []
        for f, cs in enumerate(charges):
            pos = np.array([c.position for c in cs]).reshape(-1, 3)
            for t in range(self.targets.shape[1]):
                if np.isnan(orc[f, t, 0]):
                    continue
                oerr.append(np.linalg.norm(orc[f, t] - self.targets[f, t]))
                err.append(
                    np.linalg.norm(pos - self.targets[f, t], axis=1).min() if len(pos) else diag
                )
        return float(right), float(np.mean(err)), float(np.mean(oerr))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name}
        for k in self.__dataclass_fields__:
            if k != "name":
                out[k] = np.asarray(getattr(self, k)).tolist()
        return out


def _scene(
    name: str,
    eyes: FloatArray,
    targets: FloatArray,
    group: IntArray,
    h: float | npt.ArrayLike,
    fps: float,
    room: tuple[tuple[float, float, float], tuple[float, float, float]],
    seed: int,
    noise: float | npt.ArrayLike | None = None,
) -> SocialScene:
    F = eyes.shape[0]
    dev = h if noise is None else noise
    people = looking_at(eyes, targets, group, h=dev, times=np.arange(F) / fps, seed=seed)
    hh = np.broadcast_to(np.asarray(h, dtype=np.float64), (eyes.shape[1],)).copy()
    if (hh <= 0).any() or not np.isfinite(hh).all():
        raise ValueError("h: bandwidths must be finite and > 0")
    return SocialScene(
        name=name,
        times=people.times,
        eyes=people.eyes,
        gaze=people.gaze,
        gaze_true=people.gaze_true,
        h=hh,
        noise=people.h,
        ids=people.ids,
        targets=people.targets,
        group=people.attention,
        regard=people.regard,
        room=np.array(room, dtype=np.float64),
    )


def _sway(rng: np.random.Generator, F: int, P: int, amp: float, fps: float) -> FloatArray:
    """Smooth small head motion ``(F, P, 3)``: a few random sinusoids of 0.05–0.4 Hz."""
    t = np.arange(F) / fps
    out = np.zeros((F, P, 3))
    for _ in range(3):
        f = rng.uniform(0.05, 0.4, (P, 3))
        ph = rng.uniform(0, 2 * np.pi, (P, 3))
        out += np.sin(2 * np.pi * f[None] * t[:, None, None] + ph[None]) * (amp / 3)
    out[..., 2] *= 0.5
    return out


def _ring(centre: tuple[float, float], radius: float, n: int, phase: float) -> FloatArray:
    a = phase + np.arange(n) * 2 * np.pi / n
    return np.c_[centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)]


def _switch(
    F: int, P: int, phases: list[tuple[int, npt.ArrayLike]], rng: np.random.Generator, jitter: int
) -> IntArray:
    """Per-person target over time: phase ``k`` starts at frame ``start_k`` (each person
    switching up to ``jitter`` frames late) with per-person targets ``targets_k (P,)``."""
    out = np.empty((F, P), dtype=np.int64)
    for k, (start, tg) in enumerate(phases):
        tg_a = np.broadcast_to(np.asarray(tg, dtype=np.int64), (P,))
        late = rng.integers(0, jitter + 1, P) if k > 0 else np.zeros(P, dtype=np.int64)
        for p in range(P):
            out[start + late[p] :, p] = tg_a[p]
    return out


def mocap_replica(
    n_frames: int = 300,
    *,
    h: float = 0.06,
    noise: float | None = 0.02,
    fps: float = 10.0,
    speed: float = 0.5,
    area: tuple[tuple[float, float], tuple[float, float]] = ((0.4, 3.5), (7.9, 14.5)),
    seed: int = 0,
) -> SocialScene:
    """Sec 6.2.1 replica: 6 people walk freely (eye height 1.5–1.8 m) in the 8.3 × 17.7 ×
    4.3 m capture volume and look at 2 static markers, people 0–2 at marker 0 and 3–5 at
    marker 1. Their primary gaze deviates from the true gaze by eye-in-head motion of std
    ``noise`` (gaze model, Sec 3.1; ``None`` means ``h``), and the rays carry bandwidth
    ``h``, the calibrated eye-in-head range the saliency field uses.

    People walk in the floor rectangle ``area`` (default: the middle 11 m of the volume's
    length, within about 7 m of the markers), the markers are ``targets[:, 0]`` and
    ``targets[:, 1]``, ``group`` says who looks at which."""
    s = check_seed(seed)
    room = ((0.0, 0.0, 0.0), (8.3, 17.7, 4.3))
    markers = np.array([[3.2, 7.0, 1.2], [5.4, 11.2, 2.3]])
    eyes = wander(n_frames, 6, seed=s + 1, room=area, fps=fps, speed=speed)
    group = np.broadcast_to(np.array([0, 0, 0, 1, 1, 1]), (n_frames, 6)).copy()
    return _scene("mocap_replica", eyes, markers, group, h, fps, room, s + 2, noise)


def meeting(
    n_frames: int = 300,
    *,
    h: float = 0.06,
    noise: float | None = 0.02,
    fps: float = 10.0,
    seed: int = 0,
) -> SocialScene:
    """The meeting of Fig 6.6: 11 seated people, group A (ids 0–5) around a table at
    (2, 2.5) and group B (ids 6–10) around a table at (7, 2.5). First third: each group
    attends its own focus (a point drifting slowly over its table, 1.1 m high; targets 0
    and 1); middle third: everyone faces the presenter walking at the front (target 2,
    head height); last third: back to the groups. People switch up to 1 s apart.

    True charges: 2, then 1, then 2 (``n_charges()``)."""
    s = check_seed(seed)
    rng = np.random.default_rng(s)
    F, P = n_frames, 11
    t = np.arange(F) / fps
    tables = [(2.0, 2.5), (7.0, 2.5)]
    seats = np.vstack([_ring(tables[0], 1.1, 6, 0.3), _ring(tables[1], 1.0, 5, 1.0)])
    eyes = np.empty((F, P, 3))
    eyes[..., :2] = seats[None]
    eyes[..., 2] = rng.uniform(1.15, 1.3, P)[None]
    eyes += _sway(rng, F, P, 0.06, fps)
    targets = np.empty((F, 3, 3))
    for k, (cx, cy) in enumerate(tables):
        ph = rng.uniform(0, 2 * np.pi, 2)
        targets[:, k, 0] = cx + 0.3 * np.sin(2 * np.pi * 0.03 * t + ph[0])
        targets[:, k, 1] = cy + 0.3 * np.sin(2 * np.pi * 0.045 * t + ph[1])
        targets[:, k, 2] = 1.1
    targets[:, 2, 0] = 4.5 + 1.0 * np.sin(2 * np.pi * 0.02 * t)
    targets[:, 2, 1] = 7.0
    targets[:, 2, 2] = 1.65
    own = np.array([0] * 6 + [1] * 5)
    group = _switch(F, P, [(0, own), (F // 3, 2), (2 * F // 3, own)], rng, int(fps))
    room = ((-1.0, -1.0, 0.0), (10.0, 9.0, 3.0))
    return _scene("meeting", eyes, targets, group, h, fps, room, s + 1, noise)


def party(
    n_frames: int = 300,
    *,
    h: float = 0.06,
    noise: float | None = 0.02,
    fps: float = 10.0,
    seed: int = 0,
) -> SocialScene:
    """The party of Fig 6.7 in a 12 × 9 m room: 3 people on couches watch a TV (target
    0, ids 0–2), 3 stand talking over a high table (target 1, ids 3–5), 3 at table tennis
    follow the ball (target 2, ids 6–8), 2 at pool look at the cue ball (target 3, ids
    9–10). Halfway, everyone turns to the table-tennis ball (up to 0.5 s apart) and all
    but the two players walk over (3 s) to stand around the table: 4 charges, then 1."""
    s = check_seed(seed)
    rng = np.random.default_rng(s)
    F, P = n_frames, 11
    t = np.arange(F) / fps
    tv = np.array([1.0, 8.7, 1.0])
    table = (9.0, 7.0)
    tt_centre = np.array([6.0, 2.5])
    pool = (2.5, 2.5)
    start = np.vstack(
        [
            [[0.5, 6.4], [1.3, 6.2], [2.1, 6.4]],  # couch, facing the TV to the north
            _ring(table, 0.6, 3, 0.5),  # high table
            [[4.4, 2.5], [7.6, 2.5], [6.0, 1.2]],  # players at both ends, umpire at side
            [[1.4, 2.5], [3.6, 3.0]],  # pool
        ]
    )
    heights = np.r_[rng.uniform(1.1, 1.2, 3), rng.uniform(1.55, 1.8, 8)]
    # Second half: spectators stand around the table-tennis table.
    watch = _ring((tt_centre[0], tt_centre[1]), 2.2, 11, 0.2)
    half = F // 2
    walk = int(3 * fps)
    eyes = np.empty((F, P, 3))
    eyes[..., :2] = start[None]
    eyes[..., 2] = heights[None]
    movers = [p for p in range(P) if p not in (6, 7)]
    for p in movers:
        a = np.clip((np.arange(F) - half) / walk, 0.0, 1.0)
        a = a * a * (3 - 2 * a)  # smooth start and stop
        eyes[:, p, :2] = (1 - a)[:, None] * start[p] + a[:, None] * watch[p]
        eyes[half:, p, 2] = np.maximum(heights[p], 1.55 + 0.02 * p)
    eyes += _sway(rng, F, P, 0.05, fps)
    targets = np.empty((F, 4, 3))
    targets[:, 0] = tv
    targets[:, 1] = [table[0], table[1], 1.45]
    # Table-tennis ball: back and forth along the table, bouncing.
    ph = 2 * np.pi * 0.4 * t
    targets[:, 2, 0] = tt_centre[0] + 1.2 * np.sin(ph)
    targets[:, 2, 1] = tt_centre[1] + 0.3 * np.sin(0.37 * ph)
    targets[:, 2, 2] = 0.85 + 0.25 * np.abs(np.cos(ph))
    targets[:, 3] = [pool[0], 2.7, 0.85]
    targets[:, 3, 0] = pool[0] + 0.4 * np.sin(2 * np.pi * 0.05 * t)
    before = np.array([0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3])
    group = _switch(F, P, [(0, before), (half, 2)], rng, int(fps // 2))
    room = ((0.0, 0.0, 0.0), (12.0, 9.0, 3.0))
    return _scene("party", eyes, targets, group, h, fps, room, s + 1, noise)


def _partition(
    rng: np.random.Generator, P: int, T: int, min_group: int = 2, max_group: int = 6
) -> IntArray:
    """A random assignment of ``P`` people to ``T`` targets in which every attended target
    has ``min_group`` to ``max_group`` people (some targets may be unattended)."""
    if P < min_group or P > T * max_group:
        raise ValueError(f"n_people: {P} people cannot form groups of {min_group}–{max_group}")
    while True:
        k = int(rng.integers(1, min(T, P // min_group) + 1))  # how many groups
        chosen = rng.choice(T, size=k, replace=False)
        sizes = np.full(k, min_group)
        extra = rng.multinomial(P - k * min_group, np.full(k, 1.0 / k))
        sizes = sizes + extra
        out = np.repeat(chosen, sizes)
        rng.shuffle(out)
        if sizes.max() <= max_group:
            return out.astype(np.int64)


def marker_check(
    n_frames: int = 300,
    *,
    n_people: int = 6,
    n_markers: int = 2,
    room: tuple[float, float, float] = (8.3, 17.7, 4.3),
    h: float = 0.01,
    moving: bool = False,
    switch_every: tuple[float, float] = (2.0, 5.0),
    fps: float = 10.0,
    speed: float = 0.6,
    seed: int = 0,
) -> SocialScene:
    """A held-out variant of the marker check of Sec 6.2.1 (not the scenes the charge
    options were tuned on): ``n_people`` wander the whole floor of a ``room = (length,
    width, height)`` box (metres) and every one of them always looks at one of
    ``n_markers`` markers (1–2.6 m high, anywhere in the room at least 1 m from the
    walls; static, or drifting at about 0.3 m/s when ``moving``). Every ``switch_every``
    seconds (uniform in the range, drawn per switch) the groups are redrawn: a random
    partition of the people in which every attended marker has at least 2 people, so
    groups of 2 are common and a marker may be unattended. Eye-in-head deviations are
    drawn with the rays' own bandwidth ``h`` (the gaze model at its calibrated spread).

    ``targets[:, t]`` are the markers, ``group`` who looks at which (never -1)."""
    s = check_seed(seed)
    rng = np.random.default_rng(s)
    F, P, T = int(n_frames), int(n_people), int(n_markers)
    if T < 1:
        raise ValueError(f"n_markers: need at least 1 marker, got {T}")
    L, W, H = (float(x) for x in room)
    margin = 1.0
    eyes = wander(F, P, seed=s + 1, room=((0.3, 0.3), (L - 0.3, W - 0.3)), fps=fps, speed=speed)
    start = np.c_[
        rng.uniform(margin, L - margin, T),
        rng.uniform(margin, W - margin, T),
        rng.uniform(1.0, min(2.6, H - 0.3), T),
    ]
    targets = np.broadcast_to(start, (F, T, 3)).copy()
    if moving:
        t = np.arange(F) / fps
        for k in range(T):
            f = rng.uniform(0.02, 0.05, 2)
            ph = rng.uniform(0, 2 * np.pi, 2)
            amp = 0.3 / (2 * np.pi * f)  # peak speed about 0.3 m/s per axis
            amp = np.minimum(amp, [start[k, 0] - margin, start[k, 1] - margin])
            amp = np.minimum(amp, [L - margin - start[k, 0], W - margin - start[k, 1]])
            targets[:, k, 0] += amp[0] * np.sin(2 * np.pi * f[0] * t + ph[0]) - amp[0] * np.sin(
                ph[0]
            )
            targets[:, k, 1] += amp[1] * np.sin(2 * np.pi * f[1] * t + ph[1]) - amp[1] * np.sin(
                ph[1]
            )
    group = np.empty((F, P), dtype=np.int64)
    f0 = 0
    while f0 < F:
        f1 = min(F, f0 + max(1, round(rng.uniform(*switch_every) * fps)))
        group[f0:f1] = _partition(rng, P, T)[None]
        f0 = f1
    return _scene("marker_check", eyes, targets, group, h, fps, ((0, 0, 0), (L, W, H)), s + 2)


def marker_check_family(seed: int, n_frames: int = 100) -> SocialScene:
    """One scene of the held-out family used to check the charge rule: ``seed`` draws the
    number of people (4–12) and markers (2–3, so groups of 2–6), the room (length 6–20 m,
    width 5–20 m), ``h`` log-uniform in [0.01, 0.1] and static or moving markers, then
    :func:`marker_check` with that seed."""
    s = check_seed(seed)
    rng = np.random.default_rng([s, 7013])
    T = int(rng.integers(2, 4))
    P = int(rng.integers(2 * T, min(12, 6 * T) + 1))
    room = (float(rng.uniform(6, 20)), float(rng.uniform(5, 20)), 3.5)
    h = float(np.exp(rng.uniform(np.log(0.01), np.log(0.1))))
    moving = bool(rng.integers(0, 2))
    return marker_check(n_frames, n_people=P, n_markers=T, room=room, h=h, moving=moving, seed=s)


__all__ = [
    "SocialScene",
    "marker_check",
    "marker_check_family",
    "meeting",
    "mocap_replica",
    "party",
]
